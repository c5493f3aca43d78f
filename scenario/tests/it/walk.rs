//! The walking controller on the shipped humanoid: walking, standing under pushes, turning,
//! and the regressions its metrics and checks must catch.

use std::path::{Path, PathBuf};
use twin_controllers::walk::{GaitSummary, WalkOptions, Walker};

mod frames;
mod robots;
use robots::*;
use twin_core::engine::{Check, Disturbance, Flow, Observer, StepView};
use twin_core::sim::{self, SimOptions};
use twin_scenario::{Push, Scenario, Threshold};

fn humanoid() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../models/humanoid.urdf")
}

fn scenarios() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../scenarios")
}

/// The last step's qpos (`.0`) and raw sensor readings (`.1`).
struct Last(Vec<f64>, Vec<f64>);

impl Observer for Last {
    fn observe(&mut self, step: &StepView<'_>) -> twin_core::Result<Flow> {
        self.0.clear();
        self.0.extend_from_slice(step.data.qpos());
        self.1.clear();
        self.1.extend_from_slice(step.data.sensordata());
        Ok(Flow::Continue)
    }
}

/// Runs `robot` under `controller` for `scenario`'s duration and seed, with `disturbances` and
/// `observers`.
fn simulate(
    scenario: &Scenario,
    robot: &twin_core::robot::Robot,
    controller: &mut dyn twin_core::control::Controller,
    disturbances: &mut [&mut dyn Disturbance],
    observers: &mut [&mut dyn Observer],
) {
    let options = SimOptions { duration_secs: scenario.duration_secs, seed: scenario.seed };
    sim::simulate_with(robot, controller, &options, None, &mut |_| {}, disturbances, observers).unwrap();
}

/// Runs `scenario` (with `edit` applied) on the rollout engine and returns the gait metrics,
/// the verdicts and the final state.
fn run_scenario(mut scenario: Scenario, edit: impl FnOnce(&mut Scenario)) -> (GaitSummary, Vec<Threshold>, Vec<f64>) {
    edit(&mut scenario);
    let robot = scenario.robot(&humanoid()).unwrap();
    let mut controller = scenario.controller(&robot.model).unwrap();
    let mut pushes = scenario.disturbances(&robot.model);
    let mut disturbances: Vec<&mut dyn Disturbance> = pushes.iter_mut().map(|p| p as &mut dyn Disturbance).collect();
    let mut check = scenario.check(&robot.model).unwrap();
    let mut last = Last(Vec::new(), Vec::new());
    simulate(&scenario, &robot, controller.as_mut(), &mut disturbances, &mut [&mut check, &mut last]);
    let summary = check.metrics.summary();
    let verdicts = check.verdicts();
    // The engine verdict agrees with the per-threshold ones.
    assert_eq!(check.verdict().passed, verdicts.iter().all(|v| v.passed));
    println!("{summary}");
    for v in &verdicts {
        println!("  {v}");
    }
    (summary, verdicts, last.0)
}

fn stand(duration: f64) -> Scenario {
    Scenario::parse(
        &scenarios().join("inline.toml"),
        &format!("model = {:?}\nduration = {duration:?}\n[checks]\nfalls = 0\n", humanoid()),
    )
    .unwrap()
}

/// `walk.toml` stepping every 0.5 s with 0.25-s shortest swings, the gait its kick tests were
/// timed for (`walk.toml` now steps every 0.35 s): the kick times below fall at the phases of
/// a step they name.
fn half_second_steps(sc: &mut Scenario) {
    sc.walk.step_period = 0.5;
    sc.walk.min_single_support_secs = 0.25;
}

/// Priority 1: the shipped scenario walks ≥ 10 m straight at ≥ 0.3 m/s, drifting < 0.5 m.
#[test]
fn walks_ten_metres_straight() {
    let (s, verdicts, _) = run_scenario(Scenario::load(scenarios().join("walk.toml")).unwrap(), |_| {});
    assert!(!s.fell, "fell at {:?}", s.fall_time_secs);
    assert!(s.forward_m >= 10.0, "{}", s.forward_m);
    assert!(s.lateral_m.abs() < 0.5, "{}", s.lateral_m);
    assert!(s.average_speed_mps >= 0.3, "{}", s.average_speed_mps);
    assert!(s.steps >= 50, "{}", s.steps);
    assert!(s.slip_mean_m < 0.01, "{}", s.slip_mean_m);
    assert!(verdicts.iter().all(|v| v.passed), "{verdicts:?}");
}

/// Zero velocity: a balance controller that stays put, holds a sideways push (0.4 m/s of the
/// whole robot: its capture point stays inside the feet) with its ankles, and steps to recover
/// a forward push whose capture point lies beyond the toes (0.5 m/s: 0.125 m ahead).
#[test]
fn stands_and_recovers_a_push_by_stepping() {
    let mut quiet = stand(4.0);
    quiet.checks.max_distance = Some(0.05);
    let (s, v, _) = run_scenario(quiet, |_| {});
    assert!(!s.fell && s.steps == 0 && s.distance_m < 0.05, "{s:?}");
    assert!(v.iter().all(|v| v.passed));
    let (s, _, _) = run_scenario(stand(6.0), |sc| {
        sc.pushes.push(Push { time: 2.0, duration: 0.1, force: [0.0, 140.0, 0.0], body: None });
    });
    assert!(!s.fell, "fell at {:?}", s.fall_time_secs);
    assert!(s.distance_m < 0.05, "held in place: {}", s.distance_m);
    let (s, _, _) = run_scenario(stand(6.0), |sc| {
        sc.pushes.push(Push { time: 2.0, duration: 0.1, force: [178.0, 0.0, 0.0], body: None });
    });
    assert!(!s.fell, "fell at {:?}", s.fall_time_secs);
    assert!(s.steps >= 1, "recovered by stepping: {} steps", s.steps);
    assert!((0.1..0.6).contains(&s.forward_m), "stepped forward: {}", s.forward_m);
}

/// A push far beyond what a step can capture (2.8 m/s of the whole robot) is a fall, and the
/// scenario's check fails.
#[test]
fn a_push_beyond_capture_is_a_fall() {
    let (s, v, _) = run_scenario(stand(4.0), |sc| {
        sc.pushes.push(Push { time: 2.0, duration: 0.1, force: [1000.0, 0.0, 0.0], body: None });
    });
    assert!(s.fell, "{s:?}");
    assert!(s.fall_time_secs.unwrap() > 2.0);
    assert!(v.iter().any(|v| v.name == "falls" && !v.passed), "{v:?}");
}

/// Turning in place: 0.3 rad/s for 6 s after the crouch turns ≈ 90° without walking off.
#[test]
fn turns_ninety_degrees_in_place() {
    let (s, _, _) = run_scenario(stand(7.0), |sc| sc.walk.yaw_rate = 0.3);
    assert!(!s.fell);
    let deg = s.yaw_change_rad.to_degrees();
    assert!((80.0..110.0).contains(&deg), "{deg}");
    assert!(s.distance_m < 0.3, "{}", s.distance_m);
}

/// Steering by a schedule (`[walk] commands`): after the crouch, 0.3 rad/s in place until
/// the command asks 90°, then stop. The walker turns by steps (yaw only, the feet around one
/// centre), stops, brings its feet side by side and stands: it ends within 15° of 90°, near
/// where it started, and from 2 s after the stop it neither turns nor walks. The metrics
/// report each segment's commanded and achieved angle.
#[test]
fn scheduled_ninety_degree_turn_in_place_stops_within_fifteen_degrees() {
    let turn_secs = std::f64::consts::FRAC_PI_2 / 0.3;
    let stop = 1.0 + turn_secs;
    let (s, _, _) = run_scenario(stand(stop + 4.0), |sc| {
        sc.walk.commands = vec![[1.0, 0.0, 0.0, 0.3], [stop, 0.0, 0.0, 0.0], [stop + 2.0, 0.0, 0.0, 0.0]];
    });
    assert!(!s.fell, "fell at {:?}", s.fall_time_secs);
    let deg = s.yaw_change_rad.to_degrees();
    assert!((deg - 90.0).abs() < 15.0, "turned {deg}°");
    assert!(s.distance_m < 0.3, "walked off {} m", s.distance_m);
    assert_eq!(s.segments.len(), 4, "{:?}", s.segments);
    let turn = &s.segments[1];
    assert!((turn.commanded_angle_rad - std::f64::consts::FRAC_PI_2).abs() < 1e-2, "{turn:?}");
    let still = &s.segments[3];
    assert!(still.angle_rad.abs() < 0.02 && still.distance_m < 0.02, "kept moving after the stop: {still:?}");
}

/// A scheduled stop from walking: 0.25 m/s for 4 s, then zero: the walker finishes the step
/// it is in (planned at 0.25 m/s), brings its feet side by side and stands: it goes on at
/// most two steps' advance (0.3 m) after the stop and, from 2 s after it, stands still.
#[test]
fn scheduled_stop_from_walking_stands_in_place() {
    let (s, _, _) = run_scenario(stand(10.0), |sc| {
        sc.walk.commands = vec![[1.0, 0.25, 0.0, 0.0], [5.0, 0.0, 0.0, 0.0], [7.0, 0.0, 0.0, 0.0]];
    });
    assert!(!s.fell, "fell at {:?}", s.fall_time_secs);
    let (walk, stop, still) = (&s.segments[1], &s.segments[2], &s.segments[3]);
    assert!((walk.commanded_distance_m - 1.0).abs() < 1e-9 && walk.forward_m > 0.8, "{walk:?}");
    assert!(stop.forward_m < 2.0 * 0.25 * 0.6, "{stop:?}");
    assert!(still.distance_m < 0.02 && still.angle_rad.abs() < 0.02, "{still:?}");
}

