//! `twin log info FILE`: topics, types, counts, rates, time span and gaps of a ROS 2 MCAP log
//! (a `.mcap` file or a rosbag2 folder), with what was lost if the file is damaged.

use anyhow::Context;
use std::io::Write;
use std::path::PathBuf;
use twin_core::log::{Log, LogInfo, ReadOptions};

#[derive(Debug, clap::Args)]
pub struct Args {
    #[command(subcommand)]
    pub command: LogCommand,
}

#[derive(Debug, clap::Subcommand)]
pub enum LogCommand {
    /// List topics, types, message counts, rates, time span and the largest gap per topic.
    Info {
        /// A `.mcap` file or a rosbag2 folder (metadata.yaml + .mcap).
        file: PathBuf,
        /// Fail on a damaged file instead of reading what is intact.
        #[arg(long)]
        strict: bool,
    },
}

pub fn run(args: Args) -> anyhow::Result<()> {
    match args.command {
        LogCommand::Info { file, strict } => {
            let log = Log::open(&file, ReadOptions { strict })?;
            let info = log.info().with_context(|| format!("reading {}", file.display()))?;
            for w in info.read.warnings() {
                eprintln!("warning: {w}");
            }
            let mut out = std::io::stdout().lock();
            write_info(&mut out, &log, &info)?;
            Ok(())
        }
    }
}

fn secs(nanos: u64) -> f64 {
    nanos as f64 * 1e-9
}

fn write_info(out: &mut impl Write, log: &Log, info: &LogInfo) -> std::io::Result<()> {
    writeln!(out, "log: {}", log.path().display())?;
    for f in log.files() {
        if f != log.path() {
            writeln!(out, "  file: {}", f.display())?;
        }
    }
    writeln!(
        out,
        "profile: {} · library: {}",
        if info.profile.is_empty() { "-" } else { &info.profile },
        if info.library.is_empty() { "-" } else { &info.library }
    )?;
    writeln!(
        out,
        "messages: {} · start {:.6} s · end {:.6} s · duration {:.3} s",
        info.message_count,
        secs(info.start_nanos),
        secs(info.end_nanos),
        info.duration_secs()
    )?;
    let damaged = info.read.damage().count();
    if damaged > 0 {
        writeln!(out, "damage: {damaged} finding(s), see warnings")?;
    }
    writeln!(
        out,
        "\n  {:<32} {:<34} {:>5} {:>9} {:>10} {:>12} {:>14}",
        "topic", "type", "enc", "count", "rate_hz", "max_gap_s", "gap_ends_at_s"
    )?;
    for t in &info.topics {
        writeln!(
            out,
            "  {:<32} {:<34} {:>5} {:>9} {:>10.2} {:>12.4} {:>14.6}",
            t.topic,
            t.type_name,
            t.encoding,
            t.count,
            t.rate_hz(),
            secs(t.largest_gap_nanos),
            secs(t.largest_gap_end_nanos)
        )?;
        if t.out_of_order > 0 {
            writeln!(out, "    {} messages with log time before the previous one", t.out_of_order)?;
        }
        if t.channels > 1 {
            writeln!(out, "    {} channels (publishers) on this topic", t.channels)?;
        }
    }
    Ok(())
}
