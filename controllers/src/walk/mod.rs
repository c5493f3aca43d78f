//! Model-based walking: a [`Walker`] controller and [`GaitMetrics`].
//!
//! The pipeline, each control tick:
//! 1. **State**: forward kinematics of the observed `qpos` (the model's own tree, [`kin`]) gives
//!    the centre of mass; its velocity is a filtered difference; the divergent component of
//!    motion (DCM, capture point) is `ξ = c + ċ/ω`, `ω = √(g/h)`. Torso tilt and rate come from
//!    the IMU (framequat + gyro), else from the floating base.
//! 2. **Footsteps** ([`plan`]): from the velocity command `(vx, vy, yaw_rate)`, each step lands
//!    the swing foot half a step width beside a centre path advanced by the command. During a
//!    step the landing spot moves by the DCM error predicted at touchdown beyond what the stance
//!    ankle takes back, and the touchdown comes earlier when the spot alone can't absorb it
//!    (Khadiv et al. 2016). Around that, an outer loop on position: each step, when planned, is
//!    moved toward where the command's time integral (since walking started) will be at its
//!    touchdown (`command_hold_gain`), so that the distance and angle walked follow the command
//!    and not the steps counted. With a zero command the walker stands, and starts stepping in place
//!    when its DCM nears the edge of the feet's support (`recovery_margin`): quick steps that land
//!    under the capture point predicted at touchdown.
//! 3. **CoM reference**: standing, LIPM ZMP preview control (Kajita, [`preview`]) over
//!    `preview_horizon`; walking, the DCM reference of the step in closed form (Englsberger et
//!    al. 2015, [`plan::Step::dcm`]), anchored at the stance foot's ZMP point (`zmp_inward`
//!    inside its centre, so the DCM runs farther inside the sole and a kick toward the stance
//!    side leaves it later) and the planned end-of-step DCM, moved with the corrected landing
//!    spot and re-anchored at each touchdown; the CoM reference follows it by `ċ = ω(ξ_ref − c)`.
//! 4. **DCM feedback**: the commanded ZMP is `p_ref + (1 + k/ω)(ξ − ξ_ref)`, realised by the
//!    contact forces of the feed-forward torque; the CoM command is offset by
//!    `−dcm_com_gain·(ξ − ξ_ref)`.
//! 5. **Leg IK**: the pelvis is placed to put the CoM at its command (offset from the previous
//!    tick's commanded configuration), tilted against the IMU's tilt and rate; each foot's
//!    target (planted or on its swing trajectory) goes through damped-least-squares IK.
//! 6. **Torques**: joint PD (gains by the project's PD rule, `kp = effort / saturation error`,
//!    softened on a swinging leg so that `√(kp/I)·dt` stays small) plus the static torque that
//!    holds every subtree against gravity and the planned contact forces.
//!
//! Steps 1–6 are the solve; with `plan_every_ticks` > 1 it runs on one physics step in that
//! many, and the joint PD on every one, toward the last solve's targets moved by the tilt
//! feedback since (the IMU read on every step, through a linear map of the legs' IK).
//!
//! Legs, feet (the lowest collision bodies), pelvis (the free joint's body) and IMU are found in
//! the model; [`kin::BodyNames`] overrides them.
//!
//! Any biped: the gait options come from the robot's proportions ([`derive`], applied by
//! `twin_scenario::Scenario::fit_walk` wherever twin builds the walker); the torso-tilt
//! rate loop is bounded by the inertia it turns within a physics step
//! ([`Walker::stable_tilt_rate_gains`]); robots it can't drive are refused with what to change
//! (no two six-joint legs with feet, servos without a force limit, actuators too weak to hold the
//! crouch, steps out of reach). What that gives on example-robot-data 6.0.0's humanoids, no
//! robot-specific option (`twin sim ROBOT --controller walk [--vx 0.25] --duration D`, release
//! build, 2-ms steps):
//!
//! | robot | mass | stands 10 s, pd-hold | stands 10 s, walker | walks (`--vx 0.25`, 30 s) | speed | falls | turns 90° in place |
//! |---|---|---|---|---|---|---|---|
//! | shipped humanoid (`models/humanoid.urdf`) | 35.7 kg | yes | yes | 8.64 m, drift 0.04 m | 0.29 m/s | no | 94.0° (92.9° before `command_hold_gain`) |
//! | Unitree G1 (`g1_29dof_rev_1_0.urdf`) | 33.3 kg | yes | yes | 6.64 m, drift 0.10 m, heading 0.3° (`--vx` 0.2: 5.27 m; 0.3: 7.95 m) | 0.22 m/s | no | 92.6° (94.9°) |
//! | Romeo (`romeo.urdf`) | 40.5 kg | yes | yes | 8.56 m, drift 0.08 m, heading −1.2° (`--vx` 0.2: 7.05 m; 0.3: 9.77 m) | 0.29 m/s | no | 92.4° (92.3°) |
//! | Talos (`talos_full_v2.urdf`, its position servos) | 93.3 kg | yes | yes | 7.72 m, drift 0.29 m, heading 4.8° (`--vx` 0.2: 7.93 m, drift 0.61 m; 0.3: falls at 3.7 s) | 0.26 m/s | no | 97.6° |
//! | Talos, `twin convert --actuators motor` | 93.3 kg | – | yes (10 s, upright within 0.4°) | 7.29 m, drift 0.04 m, heading 2.0° (`--vx` 0.2: 7.65 m; 0.3: 8.74 m) | 0.24 m/s | no | 97.1° (98.8°) |
//!
//! (Turning: `[walk] commands = [[1.0, 0.0, 0.0, 0.3], [6.236, 0.0, 0.0, 0.0]]`.) The G1 walks,
//! turns and is steered over `/cmd_vel` since the damping of its hip and waist loops is capped
//! on its light pelvis ([`Walker::cap_pelvis_damping`]): before, in single support its hip
//! pitch, hip roll and waist torques flipped sign on most physics steps at the hips' effort
//! limits (none at a 1-ms timestep), it fell turning and at 0.2 and 0.3 m/s. Randomized
//! (`scenarios/walk_g1.toml`, default spec, 100 episodes) it passes 28 % (BENCHMARKS.md): every
//! episode with a push under 0.15 m/s, none above 0.3 m/s. Steered by the README's `/cmd_vel`
//! node (1 m forward, 90° in place, 0.5 m to the left) it covers 1.03 m, 95.3° and 0.46 m;
//! Talos (motors) 1.07 m, 97.3° and 0.52 m; the shipped humanoid 1.09 m, 93.4° and 0.55 m;
//! Romeo 1.04 m, 91.9° and 0.53 m. Without the outer loop (`command_hold_gain` 0) the
//! G1 stepped 0.39 m of 0.5 sideways: each step's landing correction, against a DCM that
//! lagged its reference sideways and back, moved the trailing foot 1.9 cm and the leading one
//! 0.8 cm back, and the next step counted from there (BENCHMARKS.md, "Walker velocity
//! tracking"). Romeo and Talos (motors) walk since two rules derived from the robot and one
//! measured on its first step: the crouch keeps the knees bent [`derive::MIN_KNEE_BEND_RAD`]
//! in the gait's extreme poses (at the highest crouch that reached their steps their knees
//! came within 0.27 and 0.12 rad of straight; Romeo fell at 3.3 s, Talos at 4.7 s); legs
//! loaded over [`derive::SAG_FREE_LOAD`] of their effort in the crouch lift the swing foot
//! higher (Romeo only); and a first swing that strays from its trajectory by over
//! `swing_miss_fraction` of the sole switches the swing legs' damping to the error from their
//! targets' velocity (Talos 0.63, Romeo 0.78; the shipped humanoid 0.39 and the G1 0.07 do
//! not switch). At 0.3 m/s Romeo needs all three (each left out, it falls at 3.5, 5.4 and
//! 3.4 s); Talos walks with either the crouch or the switch, and with the switch at the pace
//! it is asked (0.24 against 0.31 m/s at `--vx 0.25`). BENCHMARKS.md, "Romeo walking" and
//! "Talos walks straight". What was known of those falls before:
//! - Romeo: the swing foot touches the ground at two thirds of its swing (0.2 m short, 420 N
//!   backward on the toe) while the stance foot turns on its sole (−2° to −15° in 0.5 s,
//!   hip yaw limited to 9.2 N·m); torsional friction on the soles (`condim` 6) does not change
//!   the fall (3.28 s against 3.32 s), a higher `foot_clearance` (0.1 m) delays it to 4.8 s.
//! - Talos (motors): its IMU site is on `imu_link`, half a turn from the pelvis; until the
//!   walker composed that turn ([`kin::Imu::site_rot`]) it read the torso upside down (roll
//!   ±π), its first torques flipped sign at their limits on every physics step, the feet left
//!   the ground at 0.04 s and landed 3–6 cm off, it stood leaning 6–11°, walked 0.17 m
//!   backward and fell at 3.6 s, and fell turning at 4.1 s. Read right, it stands upright and
//!   turns 90° in place; walking, it stepped 0.5 m forward by 3.2 s, then the stance foot
//!   turned on the ground, a step landed beside the stance foot and the next ones went
//!   backward. The cause was its swing leg: its hip pitch moves 2.8 kg·m², on which the gain
//!   rule's loop is slow (`√(kp/I)` 24 rad/s), and damped on the joint velocity it lags a
//!   target moving at `v` by `kd/kp · v` (84 ms): in mid swing the hip lagged 0.23 rad (the
//!   foot 18 cm behind its trajectory, the damping holding the hip at its 160 N·m limit
//!   against the motion), then the foot swung through and landed 7 cm past its aim on the
//!   first step (41 % of its sole) and 11 cm on the second, the DCM fell behind, the
//!   landing corrections stepped backward and it fell (4.7 s). Damped on the targets'
//!   velocity from the start, the G1 walked as far but held fewer pushes (BENCHMARKS.md
//!   "Talos walks straight"), hence the switch on the first swing's miss. (Placing the swing
//!   foot from the commanded pelvis, which also walked Talos, only offset the lag by the
//!   pelvis's own lag, and felled the G1.)
//! - Romeo, further: in its second step the trailing ankle sits at its −0.52 rad limit from
//!   2.11 to 2.27 s (knee 1.0 rad, hip −0.25 rad: flat would need −0.79) and the 38 N·m knee
//!   and 47 N·m hip pitch saturate, so the swing foot lags its trajectory pitched 16–20°; its
//!   toe touches down 0.22 m short. Lifting the swing target by the tipped sole's dip (from
//!   the IK's clamped solution) gave 3.46 s; from the measured foot, 3.96 s but the G1 then
//!   fell at 5.9 s; a slower step (`step_period` 0.8–0.9 at 0.22 m/s) 4.6 s. The stance
//!   foot's turn is not its friction: sliding friction 2.0 (3.30 s), `impratio` 10 (3.21 s),
//!   torsional friction 0.05 m with `condim` 6 (3.23 s; it still turns −2° to −7°).

pub mod contact;
pub mod derive;
pub mod hip;
pub mod kin;
pub mod metrics;
pub mod plan;
pub mod preview;
pub mod steer;

pub use derive::Proportions;
pub use kin::{BodyNames, Side};
pub use metrics::{GaitMetrics, GaitSummary, GaitTargets, SegmentTracking};
pub use plan::Command;

use contact::{ContactSensing, TOUCHDOWN_PROFILE_END, TOUCHDOWN_SEARCH_MPS};
use kin::{Body, Frames, LegIk, Tree};
use nalgebra::{UnitQuaternion, Vector2, Vector3};
use plan::{Foothold, Gait, Schedule, Step, dcm_error_ahead, rotation, swing_profile, wrap};
use preview::{PreviewAxis, PreviewGains};
use std::sync::Arc;
use twin_core::control::{Actuation, Controller, Observation, PdHold, PdHoldOptions, nominal_pose};
use twin_core::error::{Error, Result};
use twin_core::mj::{JointType, Model, ObjType};

/// Time constant of the filter on the joint targets' rate that a swinging leg's damping
/// tracks (`swing_miss_fraction`), s.
pub const SWING_VELOCITY_FILTER_SECS: f64 = 0.01;

/// A landed sole within this of the starting soles' height stands on the same (flat) ground, m.
pub const GROUND_DEADBAND_M: f64 = 0.004;

/// Time constant of the pelvis reference following the ground under the feet, s.
pub const GROUND_FOLLOW_SECS: f64 = 0.3;

/// The ground's slope is estimated from the planted feet only when they are at least this far
/// apart along the heading, m.
pub const GROUND_SLOPE_MIN_BASE_M: f64 = 0.05;

/// Part of a step's swing within which the stance foot's ground is read, once, at the first
/// solve where its sole is level and at rest (`follow_ground`): in mid stance the weight is on
/// a foot that lies flat, after a late or early landing has settled and before the heel lifts
/// (read on every solve, a heel lifting late in the stance read as rising ground, and the
/// walker climbed it).
pub const GROUND_READ_PHASE: [f64; 2] = [0.3, 0.7];

/// A stance sole moving faster than this (up or down) gives no ground read, m/s: it is not
/// resting on the ground (still landing, bouncing, or lifted by a body falling onto the other
/// foot).
pub const GROUND_READ_MAX_SPEED_MPS: f64 = 0.05;

/// How long a stance sole must have moved no faster than [`GROUND_READ_MAX_SPEED_MPS`] before
/// its height is read as the ground, s (a foot bouncing off an edge is still at its apex).
pub const GROUND_READ_STILL_SECS: f64 = 0.03;

/// A stance sole tilted more than this from level gives no ground read (`follow_ground`), rad:
/// it stands on an edge, a heel or a toe (a 5° ramp tilts it by 0.09).
pub const GROUND_READ_MAX_TILT_RAD: f64 = 0.2;

/// Two steps' slopes are one slope ([`WalkOptions::ground_slope_gain`]) when they differ by at
/// most this part of the steeper: on a ramp the footholds' rises vary by a few millimetres per
/// step; a single step up gives one rise and then none.
pub const GROUND_SLOPE_AGREEMENT: f64 = 0.5;

/// The ground under the footholds is rising ([`WalkOptions::step_down_reach`]) when the stance
/// foot's mid-stance read is above that foot's previous one (two reads back) by more than this,
/// m: the same foot's two reads, so that a foot's own read bias cancels; as the flat ground's
/// [`GROUND_DEADBAND_M`].
pub const GROUND_RISE_M: f64 = GROUND_DEADBAND_M;

/// Steepest ground slope the walker carries a landing height on by, rise per metre (tan 19°).
pub const MAX_GROUND_SLOPE: f64 = 0.35;

/// The soles' pitch ([`WalkOptions::ground_pitch_gain`]) is re-estimated from the planted feet
/// only when they are at least this far apart along the heading, m (as the footholds' slope,
/// [`GROUND_SLOPE_MIN_BASE_M`]); closer, it holds its last value. (It dropped to level there
/// before: after a push on a 5° ramp, stepping nearly in place, the pitch alternated between
/// 0 and 8–14° step by step.) A longer base (0.1 m) rejects more of the reads' error, but steps
/// up a 5° ramp are often shorter: the pitch stayed level from the flat, the climb slowed and
/// the nominal `walk_slope.toml` run fell short (6.09 m of 6.5).
pub const GROUND_PITCH_MIN_BASE_M: f64 = GROUND_SLOPE_MIN_BASE_M;

/// Time constant of the soles' pitch following its estimate from the planted feet, s (as the
/// pelvis follows the ground, [`GROUND_FOLLOW_SECS`]): a new estimate at each touchdown turns
/// the loaded stance sole gradually instead of in one solve (a jump of several degrees under
/// the body's weight moves the centre of pressure to a heel or a toe at once), and a single
/// step's error (the 8–14° above, over a 5–9-cm base) moves it by a fraction.
pub const GROUND_PITCH_FOLLOW_SECS: f64 = GROUND_FOLLOW_SECS;

/// Armature (reflected rotor inertia, kg·m²) the walker's models get on every joint
/// ([`twin_core::convert::ConvertOptions::armature`]) unless a scenario sets another: without it the
/// light distal links (feet) of a URDF make stiff explicit PD unstable (`kd·dt/I` too large),
/// and the shipped humanoid falls within 2 s; real actuators of this class have 0.007–0.025.
pub const WALK_ARMATURE: f64 = 0.01;

