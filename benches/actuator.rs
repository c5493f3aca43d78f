//! The cost of the drive models per physics step: the shipped humanoid with ideal motors (as
//! shipped), with a 10 ms command delay on every actuator (MuJoCo's actuator `delay`, history
//! buffers), with a DC-motor torque–speed envelope on every actuator (`dcmotor`: stall torque
//! 1.5 × the URDF effort, no-load speed 1.2 × its velocity limit), and with both; each stepped
//! by a plain C loop of `mj_step` and by twin's `Data::step`.
//!
//!     cargo bench --bench actuator -- [--steps N] [--reps R]
//!
//! Every variant starts from the same state with zero commands (the robot falls the same way in
//! all four: a zero torque is zero through delay and envelope alike, so the contacts cost the
//! same), repetitions alternate between variants so machine noise hits all alike, and the
//! medians are compared with the ideal motor's C loop.

use std::collections::BTreeMap;
use std::sync::Arc;
use std::time::Instant;
use twin_core::convert::{ConvertOptions, actuator::DriveModel};
use twin_core::mj::{Data, Model, bench_c_step_loop};

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() {
    let (mut steps, mut reps) = (20_000u64, 9usize);
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--steps" => steps = args.next().and_then(|v| v.parse().ok()).expect("--steps N"),
            "--reps" => reps = args.next().and_then(|v| v.parse().ok()).expect("--reps R"),
            _ => {}
        }
    }
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/models/humanoid.urdf");
    let ideal = twin_core::convert::load(path.as_ref(), &ConvertOptions::default(), "").expect("humanoid converts");
    let meta = ideal.converted.as_ref().expect("a URDF").meta.clone();
    let drives = |delay: bool, envelope: bool| -> BTreeMap<String, DriveModel> {
        meta.joints
            .iter()
            .filter(|j| j.actuator.is_some())
            .map(|j| {
                let m = DriveModel {
                    joint: j.name.clone(),
                    delay_secs: if delay { 0.01 } else { 0.0 },
                    stall_torque: envelope.then(|| j.effort_limit.unwrap_or(100.0) * 1.5),
                    no_load_speed: envelope.then(|| j.velocity_limit.unwrap_or(10.0) * 1.2),
                    ..DriveModel::default()
                };
                (j.name.clone(), m)
            })
            .collect()
    };
    let variant = |delay, envelope| {
        let opts = ConvertOptions { joint_drive: drives(delay, envelope), ..ConvertOptions::default() };
        twin_core::convert::load(path.as_ref(), &opts, "").expect("converts").model
    };
    let variants: Vec<(&str, Model)> = vec![
        ("ideal motor (as shipped)", ideal.model),
        ("10 ms delay, every actuator", variant(true, false)),
        ("DC-motor envelope, every actuator", variant(false, true)),
        ("delay + DC motor, every actuator", variant(true, true)),
    ];
    let mut datas: Vec<Data> =
        variants.iter().map(|(_, m)| Data::new(Arc::new(m.try_clone().unwrap())).unwrap()).collect();
    for d in &mut datas {
        bench_c_step_loop(d, steps / 4);
        d.reset().unwrap();
    }
    let mut c_times = vec![Vec::new(); variants.len()];
    let mut rust_times = vec![Vec::new(); variants.len()];
    let mut ends = vec![Vec::new(); variants.len()];
    for _ in 0..reps {
        for (i, d) in datas.iter_mut().enumerate() {
            d.reset().unwrap();
            let t = Instant::now();
            bench_c_step_loop(d, steps);
            c_times[i].push(t.elapsed().as_secs_f64() / steps as f64);
            d.reset().unwrap();
            let t = Instant::now();
            for _ in 0..steps {
                d.step().unwrap();
            }
            rust_times[i].push(t.elapsed().as_secs_f64() / steps as f64);
            ends[i] = d.qpos().to_vec();
        }
    }
    let base = median(c_times[0].clone());
    println!(
        "| humanoid ({} actuators), {steps} steps × {reps} | C mj_step loop (µs/step) | vs ideal C | twin Data::step (µs/step) | vs ideal C |",
        variants[0].1.nu()
    );
    println!("|---|---|---|---|---|");
    for (i, (name, m)) in variants.iter().enumerate() {
        let (c, r) = (median(c_times[i].clone()), median(rust_times[i].clone()));
        let diverged = ends[i].iter().zip(&ends[0]).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
        println!(
            "| {name} (nhistory {}, max |Δqpos| vs ideal {diverged:.1e}) | {:.3} | {:+.2} % | {:.3} | {:+.2} % |",
            m.raw().nhistory,
            c * 1e6,
            (c / base - 1.0) * 100.0,
            r * 1e6,
            (r / base - 1.0) * 100.0
        );
    }
}
