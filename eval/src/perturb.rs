//! The building blocks of `nelf eval stability` (issue 16, item 4): controlled,
//! seeded damage to a capture and controlled lighting and viewpoints, so that PSNR
//! can be charted against each cause of failure.
//!
//! * [`perturb_poses`]: every source camera turned by exactly `rotation_deg` about a
//!   random axis and moved by exactly `translation_mm`, images untouched — a
//!   miscalibrated capture.
//! * [`edit_masks`] with a [`MaskEdit`]: every source mask eroded, dilated or
//!   blurred — a segmentation error.
//! * [`sun_envmap`]: a dim uniform sky and a white disc sun whose power stays
//!   constant as its radius shrinks — lighting of growing sharpness.
//! * [`target_cameras_at_angles`]: evaluation cameras at a given azimuth from the
//!   frontal view, up to the back of the head (180°).
//!
//! Everything is deterministic: randomness comes from `rand_pcg::Pcg64` seeded by
//! the caller. The capture edits rewrite files in place, atomically
//! (`nelf_format::atomic`): run them on a copy of the capture.
//!
//! Conventions are the project's (`nelf_format::conventions`, `docs/CONVENTIONS.md`): metres,
//! OpenCV cameras with world-to-camera `x_cam = R·x_world + t`, lat-long maps in the
//! world frame with row 0 at the zenith (+y) and texel solid angles
//! `Ω_i = (2π/W)(cos θ_i − cos θ_{i+1})`.

use std::f64::consts::PI;
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use glam::{DMat3, DVec3};
use image::{ColorType, DynamicImage, ImageBuffer, ImageFormat, Primitive};
use nelf_format::capture::{CAPTURE_FILE_NAME, Capture, CaptureError};
use nelf_format::conventions::{LatLong, PinholeCamera};
use nelf_format::io_error::FileIoError;
use nelf_scene::envgen::{Emitter, EmitterShape, add_emitter};
use nelf_scene::synth::{SynthConfig, Viewpoint, camera_for};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

/// Errors from editing a capture. Each names the file concerned and what failed.
#[derive(Debug, thiserror::Error)]
pub enum PerturbError {
    /// Loading or saving `cameras.json` failed (the error names the file and view).
    #[error(transparent)]
    Capture(#[from] CaptureError),
    /// Reading or writing a file failed.
    #[error(transparent)]
    Io(#[from] FileIoError),
    /// Decoding or encoding an image failed.
    #[error("{path}: {source}")]
    Image {
        /// The image file.
        path: PathBuf,
        /// The codec's error.
        source: image::ImageError,
    },
    /// A source view has no mask file (its image's alpha is the mask); only mask
    /// files are edited, never images.
    #[error(
        "{path}: view {view:?} has no mask file (its image's alpha channel is the mask); \
         mask edits need a mask file per view"
    )]
    NoMaskFile {
        /// The `cameras.json` file.
        path: PathBuf,
        /// The view's name.
        view: String,
    },
    /// A mask file is not an 8/16-bit PNG or a float EXR.
    #[error("{path}: mask of view {view:?} is {found}; expected an 8- or 16-bit PNG or a float EXR")]
    UnsupportedMask {
        /// The mask file.
        path: PathBuf,
        /// The view's name.
        view: String,
        /// What the file holds.
        found: String,
    },
    /// A perturbation size is negative, out of range or not finite.
    #[error("{path}: {what} = {value} {reason}")]
    BadArgument {
        /// The `cameras.json` file of the capture it was meant for.
        path: PathBuf,
        /// Which argument.
        what: &'static str,
        /// Its value.
        value: f64,
        /// What is wrong.
        reason: &'static str,
    },
}

// ---------------------------------------------------------------------------
// Poses.

/// A unit vector uniform on the sphere: `z = 2u − 1`, `φ = 2πv`,
/// `(√(1 − z²) cos φ, √(1 − z²) sin φ, z)` (Archimedes: uniform `z` is uniform area).
fn random_unit(rng: &mut Pcg64) -> DVec3 {
    let z = 2.0 * rng.random::<f64>() - 1.0;
    let phi = 2.0 * PI * rng.random::<f64>();
    let s = (1.0 - z * z).max(0.0).sqrt();
    DVec3::new(s * phi.cos(), s * phi.sin(), z)
}