/// Options of the [`Walker`]. Every field has a default; scenario files set them by name.
#[derive(Debug, Clone, PartialEq, serde::Deserialize, serde::Serialize, smart_default::SmartDefault)]
#[serde(default, deny_unknown_fields)]
pub struct WalkOptions {
    /// Forward velocity command, m/s (default: 0.0: stand and balance).
    #[default(0.0)]
    pub vx: f64,
    /// Leftward velocity command, m/s (default: 0.0).
    #[default(0.0)]
    pub vy: f64,
    /// Yaw-rate command, rad/s (default: 0.0).
    #[default(0.0)]
    pub yaw_rate: f64,
    /// A schedule of velocity commands, `[t_secs, vx, vy, yaw_rate]` each (s, m/s, m/s,
    /// rad/s): from each time on, the walker steers toward that command ([`steer`]) at the
    /// acceleration limits below; before the first time it keeps `vx`, `vy`, `yaw_rate`
    /// (default: empty: the constant command). Times increase; each command within what the
    /// steps allow (`max_step_length / step_period`, …).
    pub commands: Vec<[f64; 4]>,
    /// Largest change per second of the forward and lateral command when it changes (a
    /// schedule's entry or a live `/cmd_vel`), m/s²: the command is taken once per step and
    /// changes by at most this × `step_period` from one step to the next (default: 0.5: at
    /// 0.6-s steps, 0.3 m/s per step).
    #[default(0.5)]
    pub max_accel_mps2: f64,
    /// Largest change per second of the yaw-rate command, rad/s², taken per step as above
    /// (default: 1.0).
    #[default(1.0)]
    pub max_yaw_accel_radps2: f64,
    /// Step duration (double + single support), s (default: 0.6).
    #[default(0.6)]
    pub step_period: f64,
    /// Fraction of a step in double support (default: 0.2).
    #[default(0.2)]
    pub double_support: f64,
    /// Lateral distance between the soles' centres, m (default: 0.18, the hip spacing).
    #[default(0.18)]
    pub step_width: f64,
    /// How far inside the stance sole's centre (toward the other foot) walking plans the ZMP
    /// in single support, m (default: 0.0).
    #[default(0.0)]
    pub zmp_inward: f64,
    /// Straight walking (no `vy`, no `yaw_rate`) holds the line it started on: each planned
    /// step's centre moves back toward that line by this fraction of the planned centre's
    /// offset from it (default: 0.0, off). It acts only through the footstep plan, so each
    /// step's DCM reference is built from the corrected plan (landing corrections after kicks
    /// otherwise leave the whole walk offset sideways).
    #[default(0.0)]
    pub line_hold_gain: f64,
    /// Largest sideways correction of one step toward the line, m (default: 0.03).
    #[default(0.03)]
    pub line_hold_step: f64,
    /// Straight walking (no `vy`, no `yaw_rate`) holds the commanded pace in step length: after
    /// each walking step (not a recovery step) the shortfall of its advance (the landed foot's
    /// sole centre ahead of the stance foot's, along the stance foot's heading) against the
    /// command's (`vx × step_period`) is added, times this gain, to a length that every planned
    /// step's advance then gets, within ±`stride_hold_step` (default: 0.0, off). An integral
    /// on the step length: on ground that shortens steps, or against landing corrections that
    /// keep pulling steps back, the distance walked follows the command; a single long or
    /// short step (a kick) moves it by the gain times that step's error only. On rough ground
    /// (±1 cm, `walk_rough.toml`) the shipped humanoid's steps came out 0.120 m against 0.129 m
    /// on flat ground for 0.133 m asked; measurements in BENCHMARKS.md, "Rough ground: the pace".
    #[default(0.0)]
    pub stride_hold_gain: f64,
    /// Largest length `stride_hold_gain` adds to (or takes from) a step, m (default: 0.03).
    #[default(0.03)]
    pub stride_hold_step: f64,
    /// Centre-of-mass height while walking, m, above the floor (z = 0), or with
    /// [`WalkOptions::follow_ground`] above the soles at the start (default: 0.62: knees bent,
    /// away from the stretched-leg singularity of the shipped humanoid, whose standing CoM is at
    /// 0.68 m).
    #[default(0.62)]
    pub com_height: f64,
    /// Swing-foot clearance at mid-swing, m (default: 0.05).
    #[default(0.05)]
    pub foot_clearance: f64,
    /// Longest forward advance per step, m (default: 0.2); a command needing more is refused.
    #[default(0.2)]
    pub max_step_length: f64,
    /// Longest sideways advance per step, m (default: 0.1).
    #[default(0.1)]
    pub max_step_lateral: f64,
    /// Largest yaw change per step, rad (default: 0.3).
    #[default(0.3)]
    pub max_step_yaw: f64,
    /// Time from the start to crouch to `com_height` before stepping, s (default: 1.0).
    #[default(1.0)]
    pub settle_secs: f64,
    /// Double support of the first step from standing, s (default: 0.3).
    #[default(0.3)]
    pub start_double_support: f64,
    /// Preview horizon of the ZMP preview control, s (default: 1.6).
    #[default(1.6)]
    pub preview_horizon: f64,
    /// Preview control's ZMP-error weight (default: 1.0).
    #[default(1.0)]
    pub preview_qe: f64,
    /// Preview control's jerk weight (default: 1e-6).
    #[default(1e-6)]
    pub preview_r: f64,
    /// DCM feedback gain `k` on the commanded ZMP, 1/s (default: 2.0).
    #[default(2.0)]
    pub dcm_zmp_gain: f64,
    /// DCM feedback on the CoM command, m per m of DCM error (default: 0.3).
    #[default(0.3)]
    pub dcm_com_gain: f64,
    /// Landing-spot correction per metre of predicted DCM error at touchdown (default: 1.0).
    #[default(1.0)]
    pub step_adjust_gain: f64,
    /// Largest landing-spot correction, m (default: 0.3).
    #[default(0.3)]
    pub max_step_adjust: f64,
    /// Part of the stance sole the landing-spot correction counts on the ankles to use: the
    /// DCM error predicted at touchdown is the one left after ZMP feedback within this part of
    /// the sole (default: 1.0; 0: the error grows as `e^(ω·t)`, no ankle help).
    #[default(1.0)]
    pub step_adjust_ankle: f64,
    /// Shortest single support a walking step is cut to when its landing spot alone can't
    /// absorb the DCM error (an earlier touchdown lets the error grow less), s (default: 0.25,
    /// as `stand.toml`'s recovery steps).
    #[default(0.25)]
    pub min_single_support_secs: f64,
    /// Single support of a recovery step (stepping after a push at a zero command), s
    /// (default: 0.35: short, since the DCM diverges while the foot swings).
    #[default(0.35)]
    pub recovery_swing_secs: f64,
    /// Double support before a recovery step, s (default: 0.05).
    #[default(0.05)]
    pub recovery_double_support_secs: f64,
    /// A standing walker steps when its DCM comes closer than this to the edge of the feet's
    /// support region (or leaves it), m; inside, the ankles and hips hold it (default: 0.02).
    #[default(0.02)]
    pub recovery_margin: f64,
    /// In double support, the part of the commanded ZMP that the weight split between the feet
    /// cannot reach (fore-aft) is given by the ankles, moving each foot's planned force within
    /// its sole (default: true: it holds fore-aft pushes in place). A controller that moves
    /// the arms while the legs balance (`grasp`) turns it off: the reaching arm shifts the
    /// commanded ZMP forward and the ankles then tip the torso into the table.
    #[default(true)]
    pub double_support_ankle: bool,
    /// Torso tilt feedback: pelvis counter-rotation per radian of tilt (default: 0.5).
    #[default(0.5)]
    pub tilt_gain: f64,
    /// Torso rate feedback: pelvis counter-rotation per rad/s of tilt rate, s (default: 0.05).
    #[default(0.05)]
    pub tilt_rate_gain: f64,
    /// PD saturation error of the leg joints, rad (`kp = effort / this`) (default: 0.1).
    #[default(0.1)]
    pub leg_saturation_error: f64,
    /// PD saturation error of the other joints, rad (default: 0.25, as `pd-hold`).
    #[default(0.25)]
    pub saturation_error: f64,
    /// PD damping ratio (default: 1.0).
    #[default(1.0)]
    pub damping_ratio: f64,
    /// Bound on `√(kp/I)·dt` of a swinging leg's joints, `I` the inertia they move (default:
    /// 0.3).
    #[default(0.3)]
    pub swing_stiffness: f64,
    /// Damped-least-squares iterations of the leg IK per tick, warm-started from the last
    /// tick's solution (default: 1: the targets move by millimetres per tick and the residual
    /// is taken up at the next one; measurements in BENCHMARKS.md, "Walker option choices").
    #[default(1)]
    pub ik_iterations: usize,
    /// Body and sensor names overriding what the walker finds.
    #[default(BodyNames::default())]
    pub bodies: BodyNames,
    /// Part of a recovery step's swing by which the foot is over its landing spot (it comes
    /// down there for the rest); the spot follows the predicted capture point for the first
    /// 2/3 of it (default: 0.6). Spread over the whole swing, the foot's sideways move comes
    /// in its middle, fast enough to saturate the hip roll, and sideways steps land short
    /// (measurements in BENCHMARKS.md, "Walker option choices").
    #[default(0.6)]
    pub recovery_reach_fraction: f64,
    /// Walking corrects the swing foot's landing spot (and touchdown time) for the measured
    /// DCM until this part of the swing has passed (default: 0.7; later, the foot is close to
    /// the ground and a moved spot drags it sideways).
    #[default(0.7)]
    pub step_adjust_until: f64,
    /// A swinging leg's IK target is placed from the measured pelvis pose instead of the
    /// commanded one, so the foot follows its trajectory in the world (default: true). From
    /// the commanded pelvis, the stance leg's give (its joints' PD error, a stance foot
    /// turning on its contacts) moves the landing spot with the body: a body tilted by a push
    /// carries the swing foot into the ground short of its spot, and on a robot with compliant
    /// legs every landing lands off by the stance leg's error (measurements in BENCHMARKS.md,
    /// "Walker option choices"). `stand.toml`'s recovery steps keep `false`.
    #[default(true)]
    pub swing_from_measured_pelvis: bool,
    /// When the swing foot of a walk's first step (from standing) strays from its trajectory,
    /// along the swing (behind or ahead), by more than this fraction of its sole's length, the
    /// swing leg does not follow its targets: from then on the swinging legs' joint damping
    /// acts on the error to their targets' velocity (the IK targets' rate) instead of on the
    /// joint velocity (default: 0.5; 0: from the start; `inf`: never). Damping on the joint
    /// velocity makes a joint lag a target moving at `v` by `kd/kp · v`: Talos's swing hip
    /// pitch (2.8 kg·m², `√(kp/I)` 24 rad/s, 84 ms) puts its first swing foot 11 cm behind
    /// (63 % of its sole), then 7 cm past its aim, and it falls; Romeo's strays 78 %. The
    /// shipped humanoid's strays 39 % on `walk.toml` (its tuned gait walks with it), the G1's
    /// 7 %: both keep the damping as tuned (tracking the targets' velocity, the G1 held fewer
    /// pushes). Only the first step is measured: undisturbed, the same on every walk (later
    /// steps stray after a push too). Measurements in BENCHMARKS.md, "Talos walks straight".
    #[default(0.5)]
    pub swing_miss_fraction: f64,
    /// Hip strategy ([`hip`]): the part of the commanded ZMP beyond the feet's support that
    /// rotating the upper body about the hips gives, by moving the CMP beyond the ZMP (default:
    /// 0.0, off; 1: all of it, within `hip_max_lean_rad`).
    #[default(0.0)]
    pub hip_gain: f64,
    /// Largest lean of the upper body the hip strategy commands (roll, pitch), rad (default:
    /// [0.15, 0.4]: the hips' roll, which also spreads the legs, has less range to spare).
    #[default([0.15, 0.4])]
    pub hip_max_lean_rad: [f64; 2],
    /// Time constant of the upper body's return upright once the feet hold the ZMP again, s
    /// (default: 0.4: the return moves the CMP back, which the feet then take).
    #[default(0.4)]
    pub hip_return_secs: f64,
    /// The walker solves (state, step planning, DCM, IK, feed-forward) on one physics step in
    /// this many, as a robot's balance layer runs below its joint servo rate; the joint PD
    /// runs on every step toward the last solve's targets, with its feed-forward and gains,
    /// the legs' targets moved by the torso-tilt feedback on every step (its pelvis
    /// counter-rotation through a linear map of the leg IK, [`LegIk::base_motion_map`])
    /// (default: 1, every step; at 2 the walker costs a third less: measurements in
    /// BENCHMARKS.md, "Walker option choices").
    #[default(1)]
    pub plan_every_ticks: u64,
    /// Blind walking on uneven ground: each landed sole's height is the ground under that foot
    /// (unless within [`GROUND_DEADBAND_M`] of the start, flat ground), a swinging foot goes
    /// from its own ground to the stance foot's, the pelvis reference rises and sinks with
    /// the mean ground under the feet, and `com_height` counts from the soles' height at the
    /// start (a start on raised ground) instead of from z = 0 (default: false: a foot that lands tilted after a kick
    /// reads as uneven ground; on flat ground with the default spec's kicks, 1 of 6 randomized
    /// `walk.toml` episodes passed with it against 6 of 6 without).
    #[default(false)]
    pub follow_ground: bool,
    /// Fraction of the ground's slope between the planted feet (along the heading) that the
    /// soles are pitched by, so that ankles follow a slope instead of standing on a heel or a
    /// toe (default: 0.0, off: on rough ground the two feet's heights are no slope).
    #[default(0.0)]
    pub ground_pitch_gain: f64,
    /// How far below the stance foot's ground a swinging foot reaches at touchdown, m: steps
    /// down a slope or a step land instead of ending in the air (default: 0.0). Not while the
    /// ground under the footholds is rising (`stance_ground_read`'s reads,
    /// [`GROUND_RISE_M`]): there the reach lands every step into the up slope, a leg pushed
    /// down at touchdown brakes the climb, and the walker climbed a 5° ramp at 0.22 m/s against
    /// 0.38 commanded, and fell under kicks it survives on the flat.
    #[default(0.0)]
    pub step_down_reach: f64,
    /// Fraction of the ground's slope along the path by which a swinging foot's landing height
    /// is carried on past the stance foot's ground (`follow_ground`): the ground ahead is taken
    /// to rise or fall as it did under the last footholds, when the last two steps rose (or
    /// fell) alike ([`GROUND_SLOPE_AGREEMENT`]), the footholds' heights being the mid-stance reads
    /// of `stance_ground_read` (without it there are none, and no slope); a single step up or
    /// down, or rough ground, is no slope, and the landing height is then the stance foot's
    /// ground (default: 0.0, off).
    /// Blind on a ramp without it, every step lands a step's rise early going up (the foot
    /// pushed into the ground) and late going down.
    #[default(0.0)]
    pub ground_slope_gain: f64,
    /// With `follow_ground`, the ground under the stance foot is read again in mid stance
    /// ([`GROUND_READ_PHASE`]), once its sole is level and at rest, replacing the height its
    /// sole had at the planned touchdown (default: false: the touchdown's height alone). The
    /// soft swing leg lags its trajectory, so a foot is often a centimetre in the air at the
    /// planned touchdown, and a foot that lands late on a down ramp reads the ground too high:
    /// the next swing then aims higher still and the walker ran down the ramp; read in mid
    /// stance the estimate is the loaded sole's. On `walk_steps.toml` (a 3-cm step) it turns a
    /// nominal pass into a fall: there a foot lands on the step's edge either way, and whether
    /// the walker survives it depends on where the feet happen to land.
    #[default(false)]
    pub stance_ground_read: bool,
    /// With `follow_ground`, a foot in the air at its planned touchdown gives no ground read
    /// then: its ground is the one its swing aimed at (the stance foot's, carried along the
    /// footholds' slope by `ground_slope_gain`) until it is on the ground and its sole has
    /// stopped, and its height there is read (default: false: the sole's height at the planned
    /// touchdown, wherever the foot is). The soft swing leg lags its trajectory, more so after a
    /// kick: a foot still in the air read as raised ground, the next swing aimed at it and
    /// landed higher in the air still (on flat ground, reads of 1–3 cm climbing step by step
    /// before falls), and the pelvis rose.
    /// In the air: on a robot with foot sensors (a `touch` or `force` sensor on the foot,
    /// [`contact`]; a scenario's `contact_sensors`), its sensors read less than
    /// [`contact::TOUCHDOWN_LOAD_FRACTION`] of the weight, and it is on the ground once they
    /// read more; without them, its sole is still coming down (faster than
    /// [`GROUND_READ_MAX_SPEED_MPS`]), which misses a foot that has stopped in the air at a
    /// target above the ground (past the crest of a slope). Randomized on `walk_slope.toml`
    /// (100 episodes, seeds 0/1/2): by the sole's motion 68/69/72 passed against 60/67/64
    /// without the option (with `step_down_reach`); with foot sensors and no reach 86/73/80,
    /// against 73/72/75 by the sole's motion, and 90/88 (seeds 0/1) with the true ground's
    /// height at every read (BENCHMARKS.md). Without sensors, a sole that is still, blocked
    /// early on higher ground (an up ramp), is read at the touchdown: waiting for it to rest
    /// level for [`GROUND_READ_STILL_SECS`] lost the up ramp (38/100).
    #[default(false)]
    pub landing_read_at_rest: bool,
    /// Walking, each step's advance counts from where the previous step was aimed (its
    /// corrected landing spot) rather than where the foot landed, by this fraction of the
    /// fore-aft gap, at most `max_step_adjust` (default: 0.0, from where it landed; 1: from the
    /// aim). A swing foot that lands past its spot (at 0.35-s steps the shipped humanoid's land
    /// 5.5 cm long) otherwise lengthens every step by that much: 0.42 m/s for 0.3 commanded.
    #[default(0.0)]
    pub progress_hold_gain: f64,
    /// Steered walking (a `/cmd_vel` target or a schedule's entry, [`steer`]): each step's
    /// landing is moved toward where the steering target, integrated over time, puts the feet's
    /// centre path when that step lands, by this fraction of the gap (position; heading against
    /// the stance foot's measured yaw), the step staying within `max_step_length`,
    /// `max_step_lateral` and `max_step_yaw`; the step that brings the feet together puts their
    /// midpoint there (default: 0.35; 0: off; 1: all of the gap). The integral runs from the
    /// feet's centre and heading while the walker walks (while it stands, it restarts there), so
    /// the distance and angle walked follow the command's time integral, not the steps the plan
    /// counted: the landing corrections against a DCM that lags its reference otherwise pull
    /// each step back and the loss adds up (the G1 stepping left at 0.1 m/s went 0.41 m of 0.5;
    /// 0.46 m with it). A constant command (`vx`, `vy`, `yaw_rate` without a target) is not
    /// held: on the G1's randomized walk (`walk_g1.toml`, pushes) holding it lost episodes
    /// (8/40 against 13/40). Measurements in BENCHMARKS.md, "Walker velocity tracking".
    #[default(0.35)]
    pub command_hold_gain: f64,
    /// Touch-down from contact ([`contact`]): whether a swing foot has landed is read from the
    /// robot's foot sensors (touch or force) or, without them, from its sole's motion, and the
    /// landed sole's height is the ground under that foot. A foot that lands early (ground
    /// higher than planned: held up more than [`contact::TOUCHDOWN_BLOCKED_M`] above its
    /// target) ends its step there, and the next step with its DCM reference starts then; a
    /// foot not down at the planned end (ground lower) goes on down at
    /// [`contact::TOUCHDOWN_SEARCH_MPS`] until it lands or has gone `touchdown_reach_m` below
    /// where it was to land, through the next step's double support (the step ends on time:
    /// holding the next lift-off until that foot had landed felled the walker on the 3-cm step,
    /// and holding the single support open, on flat ground after every step). The
    /// swing's profile comes down by [`contact::TOUCHDOWN_PROFILE_END`] of the swing, so that
    /// on flat ground the soft swing leg lands about on time (default: false: the planned
    /// time, and the sole's height then). Nominal, it walks every shipped terrain
    /// (`walk_steps.toml` 5.70 m, `walk_slope.toml` with `step_down_reach = 0` 7.9 m,
    /// `walk_rough.toml` 6.0 m against 5.67 m); randomized with kicks it does worse than
    /// without (20 episodes, seed 0: slope 6/20 against 14/20, rough 15/20 against 17/20;
    /// BENCHMARKS.md), so no shipped scenario turns it on.
    #[default(false)]
    pub touchdown_from_contact: bool,
    /// With foot contact sensors, a swing foot that carries load late in its swing (past
    /// [`contact::TOUCHDOWN_ARM_PHASE`]) is on the ground: its target goes no lower than where
    /// its sole met it, so the stiff swing leg does not drive the foot into ground met early
    /// (a ramp's rise under the toes) and lift the body off its stance foot (default: false;
    /// the Unitree G1 with sensors on a 3° hill: up and down without a fall, 6.78 m in 30 s,
    /// where without it the feet slid back and it fell at the ramp's foot; BENCHMARKS.md).
    #[default(false)]
    pub swing_holds_at_contact: bool,
    /// How far below its planned landing height a late swing foot goes on looking for the
    /// ground (`touchdown_from_contact`), m; past it the step ends in the air as planned
    /// (default: 0.04: a 3-cm step down and a centimetre more, or three steps' drop down a 5°
    /// ramp).
    #[default(0.04)]
    pub touchdown_reach_m: f64,
}

impl WalkOptions {
    /// The velocity command.
    pub fn command(&self) -> Command {
        Command { vx: self.vx, vy: self.vy, yaw_rate: self.yaw_rate }
    }

    /// The largest command the steps allow (each step's longest advance over `step_period`).
    pub fn command_bounds(&self) -> steer::CommandBounds {
        steer::CommandBounds {
            vx_mps: self.max_step_length / self.step_period,
            vy_mps: self.max_step_lateral / self.step_period,
            yaw_rate_radps: self.max_step_yaw / self.step_period,
        }
    }

    fn gait(&self) -> Gait {
        Gait {
            period: self.step_period,
            double_support: self.double_support,
            width: self.step_width,
            max_step_length: self.max_step_length,
            max_step_lateral: self.max_step_lateral,
            max_step_yaw: self.max_step_yaw,
            zmp_inward: self.zmp_inward,
        }
    }

