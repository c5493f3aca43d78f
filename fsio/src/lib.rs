//! Files the user owns: how twin opens its inputs and writes its outputs. Every command goes
//! through here, so the rules hold everywhere:
//!
//! - **Inputs** are regular files (or a folder where a folder is expected, e.g. a rosbag2 bag).
//!   FIFOs, devices and sockets are refused from their metadata *before* opening, and the file
//!   is opened with `O_NONBLOCK` (which has no effect on regular files) and checked again from
//!   the open descriptor, so a FIFO swapped in between never blocks twin.
//! - **Outputs** are checked before any work ([`check_output`]): not a folder, not a device or
//!   FIFO, not one of the command's inputs; a symlink is followed and its *target* rewritten (the
//!   link stays a link). The new content goes to a temp file beside the target, gets the
//!   target's permissions (and owner, when allowed), and is renamed over it. A target with
//!   several hard links is instead rewritten in place after its backup is made, so every link
//!   sees the new content (a crash in the middle leaves the backup complete).
//! - **Backups** are numbered and never overwritten: the first rewrite keeps the original as
//!   `NAME.bak`, later ones as `NAME.bak.1`, `NAME.bak.2`, … (the oldest original is always
//!   `NAME.bak`).
//! - **Concurrent writers** of the same folder are serialized by an advisory lock (`flock`) on
//!   the folder itself; no lock file is left behind. A folder's lock is keyed by its canonical
//!   path, so every spelling of it (relative, absolute, through `..` or a symlink) is one lock,
//!   taken once per commit; a writer waits at most [`LOCK_WAIT`] for another process's lock,
//!   saying which folder it waits for, then gives up with an error. A writer that read the file it rewrites
//!   passes what it read ([`Transaction::expect_unchanged`]): if another process changed the
//!   file meanwhile, the write is refused instead of silently losing the other result.
//! - **Several outputs** of one command are staged in a [`Transaction`] and renamed only when
//!   every one was written, so a failing second output leaves the first untouched.
//! - **Streamed outputs** (rows written as a long run finishes them, such as randomize's
//!   `episodes.csv`) go through a [`StreamingFile`]: the rows go to a named partial file beside
//!   the target (readable while it grows, kept if the run dies, so its progress can be
//!   counted), and [`StreamingFile::commit`] fsyncs it and renames it into place like any other
//!   output (checks, backup, permissions, folder lock).
//! - **Temp files** (`.NAME.twin-PID-XXXXXX`) are removed on drop, on Ctrl-C/SIGTERM/SIGHUP
//!   ([`install_signal_handler`]), and, for a process killed with SIGKILL, by the next twin
//!   writing the same file (temps whose process is gone are swept).

#![deny(unsafe_code)]

mod error;

pub use error::{Error, Result};
use std::fs::{File, Metadata, OpenOptions};
use std::io::{Read, Write};
use std::os::unix::fs::{MetadataExt, OpenOptionsExt, PermissionsExt};
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, Ordering};

/// What an input path may be.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum InputKind {
    /// A regular file.
    File,
    /// A regular file or a folder (a rosbag2 bag folder, an output folder).
    FileOrDir,
}

fn bad(path: &Path, message: impl Into<String>) -> Error {
    Error::BadPath { path: path.to_path_buf(), message: message.into() }
}

fn kind_name(meta: &Metadata) -> &'static str {
    use std::os::unix::fs::FileTypeExt;
    let t = meta.file_type();
    if t.is_dir() {
        "a folder"
    } else if t.is_fifo() {
        "a FIFO (named pipe)"
    } else if t.is_char_device() || t.is_block_device() {
        "a device"
    } else if t.is_socket() {
        "a socket"
    } else if t.is_symlink() {
        "a symbolic link"
    } else {
        "a regular file"
    }
}

fn check_kind(path: &Path, meta: &Metadata, kind: InputKind) -> Result<()> {
    let ok = meta.is_file() || (kind == InputKind::FileOrDir && meta.is_dir());
    if ok {
        return Ok(());
    }
    let expected = match kind {
        InputKind::File => "a regular file",
        InputKind::FileOrDir => "a regular file or a folder",
    };
    Err(bad(path, format!("is {}, expected {expected}; twin reads only files it can read to the end", kind_name(meta))))
}

/// Checks that `path` exists and is of `kind` (symlinks followed), without opening it.
///
/// # Errors
/// [`Error::Io`] when it cannot be stat'ed, [`Error::BadPath`] for a FIFO, device, socket or
/// (for [`InputKind::File`]) a folder.
pub fn check_input(path: &Path, kind: InputKind) -> Result<Metadata> {
    let meta = std::fs::metadata(path).map_err(|source| Error::Io { path: path.to_path_buf(), source })?;
    check_kind(path, &meta, kind)?;
    Ok(meta)
}

/// Opens a regular file for reading without ever blocking (see the module docs).
///
/// # Errors
/// As [`check_input`].
pub fn open(path: &Path) -> Result<File> {
    check_input(path, InputKind::File)?;
    let file = OpenOptions::new()
        .read(true)
        // Never block in open() on a FIFO swapped in after the check; on a regular file
        // O_NONBLOCK changes nothing, so it need not be cleared.
        .custom_flags(libc::O_NONBLOCK)
        .open(path)
        .map_err(|source| Error::Io { path: path.to_path_buf(), source })?;
    let meta = file.metadata().map_err(|source| Error::Io { path: path.to_path_buf(), source })?;
    check_kind(path, &meta, InputKind::File)?;
    Ok(file)
}

