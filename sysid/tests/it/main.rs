//! sysid's integration tests, one test binary (each file a module: one link instead of one per file).

mod actuator;
#[path = "../../../twin-core/tests/it/example_robot_data.rs"]
mod example_robot_data;
mod excite;
mod floating;
mod friction;
mod gap;
mod noise;
mod real;
mod regressor;
mod synthetic;
#[path = "../../../twin-core/tests/it/test_python.rs"]
mod test_python;

/// The three seeds of a synthetic identification run (training log, held-out log, perturbed
/// start): `default`, or from the environment variable `var` ("a,b,c") to measure the spread
/// over draws (docs/src/benchmarks-notebook.md, "sysid's synthetic logs over many draws").
fn seeds(var: &str, default: [u64; 3]) -> [u64; 3] {
    match std::env::var(var) {
        Ok(v) => {
            let s: Vec<u64> = v.split(',').filter_map(|x| x.trim().parse().ok()).collect();
            assert_eq!(s.len(), 3, "{var}={v:?}: three seeds, a,b,c");
            [s[0], s[1], s[2]]
        }
        Err(_) => default,
    }
}

/// The parameters of the robot a synthetic log simulates: the URDF's, plus the armature
/// [`sysid::synth::SynthOptions`] gives every joint by default.
fn truth_params(true_robot: &sysid::RobotModel, layout: &sysid::regressor::Layout) -> Vec<f64> {
    let mut params = sysid::identify::cad_params(true_robot, layout);
    for j in 0..true_robot.joints.len() {
        params[layout.joint_col(j) + 2] = sysid::synth::SynthOptions::default().armature;
    }
    params
}
