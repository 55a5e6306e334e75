//! Capture loading: our `cameras.json` folders and COLMAP text folders decode to
//! the right cameras, linear images and masks; every broken input is an error
//! naming the file.

#![allow(clippy::unwrap_used)] // Test helpers outside #[test] functions unwrap too.

mod common;

use std::path::Path;

use common::{SPHERE_CENTRE, five_cameras, sphere_mask};
use glam::DMat3;
use image::{ImageBuffer, Luma, Rgb, Rgba};
use nelf_bake::{BakeError, CaptureFormat, CaptureLoadOptions, load_capture};
use nelf_format::capture::{Capture, CaptureView};
use nelf_format::colmap::write_colmap_text;
use nelf_format::conventions::PinholeCamera;
use nelf_scene::mesh_io::srgb_to_linear;

const SIZE: u32 = 24;
const COLOUR: [f32; 3] = [0.5, 0.3, 0.2];

fn cameras() -> Vec<PinholeCamera> {
    five_cameras(SIZE)[..3].to_vec()
}

fn write_exr(path: &Path, w: u32, h: u32, rgb: &[[f32; 3]]) {
    let data: Vec<f32> = rgb.iter().flatten().copied().collect();
    ImageBuffer::<Rgb<f32>, _>::from_raw(w, h, data)
        .unwrap()
        .save(path)
        .unwrap();
}

fn write_mask(path: &Path, w: u32, h: u32, mask: &[f32]) {
    let data: Vec<u8> = mask.iter().map(|&m| (m * 255.0).round() as u8).collect();
    ImageBuffer::<Luma<u8>, _>::from_raw(w, h, data)
        .unwrap()
        .save(path)
        .unwrap();
}

/// A three-view `cameras.json` capture of the sphere: EXR images (the sphere's
/// coverage times a colour) and PNG masks.
fn json_capture(dir: &Path) -> Capture {
    std::fs::create_dir_all(dir.join("images")).unwrap();
    std::fs::create_dir_all(dir.join("masks")).unwrap();
    let mut views = Vec::new();
    for (i, cam) in cameras().into_iter().enumerate() {
        let name = format!("view_{i:03}");
        let mask = sphere_mask(&cam);
        let rgb: Vec<[f32; 3]> = mask.iter().map(|&m| COLOUR.map(|c| c * m)).collect();
        write_exr(&dir.join(format!("images/{name}.exr")), SIZE, SIZE, &rgb);
        write_mask(&dir.join(format!("masks/{name}.png")), SIZE, SIZE, &mask);
        views.push(CaptureView {
            image: format!("images/{name}.exr"),
            mask: Some(format!("masks/{name}.png")),
            name,
            camera: cam,
        });
    }
    let capture = Capture::new(views);
    capture.save(dir).unwrap();
    capture
}

fn load(dir: &Path) -> Result<nelf_bake::LoadedCapture, BakeError> {
    load_capture(dir, &CaptureLoadOptions::default())
}

fn assert_names(err: &BakeError, needle: &str) {
    let msg = err.to_string();
    assert!(msg.contains(needle), "error {msg:?} does not name {needle:?}");
}

#[test]
fn cameras_json_capture_loads() {
    let tmp = tempfile::tempdir().unwrap();
    json_capture(tmp.path());
    let c = load(tmp.path()).unwrap();
    assert_eq!(c.len(), 3);
    assert_eq!(c.names, ["view_000", "view_001", "view_002"]);
    assert_eq!(c.cameras, cameras());
    assert!(
        c.head_centre_m.abs_diff_eq(SPHERE_CENTRE, 1e-9),
        "{}",
        c.head_centre_m
    );
    let mask = sphere_mask(&c.cameras[1]);
    for (i, (&m, (px, &got))) in mask.iter().zip(c.images[1].iter().zip(&c.masks[1])).enumerate() {
        // EXR is linear: read back exactly; the 8-bit mask to within half a step.
        assert_eq!(*px, COLOUR.map(|x| x * m), "pixel {i}");
        assert!((got - m).abs() <= 0.5 / 255.0 + 1e-6, "mask pixel {i}");
    }
    assert!(c.description().is_some());
}

