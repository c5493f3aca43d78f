//! End-to-end tests of the `twin` binary, one module per area.

mod cli {
    pub mod convert;
}