/// Reads a regular file whole (see [`open`]).
///
/// # Errors
/// As [`open`], [`Error::Io`] on a read error.
pub fn read(path: &Path) -> Result<Vec<u8>> {
    let mut bytes = Vec::new();
    open(path)?.read_to_end(&mut bytes).map_err(|source| Error::Io { path: path.to_path_buf(), source })?;
    Ok(bytes)
}

/// Reads a regular UTF-8 text file whole (see [`open`]).
///
/// # Errors
/// As [`read`]; [`Error::Io`] with `InvalidData` for text that is not UTF-8.
pub fn read_to_string(path: &Path) -> Result<String> {
    String::from_utf8(read(path)?).map_err(|e| Error::Io {
        path: path.to_path_buf(),
        source: std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            format!("not UTF-8 text (invalid byte at offset {})", e.utf8_error().valid_up_to()),
        ),
    })
}

/// At most `max` characters of `text` (on a char boundary), with `…` when cut: error messages
/// quote bad input through this so a huge or binary file never floods the terminal.
pub fn excerpt(text: &str, max: usize) -> String {
    let mut out: String = text.chars().take(max).map(|c| if c.is_control() && c != ' ' { '�' } else { c }).collect();
    if text.chars().nth(max).is_some() {
        out.push('…');
    }
    out
}

/// A parser's message that may quote bad input (e.g. TOML errors show the offending line):
/// each line capped by [`excerpt`], at most 20 lines.
pub fn cap_message(message: &str) -> String {
    let mut lines: Vec<String> = message.lines().take(20).map(|l| excerpt(l, EXCERPT_CHARS)).collect();
    if message.lines().nth(20).is_some() {
        lines.push("…".into());
    }
    lines.join("\n")
}

/// The most characters of bad input an error message quotes.
pub const EXCERPT_CHARS: usize = 200;

/// An output path checked by [`check_output`]: where the bytes really go.
#[derive(Debug, Clone)]
pub struct OutputTarget {
    /// The path as the user gave it (for messages).
    pub requested: PathBuf,
    /// The file actually written: `requested` with symlinks followed.
    pub resolved: PathBuf,
    /// Metadata of the existing file, `None` for a new one.
    pub existing: Option<Metadata>,
}

/// Follows symlinks at `path` (also dangling ones, whose target will be created).
fn resolve_links(path: &Path) -> Result<PathBuf> {
    let mut current = path.to_path_buf();
    for _ in 0..40 {
        match std::fs::symlink_metadata(&current) {
            Ok(m) if m.file_type().is_symlink() => {
                let target =
                    std::fs::read_link(&current).map_err(|source| Error::Io { path: current.clone(), source })?;
                current =
                    if target.is_absolute() { target } else { current.parent().unwrap_or(Path::new("")).join(target) };
            }
            _ => return Ok(current),
        }
    }
    Err(bad(path, "too many levels of symbolic links"))
}

fn same_file(a: &Metadata, b: &Metadata) -> bool {
    a.dev() == b.dev() && a.ino() == b.ino()
}

/// Checks an output path before any work: its folder exists; it is not a folder, device, FIFO
/// or socket; it is none of `inputs` (compared by device and inode, so a symlink or hard link
/// to an input counts). Symlinks are followed: the target is what gets written.
///
/// # Errors
/// [`Error::BadPath`] saying what is wrong and what to do.
pub fn check_output(path: &Path, inputs: &[&Path]) -> Result<OutputTarget> {
    if path.as_os_str().is_empty() {
        return Err(bad(path, "empty output path"));
    }
    let resolved = resolve_links(path)?;
    let existing = match std::fs::metadata(&resolved) {
        Ok(m) => Some(m),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => None,
        Err(source) => return Err(Error::Io { path: path.to_path_buf(), source }),
    };
    if let Some(meta) = &existing {
        if !meta.is_file() {
            return Err(bad(
                path,
                format!(
                    "is {}: twin writes only regular files; give a file name{}",
                    kind_name(meta),
                    if meta.is_dir() { " inside it" } else { "" }
                ),
            ));
        }
        for input in inputs {
            if let Ok(im) = std::fs::metadata(input)
                && same_file(meta, &im)
            {
                return Err(bad(
                    path,
                    format!("is the input {}: writing it would destroy it; choose another output", input.display()),
                ));
            }
        }
    }
    let dir = parent_dir(&resolved);
    match std::fs::metadata(dir) {
        Ok(m) if m.is_dir() => {}
        Ok(_) => return Err(bad(path, format!("{} is not a folder", dir.display()))),
        Err(_) => return Err(bad(path, format!("folder {} does not exist; create it first", dir.display()))),
    }
    Ok(OutputTarget { requested: path.to_path_buf(), resolved, existing })
}

