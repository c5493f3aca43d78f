//! The controller's process: a DDS domain of its own ([`DomainLease`]), a loopback-only DDS
//! environment ([`dds_environment`]), starting it in its own process group with its output in
//! a log, and stopping it, bounded ([`ControllerProcess::stop`]).

use std::fs::File;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};
use twin_core::error::{Error, Result};

/// The domain ids twin hands out to controller processes: the top of the range Fast DDS's
/// default port mapping allows (0–232), away from the usual low ids of a team's own graph.
pub const DOMAINS: std::ops::RangeInclusive<u16> = 200..=232;

/// A DDS domain id held by this run: a lock on `<tmp>/twin-dds-domains/<id>.lock` that no other
/// twin process (or worker) holds at the same time. Released when dropped, or by the kernel
/// when the process dies.
#[derive(Debug)]
pub struct DomainLease {
    id: u16,
    _lock: File,
}

static LEASES: AtomicU64 = AtomicU64::new(0);

impl DomainLease {
    /// Takes a free domain id of [`DOMAINS`].
    ///
    /// # Errors
    /// [`Error::Live`] when the lock folder can't be written or every id is held.
    pub fn acquire() -> Result<DomainLease> {
        let dir = std::env::temp_dir().join("twin-dds-domains");
        std::fs::create_dir_all(&dir).map_err(|source| Error::io(dir.clone(), source))?;
        let n = u64::from(DOMAINS.end() - DOMAINS.start()) + 1;
        // Start where other processes are unlikely to: spread by pid and by lease count.
        let start = (u64::from(std::process::id()) * 7 + LEASES.fetch_add(1, Ordering::Relaxed) * 3) % n;
        for k in 0..n {
            let id = DOMAINS.start() + ((start + k) % n) as u16;
            let path = dir.join(format!("{id}.lock"));
            let file = File::options()
                .create(true)
                .truncate(false)
                .write(true)
                .open(&path)
                .map_err(|source| Error::io(path.clone(), source))?;
            if file.try_lock().is_ok() {
                return Ok(DomainLease { id, _lock: file });
            }
        }
        Err(Error::Live {
            message: format!(
                "every DDS domain id {}..={} is held by another twin run on this machine ({}): wait for them to end",
                DOMAINS.start(),
                DOMAINS.end(),
                dir.display()
            ),
        })
    }

    /// The domain id.
    pub fn id(&self) -> u16 {
        self.id
    }
}

/// How a stopped process ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stopped {
    /// It had exited already, with this status.
    Exited(ExitStatus),
    /// It ended after this signal (`"SIGINT"`, `"SIGTERM"`, `"SIGKILL"`).
    BySignal(&'static str),
}

/// A started controller process (see the [module docs](self)).
#[derive(Debug)]
pub struct ControllerProcess {
    child: Child,
    command: String,
    log: PathBuf,
    started: Instant,
    /// Set once the process has been waited for.
    status: Option<ExitStatus>,
}

impl ControllerProcess {
    /// Starts `command` with `sh -c` in `folder`, with `env` added to twin's environment, in a
    /// new process group, stdin closed, stdout and stderr appended to `log` after a line saying
    /// what starts (`note`).
    ///
    /// # Errors
    /// [`Error::File`] when the log can't be opened; [`Error::Live`] when `sh` can't start.
    pub fn start(
        command: &str,
        folder: &Path,
        env: &[(String, String)],
        log: &Path,
        note: &str,
    ) -> Result<ControllerProcess> {
        if let Some(dir) = log.parent() {
            std::fs::create_dir_all(dir).map_err(|source| Error::io(dir.to_path_buf(), source))?;
        }
        let io = |source| Error::io(log.to_path_buf(), source);
        let mut out = File::options().create(true).append(true).open(log).map_err(io)?;
        writeln!(out, "--- twin: {note}: sh -c {command:?} in {}", folder.display()).map_err(io)?;
        let err = out.try_clone().map_err(io)?;
        let mut cmd = Command::new("/bin/sh");
        cmd.arg("-c").arg(command).current_dir(folder).stdin(Stdio::null()).stdout(out).stderr(err);
        for (k, v) in env {
            if v.is_empty() {
                cmd.env_remove(k);
            } else {
                cmd.env(k, v);
            }
        }
        std::os::unix::process::CommandExt::process_group(&mut cmd, 0);
        let child = cmd.spawn().map_err(|e| Error::Live {
            message: format!("cannot start the controller `{command}` in {}: {e}", folder.display()),
        })?;
        Ok(ControllerProcess {
            child,
            command: command.to_string(),
            log: log.to_path_buf(),
            started: Instant::now(),
            status: None,
        })
    }

    /// Its process id (also its process group id).
    pub fn pid(&self) -> u32 {
        self.child.id()
    }

    /// Its log file.
    pub fn log(&self) -> &Path {
        &self.log
    }

    /// The command line.
    pub fn command(&self) -> &str {
        &self.command
    }