/// `scenarios/steer.toml`, the navigation sequence of the README's `/cmd_vel` node as a
/// schedule: 1 m forward, a 90° turn in place, 0.5 m to the left, each followed by a stop.
/// Each move with its stop covers its commanded distance or angle within 20 % (the lateral
/// leg measured across the heading it starts at, after the turn).
#[test]
fn steer_scenario_forward_turn_lateral_within_twenty_percent() {
    let (s, verdicts, _) = run_scenario(Scenario::load(scenarios().join("steer.toml")).unwrap(), |_| {});
    assert!(!s.fell, "fell at {:?}", s.fall_time_secs);
    assert!(verdicts.iter().all(|v| v.passed), "{verdicts:?}");
    let seg = &s.segments;
    assert!((seg[1].commanded_distance_m - 1.0).abs() < 1e-9 && (seg[5].commanded_distance_m - 0.5).abs() < 1e-9);
    legs_within_twenty_percent(&s);
}

/// Each leg of a `scenarios/steer.toml` run `s` within 20 % of its 1 m, 90° and 0.5 m.
fn legs_within_twenty_percent(s: &GaitSummary) {
    let (forward, turned, lateral) = steer_legs(s);
    assert!((forward - 1.0).abs() < 0.2, "forward {forward} m of 1 m");
    assert!((turned - std::f64::consts::FRAC_PI_2).abs() < 0.2 * std::f64::consts::FRAC_PI_2, "turned {turned} rad");
    assert!((lateral - 0.5).abs() < 0.1, "lateral {lateral} m of 0.5 m");
}

/// The robot at `path`, its walking options derived, follows `scenarios/steer.toml` without a
/// fall, each leg within 20 %.
fn steers_within_twenty_percent(path: &std::path::Path) {
    let mut steer = Scenario::load(scenarios().join("steer.toml")).unwrap();
    steer.model = Some(path.to_path_buf());
    let summary = derived_run(steer, path);
    assert!(!summary.fell, "steered: fell at {:?}", summary.fall_time_secs);
    legs_within_twenty_percent(&summary);
}

/// The robot at `path`, its walking options derived, turns 90° in place within 15° at
/// 0.3 rad/s (from 1 s, for π/(2·0.3) s, then standing) without a fall, moving under 0.5 m.
fn turns_ninety_degrees_in_place_within_fifteen(path: &std::path::Path) {
    let turn = walk_with_derived_options(path, 12.0, "commands = [[1.0, 0.0, 0.0, 0.3], [6.236, 0.0, 0.0, 0.0]]");
    assert!(!turn.fell, "turning: fell at {:?}", turn.fall_time_secs);
    let deg = turn.yaw_change_rad.to_degrees();
    assert!((deg - 90.0).abs() <= 15.0, "turned {deg}°");
    assert!(turn.distance_m < 0.5, "turning in place moved {} m", turn.distance_m);
}

/// The legs of `scenarios/steer.toml` in a run of it: (forward m, turned rad, lateral m), each
/// move with the stop after it, the lateral leg across the heading it starts at.
fn steer_legs(s: &GaitSummary) -> (f64, f64, f64) {
    let seg = &s.segments;
    assert_eq!(seg.len(), 7, "{seg:?}");
    let forward = seg[1].forward_m + seg[2].forward_m;
    let turned = seg[3].angle_rad + seg[4].angle_rad;
    let lateral = seg[5].lateral_m + seg[6].lateral_m;
    println!("forward {forward:.3} m of 1, turned {:.1}° of 90, lateral {lateral:.3} m of 0.5", turned.to_degrees());
    (forward, turned, lateral)
}

/// The walker's outer loop on position (`command_hold_gain`) on example-robot-data's G1 under
/// `scenarios/steer.toml` (its options derived, as `twin sim G1 --scenario steer.toml`): with
/// it (the default) each leg is within 10 % of its 1 m, 90° and 0.5 m (in the lab: 1.032 m,
/// 95.2°, 0.463 m); without it the sideways leg falls 21 % short (0.393 m: the landing
/// corrections pulled each step back), more than twice the shortfall with it.
#[test]
fn command_hold_brings_the_g1_sideways_leg_within_ten_percent() {
    let g1 = example_robot("g1_description/urdf/g1_29dof_rev_1_0.urdf");
    let steered = |gain: Option<f64>| {
        let mut s = Scenario::load(scenarios().join("steer.toml")).unwrap();
        s.model = Some(g1.clone());
        if let Some(gain) = gain {
            s.walk.command_hold_gain = gain;
        }
        let summary = derived_run(s, &g1);
        assert!(!summary.fell, "fell at {:?}", summary.fall_time_secs);
        steer_legs(&summary)
    };
    let (forward, turned, lateral) = steered(None);
    assert!((forward - 1.0).abs() < 0.1, "forward {forward} m of 1 m");
    assert!((turned - std::f64::consts::FRAC_PI_2).abs() < 0.1 * std::f64::consts::FRAC_PI_2, "turned {turned} rad");
    assert!((lateral - 0.5).abs() < 0.05, "lateral {lateral} m of 0.5 m");
    let (_, _, open_loop) = steered(Some(0.0));
    assert!(0.5 - open_loop > 2.0 * (0.5 - lateral).abs(), "without the hold: {open_loop} m, with: {lateral} m");
}

/// On a floor too slippery to walk on, the feet slide: slip is reported and its check fails.
#[test]
fn low_friction_slip_fails_its_check() {
    let (s, v, _) = run_scenario(stand(6.0), |sc| {
        sc.walk.vx = 0.3;
        sc.friction = Some(0.05);
        sc.checks.max_mean_slip = Some(0.01);
        sc.checks.falls = None;
    });
    let slip = v.iter().find(|v| v.name == "max_mean_slip").unwrap();
    assert!(!slip.passed && s.slip_mean_m > 0.01, "{s:?}");
    // Nominal friction passes the same check.
    let (s, v, _) = run_scenario(stand(6.0), |sc| {
        sc.walk.vx = 0.3;
        sc.checks.max_mean_slip = Some(0.01);
    });
    assert!(v.iter().all(|v| v.passed), "{s:?}");
}

/// A step the legs can't reach is refused before simulating, naming the option.
#[test]
fn unreachable_step_is_refused() {
    let robot = twin_core::robot::Robot::load(humanoid()).unwrap();
    let options = WalkOptions { vx: 0.9, max_step_length: 0.6, ..WalkOptions::default() };
    let e = Walker::new(&robot.model, options).unwrap_err().to_string();
    assert!(e.contains("can't reach a step of max_step_length 0.6 m"), "{e}");
    let options = WalkOptions { vx: 0.9, ..WalkOptions::default() };
    let e = Walker::new(&robot.model, options).unwrap_err().to_string();
    assert!(e.contains("option `vx`") && e.contains("max_step_length"), "{e}");
}

/// Same scenario, same result, bit for bit.
#[test]
fn deterministic() {
    let a = run_scenario(stand(2.5), |sc| sc.walk.vx = 0.3).2;
    let b = run_scenario(stand(2.5), |sc| sc.walk.vx = 0.3).2;
    assert!(!a.is_empty());
    assert_eq!(a, b);
}

#[test]
fn kinematics_match_mujoco() {
    use std::sync::Arc;
    use twin_controllers::walk::kin::{Body, BodyNames, LegIk, Tree};
    let model = Arc::new(twin_core::mj::Model::from_file(humanoid()).unwrap());
    let mut data = twin_core::mj::Data::new(model.clone()).unwrap();
    twin_core::control::reset_to_home(&mut data).unwrap();
    // A bent configuration.
    for (i, q) in data.qpos_mut().iter_mut().enumerate().skip(7) {
        *q += 0.05 * ((i as f64) * 1.7).sin();
    }
    data.forward().unwrap();
    let tree = Tree::new(&model);
    let mut frames = tree.frames();
    tree.forward(data.qpos(), &mut frames);
    for b in 0..model.nbody() {
        let p = data.xpos()[b];
        assert!((frames.xpos[b] - nalgebra::Vector3::from(p)).norm() < 1e-9, "body {b}");
        let c = data.subtree_com()[b];
        assert!((frames.subtree_com[b] - nalgebra::Vector3::from(c)).norm() < 1e-9, "com {b}");
    }
    let body = Body::find(&model, &tree, data.qpos(), &BodyNames::default()).unwrap();
    for leg in &body.legs {
        let ik = LegIk::new(&model, leg);
        let q: Vec<f64> = (0..ik.len()).map(|k| data.qpos()[ik.qpos_adr(k)]).collect();
        let (p, r) = ik.foot_pose(&q);
        let pel = frames.xrot[body.pelvis].inverse();
        let want = pel * (frames.xpos[leg.foot] - frames.xpos[body.pelvis]);
        assert!((p - want).norm() < 1e-9, "{p} {want}");
        assert!((r.inverse() * pel * frames.xrot[leg.foot]).angle() < 1e-9);
        // IK from the home pose back to this one.
        let mut q0: Vec<f64> = (0..ik.len()).map(|k| model.qpos0()[ik.qpos_adr(k)]).collect();
        let res = ik.solve((p, r), &mut q0, 50, 1e-4);
        assert!(res.position_error_m < 1e-6, "{res:?}");
    }
}