/// Rewrites `capture_dir/cameras.json` with every source view's camera pose
/// perturbed; targets, intrinsics and every image and mask are untouched, so the
/// poses no longer match the images, as in a miscalibrated capture.
///
/// For view `i` (view 0, the reference, included: every camera is miscalibrated,
/// the frame of reference is not spared) two unit vectors are drawn from
/// `Pcg64::seed_from_u64(seed)`, in view order: an axis `a_i` and a direction
/// `u_i`, both uniform on the sphere. With `θ = rotation_deg` (radians) and
/// `δ = translation_mm / 1000` (metres), the camera turns about its own centre by
/// `Q_i = rot(a_i, θ)` (in the world frame) and its centre moves by `δ·u_i`:
///
/// ```text
/// R' = R · Q_iᵀ              (camera-to-world Rᵀ becomes Q_i · Rᵀ)
/// c  = −Rᵀ t,  c' = c + δ·u_i
/// t' = −R' · c'
/// ```
///
/// so the rotation from the old to the new orientation (`Rᵀ R' = Q_iᵀ`, or
/// `R' Rᵀ = R Q_iᵀ Rᵀ`) has angle exactly `θ` and the centre moves exactly `δ`.
/// The draws do not depend on the sizes, so a sweep over sizes with one seed
/// scales one and the same perturbation. With `rotation_deg = 0` the rotation is kept bit for bit (and
/// `t' = t − R·δu_i`); with both zero the file is not rewritten at all.
///
/// The file is rewritten with [`Capture::save`] (atomic: a temporary file, then a
/// rename), so it is normalised as that writes it: lengths in metres, `"units": "m"`.
pub fn perturb_poses(
    capture_dir: &Path,
    rotation_deg: f64,
    translation_mm: f64,
    seed: u64,
) -> Result<(), PerturbError> {
    let file = capture_dir.join(CAPTURE_FILE_NAME);
    let bad = |what, value, reason| PerturbError::BadArgument {
        path: file.clone(),
        what,
        value,
        reason,
    };
    if !(rotation_deg.is_finite() && (0.0..=180.0).contains(&rotation_deg)) {
        return Err(bad("rotation_deg", rotation_deg, "must be in [0, 180]"));
    }
    if !(translation_mm.is_finite() && translation_mm >= 0.0) {
        return Err(bad("translation_mm", translation_mm, "must be finite and ≥ 0"));
    }
    let mut capture = Capture::load(capture_dir)?;
    if rotation_deg == 0.0 && translation_mm == 0.0 {
        return Ok(());
    }
    let theta = rotation_deg.to_radians();
    let delta = translation_mm / 1000.0;
    let mut rng = Pcg64::seed_from_u64(seed);
    for view in &mut capture.views {
        let axis = random_unit(&mut rng);
        let shift = random_unit(&mut rng) * delta;
        let camera = &mut view.camera;
        if theta == 0.0 {
            camera.translation -= camera.rotation * shift;
        } else {
            let centre = camera.centre();
            camera.rotation *= DMat3::from_axis_angle(axis, theta).transpose();
            camera.translation = -(camera.rotation * (centre + shift));
        }
    }
    capture.save(capture_dir)?;
    Ok(())
}

// ---------------------------------------------------------------------------
// Masks.

/// A segmentation error applied to every source mask by [`edit_masks`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum MaskEdit {
    /// Binarise (`m > 0.5`), then erode with a square `(2n+1)²` structuring element:
    /// `m'(p) = min_{q ∈ p + [−n, n]²} b(q)`, values 0 or 1.
    Erode(u32),
    /// Binarise (`m > 0.5`), then dilate with a square `(2n+1)²` structuring element:
    /// `m'(p) = max_{q ∈ p + [−n, n]²} b(q)`, values 0 or 1.
    Dilate(u32),
    /// Blur the mask as stored (soft values kept) with a Gaussian of this standard
    /// deviation in pixels: separable, weights `exp(−k²/2σ²)` for `|k| ≤ ⌈3σ⌉`,
    /// normalised; values stay in `[0, 1]`.
    Soften(f32),
}

/// Rewrites every source view's mask file in place with `edit` applied.
///
/// Masks are read as the bake reads them (`nelf_bake::capture_in`): the luma of the
/// decoded image, 8/16-bit PNG scaled to `[0, 1]`, EXR as is, clamped to `[0, 1]`
/// (NaN → 0). Each is written back in its own format and layout, atomically: a PNG
/// keeps its bit depth and channels, an EXR stays 32-bit float with its channels;
/// every channel (alpha included) holds the edited mask, quantised as
/// `round(m·255)` or `round(m·65535)` for PNG.
///
/// The capture's images are already multiplied by their true masks (composited over
/// black) and are not touched: only the mask files change, as a segmentation error
/// would change them. Target masks are not touched either (they define the
/// evaluation).
///
/// Borders: erosion and dilation windows are clipped to the image (pixels outside it
/// neither erode nor dilate), so a silhouette leaving the frame (the neck) keeps
/// leaving it; the blur renormalises its weights over the pixels inside the image.
/// `Erode(0)`, `Dilate(0)` and `Soften(0.0)` leave every file untouched (the sweep's
/// zero point is the capture as it was); a negative or non-finite σ is an error. An
/// erosion may empty a mask; the bake then reports the empty mask.
pub fn edit_masks(capture_dir: &Path, edit: MaskEdit) -> Result<(), PerturbError> {
    let file = capture_dir.join(CAPTURE_FILE_NAME);
    let sigma = match edit {
        MaskEdit::Soften(sigma) => sigma,
        MaskEdit::Erode(_) | MaskEdit::Dilate(_) => 0.0,
    };
    if !(sigma.is_finite() && sigma >= 0.0) {
        return Err(PerturbError::BadArgument {
            path: file,
            what: "soften sigma (px)",
            value: f64::from(sigma),
            reason: "must be finite and ≥ 0",
        });
    }
    let capture = Capture::load(capture_dir)?;
    // Check every view first, so that a capture with one alpha-masked view is
    // rejected before any file is changed.
    let mut masks = Vec::with_capacity(capture.views.len());
    for view in &capture.views {
        match view.mask_path(capture_dir) {
            Some(path) => masks.push((view.name.as_str(), path)),
            None => {
                return Err(PerturbError::NoMaskFile {
                    path: file,
                    view: view.name.clone(),
                });
            }
        }
    }
    if matches!(edit, MaskEdit::Erode(0) | MaskEdit::Dilate(0)) || edit == MaskEdit::Soften(0.0) {
        return Ok(());
    }
    for (view, path) in masks {
        let (image, format) = decode(&path)?;
        let (width, height) = (image.width() as usize, image.height() as usize);
        let values: Vec<f32> = image
            .to_luma32f()
            .pixels()
            .map(|p| {
                if p.0[0].is_nan() {
                    0.0
                } else {
                    p.0[0].clamp(0.0, 1.0)
                }
            })
            .collect();
        let edited = apply_edit(&values, width, height, edit);
        let out = encode_like(&image, format, &edited).ok_or_else(|| PerturbError::UnsupportedMask {
            path: path.clone(),
            view: view.to_string(),
            found: describe(format, image.color()),
        })?;
        write_image_atomically(&path, &out, format)?;
    }
    Ok(())
}

