//! Live viewers without ROS: a Foxglove WebSocket server ([`foxglove`]) that Foxglove,
//! Lichtblick and other clients connect to, and a ROS-TCP-Endpoint for Unity's
//! ROS-TCP-Connector ([`unity`]).
//!
//! Data flow in `twin sim --foxglove`: the recording's topics go to a
//! [`foxglove::FoxgloveSink`] (one more [`twin_core::topics::Sink`] beside the MCAP file, the rerun
//! recording and the DDS bridge), which streams them to subscribed clients as CDR with their
//! `ros2msg` schemas; `/robot_description` is latched. [`SimHook`], an
//! [`Observer`] of the one simulation loop, paces the run (real time × factor unless another
//! pacer runs it, as the DDS bridge does), answers the pause/resume/step/reset services between
//! steps, blocks while paused, and hands client-published joint commands to [`Teleop`], the
//! run's controller wrapper: once a client publishes a `Float64MultiArray` on
//! `/<robot>/joint_commands` (CDR, or JSON `{"data": [...]}`), its values drive the joints
//! (positions through the hold gains, as `twin sim --ros` takes them) instead of the
//! controller's. A reset acts through [`ResetOnRequest`](twin_core::engine::disturb::ResetOnRequest), a disturbance of the loop. `--unity`
//! adds a [`unity::UnitySink`] and its published commands take the same path.

pub mod foxglove;
pub mod unity;

use crate::live::{CommandInterface, Commander};
use foxglove::{Call, Server};
use serde_json::json;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use twin_core::control::{Controller, Observation};
use twin_core::engine::disturb::ResetOnRequest;
use twin_core::engine::{Flow, Observer, StepView};
use twin_core::error::Result;
use twin_core::log::cdr::{CdrReader, CdrWriter};
use twin_core::log::{Float64MultiArray, RosMessage, RosString};
use twin_core::mj::Model;
use twin_core::robot::Robot;

/// The newest command a client published, waiting for [`Teleop`].
type Slot = Arc<Mutex<Option<Float64MultiArray>>>;

/// Statistics of a viewer run.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ViewerStats {
    /// Service calls answered.
    pub service_calls: u64,
    /// Client commands taken.
    pub commands: u64,
    /// Client commands refused (wrong length, not a Float64MultiArray).
    pub rejected: u64,
    /// Resets.
    pub resets: u64,
}

/// Paces the run, serves the services and takes client commands (see the module docs).
pub struct SimHook {
    server: Option<Arc<Server>>,
    unity: Option<Arc<unity::Server>>,
    rtf: Option<f64>,
    started: Option<(Instant, f64)>,
    paused: bool,
    stepping: Option<(Call, u64)>,
    reset: Arc<AtomicBool>,
    stop: &'static AtomicBool,
    slot: Slot,
    command_topic: String,
    joint_count: usize,
    stats: ViewerStats,
    log: Box<dyn FnMut(&str) + Send>,
}

/// The run's controller with client commands on top (see the module docs).
pub struct Teleop {
    inner: Box<dyn Controller>,
    commander: Commander,
    slot: Slot,
    active: bool,
}

impl Teleop {
    /// Wraps `inner` for `model`.
    pub fn new(inner: Box<dyn Controller>, model: &Model, hook: &SimHook) -> Teleop {
        Teleop {
            inner,
            commander: Commander::new(model, CommandInterface::Position),
            slot: hook.slot.clone(),
            active: false,
        }
    }
}