/// The shipped balance scenario passes its checks (both pushes held by the ankles, in place).
#[test]
fn shipped_stand_scenario_passes() {
    let (s, verdicts, _) = run_scenario(Scenario::load(scenarios().join("stand.toml")).unwrap(), |_| {});
    assert!(!s.fell && s.distance_m < 0.1, "{s:?}");
    assert!(verdicts.iter().all(|v| v.passed), "{verdicts:?}");
}

/// The walker's diagnostics reach the recording: CoM, ZMP, DCM (reference and actual) and
/// the planned footsteps at 100 Hz, in the world frame; the measured CoM is the model's.
#[test]
fn diagnostics_are_recorded() {
    use twin_core::log::{Log, PointStamped, PoseArray, ReadOptions};
    use twin_core::sim::{RecordOptions, Recording};
    let scenario = stand(2.0);
    let robot = scenario.robot(&humanoid()).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let mcap = dir.path().join("walk.mcap");
    let options = RecordOptions { mcap: Some(mcap.clone()), ..RecordOptions::default() };
    let mut recording = Recording::with_sinks(&robot, &options, Vec::new()).unwrap();
    let mut walker = Walker::new(&robot.model, WalkOptions { vx: 0.3, ..WalkOptions::default() }).unwrap();
    sim::simulate(
        &robot,
        &mut walker,
        &SimOptions { duration_secs: 2.0, ..SimOptions::default() },
        Some(&mut recording),
        &mut |_| {},
    )
    .unwrap();
    recording.finish().unwrap();
    let log = Log::open(&mcap, ReadOptions::default()).unwrap();
    let (com, _) = log.read_typed::<PointStamped>("/walk/com").unwrap();
    assert_eq!(com.len(), 200, "100 Hz over 2 s");
    let (com_ref, _) = log.read_typed::<PointStamped>("/walk/com_ref").unwrap();
    let (dcm, _) = log.read_typed::<PointStamped>("/walk/dcm").unwrap();
    assert_eq!((com_ref.len(), dcm.len()), (200, 200));
    // After the 1-s crouch the CoM is near the commanded height and tracks its reference.
    let (_, last) = com.last().unwrap();
    let (_, last_ref) = com_ref.last().unwrap();
    assert_eq!(last.header.frame_id, "odom");
    assert!((last.point[2] - 0.62).abs() < 0.04, "{:?}", last.point);
    assert!((last.point[0] - last_ref.point[0]).hypot(last.point[1] - last_ref.point[1]) < 0.05);
    // Walking: footsteps ahead, each beside the last, advancing.
    let (steps, _) = log.read_typed::<PoseArray>("/walk/footsteps").unwrap();
    let (_, plan) = steps.last().unwrap();
    assert!(plan.poses.len() >= 3, "{plan:?}");
    assert!(plan.poses[2].position[0] > plan.poses[0].position[0] + 0.1, "{plan:?}");
}

/// Recovery stepping of `stand.toml` (step as soon as the DCM leaves the feet, a 0.25-s swing
/// with no double support before it): a sideways kick of 0.6 m/s of the whole robot (capture
/// point 0.15 m out, past the outer sole edge at 0.135 m) is caught by stepping; with the
/// walker's default recovery timing (margin 0.02 m, 0.05 s double support + 0.35 s swing) the
/// robot falls without a step.
#[test]
fn stand_scenario_catches_a_sideways_kick_the_default_timing_does_not() {
    // 0.6 m/s × 35.7 kg in 0.05 s on the pelvis, to the left, 2 s after the crouch.
    let kick = |sc: &mut Scenario| {
        sc.pushes.clear();
        sc.duration_secs = 6.0;
        sc.checks.max_distance = None;
        sc.pushes.push(Push { time: 3.0, duration: 0.05, force: [0.0, 428.4, 0.0], body: None });
    };
    let shipped = Scenario::load(scenarios().join("stand.toml")).unwrap();
    let (s, _, _) = run_scenario(shipped.clone(), kick);
    assert!(!s.fell, "fell at {:?}", s.fall_time_secs);
    assert!(s.steps >= 1, "recovered by stepping: {} steps", s.steps);
    let (s, _, _) = run_scenario(shipped, |sc| {
        kick(sc);
        let d = WalkOptions::default();
        sc.walk.recovery_margin = d.recovery_margin;
        sc.walk.recovery_swing_secs = d.recovery_swing_secs;
        sc.walk.recovery_double_support_secs = d.recovery_double_support_secs;
    });
    assert!(s.fell, "the default timing fell in the lab: {s:?}");
}

/// The walker reads the IMU the robot loader finds (`Robot::imus`, the one IMU finder): the same
/// gyro and orientation sensors, and a named override that is not an IMU is refused by name.
#[test]
fn walker_reads_the_robots_imu() {
    use twin_controllers::walk::kin::{Body, BodyNames, Tree};
    let robot = twin_core::robot::Robot::load(humanoid()).unwrap();
    let imu = robot.imus.first().expect("the shipped humanoid has an IMU");
    let tree = Tree::new(&robot.model);
    let home = twin_core::control::nominal_pose(&robot.model);
    let body = Body::find(&robot.model, &tree, &home, &BodyNames::default()).unwrap();
    let found = body.imu.expect("the walker found no IMU");
    assert_eq!((found.gyro_adr, found.quat_adr), (imu.gyro_adr, imu.quat_adr));
    assert_eq!(found.name, format!("{}_gyro", imu.meta.name));
    let names = BodyNames { imu_gyro: Some("no_such_gyro".into()), ..BodyNames::default() };
    let err = Body::find(&robot.model, &tree, &home, &names).unwrap_err().to_string();
    assert!(err.contains("no_such_gyro"), "{err}");
}

/// Walking's push response (the step's DCM reference, landing spot and touchdown corrected for
/// the DCM error at touchdown): a forward kick of 0.6 m/s of the whole robot early in a single
/// support (capture point 0.15 m ahead, growing ×e^(ω·t) while the foot swings) and a 0.45 m/s
/// kick to the swing foot's side are caught by stepping, and the walk goes on. Steps of 0.5 s
/// ([`half_second_steps`]).
#[test]
fn walk_scenario_catches_kicks_while_stepping() {
    for (force, min_forward) in [([428.4, 0.0, 0.0], 2.0), ([0.0, 321.3, 0.0], 2.0)] {
        let (s, _, _) = run_scenario(Scenario::load(scenarios().join("walk.toml")).unwrap(), |sc| {
            half_second_steps(sc);
            sc.duration_secs = 9.0;
            sc.checks = Default::default();
            // 0.05 s on the pelvis, 0.15 s into the right foot's stance (the left foot swings).
            sc.pushes.push(Push { time: 4.4, duration: 0.05, force, body: None });
        });
        assert!(!s.fell, "{force:?}: fell at {:?}", s.fall_time_secs);
        assert!(s.forward_m > min_forward, "{force:?}: walked on {} m", s.forward_m);
    }
}

/// A kick toward the stance foot's side while walking (the swing foot can't catch it without
/// crossing over): with the single-support ZMP planned 4 cm inside the sole (`walk.toml`'s
/// `zmp_inward`) the DCM runs farther inside the stance foot early in the step, and 0.3 m/s
/// kicks to the right at the start and 0.15 s into the right foot's stance are held by its
/// ankle; with the ZMP at the sole's centre the DCM leaves the sole's outer edge and the walker
/// falls over it (without `step_adjust_until`, the swing placed from the commanded pelvis: with them,
/// stepping out catches both kicks even with the ZMP at the centre). Steps of 0.5 s
/// ([`half_second_steps`]).
#[test]
fn walk_scenario_holds_kicks_toward_the_stance_side() {
    // 0.3 m/s × 35.7 kg in 0.05 s on the pelvis, to the right (−y).
    let kick = |sc: &mut Scenario, time: f64| {
        half_second_steps(sc);
        sc.duration_secs = 9.0;
        sc.checks = Default::default();
        sc.pushes.push(Push { time, duration: 0.05, force: [0.0, -214.2, 0.0], body: None });
    };
    let shipped = Scenario::load(scenarios().join("walk.toml")).unwrap();
    assert!(shipped.walk.zmp_inward > 0.0);
    let mut centred_falls = 0;
    for time in [4.26, 4.4] {
        let (s, _, _) = run_scenario(shipped.clone(), |sc| kick(sc, time));
        assert!(!s.fell, "kick at {time} s: fell at {:?}", s.fall_time_secs);
        assert!(s.forward_m > 2.0, "kick at {time} s: walked on {} m", s.forward_m);
        let (s, _, _) = run_scenario(shipped.clone(), |sc| {
            kick(sc, time);
            sc.walk.zmp_inward = 0.0;
            let defaults = WalkOptions::default();
            sc.walk.step_adjust_until = defaults.step_adjust_until;
            sc.walk.swing_from_measured_pelvis = false;
        });
        centred_falls += usize::from(s.fell);
    }
    assert_eq!(centred_falls, 2, "the ZMP at the sole's centre fell to both kicks in the lab");
}

