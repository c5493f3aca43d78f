//! Per-joint time series from a `sensor_msgs/msg/JointState` topic, with the hygiene real logs
//! need: names in any order per message, empty velocity/effort arrays, several publishers (arm
//! and gripper) merged by joint name, zero header stamps replaced by the log time, and
//! out-of-order stamps sorted and counted.

use super::cdr::{CdrReader, Value};
use super::reader::Channel;
use super::typed::JointState;
use super::{BadMessages, Decoder, Log, ReadReport, cdr};
use crate::{Error, Result};
use std::collections::{BTreeSet, HashMap};
use std::sync::Arc;

/// One joint's samples. `time_nanos` is sorted; `velocity`/`effort` hold NaN where the message
/// had none for this joint.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct JointSeries {
    /// Joint name.
    pub name: String,
    /// Sample time (header stamp, or log time where the stamp was zero), ns.
    pub time_nanos: Vec<i64>,
    /// Position, rad (or m).
    pub position: Vec<f64>,
    /// Velocity, rad/s (NaN where absent).
    pub velocity: Vec<f64>,
    /// Effort as the driver reports it (NaN where absent).
    pub effort: Vec<f64>,
}

impl JointSeries {
    /// Number of samples.
    pub fn len(&self) -> usize {
        self.time_nanos.len()
    }

    /// Whether there are no samples.
    pub fn is_empty(&self) -> bool {
        self.time_nanos.is_empty()
    }

    /// Whether any sample has a velocity.
    pub fn has_velocity(&self) -> bool {
        self.velocity.iter().any(|v| !v.is_nan())
    }

    /// Whether any sample has an effort.
    pub fn has_effort(&self) -> bool {
        self.effort.iter().any(|v| !v.is_nan())
    }
}

/// What was odd about the topic.
#[derive(Debug, Clone, Default)]
pub struct JointStateReport {
    /// Messages read.
    pub messages: u64,
    /// Channels (publisher groups as the recorder saw them) on the topic.
    pub channels: usize,
    /// Distinct sets of joint names seen: more than one means several publishers (or a
    /// driver that changes its list).
    pub name_sets: Vec<Vec<String>>,
    /// Messages whose header stamp was zero; the log time was used.
    pub zero_stamps: u64,
    /// Samples whose time went backwards for their joint; the series is sorted.
    pub non_monotonic: u64,
    /// The largest step back in time of a joint's samples, ns (0 when none went back).
    pub largest_step_back_nanos: i64,
    /// Samples stamped with the same time as their joint's previous sample (time stood still).
    pub repeated_stamps: u64,
    /// Samples of a joint, the most of them, that share one timestamp.
    pub most_at_one_stamp: u64,
    /// Messages with an empty velocity array.
    pub empty_velocity: u64,
    /// Messages with an empty effort array.
    pub empty_effort: u64,
    /// Messages whose array lengths do not match the name count (skipped).
    pub malformed: u64,
    /// File-level findings (damage, undecodable messages).
    pub read: ReadReport,
}

impl JointStateReport {
    /// Warnings worth printing, one per line.
    pub fn warnings(&self) -> Vec<String> {
        let mut w = self.read.warnings();
        if self.zero_stamps > 0 {
            w.push(format!("{} messages have a zero header stamp; their log time was used", self.zero_stamps));
        }
        if self.non_monotonic > 0 {
            w.push(format!(
                "time goes backwards: {} samples went back in time for their joint (by up to {:.6} s); the \
                 series were sorted by time, check the log's clock",
                self.non_monotonic,
                self.largest_step_back_nanos as f64 * 1e-9
            ));
        }
        if self.repeated_stamps > 0 {
            w.push(format!(
                "time stands still: {} samples carry the same timestamp as their joint's previous one (up to {} \
                 samples at one instant); check the log's clock",
                self.repeated_stamps, self.most_at_one_stamp
            ));
        }
        if self.malformed > 0 {
            w.push(format!(
                "{} messages skipped: position/velocity/effort lengths differ from the name count",
                self.malformed
            ));
        }
        if self.name_sets.len() > 1 {
            w.push(format!(
                "{} different joint-name sets on the topic (several publishers?); merged by name",
                self.name_sets.len()
            ));
        }
        w
    }
}

/// Every joint of a JointState topic as a time series.
#[derive(Debug, Clone, Default)]
pub struct JointStateSeries {
    /// The topic.
    pub topic: String,
    /// Joints in order of first appearance.
    pub joints: Vec<JointSeries>,
    /// What was odd.
    pub report: JointStateReport,
}

impl JointStateSeries {
    /// A joint by name.
    pub fn joint(&self, name: &str) -> Option<&JointSeries> {
        self.joints.iter().find(|j| j.name == name)
    }

    /// Joint names in order of first appearance.
    pub fn names(&self) -> impl Iterator<Item = &str> {
        self.joints.iter().map(|j| j.name.as_str())
    }
}

