//! Mutation harness: deterministic mutations (truncation, bit flips, attribute swaps, NaN/inf/
//! huge numbers, encoding marks, NUL bytes, deleted/duplicated lines) of valid URDFs, MJCFs,
//! ROS 2 bags, randomization specs and CSV logs, fed in-process through every parser and loader
//! of twin. Each case must end in a typed error or a result — never a panic, never a hang (a
//! watchdog aborts the process when one case takes longer than `CASE_LIMIT`), never a change to
//! the input file. The first `MIN_MUTATIONS` mutations of each input always run; more follow
//! until a fixed time budget is spent. The counts of cases and outcomes per input are printed.
//!
//! `TWIN_MUTATE_SECS` changes the budget (default 10 s: about 34,000 cases on 2 cores; CI uses the default).

use std::panic::AssertUnwindSafe;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// Mutations of each input that always run (the same ones every time), whatever the budget;
/// more follow until the budget is spent.
const MIN_MUTATIONS: u64 = 100;

/// The longest one case may take before the harness calls it a hang.
const CASE_LIMIT: Duration = Duration::from_secs(30);

fn repo(p: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(p)
}

/// The mutations depend only on the case number (the workspace's one generator, ChaCha8).
struct Rng(rand_chacha::ChaCha8Rng);
impl Rng {
    fn new(seed: u64) -> Rng {
        Rng(rand::SeedableRng::seed_from_u64(seed))
    }
    /// Uniform in `0..n` (0 when `n` is 0).
    fn below(&mut self, n: usize) -> usize {
        if n == 0 { 0 } else { rand::Rng::random_range(&mut self.0, 0..n) }
    }
}

const BAD_NUMBERS: [&str; 12] =
    ["nan", "NaN", "inf", "-inf", "1e308", "-1e308", "1e400", "0", "-0", "-1", "99999999999999999999", "0x10"];

/// Byte ranges of attribute values (`="…"`) in an XML text.
fn attribute_values(text: &[u8]) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut i = 0;
    while i + 1 < text.len() {
        if text[i] == b'=' && text[i + 1] == b'"' {
            let start = i + 2;
            if let Some(len) = text[start..].iter().position(|&b| b == b'"') {
                out.push((start, start + len));
                i = start + len;
            }
        }
        i += 1;
    }
    out
}

/// Byte ranges of numbers (digits, `.`, `-`, `e`) in a text.
fn numbers(text: &[u8]) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut i = 0;
    while i < text.len() {
        if text[i].is_ascii_digit() {
            let start = if i > 0 && text[i - 1] == b'-' { i - 1 } else { i };
            let mut end = i;
            while end < text.len() && (text[end].is_ascii_digit() || matches!(text[end], b'.' | b'e' | b'E' | b'-')) {
                end += 1;
            }
            out.push((start, end));
            i = end;
        } else {
            i += 1;
        }
    }
    out
}