    /// Checks every option's range; the error names the option (the field name).
    ///
    /// # Errors
    /// `(field, message)` for the first option out of range.
    pub fn validate(&self) -> std::result::Result<(), (&'static str, String)> {
        let positive: [(&'static str, f64); 10] = [
            ("min_single_support_secs", self.min_single_support_secs),
            ("recovery_swing_secs", self.recovery_swing_secs),
            ("step_period", self.step_period),
            ("step_width", self.step_width),
            ("com_height", self.com_height),
            ("max_step_length", self.max_step_length),
            ("preview_horizon", self.preview_horizon),
            ("preview_qe", self.preview_qe),
            ("preview_r", self.preview_r),
            ("damping_ratio", self.damping_ratio),
        ];
        twin_core::bounds::positive(positive)?;
        let non_negative: [(&'static str, f64); 23] = [
            ("touchdown_reach_m", self.touchdown_reach_m),
            ("stride_hold_step", self.stride_hold_step),
            ("ground_pitch_gain", self.ground_pitch_gain),
            ("ground_slope_gain", self.ground_slope_gain),
            ("step_down_reach", self.step_down_reach),
            ("zmp_inward", self.zmp_inward),
            ("line_hold_gain", self.line_hold_gain),
            ("line_hold_step", self.line_hold_step),
            ("recovery_double_support_secs", self.recovery_double_support_secs),
            ("foot_clearance", self.foot_clearance),
            ("max_step_lateral", self.max_step_lateral),
            ("max_step_yaw", self.max_step_yaw),
            ("settle_secs", self.settle_secs),
            ("start_double_support", self.start_double_support),
            ("dcm_zmp_gain", self.dcm_zmp_gain),
            ("dcm_com_gain", self.dcm_com_gain),
            ("step_adjust_gain", self.step_adjust_gain),
            ("max_step_adjust", self.max_step_adjust),
            ("recovery_margin", self.recovery_margin),
            ("tilt_gain", self.tilt_gain),
            ("tilt_rate_gain", self.tilt_rate_gain),
            ("swing_stiffness", self.swing_stiffness),
            ("leg_saturation_error", self.leg_saturation_error),
        ];
        twin_core::bounds::non_negative(non_negative)?;
        if self.swing_miss_fraction.is_nan() || self.swing_miss_fraction < 0.0 {
            let got = self.swing_miss_fraction;
            return Err(("swing_miss_fraction", format!("must be a non-negative number or inf (got {got})")));
        }
        if !(self.leg_saturation_error > 0.0 && self.saturation_error > 0.0) {
            return Err(("saturation_error", "saturation errors must be positive".into()));
        }
        twin_core::bounds::fraction([
            ("step_adjust_until", self.step_adjust_until),
            ("step_adjust_ankle", self.step_adjust_ankle),
        ])?;
        if !(0.0..0.9).contains(&self.double_support) {
            return Err(("double_support", format!("must be in [0, 0.9) (got {})", self.double_support)));
        }
        for (name, v) in [("vx", self.vx), ("vy", self.vy), ("yaw_rate", self.yaw_rate)] {
            if !v.is_finite() {
                return Err((name, format!("must be a finite number (got {v})")));
            }
        }
        let step = self.vx.abs() * self.step_period;
        if step > self.max_step_length + 1e-12 {
            return Err((
                "vx",
                format!(
                    "{} m/s with step_period {} s needs {step:.3} m steps, longer than max_step_length {} m: \
                     lower vx or lengthen max_step_length (if the legs reach it)",
                    self.vx, self.step_period, self.max_step_length
                ),
            ));
        }
        if self.vy.abs() * self.step_period > self.max_step_lateral + 1e-12 {
            return Err(("vy", format!("needs steps wider than max_step_lateral {} m", self.max_step_lateral)));
        }
        if self.yaw_rate.abs() * self.step_period > self.max_step_yaw + 1e-12 {
            return Err(("yaw_rate", format!("needs turns per step beyond max_step_yaw {} rad", self.max_step_yaw)));
        }
        twin_core::bounds::positive([
            ("max_accel_mps2", self.max_accel_mps2),
            ("max_yaw_accel_radps2", self.max_yaw_accel_radps2),
        ])?;
        steer::validate_schedule(&self.commands, &self.command_bounds()).map_err(|m| ("commands", m))?;
        if !(self.recovery_reach_fraction > 0.0 && self.recovery_reach_fraction <= 1.0) {
            return Err((
                "recovery_reach_fraction",
                format!("must be in (0, 1] (got {})", self.recovery_reach_fraction),
            ));
        }
        if self.ik_iterations == 0 {
            return Err(("ik_iterations", "must be at least 1".into()));
        }
        if !(1..=MAX_PLAN_EVERY_TICKS).contains(&self.plan_every_ticks) {
            return Err((
                "plan_every_ticks",
                format!("must be in 1..={MAX_PLAN_EVERY_TICKS} (got {})", self.plan_every_ticks),
            ));
        }
        twin_core::bounds::fraction([
            ("progress_hold_gain", self.progress_hold_gain),
            ("command_hold_gain", self.command_hold_gain),
            ("stride_hold_gain", self.stride_hold_gain),
        ])?;
        self.validate_hip()
    }

    /// The hip strategy's options ([`WalkOptions::validate`]).
    fn validate_hip(&self) -> std::result::Result<(), (&'static str, String)> {
        twin_core::bounds::non_negative([("hip_gain", self.hip_gain)])?;
        if !self.hip_max_lean_rad.iter().all(|m| (0.0..=1.0).contains(m)) {
            return Err(("hip_max_lean_rad", format!("must be in [0, 1] rad (got {:?})", self.hip_max_lean_rad)));
        }
        twin_core::bounds::positive([("hip_return_secs", self.hip_return_secs)])?;
        Ok(())
    }
}

/// One PD loop of the walker.
#[derive(Debug, Clone)]
struct JointLoop {
    command: usize,
    joint: usize,
    qpos_adr: usize,
    dof: usize,
    gear: f64,
    /// The command's range (a motor's torque / gear, a servo's setpoint).
    limits: [f64; 2],
    /// The joint torque its actuator can give, N·m (N on a slide): [least, most].
    torque_limits: [f64; 2],
    /// How the loop's torque becomes its command when the actuator is a servo; `None` for a
    /// motor (or `qfrc_applied`): torque / gear.
    servo: Option<AffineServo>,
    kp: f64,
    kd: f64,
    /// Gains while its leg swings.
    kp_swing: f64,
    kd_swing: f64,
    /// (leg index, index in the leg chain).
    leg: Option<(usize, usize)>,
}

/// A servo actuator with fixed gain and affine bias (MuJoCo's `position` and `velocity`
/// actuators, no activation dynamics): its force is `gain · ctrl + bias[0] + bias[1] · length +
/// bias[2] · velocity`, where a joint transmission's length and velocity are `gear · q` and
/// `gear · q̇`. The walker drives it with the setpoint whose force is the torque its own loop
/// wants, so that a robot on position servos walks on the same joint loops (the one gain rule,
/// from the servo's force range) as one on torque motors; the servo's own gains cancel.
#[derive(Debug, Clone, Copy, PartialEq)]
struct AffineServo {
    gain: f64,
    bias: [f64; 3],
}

impl AffineServo {
    /// The setpoint whose actuator force is `force` at actuator `length` and `velocity`.
    fn command_for(&self, force: f64, length: f64, velocity: f64) -> f64 {
        (force - self.bias[0] - self.bias[1] * length - self.bias[2] * velocity) / self.gain
    }
}

/// How the walker drives actuator `a` (a joint transmission) and the joint torque it can give,
/// [least, most] ([`twin_core::robot::Actuator::joint_effort_range`]): a motor by torque, a servo
/// through its setpoint ([`AffineServo`]).
fn drive_of(model: &Model, a: &twin_core::robot::Actuator) -> (Option<AffineServo>, [f64; 2]) {
    let range = a.joint_effort_range(model);
    if a.interface == twin_core::convert::Interface::Effort {
        return (None, range);
    }
    let [gain, ..] = model.actuator_gainprm()[a.id];
    let [b0, b1, b2, ..] = model.actuator_biasprm()[a.id];
    (Some(AffineServo { gain, bias: [b0, b1, b2] }), range)
}

/// Standing or stepping.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Mode {
    Standing,
    Walking(Step),
}

/// What the walker planned and measured at its last tick (for recordings and tests).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct WalkerState {
    /// Reference CoM (preview control), world, m.
    pub com_ref: [f64; 3],
    /// Measured CoM, world, m.
    pub com: [f64; 3],
    /// Reference ZMP, world x y, m.
    pub zmp_ref: [f64; 2],
    /// Commanded ZMP (with DCM feedback), world x y, m.
    pub zmp_cmd: [f64; 2],
    /// Reference DCM, world x y, m.
    pub dcm_ref: [f64; 2],
    /// Measured DCM, world x y, m.
    pub dcm: [f64; 2],
    /// Planned footholds ahead (side, x, y, yaw), the current landing first.
    pub footholds: Vec<(Side, [f64; 2], f64)>,
    /// Steps started so far.
    pub steps: u64,
    /// Whether it is stepping.
    pub walking: bool,
    /// Worst leg-IK position error this tick, m.
    pub ik_error_m: f64,
    /// The velocity command the steps are planned with (vx m/s, vy m/s, yaw rate rad/s):
    /// the constant one, or the steered one on its way to its target ([`steer`]).
    pub command: [f64; 3],
    /// Live targets ([`Walker::steer`]) cut to what the steps allow, count.
    pub commands_clamped: u64,
    /// The walking steps' touch-downs, oldest first (the last [`MAX_TOUCHDOWN_LOG`]).
    pub touchdowns: Vec<TouchdownEvent>,
}

/// How many touch-downs [`WalkerState::touchdowns`] keeps.
pub const MAX_TOUCHDOWN_LOG: usize = 1024;

/// A swing foot's touch-down: when the walker ended its step, and where the foot was.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct TouchdownEvent {
    /// When the step ended, controller seconds (from the reset).
    pub time_secs: f64,
    /// When it was planned to end (before contact moved it), controller seconds.
    pub planned_secs: f64,
    /// The foot (0 left, 1 right).
    pub leg: usize,
    /// Its sole's centre then, world, m.
    pub sole_world_m: [f64; 3],
    /// Whether contact ended the step ([`WalkOptions::touchdown_from_contact`]); false: its
    /// planned time (or the reach ran out).
    pub from_contact: bool,
    /// The ground the walker took under the landed foot, world z, m (`follow_ground`; else the
    /// sole's height): with [`WalkOptions::landing_read_at_rest`] and the sole still coming
    /// down at the touch-down, the height where it stopped.
    pub ground_m: f64,
    /// When that ground was read, controller seconds.
    pub ground_secs: f64,
}

/// The walking controller (`walk`): see the [module docs](self).
#[derive(Debug, Clone)]
pub struct Walker {
    /// Shared so that a solve holds them while it updates the walker (a clone of the options
    /// per solve was ~130 instructions).
    options: Arc<WalkOptions>,
    tree: Tree,
    body: Body,
    ik: [LegIk; 2],
    loops: Vec<JointLoop>,
    frames: Frames,
    desired: Frames,
    nominal: Vec<f64>,
    q_des: Vec<f64>,
    gravity: Vector3<f64>,
    omega: f64,
    /// Control period: time between solves, `plan_every_ticks` physics steps, s.
    dt: f64,
    /// The model's physics step (the joint PD's period), s.
    physics_dt: f64,
    /// Physics steps (calls of `compute`) since the reset.
    physics_tick: u64,
    preview: PreviewGains,
    preview_ratio: u64,
    /// Solves between refreshes of the held steps' leg maps ([`TILT_MAP_SECS`]).
    tilt_map_every: u64,
    axes: [PreviewAxis; 2],
    zmp_buf: [Vec<f64>; 2],
    schedule: Schedule,
    mode: Mode,
    command: Command,
    /// The live steering target ([`Walker::steer`]), clamped; it overrides the schedule.
    steer_target: Option<Command>,
    /// Whether the current step was planned with a zero command (feet brought side by side:
    /// at its touchdown a walker told to stop stands).
    step_zero: bool,
    /// The steering target at the last solve (`command_hold_gain`), if any.
    asked: Option<Command>,
    /// Where the asked command, integrated since walking started, puts the feet's centre path
    /// (`command_hold_gain`): world x y, m, and heading, rad; at the last solve (`hold_secs`,
    /// controller seconds). While the walker stands, the feet's midpoint and mean heading.
    hold: (Vector2<f64>, f64),
    hold_secs: f64,
    t0: f64,
    tick: u64,
    com_prev: Option<Vector3<f64>>,
    com_vel: Vector3<f64>,
    /// CoM minus pelvis in the pelvis's yaw frame, from the last commanded configuration.
    pelvis_from_com: Vector3<f64>,
    pelvis_z0: f64,
    pelvis_z: f64,
    sole_z: f64,
    /// Height of the ground under each foot (left, right), m: the sole's height where it was
    /// last planted, or `sole_z` when within [`GROUND_DEADBAND_M`] of it (flat ground).
    ground_z: [f64; 2],
    /// How far the pelvis reference is raised with the ground under the feet, m (their mean
    /// ground height above `sole_z`, low-passed over [`GROUND_FOLLOW_SECS`]).
    ground_ref: f64,
    /// The soles' pitch with the ground's slope (`ground_pitch_gain`), rad: follows its
    /// estimate from the planted feet over [`GROUND_PITCH_FOLLOW_SECS`], held while they are
    /// closer than [`GROUND_PITCH_MIN_BASE_M`] along the heading.
    ground_pitch: f64,
    /// The last three ground reads of the stance feet (`follow_ground`), oldest first: where
    /// (sole centre, world x y, m) and the ground's height there, m; `None` until read.
    ground_reads: [Option<(Vector2<f64>, f64)>; 3],
    /// Whether this step's stance foot has been read ([`GROUND_READ_PHASE`]).
    ground_read_done: bool,
    /// Each sole's height at the last solve, m (its speed for [`GROUND_READ_MAX_SPEED_MPS`]).
    sole_prev_z: [f64; 2],
    /// How long each sole has been at rest ([`GROUND_READ_STILL_SECS`]), s.
    sole_still_secs: [f64; 2],
    /// Per foot, whether its ground is still to be read once its sole rests
    /// (`landing_read_at_rest`).
    ground_pending: [bool; 2],
    /// Where each swing foot's sole met the ground late in its swing, world z, m
    /// (`swing_holds_at_contact`).
    swing_contact_z: [Option<f64>; 2],
    /// Length every planned straight step's advance gets (`stride_hold_gain`), m.
    stride_add_m: f64,
    /// The feet's contact sensing (`touchdown_from_contact`; with foot sensors also
    /// `landing_read_at_rest` and `swing_holds_at_contact`).
    contact: ContactSensing,
    /// Each sole's target height at the last solve, m.
    target_z: [f64; 2],
    /// The current step's end before its foot's contact moved it (`touchdown_from_contact`),
    /// controller seconds.
    touchdown_planned: Option<f64>,
    /// Per foot, since when its target goes on down below where it was to land, looking for
    /// the ground ([`TOUCHDOWN_SEARCH_MPS`]), controller seconds, and the height it goes down
    /// from, m: from where its swing's profile came down ([`TOUCHDOWN_PROFILE_END`]) until
    /// the foot lands, through the next step's double support when the step ended first.
    search: [Option<(f64, f64)>; 2],
    /// Per foot whose step ended before it landed: that step's end, controller seconds.
    landing: [Option<f64>; 2],
    state: WalkerState,
    /// Where the feet were planted (at the start and each touchdown): the standing feet's
    /// targets, so that an unloaded foot is held where it stands, not where it drifted.
    planted: [Foothold; 2],
    /// Stepping to recover a push from standing: quick steps under the predicted capture
    /// point until the DCM is back inside the feet's support. (Walking corrects its landing
    /// spots against its DCM reference instead: switching a walking walker to these steps
    /// after a push fell more often, 16 of 20 randomized episodes against 13.)
    recovering: bool,
    /// The line straight walking holds (`line_hold_gain`): a point on it and its heading,
    /// world, m and rad; set when walking starts, cleared by a command that is not straight.
    line: Option<(Vector2<f64>, f64)>,
    /// Walking's reference (the preview control's only serves standing).
    track: Track,
    /// Swing progress of the current step in [0, 1] and when it was last advanced: it runs so
    /// that it reaches 1 at the step's end, continuous when the touchdown is moved earlier.
    swing_s: f64,
    swing_t: f64,
    /// Per leg, how much of its IK target is placed from the measured pelvis pose rather than
    /// the commanded one (`swing_from_measured_pelvis`): 1 while it swings, then back to 0
    /// over [`MEASURED_FRAME_RELEASE_SECS`] after touchdown.
    measured_frame: [f64; 2],
    /// Whether the swinging legs' damping acts on the error to their target's velocity
    /// (`swing_miss_fraction`).
    track_swing_velocity: bool,
    /// The step under way is the first of a walk from standing, and the farthest its swing
    /// foot has been off its trajectory along the swing so far, m (`swing_miss_fraction`).
    first_step: bool,
    first_swing_off_m: f64,
    /// The diagnostics of the last tick, when it was one to publish.
    diagnostics: Diagnostics,
    /// The hip strategy's lean of the upper body (`hip_gain`).
    hip: hip::HipStrategy,
    /// What the joint PD runs on besides the IK targets.
    held: Held,
    /// The torso-tilt feedback's rate gains (roll, pitch), s
    /// ([`Walker::stable_tilt_rate_gains`]).
    tilt_rate_gains: [f64; 2],
}

/// What the joint PD ([`Walker::joint_torques`]) takes from the last solve besides the IK
/// targets `q_des`.
#[derive(Debug, Clone, Default)]
struct Held {
    /// Feed-forward torque of each joint loop (in `loops`' order), N·m (N on a slide).
    ff: Vec<f64>,
    /// The leg that was swinging (its joints take the soft swing gains).
    swinging: Option<usize>,
    /// Physics steps since the last solve.
    since: u64,
    /// Each joint loop's target offset from `q_des` on the steps between solves, rad (m on a
    /// slide): the legs' share of the tilt feedback since the solve ([`Walker::hold_targets`]).
    dq: Vec<f64>,
    /// Per leg and chain joint, its change per unit pelvis motion with the foot held
    /// ([`LegIk::base_motion_map`]), refreshed every [`TILT_MAP_SECS`] (from the first solve).
    leg_maps: [[[f64; 6]; 12]; 2],
    /// Per leg, the share of its IK base that is the measured pelvis at the solve
    /// (`measured_frame`; the rest is the commanded pelvis).
    measured: [f64; 2],
    /// The commanded pelvis's pitch axis in its frame (y turned by its roll): the y and z
    /// components, at the solve.
    pitch_axis: [f64; 2],
    /// The pelvis correction (roll, pitch) the solve commanded, rad.
    correction: [f64; 2],
    /// What the tilt feedback measured the tilt and its rate against at the solve (the hip
    /// strategy's lean and its rate: roll, pitch, rad and rad/s).
    lean: [f64; 2],
    lean_rate: [f64; 2],
    /// The measured pelvis pose (`qpos` of the free joint) at the solve, when a leg is
    /// placed from it.
    pelvis: Option<(Vector3<f64>, UnitQuaternion<f64>)>,
    /// Each joint loop's target `q_des` at the last solve (NaN before the first), rad (m on a
    /// slide), and its rate, filtered over [`SWING_VELOCITY_FILTER_SECS`], rad/s (m/s)
    /// (`swing_miss_fraction`).
    q_prev: Vec<f64>,
    qd_des: Vec<f64>,
}

/// The home pose and the crouch from it that the strength and reach checks start from
/// ([`Walker::home_crouch`]).
struct HomeCrouch {
    /// The home pose, `qpos`.
    qpos: Vec<f64>,
    /// Its frames.
    frames: Frames,
    /// Its CoM, world, m.
    com: Vector3<f64>,
    /// Its pelvis position, world, m.
    pelvis_pos: Vector3<f64>,
    /// The pelvis height that puts the CoM at `com_height`, world z, m.
    pelvis_z: f64,
}

/// Walking's DCM reference: within a step `ξ_ref(t)` runs from the stance foot to the step's
/// end DCM ([`Step::dcm`]), fixed when the step starts from the nominal plan of then
/// ([`Schedule::first_end_dcm`]). Landing-spot corrections during the step do not move it, so
/// the DCM error they answer is measured against a reference that stays put (the preview
/// control's reference reacted to every corrected landing, and the corrections chased it);
/// at touchdown the plan, and with it the reference, re-anchors at the foot that landed.
#[derive(Debug, Clone, Copy, Default)]
struct Track {
    /// DCM at the current step's end, world x y, m.
    end_dcm: Vector2<f64>,
    /// The current step's planned end, controller seconds.
    end_secs: f64,
    /// The current step's nominal landing spot (before corrections), world x y, m.
    landing: Vector2<f64>,
    /// CoM reference, world x y, m: follows the DCM reference by `ċ = ω(ξ_ref − c)`.
    com: Vector2<f64>,
}

/// Two recovery steps whose predicted misses ([`Walker::recovery_miss`]) differ by less than
/// this are equally good, m.
const RECOVERY_MISS_TIE_M: f64 = 0.01;
/// Time over which a landed leg's IK target returns from the measured pelvis frame to the
/// commanded one, s: switching at once moves the landed foot by the pelvis's pose error
/// (a rolled body lifts or drags the foot it has just put down).
const MEASURED_FRAME_RELEASE_SECS: f64 = 0.1;

/// The stability margin the torso-tilt feedback's rate loop may use
/// ([`Walker::stable_tilt_rate_gains`]), as [`PdHoldOptions::max_loop_margin`]'s default.
const TILT_LOOP_MARGIN: f64 = 0.98;

/// The pelvis's turn about one of its axes within a physics step ([`Walker::pelvis_mode`]).
struct PelvisMode {
    /// The axis, world.
    axis: Vector3<f64>,
    /// Per body, whether it turns rigidly with the pelvis.
    rigid: Vec<bool>,
    /// Their moment of inertia about the axis through the pelvis, kg·m².
    inertia: f64,
    /// Per joint loop (in loop order), its share of the turn.
    share: Vec<f64>,
}

impl PelvisMode {
    /// The joint loops' stiffness and damping terms of the Jury margin on this turn,
    /// `K·dt²/(4I)` and `D·dt/(2I)` (`K`, `D`: each loop's gain times its share).
    fn terms(&self, loops: &[JointLoop], dt: f64) -> (f64, f64) {
        let (mut k, mut d) = (0.0, 0.0);
        for (l, w) in loops.iter().zip(&self.share) {
            k += w * l.kp.max(0.0);
            d += w * l.kd.max(0.0);
        }
        (k * dt * dt / (4.0 * self.inertia), d * dt / (2.0 * self.inertia))
    }

    /// [`PelvisMode::terms`] summed.
    fn loops_margin(&self, loops: &[JointLoop], dt: f64) -> f64 {
        let (k, d) = self.terms(loops, dt);
        k + d
    }
}

/// Largest `plan_every_ticks`: beyond a few physics steps between solves the held targets
/// and feed-forward are no longer a control of the same body.
const MAX_PLAN_EVERY_TICKS: u64 = 10;

