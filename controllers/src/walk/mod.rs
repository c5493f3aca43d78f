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
//! 0.8 cm back, and the next step counted from there (docs/src/benchmarks-notebook.md, "Walker velocity
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
//! it is asked (0.24 against 0.31 m/s at `--vx 0.25`). docs/src/benchmarks-notebook.md, "Romeo walking" and
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

mod build;
pub mod contact;
pub mod derive;
pub mod hip;
mod joints;
pub mod kin;
pub mod metrics;
mod options;
pub mod plan;
pub mod preview;
pub mod steer;
mod stepping;
mod tick;
use stepping::smooth;

pub use derive::Proportions;
pub use kin::{BodyNames, Side};
pub use metrics::{GaitMetrics, GaitSummary, GaitTargets, SegmentTracking};
pub use options::WalkOptions;
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
    // A drive model's `dcmotor` position loop (`gainprm` 4 and 6: kp, kd in actuator space)
    // is the same affine servo within its torque–speed envelope.
    if model.actuator_dyn(a.id) == twin_core::mj::DynType::Dcmotor {
        let p = model.actuator_gainprm()[a.id];
        return (Some(AffineServo { gain: p[4], bias: [0.0, -p[4], -p[6]] }), range);
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