/// One deterministic mutation of `valid` for case `case`; returns it and its name.
fn mutate(valid: &[u8], case: u64, text_like: bool) -> (Vec<u8>, &'static str) {
    let mut rng = Rng::new(case.wrapping_mul(0x2545_F491_4F6C_DD1D) ^ valid.len() as u64);
    let mut v = valid.to_vec();
    let kinds = if text_like { 10 } else { 5 };
    match rng.below(kinds) {
        0 => {
            v.truncate(rng.below(valid.len()));
            (v, "truncation")
        }
        1 => {
            for _ in 0..1 + rng.below(3) {
                let i = rng.below(v.len());
                v[i] ^= 1 << rng.below(8);
            }
            (v, "bit flip")
        }
        2 => {
            let i = rng.below(v.len());
            let mark: &[u8] = match rng.below(4) {
                0 => b"\xEF\xBB\xBF",
                1 => b"\xFF\xFE",
                2 => b"\xFF",
                _ => b"\0",
            };
            let at = if rng.below(2) == 0 { 0 } else { i };
            v.splice(at..at, mark.iter().copied());
            (v, "encoding mark")
        }
        3 => {
            // Overwrite a run of bytes with zeros (a hole in a file).
            let i = rng.below(v.len());
            let n = (1 + rng.below(64)).min(v.len() - i);
            v[i..i + n].fill(0);
            (v, "zeroed run")
        }
        4 => {
            // Duplicate a slice (a repeated record or element).
            let i = rng.below(v.len());
            let n = (1 + rng.below(256)).min(v.len() - i);
            let chunk = v[i..i + n].to_vec();
            v.splice(i..i, chunk);
            (v, "duplicated slice")
        }
        5 | 6 => {
            let spans = numbers(&v);
            if spans.is_empty() {
                return (v, "no number");
            }
            let (a, b) = spans[rng.below(spans.len())];
            let bad = BAD_NUMBERS[rng.below(BAD_NUMBERS.len())];
            v.splice(a..b, bad.bytes());
            (v, "bad number")
        }
        7 => {
            let spans = attribute_values(&v);
            if spans.len() < 2 {
                return (v, "no attributes");
            }
            let (x, y) = (rng.below(spans.len()), rng.below(spans.len()));
            let (first, second) = if spans[x].0 < spans[y].0 { (spans[x], spans[y]) } else { (spans[y], spans[x]) };
            if first == second {
                return (v, "attribute swap (same)");
            }
            let a = valid[first.0..first.1].to_vec();
            let b = valid[second.0..second.1].to_vec();
            v.splice(second.0..second.1, a);
            v.splice(first.0..first.1, b);
            (v, "attribute swap")
        }
        8 => {
            let lines: Vec<&[u8]> = valid.split(|&b| b == b'\n').collect();
            let k = rng.below(lines.len());
            let mut out = Vec::new();
            for (i, l) in lines.iter().enumerate() {
                if i != k {
                    out.extend_from_slice(l);
                    out.push(b'\n');
                }
            }
            (out, "deleted line")
        }
        _ => {
            let lines: Vec<&[u8]> = valid.split(|&b| b == b'\n').collect();
            let k = rng.below(lines.len());
            let mut out = Vec::new();
            for (i, l) in lines.iter().enumerate() {
                out.extend_from_slice(l);
                out.push(b'\n');
                if i == k {
                    out.extend_from_slice(l);
                    out.push(b'\n');
                }
            }
            (out, "duplicated line")
        }
    }
}

#[derive(Default)]
struct Counts {
    cases: u64,
    ok: u64,
    errors: u64,
    panics: Vec<String>,
    damaged: Vec<String>,
    slowest_ms: f64,
}

type Loader = Box<dyn Fn(&Path, &[u8]) -> Result<(), String>>;