/// How often the held steps' maps of the pelvis's motion into the legs' targets
/// ([`Walker::hold_tilt_map`]) are refreshed, s: they change with the legs' configuration,
/// which moves by hundredths of a radian in that time, and a refresh of both costs more than
/// the legs' IK (randomized `walk.toml` at `plan_every_ticks` 2, seed 0: 182 of 200 passed
/// refreshed every 12 ms, 182 on every solve).
const TILT_MAP_SECS: f64 = 0.01;

/// Rate of the walker's diagnostic topics, Hz.
const DIAGNOSTICS_RATE_HZ: f64 = 100.0;

/// Names of the walker's diagnostic points ([`Walker::topics`] 0..6), world frame.
const DIAGNOSTIC_POINTS: [&str; 6] =
    ["/walk/com", "/walk/com_ref", "/walk/zmp", "/walk/zmp_ref", "/walk/dcm", "/walk/dcm_ref"];

/// The walker's diagnostic messages, refreshed every `1 / DIAGNOSTICS_RATE_HZ`.
#[derive(Debug, Clone, Default)]
struct Diagnostics {
    /// Whether the last tick refreshed them (then the recording publishes them).
    fresh: bool,
    /// Their stamp, simulation nanoseconds.
    stamp_nanos: u64,
    /// CoM, reference CoM, commanded ZMP, reference ZMP, DCM, reference DCM.
    points: [twin_core::log::typed::PointStamped; 6],
    /// Planned footholds ahead (the current landing first), at the sole.
    footsteps: twin_core::log::typed::PoseArray,
}

impl Walker {
    /// A walker for `model` with `options`.
    ///
    /// # Errors
    /// [`Error::Walk`] when an option is out of range, the model has no legs the walker can
    /// find, or the legs can't reach `max_step_length` at `com_height`.
    pub fn new(model: &Model, options: WalkOptions) -> Result<Walker> {
        Walker::build(model, options, true)
    }

    /// [`Walker::new`]; with `check_fit` false, without refusing the legs' reach and the
    /// actuators' strength: those check the options against the robot, once, when its walker is
    /// made; an episode's copy of the robot (`Controller::reset`: randomized masses move the
    /// CoM a few millimetres) walks with the options its nominal robot was checked for, and how
    /// it walks is the episode's result. Romeo's derived crouch is the one that reaches with its
    /// knees bent enough (`derive`), at the edge of reach: re-checked per episode, one of its
    /// first five randomized copies was refused and the whole batch with it.
    fn build(model: &Model, options: WalkOptions, check_fit: bool) -> Result<Walker> {
        options.validate().map_err(|(key, m)| Error::Walk { message: format!("option `{key}` {m}") })?;
        let tree = Tree::new(model);
        let home = nominal_pose(model);
        let body = Body::find(model, &tree, &home, &options.bodies)?;
        let ik = [LegIk::new(model, &body.legs[0]), LegIk::new(model, &body.legs[1])];
        let g = -model.gravity()[2];
        if g.is_nan() || g <= 0.0 {
            return Err(Error::Walk {
                message: format!("gravity must point down (−z); the model's is {:?}", model.gravity()),
            });
        }
        let physics_dt = model.timestep_secs();
        let dt = physics_dt * options.plan_every_ticks as f64;
        // In solves: the preview (and the commanded CoM offset) no more often than at
        // every-step solving, about 5 ms apart in physics steps.
        let preview_ratio = ((0.005 / physics_dt).round() as u64).max(1).div_ceil(options.plan_every_ticks);
        let preview_dt = dt * preview_ratio as f64;
        let horizon = (options.preview_horizon / preview_dt).ceil() as usize;
        let preview =
            PreviewGains::new(preview_dt, options.com_height, g, options.preview_qe, options.preview_r, horizon);
        let contact = ContactSensing::new(model, [body.legs[0].foot, body.legs[1].foot], tree.total_mass_kg * g);
        let mut walker = Walker {
            tree: tree.clone(),
            frames: tree.frames(),
            desired: tree.frames(),
            ik,
            loops: Vec::new(),
            nominal: home.clone(),
            q_des: home,
            gravity: Vector3::new(0.0, 0.0, -g),
            omega: (g / options.com_height).sqrt(),
            dt,
            physics_dt,
            physics_tick: 0,
            preview,
            preview_ratio,
            tilt_map_every: ((TILT_MAP_SECS / dt).round() as u64).max(1),
            axes: [PreviewAxis::default(); 2],
            zmp_buf: [vec![0.0; horizon + 1], vec![0.0; horizon + 1]],
            schedule: Schedule::default(),
            mode: Mode::Standing,
            command: options.command(),
            steer_target: None,
            step_zero: false,
            asked: None,
            hold: (Vector2::zeros(), 0.0),
            hold_secs: 0.0,
            t0: 0.0,
            tick: 0,
            com_prev: None,
            com_vel: Vector3::zeros(),
            pelvis_from_com: Vector3::zeros(),
            pelvis_z0: 0.0,
            pelvis_z: 0.0,
            sole_z: 0.0,
            ground_z: [0.0; 2],
            ground_ref: 0.0,
            ground_pitch: 0.0,
            ground_reads: [None; 3],
            ground_read_done: false,
            sole_prev_z: [0.0; 2],
            sole_still_secs: [0.0; 2],
            ground_pending: [false; 2],
            swing_contact_z: [None; 2],
            stride_add_m: 0.0,
            contact,
            target_z: [0.0; 2],
            touchdown_planned: None,
            search: [None; 2],
            landing: [None; 2],
            state: WalkerState::default(),
            planted: [Foothold { side: Side::Left, pos: Vector2::zeros(), yaw: 0.0 }; 2],
            recovering: false,
            line: None,
            track: Track::default(),
            swing_s: 0.0,
            swing_t: 0.0,
            measured_frame: [0.0; 2],
            track_swing_velocity: false,
            first_step: false,
            first_swing_off_m: 0.0,
            diagnostics: Diagnostics::default(),
            hip: hip::HipStrategy::default(),
            held: Held::default(),
            tilt_rate_gains: [options.tilt_rate_gain; 2],
            body,
            options: Arc::new(options),
        };
        walker.hip = walker.new_hip(model);
        walker.check_torque_actuators(model)?;
        if check_fit {
            walker.check_reach()?;
        }
        walker.build_loops(model);
        if check_fit {
            walker.check_strength(model)?;
        }
        walker.cap_pelvis_damping(model);
        walker.tilt_rate_gains = walker.stable_tilt_rate_gains(model);
        Ok(walker)
    }

    /// The torso-tilt feedback's rate gains (roll, pitch), s: `tilt_rate_gain`, lowered where
    /// the loop it closes would be unstable under the explicit physics step.
    ///
    /// The feedback turns the commanded pelvis against the measured tilt rate; each leg's hip
    /// joint about that axis takes the turn, so the legs' PD acts on the pelvis as a damping
    /// `S · tilt_rate_gain`, `S` the sum of those joints' `kp`. Within one step the pelvis turns
    /// on the inertia `I` that turns rigidly with it ([`Tree::rigid_axis_inertia`]); when the
    /// tilt is measured on a body that turns with it (the IMU's body, or the floating base when
    /// there is no IMU), that damping is stable under the step while `D·dt/(2I)`, with the
    /// joint loops' own margin on that turn, stays below [`TILT_LOOP_MARGIN`] (the Jury bound of [`PdHoldOptions::max_loop_margin`]). A tilt
    /// measured beyond a joint's spring (the shipped humanoid's IMU on its torso, over a waist
    /// pitch joint) closes no loop within a step, and keeps the option's gain.
    ///
    /// Example-robot-data's Unitree G1 (no IMU sensors: the base's orientation; a 3.8-kg pelvis
    /// under a torso on waist roll and pitch joints) at the default 0.05 s chattered at its hips'
    /// effort limits from the first step and fell within 0.7 s, standing; 0.03 s fell in 1.1 s,
    /// 0.02 s stood; this bound alone gave it 0.018 s (pitch) and 0.011 s (roll). The joint
    /// loops on the same turn use their share of the margin first
    /// ([`Walker::cap_pelvis_damping`]): the G1's use all of it, and its rate gains are 0.
    fn stable_tilt_rate_gains(&self, model: &Model) -> [f64; 2] {
        let wanted = self.options.tilt_rate_gain;
        let mut frames = self.tree.frames();
        self.tree.forward(&self.nominal, &mut frames);
        let measured = self.tilt_body(model);
        let mut gains = [wanted; 2];
        for (k, gain) in gains.iter_mut().enumerate() {
            let mode = self.pelvis_mode(model, &frames, k);
            if !mode.rigid[measured] || mode.inertia <= 0.0 {
                continue;
            }
            // Per leg, the hip joint (of its first three) most nearly about this axis.
            let axis = mode.axis;
            let stiffness: f64 =
                self.body
                    .legs
                    .iter()
                    .filter_map(|leg| {
                        let hip = leg.joints.iter().take(3).copied().max_by(|&a, &b| {
                            frames.axis[a].dot(&axis).abs().total_cmp(&frames.axis[b].dot(&axis).abs())
                        })?;
                        self.loops.iter().find(|l| l.joint == hip).map(|l| l.kp.max(0.0))
                    })
                    .sum();
            if stiffness > 0.0 {
                // What the joint loops leave of the margin on this mode.
                let left = (TILT_LOOP_MARGIN - mode.loops_margin(&self.loops, self.physics_dt)).max(0.0);
                *gain = wanted.min(left * 2.0 * mode.inertia / (stiffness * self.physics_dt));
            }
        }
        gains
    }

    /// The body the torso tilt is measured on: the IMU's, or the floating base without one.
    fn tilt_body(&self, model: &Model) -> usize {
        let pelvis = self.body.pelvis;
        match &self.body.imu {
            Some(imu) if imu.quat_adr.is_some() => model
                .id(ObjType::Sensor, &imu.name)
                .map_or(pelvis, |s| model.site_bodyid()[model.sensor_objid()[s] as usize] as usize),
            _ => pelvis,
        }
    }

    /// The pelvis's turn about its roll (`k` 0) or pitch (1) axis at `frames`, within one
    /// physics step: what turns rigidly with it ([`Tree::rigid_axis_inertia`], the legs
    /// excluded) and each joint loop's share of the turn, the square of its axis's part along
    /// this one for the loops that join the rigid set to what lies beyond a spring (each leg's
    /// three hip joints, a waist joint), 0 for the others.
    fn pelvis_mode(&self, model: &Model, frames: &Frames, k: usize) -> PelvisMode {
        let pelvis = self.body.pelvis;
        let axis = frames.xrot[pelvis] * Vector3::ith(k, 1.0);
        let legs: Vec<usize> = self.body.legs.iter().filter_map(|l| l.bodies.first().copied()).collect();
        let (rigid, _) = self.tree.rigid_axis_inertia(model, frames, pelvis, (frames.xpos[pelvis], axis), &legs);
        // Their moment about the axis, each body's own inertia along it (not its mean).
        let (mass, ipos, iquat, principal) =
            (model.body_mass(), model.body_ipos(), model.body_iquat(), model.body_inertia());
        let inertia: f64 = (0..rigid.len())
            .filter(|&b| rigid[b])
            .map(|b| {
                let c = frames.xpos[b] + frames.xrot[b] * Vector3::from(ipos[b]);
                let r = c - frames.xpos[pelvis];
                let perp = r - axis * axis.dot(&r);
                let local = (frames.xrot[b] * kin::quat(iquat[b])).inverse() * axis;
                let own: f64 = (0..3).map(|i| principal[b][i] * local[i] * local[i]).sum();
                mass[b] * perp.norm_squared() + own
            })
            .sum();
        let parent = model.body_parentid();
        let share = self
            .loops
            .iter()
            .map(|l| {
                let b = self.tree.joint_body(l.joint);
                let joins = match l.leg {
                    Some((_, in_chain)) => in_chain < 3,
                    None => !rigid[b] && rigid[parent[b] as usize],
                };
                if joins { frames.axis[l.joint].dot(&axis).powi(2) } else { 0.0 }
            })
            .collect();
        PelvisMode { axis, rigid, inertia, share }
    }

    /// Lowers the damping of the loops that turn the pelvis (hips, waist) where, together,
    /// they would turn it unstably under the explicit physics step, on the axes where the
    /// walker measures the tilt on a body that turns rigidly with the pelvis.
    ///
    /// The gain rule sizes each joint's `kd` on that joint's own inertia (the whole robot
    /// beyond it), but within one step the pelvis turns on what turns rigidly with it
    /// ([`Walker::pelvis_mode`]), and every hip and waist loop damps that turn at once: the
    /// margin `K·dt²/(4I) + D·dt/(2I)` (the Jury bound of [`PdHoldOptions::max_loop_margin`];
    /// `K`, `D` the loops' stiffness and damping on the turn) must stay below
    /// [`TILT_LOOP_MARGIN`]. Above it, the damping of the loops on that turn is scaled down by
    /// the one factor that meets it (the stiffness, which carries the robot, is kept); the
    /// torso-tilt rate loop gets what is left ([`Walker::stable_tilt_rate_gains`]).
    ///
    /// Example-robot-data's Unitree G1 (no IMU: the tilt is the pelvis's own; a 3.8-kg pelvis,
    /// 0.03 kg·m² about its roll and pitch axes, between two hips and a waist whose `kd` were
    /// sized on its 33 kg) had margins of 1.92 (roll) and 1.08 (pitch): its hip pitch, hip roll
    /// and waist torques flipped sign on most physics steps in single support, at the hips'
    /// effort limits (`saturated` 9.5 s of a 12-s turn, 23 s of a 30-s walk; none at a 1-ms
    /// timestep), it fell turning and at 0.2 and 0.3 m/s. Capped (kd × 0.49 on roll, × 0.90 on
    /// pitch) it saturates 0 s, turns 95° and walks at 0.2–0.3 m/s. The same estimate puts the
    /// shipped humanoid's pelvis pitch turn at 3.1 (0.014 kg·m² between hips and waist pitch),
    /// yet it walks (its tilt measured on the torso, beyond the waist's spring), and capping
    /// it there felled it at 1.0 s: the estimate overstates the margin where no feedback of
    /// the walker closes on the pelvis within a step, and the cap is kept to the axes where
    /// one does, as for the tilt-rate bound.
    fn cap_pelvis_damping(&mut self, model: &Model) {
        let mut frames = self.tree.frames();
        self.tree.forward(&self.nominal, &mut frames);
        let dt = self.physics_dt;
        let measured = self.tilt_body(model);
        for k in 0..2 {
            let mode = self.pelvis_mode(model, &frames, k);
            if !mode.rigid[measured] || mode.inertia <= 0.0 {
                continue;
            }
            let (k_term, d_term) = mode.terms(&self.loops, dt);
            if k_term + d_term <= TILT_LOOP_MARGIN || d_term <= 0.0 {
                continue;
            }
            let factor = ((TILT_LOOP_MARGIN - k_term) / d_term).clamp(0.0, 1.0);
            for (l, &w) in self.loops.iter_mut().zip(&mode.share) {
                if w > 0.0 {
                    l.kd *= factor;
                    l.kd_swing = l.kd_swing.min(l.kd);
                }
            }
        }
    }

    /// The options.
    pub fn options(&self) -> &WalkOptions {
        &self.options
    }

    /// What it planned and measured at the last tick.
    pub fn state(&self) -> &WalkerState {
        &self.state
    }

    /// The foot bodies found (left, right) and the pelvis.
    pub fn feet(&self) -> ([usize; 2], usize) {
        ([self.body.legs[0].foot, self.body.legs[1].foot], self.body.pelvis)
    }

    /// Steers toward `target` from now on (a navigation stack's `/cmd_vel`, [`steer`]): the
    /// target is clamped to what the steps allow and reached at the acceleration limits; it
    /// overrides a schedule. A zero target stops the walker: it finishes its step, brings the
    /// feet side by side and stands. Returns whether the target was cut (counted in
    /// [`WalkerState::commands_clamped`]).
    pub fn steer(&mut self, target: Command) -> bool {
        let (target, cut) = steer::clamp(target, &self.options.command_bounds());
        self.state.commands_clamped += u64::from(cut);
        self.steer_target = Some(target);
        cut
    }

    /// The command the steps are planned with now.
    pub fn command(&self) -> Command {
        self.command
    }

    /// Sets a new velocity command (takes effect at the next step).
    pub fn set_command(&mut self, command: Command) {
        self.command = command;
        if !self.straight() {
            self.line = None;
        }
    }

    /// Refuses legs driven by servos the walker can't command a torque through: the walker
    /// computes joint torques (PD toward its IK targets plus the feed-forward that holds the
    /// weight) and sends a position or velocity servo the setpoint whose force is that torque
    /// ([`AffineServo`]), which needs the servo's force law to be affine in its setpoint with no
    /// activation dynamics, and a force limit for the gain rule to scale the loop by.
    fn check_torque_actuators(&self, model: &Model) -> Result<()> {
        let legs: Vec<usize> = self.body.legs.iter().flat_map(|l| l.joints.iter().copied()).collect();
        for a in twin_core::robot::actuators_of(model, &[]) {
            let Some(joint) = a.joint.filter(|j| legs.contains(j)) else { continue };
            if a.interface == twin_core::convert::Interface::Effort {
                continue;
            }
            let affine = model.actuator_dyntype()[a.id] == 0
                && model.actuator_gaintype()[a.id] == 0
                && model.actuator_gainprm()[a.id][0] != 0.0;
            let force_limited = a.joint_effort(model).is_finite();
            let what = if !affine {
                "whose force is not an affine function of its setpoint (activation dynamics, or a \
                 gain that is not fixed)"
            } else if !force_limited {
                "with no force limit (`forcerange`), so the walker can't scale its joint loop to \
                 the actuator's strength"
            } else {
                continue;
            };
            return Err(Error::Walk {
                message: format!(
                    "the leg joint \"{}\" is driven by a {} servo (actuator \"{}\") {what}: give it \
                     a plain position servo with a force range (the URDF joint's effort limit), or \
                     convert the URDF with torque motors (`twin convert --actuators motor ROBOT.urdf`)",
                    model.name(ObjType::Joint, joint),
                    format!("{:?}", a.interface).to_lowercase(),
                    a.name
                ),
            });
        }
        Ok(())
    }

    /// Refuses a robot whose leg actuators can't hold its weight in the walking crouch: with
    /// the CoM at `com_height` over the middle of the feet where they stand in the home pose,
    /// each sole carrying half the weight at its centre, every leg joint's static torque
    /// ([`Tree::static_torque`]) must lie within what its actuator gives (its command range
    /// times its gear). Walking needs more (a whole leg's share in single support, the ankles'
    /// ZMP work); a robot that can't hold the crouch falls before its first step.
    fn check_strength(&self, model: &Model) -> Result<()> {
        for (joint, needed, [lo, hi]) in self.crouch_torques() {
            if needed < lo - 1e-9 || needed > hi + 1e-9 {
                return Err(Error::Walk {
                    message: format!(
                        "the actuator of joint \"{}\" gives {:.1} N·m but holding the robot's {:.1} kg \
                         on both feet with the CoM at com_height {} m takes {:.1} N·m: raise com_height \
                         (a straighter leg needs less), or give the joint a stronger actuator (its \
                         effort limit in the URDF)",
                        model.name(ObjType::Joint, joint),
                        if needed > 0.0 { hi } else { lo },
                        self.tree.total_mass_kg,
                        self.options.com_height,
                        needed
                    ),
                });
            }
        }
        Ok(())
    }

    /// Each leg joint's static torque holding the robot in the walking crouch (as
    /// [`Walker::check_strength`] poses it), N·m, with what its actuator gives, N·m:
    /// (joint, torque, [least, most]).
    fn crouch_torques(&self) -> Vec<(usize, f64, [f64; 2])> {
        let HomeCrouch { qpos: home, frames, pelvis_pos, pelvis_z, .. } = self.home_crouch();
        let mut q = home.clone();
        for (leg, ik) in self.ik.iter().enumerate() {
            let sole = self.sole_world(&frames, leg);
            let pelvis = Vector3::new(pelvis_pos.x, pelvis_pos.y, pelvis_z);
            let (ql, _) = self.crouched_leg(leg, &home, sole, pelvis);
            for (k, v) in ql.iter().enumerate() {
                q[ik.qpos_adr(k)] = *v;
            }
        }
        let b = self.body.base_qpos;
        q[b + 2] += pelvis_z - pelvis_pos.z;
        let mut crouched = self.tree.frames();
        self.tree.forward(&q, &mut crouched);
        let weight = -self.gravity * self.tree.total_mass_kg;
        let forces: Vec<(usize, Vector3<f64>, Vector3<f64>)> =
            (0..2).map(|leg| (self.body.legs[leg].foot, self.sole_world(&crouched, leg), weight / 2.0)).collect();
        self.loops
            .iter()
            .filter(|l| l.leg.is_some())
            .map(|l| {
                let needed = self.tree.static_torque(&crouched, l.joint, self.gravity, &forces);
                (l.joint, needed, l.torque_limits)
            })
            .collect()
    }