#[test]
fn each_broken_capture_names_the_file() {
    // Missing image: cameras.json's own check names the file.
    let tmp = tempfile::tempdir().unwrap();
    json_capture(tmp.path());
    std::fs::remove_file(tmp.path().join("images/view_001.exr")).unwrap();
    assert_names(&load(tmp.path()).unwrap_err(), "view_001.exr");

    // Image of the wrong size.
    let tmp = tempfile::tempdir().unwrap();
    json_capture(tmp.path());
    write_exr(&tmp.path().join("images/view_001.exr"), 10, 10, &[[0.0; 3]; 100]);
    let err = load(tmp.path()).unwrap_err();
    assert!(matches!(err, BakeError::SizeMismatch { .. }), "{err}");
    assert_names(&err, "images/view_001.exr");

    // Mask of the wrong size.
    let tmp = tempfile::tempdir().unwrap();
    json_capture(tmp.path());
    write_mask(&tmp.path().join("masks/view_002.png"), 10, 10, &[1.0; 100]);
    let err = load(tmp.path()).unwrap_err();
    assert!(matches!(err, BakeError::SizeMismatch { .. }), "{err}");
    assert_names(&err, "masks/view_002.png");

    // A mask with no foreground.
    let tmp = tempfile::tempdir().unwrap();
    json_capture(tmp.path());
    write_mask(
        &tmp.path().join("masks/view_000.png"),
        SIZE,
        SIZE,
        &vec![0.2; (SIZE * SIZE) as usize],
    );
    let err = load(tmp.path()).unwrap_err();
    assert!(matches!(err, BakeError::EmptyMask { .. }), "{err}");
    assert_names(&err, "masks/view_000.png");

    // No mask file and no alpha channel.
    let tmp = tempfile::tempdir().unwrap();
    let mut capture = json_capture(tmp.path());
    capture.views[2].mask = None;
    capture.save(tmp.path()).unwrap();
    let err = load(tmp.path()).unwrap_err();
    assert!(matches!(err, BakeError::NoMask { .. }), "{err}");
    assert_names(&err, "images/view_002.exr");

    // A camera facing away from the head: its optical axis still passes through the
    // head centre, which is now behind it.
    let tmp = tempfile::tempdir().unwrap();
    let mut capture = json_capture(tmp.path());
    let cam = &mut capture.views[1].camera;
    let centre = cam.centre();
    cam.rotation = DMat3::from_diagonal(glam::DVec3::new(-1.0, 1.0, -1.0)) * cam.rotation;
    cam.translation = -(cam.rotation * centre);
    capture.save(tmp.path()).unwrap();
    let err = load(tmp.path()).unwrap_err();
    assert!(matches!(err, BakeError::CameraBehindHead { .. }), "{err}");
    assert_names(&err, "cameras.json");
    assert_names(&err, "view_001");

    // Fewer than two views.
    let tmp = tempfile::tempdir().unwrap();
    let mut capture = json_capture(tmp.path());
    capture.views.truncate(1);
    capture.save(tmp.path()).unwrap();
    let err = load(tmp.path()).unwrap_err();
    assert!(matches!(err, BakeError::TooFewViews { count: 1, .. }), "{err}");
    assert_names(&err, "cameras.json");

    // A translation that is not finite after the unit conversion.
    let tmp = tempfile::tempdir().unwrap();
    json_capture(tmp.path());
    let path = tmp.path().join("cameras.json");
    let text = std::fs::read_to_string(&path).unwrap();
    assert!(text.contains("\"units\": \"m\""));
    let text = text.replacen("\"units\": \"m\"", "\"units\": { \"metres_per_unit\": 1e300 }", 1);
    std::fs::write(&path, fix_first_translation(&text)).unwrap();
    assert_names(&load(tmp.path()).unwrap_err(), "cameras.json");

    // No capture at all.
    let tmp = tempfile::tempdir().unwrap();
    let err = load(tmp.path()).unwrap_err();
    assert!(matches!(err, BakeError::NoCapture { .. }), "{err}");
    assert_names(&err, &tmp.path().display().to_string());
}

/// Replaces the first `"translation": [..]` with `[1e300, 0, 0]`.
fn fix_first_translation(text: &str) -> String {
    let start = text.find("\"translation\": [").unwrap() + "\"translation\": [".len();
    let end = start + text[start..].find(']').unwrap();
    format!("{}1e300, 0, 0{}", &text[..start], &text[end..])
}

