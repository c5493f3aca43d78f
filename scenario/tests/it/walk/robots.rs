//! The walker on other makers' humanoids (example-robot-data's Unitree G1, Aldebaran Romeo, PAL
//! Talos on motors and on its own servos): options derived from each robot's proportions,
//! standing, walking five metres straight, turning, and the refusals of legs it can't drive.

use super::*;

pub(super) fn example_robot(path: &str) -> PathBuf {
    crate::example_robot_data::example_robot_data().join(path)
}

/// Another maker's biped gets its walking options from its own proportions, and an option
/// its scenario sets keeps its value. The Unitree G1's hip pitch joints sit at y = ±0.064452 m
/// in its URDF (`left_hip_pitch_joint` / `right_hip_pitch_joint` origins): its step width is
/// that spacing, 0.13 m, not the shipped humanoid's 0.18 m.
#[test]
pub(super) fn another_biped_gets_options_from_its_proportions_and_keeps_the_given_ones() {
    let g1 = example_robot("g1_description/urdf/g1_29dof_rev_1_0.urdf");
    let text = format!("model = {g1:?}\nduration = 1.0\n[walk]\nstep_period = 0.5\n");
    let mut s = Scenario::parse(&scenarios().join("inline.toml"), &text).unwrap();
    let robot = s.robot(&g1).unwrap();
    s.fit_walk(&robot.model).unwrap();
    let p = twin_controllers::walk::Proportions::of(&robot.model, &s.walk.bodies).unwrap();
    println!("G1 {p:?}\n{:?}", s.walk);
    assert_eq!(s.walk.step_period, 0.5, "given: kept");
    assert!((s.walk.step_width - 0.13).abs() < 1e-12, "step width {}", s.walk.step_width);
    assert!((p.hip_spacing_m - 2.0 * 0.064452).abs() < 1e-3, "hip spacing {}", p.hip_spacing_m);
    // Lengths scale with the leg length (in 5 % steps), the walking CoM below the standing one.
    let scale = (p.leg_length_m / twin_controllers::walk::derive::REFERENCE_LEG_LENGTH_M * 20.0).round() / 20.0;
    assert!((s.walk.max_step_length - 0.2 * scale).abs() < 1e-12, "{} at scale {scale}", s.walk.max_step_length);
    assert!(s.walk.com_height < p.com_height_m, "crouch {} below standing {}", s.walk.com_height, p.com_height_m);
    // A second fit changes nothing; the walker takes the options.
    let once = s.walk.clone();
    s.fit_walk(&robot.model).unwrap();
    assert_eq!(s.walk, once);
    Walker::new(&robot.model, s.walk.clone()).unwrap();
}

/// The inline scenario `text` for the robot file `path`, its walking options derived from the
/// robot (`fit_walk`), run: the robot, the gait summary, whether every check passed, and the last
/// step.
pub(super) fn run_inline(path: &std::path::Path, text: &str) -> (twin_core::robot::Robot, GaitSummary, bool, Last) {
    let mut s = Scenario::parse(&scenarios().join("inline.toml"), text).unwrap();
    let robot = s.robot(path).unwrap();
    s.fit_walk(&robot.model).unwrap();
    let mut controller = s.controller(&robot.model).unwrap();
    let mut check = s.check(&robot.model).unwrap();
    let mut last = Last(Vec::new(), Vec::new());
    let options = SimOptions { duration_secs: s.duration_secs, seed: s.seed };
    sim::simulate_with(&robot, controller.as_mut(), &options, None, &mut |_| {}, &mut [], &mut [&mut check, &mut last])
        .unwrap();
    (robot, check.metrics.summary(), check.verdict().passed, last)
}

