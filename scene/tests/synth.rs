//! Synthetic captures: what is written reads back identically (cameras.json and
//! COLMAP), cameras sit where the configuration says, and runs are deterministic.
#![allow(clippy::unwrap_used)]

use indicatif::ProgressBar;
use nelf_format::capture::Capture;
use nelf_format::colmap::read_colmap_text;
use nelf_scene::synth::{SynthConfig, source_viewpoints, target_viewpoints, write_synthetic_capture};

fn tiny() -> SynthConfig {
    SynthConfig {
        width: 24,
        height: 20,
        head_cells: 40,
        texel_samples: 1,
        indirect_samples: 4,
        bounces: 1,
        ..SynthConfig::default()
    }
}

#[test]
fn capture_round_trips_and_is_deterministic() {
    let dir = tempfile::tempdir().unwrap();
    let config = tiny();
    let report = write_synthetic_capture(&config, dir.path(), &ProgressBar::hidden()).unwrap();
    assert_eq!((report.views, report.targets), (5, 2));

    let capture = Capture::load(dir.path()).unwrap();
    assert_eq!(capture.views.len(), 5);
    assert_eq!(capture.targets.len(), 2);
    let colmap = read_colmap_text(dir.path().join("colmap"), 1.0).unwrap();
    for (view, (name, cam)) in capture.views.iter().zip(&colmap) {
        assert_eq!(name, &format!("{}.exr", view.name));
        assert_eq!((cam.width, cam.height), (view.camera.width, view.camera.height));
        assert_eq!(
            (cam.fx, cam.fy, cam.cx, cam.cy),
            (view.camera.fx, view.camera.fy, view.camera.cx, view.camera.cy)
        );
        assert!(cam.rotation.abs_diff_eq(view.camera.rotation, 1e-12));
        assert!(cam.translation.abs_diff_eq(view.camera.translation, 1e-12));
    }

    // View 0 is frontal: on +z of the head centre, looking along −z.
    let centre = capture.metadata["head_centre_m"].as_array().unwrap();
    let centre = glam::DVec3::new(
        centre[0].as_f64().unwrap(),
        centre[1].as_f64().unwrap(),
        centre[2].as_f64().unwrap(),
    );
    let front = capture.views[0].camera;
    let offset = front.centre() - centre;
    assert!(offset.x.abs() < 1e-9 && offset.y.abs() < 1e-9 && offset.z > 1.0);
    assert!(front.forward().abs_diff_eq(glam::DVec3::NEG_Z, 1e-9));
    let cameras = capture
        .views
        .iter()
        .map(|v| (&v.name, v.camera))
        .chain(capture.targets.iter().map(|t| (&t.name, t.camera)));
    for (name, camera) in cameras {
        let d = camera.centre() - centre;
        let distance = d.length();
        assert!(
            (1.0 - 1e-9..=2.0 + 1e-9).contains(&distance),
            "{name}: {distance}"
        );
        let azimuth = d.x.atan2(d.z).to_degrees();
        let elevation = (d.y / distance).asin().to_degrees();
        assert!(
            azimuth.abs() <= 30.0 + 1e-6 && elevation.abs() <= 30.0 + 1e-6,
            "{name}"
        );
        // The head centre projects to the image centre.
        let c = camera.project(centre).unwrap();
        assert!((c.x - 12.0).abs() < 1e-6 && (c.y - 10.0).abs() < 1e-6);
    }

    // Images are finite, non-negative and the masks cover the head but not the corners.
    for view in &capture.views {
        let img = image::open(view.image_path(dir.path())).unwrap().into_rgb32f();
        assert!(img.as_raw().iter().all(|v| v.is_finite() && *v >= 0.0));
        let mask = image::open(view.mask_path(dir.path()).unwrap())
            .unwrap()
            .into_luma8();
        let covered = mask.as_raw().iter().filter(|&&m| m > 127).count();
        assert!(covered > 24 * 20 / 8, "{}: {covered} covered pixels", view.name);
        assert_eq!(mask.get_pixel(0, 0).0[0], 0);
    }

    // Same configuration → identical files.
    let again = tempfile::tempdir().unwrap();
    write_synthetic_capture(&config, again.path(), &ProgressBar::hidden()).unwrap();
    for rel in [
        "cameras.json",
        "images/view_003.exr",
        "masks/view_001.png",
        "targets/target_001.exr",
        "colmap/images.txt",
    ] {
        assert_eq!(
            std::fs::read(dir.path().join(rel)).unwrap(),
            std::fs::read(again.path().join(rel)).unwrap(),
            "{rel} differs between runs"
        );
    }
}

#[test]
fn viewpoints_spread_and_stay_in_the_cone() {
    let config = SynthConfig {
        views: 9,
        targets: 4,
        ..SynthConfig::default()
    };
    let sources = source_viewpoints(&config);
    let targets = target_viewpoints(&config);
    assert_eq!((sources.len(), targets.len()), (9, 4));
    assert_eq!((sources[0].azimuth_rad, sources[0].elevation_rad), (0.0, 0.0));
    let max = 30f64.to_radians();
    for v in sources.iter().chain(&targets) {
        assert!(v.azimuth_rad.abs() <= max && v.elevation_rad.abs() <= max);
    }
    // Ring views are at least 60 % of the way out; targets differ from every source.
    for v in &sources[1..] {
        assert!(v.azimuth_rad.hypot(v.elevation_rad) >= 0.6 * max - 1e-9);
    }
    for t in &targets {
        for s in &sources {
            assert!((t.direction() - s.direction()).length() > 1e-3);
        }
    }
}

#[test]
fn bad_settings_are_rejected_before_work() {
    let dir = tempfile::tempdir().unwrap();
    for config in [
        SynthConfig { views: 1, ..tiny() },
        SynthConfig { width: 4, ..tiny() },
        SynthConfig {
            min_distance_m: 3.0,
            ..tiny()
        },
        SynthConfig {
            targets: 2,
            target_envmap: vec!["a.exr".into()],
            ..tiny()
        },
    ] {
        let err = write_synthetic_capture(&config, dir.path(), &ProgressBar::hidden()).unwrap_err();
        assert!(
            err.to_string().contains("invalid synthetic capture settings"),
            "{err}"
        );
    }
    let missing = SynthConfig {
        mesh: Some(dir.path().join("nope.obj")),
        ..tiny()
    };
    let err = write_synthetic_capture(&missing, dir.path(), &ProgressBar::hidden()).unwrap_err();
    assert!(err.to_string().contains("nope.obj"), "{err}");
}
