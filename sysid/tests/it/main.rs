//! sysid's integration tests, one test binary (each file a module: one link instead of one per file).

mod excite;
mod floating;
mod friction;
mod gap;
mod noise;
mod regressor;
mod synthetic;