/// Sideways kicks while walking straight: the landing-spot corrections that catch them leave
/// the walk offset sideways, and without `line_hold_gain` the offsets add up; `walk.toml`'s
/// line hold (0.5 of the planned centre's offset per step) walks back to the start line (in
/// the lab: 1.03 m off the line without it 10 s after eight 0.3-m/s kicks, 0.03 m with it;
/// with it 0.46 m off right after the last kick, since the kicks are caught by stepping out).
#[test]
fn walk_scenario_walks_back_to_its_line_after_sideways_kicks() {
    // 0.3 m/s × 35.7 kg in 0.05 s on the pelvis, to the left (+y), eight times.
    let kicks = |sc: &mut Scenario| {
        sc.duration_secs = 24.0;
        sc.checks = Default::default();
        for time in [3.0, 4.5, 6.0, 7.5, 9.0, 10.5, 12.0, 13.5] {
            sc.pushes.push(Push { time, duration: 0.05, force: [0.0, 214.2, 0.0], body: None });
        }
    };
    let shipped = Scenario::load(scenarios().join("walk.toml")).unwrap();
    assert!(shipped.walk.line_hold_gain > 0.0);
    let (held, _, _) = run_scenario(shipped.clone(), kicks);
    let (free, _, _) = run_scenario(shipped, |sc| {
        kicks(sc);
        sc.walk.line_hold_gain = 0.0;
    });
    assert!(!held.fell && !free.fell, "fell at {:?} / {:?}", held.fall_time_secs, free.fall_time_secs);
    assert!(held.forward_m > 3.5, "walked {} m", held.forward_m);
    assert!(free.lateral_m.abs() > 0.5, "without the line hold: {} m off the line", free.lateral_m);
    assert!(held.lateral_m.abs() < 0.1, "with the line hold: {} m off the line", held.lateral_m);
}

/// Recovery steps of `stand.toml` reach their landing spot by 60 % of the swing
/// (`recovery_reach_fraction`): a backward kick of 0.6 m/s of the whole robot (capture point
/// 0.15 m behind, the soles reach 0.10 m), and a 0.55 m/s kick 1.6 s after one in another
/// direction (the second comes while the feet stand apart from the first step), are caught by
/// stepping. With the foot's move spread over the whole swing (1.0, the walking steps' blend)
/// the sideways and backward steps land short, and the robot falls to each of them (in the lab,
/// 8 directions × 8 directions of two 0.55 m/s kicks: 0 falls against 9).
#[test]
fn stand_scenario_recovery_steps_reach_their_spot_early() {
    // v m/s × 35.7 kg in 0.05 s on the pelvis at angle `deg` from +x.
    let force = |v: f64, deg: f64| {
        let f = v * 35.7 / 0.05;
        [f * deg.to_radians().cos(), f * deg.to_radians().sin(), 0.0]
    };
    let kicks: [&[(f64, f64, f64)]; 3] =
        [&[(3.0, 0.6, 180.0)], &[(3.0, 0.55, 0.0), (4.6, 0.55, 90.0)], &[(3.0, 0.55, 180.0), (4.6, 0.55, 180.0)]];
    let shipped = Scenario::load(scenarios().join("stand.toml")).unwrap();
    assert_eq!(shipped.walk.recovery_reach_fraction, 0.6);
    for pushes in kicks {
        let lab = |sc: &mut Scenario| {
            sc.pushes.clear();
            sc.duration_secs = 7.0;
            sc.checks.max_distance = None;
            for &(time, v, deg) in pushes {
                sc.pushes.push(Push { time, duration: 0.05, force: force(v, deg), body: None });
            }
        };
        let (early, _, _) = run_scenario(shipped.clone(), lab);
        assert!(!early.fell, "{pushes:?}: fell at {:?}", early.fall_time_secs);
        assert!(early.steps >= pushes.len() as u64, "{pushes:?}: caught by stepping, {} steps", early.steps);
        let (spread, _, _) = run_scenario(shipped.clone(), |sc| {
            lab(sc);
            sc.walk.recovery_reach_fraction = 1.0;
        });
        assert!(spread.fell, "{pushes:?}: the foot moving over the whole swing fell in the lab: {spread:?}");
    }
}

/// Kicks of 0.45 m/s while walking that need the landing spot moved late in the swing and the
/// swing foot to reach it with the body rolled: to the left 0.43 s into the right foot's stance
/// (the left foot about to land; at `step_adjust_until` 0.7 it lands at its planned spot with
/// the DCM beyond it) and to the right 0.15 s into it (toward the stance side: the left foot
/// lands narrow, then the right one steps out, which lowered with the rolled body touched
/// down short when its target came from the commanded pelvis). `walk.toml` catches both and
/// walks on; with the default `step_adjust_until` and the swing from the commanded pelvis the
/// walker falls to both (the lab: 11 of 64 single kicks of 0.45/0.6 m/s fell, 21 before).
/// Steps of 0.5 s ([`half_second_steps`]).
/// Asserts a walk caught the kick `what` said: it did not fall, walked on more than 2 m and
/// stayed within 0.3 m of its line.
fn assert_walked_on(s: &GaitSummary, what: &str) {
    assert!(!s.fell, "{what}: fell at {:?}", s.fall_time_secs);
    assert!(s.forward_m > 2.0, "{what}: walked on {} m", s.forward_m);
    assert!(s.lateral_m.abs() < 0.3, "{what}: {} m off the line", s.lateral_m);
}

#[test]
fn walk_scenario_steps_out_after_late_and_stance_side_kicks() {
    // 0.45 m/s × 35.7 kg in 0.05 s on the pelvis.
    let kick = |sc: &mut Scenario, time: f64, force_y: f64| {
        half_second_steps(sc);
        sc.duration_secs = 9.0;
        sc.checks = Default::default();
        sc.pushes.push(Push { time, duration: 0.05, force: [0.0, force_y, 0.0], body: None });
    };
    let shipped = Scenario::load(scenarios().join("walk.toml")).unwrap();
    assert!(shipped.walk.step_adjust_until > 0.9 && shipped.walk.swing_from_measured_pelvis);
    let defaults = WalkOptions::default();
    for (time, force_y) in [(4.68, 321.3), (4.4, -321.3)] {
        let (s, _, _) = run_scenario(shipped.clone(), |sc| kick(sc, time, force_y));
        assert_walked_on(&s, &format!("kick {force_y} N at {time} s"));
        let (s, _, _) = run_scenario(shipped.clone(), |sc| {
            kick(sc, time, force_y);
            sc.walk.step_adjust_until = defaults.step_adjust_until;
            sc.walk.swing_from_measured_pelvis = false;
        });
        assert!(s.fell, "kick {force_y} N at {time} s: the defaults fell in the lab, now walked {} m", s.forward_m);
    }
}

/// The hip strategy (`hip_gain`, on in `stand.toml`): kicks of 0.7 m/s (25 N·s) diagonally
/// forward-left and to the left, beyond what the recovery step alone catches (the capture
/// point runs past the stance sole faster than the swing foot can follow), are caught when the
/// upper body leans into the fall during the swing, moving the CMP beyond the stance sole:
/// the DCM slows and the step lands under it. Without the lean the walker falls to both.
#[test]
fn stand_scenario_hip_strategy_catches_kicks_a_step_alone_does_not() {
    // 0.7 m/s × 35.7 kg in 0.05 s on the pelvis at angle `deg` from +x.
    let kick = |sc: &mut Scenario, deg: f64| {
        let f = 0.7 * 35.7 / 0.05;
        sc.pushes.clear();
        sc.duration_secs = 6.0;
        sc.checks.max_distance = None;
        let force = [f * deg.to_radians().cos(), f * deg.to_radians().sin(), 0.0];
        sc.pushes.push(Push { time: 3.0, duration: 0.05, force, body: None });
    };
    let shipped = Scenario::load(scenarios().join("stand.toml")).unwrap();
    assert!(shipped.walk.hip_gain > 0.0);
    for deg in [45.0, 90.0] {
        let (s, _, _) = run_scenario(shipped.clone(), |sc| kick(sc, deg));
        assert!(!s.fell, "kick at {deg}°: fell at {:?}", s.fall_time_secs);
        assert!(s.distance_m < 0.5, "kick at {deg}°: recovered {} m away", s.distance_m);
        let (s, _, _) = run_scenario(shipped.clone(), |sc| {
            kick(sc, deg);
            sc.walk.hip_gain = 0.0;
        });
        assert!(s.fell, "kick at {deg}°: without the hip strategy the walker fell in the lab, now {} steps", s.steps);
    }
}

/// `walk.toml`'s quick steps (0.35 s, down to 0.2-s swings): each step moves the support under
/// the DCM sooner, so kicks of 0.5 m/s that the 0.5-s gait fell to (to the right 4.25 s in,
/// backward 4.15 s in) are caught and the walk goes on (the lab, 0.5 m/s kicks in 8 directions
/// × 10 times 4.0-4.45 s: 3 falls of 80, 7 at 0.5 s).
#[test]
fn walk_scenario_quick_steps_catch_kicks_the_half_second_gait_falls_to() {
    // 0.5 m/s × 35.7 kg in 0.05 s on the pelvis.
    let kick = |sc: &mut Scenario, time: f64, force: [f64; 3]| {
        sc.duration_secs = 9.0;
        sc.checks = Default::default();
        sc.pushes.push(Push { time, duration: 0.05, force, body: None });
    };
    let shipped = Scenario::load(scenarios().join("walk.toml")).unwrap();
    assert!(shipped.walk.step_period < 0.4, "{}", shipped.walk.step_period);
    for (time, force) in [(4.25, [0.0, -357.0, 0.0]), (4.15, [-357.0, 0.0, 0.0])] {
        let (s, _, _) = run_scenario(shipped.clone(), |sc| kick(sc, time, force));
        assert_walked_on(&s, &format!("kick {force:?} at {time} s"));
        let (s, _, _) = run_scenario(shipped.clone(), |sc| {
            kick(sc, time, force);
            half_second_steps(sc);
        });
        assert!(s.fell, "kick {force:?} at {time} s: the 0.5-s gait fell in the lab, now walked {} m", s.forward_m);
    }
}

