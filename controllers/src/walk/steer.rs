//! Steering the walker: the velocity command as it changes over a run.
//!
//! A target command comes from a scenario's schedule (`[walk] commands = [[t, vx, vy,
//! yaw_rate], …]`, piecewise constant from each time on) or live from a navigation stack
//! (`geometry_msgs/Twist` on `/cmd_vel`, `twin_bridges::live`); it is clamped to what the walker's
//! steps allow ([`clamp`]: `max_step_length`, `max_step_lateral`, `max_step_yaw` over
//! `step_period`) and the command the walker plans its steps with moves toward it at bounded
//! acceleration ([`ramp`], `max_accel_mps2`, `max_yaw_accel_radps2`), once per step: at each
//! step it plans (and when it starts from standing) by at most the limit × `step_period`, since
//! a step's advance is what the command sets. With a zero command it finishes the step it is
//! in, brings the feet side by side and stands.
//!
//! The steps alone walk what they count, not what was asked: a command that changes between
//! step starts, and every step's landing correction, add up. So while the walker walks, the
//! target is also integrated over time into a pose (from the feet's centre and heading when
//! walking starts), and each step is moved toward where that pose will be at its touchdown
//! (`command_hold_gain`); the step that brings the feet together puts their midpoint there,
//! so the walker stands where the integral stopped.
//!
//! A walker with neither a schedule nor a live target keeps its constant command
//! (`vx`, `vy`, `yaw_rate`) and never runs this path.

use super::plan::Command;

/// The command in force at `t_secs` (controller seconds from the start) of `schedule`: the
/// last entry whose time is at or before `t_secs`; `None` before the first entry.
pub fn scheduled(schedule: &[[f64; 4]], t_secs: f64) -> Option<Command> {
    schedule.iter().rev().find(|e| e[0] <= t_secs).map(|e| Command { vx: e[1], vy: e[2], yaw_rate: e[3] })
}

/// The largest command the walker's steps allow: per axis, the longest step over the step
/// period (m/s, m/s, rad/s).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CommandBounds {
    /// Largest |vx|, m/s.
    pub vx_mps: f64,
    /// Largest |vy|, m/s.
    pub vy_mps: f64,
    /// Largest |yaw rate|, rad/s.
    pub yaw_rate_radps: f64,
}

/// `command` within `bounds`, and whether any axis was cut (a non-finite axis reads as 0 and
/// counts as cut).
pub fn clamp(command: Command, bounds: &CommandBounds) -> (Command, bool) {
    let cut = |v: f64, b: f64| if v.is_finite() { v.clamp(-b, b) } else { 0.0 };
    let clamped = Command {
        vx: cut(command.vx, bounds.vx_mps),
        vy: cut(command.vy, bounds.vy_mps),
        yaw_rate: cut(command.yaw_rate, bounds.yaw_rate_radps),
    };
    let was_cut = clamped != command;
    (clamped, was_cut)
}

/// `current` moved toward `target` over `dt_secs` at most at `accel_mps2` (vx, vy) and
/// `yaw_accel_radps2` (yaw rate); exactly `target` once within reach.
pub fn ramp(current: Command, target: Command, dt_secs: f64, accel_mps2: f64, yaw_accel_radps2: f64) -> Command {
    let toward = |c: f64, t: f64, a: f64| {
        let step = a * dt_secs;
        if (t - c).abs() <= step { t } else { c + step.copysign(t - c) }
    };
    Command {
        vx: toward(current.vx, target.vx, accel_mps2),
        vy: toward(current.vy, target.vy, accel_mps2),
        yaw_rate: toward(current.yaw_rate, target.yaw_rate, yaw_accel_radps2),
    }
}