/// [`check_output`] for every output a command writes, each checked against the `inputs` and
/// against the other outputs (two options naming one file would leave only the last write).
/// `outputs` pairs each optional path with the option that names it, for the message; the
/// targets come back in the same order, `None` where the option was not given.
///
/// # Errors
/// [`Error::BadPath`] as [`check_output`], or naming the two options that share a file.
pub fn check_outputs(outputs: &[(&str, Option<&Path>)], inputs: &[&Path]) -> Result<Vec<Option<OutputTarget>>> {
    let targets =
        outputs.iter().map(|(_, p)| p.map(|p| check_output(p, inputs)).transpose()).collect::<Result<Vec<_>>>()?;
    for (i, a) in targets.iter().enumerate() {
        for (j, b) in targets.iter().enumerate().skip(i + 1) {
            if let (Some(a), Some(b)) = (a, b)
                && same_target(a, b)
            {
                return Err(bad(
                    &a.requested,
                    format!("is named by both {} and {}: give each output its own file", outputs[i].0, outputs[j].0),
                ));
            }
        }
    }
    Ok(targets)
}

/// Whether two checked outputs write the same file: same inode when both exist, else the same
/// file name in the same folder.
fn same_target(a: &OutputTarget, b: &OutputTarget) -> bool {
    if let (Some(ma), Some(mb)) = (&a.existing, &b.existing) {
        return same_file(ma, mb);
    }
    let folder = |t: &OutputTarget| std::fs::canonicalize(parent_dir(&t.resolved)).ok();
    a.resolved.file_name() == b.resolved.file_name() && folder(a).is_some() && folder(a) == folder(b)
}

/// Checks an output *folder* before any work: it is a folder or does not exist yet (its parent
/// is then created when written), and it is none of `inputs`.
///
/// # Errors
/// [`Error::BadPath`].
pub fn check_output_dir(path: &Path, inputs: &[&Path]) -> Result<()> {
    match std::fs::metadata(path) {
        Ok(m) if m.is_dir() => {
            for input in inputs {
                if let Ok(im) = std::fs::metadata(input)
                    && same_file(&m, &im)
                {
                    return Err(bad(
                        path,
                        format!(
                            "is the input {}: writing into it would overwrite it; choose another folder",
                            input.display()
                        ),
                    ));
                }
            }
            Ok(())
        }
        Ok(m) => Err(bad(path, format!("is {}, expected a folder (or a name for a new one)", kind_name(&m)))),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(()),
        Err(source) => Err(Error::Io { path: path.to_path_buf(), source }),
    }
}

fn parent_dir(path: &Path) -> &Path {
    path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."))
}

/// Whether a rewrite keeps the previous content.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Backup {
    /// Replace without a backup (generated outputs such as reports and recordings).
    #[default]
    None,
    /// Keep the previous content as the first free of `NAME.bak`, `NAME.bak.1`, `NAME.bak.2`, …
    /// (files a user edits, such as a URDF).
    Numbered,
}

/// The first free numbered backup name of `path`.
fn free_backup(path: &Path) -> PathBuf {
    let mut n = 0u32;
    loop {
        let mut name = path.as_os_str().to_owned();
        name.push(if n == 0 { ".bak".to_string() } else { format!(".bak.{n}") });
        let candidate = PathBuf::from(name);
        if std::fs::symlink_metadata(&candidate).is_err() {
            return candidate;
        }
        n += 1;
    }
}

/// Copies the current content of `path` to its first free numbered backup, keeping its mode.
/// The copy is created with `create_new`, so a concurrent writer can never overwrite it.
///
/// # Errors
/// [`Error::Io`].
pub fn backup_numbered(path: &Path) -> Result<PathBuf> {
    let io = |p: &Path| {
        let p = p.to_path_buf();
        move |source| Error::Io { path: p, source }
    };
    let mut src = open(path)?;
    let mode = src.metadata().map_err(io(path))?.permissions().mode();
    loop {
        let backup = free_backup(path);
        let mut dst = match OpenOptions::new().write(true).create_new(true).mode(mode & 0o7777).open(&backup) {
            Ok(f) => f,
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => continue,
            Err(e) => return Err(io(&backup)(e)),
        };
        std::io::copy(&mut src, &mut dst).map_err(io(&backup))?;
        dst.sync_all().map_err(io(&backup))?;
        return Ok(backup);
    }
}

// ---- temp files and signals ----

static LIVE_TEMPS: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());
static INTERRUPTED: AtomicBool = AtomicBool::new(false);
static COOPERATIVE: AtomicBool = AtomicBool::new(false);

fn remove_live_temps() {
    let temps = LIVE_TEMPS.lock().map(|mut t| std::mem::take(&mut *t)).unwrap_or_default();
    for t in temps {
        let _ = std::fs::remove_file(t);
    }
}

fn forget_temp(path: &Path) {
    if let Ok(mut t) = LIVE_TEMPS.lock() {
        t.retain(|p| p != path);
    }
}

/// Installs the process's Ctrl-C / SIGTERM / SIGHUP handler (call once, from `main`). A command
/// that stops cleanly on its own calls [`cooperate`] and polls [`interrupted`]; otherwise the
/// first signal removes twin's temp files and exits with status 130. A second signal always
/// does that.
pub fn install_signal_handler() {
    let _ = ctrlc::set_handler(|| {
        if INTERRUPTED.swap(true, Ordering::SeqCst) || !COOPERATIVE.load(Ordering::SeqCst) {
            remove_live_temps();
            std::process::exit(130);
        }
        eprintln!("\nstopping: finishing what is in flight (Ctrl-C again to abort)");
    });
}