/// The edited mask, row-major `width × height`.
fn apply_edit(values: &[f32], width: usize, height: usize, edit: MaskEdit) -> Vec<f32> {
    match edit {
        MaskEdit::Erode(n) => morphology(values, width, height, n as usize, true),
        MaskEdit::Dilate(n) => morphology(values, width, height, n as usize, false),
        MaskEdit::Soften(sigma) => gaussian_blur(values, width, height, f64::from(sigma)),
    }
}

/// Binary erosion (`erode`) or dilation of `values > 0.5` by a `(2n+1)²` square,
/// window clipped to the image. Separable (a square is a row of columns): a
/// horizontal then a vertical pass, each a sliding count of foreground pixels from
/// prefix sums — erosion keeps a pixel when the clipped window is all foreground,
/// dilation when it holds any.
fn morphology(values: &[f32], width: usize, height: usize, n: usize, erode: bool) -> Vec<f32> {
    let binary: Vec<bool> = values.iter().map(|&v| v > 0.5).collect();
    let pass = |input: &[bool], len: usize, lines: usize, index: &dyn Fn(usize, usize) -> usize| {
        let mut out = vec![false; input.len()];
        let mut prefix = vec![0usize; len + 1];
        for line in 0..lines {
            for k in 0..len {
                prefix[k + 1] = prefix[k] + usize::from(input[index(line, k)]);
            }
            for k in 0..len {
                let (lo, hi) = (k.saturating_sub(n), (k + n + 1).min(len));
                let count = prefix[hi] - prefix[lo];
                out[index(line, k)] = if erode { count == hi - lo } else { count > 0 };
            }
        }
        out
    };
    let rows = pass(&binary, width, height, &|y, x| y * width + x);
    let both = pass(&rows, height, width, &|x, y| y * width + x);
    both.into_iter().map(|b| if b { 1.0 } else { 0.0 }).collect()
}

/// Separable Gaussian blur of standard deviation `sigma` pixels, kernel truncated at
/// `⌈3σ⌉`, weights renormalised over the pixels inside the image; clamped to `[0, 1]`
/// (a convex combination of values in `[0, 1]`, clamped against rounding).
fn gaussian_blur(values: &[f32], width: usize, height: usize, sigma: f64) -> Vec<f32> {
    let radius = (3.0 * sigma).ceil() as usize;
    let kernel: Vec<f64> = (0..=radius)
        .map(|k| (-((k * k) as f64) / (2.0 * sigma * sigma)).exp())
        .collect();
    let pass = |input: &[f64], len: usize, lines: usize, index: &dyn Fn(usize, usize) -> usize| {
        let mut out = vec![0.0f64; input.len()];
        for line in 0..lines {
            for k in 0..len {
                let (lo, hi) = (k.saturating_sub(radius), (k + radius).min(len - 1));
                let (mut sum, mut weight) = (0.0, 0.0);
                for j in lo..=hi {
                    let w = kernel[j.abs_diff(k)];
                    sum += w * input[index(line, j)];
                    weight += w;
                }
                out[index(line, k)] = sum / weight;
            }
        }
        out
    };
    let input: Vec<f64> = values.iter().map(|&v| f64::from(v)).collect();
    let rows = pass(&input, width, height, &|y, x| y * width + x);
    let both = pass(&rows, height, width, &|x, y| y * width + x);
    both.into_iter().map(|v| v.clamp(0.0, 1.0) as f32).collect()
}

/// Decodes an image, returning it with the format its content has.
fn decode(path: &Path) -> Result<(DynamicImage, Option<ImageFormat>), PerturbError> {
    let io = |source| PerturbError::Io(FileIoError::new(path.to_path_buf(), source));
    let reader = image::ImageReader::open(path)
        .map_err(io)?
        .with_guessed_format()
        .map_err(io)?;
    let format = reader.format();
    let image = reader.decode().map_err(|source| PerturbError::Image {
        path: path.to_path_buf(),
        source,
    })?;
    Ok((image, format))
}

/// `format, colour type` for error messages.
fn describe(format: Option<ImageFormat>, color: ColorType) -> String {
    let name = format.map_or("an unknown format", |f| {
        f.extensions_str().first().copied().unwrap_or("?")
    });
    format!("{name} image of colour type {color:?}")
}