/// Checks a schedule against `bounds`.
///
/// # Errors
/// A message naming the first bad entry (0-based) and what to change.
pub fn validate_schedule(schedule: &[[f64; 4]], bounds: &CommandBounds) -> std::result::Result<(), String> {
    let mut last = f64::NEG_INFINITY;
    for (i, e) in schedule.iter().enumerate() {
        if let Some(v) = e.iter().find(|v| !v.is_finite()) {
            return Err(format!("entry {i} has a non-finite number ({v}); each entry is [t_secs, vx, vy, yaw_rate]"));
        }
        if e[0] < 0.0 || e[0] <= last {
            return Err(format!(
                "entry {i} starts at {} s: times must be ≥ 0 and increasing (the previous entry starts at {last} s)",
                e[0]
            ));
        }
        last = e[0];
        let names = [("vx", bounds.vx_mps, "max_step_length"), ("vy", bounds.vy_mps, "max_step_lateral")];
        for (k, (name, bound, option)) in names.iter().enumerate() {
            if e[k + 1].abs() > bound + 1e-12 {
                return Err(format!(
                    "entry {i} asks {name} = {} m/s, beyond the {bound:.3} m/s the steps allow \
                     ({option} / step_period): lower it or lengthen {option} (if the legs reach it)",
                    e[k + 1]
                ));
            }
        }
        if e[3].abs() > bounds.yaw_rate_radps + 1e-12 {
            return Err(format!(
                "entry {i} asks yaw_rate = {} rad/s, beyond the {:.3} rad/s the steps allow \
                 (max_step_yaw / step_period): lower it or raise max_step_yaw",
                e[3], bounds.yaw_rate_radps
            ));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn schedule_is_piecewise_constant_from_each_time() {
        let s = [[0.0, 0.2, 0.0, 0.0], [2.0, 0.0, 0.0, 0.5], [5.0, 0.0, 0.0, 0.0]];
        assert_eq!(scheduled(&s, 1.999).map(|c| c.vx), Some(0.2));
        assert_eq!(scheduled(&s, 2.0).map(|c| c.yaw_rate), Some(0.5));
        assert!(scheduled(&s, 9.0).is_some_and(|c| c.is_zero()));
        assert_eq!(scheduled(&s[1..], 1.0), None);
    }

    #[test]
    fn ramp_bounds_the_change_per_tick_and_lands_on_the_target() {
        let target = Command { vx: 0.3, vy: -0.1, yaw_rate: 0.5 };
        let mut c = Command::default();
        let mut ticks = 0;
        while c != target {
            let next = ramp(c, target, 0.01, 0.5, 1.0);
            assert!((next.vx - c.vx).abs() <= 0.005 + 1e-15 && (next.yaw_rate - c.yaw_rate).abs() <= 0.01 + 1e-15);
            c = next;
            ticks += 1;
        }
        // vx takes 0.3 / 0.5 = 0.6 s, the longest of the three (60 ticks, one more for rounding).
        assert!((60..=61).contains(&ticks), "{ticks}");
    }

    #[test]
    fn clamp_says_when_it_cut() {
        let b = CommandBounds { vx_mps: 0.5, vy_mps: 0.2, yaw_rate_radps: 0.6 };
        let (c, cut) = clamp(Command { vx: 1.0, vy: 0.1, yaw_rate: -2.0 }, &b);
        assert!(cut && c == Command { vx: 0.5, vy: 0.1, yaw_rate: -0.6 });
        assert!(!clamp(Command { vx: 0.1, vy: 0.0, yaw_rate: 0.0 }, &b).1);
        assert!(clamp(Command { vx: f64::NAN, vy: 0.0, yaw_rate: 0.0 }, &b) == (Command::default(), true));
    }

    #[test]
    fn schedule_errors_name_the_entry_and_the_fix() {
        let b = CommandBounds { vx_mps: 0.5, vy_mps: 0.2, yaw_rate_radps: 0.6 };
        let e = validate_schedule(&[[0.0, 0.1, 0.0, 0.0], [0.0, 0.0, 0.0, 0.1]], &b).unwrap_err();
        assert!(e.starts_with("entry 1 starts at 0 s") && e.contains("increasing"), "{e}");
        let e = validate_schedule(&[[1.0, 0.9, 0.0, 0.0]], &b).unwrap_err();
        assert!(e.contains("entry 0 asks vx = 0.9") && e.contains("max_step_length"), "{e}");
        let e = validate_schedule(&[[1.0, 0.0, 0.0, -0.7]], &b).unwrap_err();
        assert!(e.contains("yaw_rate") && e.contains("max_step_yaw"), "{e}");
        assert!(validate_schedule(&[[0.0, 0.5, -0.2, 0.6], [3.0, 0.0, 0.0, 0.0]], &b).is_ok());
    }
}
