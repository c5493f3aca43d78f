//! System identification of link inertias and joint friction from robot logs (`twin sysid`).
//!
//! A team logs its robot moving (joint positions and efforts), and gets a URDF whose link
//! inertias and joint friction reproduce the measured torques: physically valid, with
//! confidence figures, every other byte of the URDF untouched.
//!
//! ```no_run
//! use sysid::{JointLog, RobotModel, SysidOptions};
//!
//! let robot = RobotModel::from_urdf("robot.urdf")?;
//! let log = JointLog::read_csv("log.csv")?;
//! let ident = sysid::identify(&robot, &log, &SysidOptions::default())?;
//! print!("{}", ident.report.table());
//! let (links, joints) = sysid::urdf_updates(&robot, &ident);
//! sysid::writeback::update_urdf_file(robot.urdf_path.as_path(), &links, &joints, false)?;
//! # Ok::<(), sysid::Error>(())
//! ```
//!
//! ## Pipeline
//! 0. **Log and robot** ([`log`], [`hold`]): every `JointState` topic of a bag is read and
//!    merged by joint name, each with its own timestamps (`header.stamp`; the log time where a
//!    stamp is zero); URDF joints the log never names are held at their home position (links
//!    lumped into the parent, URDF inertia kept; a warning, an error with `strict`).
//! 1. **Data** ([`condition`]): the log's joints are matched to the URDF's by name, resampled
//!    on a uniform grid at the log's median rate (linear interpolation between each sample's
//!    own neighbours: a jittered 1 kHz log keeps its timing), split at gaps (a step over 5
//!    median steps: dropped samples are never bridged), low-pass
//!    filtered forward and backward (Butterworth, order 4, cut-off `min(rate/25, 20 Hz)` by
//!    default), differentiated by central differences (velocity and acceleration from the
//!    filtered positions; the effort gets the same filter), edges trimmed (3 cut-off periods),
//!    and sampled at 5× the cut-off for the regressor.
//! 2. **Model** ([`regressor`]): `τ = Y(q, q̇, q̈)·π`, per moving link the standard parameters
//!    `[m, hx, hy, hz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz]` (Pinocchio's order; `h = m·c`, inertia about
//!    the link frame origin), per joint viscous `q̇`, Coulomb `sign(q̇)` and armature `q̈`
//!    (optional offset). `Y` is built from MuJoCo's kinematics of the twin (`mj_jacBody`,
//!    `mj_jacDot`), not from a second model; tests check `Y·π` against MuJoCo's `mj_inverse` to
//!    1e-9. Rows of a joint slower than a small dead zone are left out (Coulomb friction is
//!    set-valued at rest), and so are those within half a cut-off period of a reversal of its
//!    velocity (the filter spreads the friction's jump there; `reversal_guard_periods`).
//! 3. **Estimation** ([`estimate`]): each joint's rows are compressed by QR as they come (memory
//!    and time linear in the log, only the columns a joint can touch), then stacked.
//!    Column-pivoted QR (faer) of the column-scaled problem gives the rank, the base
//!    parameters `β = π_b + K·π_d`, and which standard parameters are identifiable alone, only in
//!    combination, or not at all. Least squares is weighted per joint by the residual noise of
//!    a first unweighted pass; covariance `σ²(W_bᵀW_b)⁻¹` gives each base parameter's σ and
//!    relative σ. The excitation is diagnosed before the fit: joints that barely moved, joints
//!    always inside the dead zone, the condition number, and effort semantics (an effort with
//!    the wrong sign or a gain far from the URDF model's torques) give warnings, or errors with
//!    `strict`; a robot that stood still is always refused.
//! 4. **Physical consistency**: `min ‖W·π − τ‖²_w + Σ ((π_i − π_cad,i)/(s·scale_i))²` subject to
//!    each link's pseudo-inertia `J(π) ⪰ 0` (Wensing, Kim, Slotine 2017; for a body with
//!    fixed-joint links lumped into it, of the URDF link's own share, the one written back) and friction and
//!    armature `≥ 0`. The prior is weak (CAD trusted to ±100 % by default): directions the log
//!    can't see stay at the URDF's values, the others follow the data.
//! 5. **Write-back** ([`writeback`]): only the numbers of `<inertial>` and
//!    `<dynamics damping friction>` change, spliced at roxmltree's byte ranges; atomic write,
//!    `ROBOT.urdf.bak` kept. Armature goes to the report and, with [`mjcf`], to an MJCF model.
//! 6. **Report** ([`report`]): table and JSON; torque NRMSE before/after on the log and on a
//!    held-out log ([`validate`]).
//! 7. **Defaults from the data** ([`select`], `twin sysid` without `--cutoff-hz`/friction
//!    options): the cut-off and the friction model (sign or smooth Coulomb, torque offset,
//!    asymmetry) chosen by time-blocked cross-validation, the last 30 % held out to score the
//!    URDF before, the fit and `--compare` models on the same samples. What `<dynamics>` cannot
//!    hold goes to the URDF's `<twin_sysid>` block ([`extension`]).