    /// The legs' static load in the walking crouch: the largest part of its actuator's torque
    /// that a leg joint spends holding the robot on both feet (as the strength check poses it; at
    /// most 1 once the walker is built).
    pub fn crouch_load(&self) -> f64 {
        self.crouch_torques()
            .iter()
            .map(|(_, needed, [lo, hi])| if *needed > 0.0 { needed / hi.max(1e-9) } else { needed / lo.min(-1e-9) })
            .fold(0.0, f64::max)
    }

    /// The home pose and the pelvis height that puts the CoM at `com_height` (what the
    /// strength and reach checks start from).
    fn home_crouch(&self) -> HomeCrouch {
        let qpos = self.nominal.clone();
        let mut frames = self.tree.frames();
        self.tree.forward(&qpos, &mut frames);
        let com = frames.com();
        let pelvis_pos = frames.xpos[self.body.pelvis];
        let pelvis_z = self.options.com_height + (pelvis_pos.z - com.z);
        HomeCrouch { qpos, frames, com, pelvis_pos, pelvis_z }
    }

    /// Leg `leg`'s angles (from the home pose `home`, knee bent) that put its sole centre at
    /// `sole` (world, m) in the home foot orientation with the pelvis at `pelvis` (world, m,
    /// home orientation), and the IK's remaining error.
    fn crouched_leg(
        &self,
        leg: usize,
        home: &[f64],
        sole: Vector3<f64>,
        pelvis: Vector3<f64>,
    ) -> (Vec<f64>, kin::IkResult) {
        let ik = &self.ik[leg];
        let rot = self.body.legs[leg].foot_rot_home;
        let foot = sole - rot * self.body.legs[leg].sole_in_foot;
        let mut q: Vec<f64> = (0..ik.len()).map(|k| home[ik.qpos_adr(k)]).collect();
        ik.bend_knee(&mut q, 0.5);
        let error = ik.solve((foot - pelvis, rot), &mut q, 200, 1e-3);
        (q, error)
    }

    /// The gait's extreme poses: with the CoM at `com_height` midway between a front and a back
    /// foot `max_step_length` apart (and `step_width` + `max_step_lateral` wide), soles flat in
    /// their home orientation, each leg's IK solution (within the joint ranges) and its
    /// remaining error: (leg, angles, error), each leg in front in turn.
    fn extreme_poses(&self) -> Vec<(usize, Vec<f64>, kin::IkResult)> {
        let HomeCrouch { qpos: home, frames, com, pelvis_pos, pelvis_z } = self.home_crouch();
        let sole_z = self.sole_world(&frames, 0).z;
        let o = &self.options;
        let half_len = o.max_step_length / 2.0;
        let half_width = (o.step_width + o.max_step_lateral) / 2.0;
        let offset_x = pelvis_pos.x - com.x;
        let mut poses = Vec::with_capacity(4);
        for front in 0..2 {
            for leg in 0..2 {
                let x = if leg == front { half_len } else { -half_len };
                let y = self.body.legs[leg].side.sign() * half_width;
                let sole = Vector3::new(com.x + x, com.y + y, sole_z);
                let (q, r) = self.crouched_leg(leg, &home, sole, Vector3::new(com.x + offset_x, com.y, pelvis_z));
                poses.push((leg, q, r));
            }
        }
        poses
    }

    /// The least knee bend of the gait's extreme poses ([`LegIk::knee_bend_rad`]), rad: how far
    /// the longest step keeps the legs from the straight knee, where a leg's length stops
    /// following its knee (the crouch of [`derive`](mod@derive)).
    pub fn least_knee_bend_rad(&self) -> f64 {
        self.extreme_poses().iter().map(|(leg, q, _)| self.ik[*leg].knee_bend_rad(q)).fold(f64::INFINITY, f64::min)
    }

    /// Refuses steps the legs can't reach: in every extreme pose of the gait
    /// ([`Walker::extreme_poses`]) both legs' IK must converge.
    fn check_reach(&self) -> Result<()> {
        let o = &self.options;
        for (leg, _, r) in self.extreme_poses() {
            if r.position_error_m > 0.005 || r.rotation_error_rad > 0.02 {
                return Err(Error::WalkReach {
                    message: format!(
                        "the {} leg can't reach a step of max_step_length {} m (width {} m) with the CoM at \
                         com_height {} m: its foot stays {:.3} m and {:.3} rad from the target; shorten \
                         max_step_length, or lower com_height",
                        match self.body.legs[leg].side {
                            Side::Left => "left",
                            Side::Right => "right",
                        },
                        o.max_step_length,
                        o.step_width,
                        o.com_height,
                        r.position_error_m,
                        r.rotation_error_rad
                    ),
                });
            }
        }
        Ok(())
    }

    /// The feet's support region: the segment between the sole centres swept by a sole (in
    /// the feet's mean heading frame): start, segment, heading, sole half sizes.
    fn support_region(&self, feet: &[Foothold; 2]) -> (Vector2<f64>, Vector2<f64>, f64, Vector2<f64>) {
        let heading = feet[1].yaw + wrap(feet[0].yaw - feet[1].yaw) / 2.0;
        let sole = |k: usize| self.body.legs[0].sole_half[k].min(self.body.legs[1].sole_half[k]);
        let segment = rotation(-heading) * (feet[1].pos - feet[0].pos);
        (feet[0].pos, segment, heading, Vector2::new(sole(0), sole(1)))
    }

    /// Whether `p` lies inside the feet's support region, at least `margin` from its edge.
    fn inside_support(&self, p: Vector2<f64>, feet: &[Foothold; 2], margin: f64) -> bool {
        let (a, d, heading, half) = self.support_region(feet);
        let q = rotation(-heading) * (p - a);
        // Some s in [0, 1] with |q − s·d| ≤ half − margin on both axes.
        let (mut lo, mut hi) = (0.0_f64, 1.0_f64);
        for k in 0..2 {
            let h = half[k] - margin;
            if h <= 0.0 {
                return false;
            }
            if d[k].abs() < 1e-9 {
                if q[k].abs() > h {
                    return false;
                }
            } else {
                let (s0, s1) = ((q[k] - h) / d[k], (q[k] + h) / d[k]);
                lo = lo.max(s0.min(s1));
                hi = hi.min(s0.max(s1));
            }
        }
        lo <= hi
    }

    /// `p` moved into the feet's support region (its soles shrunk to 80 %): onto the segment
    /// between the soles, then within a sole around that point.
    fn clamp_to_support(&self, p: Vector2<f64>, feet: &[Foothold; 2]) -> Vector2<f64> {
        let (a, d, heading, half) = self.support_region(feet);
        let rot = rotation(heading);
        let q = rot.inverse() * (p - a);
        let s = (q.dot(&d) / d.norm_squared().max(1e-12)).clamp(0.0, 1.0);
        let r = q - d * s;
        let r = Vector2::new(r.x.clamp(-0.8 * half.x, 0.8 * half.x), r.y.clamp(-0.8 * half.y, 0.8 * half.y));
        a + rot * (d * s + r)
    }

    /// `p` moved into the sole of `foot` (shrunk to 80 %).
    fn clamp_to_sole(&self, foot: &Foothold, p: Vector2<f64>) -> Vector2<f64> {
        let half = self.body.legs[foot.side.index()].sole_half;
        // One `sin_cos`: the inverse is the transpose, `Rotation2::new(-yaw)` bit for bit.
        let r = rotation(foot.yaw);
        let rel = r.inverse() * (p - foot.pos);
        let rel = Vector2::new(rel.x.clamp(-half[0] * 0.8, half[0] * 0.8), rel.y.clamp(-half[1] * 0.8, half[1] * 0.8));
        foot.pos + r * rel
    }

    /// Restarts the preview control's state at the measured CoM `com` and its velocity.
    fn restart_preview(&mut self, com: Vector3<f64>) {
        self.axes = [
            PreviewAxis::restart(&self.preview, com.x, self.com_vel.x),
            PreviewAxis::restart(&self.preview, com.y, self.com_vel.y),
        ];
    }

    /// World sole centre of leg `leg` at `frames`.
    fn sole_world(&self, frames: &Frames, leg: usize) -> Vector3<f64> {
        let l = &self.body.legs[leg];
        frames.xpos[l.foot] + frames.xrot[l.foot] * l.sole_in_foot
    }

    /// Foothold (sole centre x y, heading) of leg `leg` at `frames`.
    fn foothold_of(&self, frames: &Frames, leg: usize) -> Foothold {
        let l = &self.body.legs[leg];
        let p = self.sole_world(frames, leg);
        let heading = frames.xrot[l.foot] * l.foot_rot_home.inverse();
        Foothold { side: l.side, pos: Vector2::new(p.x, p.y), yaw: kin::yaw_of(&heading) }
    }

    fn build_loops(&mut self, model: &Model) {
        let o = &self.options;
        let pd_legs = PdHold::new(
            model,
            PdHoldOptions {
                saturation_error: o.leg_saturation_error,
                damping_ratio: o.damping_ratio,
                ..Default::default()
            },
        )
        .gains();
        let pd_rest = PdHold::new(
            model,
            PdHoldOptions {
                saturation_error: o.saturation_error,
                damping_ratio: o.damping_ratio,
                ..Default::default()
            },
        )
        .gains();
        let mut frames = self.tree.frames();
        self.tree.forward(&self.nominal, &mut frames);
        let actuation = Actuation::of(model);
        let limits = actuation.limits(model);
        self.loops.clear();
        // The same loops, in the same order, as PdHold builds (joint transmissions on hinges).
        let mut k = 0;
        let mut push = |command: usize,
                        joint: usize,
                        gear: f64,
                        limits: [f64; 2],
                        drive: (Option<AffineServo>, [f64; 2]),
                        loops: &mut Vec<JointLoop>| {
            let leg = self
                .ik
                .iter()
                .enumerate()
                .find_map(|(li, _)| self.body.legs[li].joints.iter().position(|&j| j == joint).map(|ci| (li, ci)));
            let (kp, kd) = if leg.is_some() { pd_legs[k] } else { pd_rest[k] };
            k += 1;
            // Joint-space gains (PdHold's are per unit of command).
            let (kp, kd) = (kp * gear, kd * gear);
            let inertia = self.tree.subtree_axis_inertia(model, &frames, joint)
                + model.dof_armature()[model.jnt_dofadr()[joint] as usize];
            let kp_cap = (o.swing_stiffness / self.physics_dt).powi(2) * inertia;
            let kp_swing = kp.min(kp_cap);
            let kd_swing = (2.0 * o.damping_ratio * (kp_swing * inertia).sqrt())
                .min(kd.max(0.0) + 2.0 * (kp_swing * inertia).sqrt());
            loops.push(JointLoop {
                command,
                joint,
                qpos_adr: model.jnt_qposadr()[joint] as usize,
                dof: model.jnt_dofadr()[joint] as usize,
                gear,
                limits,
                torque_limits: drive.1,
                servo: drive.0,
                kp,
                kd,
                kp_swing,
                kd_swing,
                leg,
            });
        };
        let mut loops = Vec::new();
        match actuation {
            Actuation::Ctrl => {
                // The one actuator finder (joint transmissions on hinges and slides).
                for a in twin_core::robot::actuators_of(model, &[]) {
                    let Some(joint) = a.joint.filter(|_| a.gear != 0.0) else { continue };
                    push(a.id, joint, a.gear, limits[a.id], drive_of(model, &a), &mut loops);
                }
            }
            Actuation::Qfrc => {
                for joint in 0..model.njnt() {
                    if !matches!(model.joint_type(joint), JointType::Hinge | JointType::Slide) {
                        continue;
                    }
                    let dof = model.jnt_dofadr()[joint] as usize;
                    push(dof, joint, 1.0, limits[dof], (None, limits[dof]), &mut loops);
                }
            }
        }
        self.held = Held {
            ff: vec![0.0; loops.len()],
            dq: vec![0.0; loops.len()],
            q_prev: vec![f64::NAN; loops.len()],
            qd_des: vec![0.0; loops.len()],
            ..Held::default()
        };
        self.loops = loops;
    }

    /// Torso roll, pitch (heading frame) and their rates, from the IMU or the base.
    fn tilt(&self, observation: &Observation<'_>) -> ([f64; 2], [f64; 2]) {
        let base = self.body.base_qpos;
        let q = observation.qpos;
        let (rot, gyro_world) = match &self.body.imu {
            Some(imu) if imu.quat_adr.is_some() => {
                let a = imu.quat_adr.unwrap_or(0);
                let s = observation.sensordata;
                let site = kin::quat([s[a], s[a + 1], s[a + 2], s[a + 3]]);
                let g = &s[imu.gyro_adr..imu.gyro_adr + 3];
                let gyro = site * Vector3::new(g[0], g[1], g[2]);
                (site * imu.site_rot.inverse(), gyro)
            }
            _ => {
                let r = kin::quat([q[base + 3], q[base + 4], q[base + 5], q[base + 6]]);
                let d = self.body.base_dof;
                let w = observation.qvel;
                (r, r * Vector3::new(w[d + 3], w[d + 4], w[d + 5]))
            }
        };
        let (roll, pitch, yaw) = rot.euler_angles();
        let rate = rotation(-yaw) * Vector2::new(gyro_world.x, gyro_world.y);
        ([roll, pitch], [rate.x, rate.y])
    }

    /// Replans the future steps from the current one (or the rest point when standing).
    fn replan(&mut self, t: f64, feet: &[Foothold; 2]) {
        let gait = self.options.gait();
        let horizon = self.preview.horizon() as f64 * self.dt * self.preview_ratio as f64;
        self.schedule.steps.clear();
        self.schedule.settle_secs = gait.ds_secs().max(0.1);
        match self.mode {
            Mode::Standing => {
                self.schedule.rest = (feet[0].pos + feet[1].pos) / 2.0;
                if !self.command.is_zero() {
                    // The first step, where `compute` will start it, so that the preview sees it.
                    let start = t.max(self.options.settle_secs);
                    let swing = self.first_swing(None, feet);
                    let first =
                        self.first_step(start, feet, swing, self.options.start_double_support, self.schedule.rest);
                    self.extend(first, t, horizon);
                }
            }
            Mode::Walking(step) => self.extend(step, t, horizon),
        }
    }

    /// The schedule from `step` on, covering the preview horizon.
    fn extend(&mut self, step: Step, t: f64, horizon: f64) {
        let gait = self.options.gait();
        self.schedule.steps.push(step);
        if !self.command.is_zero() {
            let mut prev = step;
            let mut center = gait.center_of(&step.swing_to);
            let mut yaw = step.swing_to.yaw;
            while prev.end() < t + horizon + gait.period {
                let (c, y) = self.next_center(center, yaw);
                let next = Step {
                    start: prev.end(),
                    ds: gait.ds_secs(),
                    ss: gait.period - gait.ds_secs(),
                    zmp_from: prev.zmp_point(),
                    stance: prev.swing_to,
                    swing_from: prev.stance,
                    swing_to: gait.foothold(prev.stance.side, c, y),
                    zmp_inward: gait.zmp_inward,
                };
                (center, yaw) = (c, y);
                self.schedule.steps.push(next);
                prev = next;
            }
        }
        let last = self.schedule.steps.last().copied().unwrap_or(step);
        self.schedule.rest = (last.stance.pos + last.swing_to.pos) / 2.0;
    }

    /// Whether the command walks straight ahead or back (the only one with a line to hold).
    fn straight(&self) -> bool {
        self.command.vy == 0.0 && self.command.yaw_rate == 0.0
    }

    /// The next step's centre and heading after `(center, yaw)`: the command's advance plus,
    /// walking straight, a sideways move toward the held line (`line_hold_gain`) and the
    /// held pace's added length (`stride_hold_gain`).
    fn next_center(&self, center: Vector2<f64>, yaw: f64) -> (Vector2<f64>, f64) {
        let (mut c, y) = self.options.gait().next_center(center, yaw, &self.command);
        if let (Some((origin, heading)), true) = (self.line, self.straight()) {
            let off_m = (rotation(-heading) * (center - origin)).y;
            let reach = self.options.line_hold_step;
            let dy_m = (-self.options.line_hold_gain * off_m).clamp(-reach, reach);
            c += rotation(heading) * Vector2::new(0.0, dy_m);
        }
        if self.stride_add_m != 0.0 && self.straight() {
            c += rotation(yaw) * Vector2::new(self.stride_add_m, 0.0);
        }
        (c, y)
    }

    /// After the walking step `step` landed its foot at `landed` (`stride_hold_gain`): adds
    /// the gain times its advance's shortfall against the command's to the length every
    /// straight step gets, within ±`stride_hold_step`; other commands (turning, sideways,
    /// standing) start it over.
    fn hold_stride(&mut self, step: &Step, landed: &Foothold) {
        let o = &self.options;
        if !self.straight() || self.command.is_zero() {
            self.stride_add_m = 0.0;
            return;
        }
        let advance_m = (rotation(-step.stance.yaw) * (landed.pos - step.stance.pos)).x;
        let asked_m = (self.command.vx * o.step_period).clamp(-o.max_step_length, o.max_step_length);
        let reach = o.stride_hold_step.min((o.max_step_length - asked_m.abs()).max(0.0));
        self.stride_add_m = (self.stride_add_m + o.stride_hold_gain * (asked_m - advance_m)).clamp(-reach, reach);
    }

    /// The first step from standing at `t` with `swing` swinging.
    fn first_step(&self, t: f64, feet: &[Foothold; 2], swing: Side, ds: f64, zmp_from: Vector2<f64>) -> Step {
        let gait = self.options.gait();
        let stance = feet[swing.other().index()];
        let (c, y) = self.next_center(gait.center_of(&stance), stance.yaw);
        Step {
            start: t,
            ds,
            ss: gait.period - gait.ds_secs(),
            zmp_from,
            stance,
            swing_from: feet[swing.index()],
            swing_to: gait.foothold(swing, c, y),
            zmp_inward: gait.zmp_inward,
        }
    }

    /// Where a recovery step of `swing` lands, `secs` before touchdown, with the measured DCM
    /// `dcm`: under the capture point predicted at touchdown (the ZMP held at the `stance`
    /// sole meanwhile), within `max_step_adjust` fore-aft and at least 2/3 of a step width
    /// beside the stance foot (the feet must not cross). Also that predicted capture point.
    fn recovery_landing(
        &self,
        stance: &Foothold,
        swing: Side,
        dcm: Vector2<f64>,
        secs: f64,
    ) -> (Vector2<f64>, Vector2<f64>) {
        let o = &self.options;
        let p = self.clamp_to_sole(stance, dcm);
        let xi_td = p + (dcm - p) * (self.omega * secs.max(0.0)).exp();
        let rel = rotation(-stance.yaw) * (xi_td - stance.pos);
        let side = swing.sign();
        let reach = o.max_step_adjust;
        let x = (rel.x * o.step_adjust_gain).clamp(-reach, reach);
        let y = (side * rel.y * o.step_adjust_gain).clamp(o.step_width * 2.0 / 3.0, o.step_width + reach);
        (stance.pos + rotation(stance.yaw) * Vector2::new(x, side * y), xi_td)
    }

    /// How far the capture point predicted at a recovery step's touchdown stays outside the
    /// feet's support once `swing` has landed where [`Walker::recovery_landing`] puts it, m:
    /// 0 when that one step captures the push.
    fn recovery_miss(&self, feet: &[Foothold; 2], swing: Side, dcm: Vector2<f64>) -> f64 {
        let o = &self.options;
        let stance = feet[swing.other().index()];
        let secs = o.recovery_double_support_secs + o.recovery_swing_secs;
        let (landing, xi_td) = self.recovery_landing(&stance, swing, dcm, secs);
        let mut landed = [stance; 2];
        landed[swing.index()] = Foothold { side: swing, pos: landing, yaw: stance.yaw };
        (xi_td - self.clamp_to_support(xi_td, &landed)).norm()
    }

