//! The recording's seams: one topic table turned into typed messages once per step, fed to
//! every sink (the MCAP file, a sink written outside twin-core); a controller's own topics
//! (its diagnostics) recorded like the table's.

use std::path::PathBuf;
use std::sync::{Arc, Mutex};
use twin_core::control::{Controller, Observation, PdHold, PdHoldOptions};
use twin_core::log::{Header, Log, Odometry, PointStamped, ReadOptions, RosMessage};
use twin_core::mj::Model;
use twin_core::robot::Robot;
use twin_core::sim::{self, RecordOptions, Recording, SimOptions};
use twin_core::topics::{Qos, Sink, TopicInfo, TopicKind, TypedMessage};

fn humanoid() -> Robot {
    Robot::load(PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../models/humanoid.urdf")).unwrap()
}

/// PD hold that publishes the base position it observed as a "CoM" point every 10th step.
struct HoldWithDiagnostics {
    inner: PdHold,
    step: u64,
    point: PointStamped,
    fresh: bool,
}

impl Controller for HoldWithDiagnostics {
    fn name(&self) -> &'static str {
        "hold-with-diagnostics"
    }
    fn reset(&mut self, model: &Model, observation: &Observation<'_>) -> twin_core::Result<()> {
        self.step = 0;
        self.inner.reset(model, observation)
    }
    fn compute(&mut self, model: &Model, observation: &Observation<'_>, command: &mut [f64]) {
        // Emitted by this step's diagnostics only.
        self.fresh = self.step.is_multiple_of(10);
        if self.fresh {
            let stamp_nanos = (observation.time_secs * 1e9).round() as i64;
            self.point.header = Header { stamp_nanos, frame_id: "odom".into() };
            self.point.point = [observation.qpos[0], observation.qpos[1], observation.qpos[2]];
        }
        self.step += 1;
        self.inner.compute(model, observation, command);
    }
    fn topics(&self) -> Vec<TopicInfo> {
        vec![TopicInfo {
            name: "/test/com".into(),
            type_name: PointStamped::TYPE_NAME,
            rate_hz: None,
            frame_id: "odom".into(),
            qos: Qos::STREAM,
            kind: TopicKind::Controller(0),
        }]
    }
    fn diagnostics(&self, emit: &mut dyn FnMut(usize, u64, TypedMessage<'_>)) {
        if self.fresh {
            emit(0, self.point.header.stamp_nanos as u64, TypedMessage::Point(&self.point));
        }
    }
}

/// What [`Counter`] saw: messages per topic, and `/odom`'s heights (log time, m).
type Seen = (Vec<(String, u64)>, Vec<(u64, f64)>);

/// A sink outside twin-core: counts messages per topic and keeps `/odom`'s heights.
#[derive(Clone, Default)]
struct Counter(Arc<Mutex<Seen>>);

impl Sink for Counter {
    fn add_topic(&mut self, _id: usize, topic: &TopicInfo) -> twin_core::Result<bool> {
        self.0.lock().unwrap().0.push((topic.name.clone(), 0));
        Ok(true)
    }
    fn write(&mut self, _id: usize, topic: &TopicInfo, t: u64, message: &TypedMessage<'_>) -> twin_core::Result<()> {
        let mut g = self.0.lock().unwrap();
        g.0.iter_mut().find(|(n, _)| *n == topic.name).unwrap().1 += 1;
        if let TypedMessage::Odometry(o) = message {
            g.1.push((t, o.position[2]));
        }
        Ok(())
    }
}

#[test]
fn controller_diagnostics_reach_the_mcap_file_and_every_sink() {
    let robot = humanoid();
    let dir = tempfile::tempdir().unwrap();
    let mcap = dir.path().join("run.mcap");
    let options = RecordOptions { mcap: Some(mcap.clone()), ..RecordOptions::default() };
    let counter = Counter::default();
    let mut recording = Recording::with_sinks(&robot, &options, vec![Box::new(counter.clone())]).unwrap();
    let mut controller = HoldWithDiagnostics {
        inner: PdHold::new(&robot.model, PdHoldOptions::default()),
        step: 0,
        point: PointStamped::default(),
        fresh: false,
    };
    let report = sim::simulate(
        &robot,
        &mut controller,
        &SimOptions { duration_secs: 0.5, ..SimOptions::default() },
        Some(&mut recording),
        &mut |_| {},
    )
    .unwrap();
    let summary = recording.finish().unwrap();
    assert_eq!(report.steps, 250);

    // The controller's topic: one point per 10 steps (2 ms each), stamped at its observation.
    let log = Log::open(&mcap, ReadOptions::default()).unwrap();
    let (points, _) = log.read_typed::<PointStamped>("/test/com").unwrap();
    assert_eq!(points.len(), 25);
    // The points are the base position /odom reports at the same instants (odom = world).
    let (odom, _) = log.read_typed::<Odometry>("/odom").unwrap();
    for (t, p) in &points {
        assert_eq!(p.header.stamp_nanos as u64, *t);
        let o = odom.iter().find(|(to, _)| to == t).map(|(_, o)| o).unwrap();
        assert_eq!(p.point, o.position, "at t = {t} ns");
        assert!(p.point[2] > 0.5, "a standing humanoid's base is above 0.5 m: {:?}", p.point);
    }

    // The outside sink got every message the file got, topic for topic.
    let got = counter.0.lock().unwrap();
    let mut file_counts = summary.topics.clone();
    file_counts.sort();
    let mut sink_counts = got.0.clone();
    sink_counts.sort();
    assert_eq!(sink_counts, file_counts);
    assert!(file_counts.contains(&("/test/com".to_string(), 25)), "{file_counts:?}");
    // … with the same numbers.
    let heights: Vec<(u64, f64)> = odom.iter().map(|(t, o)| (*t, o.position[2])).collect();
    assert_eq!(got.1, heights);
}
