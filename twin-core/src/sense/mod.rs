//! Sensing by ray casting, without OpenGL: depth cameras ([`depth`]) and finding a cup on a
//! table in their point clouds ([`cup`]).

pub mod cup;
pub mod depth;

pub use cup::{CupDetectOptions, CupEstimate, detect_cup};
pub use depth::{DepthCamera, DepthCameraOptions, DepthFrame, Intrinsics};