/// `plan_every_ticks` (tput, session 6): fed the states of the every-step walk, a walker that
/// solves on one step in two commands what the every-step walker does within a bound on every
/// step, the steps between its solves included (its targets, feed-forward and gains held, the
/// PD on the measured joints), and is deterministic.
#[test]
fn solving_every_other_step_commands_what_every_step_solving_does() {
    use std::sync::Arc;
    use twin_core::control::{Actuation, Controller, Observation, reset_to_home};
    use twin_core::mj::{Data, Model};
    let loaded = Model::from_file(humanoid()).unwrap();
    let model = Arc::new(twin_scenario::prepare_model(&loaded, twin_controllers::walk::WALK_ARMATURE, None).unwrap());
    let actuation = Actuation::of(&model);
    let limits = actuation.limits(&model);
    let walker =
        |k| Walker::new(&model, WalkOptions { vx: 0.3, plan_every_ticks: k, ..WalkOptions::default() }).unwrap();
    let mut data = Data::new(model.clone()).unwrap();
    // 1 s crouch, then 2 s of walking (four steps) at 500 Hz.
    let steps = 1500;
    let run = |data: &mut Data| {
        reset_to_home(data).unwrap();
        let (mut every, mut half) = (walker(1), walker(2));
        every.reset(&model, &Observation::of(data)).unwrap();
        half.reset(&model, &Observation::of(data)).unwrap();
        let n = actuation.len(&model);
        let (mut a, mut b) = (vec![0.0; n], vec![0.0; n]);
        // Per step, the largest command difference as a fraction of its actuator's range;
        // on solve steps (even) and between them (odd).
        let mut diffs = [Vec::new(), Vec::new()];
        for step in 0..steps {
            data.step1().unwrap();
            every.compute(&model, &Observation::of(data), &mut a);
            half.compute(&model, &Observation::of(data), &mut b);
            actuation.apply(data, &a);
            data.step2().unwrap();
            let worst =
                a.iter().zip(&b).zip(&limits).map(|((x, y), l)| (x - y).abs() / (l[1] - l[0])).fold(0.0, f64::max);
            diffs[step % 2].push(worst);
        }
        (diffs, b, data.qpos().to_vec())
    };
    let (diffs, last, qpos) = run(&mut data);
    assert!(qpos[2] > 0.5 && qpos[0] > 0.3, "the every-step walker walks: {:?}", &qpos[..3]);
    for (k, d) in diffs.iter().enumerate() {
        let mean = d.iter().sum::<f64>() / d.len() as f64;
        let mut sorted = d.clone();
        sorted.sort_by(f64::total_cmp);
        let p95 = sorted[sorted.len() * 95 / 100];
        println!(
            "{} steps: worst command difference, mean {mean:.4}, 95th percentile {p95:.4} of the range",
            ["solve", "between"][k]
        );
        // Measured: 0.015 and 0.058 on solve steps, 0.066 and 0.22 between them (the hip
        // pitch joints chatter at 250 Hz in this walk, and the every-step walker's targets follow).
        let (mean_max, p95_max) = [(0.03, 0.12), (0.13, 0.45)][k];
        assert!(mean < mean_max && p95 < p95_max, "{k}: mean {mean}, 95th percentile {p95}");
    }
    // Between solves it is not the every-step walker's command (its solve is a step old).
    assert!(diffs[1].iter().any(|&d| d > 1e-6));
    // Same states, same commands, bit for bit.
    assert_eq!(run(&mut data).1, last);
    // Closed loop, the shipped walk passes its checks solving on every other step.
    let walk = Scenario::load(scenarios().join("walk.toml")).unwrap();
    let (every_step, _, _) = run_scenario(walk.clone(), |_| {});
    let (summary, verdicts, _) = run_scenario(walk, |sc| sc.walk.plan_every_ticks = 2);
    assert!(verdicts.iter().all(|v| v.passed), "{verdicts:?}");
    assert!((summary.average_speed_mps - every_step.average_speed_mps).abs() < 0.05, "{summary}");
}

/// The nominal walk goes the commanded speed: `walk.toml`'s swing feet land ~5.5 cm past their
/// spots at 0.35-s steps, and with each step's advance counted from where the foot landed
/// (`progress_hold_gain` 0) every step is that much longer (0.42 m/s for 0.3 commanded); counted
/// from where it was aimed, the walking speed is within 10 % of `vx`.
#[test]
fn walk_scenario_walks_at_its_commanded_speed() {
    let shipped = Scenario::load(scenarios().join("walk.toml")).unwrap();
    let walking_speed = |s: &GaitSummary, sc: &Scenario| s.forward_m / (sc.duration_secs - sc.walk.settle_secs);
    let vx = shipped.walk.vx;
    let (s, _, _) = run_scenario(shipped.clone(), |_| {});
    assert!(!s.fell, "fell at {:?}", s.fall_time_secs);
    let held = walking_speed(&s, &shipped);
    assert!((held - vx).abs() < 0.1 * vx, "{held} m/s walking for {vx} commanded");
    let (s, _, _) = run_scenario(shipped.clone(), |sc| sc.walk.progress_hold_gain = 0.0);
    let unheld = walking_speed(&s, &shipped);
    assert!(unheld > 1.2 * vx, "without the hold {unheld} m/s for {vx} commanded");
}

/// Between solves (`plan_every_ticks` 2) the legs' targets follow the tilt feedback through
/// a linear map of their IK (and a swinging leg placed from the measured pelvis follows that
/// pelvis): fed the states of `walk.toml`'s every-step walk, the N = 2 walker's commands on
/// the steps between its solves stay near the every-step walker's, much nearer than the last
/// solve's targets held (the worst actuator's difference as a fraction of its range, in the lab:
/// mean 0.048 and 95th percentile 0.148 with the map, 0.092 and 0.211 held).
#[test]
fn held_steps_track_every_step_solving_of_the_walk_scenario() {
    use std::sync::Arc;
    use twin_core::control::{Actuation, Controller, Observation, reset_to_home};
    use twin_core::mj::{Data, Model};
    let shipped = Scenario::load(scenarios().join("walk.toml")).unwrap();
    let loaded = Model::from_file(humanoid()).unwrap();
    let model = Arc::new(twin_scenario::prepare_model(&loaded, shipped.armature, None).unwrap());
    let actuation = Actuation::of(&model);
    let limits = actuation.limits(&model);
    let walker = |k| Walker::new(&model, WalkOptions { plan_every_ticks: k, ..shipped.walk.clone() }).unwrap();
    let mut data = Data::new(model.clone()).unwrap();
    reset_to_home(&mut data).unwrap();
    let (mut every, mut half) = (walker(1), walker(2));
    every.reset(&model, &Observation::of(&data)).unwrap();
    half.reset(&model, &Observation::of(&data)).unwrap();
    let n = actuation.len(&model);
    let (mut a, mut b) = (vec![0.0; n], vec![0.0; n]);
    // 1 s crouch, then 2 s of walking (about six steps) at 500 Hz; the steps between solves.
    let mut between = Vec::new();
    for step in 0..1500 {
        data.step1().unwrap();
        every.compute(&model, &Observation::of(&data), &mut a);
        half.compute(&model, &Observation::of(&data), &mut b);
        actuation.apply(&mut data, &a);
        data.step2().unwrap();
        if step % 2 == 1 {
            between.push(
                a.iter().zip(&b).zip(&limits).map(|((x, y), l)| (x - y).abs() / (l[1] - l[0])).fold(0.0, f64::max),
            );
        }
    }
    assert!(data.qpos()[0] > 0.4 && data.qpos()[2] > 0.5, "the every-step walker walks: {:?}", &data.qpos()[..3]);
    let mean = between.iter().sum::<f64>() / between.len() as f64;
    between.sort_by(f64::total_cmp);
    let p95 = between[between.len() * 95 / 100];
    println!("between solves: worst command difference, mean {mean:.4}, 95th percentile {p95:.4} of the range");
    assert!(mean < 0.065 && p95 < 0.18, "mean {mean}, 95th percentile {p95}");
}

/// A start on raised ground: `walk_steps.toml` with the robot seated on the 3-cm platform
/// (`start_m = 0`, 3 m of it). With `follow_ground`, `com_height` counts from the soles at the
/// start, so the walker keeps its CoM 0.62 m above the platform (not 0.59 m: 3 cm more crouch
/// than on the floor) and walks along it without a fall.
#[test]
fn walks_from_a_raised_start() {
    let scenario = Scenario::load(scenarios().join("walk_steps.toml")).unwrap();
    let (summary, verdicts, last) = run_scenario(scenario, |sc| {
        sc.duration_secs = 8.0;
        let t = sc.terrain.as_mut().unwrap();
        t.start_m = Some(0.0);
        t.depth_m = Some(3.0);
        sc.checks.min_forward = Some(1.5);
    });
    assert!(!summary.fell, "{summary}");
    assert!(verdicts.iter().all(|v| v.passed), "{verdicts:?}");
    // Still on the platform at the end, the base as high above it as when walking on the floor:
    // the 0.06 m crouch from the standing CoM (0.68 m) to com_height (0.62 m), and about 1.5 cm
    // of stepping. Measured: 0.074 m below rest + 3 cm; with com_height from z = 0 (before), 0.101.
    assert!(last[0] < 3.0 && summary.forward_m > 1.5, "{summary}");
    let flat = run_scenario(stand(0.1), |_| {}).2;
    let below = flat[2] + 0.03 - last[2];
    assert!((0.05..0.085).contains(&below), "base {below} m below its rest height over the platform");
}

