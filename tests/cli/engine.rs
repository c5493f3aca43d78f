//! A controller and a check written outside twin-core, run batched through `twin randomize`'s
//! engine: the library seams a user of twin (or the walking and grasping work) plugs into.

use randomize::{Batch, EpisodeOptions, Layout, RunOptions, Spec, run_batch};
use std::sync::atomic::AtomicBool;
use twin_core::control::{Controller, Observation};
use twin_core::engine::{Check, Flow, Measurement, Observer, StepView, Verdict};
use twin_core::mj::{Data, Model};
use twin_core::robot::Robot;

/// A user's controller: a stiff joint-space PD on every actuated joint toward the nominal pose
/// with the knees bent by `knee_bend_rad`, computed from the robot's own limits.
struct Crouch {
    /// Per actuator: (qpos address, dof, kp, kd, target).
    loops: Vec<(usize, usize, f64, f64, f64)>,
    knee_bend_rad: f64,
}

impl Crouch {
    fn new(robot: &Robot, knee_bend_rad: f64) -> Crouch {
        let mut c = Crouch { loops: Vec::new(), knee_bend_rad };
        c.bind(robot, &robot.model);
        c
    }

    fn bind(&mut self, robot: &Robot, model: &Model) {
        let home = twin_core::control::nominal_pose(model);
        self.loops = robot
            .actuators
            .iter()
            .filter_map(|a| {
                let joint = robot.joints.iter().find(|j| Some(j.id) == a.joint)?;
                let effort = joint.effort_limit.unwrap_or(50.0);
                let bend = if joint.name.contains("knee") { self.knee_bend_rad } else { 0.0 };
                // twin's one gain rule, on the joint's effective inertia, in command units.
                let inertia = 1.0 / model.dof_invweight0()[joint.dof].max(1e-12);
                let (kp, kd) = twin_core::control::pd_gains(Some(effort), inertia, &Default::default());
                Some((joint.qpos_adr, joint.dof, kp / a.gear, kd / a.gear, home[joint.qpos_adr] + bend))
            })
            .collect();
    }
}

impl Controller for Crouch {
    fn name(&self) -> &'static str {
        "crouch"
    }

    fn compute(&mut self, _model: &Model, o: &Observation<'_>, command: &mut [f64]) {
        for (u, &(adr, dof, kp, kd, target)) in self.loops.iter().enumerate() {
            command[u] = kp * (target - o.qpos[adr]) - kd * o.qvel[dof];
        }
    }
}

/// A user's check: the floating base never drops below `fraction` of its initial height.
struct StaysUp {
    fraction: f64,
    base: usize,
    start_z: f64,
    min_z: f64,
}

impl Observer for StaysUp {
    fn start(&mut self, _model: &Model, data: &Data) -> twin_core::Result<()> {
        self.start_z = data.xpos()[self.base][2];
        self.min_z = self.start_z;
        Ok(())
    }

    fn observe(&mut self, step: &StepView<'_>) -> twin_core::Result<Flow> {
        self.min_z = self.min_z.min(step.data.xpos()[self.base][2]);
        Ok(Flow::Continue)
    }
}

impl Check for StaysUp {
    fn name(&self) -> &str {
        "stays_up"
    }

    fn verdict(&self) -> Verdict {
        let passed = self.min_z >= self.fraction * self.start_z;
        Verdict {
            name: self.name().into(),
            passed,
            metrics: vec![
                Measurement::new("initial base height", self.start_z, "m"),
                Measurement::new("lowest base height", self.min_z, "m"),
            ],
            details: Vec::new(),
            cause: (!passed).then(|| "the base sank".to_string()),
        }
    }
}

fn batch(knee_bend_rad: f64, fraction: f64) -> Batch {
    let path = common::repo_root().join("randomize/tests/fixtures/humanoid.xml");
    let robot = Robot::load(&path).unwrap();
    let spec = Spec::default_spec();
    let layout = Layout::new(&spec, &robot.model).unwrap();
    let options = EpisodeOptions { duration_secs: 1.5, ..EpisodeOptions::default() };
    Batch::from_robot(robot, layout, options, 5)
        .unwrap()
        .with_controller(move |r| Ok(Box::new(Crouch::new(r, knee_bend_rad))))
        .unwrap()
        .with_checks(move |r| {
            let base = r.base_body().expect("the humanoid floats");
            Ok(vec![Box::new(StaysUp { fraction, base, start_z: 0.0, min_z: 0.0 }) as Box<dyn Check>])
        })
        .unwrap()
}

use super::common;

#[test]
fn outside_controller_and_check_run_batched_deterministically() {
    // Knees bent 0.3 rad: the robot squats to about 71 % of its standing base height, a little
    // lower or higher with each episode's masses, friction and pushes; the check's 70.8 %
    // threshold falls inside that spread.
    let b = batch(0.3, 0.708);
    assert_eq!(b.controller_name(), "crouch");
    let dir = tempfile::tempdir().unwrap();
    let spec = Spec::default_spec();
    let mut reports = Vec::new();
    for threads in [1, 2] {
        let out = dir.path().join(format!("t{threads}"));
        let info = randomize::run_info(&b, "humanoid.xml", &spec, 8, None);
        let options = RunOptions { episodes: 8, threads, out_dir: Some(out.clone()), ..RunOptions::default() };
        reports.push((run_batch(&b, info, &options, &AtomicBool::new(false), &|| {}).unwrap(), out));
    }
    let ((r1, d1), (r2, d2)) = (&reports[0], &reports[1]);
    assert_eq!(r1.summary, r2.summary);
    let csv1 = std::fs::read_to_string(d1.join("episodes.csv")).unwrap();
    assert_eq!(csv1, std::fs::read_to_string(d2.join("episodes.csv")).unwrap(), "1 and 2 threads agree");
    assert!(csv1.lines().next().unwrap().contains(",checks,"), "{csv1}");
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d1.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary["run"]["controller"], "crouch");

    // Each verdict rests on the physics: re-run episodes alone and compare the check's numbers
    // with the recorded base trajectory (rows at each step's start time; base z column 3).
    let mut worker = randomize::Worker::new(&b).unwrap();
    let (mut passed, mut failed, mut succeeded) = (0, 0, 0);
    let mut ratios = Vec::new();
    for i in 0..8 {
        let mut t = randomize::episode::Trajectory::default();
        let r = worker.run(&b, i, Some(&mut t)).unwrap();
        let v = &r.checks[0];
        let start_z = v.metrics[0].value;
        let min_z = t.rows.iter().map(|row| row[3]).fold(start_z, f64::min);
        ratios.push(min_z / start_z);
        assert_eq!(v.metrics[1].value, min_z, "episode {i}");
        assert_eq!(v.passed, min_z >= 0.708 * start_z);
        // The crouch lowers the base: the PD really drives the knees.
        assert!(min_z < start_z - 0.01, "episode {i}: {min_z} vs {start_z}");
        assert_eq!(r.success(), v.passed && !r.fell && !r.unstable);
        succeeded += u64::from(r.success());
        if v.passed {
            passed += 1
        } else {
            failed += 1
        }
        let line = csv1.lines().nth(1 + i as usize).unwrap();
        assert!(line.contains(if v.passed { "stays_up=PASS" } else { "stays_up=FAIL" }), "{line}");
    }
    assert!(
        passed > 0 && failed > 0,
        "{passed} passed, {failed} failed: the threshold should split the batch: {ratios:?}"
    );
    assert_eq!(r1.summary.outcomes.succeeded, succeeded);
}
