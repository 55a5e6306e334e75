//! The capture folder: `cameras.json` save → load round trips, unit conversion, and
//! every validation error naming the file and the view.

// Test helpers outside #[test] functions fail the test on setup errors by panicking.
#![allow(clippy::unwrap_used)]

use std::path::Path;

use glam::{DMat3, DVec3};
use nelf_format::capture::{CAPTURE_FILE_NAME, Capture, CaptureError, CaptureView, TargetView};
use nelf_format::conventions::PinholeCamera;
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

fn random_camera(rng: &mut Pcg64) -> PinholeCamera {
    let eye = DVec3::new(
        rng.random_range(-2.0..2.0),
        rng.random_range(-0.5..0.5),
        rng.random_range(1.0..3.0),
    );
    let target = DVec3::new(rng.random_range(-0.1..0.1), rng.random_range(-0.1..0.1), 0.0);
    let mut camera = PinholeCamera::look_at(eye, target, DVec3::Y, 640, 480, rng.random_range(0.3..1.2));
    camera.fy = camera.fx * rng.random_range(0.9..1.1);
    camera.cx += rng.random_range(-5.0..5.0);
    camera.cy += rng.random_range(-5.0..5.0);
    camera
}

fn touch(dir: &Path, rel: &str) {
    let path = dir.join(rel);
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    std::fs::write(path, b"").unwrap();
}

fn sample_capture(seed: u64, n: usize) -> Capture {
    let mut rng = Pcg64::seed_from_u64(seed);
    let views = (0..n)
        .map(|i| CaptureView {
            name: format!("view_{i:03}"),
            image: format!("images/view_{i:03}.exr"),
            mask: (i % 2 == 0).then(|| format!("masks/view_{i:03}.png")),
            camera: random_camera(&mut rng),
        })
        .collect();
    let mut capture = Capture::new(views);
    capture.envmap = Some("lighting/studio.exr".into());
    capture.targets = vec![TargetView {
        name: "held_out_0".into(),
        image: "targets/held_out_0.exr".into(),
        mask: None,
        envmap: "lighting/sunset.hdr".into(),
        camera: random_camera(&mut rng),
    }];
    capture.metadata = serde_json::json!({"generator": "test", "seed": seed, "notes": ["a", "b"]});
    capture
}

/// Creates every file the capture refers to.
fn touch_all(dir: &Path, capture: &Capture) {
    for v in &capture.views {
        touch(dir, &v.image);
        if let Some(m) = &v.mask {
            touch(dir, m);
        }
    }
    if let Some(e) = &capture.envmap {
        touch(dir, e);
    }
    for t in &capture.targets {
        touch(dir, &t.image);
        touch(dir, &t.envmap);
    }
}

#[test]
fn save_then_load_is_identical_and_deterministic() {
    let dir = tempfile::tempdir().unwrap();
    let capture = sample_capture(1, 5);
    touch_all(dir.path(), &capture);
    capture.save(dir.path()).unwrap();
    let first = std::fs::read(dir.path().join(CAPTURE_FILE_NAME)).unwrap();
    let loaded = Capture::load(dir.path()).unwrap();
    // Bit-exact f64 (PartialEq on every camera number), paths, names, metadata.
    assert_eq!(loaded, capture);
    assert_eq!(loaded.cameras(), capture.cameras());
    // Saving the loaded capture writes the same bytes; no temporary files are left.
    loaded.save(dir.path()).unwrap();
    assert_eq!(std::fs::read(dir.path().join(CAPTURE_FILE_NAME)).unwrap(), first);
    let entries: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(entries.len(), 5, "{entries:?}"); // cameras.json, images, masks, lighting, targets
    let text = String::from_utf8(first).unwrap();
    assert!(text.contains("\"format\": \"nelf-capture\""));
    assert!(text.contains("\"units\": \"m\""));
    assert!(text.ends_with("}\n"));
}