//! ## Around identification
//! - [`excite`] (`twin excite`): designs the trajectory to log, a finite Fourier series per
//!   joint optimized for this regressor's condition number within the robot's limits.
//! - [`gap`] (`twin gap`): the reality gap, the logged efforts replayed on the twin open loop,
//!   before and after identification.
//! - [`friction`] (`twin sysid friction`) and [`noise`] (`twin calibrate noise`): friction
//!   curves from velocity sweeps, sensor noise from a still log.

//! ## Floating base (`Base::Floating`, `twin sysid --base floating`)
//! Without `--base floating` the base is fixed (bolted down or on a gantry) and the output
//! says "fixed base". With it, the robot is loaded with a free joint between the world and
//! the URDF's root link ([`RobotModel::from_urdf_floating`]), and the log must carry:
//! - **Base motion**: `nav_msgs/msg/Odometry` (`/odom`, `--odom-topic`), REP-105: pose of the
//!   base link in the world (odom) frame, twist in the base frame. The pose is resampled on the
//!   joint-state grid (quaternion signs made continuous), filtered with the joints' filter and
//!   normalised; the twist (filtered likewise, linear part rotated to the world) gives MuJoCo's
//!   free-joint velocity (linear in the world frame, angular in the base frame) and its
//!   derivative the acceleration. An odometry without twist (all zero) is differentiated from
//!   the pose instead, which amplifies its noise. Joint samples outside the odometry's span, or
//!   in its gaps, are not used. Refused, naming the bag's topics, when there is none.
//! - **Contact wrenches**: every `geometry_msgs/msg/WrenchStamped` topic whose
//!   `header.frame_id` is a link of the URDF (e.g. `/contacts/left_foot_link`, frame
//!   `left_foot_link`): force and torque expressed in that link's frame, the torque about the
//!   link frame's origin — the convention of `twin sim`'s contact wrench topics. Outside a
//!   topic's time span the wrench is zero. Each maps to generalized forces `J_bᵀ·w`
//!   (`mj_jacBody` at the link origin), so the rows read `τ + Jᵀ·w = Y·π + friction` for the
//!   joints and `Jᵀ·w = Y_base·π` for the free joint's 6 rows. No wrench topic is a warning,
//!   not an error: a robot in free flight is identifiable from momentum conservation.
//!
//! The 6 base rows (forces in N along the world axes, torques in N·m about the base origin in
//! base axes) join the joint rows; each row group (each joint, each base row) is weighted by
//! its own residual noise from the first, unweighted pass, so the base rows, whose noise comes
//! from the odometry's differentiated twist rather than torque sensors, neither dominate nor
//! vanish. The report gives the base rows' RMS residual before/after.
//! The synthetic check ([`synth::simulate_floating`], `tests/it/floating.rs`): the humanoid in free
//! fall (for its joints and base rows the same as floating in zero gravity), joints driven by
//! the exciting trajectory, known wrenches on both feet, odometry with 0.1 mm / 1e-4 rad pose
//! and 0.002 m/s, rad/s twist noise, starting URDF off by 20–40 %: held-out torque NRMSE
//! 0.3–6 % per joint, within 1.5 points of the true model's on the same data (the twist noise
//! enters the regressor: errors in variables), the base rows' residual at the true model's,
//! every link valid; on 20 of 20 seed triples (BENCHMARKS.md).
//!
//! ## Why an interior-point fit with faer instead of Clarabel's SDP cones
//! (Real data, issue 39: on the Franka Panda log of `data/panda_gaz2019`, the barrier method
//! as first written stopped with "barrier Hessian not positive definite" in 22 of 32 runs (8
//! cut-offs × 4 friction models): at large barrier weights the Hessian spreads the identifiable
//! directions and those only the prior holds over more than a double-precision Cholesky
//! resolves. Each Newton system is now Jacobi-scaled and, where Cholesky still fails, given a
//! ridge (10⁻¹⁴ … 10⁻² of the unit diagonal, reported above 10⁻⁸); a step no ridge allows ends
//! the fit at its last iterate, which is strictly feasible. All 32 runs fit; BENCHMARKS.md.)
//! Clarabel's PSD cones need BLAS and LAPACK, which a fresh machine lacks (no OpenBLAS, no
//! gfortran) and which the build may not download. The LMI problem above is convex with tiny
//! PSD blocks (4×4 per link), so twin solves it directly: a primal log-barrier interior-point
//! method, `t·f(π) − Σ log det J_l(π) − Σ log π_i`, Newton steps with faer's Cholesky on the
//! compressed problem (one `n × n` system, `n` = number of parameters, whatever the log's
//! length), `t` raised ×10 until the duality gap is below 1e-7 of the cost. Every iterate is
//! strictly physically valid, so MuJoCo loads the result without repairs. The log-Cholesky
//! parameterisation (Rucker & Wensing 2022) solved by Levenberg–Marquardt was tried first: it
//! is always valid too, but crawled (200+ iterations, still decreasing) when the optimum lies
//! on the boundary of the cone, as it does for links the log barely excites; the barrier method
//! reaches the optimum in 50–90 Newton steps. No BLAS, no LAPACK, no download: pure Rust.
//!
//! ## Limitations
//! - Floating base: the contact wrenches must be measured (force/torque sensors or a
//!   simulation); twin does not estimate them nor project onto the contact null space. Noise in
//!   the odometry enters the regressor (errors in variables, biasing estimates slightly toward
//!   zero); no total-least-squares correction is made. Joint-limit and unmeasured contact
//!   forces are not modelled. The training NRMSE of a joint normalises by `τ + Jᵀ·w` (the
//!   held-out NRMSE by the measured `τ`). CSV logs can't carry base motion.
//! - Logs are ROS 2 bags (`sensor_msgs/msg/JointState`, plus `nav_msgs/msg/Odometry` and
//!   `geometry_msgs/msg/WrenchStamped` for a floating base) or CSV ([`log`]).
//! - Joints are revolute or prismatic; a fixed-base robot's joints the log lacks are held at
//!   home ([`hold`]; a floating base needs every joint in the log). Contacts, joint-limit forces
//!   and transmissions other than a direct drive are not modelled: log the robot in free space,
//!   inside its joint ranges, with joint-side torques (or `--effort-scale` to them).
//! - The friction model is chosen for all joints at once (the cross-validation scores each
//!   joint, but one model's columns serve every joint); Stribeck terms are not among the
//!   candidates (`twin sysid friction` fits them from constant-velocity sweeps). The fit's
//!   velocity shift of a sigmoid is its first-order term (`asymmetry`), not the shift itself.
//! - Held-out scoring and the cross-validation are for fixed-base robots; a floating base is
//!   validated with `--validate` on a log of its own.
//! - Links joined by fixed joints are identified as the MuJoCo bodies they are (loaded with
//!   `fusestatic="false"`): a welded link's inertia is only seen together with its parent's,
//!   and its share stays at the URDF's value.
//! - The validation NRMSE leaves out the samples inside the velocity dead zone and the reversal
//!   guard, where Coulomb friction is undetermined (stiction) or smeared by the filter and no
//!   friction model predicts the torque.
//! - Regressor samples after decimation are correlated (5× the cut-off), so σ is optimistic by
//!   about √(5/2).

#![forbid(unsafe_code)]

pub mod actuator;
pub mod allan;
pub mod condition;
pub mod error;
pub mod estimate;
pub mod excite;
pub mod extension;
pub mod friction;
pub mod gap;
pub mod hold;
pub mod identify;
pub mod log;
pub mod mjcf;
pub mod model;
pub mod noise;
pub mod number;
/// The SVG plots of the reports: twin-core's one plotting helper.
pub use twin_core::plot;
pub mod regressor;
pub mod report;
pub mod select;
pub mod signal;
pub mod synth;
pub mod writeback;

pub use error::{Error, Result};
pub use identify::{Base, Identification, SysidOptions, identify, urdf_updates, validate};
pub use log::JointLog;
pub use model::RobotModel;
pub use report::Report;