/// Declares that the running command polls [`interrupted`] and finishes cleanly by itself.
pub fn cooperate() {
    COOPERATIVE.store(true, Ordering::SeqCst);
}

/// Whether Ctrl-C (or SIGTERM/SIGHUP) was received.
pub fn interrupted() -> bool {
    INTERRUPTED.load(Ordering::SeqCst)
}

/// The flag behind [`interrupted`], for code that takes an `&AtomicBool` stop flag.
pub fn interrupt_flag() -> &'static AtomicBool {
    &INTERRUPTED
}

fn temp_prefix(target: &Path) -> String {
    format!(".{}.twin-", target.file_name().map_or_else(|| "out".into(), |n| n.to_string_lossy()))
}

/// Removes temp files of `target` left by twin processes that no longer run (SIGKILL).
fn sweep_stale_temps(target: &Path) {
    let prefix = temp_prefix(target);
    let Ok(entries) = std::fs::read_dir(parent_dir(target)) else { return };
    for entry in entries.flatten() {
        let name = entry.file_name();
        let Some(rest) = name.to_str().and_then(|n| n.strip_prefix(&prefix)) else { continue };
        let Some(pid) = rest.split('-').next().and_then(|p| p.parse::<u32>().ok()) else { continue };
        if pid != std::process::id() && !Path::new(&format!("/proc/{pid}")).exists() {
            let _ = std::fs::remove_file(entry.path());
        }
    }
}

/// A temp file beside an output, removed unless committed.
#[derive(Debug)]
struct Temp {
    path: PathBuf,
    file: Option<File>,
    /// Left in place on drop (a [`StreamingFile`]'s partial file when the stream is abandoned).
    keep: bool,
}

impl Temp {
    fn new(target: &Path) -> Result<Self> {
        sweep_stale_temps(target);
        let dir = parent_dir(target);
        let named = tempfile::Builder::new()
            .prefix(&format!("{}{}-", temp_prefix(target), std::process::id()))
            .tempfile_in(dir)
            .map_err(|source| Error::Io { path: target.to_path_buf(), source })?;
        let (file, path) = named.keep().map_err(|e| Error::Io { path: target.to_path_buf(), source: e.error })?;
        if let Ok(mut t) = LIVE_TEMPS.lock() {
            t.push(path.clone());
        }
        Ok(Self { path, file: Some(file), keep: false })
    }
}

impl Drop for Temp {
    fn drop(&mut self) {
        self.file = None;
        if self.keep {
            return;
        }
        let _ = std::fs::remove_file(&self.path);
        forget_temp(&self.path);
    }
}

// ---- the one atomic writer ----

/// The longest a commit waits for another process's lock on an output folder (30 s): a writer
/// holds it only while renaming its files into place, so a longer wait means a stuck process.
pub const LOCK_WAIT: std::time::Duration = std::time::Duration::from_secs(30);