#[test]
fn f64_values_round_trip_bit_exactly_through_json() {
    // Full-mantissa numbers of every magnitude: the JSON writer prints the shortest
    // round-trip form and the parser (serde_json's float_roundtrip) reads it back exactly.
    let dir = tempfile::tempdir().unwrap();
    let mut rng = Pcg64::seed_from_u64(7);
    let mut capture = sample_capture(2, 200);
    for view in &mut capture.views {
        let c = &mut view.camera;
        c.fx = f64::from_bits(rng.random_range(0x3FF0_0000_0000_0000..0x40C0_0000_0000_0000u64));
        c.fy = c.fx * rng.random::<f64>().mul_add(0.2, 0.9);
        c.cx = rng.random::<f64>() * 1e3;
        c.cy = rng.random::<f64>() * 1e-3 + 240.0;
        c.translation = DVec3::new(
            rng.random::<f64>() * 1e-9,
            -rng.random::<f64>() * 1e7,
            rng.random(),
        );
    }
    touch_all(dir.path(), &capture);
    capture.save(dir.path()).unwrap();
    let loaded = Capture::load(dir.path()).unwrap();
    for (a, b) in loaded.views.iter().zip(&capture.views) {
        let (a, b) = (a.camera, b.camera);
        for (x, y) in [(a.fx, b.fx), (a.fy, b.fy), (a.cx, b.cx), (a.cy, b.cy)] {
            assert_eq!(x.to_bits(), y.to_bits());
        }
        assert_eq!(
            a.translation.to_array().map(f64::to_bits),
            b.translation.to_array().map(f64::to_bits)
        );
        assert_eq!(
            a.rotation.to_cols_array().map(f64::to_bits),
            b.rotation.to_cols_array().map(f64::to_bits)
        );
    }
}

/// A minimal valid `cameras.json` with one view, `units` and the view's camera fields
/// supplied as JSON text.
fn one_view_json(units: &str, image: &str, camera_fields: &str) -> String {
    format!(
        r#"{{
  "format": "nelf-capture",
  "version": 1,
  "units": {units},
  "views": [
    {{
      "name": "front",
      "image": "{image}",
      {camera_fields}
    }}
  ]
}}"#
    )
}

const GOOD_CAMERA: &str = r#""width": 64, "height": 48,
      "intrinsics": {"fx": 80.0, "fy": 80.0, "cx": 32.0, "cy": 24.0},
      "world_to_camera": {"rotation": [[1, 0, 0], [0, -1, 0], [0, 0, -1]], "translation": [0, 150, 2000]}"#;

/// Writes `json` as the capture file of a fresh folder holding `images/front.png`.
fn folder_with(json: &str) -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    touch(dir.path(), "images/front.png");
    std::fs::write(dir.path().join(CAPTURE_FILE_NAME), json).unwrap();
    dir
}

fn load_err(json: &str) -> (CaptureError, String) {
    let dir = folder_with(json);
    let err = Capture::load(dir.path()).unwrap_err();
    let message = err.to_string();
    assert!(
        message.contains(CAPTURE_FILE_NAME),
        "error does not name the file: {message}"
    );
    (err, message)
}

