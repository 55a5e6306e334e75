//! Captures in: a folder with our `cameras.json` (`format/CAPTURE.md`) or a COLMAP
//! text model, decoded into cameras, linear images and masks, and checked for
//! everything that would make a bake meaningless.
//!
//! **COLMAP folder layout** (read when the folder has no `cameras.json`):
//!
//! ```text
//! DIR/cameras.txt, DIR/images.txt        (or DIR/sparse/0/cameras.txt, …/images.txt)
//! DIR/images/<NAME>                      the NAME column of images.txt, sub-folders allowed
//! DIR/masks/<NAME without extension>.png (or DIR/masks/<NAME>.png, COLMAP's own mask naming)
//! ```
//!
//! A view without a mask file uses its image's alpha channel. Camera models:
//! `PINHOLE`, `SIMPLE_PINHOLE`, `OPENCV` with zero distortion (anything else is an
//! error from [`nelf_format::colmap::read_colmap_text`] naming the file and line).
//! COLMAP models have no unit: translations are multiplied by
//! [`CaptureLoadOptions::metres_per_unit`].
//!
//! **Colour**: EXR images are linear radiance and are used as they are; PNG and
//! JPEG images are sRGB-encoded and are decoded to linear (IEC 61966-2-1). Masks
//! are coverage in `[0, 1]` (8/16-bit PNG scaled to `[0, 1]`, EXR as is); a pixel
//! is foreground when its mask value is > 0.5.
//!
//! **EXIF orientation** is not applied: pixels are used as the file stores them,
//! as COLMAP does (its poses and intrinsics are in the stored frame), and a view
//! whose JPEG carries a turn or a flip gets a note in [`LoadedCapture::notes`]. An
//! image or mask turned a quarter from its camera's size (a photo turned upright
//! by a viewer, a mask made from the turned photo) is an error that says so.
//!
//! **Checks**, each an error naming the file: a missing image or mask, an image
//! whose size is not the camera's, a mask whose size is not the image's, a
//! non-finite pixel, a mask with no foreground, a camera that is not finite or not
//! a rotation, fewer than 2 views, optical axes that are all parallel, and a camera
//! with the head behind it. The head centre is the least-squares point nearest
//! every optical axis (`argmin_c Σ_i |(I − d_i d_iᵀ)(c − o_i)|²`); it must lie in
//! front of every camera (positive depth).

use std::path::{Component, Path, PathBuf};

use glam::DVec3;
use image::metadata::Orientation;
use image::{DynamicImage, ImageDecoder as _};
use nelf_format::capture::{CAPTURE_FILE_NAME, Capture};
use nelf_format::colmap::read_colmap_text;
use nelf_format::conventions::PinholeCamera;
use nelf_format::io_error::IoResultExt;
use nelf_scene::mesh_io::srgb_to_linear;
use serde::{Deserialize, Serialize};

use crate::error::{BakeError, Result};

/// Which kind of capture folder to read.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum CaptureFormat {
    /// `cameras.json` when present, else a COLMAP text model.
    #[default]
    Auto,
    /// Our `cameras.json` (`format/CAPTURE.md`).
    CamerasJson,
    /// A COLMAP text model (see the module documentation for the layout).
    Colmap,
}

/// How to read a capture folder.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CaptureLoadOptions {
    /// Which description to read.
    pub format: CaptureFormat,
    /// Metres per COLMAP model unit (COLMAP only; `cameras.json` declares its own unit).
    pub metres_per_unit: f64,
}

impl Default for CaptureLoadOptions {
    fn default() -> Self {
        Self {
            format: CaptureFormat::Auto,
            metres_per_unit: 1.0,
        }
    }
}

/// Where the cameras of a loaded capture came from.
#[derive(Debug, Clone, PartialEq)]
pub enum CaptureSource {
    /// Our `cameras.json`, with its full description (targets, lighting, metadata).
    CamerasJson(Box<Capture>),
    /// A COLMAP text model in this folder.
    Colmap {
        /// The folder holding `cameras.txt` and `images.txt`.
        model_dir: PathBuf,
    },
}

