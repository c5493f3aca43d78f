//! What the bridge's state writers sent in lockstep, and to which of the node's readers: the
//! sink ([`super::LiveSink`]) writes through it, the controller half
//! ([`super::LiveController`]) uses it for the delivery order of a period and for the first
//! period of a run.
//!
//! - **Delivery order** ([`Outbox::deliver`]): before the `/clock` that opens period k, every
//!   state message written since the last `/clock` (stamped t_(k−1)) is acknowledged by every
//!   reliable reader that had matched (rustdds `wait_for_acknowledgments`), so a node that reads
//!   its latest state when `/clock` k arrives reads the same one on every run. A best-effort
//!   reader (`qos_profile_sensor_data`: IMUs; rclpy's `/clock`) cannot acknowledge: its sample
//!   went out before `/clock`, from the same thread and participant, and on loopback arrives
//!   first; that is the only order twin can give it.
//! - **Late readers** ([`Outbox::resend_to_late_readers`]): until a run's first command, a
//!   state message is sent again when a reader of its topic appears that discovery had not seen
//!   when it went out (DDS keeps no volatile sample for a reader it has not met; a node that
//!   subscribes late, in a callback, would otherwise never get its first state). A reader
//!   already seen gets the message once only.
//! - **What went out** ([`Outbox::describe`]): when a command is missing, which topics twin
//!   sent in that period, their stamps, and whether the node's readers were there and
//!   acknowledged, so the error names the real cause before blaming the node.

use super::LiveController;
use super::dds::{self, Node, RawCdr, RawWriter, SeenEndpoint};
use std::fmt::Write as _;
use std::sync::Arc;
use std::time::{Duration, Instant};
use twin_core::error::{Error, Result};

/// The last message of one topic and what became of it.
struct Last {
    stamp_nanos: u64,
    cdr: Vec<u8>,
    /// The readers discovery had seen when it went out (last sent).
    readers: Vec<SeenEndpoint>,
    /// Times it was sent again to readers that appeared later.
    resent: u32,
    /// `Some(true)`: every reliable reader acknowledged it; `Some(false)`: not within the wait.
    acked: Option<bool>,
}

struct Sent {
    topic: String,
    writer: Arc<RawWriter>,
    last: Option<Last>,
    /// Written since the last [`Outbox::deliver`].
    pending: bool,
    /// When a reader of the topic was first seen in this run (after [`Outbox::begin`]).
    first_seen: Option<Instant>,
}

/// The bridge's stream writers and what they sent (see the [module docs](self)).
pub struct Outbox {
    node: Arc<Node>,
    topics: Vec<Sent>,
    /// Keep each topic's last message and its readers (lockstep only: the real-time modes
    /// neither wait for acknowledgments nor re-send).
    lockstep: bool,
    /// When the run (or the episode's process) began: reader times are said from there.
    origin: Instant,
    /// The readers seen before the run began (a process of an earlier episode still in the
    /// discovery database until its leave is heard): not this run's.
    before: Vec<SeenEndpoint>,
}

impl Outbox {
    /// An outbox of `node`'s writers.
    pub fn new(node: Arc<Node>) -> Outbox {
        Outbox { node, topics: Vec::new(), lockstep: false, origin: Instant::now(), before: Vec::new() }
    }

    /// Keeps each topic's last message and its readers from now on (lockstep).
    pub fn set_lockstep(&mut self, on: bool) {
        self.lockstep = on;
    }

    /// Watches `writer` of `topic`.
    pub fn add(&mut self, topic: &str, writer: Arc<RawWriter>) {
        self.topics.push(Sent { topic: topic.to_string(), writer, last: None, pending: false, first_seen: None });
    }

    /// A new run (an episode, with a new process or a reset one): forgets the last messages;
    /// the readers seen now are an earlier process's unless they are seen again later under
    /// the same GUID (a kept process keeps its readers: `keep_readers`).
    pub fn begin(&mut self, keep_readers: bool) {
        self.origin = Instant::now();
        self.before = if keep_readers {
            Vec::new()
        } else {
            self.topics.iter().flat_map(|t| self.node.readers_of(&t.topic)).collect()
        };
        for t in &mut self.topics {
            t.last = None;
            t.pending = false;
            t.first_seen = None;
        }
    }

