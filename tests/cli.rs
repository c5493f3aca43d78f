//! End-to-end tests of the `twin` binary, one module per area under `tests/cli/`.

mod cli {
    mod sysid;
}
