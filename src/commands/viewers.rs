//! The live viewers of `twin sim` (`--foxglove [ADDR:]PORT`, `--unity [[ADDR:]PORT]`) and
//! `twin view LOG --foxglove PORT`: starting the Foxglove WebSocket server and the Unity
//! ROS-TCP-Endpoint (`twin_bridges::viewer`), hooking them into the run (sinks, an observer, a
//! reset, the controller wrapper) and playing a log to Foxglove.

use anyhow::Context;
use std::io::Write;
use std::net::SocketAddr;
#[cfg(feature = "ros")]
use std::sync::Arc;

/// `PORT`, `ADDR:PORT` or `[V6]:PORT`: a port alone binds loopback (127.0.0.1).
pub fn parse_addr(option: &str, text: &str) -> anyhow::Result<SocketAddr> {
    if let Ok(port) = text.parse::<u16>() {
        return Ok(SocketAddr::from(([127, 0, 0, 1], port)));
    }
    text.parse::<SocketAddr>().with_context(|| {
        format!(
            "{option} {text:?}: give PORT (loopback), or ADDR:PORT to listen on another interface (e.g. 0.0.0.0:8765)"
        )
    })
}

#[cfg(feature = "ros")]
pub use enabled::*;

#[cfg(feature = "ros")]
mod enabled {
    use super::*;
    use twin_bridges::viewer::foxglove::{FoxgloveOptions, FoxgloveSink, Server};
    use twin_bridges::viewer::{SimHook, Teleop};
    use twin_core::robot::Robot;

    /// The viewers of a `twin sim` run.
    pub struct Viewers {
        /// The Foxglove server.
        pub foxglove: Option<Arc<Server>>,
        /// The Unity endpoint.
        pub unity: Option<Arc<twin_bridges::viewer::unity::Server>>,
        /// The run's observer.
        pub hook: SimHook,
    }

    /// Starts the Foxglove server on `foxglove` and the Unity endpoint on `unity` for
    /// `robot`, says where on stdout; `rtf`: the pacing when no other pacer runs the loop.
    pub fn start(
        foxglove: Option<SocketAddr>,
        unity: Option<SocketAddr>,
        robot: &Robot,
        rtf: Option<f64>,
    ) -> anyhow::Result<Viewers> {
        let server = foxglove
            .map(|addr| {
                Server::start(FoxgloveOptions {
                    addr,
                    robot_file: Some(robot.path.clone()),
                    ..FoxgloveOptions::default()
                })
                .map(Arc::new)
            })
            .transpose()?;
        let endpoint = unity.map(|addr| twin_bridges::viewer::unity::Server::start(addr).map(Arc::new)).transpose()?;
        twin_core::fsio::cooperate();
        let stop = twin_core::fsio::interrupt_flag();
        let hook = SimHook::new(
            server.clone(),
            endpoint.clone(),
            robot,
            rtf,
            stop,
            Box::new(|m: &str| eprintln!("warning: {m}")),
        );
        if let Some(s) = &server {
            announce(s)?;
        }
        let mut out = std::io::stdout().lock();
        if let Some(u) = &endpoint {
            writeln!(
                out,
                "unity: ROS-TCP-Endpoint {} on {} (ROS 2 CDR)",
                twin_bridges::viewer::unity::ENDPOINT_VERSION,
                u.local_addr()
            )?;
        }
        if server.is_some() {
            writeln!(
                out,
                "foxglove: services /twin/pause, /twin/resume, /twin/step {{\"steps\": N}}, /twin/reset (json)"
            )?;
        }
        writeln!(
            out,
            "viewer commands: std_msgs/msg/Float64MultiArray on /{}/joint_commands (joint positions; Foxglove: cdr or \
             json, Unity: cdr)",
            robot.name
        )?;
        out.flush()?;
        Ok(Viewers { foxglove: server, unity: endpoint, hook })
    }

