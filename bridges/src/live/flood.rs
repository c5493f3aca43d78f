//! Flood detection in lockstep: a controller that sends far more commands than one per control
//! period (a publisher in a wall-time loop, a timer on the wrong clock) fails the run instead of
//! filling the bridge's queues and making which command a period gets depend on timing.
//!
//! Data flow: just before each `/clock` of a lockstep period, the bridge takes every command
//! still queued on its inputs. The first (in the order the period would take them) stays for
//! the period that `/clock` opens; the others are the period's *surplus*: counted per topic,
//! dropped unapplied and unrecorded. A well-behaved node has none (its one command per period
//! was taken in its period), so the commands applied do not depend on this count. [`FloodWatch`]
//! keeps the surplus of the last [`LiveOptions::flood_window_secs`](super::LiveOptions) of
//! simulated time and reports a [`Flood`] when it exceeds
//! [`LiveOptions::flood_commands_per_period`](super::LiveOptions) per period on average over
//! that window (periods not yet run count as none: a run shorter than the window fails when its
//! surplus exceeds the limit times the window's periods).

use std::collections::VecDeque;

/// How many command inputs the watch counts (trajectories, by-name, arrays, Twists).
pub const INPUTS: usize = 4;

/// The surplus of the last window of control periods.
#[derive(Debug, Clone)]
pub struct FloodWatch {
    limit_per_period: f64,
    window_periods: usize,
    period_secs: f64,
    recent: VecDeque<[u64; INPUTS]>,
    sums: [u64; INPUTS],
    /// Surplus commands dropped since the watch started (all windows).
    pub total: u64,
}

/// A flood: the window's numbers.
#[derive(Debug, Clone, PartialEq)]
pub struct Flood {
    /// Index of the input with the most surplus in the window.
    pub input: usize,
    /// Surplus commands in the window, all inputs.
    pub surplus: u64,
    /// Control periods in the window (its length, even when fewer have run).
    pub window_periods: usize,
    /// Surplus per control period, averaged over the window.
    pub per_period: f64,
    /// Surplus per simulated second, over the window.
    pub per_sim_sec: f64,
}

impl FloodWatch {
    /// A watch failing above `limit_per_period` surplus commands per period, averaged over
    /// `window_secs` of periods of `period_secs` (at least one period).
    pub fn new(limit_per_period: f64, window_secs: f64, period_secs: f64) -> Self {
        let window_periods = (window_secs / period_secs).round().max(1.0) as usize;
        FloodWatch {
            limit_per_period,
            window_periods,
            period_secs,
            recent: VecDeque::with_capacity(window_periods),
            sums: [0; INPUTS],
            total: 0,
        }
    }

    /// Forgets the window (a new episode).
    pub fn reset(&mut self) {
        self.recent.clear();
        self.sums = [0; INPUTS];
    }

    /// Adds one period's surplus per input; the flood, if the window's average is now above
    /// the limit.
    pub fn push(&mut self, surplus: [u64; INPUTS]) -> Option<Flood> {
        if self.recent.len() == self.window_periods
            && let Some(old) = self.recent.pop_front()
        {
            for (s, o) in self.sums.iter_mut().zip(old) {
                *s -= o;
            }
        }
        for (s, n) in self.sums.iter_mut().zip(surplus) {
            *s += n;
        }
        self.total += surplus.iter().sum::<u64>();
        self.recent.push_back(surplus);
        let sum: u64 = self.sums.iter().sum();
        let per_period = sum as f64 / self.window_periods as f64;
        if per_period <= self.limit_per_period {
            return None;
        }
        let input = (0..INPUTS).max_by_key(|&k| (self.sums[k], std::cmp::Reverse(k))).unwrap_or(0);
        Some(Flood {
            input,
            surplus: sum,
            window_periods: self.window_periods,
            per_period,
            per_sim_sec: per_period / self.period_secs,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_steady_surplus_under_the_limit_never_floods() {
        // 100 Hz, 1 s window, limit 10: a timer twice the control rate (1 extra per period).
        let mut w = FloodWatch::new(10.0, 1.0, 0.01);
        for _ in 0..1000 {
            assert_eq!(w.push([0, 0, 1, 0]), None);
        }
        assert_eq!(w.total, 1000);
    }

    #[test]
    fn a_flood_is_reported_when_the_window_average_passes_the_limit() {
        let mut w = FloodWatch::new(10.0, 1.0, 0.01);
        // 25 per period on the arrays: the window (100 periods) holds 1000 after 40 periods,
        // 1025 after 41.
        for k in 1..=40 {
            assert_eq!(w.push([0, 0, 25, 0]), None, "period {k}");
        }
        let f = w.push([0, 0, 25, 1]).expect("a flood");
        assert_eq!(f.input, 2);
        assert_eq!(f.surplus, 1026);
        assert_eq!(f.window_periods, 100);
        assert!((f.per_period - 10.26).abs() < 1e-12);
        assert!((f.per_sim_sec - 1026.0).abs() < 1e-9);
    }

    #[test]
    fn old_periods_leave_the_window_and_a_reset_forgets_it() {
        let mut w = FloodWatch::new(1.0, 0.05, 0.01); // 5 periods, at most 5 in the window
        assert_eq!(w.push([5, 0, 0, 0]), None);
        for _ in 0..4 {
            assert_eq!(w.push([0; INPUTS]), None);
        }
        // The 5 leave as 1 comes: 1 in the window.
        assert_eq!(w.push([0, 1, 0, 0]), None);
        assert!(w.push([0, 5, 0, 0]).is_some());
        w.reset();
        assert_eq!(w.push([0, 5, 0, 0]), None);
    }
}
