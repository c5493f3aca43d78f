//! A rollout's inputs, recorded to replay it in a plain C loop of `mj_step`: the reference
//! that benchmarks measure a controlled rollout's per-core throughput against (the same
//! physics, without the controller, the sensor model, the observers or the wrappers).
//!
//! [`InputLog`] is an observer: it keeps the initial state, the command each step applied and,
//! at the steps where a disturbance acted besides the command (a kick of the base's velocity,
//! a pinned base, an applied force), what the state and the applied forces were then.
//! [`InputLog::replay_c`] runs the rollout again from those, stepping in C between events.
//! MuJoCo being deterministic, the replay ends in the rollout's final state bit for bit.

use super::{Flow, Observer, StepView};
use crate::control::Actuation;
use crate::error::{Error, Result};
use crate::mj::{Data, Model, StateSig, bench_c_replay_loop};

/// The state and applied forces a disturbance left before one step's physics.
#[derive(Debug, Clone, PartialEq)]
struct Event {
    step: u64,
    qpos: Vec<f64>,
    qvel: Vec<f64>,
    qfrc_applied: Vec<f64>,
    xfrc_applied: Vec<[f64; 6]>,
}

/// Records a rollout's inputs (see the module docs). Reusable: each rollout's `start` clears it.
#[derive(Debug, Clone, Default)]
pub struct InputLog {
    /// `mj_getState` with [`StateSig::INTEGRATION`] once the initial state is set.
    initial: Vec<f64>,
    into_qfrc_applied: bool,
    /// The applied command of each step, back to back (`ctrl`, or `qfrc_applied` on models
    /// without actuators).
    commands: Vec<f64>,
    events: Vec<Event>,
    /// What plain stepping gives before the next step: the state after the last one and the
    /// forces applied so far.
    qpos: Vec<f64>,
    qvel: Vec<f64>,
    qfrc_applied: Vec<f64>,
    xfrc_applied: Vec<[f64; 6]>,
    steps: u64,
}

impl InputLog {
    /// An empty log.
    pub fn new() -> InputLog {
        InputLog::default()
    }

    /// Steps recorded.
    pub fn steps(&self) -> u64 {
        self.steps
    }

    /// Steps at which a disturbance acted besides the command.
    pub fn events(&self) -> usize {
        self.events.len()
    }

    /// Replays the recorded rollout on `data` (the rollout's model): sets the initial state,
    /// then runs plain C `mj_step` loops over the recorded commands, setting each event's state
    /// and forces in between. Returns the steps run.
    ///
    /// # Errors
    /// [`Error::Size`] when `data`'s model is not the recorded rollout's, [`Error::MuJoCo`] if
    /// the initial state can't be set. A MuJoCo error inside the loop is not caught (see
    /// [`crate::mj::bench_c_replay_loop`]).
    #[doc(hidden)]
    pub fn replay_c(&self, data: &mut Data) -> Result<u64> {
        if self.steps == 0 {
            return Ok(0);
        }
        let len = self.commands.len() / self.steps as usize;
        data.set_state(&self.initial, StateSig::INTEGRATION)?;
        let mut done = 0u64;
        let run_to = |data: &mut Data, end: u64, done: &mut u64| -> Result<()> {
            let range = *done as usize * len..end as usize * len;
            if !range.is_empty() {
                bench_c_replay_loop(data, self.into_qfrc_applied, &self.commands[range])?;
            }
            *done = end;
            Ok(())
        };
        for e in &self.events {
            run_to(data, e.step, &mut done)?;
            let sizes = [data.qpos().len(), data.qvel().len(), data.xfrc_applied().len()];
            if sizes != [e.qpos.len(), e.qvel.len(), e.xfrc_applied.len()] {
                return Err(Error::Size { what: "replayed state (qpos)", expected: sizes[0], got: e.qpos.len() });
            }
            data.qpos_mut().copy_from_slice(&e.qpos);
            data.qvel_mut().copy_from_slice(&e.qvel);
            data.qfrc_applied_mut().copy_from_slice(&e.qfrc_applied);
            data.xfrc_applied_mut().copy_from_slice(&e.xfrc_applied);
        }
        run_to(data, self.steps, &mut done)?;
        Ok(done)
    }
}

