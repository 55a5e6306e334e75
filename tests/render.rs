//! End-to-end tests of `nelf render`: a synthetic asset is written and rendered to PNG and
//! EXR from an orbit, a camera file, a capture view and a previous render's record; the
//! EXR equals the library's render; bad inputs fail with clear messages.
#![allow(clippy::unwrap_used)] // Test helpers outside #[test] functions unwrap too.

use std::ffi::OsStr;
use std::path::Path;
use std::process::{Command, Output};

use glam::{DMat3, DVec3};
use nelf_format::capture::{Capture, CaptureView};
use nelf_format::conventions::{LatLong, PinholeCamera, rotation_y};
use nelf_format::synthetic::SyntheticField;
use nelf_format::{Asset, CoefficientEncoding, WriteOptions, write_asset};
use nelf_render::{MarchSettings, render_asset};

fn nelf<S: AsRef<OsStr>>(args: &[S]) -> Output {
    match Command::new(env!("CARGO_BIN_EXE_nelf"))
        .arg("render")
        .args(args)
        .output()
    {
        Ok(out) => out,
        Err(e) => panic!("cannot run nelf: {e}"),
    }
}

fn succeed<S: AsRef<OsStr>>(args: &[S]) -> String {
    let out = nelf(args);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8(out.stdout).unwrap()
}

fn fail<S: AsRef<OsStr>>(args: &[S]) -> String {
    let out = nelf(args);
    assert!(!out.status.success(), "should have failed");
    String::from_utf8(out.stderr).unwrap()
}

/// Width and height from a PNG's IHDR chunk.
fn png_size(path: &Path) -> (u32, u32) {
    let bytes = std::fs::read(path).unwrap();
    assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n");
    let be = |at: usize| u32::from_be_bytes(bytes[at..at + 4].try_into().unwrap());
    (be(16), be(20))
}

fn write_synthetic(dir: &Path) -> (std::path::PathBuf, Asset) {
    let field = SyntheticField::new(8000, 3);
    let pca = field.fit_pca(6, 400);
    let coefficients =
        nelf_format::Coefficients::quantize(&field.project(&pca), 6, CoefficientEncoding::U8Affine).unwrap();
    let asset = field.asset_with(pca, coefficients).unwrap();
    let path = dir.join("head.nelf");
    write_asset(&path, &asset, &WriteOptions::default()).unwrap();
    (path, asset)
}

fn camera_json(camera: &PinholeCamera) -> serde_json::Value {
    let r = camera.rotation;
    serde_json::json!({
        "width": camera.width,
        "height": camera.height,
        "intrinsics": {"fx": camera.fx, "fy": camera.fy, "cx": camera.cx, "cy": camera.cy},
        "world_to_camera": {
            "rotation": [r.row(0).to_array(), r.row(1).to_array(), r.row(2).to_array()],
            "translation": camera.translation.to_array(),
        },
    })
}

#[test]
fn renders_png_and_exr_matching_the_library() {
    let dir = tempfile::tempdir().unwrap();
    let (asset_path, asset) = write_synthetic(dir.path());

    // Orbit, PNG: size, a printed time, and the record beside it.
    let png = dir.path().join("orbit.png");
    let stdout = succeed(&[
        asset_path.as_os_str(),
        "--orbit".as_ref(),
        "30,-10".as_ref(),
        "--width".as_ref(),
        "40".as_ref(),
        "--height".as_ref(),
        "32".as_ref(),
        "-o".as_ref(),
        png.as_os_str(),
    ]);
    assert!(
        stdout.contains(" s on the CPU") && stdout.contains("constant white"),
        "{stdout}"
    );
    assert_eq!(png_size(&png), (40, 32));
    let record: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("orbit.png.render.json")).unwrap())
            .unwrap();
    assert_eq!(record["config"]["orbit"], "30,-10");
    assert_eq!(record["rank_used"], 6);
    assert!(record["render_seconds"].as_f64().unwrap() > 0.0);

    // A camera file and an environment map (EXR), turned and truncated; EXR output.
    let camera = PinholeCamera::look_at(DVec3::new(0.1, 0.05, 0.45), DVec3::ZERO, DVec3::Y, 24, 20, 0.7);
    let camera_path = dir.path().join("cam.json");
    std::fs::write(&camera_path, camera_json(&camera).to_string()).unwrap();
    let env_texels: Vec<[f32; 3]> = (0..16 * 32)
        .map(|i| [1.0 + (i % 32) as f32 / 8.0, 0.5, 0.25 + (i / 32) as f32 / 16.0])
        .collect();
    let env_path = dir.path().join("sky.exr");
    nelf_scene::image_io::write_exr_rgb(&env_path, 32, 16, &env_texels).unwrap();
    let exr = dir.path().join("cam.exr");
    succeed(&[
        asset_path.as_os_str(),
        "--camera".as_ref(),
        camera_path.as_os_str(),
        "--envmap".as_ref(),
        env_path.as_os_str(),
        "--rotate-deg".as_ref(),
        "-40".as_ref(),
        "--rank".as_ref(),
        "4".as_ref(),
        "-o".as_ref(),
        exr.as_os_str(),
    ]);
    // Read the EXR back (the env-map loader reads any RGB EXR; it zeroes negatives).
    let rendered = nelf_scene::envmap::load_envmap(&exr).unwrap();
    assert_eq!((rendered.width(), rendered.height()), (24, 20));
    let env = LatLong::new(32, 16, env_texels).unwrap();
    let want = render_asset(
        &asset,
        &camera,
        &env,
        rotation_y((-40f64).to_radians()),
        Some(4),
        &MarchSettings::default(),
    )
    .unwrap();
    assert!(want.alpha.iter().any(|&a| a > 0.5));
    for (got, want) in rendered.texels().iter().zip(&want.rgb) {
        assert_eq!(*got, want.map(|v| v.max(0.0)));
    }

    // The record's camera re-renders the same image.
    let again = dir.path().join("again.exr");
    succeed(&[
        asset_path.as_os_str(),
        "--camera".as_ref(),
        dir.path().join("cam.exr.render.json").as_os_str(),
        "--envmap".as_ref(),
        env_path.as_os_str(),
        "--rotate-deg".as_ref(),
        "-40".as_ref(),
        "--rank".as_ref(),
        "4".as_ref(),
        "-o".as_ref(),
        again.as_os_str(),
    ]);
    assert_eq!(nelf_scene::envmap::load_envmap(&again).unwrap(), rendered);
}