/// Every shipped walking scenario of the shipped humanoid has its options come out of
/// [`Scenario::fit_walk`] bit for bit as written: the shipped humanoid's derived options are
/// its defaults, and what a file sets stays. (Their results are pinned by the tests above.)
#[test]
fn shipped_scenarios_keep_their_options_when_fitted_to_the_humanoid() {
    let mut files: Vec<PathBuf> = std::fs::read_dir(scenarios())
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    files.sort();
    let mut fitted = 0;
    for f in files {
        let Ok(s) = Scenario::load(&f) else { continue };
        // (A scenario of another robot, `walk_g1.toml`, gets that robot's options.)
        if s.controller != "walk" || s.model.as_deref().is_some_and(|m| !m.ends_with("models/humanoid.urdf")) {
            continue;
        }
        let robot = s.robot(&humanoid()).unwrap();
        let mut after = s.clone();
        after.fit_walk(&robot.model).unwrap();
        assert_eq!(after.walk, s.walk, "{}", f.display());
        fitted += 1;
    }
    assert!(fitted >= 3, "walking scenarios fitted: {fitted}");
    // `twin sim --controller walk` without a file: the defaults.
    let mut s = Scenario::defaults("walk", 1.0);
    let robot = s.robot(&humanoid()).unwrap();
    s.fit_walk(&robot.model).unwrap();
    assert_eq!(s.walk, WalkOptions::default());
}

/// `walk_slope.toml` nominal, its down ramp's mean forward speed (base from x = 4.2 m to 5.8 m)
/// and the summary.
fn down_ramp(edit: impl FnOnce(&mut Scenario)) -> (GaitSummary, Option<f64>) {
    let (summary, speeds) = base_speeds("walk_slope.toml", edit, &[(4.2, 5.8)]);
    (summary, speeds[0])
}

/// The shipped scenario `file` nominal, as `edit` leaves it: the summary and the base's mean
/// forward speed over each span (from x, to x; m), m/s (`None` where it never got to the span's end).
fn base_speeds(file: &str, edit: impl FnOnce(&mut Scenario), spans: &[(f64, f64)]) -> (GaitSummary, Vec<Option<f64>>) {
    let mut scenario = Scenario::load(scenarios().join(file)).unwrap();
    edit(&mut scenario);
    let robot = scenario.robot(&humanoid()).unwrap();
    let mut controller = scenario.controller(&robot.model).unwrap();
    let mut check = scenario.check(&robot.model).unwrap();
    let mut base = BaseX(Vec::new());
    let options = SimOptions { duration_secs: scenario.duration_secs, seed: scenario.seed };
    sim::simulate_with(&robot, controller.as_mut(), &options, None, &mut |_| {}, &mut [], &mut [&mut check, &mut base])
        .unwrap();
    let at = |x: f64| base.0.iter().find(|p| p.1 >= x).map(|p| p.0);
    let speeds = spans.iter().map(|&(a, b)| at(a).zip(at(b)).map(|(ta, tb)| (b - a) / (tb - ta))).collect();
    (check.metrics.summary(), speeds)
}

/// Blind up a 5° ramp (`walk_slope.toml`, the up ramp from x = 1 m to 3 m): the swing foot's
/// reach below the expected ground (`step_down_reach`, for the down ramp) is left out while the
/// footholds' mid-stance reads rise (`GROUND_RISE_M`), so landings are not pushed 1.5 cm into
/// the up slope. The base climbs from x = 1.2 m to 2.8 m at 0.42 m/s (0.38 commanded); with the
/// reach on every step (before) it climbed at 0.33 m/s, and the walker's DCM stayed behind its
/// feet (short steps) where kicks then felled it. Down the ramp the reach is still there: 0.40
/// m/s. (With the landing read once a descending sole stops, `landing_read_at_rest`, on in the
/// file, the nominal climb is slower, 0.35 m/s, so it is off here: this pins the reach alone.
/// The file no longer reaches: under kicks the reach cost more than it saved, BENCHMARKS.md.)
#[test]
fn climbs_a_slope_without_reaching_into_it() {
    let reach = |sc: &mut Scenario| {
        sc.walk.landing_read_at_rest = false;
        sc.walk.step_down_reach = 0.015;
    };
    let (summary, speeds) = base_speeds("walk_slope.toml", reach, &[(1.2, 2.8), (4.2, 5.8)]);
    println!(
        "{summary}
up the ramp: {:?} m/s, down: {:?} m/s",
        speeds[0], speeds[1]
    );
    assert!(!summary.fell && summary.forward_m > 6.5, "{summary}");
    let (up, down) = (speeds[0].unwrap(), speeds[1].unwrap());
    assert!((0.37..0.46).contains(&up), "up the ramp at {up} m/s, commanded 0.38 (0.33 reaching into it)");
    assert!((0.3..0.46).contains(&down), "down the ramp at {down} m/s, commanded 0.38");
}

/// Blind down a 5° ramp (`walk_slope.toml`): with the ground under each foot read in mid stance
/// (`stance_ground_read`), landing heights carried along the footholds' slope
/// (`ground_slope_gain`) and a landing's ground read once the foot carries load (its contact
/// sensor, `landing_read_at_rest`), the walker goes up, across and down the hill at its
/// commanded pace: 0.38 m/s commanded, measured 0.408 m/s down the ramp, past its foot (6 m)
/// without a fall. With the touchdown's sole height alone (before: no mid-stance read, no
/// slope, the read at the planned touch-down, a swing reaching 1.5 cm below the expected
/// ground), feet that land late on the down ramp read the ground too high, each swing aims
/// higher, and the walker ran down at 0.68 m/s.
#[test]
fn walks_down_a_slope_at_its_commanded_pace() {
    let (summary, speed) = down_ramp(|_| {});
    println!("{summary}\ndown the ramp: {speed:?} m/s");
    assert!(!summary.fell && summary.forward_m > 6.5, "{summary}");
    let speed = speed.unwrap();
    assert!((0.3..0.46).contains(&speed), "down the ramp at {speed} m/s, commanded 0.38");
    let (before, speed) = down_ramp(|sc| {
        sc.walk.stance_ground_read = false;
        sc.walk.ground_slope_gain = 0.0;
        sc.walk.landing_read_at_rest = false;
        sc.walk.step_down_reach = 0.015;
    });
    println!("touchdown reads alone: {before}\ndown the ramp: {speed:?} m/s");
    assert!(before.fell || speed.is_some_and(|v| v > 0.5), "{before}; {speed:?} m/s");
}

/// The Unitree G1 (derived options, 0.25 m/s, foot sensors on its ankle-roll links, the
/// terrain keys of `walk_slope.toml`) on the hill of `walk_slope.toml` at `slope_deg`, with
/// `walk` (TOML lines added to the `[walk]` table); its gait summary.
fn g1_on_the_hill(slope_deg: f64, walk: &str) -> GaitSummary {
    let path = example_robot("g1_description/urdf/g1_29dof_rev_1_0.urdf");
    let text = format!(
        "model = {path:?}\nduration = 30.0\ncontroller = \"walk\"\n\
         contact_sensors = [\"left_ankle_roll_link\", \"right_ankle_roll_link\"]\n\
         [terrain]\nkind = \"slope\"\nslope_deg = {slope_deg}\nstart_m = 1.0\nramp_m = 2.0\nplateau_m = 1.0\n\
         [walk]\nvx = 0.25\nfollow_ground = true\nground_pitch_gain = 1.0\nstance_ground_read = true\n\
         ground_slope_gain = 1.0\nlanding_read_at_rest = true\n{walk}\n"
    );
    let summary = derived_run(Scenario::parse(&scenarios().join("inline.toml"), &text).unwrap(), &path);
    println!("G1, {slope_deg}° hill, {walk:?}: {summary}");
    summary
}

/// Why the G1 fell where the ramp begins, and the fix: its level swing foot meets the up ramp
/// before its planned touchdown (the toe spheres, 12 cm ahead of the ankle, touch the rising
/// ground first), and its target went on down below that contact, so the stiff swing leg drove
/// the foot into the ramp and lifted the body (pelvis 0.738 → 0.771 m at the second step on the
/// ramp): the feet, unloaded, slid back (the stance soles 3 cm and 19 cm) and it fell at 7.0 s,
/// 1.09 m forward (the ramp from 1 m; 7.6 s, 1.38 m without the sensors). With
/// `swing_holds_at_contact` a swing foot whose sensor carries load late in the swing is held
/// where it met the ground: on a 3° hill the G1 walks up, across and down without a fall
/// (6.78 m in 30 s; before: fell at 7.6 s, 1.17 m), on the 5° hill it climbs and crosses the
/// top (to 5.04 m; the down ramp from 4 m) and falls on the down ramp at 19.6 s, where a foot
/// lands late (not fixed here: BENCHMARKS.md). On flat ground (slope 0, same terrain mode) it
/// walks as before: 6.68 m against 6.59 m.
#[test]
fn g1_climbs_a_hill_once_its_swing_foot_stops_at_the_ground_it_meets() {
    let hold = "swing_holds_at_contact = true";
    let before = g1_on_the_hill(5.0, "");
    assert!(before.fell && before.forward_m < 2.0, "before: {before}");
    let up = g1_on_the_hill(5.0, hold);
    assert!(up.forward_m > 4.0, "climbs and crosses the top of the 5° hill: {up}");
    assert!(up.fall_time_secs.is_none_or(|t| t > 15.0), "{up}");
    let three = g1_on_the_hill(3.0, hold);
    assert!(!three.fell && three.forward_m > 6.5, "up and down the 3° hill: {three}");
    let three_before = g1_on_the_hill(3.0, "");
    assert!(three_before.fell && three_before.forward_m < 2.0, "before, 3°: {three_before}");
}

