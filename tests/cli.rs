//! End-to-end tests of the `twin` binary, one module per area.

#[path = "cli/log.rs"]
mod log;
