//! COLMAP text models: write → read round trips, a hand-written model with the
//! format's quirks, and typed errors naming the file and line.

// Test helpers outside #[test] functions fail the test on setup errors by panicking.
#![allow(clippy::unwrap_used)]

use std::path::Path;

use glam::{DMat3, DVec3};
use nelf_format::colmap::{ColmapError, read_colmap_text, write_colmap_text};
use nelf_format::conventions::PinholeCamera;
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

fn random_views(seed: u64, n: usize) -> Vec<(String, PinholeCamera)> {
    let mut rng = Pcg64::seed_from_u64(seed);
    (0..n)
        .map(|i| {
            let eye = DVec3::new(
                rng.random_range(-3.0..3.0),
                rng.random_range(-3.0..3.0),
                rng.random_range(-3.0..3.0),
            );
            let up = DVec3::new(rng.random_range(-0.3..0.3), 1.0, rng.random_range(-0.3..0.3));
            let mut camera = PinholeCamera::look_at(eye, DVec3::ZERO, up, 800 + i as u32, 600, 0.8);
            camera.fx = rng.random_range(300.0..2000.0);
            camera.fy = rng.random_range(300.0..2000.0);
            camera.cx = rng.random_range(390.0..410.0);
            camera.cy = rng.random_range(290.0..310.0);
            (format!("img_{i:04}.png"), camera)
        })
        .collect()
}

#[test]
fn write_then_read_round_trips() {
    let dir = tempfile::tempdir().unwrap();
    let views = random_views(5, 64);
    write_colmap_text(dir.path(), &views).unwrap();
    assert!(dir.path().join("points3D.txt").is_file());
    let read = read_colmap_text(dir.path(), 1.0).unwrap();
    assert_eq!(read.len(), views.len());
    let mut worst_rotation = 0.0f64;
    for ((name_a, a), (name_b, b)) in read.iter().zip(&views) {
        assert_eq!(name_a, name_b);
        assert_eq!(
            (a.width, a.height, a.fx, a.fy, a.cx, a.cy),
            (b.width, b.height, b.fx, b.fy, b.cx, b.cy)
        );
        assert_eq!(a.translation, b.translation);
        let diff = (a.rotation - b.rotation).to_cols_array();
        worst_rotation = diff.iter().fold(worst_rotation, |m, d| m.max(d.abs()));
    }
    eprintln!("COLMAP round trip: largest rotation entry difference {worst_rotation:e}");
    assert!(worst_rotation < 1e-12, "rotation differs by {worst_rotation:e}");
    // Writing what was read gives the same files.
    let again = tempfile::tempdir().unwrap();
    write_colmap_text(again.path(), &read).unwrap();
    for file in ["cameras.txt", "points3D.txt"] {
        assert_eq!(
            std::fs::read_to_string(dir.path().join(file)).unwrap(),
            std::fs::read_to_string(again.path().join(file)).unwrap()
        );
    }
}

fn write_model(dir: &Path, cameras: &str, images: &str) {
    std::fs::write(dir.join("cameras.txt"), cameras).unwrap();
    std::fs::write(dir.join("images.txt"), images).unwrap();
}

