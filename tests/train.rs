//! End-to-end test of `nelf train`: a tiny dataset is rendered, a tiny network is
//! trained on it for a few steps and resumed, and its exported weights bake a
//! held-out head with `nelf bake capture --weights` (the widths are read from the
//! weights file). Minutes of training say nothing about accuracy; this checks that
//! the pieces fit.

#![allow(clippy::unwrap_used)] // Test helpers outside #[test] functions unwrap too.

mod common;

use common::{nelf, succeed};
use nelf_format::read_asset;

#[test]
fn train_data_run_resume_and_bake_with_the_weights() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    let run = dir.path().join("run");
    let d = data.to_str().unwrap();
    let r = run.to_str().unwrap();
    let out = succeed(&[
        "train",
        "data",
        "-o",
        d,
        "--heads",
        "2",
        "--val-heads",
        "1",
        "--size",
        "32",
        "--distill-points",
        "64",
        "--texel-samples",
        "1",
        "--indirect-samples",
        "4",
        "--bounces",
        "1",
    ]);
    assert!(out.contains("3 heads written"), "{out}");
    let train_args = |steps: &str, extra: &[&str]| -> Vec<String> {
        let mut args = vec![
            "train",
            "run",
            "--data",
            d,
            "-o",
            r,
            "--arch",
            "tiny",
            "--image-size",
            "32",
            "--rays",
            "32",
            "--coarse-samples",
            "8",
            "--fine-samples",
            "4",
            "--steps",
            steps,
            "--val-every",
            "2",
            "--val-heads",
            "1",
            "--distill-weight",
            "0.1",
        ];
        args.extend_from_slice(extra);
        args.into_iter().map(String::from).collect()
    };
    let train = |steps: &str, extra: &[&str]| {
        let args = train_args(steps, extra);
        succeed(&args.iter().map(String::as_str).collect::<Vec<_>>())
    };
    let first = train("2", &[]);
    assert!(first.contains("step 2 (2 now"), "{first}");
    assert!(run.join("curve.svg").is_file() && run.join("validation.csv").is_file());
    // Validation stands beside the flat-colour baseline of the same views.
    let log = std::fs::read_to_string(run.join("validation.csv")).unwrap();
    let last: Vec<f64> = log
        .lines()
        .last()
        .unwrap()
        .split(',')
        .map(|f| f.parse().unwrap())
        .collect();
    assert_eq!(last.len(), 8, "{log}");
    assert!(last[4..].iter().all(|db| db.is_finite() && *db > 3.0), "{log}");
    let resumed = train("3", &[]);
    assert!(resumed.contains("step 3 (1 now"), "{resumed}");
    // The network as a run ends is validated even off the --val-every grid.
    let log = std::fs::read_to_string(run.join("validation.csv")).unwrap();
    assert!(log.lines().last().unwrap().starts_with("3,"), "{log}");
    // Another width cannot continue this checkpoint.
    let refused = nelf(&[
        "train",
        "run",
        "--data",
        d,
        "-o",
        r,
        "--arch",
        "small",
        "--image-size",
        "32",
        "--steps",
        "4",
    ]);
    assert!(!refused.status.success());
    assert!(String::from_utf8_lossy(&refused.stderr).contains("checkpoint.json"));

    // The domain-adaptation hook continues the checkpoint with a folder of real
    // portraits (its decoder head starts afresh); a missing folder is named.
    let portraits = dir.path().join("portraits");
    std::fs::create_dir(&portraits).unwrap();
    let photo = concat!(env!("CARGO_MANIFEST_DIR"), "/data/metrics/astronaut.png");
    std::fs::copy(photo, portraits.join("astronaut.png")).unwrap_or_else(|e| panic!("{photo}: {e}"));
    let hooked = train("4", &["--real-images", portraits.to_str().unwrap()]);
    assert!(hooked.contains("step 4 (1 now"), "{hooked}");
    let saved = std::fs::read_to_string(run.join("train_config.json")).unwrap();
    assert!(
        saved.contains("\"real_images\"") && saved.contains("portraits"),
        "{saved}"
    );
    let nowhere = dir.path().join("nowhere");
    let args = train_args("5", &["--real-images", nowhere.to_str().unwrap()]);
    let refused = nelf(&args.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(!refused.status.success());
    assert!(String::from_utf8_lossy(&refused.stderr).contains("nowhere"));

    // The exported weights (with the hook's head, which inference ignores) bake the
    // held-out head (id 2).
    let asset = dir.path().join("net.nelf");
    let head = data.join("heads").join("h00002");
    succeed(&[
        "bake",
        "capture",
        head.to_str().unwrap(),
        "--weights",
        run.join("weights.safetensors").to_str().unwrap(),
        "-o",
        asset.to_str().unwrap(),
        "--resolution",
        "16",
        "--view-dependence",
        "off",
    ]);
    let baked = read_asset(&asset).unwrap();
    assert!(!baked.bricks.is_empty());
}