impl Controller for Teleop {
    fn name(&self) -> &'static str {
        self.inner.name()
    }

    fn reset(&mut self, model: &Model, observation: &Observation<'_>) -> Result<()> {
        self.active = false;
        self.commander = Commander::new(model, CommandInterface::Position);
        self.inner.reset(model, observation)
    }

    fn compute(&mut self, model: &Model, observation: &Observation<'_>, command: &mut [f64]) {
        if let Some(m) = self.slot.lock().ok().and_then(|mut s| s.take())
            && self.commander.check(&m).is_ok()
        {
            self.commander.set_direct(&m);
            self.active = true;
        }
        if self.active {
            self.commander.compute(observation.time_secs, observation.qpos, observation.qvel, command);
        } else {
            self.inner.compute(model, observation, command);
        }
    }

    fn initial_qpos(&self, model: &Model, qpos: &mut [f64]) {
        self.inner.initial_qpos(model, qpos);
    }

    fn proceed(&mut self) -> Result<bool> {
        self.inner.proceed()
    }

    fn report(&self) -> Vec<String> {
        self.inner.report()
    }

    fn topics(&self) -> Vec<twin_core::topics::TopicInfo> {
        self.inner.topics()
    }

    fn diagnostics(&self, emit: &mut dyn FnMut(usize, u64, twin_core::topics::TypedMessage<'_>)) {
        self.inner.diagnostics(emit);
    }
}

impl SimHook {
    /// The hook of a run of `robot` streamed by a Foxglove `server` and/or a `unity` endpoint:
    /// publishes `/robot_description` to Foxglove (the robot's file when it is a URDF,
    /// latched); paces at `rtf` (None: another pacer runs the loop, or as fast as possible).
    pub fn new(
        server: Option<Arc<Server>>,
        unity: Option<Arc<unity::Server>>,
        robot: &Robot,
        rtf: Option<f64>,
        stop: &'static AtomicBool,
        log: Box<dyn FnMut(&str) + Send>,
    ) -> SimHook {
        let text = std::fs::read_to_string(&robot.path).unwrap_or_default();
        if let Some(server) = &server
            && twin_core::urdf::is_urdf(&text)
            && let Some(schema) = twin_core::log::typed::schema_text(RosString::TYPE_NAME)
        {
            let id = server.add_channel("/robot_description", RosString::TYPE_NAME, &schema, true);
            let mut cdr = CdrWriter::new();
            RosString { data: text }.encode(&mut cdr);
            server.publish(id, 0, cdr.bytes());
        }
        let joint_count = Commander::new(&robot.model, CommandInterface::Position).joint_names().len();
        SimHook {
            server,
            unity,
            rtf,
            started: None,
            paused: false,
            stepping: None,
            reset: Arc::default(),
            stop,
            slot: Arc::default(),
            command_topic: format!("/{}/joint_commands", robot.name),
            joint_count,
            stats: ViewerStats::default(),
            log,
        }
    }

    /// The reset disturbance to give the loop.
    pub fn reset_disturbance(&self) -> ResetOnRequest {
        ResetOnRequest::new(self.reset.clone())
    }

    /// The statistics so far.
    pub fn stats(&self) -> &ViewerStats {
        &self.stats
    }