/// `path` stands 10 s under the walker with its derived options and no robot-specific one:
/// no fall, the pelvis upright (tilt < 0.1 rad) and above `min_height_m`.
pub(super) fn stands_ten_seconds_under_the_walker(path: &std::path::Path, min_height_m: f64) {
    let text = format!("model = {path:?}\nduration = 10.0\n[checks]\nfalls = 0\n");
    let (_, summary, passed, last) = run_inline(path, &text);
    println!("{}: {summary}", path.display());
    assert!(!summary.fell, "{summary}");
    assert!(passed);
    let q = &last.0;
    // The free joint first: position, then the quaternion w x y z; tilt = the angle between
    // the pelvis's z axis and the world's.
    let (w, x, y, z) = (q[3], q[4], q[5], q[6]);
    let up_z = 1.0 - 2.0 * (x * x + y * y) / (w * w + x * x + y * y + z * z);
    let tilt = up_z.clamp(-1.0, 1.0).acos();
    assert!(tilt < 0.1, "{}: tilt {tilt} rad", path.display());
    assert!(q[2] > min_height_m, "{}: pelvis height {} m", path.display(), q[2]);
}

/// Example-robot-data's Romeo (Aldebaran, 40.5 kg) and Unitree G1 (33 kg) stand 10 s under
/// the walker, crouched to their derived CoM heights. (The G1 did not stand a second before
/// the torso-tilt rate loop was bounded by its light pelvis: `Walker::stable_tilt_rate_gains`.)
/// Their pelvises stand 0.79 m (G1) and 0.80 m (Romeo) high in the home pose; crouched, a few
/// centimetres lower.
#[test]
pub(super) fn romeo_and_g1_stand_ten_seconds_under_the_walker() {
    stands_ten_seconds_under_the_walker(&example_robot("romeo_description/urdf/romeo.urdf"), 0.6);
    stands_ten_seconds_under_the_walker(&example_robot("g1_description/urdf/g1_29dof_rev_1_0.urdf"), 0.65);
}

/// The gait summary of `path` under the walker with its derived options and no robot-specific
/// one, for `duration_secs`, with `walk` (TOML lines of the `[walk]` table: the command).
pub(super) fn walk_with_derived_options(
    path: &std::path::Path,
    duration_secs: f64,
    walk: &str,
) -> twin_controllers::walk::GaitSummary {
    let text = format!("model = {path:?}\nduration = {duration_secs}\ncontroller = \"walk\"\n[walk]\n{walk}\n");
    let summary = derived_run(Scenario::parse(&scenarios().join("inline.toml"), &text).unwrap(), path);
    println!("{} {walk:?}: {summary}", path.display());
    summary
}

/// Runs the scenario `s` on the robot at `path` with the walking options it does not set
/// derived from the robot (`Scenario::fit_walk`, as `twin sim`); its gait summary.
pub(super) fn derived_run(mut s: Scenario, path: &std::path::Path) -> twin_controllers::walk::GaitSummary {
    let robot = s.robot(path).unwrap();
    s.fit_walk(&robot.model).unwrap();
    let mut controller = s.controller(&robot.model).unwrap();
    let mut check = s.check(&robot.model).unwrap();
    let options = SimOptions { duration_secs: s.duration_secs, seed: s.seed };
    sim::simulate_with(&robot, controller.as_mut(), &options, None, &mut |_| {}, &mut [], &mut [&mut check]).unwrap();
    check.metrics.summary()
}

/// The walk `s` of `who` went at least 5 m forward at 0.2 m/s or more without a fall, its
/// heading within `max_yaw_rad` and its line within `max_lateral_m`.
pub(super) fn walked_five_metres_straight(s: &GaitSummary, who: &str, max_yaw_rad: f64, max_lateral_m: f64) {
    assert!(!s.fell, "{who}: fell at {:?}", s.fall_time_secs);
    assert!(s.forward_m >= 5.0, "{who}: walked {} m", s.forward_m);
    assert!(s.average_speed_mps >= 0.2, "{who}: {} m/s", s.average_speed_mps);
    assert!(s.yaw_change_rad.abs() < max_yaw_rad, "{who}: heading off by {} rad", s.yaw_change_rad);
    assert!(s.lateral_m.abs() < max_lateral_m, "{who}: {} m off the line", s.lateral_m);
}

