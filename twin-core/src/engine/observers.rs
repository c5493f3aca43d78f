//! The observers twin itself uses: divergence and fall detection and today's rollout metrics
//! (saturation time, actuator work, foot touch-downs). Recorders are observers too
//! ([`crate::sim::Recording`]).

use super::{Flow, Measurement, Metric, Observer, StepView};
use crate::control::Actuation;
use crate::error::Result;
use crate::mj::{Data, Model};

/// Ends the rollout when the simulation diverges: MuJoCo's bad-qacc/qpos/qvel warning (it
/// then resets the state) or non-finite joint positions.
#[derive(Debug, Clone, Default)]
pub struct Divergence {
    /// Why it diverged (MuJoCo's warning text), once it has.
    pub reason: Option<String>,
    /// Time at the start of the step that diverged, seconds.
    pub time_secs: Option<f64>,
}

impl Observer for Divergence {
    fn start(&mut self, _model: &Model, _data: &Data) -> Result<()> {
        *self = Divergence::default();
        Ok(())
    }

    fn observe(&mut self, step: &StepView<'_>) -> Result<Flow> {
        let data = step.data;
        // (A fold, not `all`: without the early exit the loop is vectorized.)
        if !data.diverged() && data.qpos().iter().fold(true, |finite, q| finite & q.is_finite()) {
            return Ok(Flow::Continue);
        }
        let (_, text) = crate::mj::thread_warnings();
        self.reason = Some(if data.diverged() {
            format!("MuJoCo reset a diverged simulation: {text}")
        } else {
            "non-finite joint positions".into()
        });
        self.time_secs = Some(step.time_secs);
        Ok(Flow::EndNow)
    }
}

/// Ends the rollout after the step during which `flag` was raised (e.g. Ctrl-C through
/// [`crate::fsio::interrupt_flag`]): the observers after it still see that step, so recordings
/// end on a whole step and are closed normally.
#[derive(Debug, Clone, Copy)]
pub struct StopFlag {
    /// The flag polled once per step.
    pub flag: &'static std::sync::atomic::AtomicBool,
    /// Whether the flag ended the rollout.
    pub stopped: bool,
}

impl StopFlag {
    /// An observer polling `flag`.
    pub fn new(flag: &'static std::sync::atomic::AtomicBool) -> Self {
        StopFlag { flag, stopped: false }
    }
}

impl Observer for StopFlag {
    fn observe(&mut self, _step: &StepView<'_>) -> Result<Flow> {
        if self.flag.load(std::sync::atomic::Ordering::Relaxed) {
            self.stopped = true;
            return Ok(Flow::EndAfterStep);
        }
        Ok(Flow::Continue)
    }
}

/// Options of [`Fall`].
#[derive(Debug, Clone, PartialEq, smart_default::SmartDefault)]
pub struct FallOptions {
    /// The robot has fallen when its base is lower than this fraction of its initial height.
    /// (default: 0.6)
    #[default(0.6)]
    pub height_fraction: f64,
    /// The robot has fallen when its base tilts more than this from upright, radians.
    /// (default: 1.0, about 57°)
    #[default(1.0)]
    pub tilt_rad: f64,
}

/// Watches the floating base: its largest tilt from upright, and a fall (base below a
/// fraction of its initial height or tilted past a limit), which ends the rollout after the
/// step. Models without a floating base never fall.
#[derive(Debug, Clone, Default)]
pub struct Fall {
    /// Thresholds.
    pub options: FallOptions,
    base: Option<usize>,
    fall_z: Option<f64>,
    /// Initial base position (world, m).
    pub start_pos: Option<[f64; 3]>,
    /// Largest base tilt from upright so far, radians.
    pub max_tilt_rad: f64,
    /// Simulated time at the fall, seconds.
    pub fall_time_secs: Option<f64>,
}

impl Fall {
    /// A fall detector with `options`.
    pub fn new(options: FallOptions) -> Fall {
        Fall { options, ..Fall::default() }
    }

    /// Whether the base fell.
    pub fn fell(&self) -> bool {
        self.fall_time_secs.is_some()
    }

    /// Tilt of body `b` from upright (the angle between its z axis and the world's), radians.
    pub fn tilt_rad(data: &Data, b: usize) -> f64 {
        data.xmat()[b][8].clamp(-1.0, 1.0).acos()
    }
}

impl Observer for Fall {
    fn start(&mut self, model: &Model, data: &Data) -> Result<()> {
        self.base = model.free_joint().map(|f| f.body);
        self.start_pos = self.base.map(|b| data.xpos()[b]);
        self.fall_z = self.start_pos.map(|p| p[2] * self.options.height_fraction);
        self.max_tilt_rad = 0.0;
        self.fall_time_secs = None;
        Ok(())
    }

    fn observe(&mut self, step: &StepView<'_>) -> Result<Flow> {
        let Some(b) = self.base else { return Ok(Flow::Continue) };
        let data = step.data;
        let tilt = Fall::tilt_rad(data, b);
        self.max_tilt_rad = self.max_tilt_rad.max(tilt);
        let z = data.xpos()[b][2];
        if tilt > self.options.tilt_rad || self.fall_z.is_some_and(|f| z < f) {
            self.fall_time_secs = Some(step.sim_secs);
            return Ok(Flow::EndAfterStep);
        }
        Ok(Flow::Continue)
    }
}