struct Kind {
    name: &'static str,
    file_name: &'static str,
    valid: Vec<u8>,
    text_like: bool,
    loaders: Vec<(&'static str, Loader)>,
}

fn err<E: std::fmt::Display>(e: E) -> String {
    e.to_string()
}

fn kinds() -> Vec<Kind> {
    let mut kinds = Vec::new();
    let urdf_loaders = || -> Vec<(&'static str, Loader)> {
        vec![
            (
                "convert + compile",
                Box::new(|p: &Path, bytes: &[u8]| {
                    let text = std::str::from_utf8(bytes).map_err(err)?;
                    let c = twin_core::convert::convert_urdf_str(p, text, &Default::default()).map_err(err)?;
                    twin_core::mj::Model::from_xml_str(&c.mjcf).map(|_| ()).map_err(err)
                }),
            ),
            (
                "Model::from_file",
                Box::new(|p: &Path, _: &[u8]| twin_core::mj::Model::from_file(p).map(|_| ()).map_err(err)),
            ),
            (
                "sysid RobotModel",
                Box::new(|p: &Path, _: &[u8]| sysid::RobotModel::from_urdf(p).map(|_| ()).map_err(err)),
            ),
            (
                "urdf::validate",
                Box::new(|p: &Path, _: &[u8]| {
                    twin_core::fsio::read_to_string(p)
                        .map_err(err)
                        .and_then(|t| twin_core::urdf::validate(p, &t).map(|_| ()).map_err(err))
                }),
            ),
        ]
    };
    kinds.push(Kind {
        name: "URDF arm6",
        file_name: "arm6.urdf",
        valid: std::fs::read(repo("models/arm6.urdf")).unwrap(),
        text_like: true,
        loaders: urdf_loaders(),
    });
    kinds.push(Kind {
        name: "URDF humanoid",
        file_name: "humanoid.urdf",
        valid: std::fs::read(repo("models/humanoid.urdf")).unwrap(),
        text_like: true,
        loaders: urdf_loaders(),
    });
    let box_mjcf = br#"<mujoco model="box">
  <option timestep="0.002" gravity="0 0 -9.81"/>
  <worldbody>
    <geom name="floor" type="plane" size="5 5 0.1"/>
    <body name="box" pos="0 0 0.5">
      <freejoint/>
      <geom type="box" size="0.1 0.1 0.1" mass="1"/>
      <body name="arm" pos="0 0 0.2">
        <joint name="hinge" type="hinge" axis="0 1 0" range="-1 1" damping="0.1"/>
        <geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.02" mass="0.5"/>
      </body>
    </body>
  </worldbody>
  <actuator><motor joint="hinge" gear="10" ctrlrange="-1 1"/></actuator>
  <sensor><jointpos joint="hinge"/></sensor>
</mujoco>
"#;
    kinds.push(Kind {
        name: "MJCF",
        file_name: "box.xml",
        valid: box_mjcf.to_vec(),
        text_like: true,
        loaders: vec![
            (
                "Model::from_file",
                Box::new(|p: &Path, _: &[u8]| {
                    let m = twin_core::mj::Model::from_file(p).map_err(err)?;
                    // A model that loads must also step: no NaN blow-up panics.
                    let mut d = twin_core::mj::Data::new(Arc::new(m)).map_err(err)?;
                    for _ in 0..20 {
                        d.step().map_err(err)?;
                    }
                    Ok(())
                }),
            ),
            ("Robot::load", Box::new(|p: &Path, _: &[u8]| twin_core::robot::Robot::load(p).map(|_| ()).map_err(err))),
        ],
    });
    kinds.push(Kind {
        name: "bag (MCAP)",
        file_name: "log.mcap",
        valid: std::fs::read(repo("data/humanoid_joint_states.mcap")).unwrap(),
        text_like: false,
        loaders: vec![
            (
                "Log::info",
                Box::new(|p: &Path, _: &[u8]| {
                    let log = twin_core::log::Log::open(p, Default::default()).map_err(err)?;
                    log.info().map(|_| ()).map_err(err)
                }),
            ),
            (
                "Log::info strict",
                Box::new(|p: &Path, _: &[u8]| {
                    let log =
                        twin_core::log::Log::open(p, twin_core::log::ReadOptions { strict: true }).map_err(err)?;
                    log.info().map(|_| ()).map_err(err)
                }),
            ),
            (
                "joint_states",
                Box::new(|p: &Path, _: &[u8]| {
                    let log = twin_core::log::Log::open(p, Default::default()).map_err(err)?;
                    log.joint_states("/joint_states").map(|_| ()).map_err(err)
                }),
            ),
            (
                "sysid read_mcap",
                Box::new(|p: &Path, _: &[u8]| sysid::JointLog::read_mcap(p, None).map(|_| ()).map_err(err)),
            ),
            (
                "trajectory",
                Box::new(|p: &Path, _: &[u8]| {
                    twin_core::control::JointTrajectory::load(p, "/joint_states").map(|_| ()).map_err(err)
                }),
            ),
        ],
    });
    kinds.push(Kind {
        name: "randomize spec",
        file_name: "spec.toml",
        valid: randomize::Spec::default_spec().to_toml().into_bytes(),
        text_like: true,
        loaders: vec![(
            "Spec::from_file",
            Box::new(|p: &Path, _: &[u8]| randomize::Spec::from_file(p).map(|_| ()).map_err(err)),
        )],
    });
    let mut csv =
        String::from("time_sec,hip/position,hip/velocity,hip/effort,knee/position,knee/velocity,knee/effort\n");
    for i in 0..60 {
        let t = i as f64 * 0.01;
        csv.push_str(&format!(
            "{t},{},{},{},{},{},{}\n",
            (t * 3.0).sin(),
            3.0 * (t * 3.0).cos(),
            0.5 * t,
            (t * 2.0).cos(),
            -2.0 * (t * 2.0).sin(),
            -0.25
        ));
    }
    kinds.push(Kind {
        name: "sysid CSV",
        file_name: "log.csv",
        valid: csv.into_bytes(),
        text_like: true,
        loaders: vec![(
            "JointLog::read_csv",
            Box::new(|p: &Path, _: &[u8]| sysid::JointLog::read_csv(p).map(|_| ()).map_err(err)),
        )],
    });
    let mut traj = String::from("time_sec,hip,knee\n");
    for i in 0..40 {
        let t = i as f64 * 0.05;
        traj.push_str(&format!("{t},{},{}\n", (t).sin() * 0.3, -(t).sin() * 0.6));
    }
    kinds.push(Kind {
        name: "trajectory CSV",
        file_name: "traj.csv",
        valid: traj.into_bytes(),
        text_like: true,
        loaders: vec![(
            "JointTrajectory::load",
            Box::new(|p: &Path, _: &[u8]| {
                twin_core::control::JointTrajectory::load(p, "/joint_states").map(|_| ()).map_err(err)
            }),
        )],
    });
    kinds
}

#[test]
fn mutated_inputs_never_panic_hang_or_damage() {
    let budget =
        Duration::from_secs_f64(std::env::var("TWIN_MUTATE_SECS").ok().and_then(|s| s.parse().ok()).unwrap_or(10.0));
    // Panics are counted, not printed one by one.
    let hook = std::panic::take_hook();
    std::panic::set_hook(Box::new(|_| {}));

    // Watchdog: a case running longer than CASE_LIMIT is a hang; abort with its name.
    let current: Arc<Mutex<String>> = Arc::new(Mutex::new(String::new()));
    let heartbeat = Arc::new(AtomicU64::new(0));
    {
        let (current, heartbeat) = (current.clone(), heartbeat.clone());
        std::thread::spawn(move || {
            let mut last = (0, Instant::now());
            loop {
                std::thread::sleep(Duration::from_millis(200));
                let beat = heartbeat.load(Ordering::SeqCst);
                if beat == u64::MAX {
                    return;
                }
                if beat != last.0 {
                    last = (beat, Instant::now());
                } else if last.1.elapsed() > CASE_LIMIT {
                    eprintln!("HANG: {} took more than {CASE_LIMIT:?}", current.lock().unwrap());
                    std::process::abort();
                }
            }
        });
    }

    let dir = tempfile::tempdir().unwrap();
    let kinds = kinds();
    let started = Instant::now();
    let per_kind = budget / kinds.len() as u32;
    let mut report = Vec::new();
    let mut case_no = 0u64;
    for kind in &kinds {
        let mut counts = Counts::default();
        let path = dir.path().join(kind.file_name);
        // The valid input is accepted by every loader (else the harness tests nothing).
        std::fs::write(&path, &kind.valid).unwrap();
        for (name, load) in &kind.loaders {
            load(&path, &kind.valid).unwrap_or_else(|e| panic!("{}: {name} refuses the valid input: {e}", kind.name));
        }
        let kind_start = Instant::now();
        let mut n = 0u64;
        while n < MIN_MUTATIONS || kind_start.elapsed() < per_kind {
            let (bytes, how) = mutate(&kind.valid, n, kind.text_like);
            n += 1;
            std::fs::write(&path, &bytes).unwrap();
            for (name, load) in &kind.loaders {
                case_no += 1;
                *current.lock().unwrap() = format!("{} case {n} ({how}) through {name}", kind.name);
                heartbeat.store(case_no, Ordering::SeqCst);
                let t = Instant::now();
                let outcome = std::panic::catch_unwind(AssertUnwindSafe(|| load(&path, &bytes)));
                counts.slowest_ms = counts.slowest_ms.max(t.elapsed().as_secs_f64() * 1e3);
                counts.cases += 1;
                match outcome {
                    Ok(Ok(())) => counts.ok += 1,
                    Ok(Err(e)) => {
                        counts.errors += 1;
                        assert!(!e.trim().is_empty(), "{}: an error without a message", current.lock().unwrap());
                    }
                    Err(_) => counts.panics.push(current.lock().unwrap().clone()),
                }
                if std::fs::read(&path).unwrap() != bytes {
                    counts.damaged.push(current.lock().unwrap().clone());
                }
            }
        }
        report.push((kind.name, counts));
    }
    heartbeat.store(u64::MAX, Ordering::SeqCst);
    std::panic::set_hook(hook);

    let total: u64 = report.iter().map(|(_, c)| c.cases).sum();
    println!("mutation harness: {total} cases in {:.1} s", started.elapsed().as_secs_f64());
    println!(
        "{:<16} {:>7} {:>7} {:>7} {:>7} {:>7} {:>10}",
        "input", "cases", "ok", "error", "panic", "damage", "slowest ms"
    );
    for (name, c) in &report {
        println!(
            "{name:<16} {:>7} {:>7} {:>7} {:>7} {:>7} {:>10.1}",
            c.cases,
            c.ok,
            c.errors,
            c.panics.len(),
            c.damaged.len(),
            c.slowest_ms
        );
    }
    let panics: Vec<&String> = report.iter().flat_map(|(_, c)| &c.panics).collect();
    let damaged: Vec<&String> = report.iter().flat_map(|(_, c)| &c.damaged).collect();
    assert!(panics.is_empty(), "{} panics, e.g. {:?}", panics.len(), &panics[..panics.len().min(10)]);
    assert!(damaged.is_empty(), "{} inputs changed, e.g. {:?}", damaged.len(), &damaged[..damaged.len().min(10)]);
    // Every kind ran a meaningful number of cases, and some of each ended in an error: the
    // mutations reach the parsers.
    for (name, c) in &report {
        assert!(c.errors > 0, "{name}: no mutation was refused");
    }
}