/// Example-robot-data's Unitree G1 (33 kg, no robot-specific option) walks over 5 m straight
/// at 0.25 m/s without a fall, holding its heading (in the lab: 6.64 m in 30 s, heading
/// −0.3°, mean slip 7 mm). (Before the walker capped the damping of the loops on its light
/// pelvis, `Walker::cap_pelvis_damping`, it chattered at its hips' limits and needed the swing
/// foot placed from the measured pelvis, `swing_from_measured_pelvis`: from the commanded one
/// it fell at 3.4 s; now both walk, 6.64 m and 5.35 m.) Romeo (40.5 kg) turns 90° in place
/// within 15° (in the lab: 92.4°).
#[test]
pub(super) fn g1_walks_five_metres_straight_and_romeo_turns_in_place() {
    let g1 = example_robot("g1_description/urdf/g1_29dof_rev_1_0.urdf");
    walked_five_metres_straight(&walk_with_derived_options(&g1, 30.0, "vx = 0.25"), "G1", 0.2, 0.3);
    turns_ninety_degrees_in_place_within_fifteen(&example_robot("romeo_description/urdf/romeo.urdf"));
}

/// Example-robot-data's Romeo (40.5 kg, legs loaded 0.32 of their effort in the crouch), no
/// robot-specific option, walks over 5 m straight at 0.2, 0.25 and 0.3 m/s without a fall and
/// follows `scenarios/steer.toml` (1 m forward at 0.25 m/s, 90° in place, 0.5 m to the left)
/// within 20 % of each leg. Three derived rules make it walk, and at 0.3 m/s each is needed:
/// the crouch keeps the knees bent `MIN_KNEE_BEND_RAD` in the gait's extreme poses (at the
/// highest crouch that reaches its steps, 0.680 m, knees 0.27 rad from straight, it falls at
/// 3.5 s), the swing foot is lifted by the legs' load over `SAG_FREE_LOAD` (`walk::derive`;
/// with the Froude-scaled clearance, 0.06 m, it falls at 5.4 s), and its first swing strays
/// 78 % of its sole from its trajectory, so the walker damps the swing legs on the error to
/// their targets' velocity (`swing_miss_fraction`; never, it falls at 3.4 s). Before them it
/// fell at 3.3 s. (In the lab: 7.05 m, 8.56 m and 9.77 m in 30 s at 0.2, 0.25 and 0.3 m/s.)
#[test]
pub(super) fn romeo_walks_five_metres_straight_and_follows_the_steer_sequence() {
    let romeo = example_robot("romeo_description/urdf/romeo.urdf");
    for vx in [0.2, 0.25, 0.3] {
        let s = walk_with_derived_options(&romeo, 30.0, &format!("vx = {vx}"));
        walked_five_metres_straight(&s, &format!("Romeo at {vx} m/s"), 0.3, 0.3);
    }
    // Each derived rule matters: the old crouch, the scaled clearance and the swing damped on
    // its joints' velocity alone, given, fall at 0.3 m/s.
    for given in ["com_height = 0.6802023158286374", "foot_clearance = 0.06", "swing_miss_fraction = inf"] {
        let s = walk_with_derived_options(&romeo, 30.0, &format!("vx = 0.3\n{given}"));
        assert!(s.fell, "{given}: walked {} m without a fall", s.forward_m);
    }
    steers_within_twenty_percent(&romeo);
}

/// The G1, no robot-specific option, with the damping of its hip and waist loops capped on
/// its 0.03-kg·m² pelvis (`Walker::cap_pelvis_damping`): it turns 90° in place within 15° and
/// walks at 0.2 and 0.3 m/s without a fall, its feet slipping under 1 cm a stance. Without the
/// cap (the hips' and waist's torques flipping sign from one physics step to the next in
/// single support, at their effort limits) it spun 194° and fell at 5.5 s turning, fell at
/// 14.7 s (0.2 m/s, heading 115° off) and 3.9 s (0.3 m/s), slipping 3 cm a stance. In the
/// lab: 92.6° (moved 0.08 m; 94.9° before the outer loop on position, `command_hold_gain`);
/// 5.27 m and 7.95 m in 30 s, headings within 0.5°, slip 6 and 9 mm.
#[test]
pub(super) fn g1_turns_in_place_and_walks_at_two_and_three_tenths_of_a_metre_per_second() {
    let g1 = example_robot("g1_description/urdf/g1_29dof_rev_1_0.urdf");
    turns_ninety_degrees_in_place_within_fifteen(&g1);
    for (vx, least_m) in [(0.2, 5.0), (0.3, 7.0)] {
        let s = walk_with_derived_options(&g1, 30.0, &format!("vx = {vx}"));
        assert!(!s.fell, "{vx} m/s: fell at {:?}", s.fall_time_secs);
        assert!(s.forward_m >= least_m, "{vx} m/s: walked {} m", s.forward_m);
        assert!(s.yaw_change_rad.abs() < 0.1, "{vx} m/s: heading off by {} rad", s.yaw_change_rad);
        assert!(s.slip_mean_m < 0.01, "{vx} m/s: feet slip {} m a stance", s.slip_mean_m);
    }
}

