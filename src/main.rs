//! `twin`: digital-twin orchestrator for legged and armed robots, with MuJoCo as physics engine.

#![forbid(unsafe_code)]

mod cli;
mod commands;

use clap::Parser;
use std::process::ExitCode;

fn main() -> ExitCode {
    let cli = cli::Cli::parse();
    // Ctrl-C / SIGTERM / SIGHUP: temp files are removed; commands that can stop cleanly do.
    twin_core::fsio::install_signal_handler();
    match cli.run() {
        Ok(()) => ExitCode::SUCCESS,
        // `twin info … | head` must not report an error when the reader goes away.
        Err(e) if is_broken_pipe(&e) => ExitCode::SUCCESS,
        // Stopped by Ctrl-C after closing its outputs and printing its summary.
        Err(e) if e.is::<commands::Interrupted>() => {
            eprintln!("{e}");
            ExitCode::from(commands::EXIT_INTERRUPTED)
        }
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

fn is_broken_pipe(e: &anyhow::Error) -> bool {
    e.chain().filter_map(|c| c.downcast_ref::<std::io::Error>()).any(|io| io.kind() == std::io::ErrorKind::BrokenPipe)
}