#[test]
fn millimetre_and_other_units_load_as_metres() {
    for (units, scale) in [
        (r#""mm""#, 1e-3),
        (r#""cm""#, 1e-2),
        (r#""m""#, 1.0),
        (r#"{"metres_per_unit": 0.0254}"#, 0.0254),
    ] {
        let dir = folder_with(&one_view_json(units, "images/front.png", GOOD_CAMERA));
        let capture = Capture::load(dir.path()).unwrap();
        let camera = capture.views[0].camera;
        let want = DVec3::new(0.0, 150.0, 2000.0) * scale;
        assert!(
            camera.translation.abs_diff_eq(want, 1e-12 * want.length()),
            "{units}"
        );
        // Intrinsics are pixels: unchanged by units.
        assert_eq!((camera.fx, camera.cx, camera.cy), (80.0, 32.0, 24.0));
        assert_eq!(camera.rotation, DMat3::from_diagonal(DVec3::new(1.0, -1.0, -1.0)));
    }
    // 2000 mm is exactly 2 m (division by 1000 is correctly rounded).
    let dir = folder_with(&one_view_json(r#""mm""#, "images/front.png", GOOD_CAMERA));
    let camera = Capture::load(dir.path()).unwrap().views[0].camera;
    assert_eq!(camera.translation, DVec3::new(0.0, 0.15, 2.0));
    assert!(camera.centre().abs_diff_eq(DVec3::new(0.0, 0.15, 2.0), 1e-15));
}

#[test]
fn rejects_bad_header_and_units() {
    let good = one_view_json(r#""m""#, "images/front.png", GOOD_CAMERA);
    let (err, _) = load_err(&good.replace("\"version\": 1", "\"version\": 2"));
    assert!(matches!(err, CaptureError::UnsupportedVersion { .. }), "{err}");
    let (err, _) = load_err(&good.replace("nelf-capture", "something-else"));
    assert!(matches!(err, CaptureError::WrongFormat { .. }), "{err}");
    let (err, msg) = load_err(&one_view_json(r#""furlong""#, "images/front.png", GOOD_CAMERA));
    assert!(
        matches!(err, CaptureError::BadUnits { .. }) && msg.contains("furlong"),
        "{msg}"
    );
    let (err, _) = load_err(&one_view_json(
        r#"{"metres_per_unit": 0}"#,
        "images/front.png",
        GOOD_CAMERA,
    ));
    assert!(matches!(err, CaptureError::BadUnits { .. }), "{err}");
    // Unknown fields are typos, not extensions (a new field means a new version).
    let (err, msg) = load_err(&good.replace("\"image\"", "\"maks\": \"x.png\", \"image\""));
    assert!(
        matches!(err, CaptureError::Json { .. }) && msg.contains("maks"),
        "{msg}"
    );
    // Not JSON at all: the message has the line.
    let (err, msg) = load_err("{\n  \"format\": \"nelf-capture\",\n  oops\n}");
    assert!(
        matches!(err, CaptureError::Json { .. }) && msg.contains("line 3"),
        "{msg}"
    );
    let (err, _) = load_err(r#"{"format": "nelf-capture", "version": 1, "units": "m", "views": []}"#);
    assert!(matches!(err, CaptureError::NoViews { .. }), "{err}");
}

#[test]
fn missing_capture_file_is_an_io_error_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let err = Capture::load(dir.path()).unwrap_err();
    assert!(matches!(err, CaptureError::Io(_)));
    assert!(err.to_string().contains(CAPTURE_FILE_NAME), "{err}");
}

#[test]
fn rejects_missing_files_and_paths_leaving_the_folder() {
    let (err, msg) = load_err(&one_view_json(r#""m""#, "images/back.png", GOOD_CAMERA));
    assert!(matches!(err, CaptureError::MissingFile { .. }), "{err}");
    assert!(msg.contains("\"front\"") && msg.contains("back.png"), "{msg}");
    for bad in [
        "../outside.png",
        "images/../../outside.png",
        "/etc/front.png",
        "C:/front.png",
    ] {
        let (err, msg) = load_err(&one_view_json(r#""m""#, bad, GOOD_CAMERA));
        assert!(matches!(err, CaptureError::BadPath { .. }), "{bad}: {err}");
        assert!(msg.contains("\"front\"") && msg.contains(bad), "{msg}");
    }
    let (err, _) = load_err(&one_view_json(r#""m""#, "images/front.gif", GOOD_CAMERA));
    assert!(matches!(err, CaptureError::BadPath { .. }), "{err}");
    // A missing mask names the mask.
    let with_mask = one_view_json(r#""m""#, "images/front.png", GOOD_CAMERA)
        .replace("\"image\"", "\"mask\": \"masks/front.png\", \"image\"");
    let (err, msg) = load_err(&with_mask);
    assert!(
        matches!(err, CaptureError::MissingFile { .. }) && msg.contains("mask"),
        "{msg}"
    );
}

#[test]
fn rejects_bad_cameras_naming_the_view() {
    let json = |camera: &str| one_view_json(r#""m""#, "images/front.png", camera);
    // Overflowing numbers cannot be represented: the JSON parser names the line.
    let (err, msg) = load_err(&json(&GOOD_CAMERA.replace("\"fx\": 80.0", "\"fx\": 1e999")));
    assert!(
        matches!(err, CaptureError::Json { .. }) && msg.contains("line"),
        "{msg}"
    );
    // Non-finite after the unit conversion.
    let huge = one_view_json(r#"{"metres_per_unit": 1e306}"#, "images/front.png", GOOD_CAMERA);
    let (err, msg) = load_err(&huge);
    assert!(
        matches!(err, CaptureError::NonFinite { .. }) && msg.contains("\"front\""),
        "{msg}"
    );
    let (err, msg) = load_err(&json(&GOOD_CAMERA.replace("\"fy\": 80.0", "\"fy\": -80.0")));
    assert!(
        matches!(err, CaptureError::BadCamera { .. }) && msg.contains("fy"),
        "{msg}"
    );
    let (err, _) = load_err(&json(&GOOD_CAMERA.replace("\"width\": 64", "\"width\": 0")));
    assert!(matches!(err, CaptureError::BadCamera { .. }), "{err}");
    // 2% scale: rejected, and the message says how far off.
    let scaled = GOOD_CAMERA.replace("[[1, 0, 0]", "[[1.01, 0, 0]");
    let (err, msg) = load_err(&json(&scaled));
    match err {
        CaptureError::NotARotation { deviation, .. } => {
            assert!((deviation - 0.0201).abs() < 1e-9, "{deviation}");
        }
        other => panic!("{other}"),
    }
    assert!(msg.contains("2.010e-2") && msg.contains("\"front\""), "{msg}");
    // A reflection (det −1) is orthonormal but not a rotation.
    let reflected = GOOD_CAMERA.replace("[0, 0, -1]]", "[0, 0, 1]]");
    let (err, _) = load_err(&json(&reflected));
    assert!(matches!(err, CaptureError::NotARotation { .. }), "{err}");
}

#[test]
fn nearly_orthonormal_rotations_are_snapped() {
    // Six printed decimals of a rotation about y: off by ~1e-7, accepted and made exact.
    let (s, c) = 0.5f64.sin_cos();
    let rotation = format!("[[{c:.6}, 0, {s:.6}], [0, 1, 0], [{:.6}, 0, {c:.6}]]", -s);
    let camera = GOOD_CAMERA.replace("[[1, 0, 0], [0, -1, 0], [0, 0, -1]]", &rotation);
    let dir = folder_with(&one_view_json(r#""m""#, "images/front.png", &camera));
    let loaded = Capture::load(dir.path()).unwrap().views[0].camera;
    let r = loaded.rotation;
    assert!((r.transpose() * r).abs_diff_eq(DMat3::IDENTITY, 1e-15));
    assert!(r.abs_diff_eq(DMat3::from_rotation_y(0.5), 1e-6));
    loaded.validate().unwrap();
}

#[test]
fn rejects_duplicate_names_and_bad_saves() {
    let dir = tempfile::tempdir().unwrap();
    let mut capture = sample_capture(3, 3);
    capture.views[2].name = "view_000".into();
    let err = capture.save(dir.path()).unwrap_err();
    assert!(matches!(err, CaptureError::DuplicateName { .. }), "{err}");
    // Names are unique across views and targets.
    let mut capture = sample_capture(3, 3);
    capture.targets[0].name = "view_001".into();
    assert!(matches!(
        capture.save(dir.path()),
        Err(CaptureError::DuplicateName { .. })
    ));
    // NaN cannot be written (JSON has no NaN); the error names the view and field.
    let mut capture = sample_capture(3, 3);
    capture.views[1].camera.translation.z = f64::NAN;
    let err = capture.save(dir.path()).unwrap_err();
    let msg = err.to_string();
    assert!(matches!(err, CaptureError::NonFinite { .. }), "{msg}");
    assert!(msg.contains("view_001") && msg.contains("translation[2]") && msg.contains(CAPTURE_FILE_NAME));
    let mut capture = sample_capture(3, 3);
    capture.targets[0].envmap = "../elsewhere.exr".into();
    assert!(matches!(
        capture.save(dir.path()),
        Err(CaptureError::BadPath { .. })
    ));
    // Nothing was written by the failed saves.
    assert!(!dir.path().join(CAPTURE_FILE_NAME).exists());
    // Saving before the images exist is allowed; loading then names the first missing file.
    sample_capture(3, 3).save(dir.path()).unwrap();
    let err = Capture::load(dir.path()).unwrap_err();
    assert!(matches!(err, CaptureError::MissingFile { .. }) && err.to_string().contains("view_000"));
}

#[test]
fn the_example_in_capture_md_loads() {
    let doc = include_str!("../CAPTURE.md");
    let start = doc.find("```json\n").unwrap() + "```json\n".len();
    let json = &doc[start..start + doc[start..].find("```").unwrap()];
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join(CAPTURE_FILE_NAME), json).unwrap();
    // Files do not exist yet: the loader names the first one missing.
    let err = Capture::load(dir.path()).unwrap_err();
    assert!(err.to_string().contains("images/view_000.exr"), "{err}");
    for rel in [
        "images/view_000.exr",
        "masks/view_000.png",
        "images/view_001.png",
        "lighting/studio.exr",
        "targets/target_000.exr",
        "lighting/sunset.hdr",
    ] {
        touch(dir.path(), rel);
    }
    let capture = Capture::load(dir.path()).unwrap();
    let root3 = 3f64.sqrt();
    let want = [
        DVec3::new(0.0, 0.0, 2.0),
        DVec3::new(1.0, 0.0, root3),
        DVec3::new(2.0, 0.0, 0.0),
    ];
    let cameras: Vec<PinholeCamera> = capture
        .cameras()
        .into_iter()
        .chain([capture.targets[0].camera])
        .collect();
    for (camera, centre) in cameras.iter().zip(want) {
        assert!(
            camera.centre().abs_diff_eq(centre, 1e-12),
            "{:?} vs {centre:?}",
            camera.centre()
        );
        // Looks at the origin, world +y up in the image.
        assert!(camera.forward().abs_diff_eq(-centre / 2.0, 1e-12));
        let p = camera.project(DVec3::ZERO).unwrap();
        assert!((p.x - camera.cx).abs() < 1e-9 && (p.y - camera.cy).abs() < 1e-9);
        assert!(camera.project(DVec3::new(0.0, 0.1, 0.0)).unwrap().y < camera.cy);
    }
    assert_eq!(capture.views[0].mask.as_deref(), Some("masks/view_000.png"));
    assert_eq!(capture.targets[0].envmap, "lighting/sunset.hdr");
    assert_eq!(capture.metadata["subject"], "procedural head");
}