    /// Wall time since it started.
    pub fn age(&self) -> Duration {
        self.started.elapsed()
    }

    /// Its exit status, if it has exited (does not wait).
    pub fn exited(&mut self) -> Option<ExitStatus> {
        if self.status.is_none() {
            self.status = self.child.try_wait().ok().flatten();
        }
        self.status
    }

    /// Sends `signal` to the whole process group (a group that is gone is not an error).
    fn signal_group(&self, signal: nix::sys::signal::Signal) {
        let pgid = nix::unistd::Pid::from_raw(self.child.id() as i32);
        let _ = nix::sys::signal::killpg(pgid, signal);
    }

    /// Stops it: SIGINT to its process group, then SIGTERM after `grace` if it still runs,
    /// then SIGKILL after `grace` again; waits for it (so no zombie stays) and kills what is
    /// left of its group. Returns how it ended.
    pub fn stop(&mut self, grace: Duration) -> Stopped {
        use nix::sys::signal::Signal;
        if let Some(status) = self.exited() {
            // The leader is gone; anything it left in its group goes too.
            self.signal_group(Signal::SIGKILL);
            return Stopped::Exited(status);
        }
        for (signal, name) in [(Signal::SIGINT, "SIGINT"), (Signal::SIGTERM, "SIGTERM"), (Signal::SIGKILL, "SIGKILL")] {
            self.signal_group(signal);
            let deadline = Instant::now() + if signal == Signal::SIGKILL { Duration::from_secs(5) } else { grace };
            while Instant::now() < deadline {
                if self.exited().is_some() {
                    self.signal_group(Signal::SIGKILL);
                    return Stopped::BySignal(name);
                }
                std::thread::sleep(Duration::from_millis(5));
            }
        }
        // SIGKILL can't be ignored; a process still there is stuck in the kernel: reap it.
        self.status = self.child.wait().ok();
        Stopped::BySignal("SIGKILL")
    }
}

impl Drop for ControllerProcess {
    /// Never leaves the process behind.
    fn drop(&mut self) {
        self.stop(Duration::from_secs(1));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn domain_leases_are_distinct_and_released() {
        let a = DomainLease::acquire().unwrap();
        let b = DomainLease::acquire().unwrap();
        assert_ne!(a.id(), b.id());
        assert!(DOMAINS.contains(&a.id()) && DOMAINS.contains(&b.id()));
    }

    #[test]
    fn stop_escalates_to_sigkill_and_kills_the_group() {
        let dir = tempfile::tempdir().unwrap();
        let log = dir.path().join("c.log");
        // Ignores SIGINT and SIGTERM; a child in the same group does too.
        let mut p =
            ControllerProcess::start("trap '' INT TERM; sleep 30 & echo started; wait", dir.path(), &[], &log, "test")
                .unwrap();
        std::thread::sleep(Duration::from_millis(200));
        let t = Instant::now();
        assert_eq!(p.stop(Duration::from_millis(200)), Stopped::BySignal("SIGKILL"));
        assert!(t.elapsed() < Duration::from_secs(3));
        let pgid = nix::unistd::Pid::from_raw(p.pid() as i32);
        // Nothing of the group runs any more (a killed orphan may stay a zombie until init
        // reaps it).
        let alive = || {
            std::fs::read_dir("/proc").unwrap().flatten().any(|e| {
                let stat = std::fs::read_to_string(e.path().join("stat")).unwrap_or_default();
                let fields: Vec<&str> = stat.rsplit_once(')').map_or("", |(_, r)| r).split_whitespace().collect();
                fields.len() > 2 && fields[2] == pgid.as_raw().to_string() && fields[0] != "Z"
            })
        };
        assert!(!alive(), "a process of group {pgid} still runs");
        let text = std::fs::read_to_string(&log).unwrap();
        assert!(text.contains("--- twin: test") && text.contains("started"), "{text}");
    }

    /// Whether this process ignores SIGINT (started by `nohup`, or as a background command of
    /// a shell without job control): its children inherit that, and a shell cannot undo it.
    fn sigint_ignored_here() -> bool {
        let status = std::fs::read_to_string("/proc/self/status").unwrap();
        let mask = status.lines().find_map(|l| l.strip_prefix("SigIgn:")).unwrap().trim();
        u64::from_str_radix(mask, 16).unwrap() & (1 << (nix::sys::signal::Signal::SIGINT as u64 - 1)) != 0
    }

    #[test]
    fn sigint_stops_a_process_that_honours_it() {
        let dir = tempfile::tempdir().unwrap();
        let mut p =
            ControllerProcess::start("exec sleep 30", dir.path(), &[], &dir.path().join("c.log"), "test").unwrap();
        std::thread::sleep(Duration::from_millis(100));
        // `sleep` honours SIGINT unless it inherited SIGINT ignored: then SIGTERM stops it.
        let expected = if sigint_ignored_here() { "SIGTERM" } else { "SIGINT" };
        assert_eq!(p.stop(Duration::from_secs(2)), Stopped::BySignal(expected));
    }
}
