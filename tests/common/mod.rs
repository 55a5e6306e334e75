//! Helpers shared by the end-to-end tests of the `nelf` command: running it, the
//! parity fixtures' network weights, and a tiny, cheap synthetic capture.
#![allow(clippy::unwrap_used, dead_code)] // Each test binary uses some of these.

use std::ffi::OsStr;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// The parity fixtures' NeLF weights (random, from the official implementation;
/// `data/nelf-oracle/README.md`), zstd-compressed in the repository.
pub const FIXTURE_WEIGHTS: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/data/nelf-oracle/fixture_seed0.safetensors.zst"
);

/// The fixture weights' path, failing the test (with the reason) when missing.
pub fn fixture_weights() -> &'static str {
    assert!(
        Path::new(FIXTURE_WEIGHTS).is_file(),
        "the parity fixtures' weights are missing at {FIXTURE_WEIGHTS} (part of the repository)"
    );
    FIXTURE_WEIGHTS
}

/// Runs `nelf` with `args`.
pub fn nelf<S: AsRef<OsStr>>(args: &[S]) -> Output {
    match Command::new(env!("CARGO_BIN_EXE_nelf")).args(args).output() {
        Ok(out) => out,
        Err(e) => panic!("cannot run nelf: {e}"),
    }
}

/// Runs `nelf` with `args`, asserts success (showing its stderr) and returns stdout.
pub fn succeed<S: AsRef<OsStr>>(args: &[S]) -> String {
    let out = nelf(args);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8(out.stdout).unwrap()
}

/// The shared head scan (`data/meshes/head.off`: open at the neck, holes, thin parts)
/// baked small (`--resolution 40 --rank 8`, view-independent) into `dir/scan.nelf`;
/// fails the test, naming the file, when the scan is missing.
pub fn bake_scan_head(dir: &Path) -> PathBuf {
    let mesh = Path::new(env!("CARGO_MANIFEST_DIR")).join("data/meshes/head.off");
    assert!(
        mesh.is_file(),
        "missing test data {} (see data/README.md)",
        mesh.display()
    );
    let asset = dir.join("scan.nelf");
    succeed(&[
        "bake".as_ref(),
        "mesh".as_ref(),
        mesh.as_os_str(),
        "--resolution".as_ref(),
        "40".as_ref(),
        "--view-dependence".as_ref(),
        "off".as_ref(),
        "--render-size".as_ref(),
        "32".as_ref(),
        "--rank".as_ref(),
        "8".as_ref(),
        "--quiet".as_ref(),
        "-o".as_ref(),
        asset.as_os_str(),
    ]);
    asset
}

/// Writes `nelf capture synth` output to `dir/capture`: `size`² images, `targets`
/// held-aside views, direct lighting only with few samples (seconds, not minutes),
/// plus `extra` options. Returns the folder.
pub fn tiny_capture(dir: &Path, size: u32, targets: u32, extra: &[&str]) -> PathBuf {
    let capture = dir.join("capture");
    let size = size.to_string();
    let targets = targets.to_string();
    let mut args = vec![
        "capture",
        "synth",
        "-o",
        capture.to_str().unwrap(),
        "--width",
        &size,
        "--height",
        &size,
        "--bounces",
        "0",
        "--texel-samples",
        "2",
        "--indirect-samples",
        "4",
        "--targets",
        &targets,
    ];
    args.extend_from_slice(extra);
    succeed(&args);
    capture
}

/// Inputs of a batch of small bakes: a copy of the repository's head scan per name
/// (`dir/in/<name>.off`) in order, or, for the name `broken_capture`, a capture folder
/// whose cameras.json is damaged (its bake fails with the capture's own error).
pub fn batch_inputs(dir: &Path, names: &[&str]) -> Vec<PathBuf> {
    let mesh = Path::new(env!("CARGO_MANIFEST_DIR")).join("data/meshes/head.off");
    assert!(
        mesh.is_file(),
        "missing test data {} (see data/README.md)",
        mesh.display()
    );
    let inputs = dir.join("in");
    std::fs::create_dir_all(&inputs).unwrap();
    names
        .iter()
        .map(|name| {
            if *name == "broken_capture" {
                let broken = inputs.join(name);
                std::fs::create_dir_all(broken.join("images")).unwrap();
                std::fs::write(broken.join("cameras.json"), "{\"views\": [").unwrap();
                broken
            } else {
                let copy = inputs.join(format!("{name}.off"));
                std::fs::copy(&mesh, &copy).unwrap();
                copy
            }
        })
        .collect()
}

/// Options that make a mesh bake of the head scan take about a second.
pub const SMALL_BAKE: [&str; 6] = [
    "--resolution",
    "16",
    "--view-dependence",
    "off",
    "--render-size",
    "32",
];

/// Writes `dir/out/plan.jsonl`: one small bake per input; returns its path.
pub fn plan_small_bakes(dir: &Path, inputs: &[PathBuf]) -> PathBuf {
    let out = dir.join("out");
    let mut args: Vec<&OsStr> = vec!["batch".as_ref(), "plan".as_ref(), "bake".as_ref()];
    args.extend(inputs.iter().map(|p| p.as_os_str()));
    args.extend(["--out".as_ref(), out.as_os_str(), "--".as_ref()]);
    args.extend(SMALL_BAKE.iter().map(OsStr::new));
    let printed = succeed(&args);
    let expected = format!("{n} items in {n} array indices", n = inputs.len());
    assert!(printed.contains(&expected), "{printed}");
    out.join("plan.jsonl")
}
