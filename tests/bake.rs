//! End-to-end test of `nelf bake`: a small closed mesh is baked by the command
//! into an asset that reads back with the chosen rank, beside its `.bake.json`;
//! a folder with no capture makes `nelf bake capture` fail naming the folder.

#![allow(clippy::unwrap_used)] // Test helpers outside #[test] functions unwrap too.

mod common;

use std::fmt::Write as _;

use common::{fixture_weights, nelf, succeed, tiny_capture};
use nelf_format::read_asset;

/// A closed sphere-like mesh (a subdivided cube pushed onto a sphere of radius
/// 0.1 m, outward-facing), as OFF text.
fn sphere_off() -> String {
    let mut vertices: Vec<[f64; 3]> = Vec::new();
    let mut faces: Vec<[usize; 3]> = Vec::new();
    let n = 6usize;
    // Six faces of a cube, each an n × n grid, projected onto the sphere.
    let axes = [
        (0, 1, 2, 1.0),
        (0, 1, 2, -1.0),
        (1, 2, 0, 1.0),
        (1, 2, 0, -1.0),
        (2, 0, 1, 1.0),
        (2, 0, 1, -1.0),
    ];
    for &(u, v, w, sign) in &axes {
        let base = vertices.len();
        for i in 0..=n {
            for j in 0..=n {
                let mut p = [0.0; 3];
                p[u] = -1.0 + 2.0 * i as f64 / n as f64;
                p[v] = -1.0 + 2.0 * j as f64 / n as f64;
                p[w] = sign;
                let len = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
                vertices.push(p.map(|x| 0.1 * x / len));
            }
        }
        for i in 0..n {
            for j in 0..n {
                let a = base + i * (n + 1) + j;
                let (b, c, d) = (a + n + 1, a + 1, a + n + 2);
                // (u, v, w) is a cyclic order, so (+u) × (+v) = +w: counter-clockwise
                // seen from outside on the +w face, reversed on the −w face.
                if sign > 0.0 {
                    faces.push([a, b, c]);
                    faces.push([c, b, d]);
                } else {
                    faces.push([a, c, b]);
                    faces.push([c, d, b]);
                }
            }
        }
    }
    let mut text = format!("OFF\n{} {} 0\n", vertices.len(), faces.len());
    for p in &vertices {
        writeln!(text, "{} {} {}", p[0], p[1], p[2]).unwrap();
    }
    for f in &faces {
        writeln!(text, "3 {} {} {}", f[0], f[1], f[2]).unwrap();
    }
    text
}

#[test]
fn bake_mesh_writes_an_asset_and_bad_captures_fail() {
    let dir = tempfile::tempdir().unwrap();
    let mesh = dir.path().join("ball.off");
    std::fs::write(&mesh, sphere_off()).unwrap();
    let out_path = dir.path().join("ball.nelf");
    let strings = [
        "bake",
        "mesh",
        mesh.to_str().unwrap(),
        "-o",
        out_path.to_str().unwrap(),
        "--height-m",
        "0",
        "--resolution",
        "24",
        "--render-size",
        "32",
        "--bounces",
        "0",
        "--texel-samples",
        "1",
        "--indirect-samples",
        "0",
        "--quiet",
    ];
    let args: Vec<&std::ffi::OsStr> = strings.iter().map(std::convert::AsRef::as_ref).collect();
    let out = nelf(&args);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(text.contains("PCA rank K = "), "{text}");
    let asset = read_asset(&out_path).unwrap();
    assert!(asset.rank() >= 1 && !asset.bricks.is_empty());
    assert_eq!(asset.metadata["generator"], "nelf bake");
    let sidecar: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("ball.bake.json")).unwrap()).unwrap();
    assert_eq!(sidecar["report"]["rank"].as_u64(), Some(asset.rank() as u64));
    assert_eq!(sidecar["config"]["resolution"], 24);

    let empty = dir.path().join("empty");
    std::fs::create_dir(&empty).unwrap();
    let out = nelf(&[
        "bake".as_ref(),
        "capture".as_ref(),
        empty.as_os_str(),
        "-o".as_ref(),
        out_path.as_os_str(),
    ]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("no capture found") && err.contains(empty.to_str().unwrap()),
        "{err}"
    );
}