    /// Which foot swings first: after a push (`push`: the measured DCM) the one whose step
    /// leaves the capture point predicted at touchdown least outside the feet
    /// ([`Walker::recovery_miss`]): a foot that would have to cross the other to get under it
    /// (a sideways push toward the stance foot) can't, and stepping it in place again and
    /// again lets the DCM run away. When both do equally well, the foot farther from the DCM,
    /// so that the stance foot's ankle holds what it can while the swing foot catches the
    /// rest (stepping with the nearer foot puts the ZMP on the far one, and the DCM runs away
    /// faster than a step can follow); else toward the commanded side or turn.
    fn first_swing(&self, push: Option<Vector2<f64>>, feet: &[Foothold; 2]) -> Side {
        match push {
            Some(dcm) => {
                let (ml, mr) = (self.recovery_miss(feet, Side::Left, dcm), self.recovery_miss(feet, Side::Right, dcm));
                if (ml - mr).abs() > RECOVERY_MISS_TIE_M {
                    return if ml < mr { Side::Left } else { Side::Right };
                }
                let gap = |f: &Foothold| (self.clamp_to_sole(f, dcm) - dcm).norm();
                let (gl, gr) = (gap(&feet[0]), gap(&feet[1]));
                if (gl - gr).abs() > 1e-3 {
                    return if gl < gr { Side::Right } else { Side::Left };
                }
                // Equally near (a push straight ahead or back): the foot away from the
                // DCM's sideways offset swings.
                let mid = (feet[0].pos + feet[1].pos) / 2.0;
                let lateral = rotation(-(feet[0].yaw + feet[1].yaw) / 2.0) * (dcm - mid);
                if lateral.y >= 0.0 { Side::Right } else { Side::Left }
            }
            None if self.command.vy < 0.0 || self.command.yaw_rate < 0.0 => Side::Right,
            None => Side::Left,
        }
    }

    /// The walking step `step` with its landing spot, and when the spot alone can't absorb
    /// it its touchdown time, corrected for the measured DCM `dcm` at `t` (Khadiv et al. 2016):
    /// the DCM error against the step's reference as planned ([`Track`]), carried to touchdown
    /// under the stance ankle's ZMP feedback ([`dcm_error_ahead`], stance-foot frame), gives the
    /// DCM at touchdown `ξ_T`; the foot lands at `ξ_T − b`, `b` the plan's offset of the DCM from
    /// the landing foot, within `max_step_adjust` of the planned spot and without crossing the
    /// stance foot. When that bound cuts the correction, an earlier touchdown (down to a
    /// `min_single_support_secs` swing) that leaves less of it uncorrected is taken: the error
    /// grows as `e^(ω·t)` while the foot swings.
    fn corrected_step(&self, step: &Step, t: f64, dcm: Vector2<f64>) -> Step {
        let o = &self.options;
        let tr = &self.track;
        let omega = self.omega;
        let planned = Step { ss: tr.end_secs - step.start - step.ds, ..*step };
        let (xi_ref, _) = planned.dcm(t, tr.end_dcm, omega);
        let to_world = rotation(step.stance.yaw);
        let err = to_world.inverse() * (dcm - xi_ref);
        let half = self.body.legs[step.stance.side.index()].sole_half;
        let gain = 1.0 + o.dcm_zmp_gain / omega;
        let reach = 0.8 * o.step_adjust_ankle;
        let u = step.stance.pos;
        let zmp = step.zmp_point();
        let side = step.swing_to.side.sign();
        let ss_start = step.start + step.ds;
        let earliest = (ss_start + o.min_single_support_secs)
            .max(t + (1.0 - self.swing_s) * o.min_single_support_secs)
            .min(step.end());
        // (uncorrected part, touchdown time, landing spot), from the current touchdown on.
        let mut best = (f64::INFINITY, step.end(), step.swing_to.pos);
        const CANDIDATES: usize = 6;
        for k in 0..CANDIDATES {
            let end = step.end() - (step.end() - earliest) * k as f64 / (CANDIDATES - 1) as f64;
            let tau = (end - t).max(0.0);
            let ahead = Vector2::new(
                dcm_error_ahead(err.x, reach * half[0], gain, omega, tau),
                dcm_error_ahead(err.y, reach * half[1], gain, omega, tau),
            );
            let xi_td = zmp + (tr.end_dcm - zmp) * (omega * (end - tr.end_secs)).exp() + to_world * ahead;
            let wanted = (xi_td - tr.end_dcm) * o.step_adjust_gain;
            let mut adjust = wanted;
            if adjust.norm() > o.max_step_adjust {
                adjust *= o.max_step_adjust / adjust.norm();
            }
            // Keep the feet from crossing: at least 2/3 of the step width apart sideways.
            let rel = to_world.inverse() * (tr.landing + adjust - u);
            let lateral = side * (side * rel.y).max(o.step_width * 2.0 / 3.0);
            let target = u + to_world * Vector2::new(rel.x, lateral);
            let left = (tr.landing + wanted - target).norm();
            // A later touchdown unless an earlier one leaves at least 1 mm less.
            if left < best.0 - 1e-3 {
                best = (left, end, target);
            }
            if left < 1e-3 || end <= earliest {
                break;
            }
        }
        Step { ss: best.1 - ss_start, swing_to: Foothold { pos: best.2, ..step.swing_to }, ..*step }
    }

    /// The walking step `step` with its landing spot moved fore-aft by `progress_hold_gain` of
    /// the gap between its stance foot as aimed (`aimed`, the previous step's corrected landing
    /// spot) and as landed, at most `max_step_adjust`: the advance the command asks for then
    /// counts from the aim, so a foot that lands past its spot doesn't lengthen every step.
    fn progress_held(&self, step: Step, aimed: &Foothold) -> Step {
        let o = &self.options;
        if aimed.side != step.stance.side {
            return step;
        }
        let to_world = rotation(step.stance.yaw);
        let past_m = (to_world.inverse() * (step.stance.pos - aimed.pos)).x;
        let back_m = (-o.progress_hold_gain * past_m).clamp(-o.max_step_adjust, o.max_step_adjust);
        let pos = step.swing_to.pos + to_world * Vector2::new(back_m, 0.0);
        Step { swing_to: Foothold { pos, ..step.swing_to }, ..step }
    }

    /// Advances the steering target's integral (`command_hold_gain`) to `t` with the target
    /// `goal` while walking (not recovering from a push); standing, or with no target (a
    /// constant command), restarts it at the feet `feet` (their midpoint and mean heading).
    fn integrate_hold(&mut self, goal: Option<Command>, t: f64, feet: &[Foothold; 2]) {
        if let (Some(asked), Mode::Walking(_), false) = (goal, self.mode, self.recovering) {
            let dt = t - self.hold_secs;
            let mid_yaw = self.hold.1 + asked.yaw_rate * dt / 2.0;
            self.hold.0 += rotation(mid_yaw) * Vector2::new(asked.vx, asked.vy) * dt;
            self.hold.1 += asked.yaw_rate * dt;
        } else {
            let heading = feet[0].yaw + wrap(feet[1].yaw - feet[0].yaw) / 2.0;
            self.hold = ((feet[0].pos + feet[1].pos) / 2.0, heading);
        }
        self.asked = goal;
        self.hold_secs = t;
    }

    /// The walking step `step` with its landing moved toward where the asked command's
    /// integral will be at its touchdown (`command_hold_gain` of the gap, in position and
    /// heading; the heading measured at the stance foot): a step with a command puts the feet's
    /// centre path there (as the plan's own steps do, a step's advance after the last); a step
    /// with none, which brings the feet side by side to stand, puts their midpoint there, so
    /// that the walker stands where the integral stopped (from the centre path it would stand
    /// half the last step's overshoot past it: the last step is planned before the command
    /// stops). The step's advance stays within the step limits (or within the planned advance,
    /// when it is beyond).
    fn command_held(&self, step: Step, a: Command) -> Step {
        let o = &self.options;
        let gait = o.gait();
        let ahead = step.end() - self.hold_secs;
        let ref_yaw = self.hold.1 + a.yaw_rate * ahead;
        let ref_pos = self.hold.0 + rotation(self.hold.1 + a.yaw_rate * ahead / 2.0) * Vector2::new(a.vx, a.vy) * ahead;
        let stance_center = gait.center_of(&step.stance);
        let center = gait.center_of(&step.swing_to);
        // The feet's headings as the stance foot stands, not as planned: feet turn on the ground.
        let stance_yaw = self.foothold_of(&self.frames, step.stance.side.index()).yaw;
        let yaw = step.swing_to.yaw + wrap(stance_yaw - step.stance.yaw);
        let (gap_m, gap_rad) = if self.command.is_zero() {
            let mid_yaw = stance_yaw + wrap(yaw - stance_yaw) / 2.0;
            ((ref_pos - (stance_center + center) / 2.0) * 2.0, 2.0 * wrap(ref_yaw - mid_yaw))
        } else {
            (ref_pos - center, wrap(ref_yaw - yaw))
        };
        let k = o.command_hold_gain;
        let to_stance = rotation(-step.stance.yaw);
        let planned = to_stance * (center - stance_center);
        let held = planned + to_stance * gap_m * k;
        let within = |v: f64, planned: f64, limit: f64| v.clamp((-limit).min(planned), limit.max(planned));
        let advance =
            Vector2::new(within(held.x, planned.x, o.max_step_length), within(held.y, planned.y, o.max_step_lateral));
        let turn_planned = wrap(step.swing_to.yaw - step.stance.yaw);
        let turn = within(turn_planned + k * gap_rad, turn_planned, o.max_step_yaw);
        let swing_to = gait.foothold(
            step.swing_to.side,
            stance_center + rotation(step.stance.yaw) * advance,
            step.stance.yaw + turn,
        );
        Step { swing_to, ..step }
    }

    /// The command of the step about to be planned, moved toward the steering `goal` by at most
    /// the acceleration limits over one step period ([`steer::ramp`]): the steps' advance is
    /// what the command sets, and it changes once per step.
    fn steer_step(&mut self, goal: Command) {
        let o = &self.options;
        let next = steer::ramp(self.command, goal, o.step_period, o.max_accel_mps2, o.max_yaw_accel_radps2);
        if next != self.command {
            self.set_command(next);
        }
    }

    /// Starts a step with `swing` swinging from the feet `feet` at `t`.
    fn start_step(&mut self, t: f64, feet: &[Foothold; 2], swing: Side, ds: f64, zmp_from: Vector2<f64>) {
        let mut step = self.first_step(t, feet, swing, ds, zmp_from);
        if let (Mode::Walking(prev), false) = (self.mode, self.recovering) {
            step = self.progress_held(step, &prev.swing_to);
        }
        if let (Some(asked), false, true) = (self.asked, self.recovering, self.options.command_hold_gain > 0.0) {
            step = self.command_held(step, asked);
        }
        if self.recovering {
            // A recovery step: quick, since the DCM diverges meanwhile.
            step.ds = self.options.recovery_double_support_secs;
            step.ss = self.options.recovery_swing_secs;
            // Its ZMP goes where the DCM needs it, not to a planned point.
            step.zmp_inward = 0.0;
        }
        self.mode = Mode::Walking(step);
        self.step_zero = self.command.is_zero();
        self.swing_s = 0.0;
        self.swing_t = t;
        self.touchdown_planned = None;
        self.search[swing.index()] = None;
        self.landing[swing.index()] = None;
        self.state.steps += 1;
    }
}

impl Walker {
    /// Feet whose step ended before they landed (`touchdown_from_contact`): each one's target
    /// goes on down from where it was to land until it lands or has gone `touchdown_reach_m`
    /// down; then its sole's height is the ground under it. Updates `foot_ground` and the
    /// soles' motion state.
    fn landing_feet(&mut self, sensordata: &[f64], t: f64, foot_ground: &mut [f64; 2], swinging: Option<usize>) {
        let z = [self.sole_world(&self.frames, 0).z, self.sole_world(&self.frames, 1).z];
        self.contact.update(z, self.dt);
        for leg in 0..2 {
            let (Some(planned), Some((_, base))) = (self.landing[leg], self.search[leg]) else { continue };
            if swinging == Some(leg) {
                continue;
            }
            let gap = z[leg] - self.target_z[leg];
            if self.contact.landed(leg, sensordata, 1.0, gap, true) {
                self.foot_landed(leg, t, planned, true);
            } else if self.search_depth(leg, t) >= self.options.touchdown_reach_m {
                self.foot_landed(leg, t, planned, false);
            } else {
                foot_ground[leg] = base - self.search_depth(leg, t);
            }
        }
    }

    /// The part of a step's swing in which its foot's profile comes down to where it is to
    /// land: all of it, or [`TOUCHDOWN_PROFILE_END`] with `touchdown_from_contact`.
    fn profile_end(&self) -> f64 {
        if self.options.touchdown_from_contact { TOUCHDOWN_PROFILE_END } else { 1.0 }
    }

    /// The current step's end moved by its swing foot's contact (`touchdown_from_contact`):
    /// to now when the foot has landed, past now while a late foot goes on down looking for
    /// the ground (until it has gone `touchdown_reach_m` below its planned height).
    fn touchdown_timing(&mut self, mut step: Step, t: f64, sensordata: &[f64]) -> Step {
        let leg = step.swing_to.side.index();
        let gap = self.sole_world(&self.frames, leg).z - self.target_z[leg];
        if self.contact.landed(leg, sensordata, self.swing_s, gap, self.search[leg].is_some()) {
            self.touchdown_planned.get_or_insert(step.end());
            step.ss = step.ss.min((t - step.start - step.ds).max(0.0));
        }
        step
    }

    /// A foot landed (`touchdown_from_contact`): its sole's height is the ground under it, and
    /// the touch-down is logged.
    fn foot_landed(&mut self, leg: usize, t: f64, planned_secs: f64, from_contact: bool) {
        let sole = self.sole_world(&self.frames, leg);
        self.ground_z[leg] = self.ground_at(sole.z);
        self.search[leg] = None;
        self.landing[leg] = None;
        self.log_touchdown(TouchdownEvent {
            time_secs: t,
            planned_secs,
            leg,
            sole_world_m: [sole.x, sole.y, sole.z],
            from_contact,
            ground_m: self.ground_z[leg],
            ground_secs: t,
        });
    }

    /// Keeps `event` in [`WalkerState::touchdowns`] (the last [`MAX_TOUCHDOWN_LOG`]).
    fn log_touchdown(&mut self, event: TouchdownEvent) {
        if self.state.touchdowns.len() >= MAX_TOUCHDOWN_LOG {
            self.state.touchdowns.remove(0);
        }
        self.state.touchdowns.push(event);
    }

    /// How far below where it was to land foot `leg`'s target has gone looking for the
    /// ground at `t`, m (0 when it is not looking).
    fn search_depth(&self, leg: usize, t: f64) -> f64 {
        self.search[leg]
            .map_or(0.0, |(from, _)| (TOUCHDOWN_SEARCH_MPS * (t - from)).min(self.options.touchdown_reach_m))
    }

    /// The ground `step`'s swing foot is to land on (`follow_ground`): the stance foot's,
    /// going on rising or falling as under the last footholds (`ground_slope_gain`).
    fn landing_ground(&self, step: &Step) -> f64 {
        let mut other = self.ground_z[step.stance.side.index()];
        if self.options.ground_slope_gain != 0.0 {
            let along = Vector2::new(step.stance.yaw.cos(), step.stance.yaw.sin());
            other += self.options.ground_slope_gain
                * self.ground_slope(along)
                * (step.swing_to.pos - step.stance.pos).dot(&along);
        }
        other
    }

    /// The ground a sole resting at height `z` (world, m) stands on: the starting soles' level
    /// within [`GROUND_DEADBAND_M`] of it (flat ground), else `z`.
    fn ground_at(&self, z: f64) -> f64 {
        if (z - self.sole_z).abs() <= GROUND_DEADBAND_M { self.sole_z } else { z }
    }

    /// Whether foot `leg`'s sole rests on the ground (`follow_ground`): level within
    /// [`GROUND_READ_MAX_TILT_RAD`] (not on an edge, heel or toe) and still for
    /// [`GROUND_READ_STILL_SECS`].
    fn sole_at_rest(&self, leg: usize) -> bool {
        let l = &self.body.legs[leg];
        let sole_up = self.frames.xrot[l.foot] * l.foot_rot_home.inverse() * Vector3::z();
        sole_up.z >= GROUND_READ_MAX_TILT_RAD.cos() && self.sole_still_secs[leg] >= GROUND_READ_STILL_SECS
    }

    /// Whether the ground under the footholds rises: the stance foot's last mid-stance read is
    /// more than [`GROUND_RISE_M`] above its previous one (false without reads).
    fn ground_rising(&self) -> bool {
        matches!(self.ground_reads, [Some((_, z0)), _, Some((_, z2))] if z2 - z0 > GROUND_RISE_M)
    }

    /// The ground's slope along `along` (a unit vector) under the last three ground reads,
    /// rise per metre: the mean of the last two steps' slopes when they agree in sign and
    /// within [`GROUND_SLOPE_AGREEMENT`] of the steeper, each step at least
    /// [`GROUND_SLOPE_MIN_BASE_M`] long; 0 otherwise (a single step up, rough ground, flat).
    fn ground_slope(&self, along: Vector2<f64>) -> f64 {
        let [Some((p0, z0)), Some((p1, z1)), Some((p2, z2))] = self.ground_reads else { return 0.0 };
        let (d0, d1) = ((p1 - p0).dot(&along), (p2 - p1).dot(&along));
        if d0.abs() < GROUND_SLOPE_MIN_BASE_M || d1.abs() < GROUND_SLOPE_MIN_BASE_M {
            return 0.0;
        }
        let (s0, s1) = ((z1 - z0) / d0, (z2 - z1) / d1);
        let steeper = s0.abs().max(s1.abs());
        if s0 * s1 <= 0.0 || (s1 - s0).abs() > GROUND_SLOPE_AGREEMENT * steeper {
            return 0.0;
        }
        ((s0 + s1) / 2.0).clamp(-MAX_GROUND_SLOPE, MAX_GROUND_SLOPE)
    }
}

/// Smoothstep on [0, 1].
fn smooth(a: f64) -> f64 {
    let a = a.clamp(0.0, 1.0);
    a * a * (3.0 - 2.0 * a)
}