/// Example-robot-data's Talos (full v2), converted with torque motors as `twin convert
/// --actuators motor` does, written into `dir`.
pub(super) fn talos_on_motors(dir: &std::path::Path) -> std::path::PathBuf {
    use twin_core::convert::{ActuatorMode, ConvertOptions, convert_urdf};
    let urdf = example_robot("talos_data/robots/talos_full_v2.urdf");
    let options = ConvertOptions { actuators: ActuatorMode::Motor, ..ConvertOptions::default() };
    let converted = convert_urdf(&urdf, &options).unwrap();
    let talos = dir.join("talos_motors.xml");
    std::fs::write(&talos, &converted.mjcf).unwrap();
    talos
}

/// Talos (motors, 93 kg), no robot-specific option, walks over 5 m straight at 0.25 m/s in 30 s
/// without a fall, holding its heading, its line and the commanded speed. At the highest crouch
/// that reached its steps (knees 0.12 rad from straight) it fell at 4.7 s; the derived crouch
/// keeps them bent `MIN_KNEE_BEND_RAD`. Its swing hip pitch (2.8 kg·m²) is slow under the gain
/// rule (`√(kp/I)` 24 rad/s): damped on their joint velocity, the swing legs lag their targets
/// (the first swing foot 11 cm behind its trajectory) and the feet land 7–11 cm past their
/// aims. At the old crouch that fell it; at the derived one it walks, but 25 % faster than
/// commanded. The walker sees the first swing stray over half a sole and damps the swing legs
/// on the error to their targets' velocity (`swing_miss_fraction`): the feet land within 1 cm
/// and the pace is the command's. In the lab: 7.29 m, 0.243 m/s, drift 0.04 m; with
/// `swing_miss_fraction = inf` (never) 9.34 m, 0.31 m/s.
#[test]
pub(super) fn talos_on_motors_walks_five_metres_straight() {
    let dir = tempfile::tempdir().unwrap();
    let talos = talos_on_motors(dir.path());
    let s = walk_with_derived_options(&talos, 30.0, "vx = 0.25");
    assert!(!s.fell, "fell at {:?}", s.fall_time_secs);
    assert!(s.forward_m >= 5.0, "walked {} m", s.forward_m);
    // 29 s of walking after the 1-s settle, averaged over the 30 s.
    let commanded_mps = 0.25 * 29.0 / 30.0;
    assert!((s.average_speed_mps - commanded_mps).abs() < 0.1 * commanded_mps, "{} m/s", s.average_speed_mps);
    assert!(s.yaw_change_rad.abs() < 0.1, "heading off by {} rad", s.yaw_change_rad);
    assert!(s.lateral_m.abs() < 0.25, "drifted {} m sideways", s.lateral_m);
    // Damped on the joint velocity alone, the swing legs overshoot and the pace runs away.
    let before = walk_with_derived_options(&talos, 30.0, "vx = 0.25\nswing_miss_fraction = inf");
    assert!(
        before.fell || before.average_speed_mps > 1.2 * commanded_mps,
        "without tracking the swing's velocity: {} m/s",
        before.average_speed_mps
    );
}