    /// This run's readers of `topic` (not those of an earlier process).
    fn readers(&self, topic: &str) -> Vec<SeenEndpoint> {
        self.node.readers_of(topic).into_iter().filter(|r| !self.before.contains(r)).collect()
    }

    /// Notes that `topic`'s writer sent `cdr` stamped `stamp_nanos`.
    pub fn sent(&mut self, topic: &str, stamp_nanos: u64, cdr: &[u8]) {
        if !self.lockstep {
            return;
        }
        let readers = self.readers(topic);
        let now = Instant::now();
        if let Some(t) = self.topics.iter_mut().find(|t| t.topic == topic) {
            if t.first_seen.is_none() && !readers.is_empty() {
                t.first_seen = Some(now);
            }
            t.last = Some(Last { stamp_nanos, cdr: cdr.to_vec(), readers, resent: 0, acked: None });
            t.pending = true;
        }
    }

    /// Waits, at most `timeout` in all, until every reliable reader of each topic written since
    /// the last call has acknowledged it. `Err` names the first topic not acknowledged.
    pub fn deliver(&mut self, timeout: Duration) -> std::result::Result<(), String> {
        let deadline = Instant::now() + timeout;
        for k in 0..self.topics.len() {
            if !self.topics[k].pending {
                continue;
            }
            // A reader of an earlier process, still in the discovery database (a killed process
            // never says it leaves; its lease runs out later), would never acknowledge: the
            // order is then the writing order alone, until it is gone.
            let stale = {
                let now = self.node.readers_of(&self.topics[k].topic);
                now.iter().any(|r| self.before.contains(r))
            };
            let t = &mut self.topics[k];
            t.pending = false;
            if stale {
                continue;
            }
            let left = deadline.saturating_duration_since(Instant::now());
            let acked = t.writer.wait_for_acknowledgments(left).unwrap_or(false);
            if let Some(last) = t.last.as_mut() {
                last.acked = Some(acked);
            }
            if !acked {
                let stamp = t.last.as_ref().map_or(0, |l| l.stamp_nanos);
                return Err(format!(
                    "{} stamped {:.3} s was not acknowledged by its reliable reader(s) within {:.1} s",
                    t.topic,
                    stamp as f64 * 1e-9,
                    timeout.as_secs_f64()
                ));
            }
        }
        Ok(())
    }

    /// Sends each topic's last message again when a reader of it appeared after it went out
    /// (see the [module docs](self)); returns the topics sent again.
    pub fn resend_to_late_readers(&mut self) -> Vec<String> {
        let mut out = Vec::new();
        let now = Instant::now();
        for k in 0..self.topics.len() {
            let readers = self.readers(&self.topics[k].topic);
            let t = &mut self.topics[k];
            if t.first_seen.is_none() && !readers.is_empty() {
                t.first_seen = Some(now);
            }
            let Some(last) = t.last.as_mut() else { continue };
            if readers.iter().all(|r| last.readers.contains(r)) {
                continue;
            }
            let _ = t.writer.write(RawCdr(last.cdr.clone()), None);
            last.readers = readers;
            last.resent += 1;
            last.acked = None;
            t.pending = true;
            out.push(t.topic.clone());
        }
        out
    }

    /// The topics with a reader that appeared after their last message went out (it did not
    /// get it).
    pub fn missed_by_late_readers(&self) -> Vec<String> {
        self.topics
            .iter()
            .filter(|t| t.last.as_ref().is_some_and(|l| self.readers(&t.topic).iter().any(|r| !l.readers.contains(r))))
            .map(|t| t.topic.clone())
            .collect()
    }

    /// This run's readers of every stream topic, in topic order (to see when the set stops
    /// changing).
    pub fn all_readers(&self) -> Vec<SeenEndpoint> {
        self.topics.iter().flat_map(|t| self.readers(&t.topic)).collect()
    }

    /// Notes the time a reader of each topic was first seen (call while waiting).
    pub fn watch_readers(&mut self) {
        let now = Instant::now();
        for k in 0..self.topics.len() {
            if self.topics[k].first_seen.is_none() && !self.readers(&self.topics[k].topic).is_empty() {
                self.topics[k].first_seen = Some(now);
            }
        }
    }