impl Controller for Walker {
    fn name(&self) -> &'static str {
        "walk"
    }

    fn reset(&mut self, model: &Model, observation: &Observation<'_>) -> Result<()> {
        // Masses, inertias and gains may differ per episode (randomization): rebuild for `model`.
        // A schedule starts over; a live target and a set command carry on.
        let command = if self.options.commands.is_empty() { self.command } else { self.options.command() };
        let (steer_target, clamped) = (self.steer_target, self.state.commands_clamped);
        *self = Walker::build(model, WalkOptions::clone(&self.options), false)?;
        self.command = command;
        self.steer_target = steer_target;
        self.t0 = observation.time_secs;
        self.tree.forward(observation.qpos, &mut self.frames);
        let com = self.frames.com();
        self.axes = [PreviewAxis::at(com.x), PreviewAxis::at(com.y)];
        self.com_prev = None;
        self.com_vel = Vector3::zeros();
        let pelvis = self.frames.xpos[self.body.pelvis];
        let yaw = self.frames.xrot[self.body.pelvis].euler_angles().2;
        let d = rotation(-yaw) * Vector2::new(pelvis.x - com.x, pelvis.y - com.y);
        self.pelvis_from_com = Vector3::new(d.x, d.y, pelvis.z - com.z);
        self.pelvis_z0 = pelvis.z;
        self.sole_z = (self.sole_world(&self.frames, 0).z + self.sole_world(&self.frames, 1).z) / 2.0;
        // `com_height` is above the ground under the feet at the start when following the
        // ground (a start on a step or a hill), above the floor (z = 0) otherwise.
        let start_ground = if self.options.follow_ground { self.sole_z } else { 0.0 };
        self.pelvis_z = start_ground + self.options.com_height + (pelvis.z - com.z);
        self.ground_z = [self.sole_z; 2];
        self.ground_ref = 0.0;
        self.ground_pitch = 0.0;
        self.ground_reads = [None; 3];
        self.ground_read_done = false;
        self.sole_still_secs = [0.0; 2];
        self.ground_pending = [false; 2];
        self.sole_prev_z = [self.sole_world(&self.frames, 0).z, self.sole_world(&self.frames, 1).z];
        for ik in &self.ik {
            for k in 0..ik.len() {
                let a = ik.qpos_adr(k);
                self.q_des[a] = observation.qpos[a];
            }
        }
        self.mode = Mode::Standing;
        let feet = [self.foothold_of(&self.frames, 0), self.foothold_of(&self.frames, 1)];
        self.planted = feet;
        self.schedule = Schedule::default();
        self.replan(0.0, &feet);
        self.schedule.rest_from = self.schedule.rest;
        self.tick = 0;
        self.state = WalkerState { commands_clamped: clamped, ..WalkerState::default() };
        Ok(())
    }

    fn compute(&mut self, _model: &Model, observation: &Observation<'_>, command: &mut [f64]) {
        if self.tick > 0 && self.held.since + 1 < self.options.plan_every_ticks {
            // Between solves (`plan_every_ticks`): the joint PD, toward the last solve's
            // targets moved by the tilt feedback since.
            self.held.since += 1;
            self.hold_targets(observation);
            self.joint_torques(observation, command);
            self.publish_diagnostics(observation.time_secs);
            self.physics_tick += 1;
            return;
        }
        let t = observation.time_secs - self.t0;
        let o = Arc::clone(&self.options);
        let gait = o.gait();
        // 0. Steering: the live target or the schedule's, taken step by step (below).
        let goal = self.steer_target.or_else(|| steer::scheduled(&o.commands, t));
        // 1. State.
        self.tree.forward(observation.qpos, &mut self.frames);
        let com = self.frames.com();
        if let Some(prev) = self.com_prev {
            let raw = (com - prev) / self.dt;
            let alpha = self.dt / (self.dt + 0.01);
            self.com_vel += (raw - self.com_vel) * alpha;
        }
        self.com_prev = Some(com);
        let dcm = Vector2::new(com.x + self.com_vel.x / self.omega, com.y + self.com_vel.y / self.omega);
        let feet = [self.foothold_of(&self.frames, 0), self.foothold_of(&self.frames, 1)];
        if o.command_hold_gain > 0.0 {
            self.integrate_hold(goal, t, &feet);
        }

        // 3. Step timing: touchdown, start, stop.
        let mut replan = self.tick == 0;
        // A walking step (not a recovery one) started: its reference is set after the replan.
        let mut new_step = false;
        match self.mode {
            Mode::Standing => {
                let ready = t >= o.settle_secs;
                if let (Some(goal), true) = (goal, ready) {
                    self.steer_step(goal);
                }
                let push = ready && !self.inside_support(dcm, &feet, o.recovery_margin);
                if push {
                    self.recovering = true;
                    // Plan from where the push left the body: the reference restarts at the
                    // measured CoM state, so the feedback does not pull it back to a stale one.
                    self.restart_preview(com);
                }
                if ready && !push && !self.command.is_zero() && self.straight() && self.line.is_none() {
                    // The line to hold: through the feet's midpoint along their mean heading.
                    let heading = feet[0].yaw + wrap(feet[1].yaw - feet[0].yaw) / 2.0;
                    self.line = Some(((feet[0].pos + feet[1].pos) / 2.0, heading));
                }
                if ready && (!self.command.is_zero() || push) {
                    // Step toward where the body is falling, or as planned.
                    let swing = self.first_swing(push.then_some(dcm), &feet);
                    let ds = o.start_double_support;
                    let zmp_from = self.schedule.zmp(t, &mut 0);
                    self.start_step(t, &feet, swing, ds, zmp_from);
                    replan = true;
                    if !push {
                        (self.first_step, self.first_swing_off_m) = (true, 0.0);
                        // Walking takes over the preview's CoM reference where it is.
                        self.track.com = Vector2::new(self.axes[0].x[0], self.axes[1].x[0]);
                        new_step = true;
                    }
                }
            }
            Mode::Walking(mut step) => {
                if o.touchdown_from_contact {
                    step = self.touchdown_timing(step, t, observation.sensordata);
                    self.mode = Mode::Walking(step);
                }
                if t >= step.end() {
                    if std::mem::take(&mut self.first_step) && !self.recovering {
                        let sole_m = 2.0 * self.body.legs[step.swing_to.side.index()].sole_half[0];
                        self.track_swing_velocity |= self.first_swing_off_m > o.swing_miss_fraction * sole_m;
                    }
                    if let (Some(goal), false) = (goal, self.recovering) {
                        self.steer_step(goal);
                    }
                    // Touchdown: the landed foot is planted where it actually is.
                    let mut now = feet;
                    now[step.stance.side.index()] = step.stance;
                    // The landed foot's heading is the plan's: measured ones let it drift.
                    now[step.swing_to.side.index()].yaw = step.swing_to.yaw;
                    self.planted = now;
                    // Blind on uneven ground: the landed foot's ground is where its sole is.
                    let landed = step.swing_to.side.index();
                    if o.stride_hold_gain > 0.0 && !self.recovering {
                        self.hold_stride(&step, &feet[landed]);
                    }
                    if o.touchdown_from_contact {
                        // Landed (ended by contact), or still on its way down: its target goes on
                        // down into the next step until it lands.
                        match self.touchdown_planned {
                            Some(planned) => self.foot_landed(landed, t, planned, true),
                            None => {
                                self.landing[landed] = Some(step.end());
                                self.search[landed] = Some((t, self.target_z[landed]));
                            }
                        }
                    } else {
                        let sole = self.sole_world(&self.frames, landed);
                        // In the air: by the foot's sensors where it has them, else still coming down.
                        let airborne = match self.contact.on_ground(landed, observation.sensordata) {
                            Some(on) => !on,
                            None => sole.z - self.sole_prev_z[landed] < -GROUND_READ_MAX_SPEED_MPS * self.dt,
                        };
                        if o.follow_ground && o.landing_read_at_rest && airborne {
                            // In the air: the ground it aimed at, until it is down and still.
                            self.ground_z[landed] = self.landing_ground(&step);
                            self.ground_pending[landed] = true;
                        } else if o.follow_ground {
                            self.ground_z[landed] = self.ground_at(sole.z);
                        }
                        self.log_touchdown(TouchdownEvent {
                            time_secs: t,
                            planned_secs: step.end(),
                            leg: landed,
                            sole_world_m: [sole.x, sole.y, sole.z],
                            from_contact: false,
                            ground_m: if o.follow_ground { self.ground_z[landed] } else { sole.z },
                            ground_secs: t,
                        });
                    }
                    if self.recovering && self.inside_support(dcm, &now, o.recovery_margin) {
                        // Stop: the ZMP moves from under the DCM to between the feet, and the
                        // reference restarts at the measured state.
                        self.mode = Mode::Standing;
                        self.schedule.steps.clear();
                        self.schedule.rest_from = self.clamp_to_support(dcm, &now);
                        self.schedule.rest_start = t;
                        self.restart_preview(com);
                        self.recovering = false;
                    } else if !self.recovering
                        && self.step_zero
                        && self.command.is_zero()
                        && self.inside_support(dcm, &now, o.recovery_margin)
                    {
                        // Told to stop, and the feet are side by side: stand where they are.
                        self.mode = Mode::Standing;
                        self.schedule.steps.clear();
                        self.schedule.rest_from = self.clamp_to_support(dcm, &now);
                        self.schedule.rest_start = t;
                        self.restart_preview(com);
                    } else {
                        let swing = if self.recovering { self.first_swing(Some(dcm), &now) } else { step.stance.side };
                        self.start_step(t, &now, swing, gait.ds_secs(), step.zmp_point());
                        new_step = !self.recovering;
                    }
                    replan = true;
                } else if self.recovering
                    && step.swing_phase(t) > 0.0
                    && step.swing_phase(t) < o.recovery_reach_fraction * 2.0 / 3.0
                {
                    // Recovery step: land under the capture point predicted at touchdown, moved
                    // until the foot is 2/3 of the way there (later moves would jerk it).
                    let (landing, _) = self.recovery_landing(&step.stance, step.swing_to.side, dcm, step.end() - t);
                    let mut adjusted = step;
                    adjusted.swing_to.pos = landing;
                    self.mode = Mode::Walking(adjusted);
                    replan = true;
                } else if !self.recovering && self.swing_s < o.step_adjust_until * self.profile_end() {
                    let corrected = self.corrected_step(&step, t, dcm);
                    self.mode = Mode::Walking(corrected);
                    // While tracking a walking step only the step itself (the mode) steers; the
                    // schedule after it is telemetry (the planned footholds), rebuilt when the
                    // landing or touchdown has moved by a millimetre or millisecond since.
                    replan = self.schedule.steps.first().is_none_or(|p| {
                        (p.swing_to.pos - corrected.swing_to.pos).norm() > 1e-3
                            || (p.end() - corrected.end()).abs() > 1e-3
                    });
                }
            }
        }
        if replan {
            let rest_from = self.schedule.rest_from;
            let rest_start = self.schedule.rest_start;
            self.replan(t, &feet);
            self.schedule.rest_from = rest_from;
            self.schedule.rest_start = rest_start;
        }
        if new_step && let Mode::Walking(step) = self.mode {
            self.track.end_dcm = self.schedule.first_end_dcm(self.omega);
            self.track.end_secs = step.end();
            self.track.landing = step.swing_to.pos;
        }
        let tracking = matches!(self.mode, Mode::Walking(_)) && !self.recovering;

        // 4. Preview control at its own rate; the CoM reference in between is extrapolated.
        let ratio = self.preview_ratio;
        let pdt = self.dt * ratio as f64;
        if !tracking && self.tick.is_multiple_of(ratio) {
            let mut cursor = 0;
            for j in 0..self.zmp_buf[0].len() {
                let z = self.schedule.zmp(t + j as f64 * pdt, &mut cursor);
                self.zmp_buf[0][j] = z.x;
                self.zmp_buf[1][j] = z.y;
            }
            for a in 0..2 {
                self.axes[a].step(&self.preview, &self.zmp_buf[a]);
            }
        }
        let tau = (self.tick % ratio) as f64 * self.dt;
        let extrapolate = |a: &PreviewAxis| (a.x[0] + a.x[1] * tau + a.x[2] * tau * tau / 2.0, a.x[1] + a.x[2] * tau);
        let (cx, vx) = extrapolate(&self.axes[0]);
        let (cy, vy) = extrapolate(&self.axes[1]);
        let com_ref = Vector2::new(cx, cy);
        let dcm_ref = com_ref + Vector2::new(vx, vy) / self.omega;
        let dcm_err = dcm - dcm_ref;
        let (com_ref, dcm_ref, dcm_err, zmp_ref) = match self.mode {
            Mode::Walking(step) if self.recovering => {
                // Recovery step: no reference to return to. The DCM, with the ZMP on the
                // planned path, reaches `ξ_td` at touchdown; only the part of it outside the
                // support the landing foot will give is an error, corrected through the ZMP
                // (ankles) now.
                let decay = (-self.omega * (step.end() - t).max(0.0)).exp();
                let p = self.clamp_to_sole(&step.stance, dcm);
                let xi_td = p + (dcm - p) / decay;
                let mut landed = [step.stance; 2];
                landed[step.swing_to.side.index()] = step.swing_to;
                let err = (xi_td - self.clamp_to_support(xi_td, &landed)) * decay;
                (com.xy(), dcm - err, err, p)
            }
            Mode::Walking(step) => {
                let end = self.track.end_dcm + (step.swing_to.pos - self.track.landing);
                let (xi_ref, p_ref) = step.dcm(t, end, self.omega);
                let decay = (-self.omega * self.dt).exp();
                self.track.com = xi_ref + (self.track.com - xi_ref) * decay;
                (self.track.com, xi_ref, dcm - xi_ref, p_ref)
            }
            _ => (com_ref, dcm_ref, dcm_err, self.schedule.zmp(t, &mut 0)),
        };
        let zmp_cmd = zmp_ref + dcm_err * (1.0 + o.dcm_zmp_gain / self.omega);
        let com_cmd = com_ref - dcm_err * o.dcm_com_gain;

        // 5. Targets: feet, pelvis.
        let (stance_side, swing) = match self.mode {
            Mode::Walking(step) => (Some(step.stance.side), Some(step)),
            Mode::Standing => (None, None),
        };
        let mut foot_targets = [(self.planted[0], 0.0), (self.planted[1], 0.0)];
        // Ground under each foot target: a swinging foot goes from its own ground to the stance
        // foot's (the ground ahead taken as level with the stance foot's: blind).
        let mut foot_ground = self.ground_z;
        let mut swinging: Option<usize> = None;
        if let Some(step) = swing {
            foot_targets[step.stance.side.index()] = (step.stance, 0.0);
            let s_before = self.swing_s;
            let ss_start = step.start + step.ds;
            if t <= ss_start {
                self.swing_s = 0.0;
            } else {
                // (1 − s) shrinks with the time left, whatever the end is now.
                let (left, before) = (step.end() - t, step.end() - self.swing_t.max(ss_start));
                self.swing_s =
                    if left <= 0.0 || before <= 0.0 { 1.0 } else { 1.0 - (1.0 - self.swing_s) * left / before };
            }
            self.swing_t = t;
            let s = self.swing_s;
            if s_before < GROUND_READ_PHASE[0] {
                self.ground_read_done = false;
            }
            if o.follow_ground
                && o.stance_ground_read
                && !self.ground_read_done
                && (GROUND_READ_PHASE[0]..GROUND_READ_PHASE[1]).contains(&s)
            {
                // In single support the weight is on the stance foot, so it is on the ground:
                // its sole's height is the ground under it (read once a step, in mid stance, so
                // that a foot that landed in the air, or before its ground, is corrected once
                // loaded).
                // A sole tilted beyond any slope the walker follows stands on an edge or a heel:
                // its height is no ground (the landing's read stays).
                let stance = step.stance.side.index();
                let z = self.sole_world(&self.frames, stance).z;
                if self.sole_at_rest(stance) {
                    self.ground_read_done = true;
                    self.ground_pending[stance] = false;
                    self.ground_z[stance] = self.ground_at(z);
                    foot_ground[stance] = self.ground_z[stance];
                    self.ground_reads = [self.ground_reads[1], self.ground_reads[2], Some((feet[stance].pos, z))];
                }
            }
            // From contact, the swing's profile reaches the ground early and the target then goes on
            // down until the foot lands ([`contact::TOUCHDOWN_PROFILE_END`]).
            let s_profile = if o.touchdown_from_contact { s / TOUCHDOWN_PROFILE_END } else { s };
            let (mut blend, lift) = swing_profile(s_profile);
            if self.recovering {
                // A recovery step's foot gets over its landing spot early, then comes down.
                blend = swing_profile(s / o.recovery_reach_fraction).0;
            }
            let from = step.swing_from;
            let to = step.swing_to;
            let pos = from.pos + (to.pos - from.pos) * blend;
            let yaw = from.yaw + wrap(to.yaw - from.yaw) * blend;
            foot_targets[to.side.index()] = (Foothold { side: to.side, pos, yaw }, lift * o.foot_clearance);
            let (own, other) = (self.ground_z[to.side.index()], self.landing_ground(&step));
            foot_ground[to.side.index()] = own + (other - own) * blend;
            if o.step_down_reach > 0.0 && !self.ground_rising() {
                // Late in the swing the foot keeps going down past the stance foot's ground
                // (not on ground known to rise: there it would push the foot into the slope).
                foot_ground[to.side.index()] -= o.step_down_reach * blend;
            }
            if o.swing_holds_at_contact {
                let leg = to.side.index();
                if s < contact::TOUCHDOWN_ARM_PHASE {
                    self.swing_contact_z[leg] = None;
                } else if self.swing_contact_z[leg].is_none()
                    && self.contact.on_ground(leg, observation.sensordata) == Some(true)
                {
                    self.swing_contact_z[leg] = Some(self.sole_world(&self.frames, leg).z);
                }
                if let Some(z) = self.swing_contact_z[leg] {
                    let lift = foot_targets[leg].1;
                    foot_ground[leg] = foot_ground[leg].max(z - lift);
                }
            }
            if s > 0.0 && s < 1.0 {
                swinging = Some(to.side.index());
                if self.first_step {
                    // How far the foot is off its trajectory, along the swing.
                    let along = (to.pos - from.pos).try_normalize(1e-9).unwrap_or_default();
                    let off = (self.sole_world(&self.frames, to.side.index()).xy() - pos).dot(&along);
                    self.first_swing_off_m = self.first_swing_off_m.max(off.abs());
                }
            }
        }
        if o.touchdown_from_contact {
            self.landing_feet(observation.sensordata, t, &mut foot_ground, swinging);
        }
        if o.follow_ground {
            for (leg, ground) in foot_ground.iter_mut().enumerate() {
                let z = self.sole_world(&self.frames, leg).z;
                let moved = (z - self.sole_prev_z[leg]).abs() > GROUND_READ_MAX_SPEED_MPS * self.dt;
                self.sole_still_secs[leg] = if moved { 0.0 } else { self.sole_still_secs[leg] + self.dt };
                self.sole_prev_z[leg] = z;
                if self.ground_pending[leg] && swinging == Some(leg) {
                    self.ground_pending[leg] = false;
                } else if self.ground_pending[leg]
                    && !moved
                    && self.contact.on_ground(leg, observation.sensordata) != Some(false)
                {
                    // A foot that came down after its planned touchdown, now stopped on its ground
                    // (and, with foot sensors, carrying load).
                    self.ground_pending[leg] = false;
                    self.ground_z[leg] = self.ground_at(z);
                    *ground = self.ground_z[leg];
                    if let Some(e) = self.state.touchdowns.iter_mut().rev().find(|e| e.leg == leg) {
                        (e.ground_m, e.ground_secs) = (self.ground_z[leg], t);
                    }
                }
            }
        }
        let yaw_l = foot_targets[0].0.yaw;
        let yaw_r = foot_targets[1].0.yaw;
        let heading = yaw_r + wrap(yaw_l - yaw_r) / 2.0;
        let (tilt_raw, rate_raw) = self.tilt(observation);
        let (lean, tilt, rate) =
            self.hip_lean(zmp_cmd, dcm, &feet, swinging.and(stance_side), heading, tilt_raw, rate_raw);
        // (Without a lean the correction alone, bit for bit.)
        let lean_plus = |k: usize, c: f64| if lean[k] == 0.0 { c } else { lean[k] + c };
        let correction = self.tilt_correction(tilt, rate);
        let pelvis_rot = kin::euler_quat(0.0, 0.0, heading)
            * kin::euler_quat(lean_plus(0, correction[0]), lean_plus(1, correction[1]), 0.0);
        let off = rotation(heading) * self.pelvis_from_com.xy();
        let crouch = smooth(t / o.settle_secs.max(1e-9));
        let pelvis_z = self.pelvis_z0 + (self.pelvis_z - self.pelvis_z0) * crouch;
        // The body rises and sinks with the ground under the planted feet.
        let ground = (self.ground_z[0] + self.ground_z[1]) / 2.0 - self.sole_z;
        self.ground_ref += (ground - self.ground_ref) * (self.dt / (self.dt + GROUND_FOLLOW_SECS));
        let pelvis_pos = Vector3::new(com_cmd.x + off.x, com_cmd.y + off.y, pelvis_z + self.ground_ref);
        // The soles pitched with the ground's slope along the heading between the planted feet
        // (ankles that follow a slope, not stand on a heel), re-estimated only over a base long
        // enough to tell a slope from the reads' errors, and followed gradually.
        if o.ground_pitch_gain != 0.0 {
            let along = Vector2::new(heading.cos(), heading.sin());
            let (d, dz) =
                ((self.planted[0].pos - self.planted[1].pos).dot(&along), self.ground_z[0] - self.ground_z[1]);
            if d.abs() >= GROUND_PITCH_MIN_BASE_M || dz == 0.0 {
                let slope = if dz == 0.0 { 0.0 } else { (dz / d).clamp(-MAX_GROUND_SLOPE, MAX_GROUND_SLOPE) };
                let wanted = -o.ground_pitch_gain * slope.atan();
                self.ground_pitch += (wanted - self.ground_pitch) * (self.dt / (self.dt + GROUND_PITCH_FOLLOW_SECS));
            }
        }
        let ground_pitch = self.ground_pitch;

        // 6. Leg IK, both legs on every solve (the physics steps between solves,
        // `plan_every_ticks`, track the last solution). The measured-pelvis weights move on
        // each solve.
        for (leg, w) in self.measured_frame.iter_mut().enumerate() {
            *w = if o.swing_from_measured_pelvis && swinging == Some(leg) {
                1.0
            } else {
                (*w - self.dt / MEASURED_FRAME_RELEASE_SECS).max(0.0)
            };
        }
        let mut ik_error: f64 = 0.0;
        for (leg, &(f, lift)) in foot_targets.iter().enumerate() {
            let l = &self.body.legs[leg];
            let rot = if ground_pitch == 0.0 {
                kin::euler_quat(0.0, 0.0, f.yaw) * l.foot_rot_home
            } else {
                kin::euler_quat(0.0, 0.0, f.yaw) * kin::euler_quat(0.0, ground_pitch, 0.0) * l.foot_rot_home
            };
            let sole = Vector3::new(f.pos.x, f.pos.y, foot_ground[leg] + lift);
            self.target_z[leg] = sole.z;
            let foot = sole - rot * l.sole_in_foot;
            let w = self.measured_frame[leg];
            let (base_pos, base_rot) = if w > 0.0 {
                let (pos, rot) = (self.frames.xpos[self.body.pelvis], self.frames.xrot[self.body.pelvis]);
                // (Half a turn apart, e.g. fallen over, has no slerp: the measured pose then.)
                (pelvis_pos.lerp(&pos, w), pelvis_rot.try_slerp(&rot, w, 1e-9).unwrap_or(rot))
            } else {
                (pelvis_pos, pelvis_rot)
            };
            let inv = base_rot.inverse();
            let target = (inv * (foot - base_pos), inv * rot);
            let ik = &self.ik[leg];
            let mut q = [0.0; 12];
            let n = ik.len().min(12);
            for (k, qk) in q.iter_mut().enumerate().take(n) {
                *qk = self.q_des[ik.qpos_adr(k)];
            }
            ik.bend_knee(&mut q[..n], 0.05);
            let r = ik.solve(target, &mut q[..n], o.ik_iterations, 1e-3);
            ik_error = ik_error.max(r.position_error_m);
            for (k, qk) in q.iter().enumerate().take(n) {
                self.q_des[ik.qpos_adr(k)] = *qk;
            }
        }
        if o.plan_every_ticks > 1 {
            let against =
                ([tilt_raw[0] - tilt[0], tilt_raw[1] - tilt[1]], [rate_raw[0] - rate[0], rate_raw[1] - rate[1]]);
            self.hold_tilt_map(observation, correction, lean_plus(0, correction[0]), against);
        }
        // The commanded configuration's CoM offset, for the next ticks: refreshed at the
        // preview rate (it changes slowly with the legs' posture; a whole-tree pass per tick
        // was a third of the walker's cost).
        if self.tick.is_multiple_of(ratio) {
            let b = self.body.base_qpos;
            self.q_des[b..b + 3].copy_from_slice(pelvis_pos.as_slice());
            let qq = pelvis_rot.into_inner();
            self.q_des[b + 3..b + 7].copy_from_slice(&[qq.w, qq.i, qq.j, qq.k]);
            let c = self.tree.com(&self.q_des, &mut self.desired);
            let d = rotation(-heading) * Vector2::new(pelvis_pos.x - c.x, pelvis_pos.y - c.y);
            self.pelvis_from_com = Vector3::new(d.x, d.y, pelvis_pos.z - c.z);
        }

        // 7. Feed-forward: gravity and the planned contact forces at the commanded ZMP.
        let weight = -self.gravity * self.tree.total_mass_kg;
        let mut forces: [(usize, Vector3<f64>, Vector3<f64>); 2] = [(0, Vector3::zeros(), Vector3::zeros()); 2];
        let nforces;
        let clamp_to_sole = |leg: usize, p: Vector2<f64>| self.clamp_to_sole(&feet[leg], p);
        match (swinging, stance_side) {
            (Some(_), Some(stance)) => {
                let i = stance.index();
                let p = clamp_to_sole(i, zmp_cmd);
                forces[0] = (self.body.legs[i].foot, Vector3::new(p.x, p.y, self.sole_z), weight);
                nforces = 1;
            }
            _ => {
                let (a, b) = (feet[0].pos, feet[1].pos);
                let ab = b - a;
                let alpha = ((zmp_cmd - a).dot(&ab) / ab.norm_squared().max(1e-9)).clamp(0.0, 1.0);
                // What the weight split can't reach (fore-aft, or beyond a foot) the ankles
                // give: each foot's force moves by it within its sole.
                let residual = if o.double_support_ankle { zmp_cmd - (a + ab * alpha) } else { Vector2::zeros() };
                for (k, (leg, w)) in [(0usize, 1.0 - alpha), (1usize, alpha)].into_iter().enumerate() {
                    let p = clamp_to_sole(leg, feet[leg].pos + residual);
                    forces[k] = (self.body.legs[leg].foot, Vector3::new(p.x, p.y, self.sole_z), weight * w);
                }
                nforces = 2;
            }
        }

        self.track_swing_velocity |= o.swing_miss_fraction == 0.0;
        if self.track_swing_velocity {
            // The targets' rate between solves, filtered (the IK's one iteration a solve
            // moves them in small, uneven steps).
            let alpha = self.dt / (self.dt + SWING_VELOCITY_FILTER_SECS);
            let h = &mut self.held;
            for (i, l) in self.loops.iter().enumerate() {
                let q = self.q_des[l.qpos_adr];
                let v = if h.q_prev[i].is_finite() { (q - h.q_prev[i]) / self.dt } else { 0.0 };
                h.qd_des[i] += (v - h.qd_des[i]) * alpha;
                h.q_prev[i] = q;
            }
        }
        // 8. PD + feed-forward.
        self.hold_feed_forward(&forces[..nforces], swinging);
        self.joint_torques(observation, command);

        // Telemetry.
        self.state.com_ref = [com_ref.x, com_ref.y, self.options.com_height];
        self.state.com = [com.x, com.y, com.z];
        self.state.zmp_ref = [zmp_ref.x, zmp_ref.y];
        self.state.zmp_cmd = [zmp_cmd.x, zmp_cmd.y];
        self.state.dcm_ref = [dcm_ref.x, dcm_ref.y];
        self.state.dcm = [dcm.x, dcm.y];
        self.state.walking = matches!(self.mode, Mode::Walking(_));
        self.state.command = [self.command.vx, self.command.vy, self.command.yaw_rate];
        self.state.ik_error_m = ik_error;
        self.state.footholds.clear();
        for s in self.schedule.steps.iter().take(6) {
            self.state.footholds.push((s.swing_to.side, [s.swing_to.pos.x, s.swing_to.pos.y], s.swing_to.yaw));
        }
        self.publish_diagnostics(observation.time_secs);
        self.tick += 1;
        self.physics_tick += 1;
    }

    /// CoM, ZMP and DCM (reference and actual) as points, the planned footsteps as poses, all
    /// in the world (`odom`) frame at 100 Hz: Foxglove and PlotJuggler plot the points'
    /// coordinates, rerun draws them in 3-D with the robot.
    fn topics(&self) -> Vec<twin_core::topics::TopicInfo> {
        use twin_core::log::typed::{PointStamped, PoseArray, RosMessage};
        use twin_core::topics::{Qos, TopicInfo, TopicKind};
        let topic = |name: &str, type_name, k| TopicInfo {
            name: name.to_string(),
            type_name,
            rate_hz: Some(DIAGNOSTICS_RATE_HZ),
            frame_id: "odom".into(),
            qos: Qos::STREAM,
            kind: TopicKind::Controller(k),
        };
        let mut topics: Vec<TopicInfo> =
            DIAGNOSTIC_POINTS.iter().enumerate().map(|(k, n)| topic(n, PointStamped::TYPE_NAME, k)).collect();
        topics.push(topic("/walk/footsteps", PoseArray::TYPE_NAME, DIAGNOSTIC_POINTS.len()));
        topics
    }

    fn diagnostics(&self, emit: &mut dyn FnMut(usize, u64, twin_core::topics::TypedMessage<'_>)) {
        let d = &self.diagnostics;
        if !d.fresh {
            return;
        }
        for (k, p) in d.points.iter().enumerate() {
            emit(k, d.stamp_nanos, twin_core::topics::TypedMessage::Point(p));
        }
        emit(DIAGNOSTIC_POINTS.len(), d.stamp_nanos, twin_core::topics::TypedMessage::Poses(&d.footsteps));
    }
}