/// An advisory exclusive lock on a folder (flock), released on drop.
struct DirLock(#[allow(dead_code)] File);

/// The key of a folder's lock: its canonical path (symlinks, `.` and `..` resolved, absolute),
/// so that two spellings of one folder are one lock.
///
/// # Errors
/// [`Error::Io`] when the folder cannot be resolved (it vanished).
pub fn lock_key(dir: &Path) -> Result<PathBuf> {
    std::fs::canonicalize(dir).map_err(|source| Error::Io { path: dir.to_path_buf(), source })
}

/// Locks the folder `dir` (a canonical path, [`lock_key`]), waiting at most `wait` for another
/// holder and saying once on stderr which folder it waits for.
fn lock_dir(dir: &Path, wait: std::time::Duration) -> Result<DirLock> {
    let f = File::open(dir).map_err(|source| Error::Io { path: dir.to_path_buf(), source })?;
    let started = std::time::Instant::now();
    let mut said = false;
    loop {
        match f.try_lock() {
            Ok(()) => return Ok(DirLock(f)),
            Err(std::fs::TryLockError::WouldBlock) => {}
            Err(std::fs::TryLockError::Error(source)) => return Err(Error::Io { path: dir.to_path_buf(), source }),
        }
        if started.elapsed() >= wait {
            return Err(bad(
                dir,
                format!(
                    "another process has held the write lock of this folder for {:.0} s (another twin writing \
                     here?); nothing was written: run again when it has finished",
                    started.elapsed().as_secs_f64()
                ),
            ));
        }
        if !said {
            eprintln!(
                "waiting (at most {} s) for the write lock of folder {}: another process is writing there",
                wait.as_secs(),
                dir.display()
            );
            said = true;
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
}

#[derive(Debug)]
struct Staged {
    target: OutputTarget,
    temp: Temp,
    backup: Backup,
    expect: Option<Vec<u8>>,
}

/// What [`Transaction::commit`] did for one output.
#[derive(Debug, Clone)]
pub struct Written {
    /// The output as the user named it.
    pub path: PathBuf,
    /// Its backup, when one was made.
    pub backup: Option<PathBuf>,
}

/// Several outputs of one command, written to temp files and renamed into place only when all
/// were written ([`Transaction::commit`]). Dropped uncommitted, it removes its temp files and
/// leaves every target untouched.
#[derive(Debug, Default)]
pub struct Transaction {
    staged: Vec<Staged>,
}

impl Transaction {
    /// An empty transaction.
    pub fn new() -> Self {
        Self::default()
    }

    /// Stages `bytes` for `target` (checked with [`check_output`]).
    ///
    /// # Errors
    /// [`Error::Io`] when the temp file cannot be written.
    pub fn stage(&mut self, target: &OutputTarget, bytes: &[u8], backup: Backup) -> Result<()> {
        self.stage_with(target, backup, |f| f.write_all(bytes))
    }

    /// Stages what `write` writes for `target`.
    ///
    /// # Errors
    /// [`Error::Io`] from the temp file or `write`.
    pub fn stage_with(
        &mut self,
        target: &OutputTarget,
        backup: Backup,
        write: impl FnOnce(&mut File) -> std::io::Result<()>,
    ) -> Result<()> {
        let io = |source| Error::Io { path: target.requested.clone(), source };
        let mut temp = Temp::new(&target.resolved)?;
        let file = temp.file.as_mut().expect("a new temp has its file");
        write(file).map_err(io)?;
        file.flush().map_err(io)?;
        file.sync_all().map_err(io)?;
        self.staged.push(Staged { target: target.clone(), temp, backup, expect: None });
        Ok(())
    }

    /// Refuses to commit if the last staged output's current content is no longer `original`
    /// (another process rewrote it since this one read it).
    pub fn expect_unchanged(&mut self, original: &[u8]) {
        if let Some(s) = self.staged.last_mut() {
            s.expect = Some(original.to_vec());
        }
    }

    /// Renames every staged output into place (backups first), under a lock of each folder.
    ///
    /// # Errors
    /// [`Error::BadPath`] when a target changed since it was read or checked; [`Error::Io`].
    pub fn commit(self) -> Result<Vec<Written>> {
        // One lock per folder, whatever the spelling of its outputs' paths: the same folder
        // locked twice through two descriptors would wait for itself.
        let mut dirs =
            self.staged.iter().map(|s| lock_key(parent_dir(&s.target.resolved))).collect::<Result<Vec<PathBuf>>>()?;
        dirs.sort();
        dirs.dedup();
        let _locks = dirs.iter().map(|d| lock_dir(d, LOCK_WAIT)).collect::<Result<Vec<_>>>()?;
        // Everything that can be refused is refused before anything is renamed.
        let mut current = Vec::with_capacity(self.staged.len());
        for s in &self.staged {
            let meta = match std::fs::metadata(&s.target.resolved) {
                Ok(m) => Some(m),
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => None,
                Err(source) => return Err(Error::Io { path: s.target.requested.clone(), source }),
            };
            if let Some(m) = &meta
                && !m.is_file()
            {
                return Err(bad(&s.target.requested, format!("became {} while twin worked", kind_name(m))));
            }
            if let Some(expected) = &s.expect {
                let now = if meta.is_some() { Some(read(&s.target.resolved)?) } else { None };
                if now.as_deref() != Some(expected.as_slice()) {
                    return Err(bad(
                        &s.target.requested,
                        "changed while twin worked on it (another twin or an editor wrote it); nothing was \
                         written: run again on the new content",
                    ));
                }
            }
            current.push(meta);
        }
        let mut written = Vec::with_capacity(self.staged.len());
        for (mut s, meta) in self.staged.into_iter().zip(current) {
            let io = |source| Error::Io { path: s.target.requested.clone(), source };
            let backup = match (s.backup, &meta) {
                (Backup::Numbered, Some(_)) => Some(backup_numbered(&s.target.resolved)?),
                _ => None,
            };
            match &meta {
                Some(m) if m.nlink() > 1 => {
                    // Hard links: rewrite the shared inode in place so every link sees it.
                    let mut src = File::open(&s.temp.path).map_err(io)?;
                    let mut dst = OpenOptions::new().write(true).truncate(true).open(&s.target.resolved).map_err(io)?;
                    std::io::copy(&mut src, &mut dst).map_err(io)?;
                    dst.sync_all().map_err(io)?;
                }
                _ => {
                    if let Some(m) = &meta {
                        let _ =
                            std::fs::set_permissions(&s.temp.path, std::fs::Permissions::from_mode(m.mode() & 0o7777));
                        // Keep the owner when allowed (root rewriting a user's file).
                        let _ = std::os::unix::fs::chown(&s.temp.path, Some(m.uid()), Some(m.gid()));
                    } else {
                        // tempfile creates 0600; a new output gets the usual 0666 & ~umask.
                        let _ =
                            std::fs::set_permissions(&s.temp.path, std::fs::Permissions::from_mode(0o666 & !umask()));
                    }
                    s.temp.file = None;
                    std::fs::rename(&s.temp.path, &s.target.resolved).map_err(io)?;
                }
            }
            written.push(Written { path: s.target.requested.clone(), backup });
        }
        Ok(written)
    }
}

/// One output written as a stream (rows appended as a long run finishes them), then put in place
/// atomically. The bytes go, buffered, to `partial`, a file the caller names beside the target
/// (others may read it while it grows: how far a run got); [`StreamingFile::commit`] flushes and
/// fsyncs it and renames it over the target exactly as [`Transaction::commit`] does (backup,
/// permissions, hard links, folder lock). Dropped uncommitted (an error, a killed run), the
/// target is untouched and the partial file stays, holding what was written.
#[derive(Debug)]
pub struct StreamingFile {
    target: OutputTarget,
    backup: Backup,
    /// `None` once committed.
    temp: Option<Temp>,
    writer: std::io::BufWriter<File>,
}

impl StreamingFile {
    /// Checks `path` ([`check_output`] with no inputs) and creates (or truncates) `partial`.
    ///
    /// # Errors
    /// As [`check_output`]; [`Error::BadPath`] when `partial` is not beside `path` or is `path`;
    /// [`Error::Io`] when `partial` cannot be created.
    pub fn create(path: &Path, partial: &Path, backup: Backup) -> Result<Self> {
        let target = check_output(path, &[])?;
        if parent_dir(partial) != parent_dir(path) || partial.file_name() == path.file_name() {
            return Err(bad(partial, "a streamed output's partial file must be another file in the target's folder"));
        }
        let file = File::create(partial).map_err(|source| Error::Io { path: partial.to_path_buf(), source })?;
        let writer = std::io::BufWriter::new(
            file.try_clone().map_err(|source| Error::Io { path: partial.to_path_buf(), source })?,
        );
        let temp = Temp { path: partial.to_path_buf(), file: Some(file), keep: false };
        Ok(Self { target, backup, temp: Some(temp), writer })
    }

    /// The partial file the bytes go to until [`StreamingFile::commit`].
    pub fn partial_path(&self) -> &Path {
        self.temp.as_ref().map_or(Path::new(""), |t| t.path.as_path())
    }

    /// Flushes, fsyncs and renames the partial file over the target (backup first, as
    /// `backup` says); returns the backup's path when one was made.
    ///
    /// # Errors
    /// [`Error::Io`] from the flush or the sync; as [`Transaction::commit`].
    pub fn commit(mut self) -> Result<Option<PathBuf>> {
        let partial = self.partial_path().to_path_buf();
        let io = |source| Error::Io { path: partial.clone(), source };
        self.writer.flush().map_err(io)?;
        self.writer.get_ref().sync_all().map_err(io)?;
        let temp = self.temp.take().expect("a streaming file is committed once");
        let staged = Staged { target: self.target.clone(), temp, backup: self.backup, expect: None };
        Ok(Transaction { staged: vec![staged] }.commit()?.pop().and_then(|w| w.backup))
    }
}

impl Write for StreamingFile {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.writer.write(buf)
    }
    fn flush(&mut self) -> std::io::Result<()> {
        self.writer.flush()
    }
}

impl Drop for StreamingFile {
    fn drop(&mut self) {
        if let Some(t) = self.temp.as_mut() {
            // Abandoned: what was written stays readable (the writer flushes it as it drops).
            t.keep = true;
        }
    }
}

/// The process umask (read from /proc; 022 when unavailable).
fn umask() -> u32 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines().find_map(|l| l.strip_prefix("Umask:").and_then(|v| u32::from_str_radix(v.trim(), 8).ok()))
        })
        .unwrap_or(0o022)
}

