//! The twin's bridges to the outside, the floor above the built-in controllers: the live ROS 2
//! bridge ([`live`], `twin sim --ros`: DDS through rustdds, no ROS install), the live viewers
//! without ROS ([`viewer`]: Foxglove WebSocket and Unity's ROS-TCP protocol) and a scenario's
//! external controller ([`external`]: a user's ROS 2 node that twin starts, drives in lockstep
//! and stops).
//!
//! Data flows both ways through the one simulation loop (`twin_core::sim`): what the recorder
//! writes (the observation the engine gave the controller) goes out through a
//! `twin_core::topics::Sink` on each bridge; commands come back in as the run's
//! `twin_core::control::Controller`. With the cargo feature `ros` off, [`live`] and [`viewer`]
//! are not built and an external controller is refused with what to rebuild.
//!
//! `unsafe` code is denied here.

#![deny(unsafe_code)]

pub mod external;
#[cfg(feature = "ros")]
pub mod live;
#[cfg(feature = "ros")]
pub mod viewer;