/// A COLMAP folder: text model, sRGB PNG images with alpha, a mask file for view 0.
fn colmap_capture(dir: &Path, model_dir: &Path) {
    std::fs::create_dir_all(dir.join("images")).unwrap();
    std::fs::create_dir_all(dir.join("masks")).unwrap();
    let mut model = Vec::new();
    for (i, cam) in cameras().into_iter().enumerate() {
        let name = format!("IMG_{i}.png");
        let mask = sphere_mask(&cam);
        let data: Vec<u8> = mask
            .iter()
            .enumerate()
            .flat_map(|(p, &m)| [(p % 251) as u8, 128, 255, (m * 255.0).round() as u8])
            .collect();
        ImageBuffer::<Rgba<u8>, _>::from_raw(SIZE, SIZE, data)
            .unwrap()
            .save(dir.join("images").join(&name))
            .unwrap();
        if i == 0 {
            write_mask(
                &dir.join("masks/IMG_0.png"),
                SIZE,
                SIZE,
                &vec![1.0; (SIZE * SIZE) as usize],
            );
        }
        model.push((name, cam));
    }
    write_colmap_text(model_dir, &model).unwrap();
}

#[test]
fn colmap_capture_loads() {
    let tmp = tempfile::tempdir().unwrap();
    colmap_capture(tmp.path(), tmp.path());
    let c = load(tmp.path()).unwrap();
    assert_eq!(c.names, ["IMG_0.png", "IMG_1.png", "IMG_2.png"]);
    assert!(c.description().is_none());
    for (got, want) in c.cameras.iter().zip(cameras()) {
        assert_eq!(got.translation, want.translation);
        assert_eq!(
            (got.fx, got.fy, got.cx, got.cy),
            (want.fx, want.fy, want.cx, want.cy)
        );
        assert!(got.rotation.abs_diff_eq(want.rotation, 1e-12));
    }
    // PNG is sRGB: decoded to linear.
    assert_eq!(
        c.images[1][7],
        [srgb_to_linear(7.0 / 255.0), srgb_to_linear(128.0 / 255.0), 1.0]
    );
    // View 0 has a mask file (all ones); the others use the alpha channel.
    assert!(c.masks[0].iter().all(|&m| m == 1.0));
    let alpha = sphere_mask(&c.cameras[2]);
    for (a, m) in alpha.iter().zip(&c.masks[2]) {
        assert!((a - m).abs() <= 0.5 / 255.0 + 1e-6);
    }

    // Scale: translations are multiplied by the metres per unit.
    let half = load_capture(
        tmp.path(),
        &CaptureLoadOptions {
            format: CaptureFormat::Colmap,
            metres_per_unit: 0.5,
        },
    )
    .unwrap();
    assert_eq!(half.cameras[1].translation, cameras()[1].translation * 0.5);

    // The sparse/0 layout.
    let tmp = tempfile::tempdir().unwrap();
    colmap_capture(tmp.path(), &tmp.path().join("sparse/0"));
    assert_eq!(load(tmp.path()).unwrap().len(), 3);
}

#[test]
fn broken_colmap_models_name_the_file() {
    // A non-finite pose.
    let tmp = tempfile::tempdir().unwrap();
    colmap_capture(tmp.path(), tmp.path());
    let images = tmp.path().join("images.txt");
    let text = std::fs::read_to_string(&images).unwrap();
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    let first = lines
        .iter()
        .position(|l| !l.starts_with('#') && !l.is_empty())
        .unwrap();
    let mut fields: Vec<String> = lines[first].split_whitespace().map(str::to_string).collect();
    fields[5] = "nan".into();
    lines[first] = fields.join(" ");
    std::fs::write(&images, lines.join("\n") + "\n").unwrap();
    assert_names(&load(tmp.path()).unwrap_err(), "images.txt");

    // A distorted camera.
    let tmp = tempfile::tempdir().unwrap();
    colmap_capture(tmp.path(), tmp.path());
    let cams = tmp.path().join("cameras.txt");
    let text = std::fs::read_to_string(&cams).unwrap();
    let text = text.replacen(" PINHOLE ", " OPENCV ", 1);
    let text = text
        .lines()
        .map(|l| {
            if l.contains(" OPENCV ") {
                format!("{l} 0.1 0 0 0")
            } else {
                l.to_string()
            }
        })
        .collect::<Vec<_>>()
        .join("\n");
    std::fs::write(&cams, text + "\n").unwrap();
    assert_names(&load(tmp.path()).unwrap_err(), "cameras.txt");

    // A missing image.
    let tmp = tempfile::tempdir().unwrap();
    colmap_capture(tmp.path(), tmp.path());
    std::fs::remove_file(tmp.path().join("images/IMG_2.png")).unwrap();
    let err = load(tmp.path()).unwrap_err();
    assert!(matches!(err, BakeError::MissingFile { .. }), "{err}");
    assert_names(&err, "IMG_2.png");
}

