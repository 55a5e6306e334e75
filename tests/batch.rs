//! `nelf batch` end to end with the real command: a batch's outputs equal the same
//! commands run one by one; the faults that must lose nothing (a runner killed with
//! its item mid-write, two runs of one index at once, a bad capture among good ones,
//! a manifest edited after planning or damaged); `nelf train data` through shards
//! equal to one process. The same plan on a real one-node Slurm cluster is in
//! `tests/batch_slurm.rs`.

// Process groups, signals, `sh` and Slurm: Unix only (Windows is type-checked, not run).
#![cfg(unix)]
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

use common::{nelf, succeed};

/// Two copies of the repository's head scan, a capture folder whose cameras.json is
/// damaged, a third copy; in plan order.
fn inputs(dir: &Path) -> Vec<PathBuf> {
    common::batch_inputs(dir, &["a", "b", "broken_capture", "c"])
}

fn plan_bakes(dir: &Path, inputs: &[PathBuf]) -> PathBuf {
    common::plan_small_bakes(dir, inputs)
}

/// A JSON file with every `*_secs` number (measured time) removed.
fn without_timings(value: &mut serde_json::Value) {
    match value {
        serde_json::Value::Object(map) => {
            map.retain(|k, _| !k.ends_with("_secs"));
            map.values_mut().for_each(without_timings);
        }
        serde_json::Value::Array(items) => items.iter_mut().for_each(without_timings),
        _ => {}
    }
}

/// Asserts that two folders hold the same files: byte for byte, except JSON records
/// whose measured seconds differ.
fn assert_same_files(a: &Path, b: &Path) {
    let list = |dir: &Path| {
        let mut out = Vec::new();
        let mut stack = vec![dir.to_path_buf()];
        while let Some(d) = stack.pop() {
            for e in std::fs::read_dir(&d).unwrap() {
                let p = e.unwrap().path();
                if p.is_dir() {
                    stack.push(p);
                } else {
                    out.push(p.strip_prefix(dir).unwrap().to_path_buf());
                }
            }
        }
        out.sort();
        out
    };
    let files = list(a);
    assert_eq!(
        files,
        list(b),
        "{} and {} hold different files",
        a.display(),
        b.display()
    );
    assert!(!files.is_empty());
    for file in files {
        let (x, y) = (
            std::fs::read(a.join(&file)).unwrap(),
            std::fs::read(b.join(&file)).unwrap(),
        );
        if x == y {
            continue;
        }
        assert!(
            file.extension().is_some_and(|e| e == "json"),
            "{} differs",
            file.display()
        );
        let mut x: serde_json::Value = serde_json::from_slice(&x).unwrap();
        let mut y: serde_json::Value = serde_json::from_slice(&y).unwrap();
        without_timings(&mut x);
        without_timings(&mut y);
        assert_eq!(x, y, "{} differs beyond its timings", file.display());
    }
}

fn status_json(plan: &Path) -> serde_json::Value {
    serde_json::from_str(&succeed(&["batch", "status", plan.to_str().unwrap(), "--json"])).unwrap()
}