    fn serve(&mut self, t_secs: f64) {
        let mut messages = self.server.as_ref().map(|s| s.take_client_messages()).unwrap_or_default();
        messages.extend(self.unity.as_ref().map(|u| u.take_client_messages()).unwrap_or_default());
        for m in messages {
            if m.topic != self.command_topic {
                self.stats.rejected += 1;
                (self.log)(&format!(
                    "a client published on {} ({}); twin takes commands on {} (std_msgs/msg/Float64MultiArray)",
                    m.topic, m.schema_name, self.command_topic
                ));
                continue;
            }
            let decoded: std::result::Result<Float64MultiArray, String> = match m.encoding.as_str() {
                "cdr" => CdrReader::new(&m.payload)
                    .and_then(|mut r| Float64MultiArray::decode(&mut r))
                    .map_err(|e| format!("not a CDR Float64MultiArray: {}", e.message)),
                "json" => serde_json::from_slice::<serde_json::Value>(&m.payload)
                    .map_err(|e| format!("invalid JSON: {e}"))
                    .and_then(|v| {
                        let data: Option<Vec<f64>> =
                            v["data"].as_array().map(|a| a.iter().filter_map(serde_json::Value::as_f64).collect());
                        data.map(|data| Float64MultiArray { data, ..Default::default() })
                            .ok_or_else(|| "JSON without a \"data\" array".to_string())
                    }),
                other => Err(format!("encoding {other:?} (give cdr or json)")),
            };
            match decoded {
                Ok(cmd) if cmd.data.len() == self.joint_count => {
                    self.stats.commands += 1;
                    if let Ok(mut s) = self.slot.lock() {
                        *s = Some(cmd);
                    }
                }
                Ok(cmd) => {
                    self.stats.rejected += 1;
                    (self.log)(&format!(
                        "command on {} has {} values, expected {} (joint positions)",
                        self.command_topic,
                        cmd.data.len(),
                        self.joint_count
                    ));
                }
                Err(why) => {
                    self.stats.rejected += 1;
                    (self.log)(&format!("command on {} refused: {why}", self.command_topic));
                }
            }
        }
        let calls = self.server.as_ref().map(|s| s.take_calls()).unwrap_or_default();
        for call in calls {
            self.stats.service_calls += 1;
            let reply = |ok: bool, message: String, paused: bool| json!({"ok": ok, "message": message, "paused": paused, "time_secs": t_secs});
            match call.service {
                1 => {
                    self.paused = true;
                    call.answer(&reply(true, "paused".into(), true));
                }
                2 => {
                    if self.stepping.is_some() {
                        call.answer(&reply(false, "a step is in progress".into(), true));
                        continue;
                    }
                    self.paused = false;
                    // Pacing goes on from now.
                    self.started = None;
                    call.answer(&reply(true, "playing".into(), false));
                }
                3 => {
                    let steps = serde_json::from_slice::<serde_json::Value>(&call.payload)
                        .ok()
                        .and_then(|v| v["steps"].as_u64())
                        .unwrap_or(1);
                    if !self.paused {
                        call.answer(&reply(false, "pause first (/twin/pause)".into(), false));
                    } else if self.stepping.is_some() {
                        call.answer(&reply(false, "a step is in progress".into(), true));
                    } else if steps == 0 {
                        call.answer(&reply(true, "0 steps".into(), true));
                    } else {
                        self.stepping = Some((call, steps));
                    }
                }
                4 => {
                    self.reset.store(true, Ordering::Relaxed);
                    self.stats.resets += 1;
                    if let Ok(mut s) = self.slot.lock() {
                        *s = None;
                    }
                    call.answer(&reply(true, "the start state comes back at the next step".into(), self.paused));
                }
                _ => call.answer(&reply(false, "no such service".into(), self.paused)),
            }
        }
    }
}

impl Observer for SimHook {
    fn observe(&mut self, step: &StepView<'_>) -> Result<Flow> {
        let t = step.sim_secs;
        self.serve(t);
        if let Some((call, left)) = self.stepping.as_mut() {
            *left -= 1;
            if *left == 0 {
                if let Some(s) = &self.server {
                    s.broadcast_time((t * 1e9).round() as u64);
                }
                call.answer(&json!({"ok": true, "message": "stepped", "paused": true, "time_secs": t}));
                self.stepping = None;
            }
        }
        while self.paused && self.stepping.is_none() && !self.stop.load(Ordering::Relaxed) {
            std::thread::sleep(Duration::from_millis(5));
            self.serve(t);
        }
        if let Some(factor) = self.rtf {
            let now = Instant::now();
            let (wall0, sim0) = *self.started.get_or_insert((now, t));
            let target = wall0 + Duration::from_secs_f64(((t - sim0) / factor).max(0.0));
            if target > now {
                std::thread::sleep(target - now);
            }
        }
        Ok(if self.stop.load(Ordering::Relaxed) { Flow::EndAfterStep } else { Flow::Continue })
    }
}

impl Drop for SimHook {
    fn drop(&mut self) {
        if let Some((call, left)) = self.stepping.take() {
            call.answer(&json!({"ok": false, "message": format!("the run ended with {left} steps to take")}));
        }
    }
}