impl Observer for InputLog {
    fn start(&mut self, model: &Model, data: &Data) -> Result<()> {
        self.initial = data.state(StateSig::INTEGRATION)?;
        self.into_qfrc_applied = Actuation::of(model) == Actuation::Qfrc;
        self.commands.clear();
        self.events.clear();
        self.qpos = data.qpos().to_vec();
        self.qvel = data.qvel().to_vec();
        self.qfrc_applied = data.qfrc_applied().to_vec();
        self.xfrc_applied = data.xfrc_applied().to_vec();
        self.steps = 0;
        Ok(())
    }

    fn observe(&mut self, step: &StepView<'_>) -> Result<Flow> {
        let data = step.data;
        // The forces the step applied are still in `data`; the state before the physics (after
        // the disturbances) is the view's.
        let (qfrc, xfrc) = (data.qfrc_applied(), data.xfrc_applied());
        let moved = step.qpos != self.qpos.as_slice() || step.qvel != self.qvel.as_slice();
        let forced = xfrc != self.xfrc_applied.as_slice() || (!self.into_qfrc_applied && qfrc != self.qfrc_applied);
        if moved || forced {
            self.events.push(Event {
                step: step.index,
                qpos: step.qpos.to_vec(),
                qvel: step.qvel.to_vec(),
                qfrc_applied: qfrc.to_vec(),
                xfrc_applied: xfrc.to_vec(),
            });
            self.qfrc_applied.copy_from_slice(qfrc);
            self.xfrc_applied.copy_from_slice(xfrc);
        }
        self.commands.extend_from_slice(if self.into_qfrc_applied { qfrc } else { data.ctrl() });
        self.qpos.copy_from_slice(data.qpos());
        self.qvel.copy_from_slice(data.qvel());
        self.steps = step.index + 1;
        Ok(Flow::Continue)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::control::{PdHold, PdHoldOptions};
    use crate::engine::disturb::{Push, TimedForce};
    use crate::engine::{Disturbance, Engine, Episode, SensorModel};
    use rand::SeedableRng;
    use std::sync::Arc;

    /// The shipped humanoid under a noisy, late PD hold, kicked every 0.1 s and pushed by an
    /// applied force: the C replay of its inputs ends in the rollout's state bit for bit, and
    /// a replay without the events does not.
    #[test]
    fn c_replay_reproduces_a_disturbed_rollout_bit_for_bit() {
        let model =
            Arc::new(Model::from_file(concat!(env!("CARGO_MANIFEST_DIR"), "/../models/humanoid.urdf")).unwrap());
        let episode = Episode {
            steps: 400,
            sensors: SensorModel { qpos_noise_std: vec![0.01; model.nq()], latency_steps: 2, ..SensorModel::default() },
            ..Episode::default()
        };
        let mut controller = PdHold::new(&model, PdHoldOptions::default());
        let (mut kicks, mut force) = (Push::new(0.1, 0.3, None), TimedForce::new(0.33, 0.1, [0.0, 40.0, 0.0], 1));
        let mut disturbances: [&mut dyn Disturbance; 2] = [&mut kicks, &mut force];
        let mut log = InputLog::new();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
        let mut engine = Engine::new();
        let outcome =
            engine.run(&model, &episode, &mut controller, &mut disturbances, &mut [&mut log], &mut rng).unwrap();
        assert_eq!((outcome.steps, log.steps()), (400, 400));
        // A kick at 0.1, 0.2 … 0.7 s, the force on at 0.33 s and off at 0.43 s.
        let steps: Vec<u64> = log.events.iter().map(|e| e.step).collect();
        assert_eq!(steps, [50, 100, 150, 165, 200, 215, 250, 300, 350]);
        let rollout = engine.take_data().unwrap();
        let mut data = Data::new(model.clone()).unwrap();
        assert_eq!(log.replay_c(&mut data).unwrap(), 400);
        assert_eq!([data.qpos(), data.qvel()], [rollout.qpos(), rollout.qvel()]);

        let mut undisturbed = log.clone();
        undisturbed.events.clear();
        undisturbed.replay_c(&mut data).unwrap();
        assert_ne!(data.qvel(), rollout.qvel());
    }
}