/// Blind over rough ground (`walk_rough.toml`, ±1 cm from x = 0.6 m): the steps come out
/// shorter than asked (bumps stop a swing foot short, landing corrections pull steps back), and
/// holding the pace in step length (`stride_hold_gain`, on in the file) brings the base's speed
/// over the rough stretch (x from 1 m to 5 m) back to the commanded 0.38 m/s: 0.378 m/s against 0.338 m/s
/// not held (nominal, 6.13 m against 5.67 m in 18 s, both without a fall)
#[test]
fn holds_its_pace_on_rough_ground() {
    let spans = [(1.0, 5.0)];
    let (held, speed) = base_speeds("walk_rough.toml", |_| {}, &spans);
    let (free, free_speed) = base_speeds("walk_rough.toml", |sc| sc.walk.stride_hold_gain = 0.0, &spans);
    println!("held: {held}\n{speed:?} m/s\nnot held: {free}\n{free_speed:?} m/s");
    assert!(!held.fell && !free.fell, "{held}\n{free}");
    let (speed, free_speed) = (speed[0].unwrap(), free_speed[0].unwrap());
    assert!((speed - 0.38).abs() < 0.02, "held: {speed} m/s over the rough stretch, commanded 0.38");
    assert!(speed - free_speed > 0.015, "held {speed} m/s against {free_speed} m/s not held");
}

/// When each foot's contact with the ground (the world body) starts after at least 0.05 s off
/// it, from MuJoCo's contacts: the landings as the physics has them, to hold the walker's
/// (read from its sole's motion, no contact access) against.
struct FootContacts {
    /// Foot index per geom (−1: not a foot's).
    geom_foot: Vec<i32>,
    air_secs: [f64; 2],
    /// (time, foot) of each contact start.
    starts: Vec<(f64, usize)>,
}

impl FootContacts {
    fn new(model: &twin_core::mj::Model, feet: [usize; 2]) -> FootContacts {
        let geom_foot = (0..model.ngeom())
            .map(|g| {
                let body = model.geom_bodyid()[g] as usize;
                feet.iter().position(|&f| model.in_subtree(f, body)).map_or(-1, |k| k as i32)
            })
            .collect();
        FootContacts { geom_foot, air_secs: [0.0; 2], starts: Vec::new() }
    }
}

impl Observer for FootContacts {
    fn observe(&mut self, step: &StepView<'_>) -> twin_core::Result<Flow> {
        let model = step.data.model();
        let mut now = [false; 2];
        for [g1, g2] in step.data.contact_geoms() {
            for (a, b) in [(g1, g2), (g2, g1)] {
                if a >= 0 && b >= 0 && self.geom_foot[a as usize] >= 0 && model.geom_bodyid()[b as usize] == 0 {
                    now[self.geom_foot[a as usize] as usize] = true;
                }
            }
        }
        for (k, (&on, air)) in now.iter().zip(&mut self.air_secs).enumerate() {
            if on {
                if *air >= 0.05 {
                    self.starts.push((step.sim_secs, k));
                }
                *air = 0.0;
            } else {
                *air += step.dt_secs;
            }
        }
        Ok(Flow::Continue)
    }
}

/// `walk_steps.toml` with the robot seated on the 3-cm platform (`start_m = 0`), which ends
/// 1.5 m ahead: a step down, 8 s, the walker's options as `edit` leaves them, nominal. The
/// summary, the walker's touch-downs and the feet's contact starts.
fn step_down_touchdowns(
    edit: impl FnOnce(&mut WalkOptions),
) -> (GaitSummary, Vec<twin_controllers::walk::TouchdownEvent>, Vec<(f64, usize)>) {
    step_down_touchdowns_of(&humanoid(), &[], edit)
}

/// [`step_down_touchdowns`] for the robot file `urdf`, with a contact sensor on each link of
/// `contact_sensors` (the scenario key).
fn step_down_touchdowns_of(
    urdf: &Path,
    contact_sensors: &[&str],
    edit: impl FnOnce(&mut WalkOptions),
) -> (GaitSummary, Vec<twin_controllers::walk::TouchdownEvent>, Vec<(f64, usize)>) {
    let mut scenario = Scenario::load(scenarios().join("walk_steps.toml")).unwrap();
    scenario.contact_sensors = contact_sensors.iter().map(|l| l.to_string()).collect();
    edit(&mut scenario.walk);
    scenario.duration_secs = 8.0;
    let terrain = scenario.terrain.as_mut().unwrap();
    terrain.start_m = Some(0.0);
    terrain.depth_m = Some(1.5);
    scenario.model = Some(urdf.to_path_buf());
    let robot = scenario.robot(urdf).unwrap();
    let mut walker = Walker::new(&robot.model, scenario.walk.clone()).unwrap();
    let mut check = scenario.check(&robot.model).unwrap();
    let mut contacts = FootContacts::new(&robot.model, walker.feet().0);
    let options = SimOptions { duration_secs: scenario.duration_secs, seed: scenario.seed };
    sim::simulate_with(&robot, &mut walker, &options, None, &mut |_| {}, &mut [], &mut [&mut check, &mut contacts])
        .unwrap();
    (check.metrics.summary(), walker.state().touchdowns.clone(), contacts.starts)
}

/// The walk of [`step_down_touchdowns`] went on past the step (no fall, > 2 m); returns the
/// first landing wholly past the down edge (x = 1.5 m, plus the sole's half length and a
/// margin) and the start of MuJoCo's last contact of that foot before it.
fn landing_past_the_edge(
    summary: &GaitSummary,
    events: &[twin_controllers::walk::TouchdownEvent],
    starts: &[(f64, usize)],
) -> (twin_controllers::walk::TouchdownEvent, f64) {
    println!("{summary}");
    assert!(!summary.fell && summary.forward_m > 2.0, "{summary}");
    let down = *events.iter().find(|e| e.sole_world_m[0] > 1.5 + 0.15).expect("a landing past the step down");
    let contact = starts
        .iter()
        .filter(|&&(t, leg)| leg == down.leg && t <= down.time_secs + 0.002)
        .map(|&(t, _)| t)
        .next_back()
        .expect("a contact start of that foot");
    (down, contact)
}

/// Touch-down from contact, blind, on a step down (3 cm at x = 1.5 m, [`step_down_touchdowns`]):
/// the first foot to land past the edge is late (the ground 3 cm below the platform its swing
/// was planned on); its step ends on time and its target goes on down through the next double
/// support until the foot lands, read from the sole's motion (no contact access). The landing
/// the walker logs is within 50 ms after MuJoCo's first contact of that foot (a heel or toe
/// touches first and the sole rolls flat; the detector then waits for 10 ms of a still sole,
/// solving every 6 ms; measured 40 ms, the landing 112 ms after the planned touch-down), after
/// the planned touch-down, and at the ground's height (0) within 5 mm (measured 0.0 mm);
/// landings on the platform are at its 3 cm within 5 mm (measured 29.9 mm).
/// With touch-down at the planned time (before), that foot was more than 1 cm above the ground
/// when its step ended, and that height was taken as the ground under it.
#[test]
fn swing_ends_at_contact_on_a_step_down() {
    let (summary, events, starts) = step_down_touchdowns(|w| w.touchdown_from_contact = true);
    let past_edge = |e: &&twin_controllers::walk::TouchdownEvent| e.sole_world_m[0] > 1.5 + 0.15;
    let (down, contact) = landing_past_the_edge(&summary, &events, &starts);
    println!("step down: {down:?}; MuJoCo contact start {contact:.3} s");
    assert!(down.from_contact, "{down:?}");
    assert!(down.time_secs > down.planned_secs, "a late landing: {down:?}");
    assert!(
        (0.0..=0.05).contains(&(down.time_secs - contact)),
        "landed {:.3} s after contact",
        down.time_secs - contact
    );
    assert!(down.sole_world_m[2].abs() <= 0.005, "landed at z = {:.4} m on ground at 0", down.sole_world_m[2]);
    let on_platform: Vec<_> = events.iter().filter(|e| (0.15..1.5 - 0.15).contains(&e.sole_world_m[0])).collect();
    assert!(on_platform.len() >= 4, "{on_platform:?}");
    for e in &on_platform {
        assert!(e.from_contact && (e.sole_world_m[2] - 0.03).abs() <= 0.005, "on the 3-cm platform: {e:?}");
    }
    let (_, before, _) = step_down_touchdowns(|_| {});
    let down = *before.iter().find(past_edge).expect("a landing past the step down");
    println!("planned touch-down: {down:?}");
    assert!(down.sole_world_m[2] > 0.01, "at the planned time the foot was on the ground already: {down:?}");
}