#[test]
fn parses_a_hand_written_model() {
    let cameras = "\u{feff}# Camera list with one line of data per camera:\r\n\
                   #   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\r\n\
                   \r\n\
                   7 SIMPLE_PINHOLE 640 480 500 320 240\r\n\
                   3   OPENCV 1024 768 900.5 901.25 512 384.5 0 0 0.0 -0\r\n\
                   4 PINHOLE 100 50 60 61 49.5 25\r\n";
    // Images out of id order, a non-empty 2D-points line, a name with a space, a
    // non-unit quaternion, CRLF, and a last image with no points line before EOF.
    let (s, c) = (0.25f64.sin(), 0.25f64.cos()); // half of 0.5 rad
    let images = format!(
        "# Image list with two lines of data per image:\r\n\
         #   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME\r\n\
         #   POINTS2D[] as (X, Y, POINT3D_ID)\r\n\
         \r\n\
         20 {} 0 {} 0 10 -20 300 3 back view.jpg\r\n\
         \r\n\
         5 2 0 0 0 1 2 3 7 front.jpg\r\n\
         12.5 33.0 -1 40 41 17\r\n\
         9 1 0 0 0 0 0 0 4 side.png",
        2.0 * c,
        2.0 * s,
    );
    let dir = tempfile::tempdir().unwrap();
    write_model(dir.path(), cameras, &images);
    let read = read_colmap_text(dir.path(), 0.01).unwrap();
    let names: Vec<&str> = read.iter().map(|(n, _)| n.as_str()).collect();
    assert_eq!(names, ["front.jpg", "side.png", "back view.jpg"]);

    let front = read[0].1;
    assert_eq!((front.width, front.height), (640, 480));
    assert_eq!(
        (front.fx, front.fy, front.cx, front.cy),
        (500.0, 500.0, 320.0, 240.0)
    );
    assert_eq!(front.rotation, DMat3::IDENTITY);
    assert!(front.translation.abs_diff_eq(DVec3::new(0.01, 0.02, 0.03), 1e-15));

    let side = read[1].1;
    assert_eq!((side.fx, side.fy, side.cx, side.cy), (60.0, 61.0, 49.5, 25.0));

    let back = read[2].1;
    assert_eq!((back.width, back.height), (1024, 768));
    assert_eq!(
        (back.fx, back.fy, back.cx, back.cy),
        (900.5, 901.25, 512.0, 384.5)
    );
    // q = (cos ½α, 0, sin ½α, 0) scaled by 2: a rotation by α = 0.5 about +y (Hamilton).
    assert!(back.rotation.abs_diff_eq(DMat3::from_rotation_y(0.5), 1e-15));
    assert!(back.translation.abs_diff_eq(DVec3::new(0.1, -0.2, 3.0), 1e-15));
}

/// Loads a model expecting an error; checks the message names `file` and `line`.
fn read_err(cameras: &str, images: &str, file: &str, line: usize) -> ColmapError {
    let dir = tempfile::tempdir().unwrap();
    write_model(dir.path(), cameras, images);
    let err = read_colmap_text(dir.path(), 1.0).unwrap_err();
    let message = err.to_string();
    assert!(
        message.contains(&format!("{file}:{line}:")),
        "expected {file}:{line} in {message}"
    );
    err
}

const CAMERA: &str = "1 PINHOLE 64 48 50 50 32 24\n";
const IMAGE: &str = "# comment\n1 1 0 0 0 0 0 1 1 a.png\n\n";

#[test]
fn rejects_distortion_and_unknown_models() {
    let err = read_err(
        "# c\n\n1 OPENCV 64 48 50 50 32 24 0.01 0 0 0\n",
        IMAGE,
        "cameras.txt",
        3,
    );
    assert!(
        matches!(err, ColmapError::Distorted { camera_id: 1, .. }),
        "{err}"
    );
    assert!(err.to_string().contains("0.01"));
    let err = read_err("1 SIMPLE_RADIAL 64 48 50 32 24 0.1\n", IMAGE, "cameras.txt", 1);
    assert!(matches!(err, ColmapError::UnsupportedModel { .. }) && err.to_string().contains("SIMPLE_RADIAL"));
    let err = read_err("1 PINHOLE 64 48 50 50 32\n", IMAGE, "cameras.txt", 1);
    assert!(matches!(err, ColmapError::Syntax { .. }), "{err}");
    let err = read_err("1 PINHOLE 64 48 50 inf 32 24\n", IMAGE, "cameras.txt", 1);
    assert!(matches!(err, ColmapError::NonFinite { .. }), "{err}");
    let err = read_err("1 PINHOLE 64 48 -50 50 32 24\n", IMAGE, "cameras.txt", 1);
    assert!(matches!(err, ColmapError::InvalidCamera { .. }), "{err}");
    let err = read_err(
        "1 PINHOLE 64 48 50 50 32 24\n1 PINHOLE 64 48 50 50 32 24\n",
        IMAGE,
        "cameras.txt",
        2,
    );
    assert!(
        matches!(err, ColmapError::Duplicate { first_line: 1, .. }),
        "{err}"
    );
}