/// `values` repeated `channels` times per pixel, as a buffer of `original`'s size.
fn replicated<P, T>(original: &DynamicImage, values: &[T]) -> Option<ImageBuffer<P, Vec<T>>>
where
    P: image::Pixel<Subpixel = T>,
    T: Primitive,
{
    let channels = usize::from(P::CHANNEL_COUNT);
    let data: Vec<T> = values
        .iter()
        .flat_map(|&v| std::iter::repeat_n(v, channels))
        .collect();
    ImageBuffer::from_raw(original.width(), original.height(), data)
}

/// The edited mask in `original`'s layout (PNG: same bit depth and channels; EXR:
/// 32-bit float, same channels); `None` for any other format or layout.
fn encode_like(original: &DynamicImage, format: Option<ImageFormat>, mask: &[f32]) -> Option<DynamicImage> {
    let q8: Vec<u8> = mask.iter().map(|&v| (v * 255.0).round() as u8).collect();
    let q16: Vec<u16> = mask.iter().map(|&v| (v * 65535.0).round() as u16).collect();
    match (format?, original.color()) {
        (ImageFormat::Png, ColorType::L8) => replicated(original, &q8).map(DynamicImage::ImageLuma8),
        (ImageFormat::Png, ColorType::La8) => replicated(original, &q8).map(DynamicImage::ImageLumaA8),
        (ImageFormat::Png, ColorType::Rgb8) => replicated(original, &q8).map(DynamicImage::ImageRgb8),
        (ImageFormat::Png, ColorType::Rgba8) => replicated(original, &q8).map(DynamicImage::ImageRgba8),
        (ImageFormat::Png, ColorType::L16) => replicated(original, &q16).map(DynamicImage::ImageLuma16),
        (ImageFormat::Png, ColorType::La16) => replicated(original, &q16).map(DynamicImage::ImageLumaA16),
        (ImageFormat::Png, ColorType::Rgb16) => replicated(original, &q16).map(DynamicImage::ImageRgb16),
        (ImageFormat::Png, ColorType::Rgba16) => replicated(original, &q16).map(DynamicImage::ImageRgba16),
        (ImageFormat::OpenExr, ColorType::Rgb32F) => {
            replicated(original, mask).map(DynamicImage::ImageRgb32F)
        }
        (ImageFormat::OpenExr, ColorType::Rgba32F) => {
            replicated(original, mask).map(DynamicImage::ImageRgba32F)
        }
        _ => None,
    }
}

/// Writes `image` to `path` in `format` atomically (`nelf_format::atomic`).
fn write_image_atomically(
    path: &Path,
    image: &DynamicImage,
    format: Option<ImageFormat>,
) -> Result<(), PerturbError> {
    let format = format.unwrap_or(ImageFormat::Png);
    let mut image_error = None;
    nelf_format::atomic::write_atomically(path, |w: &mut BufWriter<File>| {
        image.write_to(w, format).map_err(|e| {
            let message = e.to_string();
            image_error = Some(e);
            std::io::Error::other(message)
        })
    })
    .map_err(|source| match image_error.take() {
        Some(source) => PerturbError::Image {
            path: path.to_path_buf(),
            source,
        },
        None => PerturbError::Io(FileIoError::new(path.to_path_buf(), source)),
    })
}

// ---------------------------------------------------------------------------
// Lighting.

/// A `width × height` lat-long map (world frame, project layout) of a uniform sky of
/// radiance `sky` plus a white disc sun of angular radius `sun_radius_deg` around
/// `sun_direction` whose power `P = ∫_disc L dΩ = sun_radiance_total` (per channel,
/// radiance × solid angle, e.g. W/m² for W/m²/sr) does not depend on the radius:
/// shrinking the sun only sharpens the lighting.
///
/// The sun is a disc emitter of radiance `P / 2π(1 − cos α)` added by
/// `nelf_scene::envgen::add_emitter` (covered fractions from sub-texel points,
/// renormalised to the disc's exact solid angle), so `Σ_k Ω_k (L_k − sky) = P` (up
/// to the `f32` texels), and a sun smaller than a texel (or of radius ≤ 0: a point)
/// lands whole in the texel holding its centre. A zero or
/// non-finite direction is taken as the zenith (+y); the radius is clamped to 180°;
/// the size to at least 1 × 1.
pub fn sun_envmap(
    sun_radius_deg: f64,
    sun_direction: DVec3,
    sun_radiance_total: f64,
    sky: [f32; 3],
    width: usize,
    height: usize,
) -> LatLong {
    let (width, height) = (width.max(1), height.max(1));
    let centre = sun_direction.try_normalize().unwrap_or(DVec3::Y);
    // A point sun is a disc far below a texel: the emitter lands whole in one texel.
    let alpha = if sun_radius_deg.is_finite() {
        sun_radius_deg.to_radians().clamp(MIN_SUN_RADIUS_RAD, PI)
    } else {
        MIN_SUN_RADIUS_RAD
    };
    let radiance = (sun_radiance_total / (2.0 * PI * (1.0 - alpha.cos()))) as f32;
    let mut map = LatLong::constant(width, height, sky);
    add_emitter(
        &mut map,
        &Emitter {
            shape: EmitterShape::Disc {
                centre,
                half_angle_rad: alpha,
            },
            radiance: [radiance; 3],
        },
    );
    map
}