#[test]
fn bake_capture_with_network_weights() {
    let dir = tempfile::tempdir().unwrap();
    let cap = tiny_capture(dir.path(), 32, 0, &["--head-cells", "40"]);
    let weights = fixture_weights();
    let asset_path = dir.path().join("net.nelf");
    let bake = nelf(
        &[
            "bake",
            "capture",
            cap.to_str().unwrap(),
            "--weights",
            weights,
            "-o",
            asset_path.to_str().unwrap(),
            "--resolution",
            "24",
            "--quiet",
        ]
        .map(std::ffi::OsStr::new),
    );
    assert!(bake.status.success(), "{}", String::from_utf8_lossy(&bake.stderr));
    let asset = read_asset(&asset_path).unwrap();
    assert_eq!(
        asset.metadata["source"]["source"]["kind"], "nelf-network",
        "{}",
        asset.metadata
    );
    // The light frame is the network's (view 0's camera turned by π about its z):
    // for the frontal view 0 of a synthetic capture that is diag(−1, 1, −1).
    let expected = glam::DMat3::from_diagonal(glam::DVec3::new(-1.0, 1.0, -1.0));
    assert!(
        asset.world_from_light.abs_diff_eq(expected, 1e-9),
        "{:?}",
        asset.world_from_light
    );
    assert!(asset.voxel_count() > 0);

    // Missing weights: a clear error naming the file.
    let missing = nelf(
        &[
            "bake",
            "capture",
            cap.to_str().unwrap(),
            "--weights",
            "/nonexistent/w.safetensors",
            "-o",
            asset_path.to_str().unwrap(),
            "--quiet",
        ]
        .map(std::ffi::OsStr::new),
    );
    assert!(!missing.status.success());
    assert!(String::from_utf8_lossy(&missing.stderr).contains("/nonexistent/w.safetensors"));
}