/// Time with at least one command entry at a finite limit, seconds.
#[derive(Debug, Clone, Default)]
pub struct Saturation {
    /// Seconds saturated so far.
    pub secs: f64,
}

impl Observer for Saturation {
    fn start(&mut self, _model: &Model, _data: &Data) -> Result<()> {
        self.secs = 0.0;
        Ok(())
    }

    fn observe(&mut self, step: &StepView<'_>) -> Result<Flow> {
        if step.saturated {
            self.secs += step.dt_secs;
        }
        Ok(Flow::Continue)
    }
}

impl Metric for Saturation {
    fn measurements(&self) -> Vec<Measurement> {
        vec![Measurement::new("saturation time", self.secs, "s")]
    }
}

/// Actuator work `∫ Σ|τ·q̇| dt`, joules: τ the actuator forces (`qfrc_actuator`) or, for
/// models without actuators, the applied joint forces (`qfrc_applied`).
#[derive(Debug, Clone, Default)]
pub struct Energy {
    /// Work so far, J.
    pub joules: f64,
}

impl Observer for Energy {
    fn start(&mut self, _model: &Model, _data: &Data) -> Result<()> {
        self.joules = 0.0;
        Ok(())
    }

    fn observe(&mut self, step: &StepView<'_>) -> Result<Flow> {
        let data = step.data;
        let force = match step.actuation {
            Actuation::Ctrl => data.qfrc_actuator(),
            Actuation::Qfrc => data.qfrc_applied(),
        };
        let power: f64 = force.iter().zip(data.qvel()).map(|(t, v)| (t * v).abs()).sum();
        self.joules += power * step.dt_secs;
        Ok(Flow::Continue)
    }
}

impl Metric for Energy {
    fn measurements(&self) -> Vec<Measurement> {
        vec![Measurement::new("actuator work", self.joules, "J")]
    }
}

/// Least time a foot is off the ground before its next contact counts as a touch-down, s:
/// shorter gaps are a rolling or chattering sole (a walking foot's contacts flicker several
/// times a stance), not a step.
pub const TOUCHDOWN_MIN_AIR_SECS: f64 = 0.05;

/// Foot touch-downs: a foot's contact with the world body starting after at least
/// [`TOUCHDOWN_MIN_AIR_SECS`] off it. A foot's geoms are those of its body and of the bodies
/// below it.
#[derive(Debug, Clone, Default)]
pub struct Touchdowns {
    /// Foot index per geom (−1: not a foot's).
    geom_foot: Vec<i32>,
    /// Time each foot has been off the ground, s.
    air_secs: Vec<f64>,
    now: Vec<bool>,
    /// Touch-downs so far.
    pub count: u64,
}

impl Touchdowns {
    /// Counts touch-downs of `feet` (body ids, e.g. [`crate::robot::Robot::feet`]) of `model`.
    pub fn new(model: &Model, feet: &[usize]) -> Touchdowns {
        let geom_foot = (0..model.ngeom())
            .map(|g| {
                let body = model.geom_bodyid()[g] as usize;
                feet.iter().position(|&f| model.in_subtree(f, body)).map_or(-1, |k| k as i32)
            })
            .collect();
        Touchdowns { geom_foot, air_secs: vec![0.0; feet.len()], now: vec![false; feet.len()], count: 0 }
    }

    fn mark(&self, data: &Data, now: &mut [bool]) {
        let model = data.model();
        now.fill(false);
        for [g1, g2] in data.contact_geoms() {
            if g1 < 0 || g2 < 0 {
                continue;
            }
            let (b1, b2) = (model.geom_bodyid()[g1 as usize], model.geom_bodyid()[g2 as usize]);
            let (f1, f2) = (self.geom_foot[g1 as usize], self.geom_foot[g2 as usize]);
            if f1 >= 0 && b2 == 0 {
                now[f1 as usize] = true;
            }
            if f2 >= 0 && b1 == 0 {
                now[f2 as usize] = true;
            }
        }
    }
}

impl Observer for Touchdowns {
    fn start(&mut self, _model: &Model, _data: &Data) -> Result<()> {
        // A foot on the ground or in the air at the start has not touched down yet.
        self.air_secs.fill(0.0);
        self.count = 0;
        Ok(())
    }

    fn observe(&mut self, step: &StepView<'_>) -> Result<Flow> {
        let mut now = std::mem::take(&mut self.now);
        self.mark(step.data, &mut now);
        for (air, &n) in self.air_secs.iter_mut().zip(&now) {
            if n {
                if *air >= TOUCHDOWN_MIN_AIR_SECS {
                    self.count += 1;
                }
                *air = 0.0;
            } else {
                *air += step.dt_secs;
            }
        }
        self.now = now;
        Ok(Flow::Continue)
    }
}

impl Metric for Touchdowns {
    fn measurements(&self) -> Vec<Measurement> {
        vec![Measurement::new("foot touch-downs", self.count as f64, "")]
    }
}