#[test]
fn renders_a_capture_view_under_its_lighting() {
    let dir = tempfile::tempdir().unwrap();
    let (asset_path, _) = write_synthetic(dir.path());
    let capture_dir = dir.path().join("capture");
    std::fs::create_dir_all(capture_dir.join("images")).unwrap();
    std::fs::write(capture_dir.join("images/front.png"), b"").unwrap();
    let camera = PinholeCamera::look_at(DVec3::new(0.0, 0.0, 0.5), DVec3::ZERO, DVec3::Y, 30, 30, 0.8);
    let mut capture = Capture::new(vec![CaptureView {
        name: "front".into(),
        image: "images/front.png".into(),
        mask: None,
        camera,
    }]);
    capture.envmap = Some("light.exr".into());
    nelf_scene::image_io::write_exr_rgb(capture_dir.join("light.exr"), 4, 2, &[[2.0, 1.0, 0.5]; 8]).unwrap();
    capture.save(&capture_dir).unwrap();
    let png = dir.path().join("front.png");
    let view = format!("{}:front", capture_dir.display());
    let stdout = succeed(&[
        asset_path.as_os_str(),
        "--view-of".as_ref(),
        view.as_ref(),
        "--width".as_ref(),
        "15".as_ref(),
        "-o".as_ref(),
        png.as_os_str(),
    ]);
    assert!(stdout.contains("light.exr"), "{stdout}");
    assert_eq!(png_size(&png), (15, 15));
    let err = fail(&[
        asset_path.as_os_str(),
        "--view-of".as_ref(),
        format!("{}:nope", capture_dir.display()).as_ref(),
        "-o".as_ref(),
        png.as_os_str(),
    ]);
    assert!(err.contains("no view or target named \"nope\""), "{err}");
}

#[test]
fn bad_inputs_fail_with_clear_messages() {
    let dir = tempfile::tempdir().unwrap();
    let (asset_path, _) = write_synthetic(dir.path());
    let out = dir.path().join("x.png");
    let missing = dir.path().join("missing.nelf");
    let err = fail(&[missing.as_os_str(), "-o".as_ref(), out.as_os_str()]);
    assert!(
        err.contains("cannot read") && err.contains("missing.nelf"),
        "{err}"
    );

    let mut bytes = std::fs::read(&asset_path).unwrap();
    let last = bytes.len() - 100;
    bytes[last] ^= 0x40;
    let damaged = dir.path().join("damaged.nelf");
    std::fs::write(&damaged, bytes).unwrap();
    let err = fail(&[damaged.as_os_str(), "-o".as_ref(), out.as_os_str()]);
    assert!(err.contains("damaged.nelf") && err.contains("checksum"), "{err}");

    let mut camera = camera_json(&PinholeCamera::look_at(
        DVec3::new(0.0, 0.0, 0.5),
        DVec3::ZERO,
        DVec3::Y,
        8,
        8,
        0.8,
    ));
    let mirrored = DMat3::from_diagonal(DVec3::new(1.0, 1.0, -1.0));
    camera["world_to_camera"]["rotation"] = serde_json::json!([
        mirrored.row(0).to_array(),
        mirrored.row(1).to_array(),
        mirrored.row(2).to_array()
    ]);
    let camera_path = dir.path().join("bad_cam.json");
    std::fs::write(&camera_path, camera.to_string()).unwrap();
    let err = fail(&[
        asset_path.as_os_str(),
        "--camera".as_ref(),
        camera_path.as_os_str(),
        "-o".as_ref(),
        out.as_os_str(),
    ]);
    assert!(err.contains("not a rotation"), "{err}");

    for (args, needle) in [
        (vec!["--rank", "7"], "PCA rank 6"),
        (vec!["--orbit", "0,90"], "elevation"),
        (vec!["--orbit", "a,b"], "AZ,EL"),
        (vec!["--step-voxels", "0"], "step_voxels"),
    ] {
        let mut all: Vec<&OsStr> = vec![asset_path.as_os_str()];
        all.extend(args.iter().map(OsStr::new));
        all.extend(["-o".as_ref(), out.as_os_str()]);
        let err = fail(&all);
        assert!(err.contains(needle), "{args:?}: {err}");
    }
    let err = fail(&[asset_path.as_os_str(), "-o".as_ref(), "x.jpg".as_ref()]);
    assert!(err.contains(".png or .exr"), "{err}");
    assert!(!out.exists());
}