    /// Whether `topic`'s last message reached every reader the node has of it now: some reader
    /// is there, each was there when it went out, and the reliable ones acknowledged it.
    /// `None` when twin sent nothing on `topic`.
    pub fn reached(&self, topic: &str) -> Option<bool> {
        let t = self.topics.iter().find(|t| t.topic == topic)?;
        let last = t.last.as_ref()?;
        let now = self.readers(topic);
        Some(!now.is_empty() && now.iter().all(|r| last.readers.contains(r)) && last.acked != Some(false))
    }

    /// What went out on the topics the node reads (see the [module docs](self)): one clause per
    /// topic with a reader, and for each of `always`, e.g. `/joint_states stamped 0.000 s to 1
    /// reliable and 0 best-effort reader(s) (acknowledged; a reader first seen 0.41 s after the
    /// start)`.
    pub fn describe(&self, always: &[String]) -> String {
        let mut clauses = Vec::new();
        for t in &self.topics {
            let readers = self.readers(&t.topic);
            if readers.is_empty() && t.first_seen.is_none() && !always.contains(&t.topic) {
                continue;
            }
            let reliable = readers.iter().filter(|r| r.reliable).count();
            let best_effort = readers.len() - reliable;
            let mut c = String::new();
            match &t.last {
                Some(l) => {
                    let _ = write!(c, "{} stamped {:.3} s", t.topic, l.stamp_nanos as f64 * 1e-9);
                }
                None => {
                    let _ = write!(c, "{} (nothing sent yet)", t.topic);
                }
            }
            let _ = write!(c, " to {reliable} reliable and {best_effort} best-effort reader(s)");
            let mut notes = Vec::new();
            if let Some(l) = &t.last {
                let late = readers.iter().filter(|r| !l.readers.contains(r)).count();
                if late > 0 {
                    notes.push(format!("{late} reader(s) appeared after it went out: they did not get it"));
                }
                match l.acked {
                    Some(true) if reliable > 0 => notes.push("acknowledged".into()),
                    Some(false) => notes.push("NOT acknowledged".into()),
                    _ => {}
                }
                if l.resent > 0 {
                    notes.push(format!("sent again {} time(s) to late readers", l.resent));
                }
            }
            if let Some(seen) = t.first_seen {
                notes.push(format!(
                    "a reader first seen {:.2} s after the start",
                    seen.saturating_duration_since(self.origin).as_secs_f64()
                ));
            }
            if !notes.is_empty() {
                let _ = write!(c, " ({})", notes.join("; "));
            }
            clauses.push(c);
        }
        if clauses.is_empty() { "no reader of any state topic was seen".into() } else { clauses.join(", ") }
    }
}

fn poisoned_outbox() -> Error {
    Error::Live { message: "the live bridge's outbox was poisoned by a panic on another thread".into() }
}

/// The controller half's use of the outbox (see the [module docs](self)).
impl LiveController {
    /// Another run begins on this bridge (an episode): its state goes out again to readers
    /// that appear before its first command; with `keep_readers` false (a new controller
    /// process), the readers discovery sees now are an earlier process's and do not count as
    /// this run's ([`Outbox::begin`]).
    pub fn begin_run(&mut self, keep_readers: bool) {
        self.awaiting_first = true;
        if let Ok(mut o) = self.outbox.lock() {
            o.begin(keep_readers);
        }
    }

    /// Lockstep: waits until every reliable reader acknowledged the state written since the
    /// last `/clock` ([`Outbox::deliver`]), at most the lockstep timeout.
    pub(super) fn deliver(&mut self, t_secs: f64) -> Result<()> {
        let timeout = Duration::from_secs_f64(self.options.lockstep_timeout_secs);
        let delivered = self.outbox.lock().map_err(|_| poisoned_outbox())?.deliver(timeout);
        delivered.map_err(|why| Error::Live {
            message: format!(
                "lockstep: before /clock = {t_secs:.3} s, {why}: the node's reader no longer answers (is it \
                 still running, its executor not blocked?)"
            ),
        })
    }

    /// The run's first command came: says so in the log when a reader of a state topic had
    /// appeared after that topic's last message went out, so the node computed it without (the
    /// runs may then differ): the topic belongs in the `[ros] subscribes` list, which the join
    /// waits for.
    pub(super) fn first_command_came(&mut self, t_nanos: u64) {
        if !std::mem::replace(&mut self.awaiting_first, false) {
            return;
        }
        let late = self.outbox.lock().map(|o| o.missed_by_late_readers()).unwrap_or_default();
        if !late.is_empty() {
            self.warn(format!(
                "lockstep: the first command (/clock = {:.3} s) came while the node's reader of {} had not got the \
                 state that went out before it (the reader appeared later): list it in [ros] subscribes so that the \
                 join waits for it, or this run may differ from another",
                t_nanos as f64 * 1e-9,
                late.join(", ")
            ));
        }
    }

