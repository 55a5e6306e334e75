//! `nelf batch` on a real Slurm cluster: `scripts/slurm_cluster.sh` starts a
//! one-node cluster on localhost (munged, slurmctld, slurmd, all under a temp
//! folder, no systemd), a plan of small bakes with one bad capture runs as a job
//! array, and a node is lost mid-array (slurmd stopped and its job steps killed, as
//! when a machine dies): `status` lists the indices that did not finish, and
//! submitting them again completes the batch. Slurm comes from Debian's packages,
//! which `./scripts/test` installs; missing programs fail this test, naming them.

// Process groups, signals, `sh` and Slurm: Unix only (Windows is type-checked, not run).
#![cfg(unix)]
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

fn script() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("scripts/slurm_cluster.sh")
}

/// A running one-node cluster, stopped when dropped (also when the test fails).
struct Cluster {
    dir: tempfile::TempDir,
    conf: String,
}

impl Cluster {
    fn start() -> Self {
        let missing: Vec<&str> = ["munged", "slurmctld", "slurmd", "sbatch", "squeue", "scontrol"]
            .into_iter()
            .filter(|p| {
                !["/usr/bin", "/usr/sbin", "/bin", "/sbin"]
                    .iter()
                    .any(|d| Path::new(d).join(p).is_file())
            })
            .collect();
        assert!(
            missing.is_empty(),
            "Slurm is not installed (missing {}): run ./scripts/test, which installs slurmctld slurmd slurm-client munge, or scripts/slurm_cluster.sh install",
            missing.join(", ")
        );
        let dir = tempfile::tempdir().unwrap();
        let out = Command::new(script())
            .arg("start")
            .arg(dir.path())
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "the one-node cluster did not start: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        let conf = dir.path().join("etc/slurm.conf").to_string_lossy().into_owned();
        Self { dir, conf }
    }

    fn script(&self, command: &str, extra: &[&str]) {
        let out = Command::new(script())
            .arg(command)
            .arg(self.dir.path())
            .args(extra)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{command}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
    }

    /// `nelf` with this cluster's `SLURM_CONF`.
    fn nelf(&self, args: &[&str]) -> std::process::Output {
        Command::new(env!("CARGO_BIN_EXE_nelf"))
            .args(args)
            .env("SLURM_CONF", &self.conf)
            .output()
            .unwrap()
    }

    /// `nelf batch slurm PLAN --cpus 1 --mem 1G --submit` and `extra`.
    fn submit(&self, plan: &Path, extra: &[&str]) -> String {
        let mut args = vec![
            "batch",
            "slurm",
            plan.to_str().unwrap(),
            "--cpus",
            "1",
            "--mem",
            "1G",
            "--submit",
        ];
        args.extend(extra);
        self.succeed(&args)
    }

    fn succeed(&self, args: &[&str]) -> String {
        let out = self.nelf(args);
        assert!(
            out.status.success(),
            "nelf {args:?}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        String::from_utf8(out.stdout).unwrap()
    }
}

impl Drop for Cluster {
    fn drop(&mut self) {
        let _ = Command::new(script()).arg("stop").arg(self.dir.path()).output();
    }
}

/// Small bakes of the repository's head scan (`names`; `broken_capture`: a capture
/// whose cameras.json is damaged), planned in `dir/out/plan.jsonl`.
fn plan(dir: &Path, names: &[&str]) -> PathBuf {
    common::plan_small_bakes(dir, &common::batch_inputs(dir, names))
}

fn status(cluster: &Cluster, plan: &Path) -> serde_json::Value {
    serde_json::from_str(&cluster.succeed(&["batch", "status", plan.to_str().unwrap(), "--json"])).unwrap()
}

#[test]
fn a_job_array_bakes_a_plan_and_a_lost_node_loses_nothing() {
    let cluster = Cluster::start();
    let work = tempfile::tempdir().unwrap();

    // A plan with a bad capture: the array runs, the bad item fails alone.
    let first = plan(&work.path().join("one"), &["a", "b", "c", "broken_capture"]);
    let first_arg = first.to_str().unwrap();
    let printed = cluster.submit(&first, &["--wait"]);
    assert!(printed.contains("3 done, 1 failed"), "{printed}");
    let state = status(&cluster, &first);
    assert_eq!(state["resubmit"], "3");
    assert!(
        state["failures"][0][1].as_str().unwrap().contains("cameras.json"),
        "{state}"
    );
    let logs: Vec<_> = std::fs::read_dir(first.with_extension("logs")).unwrap().collect();
    assert_eq!(logs.len(), 4, "one log per array task");
    let collected = cluster.succeed(&["batch", "collect", first_arg]);
    assert!(collected.contains("3 done, 1 failed"), "{collected}");

    // A node lost while the array runs one task at a time.
    let second = plan(&work.path().join("two"), &["a", "b", "c", "d"]);
    cluster.submit(&second, &["--max-parallel", "1"]);
    let out_dir = second.parent().unwrap();
    let start = Instant::now();
    // Wait until the second item is being written, then lose the node.
    while !std::fs::read_dir(out_dir)
        .unwrap()
        .flatten()
        .any(|e| e.file_name().to_string_lossy().starts_with("b.part-"))
    {
        assert!(
            start.elapsed() < Duration::from_secs(120),
            "the array never reached its second item"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    cluster.script("stop-node", &["--kill-jobs"]);
    // The operator gives up on the array (instead of waiting for Slurm's requeue).
    let cancelled = Command::new("scancel")
        .args(["--name", "nelf-plan"])
        .env("SLURM_CONF", &cluster.conf)
        .status();
    assert!(cancelled.unwrap().success());
    let state = status(&cluster, &second);
    assert_eq!(state["done"], 1, "{state}");
    assert_eq!(state["resubmit"], "1-3", "{state}");
    assert!(!out_dir.join("b").exists(), "no partial output at the final path");
    assert_eq!(
        state["staging"].as_array().unwrap().len(),
        1,
        "the killed task's staging folder is listed: {state}"
    );
    let a_record = std::fs::read(second.with_extension("results").join("a.json")).unwrap();

    // The node comes back; the indices status printed are submitted again.
    cluster.script("start-node", &[]);
    let printed = cluster.submit(&second, &["--indices", "1-3", "--wait"]);
    assert!(
        printed.contains("4 done, 0 failed") && printed.contains("all done"),
        "{printed}"
    );
    assert!(
        status(&cluster, &second)["staging"]
            .as_array()
            .unwrap()
            .is_empty()
    );
    assert_eq!(
        std::fs::read(second.with_extension("results").join("a.json")).unwrap(),
        a_record
    );
}