#[test]
fn rejects_bad_images() {
    let err = read_err(CAMERA, "1 0 0 0 0 0 0 1 1 a.png\n\n", "images.txt", 1);
    assert!(matches!(err, ColmapError::BadQuaternion { .. }), "{err}");
    let err = read_err(CAMERA, "\n\n1 1 0 0 0 0 0 1 2 a.png\n\n", "images.txt", 3);
    assert!(
        matches!(err, ColmapError::UnknownCamera { camera_id: 2, .. }),
        "{err}"
    );
    let err = read_err(CAMERA, "1 1 0 0 0 NaN 0 1 1 a.png\n\n", "images.txt", 1);
    assert!(matches!(err, ColmapError::NonFinite { field: "TX", .. }), "{err}");
    let err = read_err(CAMERA, "1 1 0 0 0 0 0 1\n\n", "images.txt", 1);
    assert!(matches!(err, ColmapError::Syntax { .. }), "{err}");
    // A forgotten 2D-points line would swallow the next image: rejected, not skipped.
    let err = read_err(
        CAMERA,
        "1 1 0 0 0 0 0 1 1 a.png\n2 1 0 0 0 0 0 1 1 b.png\n\n",
        "images.txt",
        2,
    );
    assert!(
        matches!(err, ColmapError::Syntax { .. }) && err.to_string().contains("2D-points"),
        "{err}"
    );
    let err = read_err(
        CAMERA,
        "1 1 0 0 0 0 0 1 1 a.png\n\n1 1 0 0 0 0 0 1 1 b.png\n\n",
        "images.txt",
        3,
    );
    assert!(
        matches!(err, ColmapError::Duplicate { what: "image id", .. }),
        "{err}"
    );
    let err = read_err(
        CAMERA,
        "1 1 0 0 0 0 0 1 1 a.png\n\n2 1 0 0 0 0 0 1 1 a.png\n\n",
        "images.txt",
        3,
    );
    assert!(
        matches!(
            err,
            ColmapError::Duplicate {
                what: "image name",
                ..
            }
        ),
        "{err}"
    );
}

#[test]
fn missing_files_and_bad_arguments() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("cameras.txt"), CAMERA).unwrap();
    let err = read_colmap_text(dir.path(), 1.0).unwrap_err();
    assert!(
        matches!(err, ColmapError::Io(_)) && err.to_string().contains("images.txt"),
        "{err}"
    );
    assert!(matches!(
        read_colmap_text(dir.path(), 0.0),
        Err(ColmapError::BadScale(_))
    ));
    assert!(matches!(
        read_colmap_text(dir.path(), f64::NAN),
        Err(ColmapError::BadScale(_))
    ));

    let mut views = random_views(1, 2);
    views[1].0 = "has space.png".into();
    assert!(matches!(
        write_colmap_text(dir.path(), &views),
        Err(ColmapError::InvalidInput { .. })
    ));
    let mut views = random_views(1, 2);
    views[1].0 = views[0].0.clone();
    assert!(matches!(
        write_colmap_text(dir.path(), &views),
        Err(ColmapError::InvalidInput { .. })
    ));
    let mut views = random_views(1, 2);
    views[0].1.rotation *= 2.0;
    assert!(matches!(
        write_colmap_text(dir.path(), &views),
        Err(ColmapError::InvalidInput { .. })
    ));
    // Failed writes leave nothing behind.
    assert!(!dir.path().join("images.txt").exists());
}