/// Talos as `twin convert` makes it by default: its legs on the position servos its
/// transmissions declare (kp 2000–5000, force ranges from its effort limits). The walker sends
/// each servo the setpoint whose force is the torque its own loop wants (`AffineServo`): the
/// same joint loops as on torque motors, the servo's gains cancelled. No robot-specific
/// option: it walks over 5 m straight at 0.25 m/s, turns 90° in place within 15° and follows
/// `scenarios/steer.toml` within 20 % of each leg. (It was
/// refused: "the leg joint is driven by a position servo … convert with torque motors". In
/// the lab: 7.72 m, 0.257 m/s, heading 4.8°, drift 0.29 m; turned 97.6°; steered 1.109 m,
/// 99.7°, 0.532 m.)
#[test]
pub(super) fn talos_on_its_position_servos_walks_and_turns() {
    let urdf = example_robot("talos_data/robots/talos_full_v2.urdf");
    let converted = twin_core::convert::convert_urdf(&urdf, &Default::default()).unwrap();
    assert!(converted.mjcf.matches("<position ").count() >= 12, "Talos's legs on position servos");
    let dir = tempfile::tempdir().unwrap();
    let talos = dir.path().join("talos.xml");
    std::fs::write(&talos, &converted.mjcf).unwrap();
    walked_five_metres_straight(&walk_with_derived_options(&talos, 30.0, "vx = 0.25"), "Talos", 0.15, 0.5);
    turns_ninety_degrees_in_place_within_fifteen(&talos);
    steers_within_twenty_percent(&talos);
}

/// Example-robot-data's Talos (full v2, 93 kg) converted with torque motors (`twin convert
/// --actuators motor`) stands upright under the walker
/// and turns 90° in place within 15°, no robot-specific option. Its IMU site is on `imu_link`,
/// turned half a turn about the pelvis's x + y axis: read as the pelvis's own orientation, the
/// walker saw the torso upside down (roll ±π), its tilt feedback flipped the pelvis ±0.2 rad
/// from one physics step to the next, the legs' torques hit their limits with alternating
/// signs, the feet left the ground at 0.04 s and landed 3 to 6 cm from where they stood, the
/// pelvis leant 6–11° while standing (0.185 rad at 0.94 s), and the turn fell at 4.1 s. (In
/// the lab: upright within 0.3°, turned 97.1°; 98.8° before the crouch kept its knees bent
/// `MIN_KNEE_BEND_RAD`, 100.3° before `command_hold_gain`.)
#[test]
pub(super) fn talos_on_motors_stands_upright_and_turns_in_place() {
    let dir = tempfile::tempdir().unwrap();
    let talos = talos_on_motors(dir.path());

    /// The largest pelvis tilt (rad) before `until_secs`.
    struct MaxTilt {
        until_secs: f64,
        tilt_rad: f64,
    }
    impl Observer for MaxTilt {
        fn observe(&mut self, step: &StepView<'_>) -> twin_core::Result<Flow> {
            if step.time_secs < self.until_secs {
                let q = step.qpos;
                let (w, x, y, z) = (q[3], q[4], q[5], q[6]);
                let up_z = 1.0 - 2.0 * (x * x + y * y) / (w * w + x * x + y * y + z * z);
                self.tilt_rad = self.tilt_rad.max(up_z.clamp(-1.0, 1.0).acos());
            }
            Ok(Flow::Continue)
        }
    }
    // 0.3 rad/s for π/(2·0.3) s from 1 s: 90° to the left, then standing.
    let text = format!(
        "model = {talos:?}\nduration = 12.0\ncontroller = \"walk\"\n[walk]\n\
         commands = [[1.0, 0.0, 0.0, 0.3], [6.236, 0.0, 0.0, 0.0]]\n"
    );
    let mut s = Scenario::parse(&scenarios().join("inline.toml"), &text).unwrap();
    let robot = s.robot(&talos).unwrap();
    s.fit_walk(&robot.model).unwrap();
    let mut controller = s.controller(&robot.model).unwrap();
    let mut check = s.check(&robot.model).unwrap();
    let mut standing = MaxTilt { until_secs: 1.0, tilt_rad: 0.0 };
    simulate(&s, &robot, controller.as_mut(), &mut [], &mut [&mut check, &mut standing]);
    let summary = check.metrics.summary();
    println!("Talos (motors), turning: {summary}; tilt standing {} rad", standing.tilt_rad);
    assert!(standing.tilt_rad < 0.02, "pelvis tilted {} rad while standing", standing.tilt_rad);
    assert!(!summary.fell, "turning: fell at {:?}", summary.fall_time_secs);
    let deg = summary.yaw_change_rad.to_degrees();
    assert!((deg - 90.0).abs() <= 15.0, "turned {deg}°");
    assert!(summary.distance_m < 0.5, "turning in place moved {} m", summary.distance_m);
}

