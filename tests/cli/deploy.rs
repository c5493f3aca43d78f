//! The deployment files in `deploy/`: the Kubernetes manifests are valid YAML that fit together
//! (parsed by PyYAML from `TWIN_PYTHON`, default `python3`: the test fails when it is missing),
//! and the commands the manifests and the Slurm scripts run, run here with the environment the
//! scheduler would give them, reproduce the single-machine batch byte for byte. The scripts on
//! a real Slurm: `.ci/slurm-test`.

use crate::common::{output_of, repo_root, run};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;

fn fixture() -> String {
    repo_root().join("randomize/tests/fixtures/humanoid.xml").display().to_string()
}

/// The folder of the `twin` binary under test, for PATH (the manifests call `twin`).
fn path_with_twin() -> String {
    let bin = PathBuf::from(env!("CARGO_BIN_EXE_twin"));
    format!("{}:{}", bin.parent().unwrap().display(), std::env::var("PATH").unwrap_or_default())
}

/// Every YAML document of `file` as JSON, parsed by PyYAML.
fn yaml_documents(file: &Path) -> Vec<Value> {
    let python = crate::test_python::python();
    let out = Command::new(&python)
        .args(["-c", "import json, sys, yaml; print(json.dumps(list(yaml.safe_load_all(open(sys.argv[1])))))"])
        .arg(file)
        .output()
        .unwrap_or_else(|e| panic!("cannot run {}: {e}", python.display()));
    assert!(
        out.status.success(),
        "{} is not valid YAML (parsed by PyYAML in {}): {}",
        file.display(),
        python.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap()
}

fn run_ok(cmd: &mut Command) -> String {
    let (success, stdout, stderr) = output_of(cmd.output().unwrap());
    assert!(success, "{cmd:?} failed:\n{stdout}\n{stderr}");
    stdout
}

/// Runs `twin randomize FIXTURE ARGS` on one machine (into `dir/single`) and asserts that the
/// merge of the shards printed its summary (`merged` ends with it) and wrote the same files
/// into `out/all`.
fn same_as_one_machine(dir: &Path, args: &[&str], merged: &str, out: &Path) {
    let (model, single) = (fixture(), dir.join("single"));
    let single_arg = single.display().to_string();
    let (success, whole, stderr) = run(&[&["randomize", model.as_str()], args, &["--out", &single_arg]].concat());
    assert!(success, "{stderr}");
    assert!(merged.ends_with(&whole), "merge prints the single-machine summary:\n{merged}\nvs\n{whole}");
    same_outputs(&single, &out.join("all"));
}

fn same_outputs(single: &Path, merged: &Path) {
    for file in ["episodes.csv", "summary.json", "spec.toml"] {
        let (a, b) = (std::fs::read(single.join(file)).unwrap(), std::fs::read(merged.join(file)).unwrap());
        assert!(a == b, "{file}: merged shards differ from the single-machine run");
    }
}

/// The shell command a Job's container runs (`command: [/bin/sh, -c]`, `args: [SCRIPT]`), and
/// the container.
fn job_script(job: &Value) -> (String, &Value) {
    let container = &job["spec"]["template"]["spec"]["containers"][0];
    assert_eq!(container["command"], serde_json::json!(["/bin/sh", "-c"]));
    (container["args"][0].as_str().unwrap().to_string(), container)
}

#[test]
fn kubernetes_manifests_are_valid_and_their_commands_reproduce_one_machine() {
    let k8s = repo_root().join("deploy/k8s");
    let params = yaml_documents(&k8s.join("params.yaml"));
    let job = yaml_documents(&k8s.join("randomize-job.yaml"));
    let merge = yaml_documents(&k8s.join("merge-job.yaml"));
    let (params, job, merge) = (&params[0], &job[0], &merge[0]);
    assert_eq!(params["kind"], "ConfigMap");
    let config = params["metadata"]["name"].as_str().unwrap();
    let data = params["data"].as_object().unwrap();
    for key in ["TWIN_MODEL", "TWIN_SPEC", "TWIN_EPISODES", "TWIN_SEED", "TWIN_SHARDS", "TWIN_THREADS", "TWIN_OUT"] {
        assert!(data[key].is_string(), "params.yaml: {key} must be a string (ConfigMap values are)");
    }
    let shards: u64 = data["TWIN_SHARDS"].as_str().unwrap().parse().unwrap();
    for (name, doc) in [("randomize-job.yaml", job), ("merge-job.yaml", merge)] {
        assert_eq!((doc["apiVersion"].as_str(), doc["kind"].as_str()), (Some("batch/v1"), Some("Job")), "{name}");
        let pod = &doc["spec"]["template"]["spec"];
        assert_eq!(pod["restartPolicy"], "Never", "{name}");
        let (_, container) = job_script(doc);
        assert_eq!(container["envFrom"][0]["configMapRef"]["name"], config, "{name}: parameters from params.yaml");
        let mount = &container["volumeMounts"][0];
        assert_eq!(pod["volumes"][0]["name"], mount["name"], "{name}: the mounted volume is declared");
        let out = data["TWIN_OUT"].as_str().unwrap();
        assert!(out.starts_with(mount["mountPath"].as_str().unwrap()), "{name}: TWIN_OUT is on the shared volume");
    }
    assert_eq!(job["spec"]["completionMode"], "Indexed");
    assert_eq!(job["spec"]["completions"].as_u64(), Some(shards), "completions = TWIN_SHARDS");
    assert!(job["spec"]["parallelism"].as_u64().unwrap() <= shards);
    let threads = data["TWIN_THREADS"].as_str().unwrap();
    let (_, container) = job_script(job);
    assert_eq!(container["resources"]["requests"]["cpu"].as_str(), Some(threads), "cpu request = TWIN_THREADS");

    // The containers' commands, run here: every index of the Indexed Job, then the merge Job.
    let dir = tempfile::tempdir().unwrap();
    let spec = dir.path().join("spec.toml");
    std::fs::write(&spec, run_ok(crate::common::twin().args(["randomize", "--print-config"]))).unwrap();
    let out = dir.path().join("runs");
    let env = [
        ("TWIN_MODEL", fixture()),
        ("TWIN_SPEC", spec.display().to_string()),
        ("TWIN_EPISODES", "9".into()),
        ("TWIN_SEED", "11".into()),
        ("TWIN_SHARDS", "3".into()),
        ("TWIN_THREADS", "1".into()),
        ("TWIN_OUT", out.display().to_string()),
        ("PATH", path_with_twin()),
    ];
    let sh = |script: &str| {
        let mut c = Command::new("/bin/sh");
        c.arg("-c").arg(script).current_dir(dir.path()).envs(env.iter().map(|(k, v)| (k, v)));
        c
    };
    let (shard_script, _) = job_script(job);
    for index in 0..3 {
        run_ok(sh(&shard_script).env("JOB_COMPLETION_INDEX", index.to_string()));
    }
    let (merge_script, _) = job_script(merge);
    let merged = run_ok(&mut sh(&merge_script));
    assert!(merged.contains("total: 9/9 episodes") && merged.contains("episodes: 9 of 9"), "{merged}");
    let spec = spec.display().to_string();
    same_as_one_machine(dir.path(), &["--config", &spec, "--episodes", "9", "--seed", "11"], &merged, &out);
}

#[test]
fn slurm_scripts_reproduce_one_machine_and_name_a_missing_shard() {
    let slurm = repo_root().join("deploy/slurm");
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("runs");
    let twin = env!("CARGO_BIN_EXE_twin");
    let env = [
        ("TWIN", twin.to_string()),
        ("TWIN_MODEL", fixture()),
        ("TWIN_EPISODES", "8".to_string()),
        ("TWIN_SEED", "4".into()),
        ("TWIN_SHARDS", "4".into()),
        ("TWIN_DURATION", "0.3".into()),
        ("TWIN_OUT", out.display().to_string()),
        ("TWIN_SUBMIT", "deploy/slurm/submit".into()),
    ];
    // What sbatch gives each array task: its index and CPUs.
    let task = |script: &str, index: Option<u64>| {
        let mut c = Command::new("bash");
        c.arg(slurm.join(script)).current_dir(dir.path()).envs(env.iter().map(|(k, v)| (k, v)));
        if let Some(i) = index {
            c.env("SLURM_ARRAY_TASK_ID", i.to_string()).env("SLURM_CPUS_PER_TASK", "1");
        }
        output_of(c.output().unwrap())
    };
    for i in [0, 1, 3] {
        let (success, _, stderr) = task("randomize.sbatch", Some(i));
        assert!(success, "{stderr}");
    }
    let (success, stdout, stderr) = task("merge.sbatch", None);
    assert!(!success, "merge of 3 of 4 shards must fail");
    assert!(stdout.contains("total: 6/8 episodes"), "{stdout}");
    assert!(stderr.contains("shard 3/4 is missing") && stderr.contains("--shard 3/4"), "{stderr}");
    assert!(stderr.contains(&format!("--out {}", out.join("shard-3").display())), "{stderr}");
    assert!(stderr.contains("deploy/slurm/submit --out") && stderr.contains("--only 3"), "{stderr}");
    assert!(!out.join("all").exists());

    let (success, _, stderr) = task("randomize.sbatch", Some(2));
    assert!(success, "{stderr}");
    let (success, merged, stderr) = task("merge.sbatch", None);
    assert!(success, "{stderr}");
    same_as_one_machine(dir.path(), &["--episodes", "8", "--seed", "4", "--duration", "0.3"], &merged, &out);

    // Outside an array the script says how to submit it.
    let (success, _, stderr) = task("randomize.sbatch", None);
    assert!(!success && stderr.contains("--array"), "{stderr}");
}
