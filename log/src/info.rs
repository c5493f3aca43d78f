//! `twin log info`: what a log holds, computed by one streaming pass over every message's
//! log time.

use super::{Log, ReadReport};
use crate::Result;
use std::collections::BTreeMap;

/// One topic's summary.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TopicInfo {
    /// Topic name.
    pub topic: String,
    /// Message type(s) (more than one would be a recording oddity).
    pub type_name: String,
    /// Message encoding (`cdr`, `json`, …).
    pub encoding: String,
    /// Channels with this topic (one per file and QoS set, usually).
    pub channels: usize,
    /// Messages.
    pub count: u64,
    /// First log time, ns.
    pub first_nanos: u64,
    /// Last log time, ns.
    pub last_nanos: u64,
    /// Largest gap between consecutive messages (in file order), ns.
    pub largest_gap_nanos: u64,
    /// Log time at which the largest gap ends, ns.
    pub largest_gap_end_nanos: u64,
    /// Messages whose log time is before the previous one's.
    pub out_of_order: u64,
}

impl TopicInfo {
    /// Mean rate over the span, Hz (0 for fewer than two messages).
    pub fn rate_hz(&self) -> f64 {
        let span = self.last_nanos.saturating_sub(self.first_nanos);
        if self.count < 2 || span == 0 { 0.0 } else { (self.count - 1) as f64 / (span as f64 * 1e-9) }
    }
}

/// A whole log's summary.
#[derive(Debug, Clone, Default)]
pub struct LogInfo {
    /// Topics sorted by name.
    pub topics: Vec<TopicInfo>,
    /// Messages in all topics.
    pub message_count: u64,
    /// Earliest log time, ns (0 when empty).
    pub start_nanos: u64,
    /// Latest log time, ns.
    pub end_nanos: u64,
    /// Header profile and library of the first file.
    pub profile: String,
    /// Header library of the first file.
    pub library: String,
    /// File-level findings.
    pub read: ReadReport,
}

impl LogInfo {
    /// Duration covered, s.
    pub fn duration_secs(&self) -> f64 {
        self.end_nanos.saturating_sub(self.start_nanos) as f64 * 1e-9
    }

    /// The topics whose message type ends in `type_suffix` (`"JointState"`, `"Odometry"`), by name.
    pub fn topics_of_type(&self, type_suffix: &str) -> Vec<&str> {
        self.topics.iter().filter(|t| t.type_name.ends_with(type_suffix)).map(|t| t.topic.as_str()).collect()
    }
}

pub(crate) fn log_info(log: &Log) -> Result<LogInfo> {
    // Keyed by topic: several channels (publishers, files) of one topic are merged.
    let mut topics: BTreeMap<String, TopicInfo> = BTreeMap::new();
    let mut last_channel: Option<(*const super::Channel, String)> = None;
    let read = log.for_each_raw(&|_| true, |m| {
        let key = match &last_channel {
            Some((p, t)) if *p == std::sync::Arc::as_ptr(m.channel) => t.clone(),
            _ => {
                let t = m.channel.topic.clone();
                last_channel = Some((std::sync::Arc::as_ptr(m.channel), t.clone()));
                t
            }
        };
        let t = topics.entry(key).or_insert_with(|| TopicInfo {
            topic: m.channel.topic.clone(),
            type_name: m.channel.type_name().to_string(),
            encoding: m.channel.message_encoding.clone(),
            first_nanos: m.log_time_nanos,
            last_nanos: m.log_time_nanos,
            ..Default::default()
        });
        let time = m.log_time_nanos;
        if t.count > 0 {
            if time < t.last_nanos {
                t.out_of_order += 1;
            } else if time - t.last_nanos > t.largest_gap_nanos {
                t.largest_gap_nanos = time - t.last_nanos;
                t.largest_gap_end_nanos = time;
            }
        }
        t.count += 1;
        t.first_nanos = t.first_nanos.min(time);
        // `last_nanos` follows file order for gap computation; the span uses min/max below.
        t.last_nanos = if t.count == 1 { time } else { time.max(t.last_nanos) };
        Ok(())
    })?;
    let mut info = LogInfo { read, ..Default::default() };
    // Channel counts and topics without messages come from the channel records.
    for (_, r) in &info.read.files {
        for c in &r.channels {
            let t = topics.entry(c.topic.clone()).or_insert_with(|| TopicInfo {
                topic: c.topic.clone(),
                type_name: c.type_name().to_string(),
                encoding: c.message_encoding.clone(),
                ..Default::default()
            });
            t.channels += 1;
            if !t.type_name.split(", ").any(|n| n == c.type_name()) {
                t.type_name = format!("{}, {}", t.type_name, c.type_name());
            }
        }
    }
    if let Some((_, first)) = info.read.files.first() {
        info.profile.clone_from(&first.profile);
        info.library.clone_from(&first.library);
    }
    info.topics = topics.into_values().collect();
    let with_messages = info.topics.iter().filter(|t| t.count > 0);
    info.message_count = info.topics.iter().map(|t| t.count).sum();
    info.start_nanos = with_messages.clone().map(|t| t.first_nanos).min().unwrap_or(0);
    info.end_nanos = with_messages.map(|t| t.last_nanos).max().unwrap_or(0);
    Ok(info)
}