/// A decoded capture: cameras (metres), linear images and masks, one per view.
#[derive(Debug, Clone)]
pub struct LoadedCapture {
    /// The capture folder.
    pub dir: PathBuf,
    /// The file the cameras were read from (`cameras.json` or `images.txt`), for messages.
    pub camera_file: PathBuf,
    /// Where the cameras came from.
    pub source: CaptureSource,
    /// View names (unique).
    pub names: Vec<String>,
    /// One camera per view (OpenCV pinhole, metres).
    pub cameras: Vec<PinholeCamera>,
    /// Image files, one per view.
    pub image_files: Vec<PathBuf>,
    /// Linear RGB images, row-major, `width × height` of the view's camera.
    pub images: Vec<Vec<[f32; 3]>>,
    /// Masks in `[0, 1]`, row-major, same size as the image.
    pub masks: Vec<Vec<f32>>,
    /// Estimated head centre (least-squares point nearest every optical axis), metres.
    pub head_centre_m: DVec3,
    /// What the loader noticed and worked around (e.g. an EXIF orientation it did
    /// not apply), one sentence each naming the file.
    pub notes: Vec<String>,
}

impl LoadedCapture {
    /// The capture's description when it came from `cameras.json`.
    pub fn description(&self) -> Option<&Capture> {
        match &self.source {
            CaptureSource::CamerasJson(c) => Some(c),
            CaptureSource::Colmap { .. } => None,
        }
    }

    /// The environment map the views were lit by, when `cameras.json` names one.
    pub fn source_envmap_path(&self) -> Option<PathBuf> {
        self.description().and_then(|c| c.envmap_path(&self.dir))
    }

    /// Number of views.
    pub fn len(&self) -> usize {
        self.cameras.len()
    }

    /// Whether there is no view (never true for a capture that loaded).
    pub fn is_empty(&self) -> bool {
        self.cameras.is_empty()
    }
}

/// One view before decoding: name, camera, image file and optional mask file.
struct ViewFiles {
    name: String,
    camera: PinholeCamera,
    image: PathBuf,
    mask: Option<PathBuf>,
}