/// THE atomic writer: checks `path` ([`check_output`] with no inputs), writes `bytes` to a temp
/// file beside its target and renames it into place, with `backup`.
///
/// # Errors
/// As [`check_output`] and [`Transaction::commit`].
pub fn write_atomic(path: &Path, bytes: &[u8], backup: Backup) -> Result<Option<PathBuf>> {
    let target = check_output(path, &[])?;
    let mut tx = Transaction::new();
    tx.stage(&target, bytes, backup)?;
    Ok(tx.commit()?.pop().and_then(|w| w.backup))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(dir: &Path) -> Vec<String> {
        let mut v: Vec<String> =
            std::fs::read_dir(dir).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
        v.sort();
        v
    }

    #[test]
    fn fifo_and_devices_are_refused_without_blocking() {
        let dir = tempfile::tempdir().unwrap();
        let fifo = dir.path().join("f.urdf");
        assert!(std::process::Command::new("mkfifo").arg(&fifo).status().unwrap().success());
        let e = read_to_string(&fifo).unwrap_err().to_string();
        assert!(e.contains("FIFO"), "{e}");
        assert!(read(Path::new("/dev/zero")).unwrap_err().to_string().contains("device"));
        assert!(read(dir.path()).unwrap_err().to_string().contains("folder"));
        check_input(dir.path(), InputKind::FileOrDir).unwrap();
    }

    #[test]
    fn outputs_that_are_folders_devices_or_inputs_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let input = dir.path().join("r.urdf");
        std::fs::write(&input, "x").unwrap();
        assert!(check_output(dir.path(), &[]).unwrap_err().to_string().contains("folder"));
        assert!(check_output(Path::new("/dev/null"), &[]).unwrap_err().to_string().contains("device"));
        let e = check_output(&input, &[&input]).unwrap_err().to_string();
        assert!(e.contains("is the input"), "{e}");
        let link = dir.path().join("link.xml");
        std::os::unix::fs::symlink(&input, &link).unwrap();
        assert!(check_output(&link, &[&input]).unwrap_err().to_string().contains("is the input"));
        let e = check_output(Path::new("/nonexistent/x.xml"), &[]).unwrap_err().to_string();
        assert!(e.contains("does not exist"), "{e}");
        assert_eq!(std::fs::read(&input).unwrap(), b"x");
    }

    #[test]
    fn two_outputs_naming_one_file_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let a = dir.path().join("out.json");
        let sub = dir.path().join("sub");
        std::fs::create_dir(&sub).unwrap();
        // New file reached by two spellings of one folder.
        let b = sub.join("..").join("out.json");
        let e = check_outputs(&[("--report", Some(&a)), ("--plot", Some(&b))], &[]).unwrap_err().to_string();
        assert!(e.contains("--report") && e.contains("--plot"), "{e}");
        // Existing file and a symlink to it.
        std::fs::write(&a, "x").unwrap();
        let link = dir.path().join("link.svg");
        std::os::unix::fs::symlink(&a, &link).unwrap();
        assert!(check_outputs(&[("--report", Some(&a)), ("--plot", Some(&link))], &[]).is_err());
        // Distinct files pass, in order.
        let c = dir.path().join("plot.svg");
        let t = check_outputs(&[("--report", Some(&a)), ("--rerun", None), ("--plot", Some(&c))], &[]).unwrap();
        assert!(t[1].is_none());
        assert_eq!(t[2].as_ref().unwrap().requested, c);
    }

    #[test]
    fn backups_are_numbered_and_never_overwritten() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("r.urdf");
        std::fs::write(&p, "v0").unwrap();
        std::fs::set_permissions(&p, std::fs::Permissions::from_mode(0o664)).unwrap();
        assert_eq!(write_atomic(&p, b"v1", Backup::Numbered).unwrap(), Some(dir.path().join("r.urdf.bak")));
        assert_eq!(write_atomic(&p, b"v2", Backup::Numbered).unwrap(), Some(dir.path().join("r.urdf.bak.1")));
        assert_eq!(std::fs::read(dir.path().join("r.urdf.bak")).unwrap(), b"v0");
        assert_eq!(std::fs::read(dir.path().join("r.urdf.bak.1")).unwrap(), b"v1");
        assert_eq!(std::fs::read(&p).unwrap(), b"v2");
        assert_eq!(std::fs::metadata(&p).unwrap().permissions().mode() & 0o777, 0o664);
        assert_eq!(names(dir.path()), ["r.urdf", "r.urdf.bak", "r.urdf.bak.1"]);
    }

    #[test]
    fn symlinks_and_hard_links_are_kept() {
        let dir = tempfile::tempdir().unwrap();
        let real = dir.path().join("real.urdf");
        let link = dir.path().join("link.urdf");
        let hard = dir.path().join("hard.urdf");
        std::fs::write(&real, "old").unwrap();
        std::os::unix::fs::symlink("real.urdf", &link).unwrap();
        write_atomic(&link, b"new", Backup::None).unwrap();
        assert!(std::fs::symlink_metadata(&link).unwrap().file_type().is_symlink());
        assert_eq!(std::fs::read(&real).unwrap(), b"new");
        std::fs::hard_link(&real, &hard).unwrap();
        write_atomic(&hard, b"newer", Backup::Numbered).unwrap();
        assert_eq!(std::fs::read(&real).unwrap(), b"newer");
        assert_eq!(std::fs::metadata(&real).unwrap().nlink(), 2);
        assert_eq!(std::fs::read(dir.path().join("hard.urdf.bak")).unwrap(), b"new");
    }

    #[test]
    fn a_transaction_writes_all_or_nothing_and_detects_concurrent_changes() {
        let dir = tempfile::tempdir().unwrap();
        let a = dir.path().join("a.txt");
        std::fs::write(&a, "a0").unwrap();
        let ta = check_output(&a, &[]).unwrap();
        {
            let mut tx = Transaction::new();
            tx.stage(&ta, b"a1", Backup::Numbered).unwrap();
            // A second output that fails: nothing is renamed, temps are gone.
            let tb = check_output(&dir.path().join("b.txt"), &[]).unwrap();
            assert!(tx.stage_with(&tb, Backup::None, |_| Err(std::io::Error::other("boom"))).is_err());
        }
        assert_eq!(std::fs::read(&a).unwrap(), b"a0");
        assert_eq!(names(dir.path()), ["a.txt"]);
        let mut tx = Transaction::new();
        tx.stage(&ta, b"a1", Backup::Numbered).unwrap();
        tx.expect_unchanged(b"a0");
        std::fs::write(&a, "someone else").unwrap();
        assert!(tx.commit().unwrap_err().to_string().contains("changed while twin worked"));
        assert_eq!(std::fs::read(&a).unwrap(), b"someone else");
        assert_eq!(names(dir.path()), ["a.txt"]);
    }

    /// Commits a transaction writing `first` and `second` (two spellings of files in one
    /// folder) on another thread; fails instead of hanging if it does not end within 5 s.
    fn commit_two_within_5_s(first: PathBuf, second: PathBuf) {
        let (tx, rx) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            let run = || -> Result<Vec<Written>> {
                let mut t = Transaction::new();
                t.stage(&check_output(&first, &[])?, b"one", Backup::Numbered)?;
                t.stage(&check_output(&second, &[])?, b"two", Backup::None)?;
                t.commit()
            };
            let _ = tx.send(run().map(|w| w.len()));
        });
        let got = rx.recv_timeout(std::time::Duration::from_secs(5)).expect("the commit ended within 5 s");
        assert_eq!(got.unwrap(), 2);
    }

    #[test]
    fn one_folder_under_two_spellings_is_one_lock_absolute_and_dotdot() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::create_dir(dir.path().join("sub")).unwrap();
        std::fs::write(dir.path().join("robot.urdf"), "old").unwrap();
        let dotdot = dir.path().join("sub/../rep.json");
        assert_eq!(lock_key(dir.path()).unwrap(), lock_key(&dir.path().join("sub/..")).unwrap());
        commit_two_within_5_s(dir.path().join("robot.urdf"), dotdot);
        assert_eq!(std::fs::read(dir.path().join("rep.json")).unwrap(), b"two");
        assert_eq!(std::fs::read(dir.path().join("robot.urdf.bak")).unwrap(), b"old");
    }

    #[test]
    fn one_folder_under_two_spellings_is_one_lock_symlink() {
        let dir = tempfile::tempdir().unwrap();
        let real = dir.path().join("real");
        std::fs::create_dir(&real).unwrap();
        let link = dir.path().join("link");
        std::os::unix::fs::symlink(&real, &link).unwrap();
        assert_eq!(lock_key(&real).unwrap(), lock_key(&link).unwrap());
        commit_two_within_5_s(real.join("robot.urdf"), link.join("rep.json"));
        assert_eq!(names(&real), ["rep.json", "robot.urdf"]);
    }

    #[test]
    fn one_folder_under_two_spellings_is_one_lock_relative() {
        // The folder spelled relative to the working directory: up to the root, then down.
        let dir = tempfile::tempdir().unwrap();
        let here = std::env::current_dir().unwrap();
        let mut relative = PathBuf::new();
        for _ in here.components().skip(1) {
            relative.push("..");
        }
        relative.push(dir.path().strip_prefix("/").unwrap());
        assert!(relative.is_relative());
        assert_eq!(lock_key(&relative).unwrap(), lock_key(dir.path()).unwrap());
        commit_two_within_5_s(dir.path().join("robot.urdf"), relative.join("rep.json"));
        assert_eq!(names(dir.path()), ["rep.json", "robot.urdf"]);
    }

    #[test]
    fn a_held_lock_is_waited_for_a_bounded_time_naming_the_folder() {
        let dir = tempfile::tempdir().unwrap();
        let key = lock_key(dir.path()).unwrap();
        let _held = lock_dir(&key, LOCK_WAIT).unwrap();
        let started = std::time::Instant::now();
        let e = lock_dir(&key, std::time::Duration::from_millis(200)).err().expect("a second holder is refused");
        assert!(started.elapsed() < std::time::Duration::from_secs(2));
        let msg = e.to_string();
        assert!(msg.contains(&key.display().to_string()) && msg.contains("write lock"), "{msg}");
    }

    #[test]
    fn a_streamed_output_is_renamed_into_place_with_a_backup_or_left_partial() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("rows.csv");
        let partial = dir.path().join(".rows.csv.tmp");
        std::fs::write(&out, "old\n").unwrap();
        let mut s = StreamingFile::create(&out, &partial, Backup::Numbered).unwrap();
        s.write_all(b"a\n").unwrap();
        s.flush().unwrap();
        // Readable while it streams; the target is untouched until the commit.
        assert_eq!(std::fs::read(&partial).unwrap(), b"a\n");
        assert_eq!(std::fs::read(&out).unwrap(), b"old\n");
        s.write_all(b"b\n").unwrap();
        assert_eq!(s.commit().unwrap(), Some(dir.path().join("rows.csv.bak")));
        assert_eq!(std::fs::read(&out).unwrap(), b"a\nb\n");
        assert_eq!(std::fs::read(dir.path().join("rows.csv.bak")).unwrap(), b"old\n");
        assert_eq!(names(dir.path()), ["rows.csv", "rows.csv.bak"]);
        // Abandoned (an error, a killed run): the target stays, the rows written stay readable.
        let mut s = StreamingFile::create(&out, &partial, Backup::Numbered).unwrap();
        s.write_all(b"c\n").unwrap();
        drop(s);
        assert_eq!(std::fs::read(&out).unwrap(), b"a\nb\n");
        assert_eq!(std::fs::read(&partial).unwrap(), b"c\n");
        // The partial file must be another file beside the target.
        let e = StreamingFile::create(&out, &std::env::temp_dir().join(".rows.csv.tmp"), Backup::None).unwrap_err();
        assert!(e.to_string().contains("partial file"), "{e}");
        assert!(StreamingFile::create(dir.path(), &partial, Backup::None).is_err());
    }

    #[test]
    fn stale_temps_of_killed_processes_are_swept() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("r.urdf");
        // pid 0x7fff_fff0 does not exist.
        std::fs::write(dir.path().join(".r.urdf.twin-2147483632-abc123"), "junk").unwrap();
        write_atomic(&p, b"x", Backup::None).unwrap();
        assert_eq!(names(dir.path()), ["r.urdf"]);
    }

    #[test]
    fn excerpts_are_capped() {
        let long = "\0".repeat(10_000);
        let e = excerpt(&long, EXCERPT_CHARS);
        assert_eq!(e.chars().count(), EXCERPT_CHARS + 1);
        assert_eq!(excerpt("short", 200), "short");
        let m = cap_message(&format!("line 1\n{}\n", "x".repeat(5000)));
        assert!(m.len() < 300, "{m}");
    }
}
