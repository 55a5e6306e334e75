//! Issue 18's must-hold on accuracy: the shipped network's bake of a held-out
//! procedural head, at small size, beats the flat-colour oracle (the true foreground
//! mean inside the true silhouette) on foreground PSNR at novel views under novel
//! light, as `nelf eval network` scores it.
//!
//! The head is the first of the five fixed in advance by `scripts/eval_heldout_heads.sh`
//! (seed 2⁶² + 1, from the validation range `nelf train data` never trains on; 64²
//! views under the real `forest` HDRI; targets under `interior` and under `forest`
//! turned 90°). Of those five it is the one where the bake leads the flat colour by
//! least (models/README.md), so the test is not a chosen easy case. It also runs the
//! `--split` bakes (parts of the field taken from the ground truth) and checks that
//! the truth's light transport, put in the network's place, gains what it measured.
#![allow(clippy::unwrap_used)] // Test helpers outside #[test] functions unwrap too.

mod common;

use std::path::Path;

use common::succeed;

#[test]
fn the_shipped_networks_bake_of_a_held_out_head_beats_the_flat_colour() {
    let dir = tempfile::tempdir().unwrap();
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let map = |name: &str| {
        let path = root.join("data/envmaps").join(name);
        assert!(
            path.is_file(),
            "{} is missing (part of the repository)",
            path.display()
        );
        path.to_str().unwrap().to_string()
    };
    let capture = dir.path().join("head");
    let seed = ((1u64 << 62) + 1).to_string();
    succeed(&[
        "capture",
        "synth",
        "--head-seed",
        &seed,
        "--width",
        "64",
        "--height",
        "64",
        "--envmap",
        &map("forest.exr"),
        "--target-envmap",
        &map("interior.exr"),
        "--target-envmap",
        &map("forest.exr"),
        "--target-env-rotate-deg",
        "0",
        "--target-env-rotate-deg",
        "90",
        "-o",
        capture.to_str().unwrap(),
    ]);
    let scores = dir.path().join("scores");
    let (summary, text) = eval_network(
        &capture,
        &["--split", "density,transport,shading,colour"],
        &scores,
    );
    let rows = summary["rows"].as_array().unwrap();
    assert_eq!(rows.len(), 2, "{text}");
    let mean = |kind: &str, key: &str| {
        rows.iter().map(|r| r[kind][key].as_f64().unwrap()).sum::<f64>() / rows.len() as f64
    };
    let bake = mean("network_bake", "foreground_psnr");
    let flat = mean("network_bake", "flat_foreground_psnr");
    let truth = mean("truth_bake", "foreground_psnr");
    // Measured 24.62 against 21.48 dB with the prior's normals over 3 mm at weight 0.7
    // (24.54 over 5 mm and 24.39 over 8 mm at 0.5; 24.32 before the bake carved its
    // density to the masks' visual hull; ground-truth bake 28.54; 21.63 with the
    // one-gain calibration and the weights shipped before the shading prior): 44 % of
    // the gap, on the head where the bake leads by least. A network that learned only
    // the silhouette and the average colour scores about the flat colour.
    assert!(
        bake > flat + 2.0,
        "network bake {bake:.2} dB vs flat colour {flat:.2} dB (foreground): less than 2 dB ahead"
    );
    assert!(
        truth > bake + 3.0,
        "ground-truth bake {truth:.2} vs network bake {bake:.2}"
    );
    // `--split`: the same bake with the ground truth's light transport in place of the
    // network's closes most of what is left (measured with the prior over 5 mm at 0.5:
    // 27.29 dB; the truth's density with the network's transport 24.40, the truth's
    // shading with the network's colour 25.77, the truth's colour with the network's
    // shading 24.45): the network's error is in its transport, not its geometry.
    let split = |part: &str| summary["mean_split"][part]["foreground_psnr"].as_f64().unwrap();
    let transport = split("truth_transport_bake");
    assert!(
        transport > bake + 1.5,
        "the truth's transport {transport:.2} dB against the network's bake {bake:.2}"
    );
    for part in ["truth_density_bake", "truth_shading_bake", "truth_colour_bake"] {
        let score = split(part);
        assert!(
            score.is_finite() && score > flat,
            "{part}: {score:.2} dB ({text})"
        );
    }
    // The network was normalised to the capture's source lighting, with the default prior.
    let asset = nelf_format::read_asset(&scores.join("capture0_network.nelf")).unwrap();
    let source = &asset.metadata["source"]["source"];
    assert_eq!(
        source["source_normalised"],
        serde_json::json!(true),
        "{}",
        asset.metadata
    );
    assert_eq!(
        source["shading_prior"],
        serde_json::json!({"step_mm": nelf_field::prior::DEFAULT_STEP_MM, "weight": nelf_field::prior::DEFAULT_WEIGHT}),
        "{}",
        asset.metadata
    );
    assert_eq!(
        source["light_transport_scale"].as_f64(),
        Some(1.0),
        "{}",
        asset.metadata
    );
    // `--bakes-only` skips the network's direct renders and scores the same bakes.
    let (only, text) = eval_network(&capture, &["--bakes-only"], &dir.path().join("bakes"));
    assert!(only["mean_foreground_psnr"]["network"].is_null(), "{text}");
    let only_rows = only["rows"].as_array().unwrap();
    assert_eq!(only_rows.len(), rows.len(), "{text}");
    for (a, b) in rows.iter().zip(only_rows) {
        assert!(b["network"].is_null(), "{text}");
        for kind in ["network_bake", "truth_bake"] {
            for key in ["foreground_psnr", "psnr", "ssim"] {
                let (x, y) = (a[kind][key].as_f64().unwrap(), b[kind][key].as_f64().unwrap());
                assert!(
                    (x - y).abs() < 1e-3,
                    "{kind} {key}: {x} against {y} with --bakes-only"
                );
            }
        }
    }
}

/// `nelf eval network CAPTURE --resolution 32 EXTRA… -o OUT`: its `network.json`, parsed
/// and as text.
fn eval_network(capture: &Path, extra: &[&str], out: &Path) -> (serde_json::Value, String) {
    let mut args = vec!["eval", "network", capture.to_str().unwrap(), "--resolution", "32"];
    args.extend_from_slice(extra);
    args.extend(["-o", out.to_str().unwrap()]);
    succeed(&args);
    let text = std::fs::read_to_string(out.join("network.json")).unwrap();
    (serde_json::from_str(&text).unwrap(), text)
}