/// Loads and checks a capture folder (see the module documentation).
pub fn load_capture(dir: impl AsRef<Path>, options: &CaptureLoadOptions) -> Result<LoadedCapture> {
    let dir = dir.as_ref();
    let json = dir.join(CAPTURE_FILE_NAME);
    let use_json = match options.format {
        CaptureFormat::Auto => json.is_file(),
        CaptureFormat::CamerasJson => true,
        CaptureFormat::Colmap => false,
    };
    let (camera_file, source, views) = if use_json {
        let capture = Capture::load(dir)?;
        let views = capture
            .views
            .iter()
            .map(|v| ViewFiles {
                name: v.name.clone(),
                camera: v.camera,
                image: v.image_path(dir),
                mask: v.mask_path(dir),
            })
            .collect();
        (json, CaptureSource::CamerasJson(Box::new(capture)), views)
    } else {
        let model_dir = find_colmap_model(dir).ok_or_else(|| BakeError::NoCapture {
            dir: dir.to_path_buf(),
        })?;
        let images_txt = model_dir.join("images.txt");
        let cameras = read_colmap_text(&model_dir, options.metres_per_unit)?;
        let mut views = Vec::with_capacity(cameras.len());
        for (name, camera) in cameras {
            let relative = safe_relative(&name).ok_or_else(|| BakeError::BadCamera {
                path: images_txt.clone(),
                view: name.clone(),
                reason: "the image name must be a relative path inside images/ (no '..', not absolute)"
                    .into(),
            })?;
            let image = dir.join("images").join(&relative);
            let mask = colmap_mask_candidates(dir, &relative)
                .into_iter()
                .find(|p| p.is_file());
            views.push(ViewFiles {
                name,
                camera,
                image,
                mask,
            });
        }
        (images_txt, CaptureSource::Colmap { model_dir }, views)
    };
    if views.len() < 2 {
        return Err(BakeError::TooFewViews {
            path: camera_file,
            count: views.len(),
        });
    }
    for v in &views {
        v.camera.validate().map_err(|e| BakeError::BadCamera {
            path: camera_file.clone(),
            view: v.name.clone(),
            reason: e.to_string(),
        })?;
    }
    let cameras: Vec<PinholeCamera> = views.iter().map(|v| v.camera).collect();
    let head_centre_m = head_centre(&cameras).ok_or_else(|| BakeError::ParallelAxes {
        path: camera_file.clone(),
    })?;
    for v in &views {
        let depth = v.camera.camera_from_world(head_centre_m).z;
        if depth.is_nan() || depth <= 0.0 {
            return Err(BakeError::CameraBehindHead {
                path: camera_file.clone(),
                view: v.name.clone(),
                centre_m: head_centre_m.to_array(),
                depth_m: depth,
            });
        }
    }

    let mut names = Vec::with_capacity(views.len());
    let mut image_files = Vec::with_capacity(views.len());
    let mut images = Vec::with_capacity(views.len());
    let mut masks = Vec::with_capacity(views.len());
    let mut notes = Vec::new();
    for v in views {
        let (image, mask) = load_view(&v, &mut notes)?;
        names.push(v.name);
        image_files.push(v.image);
        images.push(image);
        masks.push(mask);
    }
    Ok(LoadedCapture {
        dir: dir.to_path_buf(),
        camera_file,
        source,
        names,
        cameras,
        image_files,
        images,
        masks,
        head_centre_m,
        notes,
    })
}

/// The folder of a COLMAP text model: `dir` itself or `dir/sparse/0`.
fn find_colmap_model(dir: &Path) -> Option<PathBuf> {
    [dir.to_path_buf(), dir.join("sparse").join("0")]
        .into_iter()
        .find(|d| d.join("cameras.txt").is_file() && d.join("images.txt").is_file())
}

/// `name` as a relative path with only normal components, or `None`.
fn safe_relative(name: &str) -> Option<PathBuf> {
    let path = Path::new(name);
    let ok = !name.is_empty()
        && !name.contains('\\')
        && path.components().all(|c| matches!(c, Component::Normal(_)));
    ok.then(|| path.to_path_buf())
}

/// Mask files tried for a COLMAP image, in order.
fn colmap_mask_candidates(dir: &Path, relative: &Path) -> Vec<PathBuf> {
    let masks = dir.join("masks");
    let mut out = vec![masks.join(relative.with_extension("png"))];
    let mut appended = relative.as_os_str().to_owned();
    appended.push(".png");
    out.push(masks.join(appended));
    out
}

pub use nelf_format::conventions::nearest_point_to_axes as head_centre;

/// Decodes an image file, with the orientation its EXIF data asks for (not applied).
fn decode(path: &Path, what: &str) -> Result<(DynamicImage, Orientation)> {
    if !path.is_file() {
        return Err(BakeError::MissingFile {
            path: path.to_path_buf(),
            what: what.to_string(),
        });
    }
    let image_error = |source| BakeError::Image {
        path: path.to_path_buf(),
        source,
    };
    let mut decoder = image::ImageReader::open(path)
        .with_path(path)?
        .with_guessed_format()
        .with_path(path)?
        .into_decoder()
        .map_err(image_error)?;
    // Unreadable EXIF data is no reason to refuse the pixels.
    let orientation = decoder.orientation().unwrap_or(Orientation::NoTransforms);
    let image = DynamicImage::from_decoder(decoder).map_err(image_error)?;
    Ok((image, orientation))
}

fn is_exr(path: &Path) -> bool {
    path.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("exr"))
}