/// A capture with no ground truth bakes with the shipped network by default;
/// `--source` chooses explicitly, and impossible choices are refused.
#[test]
fn a_capture_without_ground_truth_bakes_from_its_photographs_or_with_the_shipped_network() {
    let dir = tempfile::tempdir().unwrap();
    let cap = tiny_capture(dir.path(), 64, 0, &["--head-cells", "40"]);
    // A synthetic capture carries its ground truth (synth_config.json); without
    // it, the capture is like a photographed one.
    std::fs::remove_file(cap.join("synth_config.json")).unwrap();
    let out = cap.to_str().unwrap();
    // The shipped network's bake of the capture at 24³, without view dependence,
    // written to `name` with the `extra` options and read back.
    let bake_shipped = |name: &str, extra: &[&str]| {
        let path = dir.path().join(name);
        let mut args = vec![
            "bake",
            "capture",
            out,
            "-o",
            path.to_str().unwrap(),
            "--resolution",
            "24",
            "--view-dependence",
            "off",
            "--quiet",
        ];
        args.extend_from_slice(extra);
        succeed(&args);
        (read_asset(&path).unwrap(), path)
    };
    // By default (`--source auto`) such a capture is reconstructed from its
    // photographs and the surface baked; the reconstruction is written beside it.
    let (photos, photos_path) = bake_shipped("photos.nelf", &[]);
    let truth = &photos.metadata["source"]["source"]["ground_truth"];
    assert_eq!(truth["kind"], "reconstructed-mesh", "{}", photos.metadata);
    assert_eq!(
        truth["reconstruction"]["surface"]["geometry"], "network",
        "{truth}"
    );
    assert!(photos.voxel_count() > 0);
    // The reconstruction opens as a textured OBJ (OBJ + MTL + atlas image), read back
    // by the same loader as a scan's.
    let reconstruction = photos_path.with_extension("reconstruction");
    for file in [
        "reconstruction.obj",
        "reconstruction.mtl",
        "reconstruction_albedo.jpg",
        "reconstruction.json",
    ] {
        assert!(reconstruction.join(file).is_file(), "{file}");
    }
    let options = nelf_scene::mesh_io::LoadOptions {
        fit_height_m: None,
        orient_outward: false,
        close_holes: false,
        ..nelf_scene::mesh_io::LoadOptions::default()
    };
    let mesh = nelf_scene::mesh_io::load_mesh(reconstruction.join("reconstruction.obj"), &options).unwrap();
    assert!(matches!(mesh.albedo, nelf_scene::mesh::Albedo::Texture { .. }));
    let (asset, asset_path) = bake_shipped("shipped.nelf", &["--source", "network"]);
    let source = &asset.metadata["source"]["source"];
    assert_eq!(source["kind"], "nelf-network", "{}", asset.metadata);
    assert!(
        source["weights"].as_str().unwrap().contains("nelf-small"),
        "{source}"
    );
    // The shipped network was trained at 64 pixels: the views are encoded so.
    assert_eq!(source["encoded_image_size"][0], source["working_image_size"]);
    // It takes lightings relative to the source lighting's power. This capture's
    // cameras.json names that lighting, so by default every view's transport is
    // normalised to it point by point (physical units, no scale) with the Lambertian
    // shading prior mixed in.
    assert_eq!(source["source_relative_light"], true, "{source}");
    assert_eq!(source["source_normalised"], true, "{source}");
    assert_eq!(source["light_transport_scale"].as_f64(), Some(1.0), "{source}");
    assert_eq!(
        source["shading_prior"],
        serde_json::json!({"step_mm": nelf_field::prior::DEFAULT_STEP_MM, "weight": nelf_field::prior::DEFAULT_WEIGHT}),
        "{source}"
    );
    // The shipped weights' last steps trained through the prior at the training weight,
    // with normals over 8 mm (bakes take a step and weight of their own since,
    // `nelf_field::prior::DEFAULT_STEP_MM` and `DEFAULT_WEIGHT`), and say so.
    assert_eq!(
        source["trained_shading_prior"],
        serde_json::json!({"step_mm": 8.0, "weight": nelf_field::prior::TRAINING_WEIGHT}),
        "{source}"
    );
    assert!(asset.voxel_count() > 0);
    // A network's density is stored signed (`--network-skin-mm`, field/README.md).
    assert!(nelf_format::asset::has_negative_density(&asset.density));
    let sidecar: serde_json::Value =
        serde_json::from_slice(&std::fs::read(asset_path.with_extension("bake.json")).unwrap()).unwrap();
    assert_eq!(sidecar["config"]["network_skin_mm"], 1.0, "{sidecar}");
    assert_eq!(
        sidecar["config"]["shading_prior_weight"].as_f64(),
        Some(f64::from(nelf_field::prior::DEFAULT_WEIGHT)),
        "{sidecar}"
    );
    // ... and carved to the visual hull of the masks (`nelf_bake::silhouette`).
    assert_eq!(sidecar["config"]["no_network_hull_carve"], false, "{sidecar}");
    assert_eq!(
        sidecar["config"]["network_hull_margin_px"].as_f64(),
        Some(f64::from(nelf_pipeline::DEFAULT_NETWORK_HULL_MARGIN_PX)),
        "{sidecar}"
    );

    // --shading-prior-mm 0: the one-gain calibration instead, the transport divided by
    // the source lighting's power and scaled by the gain.
    let (gain, _) = bake_shipped("gain.nelf", &["--source", "network", "--shading-prior-mm", "0"]);
    let source = &gain.metadata["source"]["source"];
    assert_eq!(source["source_normalised"], false, "{source}");
    assert!(source["shading_prior"].is_null(), "{source}");
    // What the weights were trained through stays on record.
    assert_eq!(source["trained_shading_prior"]["weight"], 0.5, "{source}");
    let scale = source["light_transport_scale"].as_f64().unwrap();
    assert!(scale.is_finite() && scale > 0.0 && scale != 1.0, "{source}");

    // --source truth without a mesh: refused, naming the folder and what is missing.
    let truth = nelf(&[
        "bake",
        "capture",
        out,
        "--source",
        "truth",
        "-o",
        asset_path.to_str().unwrap(),
        "--quiet",
    ]);
    assert!(!truth.status.success());
    let message = String::from_utf8_lossy(&truth.stderr);
    assert!(
        message.contains("synth_config.json") && message.contains(out),
        "{message}"
    );
    // --source truth with --weights: contradictory.
    let both = nelf(&[
        "bake",
        "capture",
        out,
        "--source",
        "truth",
        "--weights",
        fixture_weights(),
        "-o",
        asset_path.to_str().unwrap(),
        "--quiet",
    ]);
    assert!(!both.status.success());
}