pub(crate) fn read_joint_states(log: &Log, topic: &str) -> Result<JointStateSeries> {
    let mut out = JointStateSeries { topic: topic.to_string(), ..Default::default() };
    let mut index: HashMap<String, usize> = HashMap::new();
    let mut decoders: HashMap<*const Channel, Decoder> = HashMap::new();
    let mut name_sets: BTreeSet<Vec<String>> = BTreeSet::new();
    let mut last_names: Vec<String> = Vec::new();
    let mut slots: Vec<usize> = Vec::new();
    let mut js = JointState::default();
    let mut bad = BadMessages::default();
    let mut rep = JointStateReport::default();
    let mut channels = 0usize;

    let read = log.for_each_raw(&|c| c.topic == topic, |m| {
        let type_name = super::msgdef::normalize_type_name(m.channel.type_name());
        let dec = decoders.entry(Arc::as_ptr(m.channel)).or_insert_with(|| {
            channels += 1;
            Decoder::for_channel(m.channel)
        });
        if !matches!(dec, Decoder::Json) && type_name != "sensor_msgs/msg/JointState" {
            return Err(Error::LogTopic {
                path: log.path().to_path_buf(),
                topic: topic.to_string(),
                message: format!("topic {topic} has type {type_name}, expected sensor_msgs/msg/JointState"),
            });
        }
        let decoded: std::result::Result<(), String> = match dec {
            Decoder::Cdr { fast: true, .. } => CdrReader::new(m.data)
                .and_then(|mut r| js.decode_into(&mut r))
                .map_err(|e| format!("{} (at byte {})", e.message, e.offset)),
            Decoder::Cdr { defs, fast: false } => cdr::decode(defs, m.data)
                .map_err(|e| format!("{} (at byte {})", e.message, e.offset))
                .and_then(|v: Value| {
                    js = JointState::from_value(&v).ok_or("message lacks JointState's name/position fields")?;
                    Ok(())
                }),
            Decoder::Json => serde_json::from_slice::<serde_json::Value>(m.data)
                .map_err(|e| format!("invalid JSON: {e}"))
                .and_then(|v| {
                    js = JointState::from_json(&v).ok_or("JSON message is not JointState-shaped (name, position…)")?;
                    Ok(())
                }),
            Decoder::Unsupported(why) => Err(format!("cannot decode: {why}")),
        };
        if let Err(message) = decoded {
            return bad.push(log, &m, message);
        }
        rep.messages += 1;
        let n = js.name.len();
        if js.position.len() != n
            || !(js.velocity.is_empty() || js.velocity.len() == n)
            || !(js.effort.is_empty() || js.effort.len() == n)
        {
            rep.malformed += 1;
            return Ok(());
        }
        rep.empty_velocity += u64::from(js.velocity.is_empty());
        rep.empty_effort += u64::from(js.effort.is_empty());
        let time_nanos = if js.header.stamp_nanos == 0 {
            // A zero stamp logged at time 0 (a simulation's first instant) is no substitution.
            rep.zero_stamps += u64::from(m.log_time_nanos != 0);
            m.log_time_nanos as i64
        } else {
            js.header.stamp_nanos
        };
        // Most messages repeat the previous name list: skip the lookups then.
        if js.name != last_names {
            slots.clear();
            for name in &js.name {
                let next = out.joints.len();
                let slot = *index.entry(name.clone()).or_insert(next);
                if slot == next {
                    out.joints.push(JointSeries { name: name.clone(), ..Default::default() });
                }
                slots.push(slot);
            }
            name_sets.insert(js.name.clone());
            last_names.clone_from(&js.name);
        }
        for (i, &slot) in slots.iter().enumerate() {
            let j = &mut out.joints[slot];
            if let Some(&t) = j.time_nanos.last()
                && time_nanos < t
            {
                rep.non_monotonic += 1;
                rep.largest_step_back_nanos = rep.largest_step_back_nanos.max(t - time_nanos);
            }
            j.time_nanos.push(time_nanos);
            j.position.push(js.position[i]);
            j.velocity.push(js.velocity.get(i).copied().unwrap_or(f64::NAN));
            j.effort.push(js.effort.get(i).copied().unwrap_or(f64::NAN));
        }
        Ok(())
    })?;
    log.check_topic(&read, topic)?;
    rep.read = read;
    bad.into_report(&mut rep.read);
    rep.channels = channels;
    rep.name_sets = name_sets.into_iter().collect();
    if rep.non_monotonic > 0 {
        for j in &mut out.joints {
            sort_by_time(j);
        }
    }
    for j in &out.joints {
        let mut run = 1u64;
        for w in j.time_nanos.windows(2) {
            if w[1] == w[0] {
                rep.repeated_stamps += 1;
                run += 1;
                rep.most_at_one_stamp = rep.most_at_one_stamp.max(run);
            } else {
                run = 1;
            }
        }
    }
    out.report = rep;
    Ok(out)
}

fn sort_by_time(j: &mut JointSeries) {
    let mut order: Vec<usize> = (0..j.len()).collect();
    order.sort_by_key(|&i| j.time_nanos[i]); // stable: equal stamps keep log order
    let pick = |v: &[f64]| order.iter().map(|&i| v[i]).collect::<Vec<_>>();
    j.position = pick(&j.position);
    j.velocity = pick(&j.velocity);
    j.effort = pick(&j.effort);
    j.time_nanos = order.iter().map(|&i| j.time_nanos[i]).collect();
}
