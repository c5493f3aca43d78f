//! Is the batch reproducible? The first episode run again, compared column by column
//! ([`RunOptions::repeat_first`](crate::RunOptions::repeat_first)).
//!
//! A built-in controller is a function of the simulation: an episode is the same whatever the
//! thread count, and `--record-worst` checks that bit for bit. A user's process over ROS 2
//! (`controller = "ros"`) is a function of what twin sent it only if the node computes from one
//! period's messages; some ways of writing a node (several topics read in their own callbacks,
//! callbacks running at the same time) make its answers depend on the order its executor ran
//! them. Nothing in one run shows that; a second run of the same episode does. Data flows:
//! the batch's first result → [`check`] runs that episode again on a fresh [`Worker`] → a
//! [`Repeat`] naming the columns that differ and what the controller's check said of the node.

use crate::episode::{Batch, EpisodeResult, Worker};
use crate::error::Result;
use crate::summary::{csv_header, csv_record};

/// The first episode of a batch and its second run.
#[derive(Debug, Clone, PartialEq)]
pub struct Repeat {
    /// Episode index.
    pub index: u64,
    /// Columns of `episodes.csv` that differ: (column, first run, second run).
    pub differences: Vec<(String, String, String)>,
    /// What the controller's check said of the first run (its details), for the cause.
    pub controller: Vec<String>,
}

impl Repeat {
    /// Whether the second run gave the same row.
    pub fn reproducible(&self) -> bool {
        self.differences.is_empty()
    }

    /// One paragraph for the user: what differed and why the controller is the likely cause.
    pub fn explain(&self) -> String {
        if self.reproducible() {
            return format!("episode {} run again: the same row of episodes.csv (reproducible)", self.index);
        }
        let shown: Vec<String> = self.differences.iter().take(4).map(|(c, a, b)| format!("{c} {a} then {b}")).collect();
        let mut text = format!(
            "episode {} run again gave another result ({}{}): this batch is not reproducible. The episode's \
             physics and draws are the same every run, so its controller's output depends on more than what twin \
             sent it",
            self.index,
            shown.join(", "),
            if self.differences.len() > shown.len() {
                format!(" and {} more column(s)", self.differences.len() - shown.len())
            } else {
                String::new()
            }
        );
        if self.controller.is_empty() {
            text.push('.');
        } else {
            text.push_str(": ");
            text.push_str(&self.controller.join("; "));
        }
        text
    }
}

/// Runs episode `first.index` of `batch` again and compares its row with `first`'s.
///
/// # Errors
/// Errors of [`Worker::new`] and [`Worker::run`].
pub fn check(batch: &Batch, first: &EpisodeResult) -> Result<Repeat> {
    let again = Worker::new(batch)?.run(batch, first.index, None)?;
    let checks = batch.check_verdicts()?;
    let header = csv_header(&batch.layout.columns, !checks.is_empty(), &crate::summary::check_metric_names(&checks));
    let (a, b) = (csv_record(first), csv_record(&again));
    let differences = header
        .iter()
        .zip(a.iter().zip(b.iter()))
        .filter(|(_, (x, y))| x != y)
        .map(|(c, (x, y))| (c.clone(), x.clone(), y.clone()))
        .collect();
    let controller = first.checks.iter().filter(|v| v.name == "controller").flat_map(|v| v.details.clone()).collect();
    Ok(Repeat { index: first.index, differences, controller })
}
