//! End-to-end test of `nelf light`: a small synthetic capture is written with
//! `nelf capture synth`, its lighting estimated with the parity fixtures' weights
//! (`data/nelf-oracle/fixture_seed0.safetensors.zst`), and the world-frame map is
//! checked against the raw light-frame estimate through the reported
//! `world_from_light`; bad inputs fail with clear messages.
#![allow(clippy::unwrap_used)] // Test helpers outside #[test] functions unwrap too.

mod common;

use common::{fixture_weights, nelf, succeed, tiny_capture};
use glam::DMat3;
use nelf_format::conventions::{is_rotation, project_envmap};
use nelf_scene::envmap::load_envmap;

#[test]
fn light_writes_the_estimate_in_the_world_frame() {
    let weights = fixture_weights();
    let dir = tempfile::tempdir().unwrap();
    let capture = tiny_capture(dir.path(), 64, 1, &[]);
    let cap = capture.to_str().unwrap();
    let world = dir.path().join("light.exr");
    let raw = dir.path().join("light_frame.exr");
    let summary: serde_json::Value = serde_json::from_str(&succeed(&[
        "light",
        cap,
        "--weights",
        weights,
        "-o",
        world.to_str().unwrap(),
        "--width",
        "128",
        "--json",
    ]))
    .unwrap();
    succeed(&[
        "light",
        cap,
        "--weights",
        weights,
        "-o",
        raw.to_str().unwrap(),
        "--light-frame",
    ]);

    // Without --weights the shipped network estimates the lighting.
    let shipped = dir.path().join("shipped.exr");
    let shipped_summary: serde_json::Value = serde_json::from_str(&succeed(&[
        "light",
        cap,
        "-o",
        shipped.to_str().unwrap(),
        "--json",
    ]))
    .unwrap();
    assert!(
        shipped_summary["weights"]
            .as_str()
            .unwrap()
            .contains("nelf-small"),
        "{shipped_summary}"
    );
    assert!(
        load_envmap(&shipped)
            .unwrap()
            .texels()
            .iter()
            .flatten()
            .all(|v| v.is_finite())
    );

    let world_map = load_envmap(&world).unwrap();
    let light_map = load_envmap(&raw).unwrap();
    assert_eq!((world_map.width(), world_map.height()), (128, 64));
    assert_eq!((light_map.width(), light_map.height()), (16, 8));
    assert!(
        light_map
            .texels()
            .iter()
            .flatten()
            .all(|v| v.is_finite() && *v > 0.0)
    );
    let cols: Vec<f64> = summary["world_from_light"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    let world_from_light = DMat3::from_cols_slice(&cols);
    assert!(is_rotation(world_from_light, 1e-9));
    // Projecting the world-frame file back into the light frame gives the estimate.
    let back = project_envmap(&world_map, world_from_light).unwrap();
    let scale = light_map.texels().iter().flatten().fold(0.0f32, |a, b| a.max(*b));
    for (a, b) in light_map.texels().iter().zip(back.texels()) {
        for c in 0..3 {
            assert!((a[c] - b[c]).abs() < 0.05 * scale, "{a:?} vs {b:?}");
        }
    }
    let power = summary["power_rgb"].as_array().unwrap();
    let want = world_map.integral();
    for c in 0..3 {
        assert!((power[c].as_f64().unwrap() - want[c]).abs() < 1e-3 * want[c]);
    }

    // Bad inputs: clear messages, no panic.
    let out = nelf(&[
        "light",
        cap,
        "--weights",
        dir.path().join("missing.safetensors").to_str().unwrap(),
    ]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("missing.safetensors"));
    let out = nelf(&["light", dir.path().to_str().unwrap(), "--weights", weights]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("loading the capture"));
}
