//! The bridge's `simulation_interfaces` services (names under the node, `/twin/…`):
//!
//! | service | type | what it does |
//! |---|---|---|
//! | `/twin/get_simulation_state` | `GetSimulationState` | `STATE_PLAYING` or `STATE_PAUSED` |
//! | `/twin/set_simulation_state` | `SetSimulationState` | `PAUSED` pauses, `PLAYING` resumes, `STOPPED` pauses and resets, `QUITTING` ends the run (recordings closed) |
//! | `/twin/step_simulation` | `StepSimulation` | while paused, `steps` physics steps, then paused again; replies when done |
//! | `/twin/reset_simulation` | `ResetSimulation` | the robot's state (positions, velocities, activations) back to the start; the controller's command back to holding the home pose |
//!
//! And Gazebo Classic's (`gazebo_ros`) `std_srvs/srv/Empty` services, for the scripts and
//! tools written against it (`std_srvs` has wheels on PyPI; `simulation_interfaces` has none):
//!
//! | service | type | what it does |
//! |---|---|---|
//! | `/pause_physics` | `std_srvs/srv/Empty` | pauses (as `SetSimulationState` `PAUSED`; already paused: nothing) |
//! | `/unpause_physics` | `std_srvs/srv/Empty` | resumes (as `PLAYING`; already playing: nothing) |
//! | `/reset_simulation` | `std_srvs/srv/Empty` | the robot's state back to the start, as `/twin/reset_simulation` (time is not reset, see below) |
//! | `/reset_world` | `std_srvs/srv/Empty` | the same (Gazebo: poses reset, time kept) |
//!
//! An `Empty` reply carries no result: a call twin can't do (pausing or resuming during a
//! `StepSimulation`) is answered all the same and said in a warning.
//!
//! Simulation time is not reset: `/clock` and the recordings stay monotonic, so a reset
//! asked with the `SCOPE_TIME` bit (`SCOPE_TIME`, `SCOPE_ALL`) is refused with
//! `RESULT_FEATURE_UNSUPPORTED`; `SCOPE_DEFAULT` and `SCOPE_STATE` reset the state. Gazebo's
//! `/reset_simulation` also sets time back to 0; twin's resets the state alone, as
//! `/reset_world` does. twin spawns nothing, so `SCOPE_SPAWNED` has nothing to do.

use super::service::{Request, RequestId, ServiceServer};
use twin_core::error::Result;
use twin_core::log::cdr::{CdrError, CdrWriter};

/// `simulation_interfaces/msg/SimulationState` values.
pub mod state {
    /// Stopped (paused and reset).
    pub const STOPPED: u8 = 0;
    /// Playing.
    pub const PLAYING: u8 = 1;
    /// Paused.
    pub const PAUSED: u8 = 2;
    /// Quitting.
    pub const QUITTING: u8 = 3;
}

/// `simulation_interfaces/msg/Result` codes (and the services' own, above 100).
pub mod result {
    /// Not supported.
    pub const FEATURE_UNSUPPORTED: u8 = 0;
    /// Done.
    pub const OK: u8 = 1;
    /// The simulation is in the wrong state for the call.
    pub const INCORRECT_STATE: u8 = 3;
    /// Failed; see the message.
    pub const OPERATION_FAILED: u8 = 4;
    /// `SetSimulationState`: already in the target state.
    pub const ALREADY_IN_TARGET_STATE: u8 = 101;
    /// `SetSimulationState`: not a transition twin makes.
    pub const INCORRECT_TRANSITION: u8 = 103;
}

/// `ResetSimulation` scope bits.
pub mod scope {
    /// Everything (same as [`ALL`]).
    pub const DEFAULT: u8 = 0;
    /// Simulation time.
    pub const TIME: u8 = 1;
    /// Poses and velocities.
    pub const STATE: u8 = 2;
    /// Spawned entities.
    pub const SPAWNED: u8 = 4;
    /// Everything.
    pub const ALL: u8 = 255;
}

/// The type of Gazebo Classic's services: no request fields, no reply fields.
pub const EMPTY: &str = "std_srvs/srv/Empty";

/// Service names of the bridge, with their types: the `simulation_interfaces` ones, then
/// Gazebo Classic's ([`Gazebo`], in its order).
pub const SERVICES: [(&str, &str); 8] = [
    ("/twin/get_simulation_state", "simulation_interfaces/srv/GetSimulationState"),
    ("/twin/set_simulation_state", "simulation_interfaces/srv/SetSimulationState"),
    ("/twin/step_simulation", "simulation_interfaces/srv/StepSimulation"),
    ("/twin/reset_simulation", "simulation_interfaces/srv/ResetSimulation"),
    ("/pause_physics", EMPTY),
    ("/unpause_physics", EMPTY),
    ("/reset_simulation", EMPTY),
    ("/reset_world", EMPTY),
];