/// Smallest sun radius, radians (a "point" sun), where `1 − cos α` is still exact
/// enough in `f64`.
const MIN_SUN_RADIUS_RAD: f64 = 1e-4;

// ---------------------------------------------------------------------------
// Viewpoints.

/// Evaluation cameras on the horizontal circle of radius `distance_m` around
/// `centre`, at azimuth `angle` (degrees) from the frontal direction (+z), positive
/// toward +x: the camera sits at `centre + distance·(sin a, 0, cos a)`, looks at
/// `centre` with +y up, and is framed as the synthetic captures frame theirs
/// ([`nelf_scene::synth::camera_for`]: the vertical field of view makes a sphere of
/// `radius_m` fill `fill` of the frame height; square pixels, principal point at the
/// image centre). 0° is the frontal view, 90° the right profile (+x), 180° the back
/// of the head.
pub fn target_cameras_at_angles(
    centre: DVec3,
    radius_m: f64,
    distance_m: f64,
    width: u32,
    height: u32,
    fill: f64,
    angles_deg: &[f64],
) -> Vec<PinholeCamera> {
    let config = SynthConfig {
        width,
        height,
        fill,
        ..SynthConfig::default()
    };
    angles_deg
        .iter()
        .map(|&angle| {
            let view = Viewpoint {
                azimuth_rad: angle.to_radians(),
                elevation_rad: 0.0,
                distance_m,
            };
            camera_for(&view, centre, radius_m, &config)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use image::{Luma, Rgb};
    use nelf_format::capture::{CaptureView, TargetView};
    use nelf_format::conventions::{texel_center_direction, texel_of_direction, texel_solid_angle};

    type TestResult = Result<(), Box<dyn std::error::Error>>;

    /// Angle of a rotation matrix, `atan2(|vee(M − Mᵀ)|/2, (tr M − 1)/2)` (accurate
    /// near 0 and π, unlike `acos`).
    fn rotation_angle(m: DMat3) -> f64 {
        let s = DVec3::new(
            m.y_axis.z - m.z_axis.y,
            m.z_axis.x - m.x_axis.z,
            m.x_axis.y - m.y_axis.x,
        );
        let trace = m.x_axis.x + m.y_axis.y + m.z_axis.z;
        (0.5 * s.length()).atan2(0.5 * (trace - 1.0))
    }

    /// Angle between two vectors, `atan2(|a × b|, a · b)`.
    fn angle_between(a: DVec3, b: DVec3) -> f64 {
        a.cross(b).length().atan2(a.dot(b))
    }

    const SIZE: u32 = 16;

    /// A 16 × 16 mask with a 5 × 5 square of ones at x, y ∈ 5..10.
    fn square_mask() -> Vec<f32> {
        let mut m = vec![0.0f32; (SIZE * SIZE) as usize];
        for y in 5..10 {
            for x in 5..10 {
                m[y * SIZE as usize + x] = 1.0;
            }
        }
        m
    }

    /// A tiny capture written by hand: two views (8-bit PNG mask, RGB float EXR
    /// mask), one target with its lighting.
    fn tiny_capture(dir: &Path) -> TestResult {
        for sub in ["images", "masks", "targets", "lighting"] {
            std::fs::create_dir_all(dir.join(sub))?;
        }
        let mask = square_mask();
        let grey = ImageBuffer::<Rgb<u8>, _>::from_fn(SIZE, SIZE, |x, y| Rgb([x as u8 * 9, y as u8 * 9, 77]));
        for name in ["images/a.png", "images/b.png", "targets/t.png"] {
            grey.save(dir.join(name))?;
        }
        let png = ImageBuffer::<Luma<u8>, _>::from_fn(SIZE, SIZE, |x, y| {
            Luma([(mask[(y * SIZE + x) as usize] * 255.0) as u8])
        });
        png.save(dir.join("masks/a.png"))?;
        let exr =
            ImageBuffer::<Rgb<f32>, _>::from_fn(SIZE, SIZE, |x, y| Rgb([mask[(y * SIZE + x) as usize]; 3]));
        DynamicImage::ImageRgb32F(exr).save(dir.join("masks/b.exr"))?;
        DynamicImage::ImageRgb32F(ImageBuffer::from_pixel(16, 8, Rgb([1.0f32; 3])))
            .save(dir.join("lighting/t.exr"))?;
        let cam = |eye| PinholeCamera::look_at(eye, DVec3::ZERO, DVec3::Y, SIZE, SIZE, 0.5);
        let mut capture = Capture::new(vec![
            CaptureView {
                name: "a".into(),
                image: "images/a.png".into(),
                mask: Some("masks/a.png".into()),
                camera: cam(DVec3::new(0.0, 0.0, 1.5)),
            },
            CaptureView {
                name: "b".into(),
                image: "images/b.png".into(),
                mask: Some("masks/b.exr".into()),
                camera: cam(DVec3::new(0.7, 0.2, 1.3)),
            },
        ]);
        capture.targets.push(TargetView {
            name: "t".into(),
            image: "targets/t.png".into(),
            mask: None,
            envmap: "lighting/t.exr".into(),
            camera: cam(DVec3::new(-0.6, 0.1, 1.4)),
        });
        capture.save(dir)?;
        Ok(())
    }

    /// The mask values of a file (first channel, `[0, 1]`) and its colour type.
    fn read_mask(path: &Path) -> Result<(Vec<f32>, ColorType), Box<dyn std::error::Error>> {
        let image = image::open(path)?;
        let values = image.to_rgba32f().pixels().map(|p| p.0[0]).collect();
        Ok((values, image.color()))
    }

    /// Bounding box `(x0, y0, x1, y1)` (inclusive) and count of values > 0.5.
    fn foreground(values: &[f32]) -> (usize, usize, usize, usize, usize) {
        let w = SIZE as usize;
        let mut bbox = (usize::MAX, usize::MAX, 0, 0, 0);
        for (i, _) in values.iter().enumerate().filter(|&(_, &v)| v > 0.5) {
            let (x, y) = (i % w, i / w);
            bbox = (
                bbox.0.min(x),
                bbox.1.min(y),
                bbox.2.max(x),
                bbox.3.max(y),
                bbox.4 + 1,
            );
        }
        bbox
    }

    fn file_bytes(dir: &Path, names: &[&str]) -> Result<Vec<Vec<u8>>, std::io::Error> {
        names.iter().map(|n| std::fs::read(dir.join(n))).collect()
    }

    #[test]
    fn poses_turn_and_move_by_exactly_the_requested_amounts() -> TestResult {
        let dir = tempfile::tempdir()?;
        tiny_capture(dir.path())?;
        let before = Capture::load(dir.path())?;
        let images = [
            "images/a.png",
            "images/b.png",
            "masks/a.png",
            "masks/b.exr",
            "targets/t.png",
        ];
        let image_bytes = file_bytes(dir.path(), &images)?;
        for (rotation_deg, translation_mm, seed) in [
            (2.5, 7.0, 1),
            (0.01, 0.5, 2),
            (170.0, 40.0, 3),
            (0.0, 3.0, 4),
            (1.0, 0.0, 5),
        ] {
            let work = tempfile::tempdir()?;
            tiny_capture(work.path())?;
            perturb_poses(work.path(), rotation_deg, translation_mm, seed)?;
            let after = Capture::load(work.path())?;
            assert_eq!(after.targets, before.targets, "targets untouched");
            for (old, new) in before.views.iter().zip(&after.views) {
                let (r0, r1) = (old.camera.rotation, new.camera.rotation);
                let angle = rotation_angle(r1 * r0.transpose()).to_degrees();
                assert!(
                    (angle - rotation_deg).abs() < 1e-9,
                    "{}: {angle}° vs {rotation_deg}°",
                    old.name
                );
                let also = rotation_angle(r0.transpose() * r1).to_degrees();
                assert!((also - rotation_deg).abs() < 1e-9);
                let moved_mm = (new.camera.centre() - old.camera.centre()).length() * 1000.0;
                assert!(
                    (moved_mm - translation_mm).abs() < 1e-9,
                    "{}: {moved_mm} mm",
                    old.name
                );
                assert_eq!(
                    (new.camera.fx, new.camera.cx, new.camera.width),
                    (old.camera.fx, old.camera.cx, old.camera.width)
                );
                if rotation_deg == 0.0 {
                    assert_eq!(r0, r1, "no rotation keeps R bit for bit");
                }
            }
            assert_eq!(
                file_bytes(work.path(), &images)?,
                image_bytes,
                "images and masks untouched"
            );
        }
        Ok(())
    }

    #[test]
    fn zero_pose_noise_leaves_the_file_identical_and_seeds_are_deterministic() -> TestResult {
        let dir = tempfile::tempdir()?;
        tiny_capture(dir.path())?;
        let original = std::fs::read(dir.path().join(CAPTURE_FILE_NAME))?;
        perturb_poses(dir.path(), 0.0, 0.0, 9)?;
        assert_eq!(std::fs::read(dir.path().join(CAPTURE_FILE_NAME))?, original);

        let run = |rotation, translation, seed| -> Result<Capture, Box<dyn std::error::Error>> {
            let work = tempfile::tempdir()?;
            tiny_capture(work.path())?;
            perturb_poses(work.path(), rotation, translation, seed)?;
            Ok(Capture::load(work.path())?)
        };
        assert_eq!(run(3.0, 5.0, 11)?, run(3.0, 5.0, 11)?, "same seed, same capture");
        assert_ne!(run(3.0, 5.0, 11)?.views, run(3.0, 5.0, 12)?.views);
        // One seed draws one perturbation whatever its size: the same axes and directions.
        let before = Capture::load(dir.path())?;
        let (small, large) = (run(1.0, 2.0, 11)?, run(3.0, 6.0, 11)?);
        for ((old, s), l) in before.views.iter().zip(&small.views).zip(&large.views) {
            let axis = |r: DMat3| {
                let (axis, _) =
                    glam::DQuat::from_mat3(&(old.camera.rotation.transpose() * r)).to_axis_angle();
                axis
            };
            assert!(axis(s.camera.rotation).abs_diff_eq(axis(l.camera.rotation), 1e-6));
            let (ds, dl) = (
                s.camera.centre() - old.camera.centre(),
                l.camera.centre() - old.camera.centre(),
            );
            assert!((ds * 3.0).abs_diff_eq(dl, 1e-12));
        }
        assert!(perturb_poses(dir.path(), -1.0, 0.0, 0).is_err());
        assert!(perturb_poses(dir.path(), 1.0, f64::NAN, 0).is_err());
        assert_eq!(std::fs::read(dir.path().join(CAPTURE_FILE_NAME))?, original);
        Ok(())
    }

    #[test]
    fn erosion_and_dilation_change_a_square_by_one_pixel_a_side_in_both_formats() -> TestResult {
        for (edit, side) in [
            (MaskEdit::Erode(1), 3),
            (MaskEdit::Dilate(1), 7),
            (MaskEdit::Dilate(2), 9),
            (MaskEdit::Erode(2), 1),
        ] {
            let dir = tempfile::tempdir()?;
            tiny_capture(dir.path())?;
            let untouched = ["images/a.png", "images/b.png", CAPTURE_FILE_NAME];
            let before = file_bytes(dir.path(), &untouched)?;
            edit_masks(dir.path(), edit)?;
            for (file, color) in [("masks/a.png", ColorType::L8), ("masks/b.exr", ColorType::Rgb32F)] {
                let (values, found) = read_mask(&dir.path().join(file))?;
                assert_eq!(found, color, "{file}: format kept");
                assert!(values.iter().all(|&v| v == 0.0 || v == 1.0), "{file}: binary");
                let lo = 7 - side / 2;
                let hi = 7 + side / 2;
                assert_eq!(
                    foreground(&values),
                    (lo, lo, hi, hi, side * side),
                    "{file} {edit:?}"
                );
            }
            assert_eq!(file_bytes(dir.path(), &untouched)?, before, "only masks change");
        }
        Ok(())
    }

    #[test]
    fn softening_keeps_values_in_range_and_the_sum() -> TestResult {
        let dir = tempfile::tempdir()?;
        tiny_capture(dir.path())?;
        edit_masks(dir.path(), MaskEdit::Soften(1.0))?;
        for (file, color, tolerance) in [
            ("masks/a.png", ColorType::L8, 0.02),
            ("masks/b.exr", ColorType::Rgb32F, 1e-5),
        ] {
            let (values, found) = read_mask(&dir.path().join(file))?;
            assert_eq!(found, color, "{file}: format kept");
            assert!(
                values.iter().all(|v| (0.0..=1.0).contains(v)),
                "{file}: in [0, 1]"
            );
            let sum: f32 = values.iter().sum();
            assert!((sum - 25.0).abs() < tolerance * 25.0, "{file}: sum {sum}");
            let soft = values.iter().filter(|&&v| v > 0.01 && v < 0.99).count();
            assert!(soft > 20, "{file}: {soft} soft pixels");
            // Symmetric blur of a centred square: the centre pixel stays the largest.
            let centre = values[7 * SIZE as usize + 7];
            assert!(values.iter().all(|&v| v <= centre));
        }
        Ok(())
    }

    #[test]
    fn zero_edits_and_bad_masks_change_nothing() -> TestResult {
        let dir = tempfile::tempdir()?;
        tiny_capture(dir.path())?;
        let files = ["masks/a.png", "masks/b.exr", CAPTURE_FILE_NAME];
        let before = file_bytes(dir.path(), &files)?;
        for edit in [MaskEdit::Erode(0), MaskEdit::Dilate(0), MaskEdit::Soften(0.0)] {
            edit_masks(dir.path(), edit)?;
        }
        assert!(edit_masks(dir.path(), MaskEdit::Soften(-1.0)).is_err());
        assert!(edit_masks(dir.path(), MaskEdit::Soften(f32::NAN)).is_err());
        assert_eq!(file_bytes(dir.path(), &files)?, before);
        // A view whose mask is its image's alpha: an error naming it, nothing written.
        let mut capture = Capture::load(dir.path())?;
        capture.views[1].mask = None;
        capture.save(dir.path())?;
        let err = edit_masks(dir.path(), MaskEdit::Erode(1))
            .err()
            .map(|e| e.to_string());
        assert!(err.is_some_and(|e| e.contains("\"b\"") && e.contains(CAPTURE_FILE_NAME)));
        assert_eq!(file_bytes(dir.path(), &files[..2])?, before[..2]);
        Ok(())
    }

    #[test]
    fn morphology_clips_at_the_border_and_is_a_square() {
        // A square touching the left and top border stays touching it.
        let (w, h) = (8, 6);
        let mut m = vec![0.0f32; w * h];
        for y in 0..4 {
            for x in 0..3 {
                m[y * w + x] = 0.9;
            }
        }
        let eroded = morphology(&m, w, h, 1, true);
        let kept: Vec<usize> = (0..w * h).filter(|&i| eroded[i] == 1.0).collect();
        assert_eq!(kept, vec![0, 1, w, w + 1, 2 * w, 2 * w + 1]);
        // One pixel dilated by n: a (2n+1)² square, including its corners.
        let mut dot = vec![0.0f32; 9 * 9];
        dot[4 * 9 + 4] = 1.0;
        let grown = morphology(&dot, 9, 9, 2, false);
        assert_eq!(grown.iter().filter(|&&v| v == 1.0).count(), 25);
        assert_eq!(
            (grown[2 * 9 + 2], grown[6 * 9 + 6], grown[9 + 4]),
            (1.0, 1.0, 0.0)
        );
        // A constant mask blurs to itself (weights renormalised at the borders).
        let flat = gaussian_blur(&[0.6; 7 * 5], 7, 5, 2.0);
        assert!(flat.iter().all(|&v| (v - 0.6).abs() < 1e-6));
    }

    #[test]
    fn sun_power_is_constant_as_the_sun_shrinks() {
        let sky = [0.05f32, 0.06, 0.08];
        let sun = DVec3::new(0.3, 0.8, -0.5).normalize();
        let (w, h) = (256, 128);
        let mut peaks = Vec::new();
        for radius in [20.0, 5.0, 1.0, 0.0] {
            let map = sun_envmap(radius, sun, 50.0, sky, w, h);
            let total = map.integral();
            for c in 0..3 {
                let sun_power = total[c] - 4.0 * PI * f64::from(sky[c]);
                assert!((sun_power - 50.0).abs() < 0.01 * 50.0, "{radius}°: {sun_power}");
            }
            // Centred on the direction: the power-weighted mean direction is the sun's.
            let mut mean = DVec3::ZERO;
            for row in 0..h {
                let omega = texel_solid_angle(row, h, w);
                for col in 0..w {
                    let excess = f64::from(map.get(row, col)[0] - sky[0]);
                    mean += texel_center_direction(row, col, h, w) * omega * excess;
                }
            }
            if radius >= 5.0 {
                let off = angle_between(mean, sun).to_degrees();
                assert!(off < 0.1, "{radius}°: centre off by {off}°");
            }
            // A disc around the direction: lit texels lie within the radius plus half
            // a texel diagonal (< 1.5° at 256 × 128), texels well inside are fully lit.
            let inside = 50.0 / (2.0 * PI * (1.0 - radius.to_radians().cos()));
            for row in 0..h {
                for col in 0..w {
                    let excess = f64::from(map.get(row, col)[0] - sky[0]);
                    let from_sun = angle_between(texel_center_direction(row, col, h, w), sun).to_degrees();
                    if excess > 1e-4 {
                        assert!(from_sun < radius + 1.5, "{radius}°: lit at {from_sun}°");
                    }
                    if from_sun < radius - 1.5 {
                        assert!(
                            (excess - inside).abs() < 0.01 * inside,
                            "{radius}°: {excess} vs {inside}"
                        );
                    }
                }
            }
            let (row, col) = texel_of_direction(sun, h, w);
            let peak = map.get(row, col)[0];
            assert!(
                map.texels().iter().all(|t| t[0] <= peak),
                "{radius}°: brightest at the centre"
            );
            peaks.push(peak);
        }
        assert!(
            peaks.windows(2).all(|p| p[1] > p[0]),
            "sharper as it shrinks: {peaks:?}"
        );
    }

    #[test]
    fn target_cameras_sit_at_the_requested_angles_and_frame_the_head() {
        let centre = DVec3::new(0.01, 1.6, -0.02);
        let (radius, distance, fill) = (0.15, 1.2, 0.8);
        let angles = [0.0, 15.0, 45.0, 90.0, 135.0, 179.0, 180.0, -60.0];
        let cams = target_cameras_at_angles(centre, radius, distance, 64, 48, fill, &angles);
        assert_eq!(cams.len(), angles.len());
        for (cam, &angle) in cams.iter().zip(&angles) {
            let offset = cam.centre() - centre;
            assert!((offset.length() - distance).abs() < 1e-12);
            assert!(offset.y.abs() < 1e-12, "on the horizontal circle");
            let from_front = angle_between(offset, DVec3::Z).to_degrees();
            assert!((from_front - angle.abs()).abs() < 1e-9, "{angle}°: {from_front}°");
            if angle.abs() > 0.0 && angle.abs() < 180.0 {
                assert_eq!(offset.x > 0.0, angle > 0.0, "positive angles toward +x");
            }
            assert!(
                cam.forward().abs_diff_eq(-offset / distance, 1e-12),
                "looks at the centre"
            );
            let pixel = cam.project(centre).map(|p| (p.x, p.y));
            assert!(pixel.is_some_and(|(u, v)| (u - 32.0).abs() < 1e-9 && (v - 24.0).abs() < 1e-9));
            // The head sphere's outline spans `fill` of the frame height.
            let half_angle = (radius / distance).asin();
            assert!((cam.fy * half_angle.tan() - fill * 24.0).abs() < 1e-9);
            assert!(cam.validate().is_ok());
        }
    }

    #[test]
    fn mask_encoding_keeps_layouts() -> TestResult {
        let mask = [0.0f32, 0.25, 0.5, 1.0];
        let original = DynamicImage::ImageLumaA16(ImageBuffer::from_pixel(2, 2, image::LumaA([0u16, 0])));
        let out = encode_like(&original, Some(ImageFormat::Png), &mask).ok_or("no encoding")?;
        assert_eq!(out.color(), ColorType::La16);
        let pixel = out.as_luma_alpha16().ok_or("not LA16")?.get_pixel(1, 0).0;
        assert_eq!(pixel, [16384, 16384]);
        let jpeg = DynamicImage::ImageRgb8(ImageBuffer::from_pixel(2, 2, Rgb([0u8; 3])));
        assert!(encode_like(&jpeg, Some(ImageFormat::Jpeg), &mask).is_none());
        Ok(())
    }
}