/// Touch-down from contact read from foot sensors: the humanoid with a Gazebo `contact` sensor
/// on each foot link (a MuJoCo `touch` sensor over the sole after conversion) on the step down
/// of [`step_down_touchdowns`]. The walker finds a touch sensor on each foot (not the sole's
/// motion), and the foot past the edge lands, by its sensor's load, within 15 ms after MuJoCo's
/// first contact of that foot (measured 2 ms: the load crosses 10 % of the weight as the heel
/// or toe strikes; the sole's motion needs the sole rolled flat and still: 40 ms in the blind
/// test), at the floor's height within 1 cm (measured 3.7 mm: the sole is still rolling flat
/// when it counts as landed).
#[test]
fn swing_ends_at_a_foot_sensors_load_on_a_step_down() {
    use twin_controllers::walk::contact::{ContactSensing, FootSensor};
    let dir = tempfile::tempdir().unwrap();
    let urdf = dir.path().join("humanoid_touch.urdf");
    let text = std::fs::read_to_string(humanoid()).unwrap();
    let sensors: String = ["left", "right"]
        .iter()
        .map(|side| {
            format!(
                "  <gazebo reference=\"{side}_foot_link\">\n    <sensor name=\"{side}_foot_contact\" type=\"contact\">\n      \
                 <update_rate>500</update_rate>\n      <contact><collision>{side}_foot_link_collision</collision></contact>\n    \
                 </sensor>\n  </gazebo>\n"
            )
        })
        .collect();
    assert!(text.contains("</robot>"));
    std::fs::write(&urdf, text.replacen("</robot>", &format!("{sensors}</robot>"), 1)).unwrap();
    let robot = twin_core::robot::Robot::load(&urdf).unwrap();
    let walker = Walker::new(&robot.model, WalkOptions::default()).unwrap();
    let sensing = ContactSensing::new(&robot.model, walker.feet().0, 350.0);
    for foot in &sensing.feet {
        assert!(matches!(foot, FootSensor::Touch(a) if a.len() == 1), "{:?}", sensing.feet);
    }

    let (summary, events, starts) = step_down_touchdowns_of(&urdf, &[], |w| w.touchdown_from_contact = true);
    let (down, contact) = landing_past_the_edge(&summary, &events, &starts);
    println!("step down, by the foot sensor: {down:?}; MuJoCo contact start {contact:.3} s");
    assert!(down.from_contact && down.time_secs > down.planned_secs, "{down:?}");
    assert!(
        (0.0..=0.015).contains(&(down.time_secs - contact)),
        "landed {:.3} s after contact",
        down.time_secs - contact
    );
    assert!(down.sole_world_m[2].abs() <= 0.01, "landed at z = {:.4} m on ground at 0", down.sole_world_m[2]);
}

/// The landing ground read once a descending sole stops (`landing_read_at_rest`), blind, on
/// the step down of [`step_down_touchdowns`]: the first foot past the edge is still coming down
/// at its planned touch-down (its swing aimed at the platform, 3 cm up), so the walker takes the
/// platform's ground until the sole stops, and then its height: the ground under it is the
/// floor's (0) within 5 mm. Read at the planned touch-down (the option off), that foot's ground
/// is more than 1 cm above the floor: the foot was still in the air.
#[test]
fn landing_ground_read_once_the_sole_stops() {
    let past_edge = |e: &&twin_controllers::walk::TouchdownEvent| e.sole_world_m[0] > 1.5 + 0.15;
    let (summary, events, _) = step_down_touchdowns(|w| w.landing_read_at_rest = true);
    println!("{summary}");
    let down = *events.iter().find(past_edge).expect("a landing past the step down");
    println!("read once stopped: {down:?}");
    assert!(!summary.fell && summary.forward_m > 2.0, "{summary}");
    assert!(down.ground_secs > down.time_secs, "read at the touch-down, in the air: {down:?}");
    assert!(down.ground_m.abs() <= 0.005, "ground {:.4} m under a foot on the floor at 0", down.ground_m);
    let (_, before, _) = step_down_touchdowns(|_| {});
    let down = *before.iter().find(past_edge).expect("a landing past the step down");
    println!("read at the planned touch-down: {down:?}");
    assert!(down.ground_m > 0.01, "at the planned time the foot was on the ground already: {down:?}");
}

/// The landing ground read once the foot carries load (`landing_read_at_rest` on a robot with
/// foot sensors: the scenario's `contact_sensors` on both feet, MuJoCo touch sensors), on the
/// step down of [`step_down_touchdowns`]: the walker finds a touch sensor on each foot; the
/// first foot past the edge reads no load at its planned touch-down (its swing aimed at the
/// platform, 3 cm up: in the air), so its ground is the platform's until it carries more than
/// 10 % of the weight and its sole stops, and then its height: the floor's (0) within 5 mm, read
/// after MuJoCo's first contact of that foot and after the planned touch-down.
#[test]
fn landing_ground_read_once_the_foot_carries_load() {
    use twin_controllers::walk::contact::{ContactSensing, FootSensor};
    let feet = ["left_foot_link", "right_foot_link"];
    let mut scenario = Scenario::load(scenarios().join("walk_steps.toml")).unwrap();
    scenario.contact_sensors = feet.iter().map(|l| l.to_string()).collect();
    let robot = scenario.robot(&humanoid()).unwrap();
    let walker = Walker::new(&robot.model, WalkOptions::default()).unwrap();
    let sensing = ContactSensing::new(&robot.model, walker.feet().0, 350.0);
    for foot in &sensing.feet {
        assert!(matches!(foot, FootSensor::Touch(a) if a.len() == 1), "{:?}", sensing.feet);
    }
    let (summary, events, starts) = step_down_touchdowns_of(&humanoid(), &feet, |w| w.landing_read_at_rest = true);
    println!("{summary}");
    assert!(!summary.fell, "{summary}");
    let down = *events.iter().find(|e| e.sole_world_m[0] > 1.5 + 0.15).expect("a landing past the step down");
    let contact = starts
        .iter()
        .filter(|&&(t, leg)| leg == down.leg && t <= down.ground_secs)
        .map(|&(t, _)| t)
        .next_back()
        .expect("a contact start of that foot before its read");
    println!("read once loaded: {down:?}; MuJoCo contact start {contact:.3} s");
    assert!(down.ground_secs > down.time_secs, "read at the touch-down, in the air: {down:?}");
    assert!(down.ground_secs >= contact, "read before the foot touched the ground: {down:?}, contact {contact:.3} s");
    assert!(down.ground_m.abs() <= 0.005, "ground {:.4} m under a foot on the floor at 0", down.ground_m);
}

/// A scenario's `contact_sensors` on a robot twin did not shape: the Unitree G1, whose feet
/// (`left_ankle_roll_link`, `right_ankle_roll_link`) touch the ground with four 5-mm spheres
/// each. Each foot gets a touch sensor over every sphere, the walker's contact sensing finds
/// the four on each foot, and standing 3 s under the walker the two feet's sensors together
/// read the robot's weight (its bodies' masses × g, 33 kg) within 5 %: the load the walker's
/// landing test (10 % of the weight) reads is the load the feet carry. A sensor over the first
/// sphere alone (a Gazebo contact sensor's one collision) would read one corner's share.
#[test]
fn contact_sensors_on_the_g1s_feet_read_its_weight() {
    use twin_controllers::walk::contact::{ContactSensing, FootSensor};
    let g1 = example_robot("g1_description/urdf/g1_29dof_rev_1_0.urdf");
    let text = format!(
        "model = {g1:?}\nduration = 3.0\ncontact_sensors = [\"left_ankle_roll_link\", \"right_ankle_roll_link\"]\n"
    );
    let (robot, summary, _, last) = run_inline(&g1, &text);
    assert!(!summary.fell, "{summary}");
    let weight_n = robot.model.body_mass().iter().sum::<f64>() * -robot.model.gravity()[2];
    let walker = Walker::new(&robot.model, WalkOptions::default()).unwrap();
    let sensing = ContactSensing::new(&robot.model, walker.feet().0, weight_n);
    for foot in &sensing.feet {
        assert!(matches!(foot, FootSensor::Touch(a) if a.len() == 4), "{:?}", sensing.feet);
    }
    let load: f64 = (0..2).map(|leg| sensing.load_n(leg, &last.1).unwrap()).sum();
    println!("G1 weight {weight_n:.1} N; feet's touch sensors {load:.1} N");
    assert!((load / weight_n - 1.0).abs() < 0.05, "feet read {load:.1} N of a {weight_n:.1} N robot");
}

/// A scenario's `contact_sensors` naming a link its robot lacks: the error names the scenario
/// file, the key's line and the key, the robot's file, and the links to choose from.
#[test]
fn contact_sensors_on_a_missing_link_name_the_scenario_line_and_the_links() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("feet.toml");
    let text = format!("model = {:?}\nduration = 1.0\ncontact_sensors = [\"left_foot\"]\n", humanoid());
    std::fs::write(&file, text).unwrap();
    let scenario = Scenario::load(&file).unwrap();
    let e = scenario.robot(&humanoid()).unwrap_err().to_string();
    assert!(e.starts_with(&format!("{}:3: `contact_sensors`: ", file.display())), "{e}");
    assert!(e.contains("humanoid.urdf has no link \"left_foot\"") && e.contains("left_foot_link"), "{e}");
}