/// Index in [`SERVICES`] of the first Gazebo service.
const FIRST_GAZEBO: usize = 4;

/// Gazebo Classic's `std_srvs/srv/Empty` services, in [`SERVICES`] order.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Gazebo {
    /// `/pause_physics`.
    Pause,
    /// `/unpause_physics`.
    Unpause,
    /// `/reset_simulation`.
    ResetSimulation,
    /// `/reset_world`.
    ResetWorld,
}

/// What a client asked.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Call {
    /// `GetSimulationState`.
    GetState,
    /// `SetSimulationState` to this state.
    SetState(u8),
    /// `StepSimulation` this many steps.
    Step(u64),
    /// `ResetSimulation` with this scope.
    Reset(u8),
    /// A Gazebo Classic service.
    Gazebo(Gazebo),
}

/// The servers of [`SERVICES`].
pub struct SimulationServices {
    servers: Vec<ServiceServer>,
}

/// A `simulation_interfaces/msg/Result`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Outcome {
    /// Result code ([`result`]).
    pub code: u8,
    /// Why, when useful.
    pub message: String,
}

impl Outcome {
    /// `RESULT_OK`.
    pub fn ok() -> Outcome {
        Outcome { code: result::OK, message: String::new() }
    }

    /// A result code with its explanation.
    pub fn new(code: u8, message: impl Into<String>) -> Outcome {
        Outcome { code, message: message.into() }
    }

    fn encode(&self, w: &mut CdrWriter) {
        w.u8(self.code);
        w.string(&self.message);
    }
}

impl SimulationServices {
    /// Offers the services of [`SERVICES`] on `node`.
    ///
    /// # Errors
    /// [`twin_core::Error::Live`] from rustdds.
    pub fn new(node: &super::dds::Node) -> Result<SimulationServices> {
        let servers = SERVICES.iter().map(|(name, ty)| ServiceServer::new(node, name, ty)).collect::<Result<_>>()?;
        Ok(SimulationServices { servers })
    }

    /// The request readers, to register with a poller.
    pub fn readers_mut(&mut self) -> impl Iterator<Item = &mut super::dds::RawReader> {
        self.servers.iter_mut().map(ServiceServer::requests_mut)
    }

    /// The next call waiting on any service: `Ok((service index, id, call))`, or `Err` with a
    /// sentence for a request that can't be decoded (answered already with
    /// `RESULT_OPERATION_FAILED` when it had an id).
    pub fn next_call(&mut self) -> Option<std::result::Result<(usize, RequestId, Call), String>> {
        for k in 0..self.servers.len() {
            let Some(taken) = self.servers[k].take() else { continue };
            let request = match taken {
                Ok(r) => r,
                Err(why) => return Some(Err(why)),
            };
            return Some(match decode(k, &request) {
                Ok(call) => Ok((k, request.id, call)),
                Err(why) => {
                    let why = format!("{}: {why}", self.servers[k].name());
                    let _ = self.answer(k, &request.id, state::PLAYING, &Outcome::new(result::OPERATION_FAILED, &why));
                    Err(why)
                }
            });
        }
        None
    }

    /// Answers call `k`'s request `id` with `outcome` (`current` is the state
    /// `GetSimulationState` reports).
    ///
    /// # Errors
    /// [`twin_core::Error::Live`] when the reply can't be written.
    pub fn answer(&self, k: usize, id: &RequestId, current: u8, outcome: &Outcome) -> Result<()> {
        self.servers[k].reply(id, |w| {
            if SERVICES[k].1 == EMPTY {
                // An empty structure: its one placeholder byte (`structure_needs_at_least_one_member`).
                w.u8(0);
                return;
            }
            if k == 0 {
                w.u8(current);
            }
            outcome.encode(w);
        })
    }
}

fn decode(k: usize, request: &Request) -> std::result::Result<Call, String> {
    let mut r = request.reader().map_err(|e| e.message)?;
    let bad = |e: CdrError| format!("undecodable request: {}", e.message);
    Ok(match k {
        0 => Call::GetState,
        1 => Call::SetState(r.u8().map_err(bad)?),
        2 => Call::Step(r.u64().map_err(bad)?),
        3 => Call::Reset(r.u8().map_err(bad)?),
        k => Call::Gazebo(match k - FIRST_GAZEBO {
            0 => Gazebo::Pause,
            1 => Gazebo::Unpause,
            2 => Gazebo::ResetSimulation,
            _ => Gazebo::ResetWorld,
        }),
    })
}