impl Walker {
    /// The hip strategy for the model, in its home pose.
    fn new_hip(&self, model: &Model) -> hip::HipStrategy {
        let mut frames = self.tree.frames();
        self.tree.forward(&self.nominal, &mut frames);
        hip::HipStrategy::new(model, &self.tree, &frames, &self.body, -self.gravity.z)
    }

    /// The hip strategy's lean of the upper body this tick (roll, pitch, heading frame, rad),
    /// and the torso tilt and rate the tilt feedback acts on: measured against the lean, so
    /// that the feedback holds the commanded lean instead of taking it back. `stance`: the
    /// foot that alone supports (else both do). Zero, and the tilt unchanged, when off.
    ///
    /// What drives it is the commanded ZMP's distance beyond the feet, except during a recovery
    /// step: there the ZMP is planned at the stance sole's edge and the landing spot is to
    /// catch the rest, so the lean acts on the DCM beyond the stance sole and slows it while
    /// the foot swings (the landing spot follows the slower DCM, and lands nearer).
    #[allow(clippy::too_many_arguments)]
    fn hip_lean(
        &mut self,
        zmp_cmd: Vector2<f64>,
        dcm: Vector2<f64>,
        feet: &[Foothold; 2],
        stance: Option<Side>,
        heading: f64,
        tilt: [f64; 2],
        rate: [f64; 2],
    ) -> ([f64; 2], [f64; 2], [f64; 2]) {
        let o = &self.options;
        if o.hip_gain == 0.0 {
            return ([0.0; 2], tilt, rate);
        }
        // What the feet give: the forces' points (step 7) are clamped the same way.
        let wanted = if self.recovering && stance.is_some() { dcm } else { zmp_cmd };
        let held = match stance {
            Some(side) => self.clamp_to_sole(&feet[side.index()], wanted),
            None => self.clamp_to_support(wanted, feet),
        };
        let excess = rotation(-heading) * (wanted - held);
        let params =
            hip::HipParams { gain: o.hip_gain, max_lean_rad: o.hip_max_lean_rad, return_secs: o.hip_return_secs };
        let (lean, lean_rate) = self.hip.update(excess, stance.is_some(), self.dt, &params);
        ([lean.x, lean.y], [tilt[0] - lean.x, tilt[1] - lean.y], [rate[0] - lean_rate.x, rate[1] - lean_rate.y])
    }

    /// Each joint loop's feed-forward torque (gravity and the planned contact `forces` at the
    /// observed configuration, `self.frames`) and the swinging leg, kept for the joint PD
    /// ([`Walker::joint_torques`]).
    fn hold_feed_forward(&mut self, forces: &[(usize, Vector3<f64>, Vector3<f64>)], swinging: Option<usize>) {
        self.held.swinging = swinging;
        for (ff, l) in self.held.ff.iter_mut().zip(&self.loops) {
            *ff = self.tree.static_torque(&self.frames, l.joint, self.gravity, forces);
        }
        self.held.since = 0;
    }

    /// The joint PD toward the IK targets plus the held feed-forward, into `command`.
    fn joint_torques(&self, observation: &Observation<'_>, command: &mut [f64]) {
        command.fill(0.0);
        for (i, ((l, &ff), &dq)) in self.loops.iter().zip(&self.held.ff).zip(&self.held.dq).enumerate() {
            let (kp, kd, track) = match (l.leg, self.held.swinging) {
                (Some((leg, _)), Some(s)) if leg == s => (l.kp_swing, l.kd_swing, self.track_swing_velocity),
                _ => (l.kp, l.kd, false),
            };
            // (`dq` is zero on a solve's step.)
            let q_target = self.q_des[l.qpos_adr] + dq;
            let qd_target = if track { self.held.qd_des[i] } else { 0.0 };
            let tau = kp * (q_target - observation.qpos[l.qpos_adr]) - kd * (observation.qvel[l.dof] - qd_target) + ff;
            let u = match &l.servo {
                None => tau / l.gear,
                Some(servo) => servo.command_for(
                    tau / l.gear,
                    l.gear * observation.qpos[l.qpos_adr],
                    l.gear * observation.qvel[l.dof],
                ),
            };
            command[l.command] = u.clamp(l.limits[0], l.limits[1]);
        }
    }

    /// The pelvis's counter-rotation (roll, pitch, heading frame, rad) against the torso's
    /// `tilt` and its `rate` (rad, rad/s), within ±0.2 rad.
    fn tilt_correction(&self, tilt: [f64; 2], rate: [f64; 2]) -> [f64; 2] {
        let (o, g) = (&self.options, &self.tilt_rate_gains);
        [
            (-(o.tilt_gain * tilt[0] + g[0] * rate[0])).clamp(-0.2, 0.2),
            (-(o.tilt_gain * tilt[1] + g[1] * rate[1])).clamp(-0.2, 0.2),
        ]
    }

    /// On a solve's step with steps held after it (`plan_every_ticks` > 1): what the steps
    /// until the next solve need to move each leg's targets, just solved, with the tilt
    /// feedback ([`Walker::hold_targets`]). The stance leg carries the pelvis, whose commanded
    /// roll and pitch counter-rotate against the torso's tilt rate, and that loop minds the
    /// delay: held for the steps between solves it lets the walk fall more
    /// (`plan_every_ticks` docs). Linear about the solve ([`LegIk::base_motion_map`], feet held
    /// where they are): the commanded pelvis's correction `correction` (its roll `roll`, lean
    /// included), the tilt and rate offsets it was measured against (`against`) and, for a leg
    /// placed from the measured pelvis (`swing_from_measured_pelvis`), that pose.
    fn hold_tilt_map(
        &mut self,
        observation: &Observation<'_>,
        correction: [f64; 2],
        roll: f64,
        against: ([f64; 2], [f64; 2]),
    ) {
        let h = &mut self.held;
        h.correction = correction;
        (h.lean, h.lean_rate) = against;
        h.dq.fill(0.0);
        // Pelvis rotation (in its frame) per unit correction: roll about x; pitch about the
        // pitch axis, y turned by the roll (`euler_quat`: yaw · pitch · roll).
        let (sin_roll, cos_roll) = roll.sin_cos();
        h.pitch_axis = [cos_roll, -sin_roll];
        if self.tick.is_multiple_of(self.tilt_map_every) {
            for (ik, map) in self.ik.iter().zip(h.leg_maps.iter_mut()) {
                let n = ik.len().min(12);
                let mut q = [0.0; 12];
                for (k, qk) in q.iter_mut().enumerate().take(n) {
                    *qk = self.q_des[ik.qpos_adr(k)];
                }
                ik.base_motion_map(&q[..n], 1e-3, &mut map[..n]);
            }
        }
        h.measured = self.measured_frame;
        h.pelvis = h.measured.iter().any(|&w| w > 0.0).then(|| {
            let (q, b) = (observation.qpos, self.body.base_qpos);
            (Vector3::new(q[b], q[b + 1], q[b + 2]), kin::quat([q[b + 3], q[b + 4], q[b + 5], q[b + 6]]))
        });
    }

    /// On a step between solves: each leg's targets moved from the last solve's by the change
    /// of the tilt feedback's pelvis correction since (this step's IMU against the held lean),
    /// and of the measured pelvis pose for a leg placed from it, through the maps of
    /// [`Walker::hold_tilt_map`]; into `held.dq`.
    fn hold_targets(&mut self, observation: &Observation<'_>) {
        let (tilt, rate) = self.tilt(observation);
        let h = &self.held;
        let c = self.tilt_correction(
            [tilt[0] - h.lean[0], tilt[1] - h.lean[1]],
            [rate[0] - h.lean_rate[0], rate[1] - h.lean_rate[1]],
        );
        let dc = [c[0] - h.correction[0], c[1] - h.correction[1]];
        // The commanded pelvis's rotation since the solve, in its frame (x, y, z).
        let turn = [dc[0], dc[1] * h.pitch_axis[0], dc[1] * h.pitch_axis[1]];
        // The measured pelvis's motion since the solve, in its frame at the solve: a few
        // milliseconds' rotation is twice the vector part of its quaternion.
        let moved = h.pelvis.map(|(pos0, rot0)| {
            let (q, b) = (observation.qpos, self.body.base_qpos);
            let inv = rot0.inverse();
            let dp = inv * (Vector3::new(q[b], q[b + 1], q[b + 2]) - pos0);
            let dr = (inv * kin::quat([q[b + 3], q[b + 4], q[b + 5], q[b + 6]])).into_inner();
            let s = 2.0f64.copysign(dr.w);
            [dp.x, dp.y, dp.z, s * dr.i, s * dr.j, s * dr.k]
        });
        let h = &mut self.held;
        for (i, l) in self.loops.iter().enumerate() {
            let Some((leg, k)) = l.leg.filter(|&(_, k)| k < 12) else { continue };
            let m = &h.leg_maps[leg][k];
            let w = h.measured[leg];
            let mut dq = (1.0 - w) * (m[3] * turn[0] + m[4] * turn[1] + m[5] * turn[2]);
            if let (Some(v), true) = (&moved, w > 0.0) {
                dq += w * m.iter().zip(v).map(|(a, b)| a * b).sum::<f64>();
            }
            h.dq[i] = dq;
        }
    }

    /// Refreshes the diagnostic messages from this tick's state at their rate.
    fn publish_diagnostics(&mut self, time_secs: f64) {
        // Counted in physics steps: their rate whatever `plan_every_ticks` (between solves they
        // repeat the last one's state).
        let every = ((1.0 / DIAGNOSTICS_RATE_HZ) / self.physics_dt).round().max(1.0) as u64;
        let d = &mut self.diagnostics;
        d.fresh = self.physics_tick.is_multiple_of(every);
        if !d.fresh {
            return;
        }
        let stamp = (time_secs.max(0.0) * 1e9).round();
        d.stamp_nanos = stamp as u64;
        let s = &self.state;
        let z = self.sole_z;
        let values = [
            s.com,
            s.com_ref,
            [s.zmp_cmd[0], s.zmp_cmd[1], z],
            [s.zmp_ref[0], s.zmp_ref[1], z],
            [s.dcm[0], s.dcm[1], z],
            [s.dcm_ref[0], s.dcm_ref[1], z],
        ];
        for (p, v) in d.points.iter_mut().zip(values) {
            p.header.stamp_nanos = stamp as i64;
            if p.header.frame_id.is_empty() {
                p.header.frame_id = "odom".into();
            }
            p.point = v;
        }
        d.footsteps.header.stamp_nanos = stamp as i64;
        if d.footsteps.header.frame_id.is_empty() {
            d.footsteps.header.frame_id = "odom".into();
        }
        d.footsteps.poses.resize(s.footholds.len(), twin_core::log::typed::Pose::default());
        for (pose, (_, xy, yaw)) in d.footsteps.poses.iter_mut().zip(&s.footholds) {
            pose.position = [xy[0], xy[1], z];
            // (The planned yaws repeat from tick to tick: their sines are kept.)
            let (sin, cos) = kin::kept_sin_cos(yaw / 2.0);
            pose.orientation_xyzw = [0.0, 0.0, sin, cos];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn options_out_of_range_name_the_option() {
        let mut o = WalkOptions { step_period: -1.0, ..WalkOptions::default() };
        assert_eq!(o.validate().unwrap_err().0, "step_period");
        o = WalkOptions { vx: 1.0, ..WalkOptions::default() };
        let (key, message) = o.validate().unwrap_err();
        assert_eq!(key, "vx");
        assert!(message.contains("0.600 m steps"), "{message}");
        assert!(WalkOptions { vx: 0.3, ..WalkOptions::default() }.validate().is_ok());
        for bad in [0.0, 1.5, f64::NAN] {
            let o = WalkOptions { recovery_reach_fraction: bad, ..WalkOptions::default() };
            assert_eq!(o.validate().unwrap_err().0, "recovery_reach_fraction");
        }
        for bad in [0, MAX_PLAN_EVERY_TICKS + 1] {
            let o = WalkOptions { plan_every_ticks: bad, ..WalkOptions::default() };
            assert_eq!(o.validate().unwrap_err().0, "plan_every_ticks");
        }
        for bad in [-0.1, f64::NAN] {
            let o = WalkOptions { swing_miss_fraction: bad, ..WalkOptions::default() };
            assert_eq!(o.validate().unwrap_err().0, "swing_miss_fraction");
        }
        // `inf`: never switch.
        assert!(WalkOptions { swing_miss_fraction: f64::INFINITY, ..WalkOptions::default() }.validate().is_ok());
    }

    #[test]
    fn progress_command_and_stride_hold_gains_out_of_range_are_refused() {
        for bad in [-0.1, 1.5, f64::NAN] {
            let o = WalkOptions { progress_hold_gain: bad, ..WalkOptions::default() };
            assert_eq!(o.validate().unwrap_err().0, "progress_hold_gain");
            let o = WalkOptions { command_hold_gain: bad, ..WalkOptions::default() };
            assert_eq!(o.validate().unwrap_err().0, "command_hold_gain");
            let o = WalkOptions { stride_hold_gain: bad, ..WalkOptions::default() };
            assert_eq!(o.validate().unwrap_err().0, "stride_hold_gain");
        }
        let o = WalkOptions { stride_hold_step: -0.01, ..WalkOptions::default() };
        assert_eq!(o.validate().unwrap_err().0, "stride_hold_step");
        let ends = WalkOptions {
            progress_hold_gain: 1.0,
            command_hold_gain: 1.0,
            stride_hold_gain: 1.0,
            ..WalkOptions::default()
        };
        assert!(ends.validate().is_ok());
        assert!(WalkOptions { command_hold_gain: 0.0, ..WalkOptions::default() }.validate().is_ok());
    }
}