    fn announce(server: &Server) -> anyhow::Result<()> {
        let mut out = std::io::stdout().lock();
        writeln!(
            out,
            "foxglove: ws://{} (subprotocols {})",
            server.local_addr(),
            twin_bridges::viewer::foxglove::SUBPROTOCOLS.join(", ")
        )?;
        out.flush()?;
        Ok(())
    }

    impl Viewers {
        /// The recording's sinks.
        pub fn sinks(&self) -> Vec<Box<dyn twin_core::topics::Sink>> {
            let mut out: Vec<Box<dyn twin_core::topics::Sink>> = Vec::new();
            if let Some(s) = &self.foxglove {
                out.push(Box::new(FoxgloveSink::new(s.clone())));
            }
            if let Some(u) = &self.unity {
                out.push(Box::new(twin_bridges::viewer::unity::UnitySink::new(u.clone())));
            }
            out
        }

        /// `controller` with client commands on top.
        pub fn wrap(
            &self,
            controller: Box<dyn twin_core::control::Controller>,
            model: &twin_core::mj::Model,
        ) -> Box<dyn twin_core::control::Controller> {
            Box::new(Teleop::new(controller, model, &self.hook))
        }

        /// The reset the `/twin/reset` service asks for, a disturbance of the loop.
        pub fn reset_disturbance(&self) -> Box<dyn twin_core::engine::Disturbance> {
            Box::new(self.hook.reset_disturbance())
        }

        /// `--wait-for-subscriber` with `--foxglove`: waits up to `secs` for a client to
        /// subscribe to a channel (the channels exist once the recording is open).
        pub fn wait_for_subscriber(&self, secs: f64) -> anyhow::Result<()> {
            let Some(server) = &self.foxglove else { return Ok(()) };
            let stop = twin_core::fsio::interrupt_flag();
            // Ctrl-C while waiting: the run stops at once and says so.
            if !server.wait_for_subscriber(std::time::Duration::from_secs_f64(secs), stop)
                && !stop.load(std::sync::atomic::Ordering::Relaxed)
            {
                anyhow::bail!(
                    "no Foxglove client subscribed to a channel on ws://{} within {secs} s (--wait-for-subscriber)",
                    server.local_addr()
                );
            }
            Ok(())
        }

        /// The run's observer (pacing, services, pause).
        pub fn observer(&mut self) -> &mut dyn twin_core::engine::Observer {
            &mut self.hook
        }

        /// One line of statistics.
        pub fn report(&self, out: &mut impl Write) -> anyhow::Result<()> {
            let s = self.hook.stats();
            writeln!(
                out,
                "viewers: {} Foxglove clients, {} service calls, {} client commands ({} refused), {} resets, {} \
                 messages dropped (slow clients)",
                self.foxglove.as_ref().map_or(0, |f| f.clients_seen()),
                s.service_calls,
                s.commands,
                s.rejected,
                s.resets,
                self.foxglove.as_ref().map_or(0, |f| f.dropped()) + self.unity.as_ref().map_or(0, |u| u.dropped())
            )?;
            Ok(())
        }
    }