/// A little-endian EXIF (TIFF) chunk holding one entry: orientation `value`.
fn exif_orientation(value: u16) -> Vec<u8> {
    let mut chunk = vec![0x49, 0x49, 42, 0, 8, 0, 0, 0, 1, 0];
    chunk.extend_from_slice(&0x0112u16.to_le_bytes()); // Orientation
    chunk.extend_from_slice(&3u16.to_le_bytes()); // SHORT
    chunk.extend_from_slice(&1u32.to_le_bytes()); // one value
    chunk.extend_from_slice(&value.to_le_bytes());
    chunk.extend_from_slice(&[0, 0, 0, 0, 0, 0]); // padding, no next IFD
    chunk
}

#[test]
fn an_exif_turn_is_noted_not_applied_and_a_turned_file_is_an_error_that_says_so() {
    use image::ImageEncoder as _;
    // A phone's JPEG: stored pixels as the camera (and COLMAP) saw them, EXIF asking
    // viewers to turn it a quarter (orientation 6).
    let tmp = tempfile::tempdir().unwrap();
    let mut capture = json_capture(tmp.path());
    let cam = capture.views[1].camera;
    let mask = sphere_mask(&cam);
    let rgb: Vec<u8> = mask
        .iter()
        .flat_map(|&m| COLOUR.map(|c| (255.0 * nelf_scene::srgb::linear_to_srgb(c * m)).round() as u8))
        .collect();
    let file = std::fs::File::create(tmp.path().join("images/view_001.jpg")).unwrap();
    let mut encoder = image::codecs::jpeg::JpegEncoder::new_with_quality(file, 100);
    encoder.set_exif_metadata(exif_orientation(6)).unwrap();
    encoder
        .write_image(&rgb, SIZE, SIZE, image::ExtendedColorType::Rgb8)
        .unwrap();
    capture.views[1].image = "images/view_001.jpg".into();
    capture.save(tmp.path()).unwrap();
    let loaded = load(tmp.path()).unwrap();
    assert_eq!(loaded.notes.len(), 1, "{:?}", loaded.notes);
    assert!(
        loaded.notes[0].contains("view_001.jpg") && loaded.notes[0].contains("Rotate90"),
        "{:?}",
        loaded.notes
    );
    // The pixels are the stored ones: the sphere's centre pixel is the colour.
    let centre = loaded.images[1][(SIZE / 2 * SIZE + SIZE / 2) as usize];
    for (got, want) in centre.iter().zip(COLOUR) {
        assert!((got - want).abs() < 0.03, "{centre:?}");
    }

    // A non-square view whose mask was made from the photo turned upright.
    let tmp = tempfile::tempdir().unwrap();
    let mut capture = json_capture(tmp.path());
    let cam = &mut capture.views[2].camera;
    cam.height = SIZE - 6;
    cam.cy -= 3.0;
    let cam = *cam;
    let mask = sphere_mask(&cam);
    let rgb: Vec<[f32; 3]> = mask.iter().map(|&m| COLOUR.map(|c| c * m)).collect();
    write_exr(&tmp.path().join("images/view_002.exr"), SIZE, SIZE - 6, &rgb);
    write_mask(&tmp.path().join("masks/view_002.png"), SIZE - 6, SIZE, &mask);
    capture.save(tmp.path()).unwrap();
    let err = load(tmp.path()).unwrap_err();
    assert!(matches!(err, BakeError::SizeMismatch { .. }), "{err}");
    assert_names(&err, "masks/view_002.png");
    assert_names(&err, "turned a quarter");
}