#[test]
fn a_batch_equals_its_commands_one_by_one_and_a_bad_capture_fails_alone() {
    let dir = tempfile::tempdir().unwrap();
    let inputs = inputs(dir.path());
    let plan = plan_bakes(dir.path(), &inputs);
    let out = nelf(&["batch", "local", plan.to_str().unwrap(), "-j", "2", "--quiet"]);
    assert!(!out.status.success(), "a failed item fails the batch");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("3 done, 0 already done, 1 failed"), "{stdout}");
    let status = status_json(&plan);
    assert_eq!(status["done"], 3);
    assert_eq!(status["failed"], 1);
    assert_eq!(status["resubmit"], "2");
    let failure = status["failures"][0][1].as_str().unwrap();
    assert!(
        failure.contains("cameras.json"),
        "the capture's own error: {failure}"
    );
    assert!(!dir.path().join("out/broken_capture").exists());
    let collected = succeed(&["batch", "collect", plan.to_str().unwrap()]);
    assert!(collected.contains("3 done, 1 failed"), "{collected}");
    let csv = std::fs::read_to_string(plan.with_extension("results.csv")).unwrap();
    assert!(
        csv.lines().next().unwrap().contains("file_size"),
        "figures become columns: {csv}"
    );
    assert!(
        csv.lines().any(|l| l.starts_with("broken_capture,bake,failed,")),
        "{csv}"
    );

    // The same items as plain commands, one by one, writing the same paths after the
    // batch's outputs are moved aside.
    let direct = succeed(&["batch", "commands", plan.to_str().unwrap(), "--direct"]);
    let lines: Vec<&str> = direct.lines().collect();
    assert_eq!(lines.len(), 4);
    let batched = dir.path().join("batched");
    std::fs::create_dir_all(&batched).unwrap();
    for name in ["a", "b", "c"] {
        std::fs::rename(dir.path().join("out").join(name), batched.join(name)).unwrap();
    }
    for (line, name) in lines.iter().zip(["a", "b", "broken_capture", "c"]) {
        std::fs::create_dir_all(dir.path().join("out").join(name)).unwrap();
        let ran = Command::new("sh").args(["-c", line]).output().unwrap();
        assert_eq!(ran.status.success(), name != "broken_capture", "{line}");
    }
    for name in ["a", "b", "c"] {
        assert_same_files(&batched.join(name), &dir.path().join("out").join(name));
    }
    std::fs::remove_dir_all(dir.path().join("out/broken_capture")).unwrap();
    for name in ["a", "b", "c"] {
        std::fs::remove_dir_all(dir.path().join("out").join(name)).unwrap();
        std::fs::rename(batched.join(name), dir.path().join("out").join(name)).unwrap();
    }
    // Rerunning skips what is done and fails the bad item again, alone.
    let again = nelf(&["batch", "local", plan.to_str().unwrap(), "--quiet"]);
    assert!(String::from_utf8_lossy(&again.stdout).contains("0 done, 3 already done, 1 failed"));
}