    /// `twin view LOG --foxglove ADDR`: waits up to `wait_secs` for a client to subscribe, then
    /// plays the log's CDR and JSON channels at `rate` × the log's pace, the server time
    /// following the log time.
    pub fn play(
        log_path: &std::path::Path,
        model: Option<&std::path::Path>,
        addr: SocketAddr,
        rate: f64,
        wait_secs: f64,
        strict: bool,
    ) -> anyhow::Result<()> {
        use std::collections::HashMap;
        use twin_core::log::{Log, ReadOptions};
        let log = Log::open(log_path, ReadOptions { strict })?;
        let server = Arc::new(Server::start(FoxgloveOptions {
            addr,
            robot_file: model.map(std::path::Path::to_path_buf),
            services: false,
            ..FoxgloveOptions::default()
        })?);
        announce(&server)?;
        twin_core::fsio::cooperate();
        let stop = twin_core::fsio::interrupt_flag();
        // Advertise every channel up front, so a client can subscribe before the playback.
        let info = log.info().with_context(|| format!("reading {}", log_path.display()))?;
        let mut channels: HashMap<String, Option<u32>> = HashMap::new();
        log.for_each_raw(&|_| true, |m| {
            let c = m.channel;
            if channels.contains_key(&c.topic) {
                return Ok(());
            }
            let id = match (&c.schema, c.message_encoding.as_str()) {
                (Some(s), "cdr") if s.encoding == "ros2msg" => {
                    Some(server.add_channel(&c.topic, &s.name, &String::from_utf8_lossy(&s.data), false))
                }
                _ => None,
            };
            channels.insert(c.topic.clone(), id);
            Ok(())
        })?;
        let skipped: Vec<&String> = channels.iter().filter(|(_, id)| id.is_none()).map(|(t, _)| t).collect();
        if !skipped.is_empty() {
            eprintln!("note: not streamed (not CDR with a ros2msg schema): {skipped:?}");
        }
        let mut out = std::io::stdout().lock();
        writeln!(
            out,
            "playing {} ({} messages, {:.3} s) at {rate}× once a client subscribes (waiting up to {wait_secs} s)",
            log_path.display(),
            info.message_count,
            info.duration_secs()
        )?;
        out.flush()?;
        if !server.wait_for_subscriber(std::time::Duration::from_secs_f64(wait_secs), stop) {
            eprintln!("no client subscribed within {wait_secs} s; playing anyway");
        }
        let started = std::time::Instant::now();
        let mut first: Option<u64> = None;
        let mut sent = 0u64;
        log.for_each_raw(&|c| channels.get(&c.topic).is_some_and(Option::is_some), |m| {
            if stop.load(std::sync::atomic::Ordering::Relaxed) {
                return Ok(());
            }
            let t0 = *first.get_or_insert(m.log_time_nanos);
            let target =
                started + std::time::Duration::from_secs_f64(m.log_time_nanos.saturating_sub(t0) as f64 * 1e-9 / rate);
            let now = std::time::Instant::now();
            if target > now {
                std::thread::sleep(target - now);
            }
            if let Some(Some(id)) = channels.get(&m.channel.topic) {
                server.broadcast_time(m.log_time_nanos);
                server.publish(*id, m.log_time_nanos, m.data);
                sent += 1;
            }
            Ok(())
        })?;
        // Let the clients' queues drain.
        std::thread::sleep(std::time::Duration::from_millis(500));
        writeln!(out, "played {sent} messages to {} clients ({} dropped)", server.clients_seen(), server.dropped())?;
        if twin_core::fsio::interrupted() {
            out.flush()?;
            return Err(super::super::Interrupted(format!("played {sent} messages")).into());
        }
        Ok(())
    }
}

/// Without the `ros` feature there is no viewer server.
#[cfg(not(feature = "ros"))]
pub fn unavailable() -> anyhow::Error {
    twin_core::Error::FeatureMissing { feature: "ros", what: "--foxglove and --unity (the live viewers)".into() }.into()
}

/// Without the `ros` feature: no server, ever.
#[cfg(not(feature = "ros"))]
pub enum Viewers {}

#[cfg(not(feature = "ros"))]
impl Viewers {
    pub fn sinks(&self) -> Vec<Box<dyn twin_core::topics::Sink>> {
        match *self {}
    }
    pub fn wrap(
        &self,
        _controller: Box<dyn twin_core::control::Controller>,
        _model: &twin_core::mj::Model,
    ) -> Box<dyn twin_core::control::Controller> {
        match *self {}
    }
    pub fn reset_disturbance(&self) -> Box<dyn twin_core::engine::Disturbance> {
        match *self {}
    }
    pub fn observer(&mut self) -> &mut dyn twin_core::engine::Observer {
        match *self {}
    }
    pub fn wait_for_subscriber(&self, _secs: f64) -> anyhow::Result<()> {
        match *self {}
    }
    pub fn report(&self, _out: &mut impl Write) -> anyhow::Result<()> {
        match *self {}
    }
}