/// The walker refuses what it can't drive, saying what to change, instead of a fall: legs on
/// position servos with no force limit (Talos's transmissions with their `forcerange` taken
/// out, and the joints' actuator-force ranges: nothing to scale the joint loops by), and actuators too weak to hold the crouch (the
/// shipped humanoid with every effort limit cut to 10 N·m: its knees need 14.8 N·m at the
/// 0.62-m crouch, half its weight on each foot).
#[test]
pub(super) fn walker_refuses_servo_legs_and_weak_actuators() {
    let talos = example_robot("talos_data/robots/talos_full_v2.urdf");
    let converted = twin_core::convert::convert_urdf(&talos, &Default::default()).unwrap();
    let unlimited = strip_attribute(&strip_attribute(&converted.mjcf, " forcerange=\""), " actuatorfrcrange=\"");
    let model = twin_core::mj::Model::from_xml_str(&unlimited).unwrap();
    let e = Walker::new(&model, WalkOptions::default()).unwrap_err().to_string();
    assert!(e.contains("position servo") && e.contains("no force limit") && e.contains("--actuators motor"), "{e}");
    let text = std::fs::read_to_string(humanoid()).unwrap();
    let weak = with_efforts_of_ten(&text);
    let dir = std::env::temp_dir().join(format!("twin-weak-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("weak.urdf");
    std::fs::write(&path, weak).unwrap();
    let mut s = Scenario::defaults("walk", 1.0);
    let robot = s.robot(&path).unwrap();
    let e = s.fit_walk(&robot.model).unwrap_err().to_string();
    assert!(e.contains("left_knee_joint") && e.contains("gives -10.0 N·m") && e.contains("raise com_height"), "{e}");
    std::fs::remove_dir_all(&dir).ok();
}

/// `text` with every attribute that starts with `attribute` (e.g. ` forcerange="`) taken out.
pub(super) fn strip_attribute(text: &str, attribute: &str) -> String {
    let mut out = String::new();
    let mut rest = text;
    while let Some(i) = rest.find(attribute) {
        out.push_str(&rest[..i]);
        let after = &rest[i + attribute.len()..];
        rest = &after[after.find('"').map_or(after.len(), |e| e + 1)..];
    }
    out.push_str(rest);
    out
}

/// Every effort limit of a URDF (`effort="…"` and ros2_control's `min`/`max` params) set to 10.
pub(super) fn with_efforts_of_ten(text: &str) -> String {
    let mut out = String::new();
    for line in text.lines() {
        let mut l = line.to_string();
        if let Some(i) = l.find("effort=\"") {
            let end = l[i + 8..].find('"').map(|e| i + 8 + e).unwrap();
            l.replace_range(i..=end, "effort=\"10\"");
        }
        for (tag, v) in [("<param name=\"min\">", "-10"), ("<param name=\"max\">", "10")] {
            if let (Some(i), Some(j)) = (l.find(tag), l.find("</param>")) {
                l.replace_range(i + tag.len()..j, v);
            }
        }
        out.push_str(&l);
        out.push('\n');
    }
    out
}

/// Records the base's (pelvis's) x over time.
pub(super) struct BaseX(pub(super) Vec<(f64, f64)>);

impl Observer for BaseX {
    fn observe(&mut self, step: &StepView<'_>) -> twin_core::Result<Flow> {
        self.0.push((step.time_secs, step.qpos[0]));
        Ok(Flow::Continue)
    }
}