/// Waits until `dir` holds an entry whose name contains `part`.
fn wait_for_staging(dir: &Path, timeout: Duration) -> bool {
    let start = Instant::now();
    while start.elapsed() < timeout {
        if std::fs::read_dir(dir).is_ok_and(|entries| {
            entries
                .flatten()
                .any(|e| e.file_name().to_string_lossy().contains(".part-"))
        }) {
            return true;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    false
}

#[test]
fn a_killed_runner_loses_nothing_and_two_runs_of_one_index_agree() {
    let dir = tempfile::tempdir().unwrap();
    let inputs = inputs(dir.path());
    let plan = plan_bakes(dir.path(), &inputs);
    let plan_arg = plan.to_str().unwrap();
    succeed(&["batch", "run", plan_arg, "--index", "0"]);
    let a = dir.path().join("out/a");
    let a_record = std::fs::read(plan.with_extension("results").join("a.json")).unwrap();

    // Index 1 killed with SIGKILL, runner and item together (as Slurm kills a task).
    let mut runner = {
        use std::os::unix::process::CommandExt;
        Command::new(env!("CARGO_BIN_EXE_nelf"))
            .args(["batch", "run", plan_arg, "--index", "1"])
            .process_group(0)
            .stderr(std::process::Stdio::null())
            .spawn()
            .unwrap()
    };
    assert!(wait_for_staging(&dir.path().join("out"), Duration::from_secs(20)));
    std::thread::sleep(Duration::from_millis(300));
    let group = format!("-{}", runner.id());
    assert!(
        Command::new("kill")
            .args(["-9", "--", &group])
            .status()
            .unwrap()
            .success()
    );
    runner.wait().unwrap();
    let b = dir.path().join("out/b");
    assert!(!b.exists(), "no partial output at the final path");
    let status = status_json(&plan);
    assert_eq!(status["states"][1][1], "missing");
    assert_eq!(status["staging"].as_array().unwrap().len(), 1, "{status}");

    // The rerun clears the killed run's staging folder and completes the item; item a
    // is untouched.
    succeed(&["batch", "run", plan_arg, "--index", "1"]);
    assert!(b.join("asset.nelf").is_file());
    assert_eq!(
        std::fs::read(plan.with_extension("results").join("a.json")).unwrap(),
        a_record
    );
    assert!(status_json(&plan)["staging"].as_array().unwrap().is_empty());

    // Two runs of index 3 at once: both finish, and the output is whole: the files the
    // record lists (the last run to finish wrote it), the asset byte for byte (the
    // JSON sidecar differs between runs in its measured seconds only).
    let spawn = || {
        Command::new(env!("CARGO_BIN_EXE_nelf"))
            .args(["batch", "run", plan_arg, "--index", "3", "--force"])
            .stderr(std::process::Stdio::null())
            .spawn()
            .unwrap()
    };
    let (mut first, mut second) = (spawn(), spawn());
    assert!(first.wait().unwrap().success() && second.wait().unwrap().success());
    let record: serde_json::Value =
        serde_json::from_slice(&std::fs::read(plan.with_extension("results").join("c.json")).unwrap())
            .unwrap();
    let c = dir.path().join("out/c");
    let listed = record["outputs"].as_array().unwrap();
    assert_eq!(listed.len(), std::fs::read_dir(&c).unwrap().count());
    for file in listed {
        let name = file["path"].as_str().unwrap();
        let bytes = std::fs::read(c.join(name)).unwrap();
        if Path::new(name).extension().is_none_or(|e| e != "json") {
            assert_eq!(bytes.len() as u64, file["bytes"].as_u64().unwrap(), "{name}");
        }
    }
    succeed(&["inspect", c.join("asset.nelf").to_str().unwrap()]);
    assert!(status_json(&plan)["staging"].as_array().unwrap().is_empty());
    assert!(a.join("asset.nelf").is_file());
}

#[test]
fn an_edited_manifest_reruns_what_changed_and_a_damaged_one_names_its_line() {
    let dir = tempfile::tempdir().unwrap();
    let inputs = inputs(dir.path());
    let plan = plan_bakes(dir.path(), &[inputs[0].clone(), inputs[1].clone()]);
    let plan_arg = plan.to_str().unwrap();
    succeed(&["batch", "local", plan_arg, "--quiet"]);
    let text = std::fs::read_to_string(&plan).unwrap();
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    // Item b (line 3) at another resolution.
    lines[2] = lines[2].replace(r#""--resolution","16""#, r#""--resolution","20""#);
    assert!(lines[2].contains(r#""20""#));
    std::fs::write(&plan, lines.join("\n") + "\n").unwrap();
    let status = status_json(&plan);
    assert_eq!(
        (status["done"].as_u64(), status["changed"].as_u64()),
        (Some(1), Some(1))
    );
    assert_eq!(status["resubmit"], "1");
    let rerun = succeed(&["batch", "local", plan_arg, "--quiet"]);
    assert!(rerun.contains("1 done, 1 already done, 0 failed"), "{rerun}");
    let sidecar = std::fs::read_to_string(dir.path().join("out/b/asset.bake.json")).unwrap();
    assert!(
        sidecar.contains("\"resolution\": 20"),
        "the edited setting was baked"
    );

    lines[2] = "{\"id\": \"b\", \"kind\"".into();
    std::fs::write(&plan, lines.join("\n") + "\n").unwrap();
    let out = nelf(&["batch", "status", plan_arg]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && stderr.contains("line 3") && stderr.contains("plan.jsonl"),
        "{stderr}"
    );
}

#[test]
fn training_data_in_shards_equals_one_process() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    let root = env!("CARGO_MANIFEST_DIR");
    let common = ["--size", "16", "--heads", "3", "--val-heads", "2"];
    let mut single = vec!["train", "data", "--out", data.to_str().unwrap(), "--quiet"];
    single.extend(common);
    let out = Command::new(env!("CARGO_BIN_EXE_nelf"))
        .args(&single)
        .current_dir(root)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let whole = dir.path().join("whole");
    std::fs::rename(&data, &whole).unwrap();

    let plan = dir.path().join("plan.jsonl");
    let out = Command::new(env!("CARGO_BIN_EXE_nelf"))
        .args([
            "batch",
            "plan",
            "train-data",
            "--out",
            data.to_str().unwrap(),
            "--heads",
            "3",
            "--val-heads",
            "2",
        ])
        .args([
            "--shard",
            "2",
            "--plan",
            plan.to_str().unwrap(),
            "--",
            "--size",
            "16",
        ])
        .current_dir(root)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    // Run from elsewhere: items run in the folder the plan was made in.
    let ran = Command::new(env!("CARGO_BIN_EXE_nelf"))
        .args(["batch", "local", plan.to_str().unwrap(), "-j", "2", "--quiet"])
        .current_dir(dir.path())
        .output()
        .unwrap();
    assert!(ran.status.success(), "{}", String::from_utf8_lossy(&ran.stdout));
    assert_same_files(&whole, &data);
}

/// The rows of a CSV without the named (measured-time) columns.
fn csv_without(path: &Path, skip: &[&str]) -> Vec<Vec<String>> {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let keep: Vec<usize> = (0..header.len())
        .filter(|i| !skip.contains(&header[*i]))
        .collect();
    std::iter::once(header.iter().map(|s| (*s).to_string()).collect::<Vec<_>>())
        .chain(lines.map(|l| l.split(',').map(str::to_string).collect()))
        .map(|row| keep.iter().map(|i| row[*i].clone()).collect())
        .collect()
}

#[test]
fn sweeps_run_in_parts_merge_into_the_report_one_machine_writes() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path();
    // Pareto: one grid resolution per item.
    let single = root.join("pareto_single");
    succeed(&[
        "eval",
        "pareto",
        "--quick",
        "--no-gpu",
        "--quiet",
        "--out",
        single.to_str().unwrap(),
    ]);
    let parts = root.join("pareto_parts");
    let out = parts.to_str().unwrap();
    succeed(&[
        "batch",
        "plan",
        "pareto",
        "head:0",
        "--out",
        out,
        "--resolutions",
        "24,40",
        "--",
        "--quick",
        "--no-gpu",
    ]);
    let plan = parts.join("plan.jsonl");
    succeed(&["batch", "local", plan.to_str().unwrap(), "-j", "2", "--quiet"]);
    let printed = succeed(&["batch", "collect", plan.to_str().unwrap()]);
    assert!(printed.contains("pareto report of 2 of 2 parts"), "{printed}");
    assert!(parts.join("report/report.html").is_file());
    let timings = ["bake_secs", "cpu_render_ms", "front_frame"];
    assert_eq!(
        csv_without(&parts.join("report/results.csv"), &timings),
        csv_without(&single.join("results.csv"), &timings)
    );

    // Stability: one axis per item.
    let small = ["--quick", "--image-size", "32", "--resolution", "16"];
    let single = root.join("stability_single");
    let mut args = vec![
        "eval",
        "stability",
        "head:0",
        "--axes",
        "rank,sun_radius_deg",
        "--quiet",
    ];
    args.extend(["--out", single.to_str().unwrap()]);
    args.extend(small);
    succeed(&args);
    let parts = root.join("stability_parts");
    let mut args = vec![
        "batch",
        "plan",
        "stability",
        "head:0",
        "--out",
        parts.to_str().unwrap(),
    ];
    args.extend(["--axes", "rank,sun_radius_deg", "--"]);
    args.extend(small);
    succeed(&args);
    let plan = parts.join("plan.jsonl");
    succeed(&["batch", "local", plan.to_str().unwrap(), "-j", "2", "--quiet"]);
    let printed = succeed(&["batch", "collect", plan.to_str().unwrap()]);
    assert!(printed.contains("stability report of 2 of 2 parts"), "{printed}");
    assert_eq!(
        std::fs::read_to_string(parts.join("report/stability.csv")).unwrap(),
        std::fs::read_to_string(single.join("stability.csv")).unwrap()
    );
    let bad = nelf(&[
        "batch",
        "plan",
        "stability",
        "head:0",
        "--out",
        out,
        "--axes",
        "rank,no_such_axis",
    ]);
    assert!(String::from_utf8_lossy(&bad.stderr).contains("unknown axis \"no_such_axis\""));
}

#[test]
fn a_reader_that_stops_early_ends_the_listing_quietly() {
    let dir = tempfile::tempdir().unwrap();
    let list = dir.path().join("list.csv");
    let paths = (0..5000)
        .map(|i| format!("/shared/captures/person{i:05}"))
        .collect::<Vec<_>>()
        .join("\n");
    std::fs::write(&list, paths).unwrap();
    let out = dir.path().join("out");
    succeed(&[
        "batch",
        "plan",
        "bake",
        "--list",
        list.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    let plan = out.join("plan.jsonl");
    for what in [&["commands", "--direct"][..], &["status"][..]] {
        let mut child = Command::new(env!("CARGO_BIN_EXE_nelf"))
            .arg("batch")
            .arg(what[0])
            .arg(&plan)
            .args(&what[1..])
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        // Read one line, then go away (as `| head -1` does).
        let mut first = String::new();
        std::io::BufRead::read_line(
            &mut std::io::BufReader::new(child.stdout.take().unwrap()),
            &mut first,
        )
        .unwrap();
        assert!(!first.is_empty());
        let done = child.wait_with_output().unwrap();
        let stderr = String::from_utf8_lossy(&done.stderr);
        assert!(
            done.status.success() && !stderr.contains("panicked"),
            "{what:?}: {stderr}"
        );
    }
}