    /// Says `t_secs` on `/clock` before a run's first state goes out ([`Self::announce_time`]),
    /// waits (at most `timeout`) until every reliable `/clock` reader acknowledged it, and says
    /// it again: a volatile reader that matched twin's writer only after the first write
    /// acknowledges what it skipped (Cyclone DDS does), so the second write is the one it gets.
    /// A node that answers states only once it has seen a `/clock` lost whole episodes so. The
    /// same time twice fires no timer.
    pub fn announce_time_delivered(&mut self, t_secs: f64, timeout: Duration) {
        self.announce_time(t_secs);
        let _ = self.clock.wait_for_acknowledgments(timeout);
        self.repeat_time();
        let _ = self.clock.wait_for_acknowledgments(timeout);
    }

    /// Sends the state again to readers that appeared after it went out, saying so.
    pub(super) fn resend_to_late_readers(&mut self, t_nanos: u64) {
        let resent = match self.outbox.lock() {
            Ok(mut o) => o.resend_to_late_readers(),
            Err(_) => return,
        };
        if !resent.is_empty() {
            self.warn(format!(
                "lockstep: before the first command (/clock = {:.3} s) a reader of {} appeared after its state went \
                 out: sent again",
                t_nanos as f64 * 1e-9,
                resent.join(", ")
            ));
        }
    }

    /// What the state writers sent before the last `/clock`, to which readers, and whether
    /// they acknowledged it ([`Outbox::describe`], `always` among them), with the `/clock`
    /// readers.
    pub fn sent_before_clock(&self, always: &[String]) -> String {
        let clock = self.node.readers_of("/clock").len();
        let state = self.outbox.lock().map(|o| o.describe(always)).unwrap_or_default();
        format!("{state}; /clock to {clock} reader(s)")
    }

    /// Sets the state topics the node reads (default: `/joint_states`): a missing command's
    /// account names them even without a reader ([`LiveController::missing_command`]).
    pub fn set_reads(&mut self, topics: Vec<String>) {
        self.reads = topics;
    }

    /// When the last period's command did not come: what twin had sent before that `/clock`
    /// ([`LiveController::sent_before_clock`]), and which of the topics the node reads had not
    /// reached it then ([`LiveController::reached`]).
    pub fn missing_command(&self) -> Option<&(String, Vec<String>)> {
        self.missing.as_ref()
    }

    /// Whether the last message on `topic` reached every reader the node has of it
    /// ([`Outbox::reached`]; `None`: nothing sent on it).
    pub fn reached(&self, topic: &str) -> Option<bool> {
        self.outbox.lock().ok().and_then(|o| o.reached(topic))
    }

    /// Notes when each state topic's first reader is seen ([`Outbox::watch_readers`]).
    pub fn watch_readers(&self) {
        if let Ok(mut o) = self.outbox.lock() {
            o.watch_readers();
        }
    }

    /// This run's readers of the state topics ([`Outbox::all_readers`]).
    pub fn state_readers(&self) -> Vec<SeenEndpoint> {
        self.outbox.lock().map(|o| o.all_readers()).unwrap_or_default()
    }

    /// The other participants' readers of `ros_topic` discovery has seen now
    /// ([`Node::readers_of`]).
    pub fn readers_of(&self, ros_topic: &str) -> Vec<dds::SeenEndpoint> {
        self.node.readers_of(ros_topic)
    }

    /// The other participants' writers of `ros_topic` discovery has seen now.
    pub fn writers_of(&self, ros_topic: &str) -> Vec<dds::SeenEndpoint> {
        self.node.writers_of(ros_topic)
    }

    /// The topics a controller commands on: joint commands, trajectories, `JointState` by
    /// name, `/cmd_vel`.
    pub fn command_topics(&self) -> [&str; 4] {
        [&self.command_topic, &self.trajectory_topic, &self.by_name_topic, twin_core::topics::CMD_VEL_TOPIC]
    }
}