/// Decodes one view's image (linear RGB) and mask, checking sizes and values.
fn load_view(view: &ViewFiles, notes: &mut Vec<String>) -> Result<(Vec<[f32; 3]>, Vec<f32>)> {
    let (w, h) = (view.camera.width, view.camera.height);
    let (image, orientation) = decode(&view.image, &format!("image of view {:?}", view.name))?;
    let check_size = |img: &DynamicImage, path: &Path, what: &str| {
        if img.width() == w && img.height() == h {
            Ok(())
        } else {
            let turned = w != h && img.width() == h && img.height() == w;
            Err(BakeError::SizeMismatch {
                path: path.to_path_buf(),
                what: what.to_string(),
                expected_w: w,
                expected_h: h,
                found_w: img.width(),
                found_h: img.height(),
                hint: if turned {
                    "; it is the camera's size turned a quarter: was it turned upright from its \
                     EXIF orientation? Poses (COLMAP's too) are in the frame the camera stored the \
                     pixels in; give the image and its mask in that frame"
                        .into()
                } else {
                    String::new()
                },
            })
        }
    };
    check_size(
        &image,
        &view.image,
        &format!("the image of view {:?} (camera size)", view.name),
    )?;
    if orientation != Orientation::NoTransforms {
        notes.push(format!(
            "{}: EXIF orientation {orientation:?} not applied (pixels used as stored, as COLMAP does)",
            view.image.display()
        ));
    }
    let linear = is_exr(&view.image);
    let rgba = image.to_rgba32f();
    let mut rgb = Vec::with_capacity((w * h) as usize);
    for (i, p) in rgba.pixels().enumerate() {
        let [r, g, b, _] = p.0;
        if !(r.is_finite() && g.is_finite() && b.is_finite()) {
            return Err(BakeError::NonFinitePixel {
                path: view.image.clone(),
                x: (i as u32) % w,
                y: (i as u32) / w,
            });
        }
        rgb.push(if linear {
            [r, g, b]
        } else {
            [srgb_to_linear(r), srgb_to_linear(g), srgb_to_linear(b)]
        });
    }
    let (mask, mask_file) = if let Some(path) = &view.mask {
        let (m, _) = decode(path, &format!("mask of view {:?}", view.name))?;
        check_size(
            &m,
            path,
            &format!("the mask of view {:?} (image size)", view.name),
        )?;
        let luma = m.to_luma32f();
        (
            luma.pixels().map(|p| sanitize_mask(p.0[0])).collect::<Vec<f32>>(),
            path,
        )
    } else {
        if !image.color().has_alpha() {
            return Err(BakeError::NoMask {
                path: view.image.clone(),
                view: view.name.clone(),
            });
        }
        (
            rgba.pixels().map(|p| sanitize_mask(p.0[3])).collect(),
            &view.image,
        )
    };
    if !mask.iter().any(|&m| m > 0.5) {
        return Err(BakeError::EmptyMask {
            path: mask_file.clone(),
            view: view.name.clone(),
        });
    }
    Ok((rgb, mask))
}

/// Clamps a mask value to `[0, 1]`; NaN counts as background.
fn sanitize_mask(v: f32) -> f32 {
    if v.is_nan() { 0.0 } else { v.clamp(0.0, 1.0) }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn colmap_names_are_kept_inside_the_folder() {
        assert!(safe_relative("a/b.jpg").is_some());
        assert!(safe_relative("../b.jpg").is_none());
        assert!(safe_relative("/etc/passwd").is_none());
        assert!(safe_relative("a\\b.jpg").is_none());
        let c = colmap_mask_candidates(Path::new("/d"), Path::new("x/IMG_1.JPG"));
        assert_eq!(c[0], Path::new("/d/masks/x/IMG_1.png"));
        assert_eq!(c[1], Path::new("/d/masks/x/IMG_1.JPG.png"));
    }
}
