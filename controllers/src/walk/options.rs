//! The walker's options ([`WalkOptions`]): every gait, balance and joint-loop setting with its
//! default and range, and their validation. A scenario's `[walk]` table fills them by name; what
//! it leaves unset is derived from the robot ([`super::derive`]).

use super::*;

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
    /// on flat ground for 0.133 m asked; measurements in docs/src/benchmarks-notebook.md, "Rough ground: the pace".
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
    /// is taken up at the next one; measurements in docs/src/benchmarks-notebook.md, "Walker option choices").
    #[default(1)]
    pub ik_iterations: usize,
    /// Body and sensor names overriding what the walker finds.
    #[default(BodyNames::default())]
    pub bodies: BodyNames,
    /// Part of a recovery step's swing by which the foot is over its landing spot (it comes
    /// down there for the rest); the spot follows the predicted capture point for the first
    /// 2/3 of it (default: 0.6). Spread over the whole swing, the foot's sideways move comes
    /// in its middle, fast enough to saturate the hip roll, and sideways steps land short
    /// (measurements in docs/src/benchmarks-notebook.md, "Walker option choices").
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
    /// legs every landing lands off by the stance leg's error (measurements in docs/src/benchmarks-notebook.md,
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
    /// steps stray after a push too). Measurements in docs/src/benchmarks-notebook.md, "Talos walks straight".
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
    /// docs/src/benchmarks-notebook.md, "Walker option choices").
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
    /// (8/40 against 13/40). Measurements in docs/src/benchmarks-notebook.md, "Walker velocity tracking".
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

    pub(super) fn gait(&self) -> Gait {
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
    pub(super) fn validate_hip(&self) -> std::result::Result<(), (&'static str, String)> {
        twin_core::bounds::non_negative([("hip_gain", self.hip_gain)])?;
        if !self.hip_max_lean_rad.iter().all(|m| (0.0..=1.0).contains(m)) {
            return Err(("hip_max_lean_rad", format!("must be in [0, 1] rad (got {:?})", self.hip_max_lean_rad)));
        }
        twin_core::bounds::positive([("hip_return_secs", self.hip_return_secs)])?;
        Ok(())
    }
}
