//! A capture in our conventions (metres, world frame +y up, OpenCV cameras;
//! `format/CAPTURE.md`) as the network's inputs (millimetres, its own world frame).
//!
//! **Units.** The network thinks in millimetres (its near/far bounds, head radius,
//! depths and densities): points and camera translations are multiplied by
//! [`MM_PER_M`], densities divided by it (σ in 1/mm → 1/m).
//!
//! **World frame.** The per-point networks take world-frame directions, so the
//! world must be oriented as in the official data: up = +z, the face toward −y
//! (cameras on the −y side). Our synthetic captures have up = +y and the face
//! toward +z, so the default `net_from_world` is a rotation of +90° about x
//! (`+y ↦ +z`, `+z ↦ −y`). A point maps as `x_net = 1000 · net_from_world · x`; a
//! camera `[R|t]` as `[R·net_from_worldᵀ | 1000·t]` (intrinsics unchanged).
//!
//! **Images.** Every view must have one size; images are multiplied by their masks
//! (the official tester does the same) and cropped at the right and bottom to
//! multiples of 16 (the encoder halves the resolution four times), which keeps the
//! principal point where it was.
//!
//! A network trained at a small image size ([`crate::Model::working_image_size`]) is
//! given the views box-filtered by a whole factor toward that size
//! ([`NetCapture::for_model`]).
//!
//! [`load_capture_dir`] reads a capture folder: EXR images are linear, PNG/JPEG
//! sRGB-decoded (IEC 61966-2-1); masks are the mask file's value in `[0, 1]` or the
//! image's alpha; the head centre is the point nearest every optical axis.

use std::path::Path;

use glam::{DMat3, DVec3};
use image::DynamicImage;
use nelf_format::capture::Capture;
use nelf_format::conventions::PinholeCamera;
use nelf_scene::mesh_io::srgb_to_linear;

use crate::error::NetError;
use crate::geometry::NetCamera;
use crate::light::world_from_light;
use crate::views::SourceViews;

/// Millimetres per metre: the network's unit is the millimetre.
pub const MM_PER_M: f64 = 1000.0;

/// The default rotation from our world (+y up, face toward +z) to the network's
/// (+z up, face toward −y): +90° about x.
pub fn default_net_from_world() -> DMat3 {
    DMat3::from_rotation_x(std::f64::consts::FRAC_PI_2)
}

/// Averages `factor × factor` blocks of a row-major `width`-wide image (a last
/// partial block column or row is cropped, which keeps the principal point).
pub fn box_down<T: Copy>(
    pixels: &[T],
    width: usize,
    factor: usize,
    zero: T,
    add: impl Fn(T, T) -> T,
    scale: impl Fn(T, f32) -> T,
) -> Vec<T> {
    let height = pixels.len() / width.max(1);
    let (w, h) = (width / factor, height / factor);
    let inv = 1.0 / (factor * factor) as f32;
    let mut out = Vec::with_capacity(w * h);
    for y in 0..h {
        for x in 0..w {
            let mut acc = zero;
            for dy in 0..factor {
                for dx in 0..factor {
                    acc = add(acc, pixels[(y * factor + dy) * width + x * factor + dx]);
                }
            }
            out.push(scale(acc, inv));
        }
    }
    out
}

/// [`box_down`] of linear RGB.
pub fn down_rgb(pixels: &[[f32; 3]], width: usize, factor: usize) -> Vec<[f32; 3]> {
    box_down(
        pixels,
        width,
        factor,
        [0.0; 3],
        |a, b| [a[0] + b[0], a[1] + b[1], a[2] + b[2]],
        |a, s| a.map(|v| v * s),
    )
}

/// [`box_down`] of one channel (a mask: soft where a block straddles its edge).
pub fn down_scalar(pixels: &[f32], width: usize, factor: usize) -> Vec<f32> {
    box_down(pixels, width, factor, 0.0, |a, b| a + b, |a, s| a * s)
}

/// `camera` seen at `1/factor` of its resolution.
pub fn scaled_camera(camera: &PinholeCamera, factor: usize) -> PinholeCamera {
    let s = 1.0 / factor as f64;
    PinholeCamera {
        width: camera.width / factor as u32,
        height: camera.height / factor as u32,
        fx: camera.fx * s,
        fy: camera.fy * s,
        cx: camera.cx * s,
        cy: camera.cy * s,
        ..*camera
    }
}

/// The whole factor that brings a `width × height` capture nearest to a network's
/// working image side (the shorter side ≈ `working`), never enlarging: 1 when
/// `working` is unknown or not smaller.
pub fn working_factor(width: usize, height: usize, working: Option<usize>) -> usize {
    match working {
        Some(side) if side > 0 => {
            let short = width.min(height) as f64;
            ((short / side as f64).round() as usize).max(1)
        }
        _ => 1,
    }
}

/// Cameras, linear RGB images (row-major) and masks of a set of views.
pub type ViewSet = (Vec<PinholeCamera>, Vec<Vec<[f32; 3]>>, Vec<Vec<f32>>);

/// Views reduced by a whole `factor` ([`box_down`] of images and masks, intrinsics
/// scaled); `factor = 1` returns them as they are.
pub fn reduce_views(
    cameras: &[PinholeCamera],
    images: &[Vec<[f32; 3]>],
    masks: &[Vec<f32>],
    factor: usize,
) -> ViewSet {
    if factor <= 1 {
        return (cameras.to_vec(), images.to_vec(), masks.to_vec());
    }
    let cams = cameras.iter().map(|c| scaled_camera(c, factor)).collect();
    let imgs = images
        .iter()
        .zip(cameras)
        .map(|(i, c)| down_rgb(i, c.width as usize, factor))
        .collect();
    let msks = masks
        .iter()
        .zip(cameras)
        .map(|(m, c)| down_scalar(m, c.width as usize, factor))
        .collect();
    (cams, imgs, msks)
}

/// Views of different sizes brought to one, so that the network, which stacks its
/// views, takes them all, at one scale: each view is first resampled (bilinear,
/// pixel centres at half-integers, edges clamped) so that its focal length `fx` is
/// the views' largest (a head then spans as many pixels in every view, as in
/// training), then padded on the right and below with empty pixels (mask 0) to the
/// largest width and height among them (intrinsics unchanged by the padding).
/// Views of one size are returned as they are.
pub fn to_one_size(cameras: &[PinholeCamera], images: &[Vec<[f32; 3]>], masks: &[Vec<f32>]) -> ViewSet {
    let same = cameras
        .windows(2)
        .all(|p| (p[0].width, p[0].height) == (p[1].width, p[1].height));
    let consistent = cameras.iter().zip(images.iter().zip(masks)).all(|(c, (i, m))| {
        c.width > 0 && c.height > 0 && i.len() == m.len() && i.len() == (c.width * c.height) as usize
    });
    if same || !consistent {
        // As they are (a wrong pixel count is reported by the caller's checks).
        return (cameras.to_vec(), images.to_vec(), masks.to_vec());
    }
    let focal = cameras.iter().map(|c| c.fx).fold(0.0f64, f64::max);
    let scaled: Vec<(PinholeCamera, Vec<[f32; 3]>, Vec<f32>)> = cameras
        .iter()
        .zip(images.iter().zip(masks))
        .map(|(camera, (image, mask))| {
            let k = if camera.fx > 0.0 { focal / camera.fx } else { 1.0 };
            if (k - 1.0).abs() < 1e-9 {
                return (*camera, image.clone(), mask.clone());
            }
            let (w, h) = (camera.width as usize, camera.height as usize);
            let (nw, nh) = (
                ((w as f64 * k).round() as usize).max(1),
                ((h as f64 * k).round() as usize).max(1),
            );
            let (sx, sy) = (w as f64 / nw as f64, h as f64 / nh as f64);
            // Bilinear taps of the old image at the centre of new pixel i.
            let taps = |i: usize, old: usize, s: f64| -> (usize, usize, f32) {
                let x = ((i as f64 + 0.5) * s - 0.5).clamp(0.0, (old - 1) as f64);
                let x0 = x.floor() as usize;
                (x0, (x0 + 1).min(old - 1), (x - x0 as f64) as f32)
            };
            let mut rgb = Vec::with_capacity(nw * nh);
            let mut alpha = Vec::with_capacity(nw * nh);
            for j in 0..nh {
                let (y0, y1, ty) = taps(j, h, sy);
                for i in 0..nw {
                    let (x0, x1, tx) = taps(i, w, sx);
                    let weights = [
                        (y0 * w + x0, (1.0 - tx) * (1.0 - ty)),
                        (y0 * w + x1, tx * (1.0 - ty)),
                        (y1 * w + x0, (1.0 - tx) * ty),
                        (y1 * w + x1, tx * ty),
                    ];
                    rgb.push(std::array::from_fn(|c| {
                        weights.iter().map(|&(p, wt)| image[p][c] * wt).sum()
                    }));
                    alpha.push(weights.iter().map(|&(p, wt)| mask[p] * wt).sum());
                }
            }
            let camera = PinholeCamera {
                width: nw as u32,
                height: nh as u32,
                fx: camera.fx / sx,
                cx: camera.cx / sx,
                fy: camera.fy / sy,
                cy: camera.cy / sy,
                ..*camera
            };
            (camera, rgb, alpha)
        })
        .collect();
    let width = scaled.iter().map(|v| v.0.width).max().unwrap_or(0);
    let height = scaled.iter().map(|v| v.0.height).max().unwrap_or(0);
    let mut out: ViewSet = (Vec::new(), Vec::new(), Vec::new());
    for (camera, image, mask) in scaled {
        let w = camera.width as usize;
        let mut rgb = vec![[0.0f32; 3]; (width * height) as usize];
        let mut alpha = vec![0.0f32; (width * height) as usize];
        for (y, (row, mask_row)) in image.chunks(w).zip(mask.chunks(w)).enumerate() {
            let at = y * width as usize;
            rgb[at..at + w].copy_from_slice(row);
            alpha[at..at + w].copy_from_slice(mask_row);
        }
        out.0.push(PinholeCamera {
            width,
            height,
            ..camera
        });
        out.1.push(rgb);
        out.2.push(alpha);
    }
    out
}

/// A capture prepared for the network.
#[derive(Debug, Clone)]
pub struct NetCapture {
    /// The network's inputs (millimetres, network frame).
    pub views: SourceViews,
    /// Our cameras (metres, world frame), with the cropped image size.
    pub cameras: Vec<PinholeCamera>,
    /// Rotation from our world frame to the network's.
    pub net_from_world: DMat3,
    /// Centre of the head (rays are bounded by a sphere around it), metres.
    pub head_centre_m: DVec3,
}

impl NetCapture {
    /// [`NetCapture::new`] after reducing the views toward `model`'s working image
    /// size ([`working_factor`]), so that a network trained at 64 pixels sees a
    /// 512-pixel capture as it saw its training images.
    pub fn for_model(
        model: &crate::Model,
        cameras: &[PinholeCamera],
        images: &[Vec<[f32; 3]>],
        masks: &[Vec<f32>],
        head_centre_m: DVec3,
        net_from_world: DMat3,
    ) -> Result<Self, NetError> {
        Self::at_working_size(
            cameras,
            images,
            masks,
            head_centre_m,
            net_from_world,
            model.working_image_size(),
        )
    }

    /// [`NetCapture::new`] after reducing the views toward a working image side
    /// ([`working_factor`]; `None`: as they are).
    fn at_working_size(
        cameras: &[PinholeCamera],
        images: &[Vec<[f32; 3]>],
        masks: &[Vec<f32>],
        head_centre_m: DVec3,
        net_from_world: DMat3,
        working_image_size: Option<usize>,
    ) -> Result<Self, NetError> {
        let (cameras, images, masks) = to_one_size(cameras, images, masks);
        let factor = cameras.first().map_or(1, |c| {
            working_factor(c.width as usize, c.height as usize, working_image_size)
        });
        let (cams, imgs, msks) = reduce_views(&cameras, &images, &masks, factor);
        Self::new(&cams, &imgs, &msks, head_centre_m, net_from_world)
    }

    /// Prepares views: `images` (linear RGB, row-major) and `masks` (`[0, 1]`) of the
    /// size of each camera, all views one size, at least two; `head_centre_m` in our
    /// world; `net_from_world` a rotation ([`default_net_from_world`] for our captures).
    pub fn new(
        cameras: &[PinholeCamera],
        images: &[Vec<[f32; 3]>],
        masks: &[Vec<f32>],
        head_centre_m: DVec3,
        net_from_world: DMat3,
    ) -> Result<Self, NetError> {
        if !nelf_format::conventions::is_rotation(net_from_world, 1e-6) {
            return Err(NetError::input("net_from_world is not a rotation"));
        }
        if !head_centre_m.is_finite() {
            return Err(NetError::input("the head centre is not finite"));
        }
        let v = cameras.len();
        if v < 2 || images.len() != v || masks.len() != v {
            return Err(NetError::input(format!(
                "{v} cameras, {} images and {} masks: need at least 2 views, one of each",
                images.len(),
                masks.len()
            )));
        }
        let (full_w, full_h) = (cameras[0].width as usize, cameras[0].height as usize);
        let (w, h) = (full_w / 16 * 16, full_h / 16 * 16);
        if w == 0 || h == 0 {
            return Err(NetError::input(format!(
                "images of {full_w}×{full_h} are smaller than 16 pixels"
            )));
        }
        let mut view_images = Vec::with_capacity(v * w * h * 3);
        let mut view_masks = Vec::with_capacity(v * w * h);
        let mut ours = Vec::with_capacity(v);
        for (i, ((cam, image), mask)) in cameras.iter().zip(images).zip(masks).enumerate() {
            cam.validate()?;
            if cam.width as usize != full_w || cam.height as usize != full_h {
                return Err(NetError::input(format!(
                    "view {i} is {}×{}, view 0 {full_w}×{full_h}: the network needs one size",
                    cam.width, cam.height
                )));
            }
            if image.len() != full_w * full_h || mask.len() != full_w * full_h {
                return Err(NetError::input(format!(
                    "view {i}: {} pixels and {} mask values for a {full_w}×{full_h} camera",
                    image.len(),
                    mask.len()
                )));
            }
            for y in 0..h {
                for x in 0..w {
                    let m = mask[y * full_w + x];
                    let m = if m.is_finite() { m.clamp(0.0, 1.0) } else { 0.0 };
                    let rgb = image[y * full_w + x];
                    view_images.extend(rgb.map(|c| if c.is_finite() { c * m } else { 0.0 }));
                    view_masks.push(m);
                }
            }
            let mut cropped = *cam;
            cropped.width = w as u32;
            cropped.height = h as u32;
            ours.push(cropped);
        }
        let views = SourceViews {
            images: view_images,
            masks: view_masks,
            cameras: ours
                .iter()
                .map(|c| NetCamera::from_pinhole(c, net_from_world))
                .collect(),
            width: w,
            height: h,
        };
        views.validate()?;
        Ok(Self {
            views,
            cameras: ours,
            net_from_world,
            head_centre_m,
        })
    }

    /// A point of our world (metres) in the network's (millimetres).
    pub fn to_net_point(&self, p_m: DVec3) -> [f32; 3] {
        (self.net_from_world * p_m * MM_PER_M).as_vec3().to_array()
    }

    /// A direction of our world in the network's frame.
    pub fn to_net_direction(&self, d: DVec3) -> [f32; 3] {
        (self.net_from_world * d).as_vec3().to_array()
    }

    /// One of our cameras as the network sees it.
    pub fn net_camera(&self, camera: &PinholeCamera) -> NetCamera {
        NetCamera::from_pinhole(camera, self.net_from_world)
    }

    /// The head centre in the network's frame (millimetres).
    pub fn head_centre_net(&self) -> [f32; 3] {
        self.to_net_point(self.head_centre_m)
    }

    /// Rotation from the light frame of the network's lighting and light transport
    /// (columns reversed into our layout, [`crate::light`]) to our world: `R₀ᵀ·F`.
    pub fn world_from_light(&self) -> DMat3 {
        world_from_light(self.cameras[0].rotation)
    }
}

pub use nelf_format::conventions::nearest_point_to_axes as head_centre;

fn decode(path: &Path) -> Result<DynamicImage, NetError> {
    image::ImageReader::open(path)
        .map_err(|e| NetError::file(path, e.to_string()))?
        .with_guessed_format()
        .map_err(|e| NetError::file(path, e.to_string()))?
        .decode()
        .map_err(|e| NetError::file(path, e.to_string()))
}

fn clamp_mask(v: f32) -> f32 {
    if v.is_nan() { 0.0 } else { v.clamp(0.0, 1.0) }
}

/// One view's linear RGB (EXR as is, PNG/JPEG sRGB-decoded) and mask (the mask
/// file's luminance, else the image's alpha), checked against the camera's size.
fn load_view(
    dir: &Path,
    view: &nelf_format::capture::CaptureView,
) -> Result<(Vec<[f32; 3]>, Vec<f32>), NetError> {
    let path = view.image_path(dir);
    let image = decode(&path)?;
    let (w, h) = (view.camera.width, view.camera.height);
    if image.width() != w || image.height() != h {
        return Err(NetError::file(
            &path,
            format!("{}×{} image for a {w}×{h} camera", image.width(), image.height()),
        ));
    }
    let linear = path
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("exr"));
    let rgba = image.to_rgba32f();
    let decode_channel = |c: f32| {
        let c = if c.is_finite() { c.max(0.0) } else { 0.0 };
        if linear { c } else { srgb_to_linear(c) }
    };
    let rgb = rgba
        .pixels()
        .map(|p| [0, 1, 2].map(|k| decode_channel(p.0[k])))
        .collect();
    let mask: Vec<f32> = if let Some(mask_path) = view.mask_path(dir) {
        let m = decode(&mask_path)?;
        if m.width() != w || m.height() != h {
            return Err(NetError::file(
                &mask_path,
                format!("mask is {}×{}, image {w}×{h}", m.width(), m.height()),
            ));
        }
        m.to_luma32f().pixels().map(|p| clamp_mask(p.0[0])).collect()
    } else if image.color().has_alpha() {
        rgba.pixels().map(|p| clamp_mask(p.0[3])).collect()
    } else {
        return Err(NetError::file(
            &path,
            format!("view {:?} has no mask file and no alpha", view.name),
        ));
    };
    if !mask.iter().any(|&m| m > 0.5) {
        return Err(NetError::file(
            &path,
            format!("view {:?}: the mask is empty", view.name),
        ));
    }
    Ok((rgb, mask))
}

/// Loads a capture folder (`cameras.json`, `format/CAPTURE.md`) for the network:
/// decodes every view's image and mask, estimates the head centre
/// ([`head_centre`]) and prepares the views ([`NetCapture::new`]). Returns the
/// capture's description too.
pub fn load_capture_dir(
    dir: impl AsRef<Path>,
    net_from_world: DMat3,
) -> Result<(NetCapture, Capture), NetError> {
    load_capture_dir_at(dir.as_ref(), net_from_world, None)
}

/// [`load_capture_dir`] for `model`: the views reduced toward its working image size
/// as [`NetCapture::for_model`] does.
pub fn load_capture_dir_for_model(
    dir: impl AsRef<Path>,
    net_from_world: DMat3,
    model: &crate::Model,
) -> Result<(NetCapture, Capture), NetError> {
    load_capture_dir_at(dir.as_ref(), net_from_world, model.working_image_size())
}

fn load_capture_dir_at(
    dir: &Path,
    net_from_world: DMat3,
    working_image_size: Option<usize>,
) -> Result<(NetCapture, Capture), NetError> {
    let capture = Capture::load(dir)?;
    let mut images = Vec::with_capacity(capture.views.len());
    let mut masks = Vec::with_capacity(capture.views.len());
    for view in &capture.views {
        let (rgb, mask) = load_view(dir, view)?;
        images.push(rgb);
        masks.push(mask);
    }
    let cameras = capture.cameras();
    let centre = head_centre(&cameras).ok_or_else(|| {
        NetError::file(
            dir,
            "the cameras' optical axes are (nearly) parallel: no head centre",
        )
    })?;
    let prepared = NetCapture::at_working_size(
        &cameras,
        &images,
        &masks,
        centre,
        net_from_world,
        working_image_size,
    )?;
    Ok((prepared, capture))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn views_of_other_sizes_are_brought_to_one_scale_and_size() {
        let big = PinholeCamera::look_at(DVec3::new(0.0, 0.0, 1.0), DVec3::ZERO, DVec3::Y, 40, 30, 0.6);
        // Half the focal length (a wider lens, or a smaller photograph) and off-centre.
        let small = PinholeCamera {
            cx: 11.0,
            ..PinholeCamera::look_at(DVec3::new(0.3, 0.0, 1.0), DVec3::ZERO, DVec3::Y, 20, 10, 0.6)
        };
        // The same focal length, another size: only padded.
        let tall = PinholeCamera::look_at(DVec3::new(0.0, 0.3, 1.0), DVec3::ZERO, DVec3::Y, 40, 36, 0.6);
        // A ramp in continuous pixel coordinates, which bilinear resampling keeps.
        let ramp = |c: &PinholeCamera| -> Vec<[f32; 3]> {
            (0..c.width * c.height)
                .map(|k| {
                    let (x, y) = (f64::from(k % c.width) + 0.5, f64::from(k / c.width) + 0.5);
                    [(0.01 * x) as f32, (0.02 * y) as f32, 1.0]
                })
                .collect()
        };
        let cameras = [big, small, tall];
        let images: Vec<_> = cameras.iter().map(ramp).collect();
        let masks: Vec<_> = cameras
            .iter()
            .map(|c| vec![0.5f32; (c.width * c.height) as usize])
            .collect();
        let (cams, imgs, msks) = to_one_size(&cameras, &images, &masks);
        assert!(cams.iter().all(|c| (c.width, c.height) == (40, 36)), "{cams:?}");
        assert!(imgs.iter().all(|i| i.len() == 40 * 36) && msks.iter().all(|m| m.len() == 40 * 36));
        assert!(cams.iter().all(|c| (c.fx - big.fx).abs() < 1e-9), "{cams:?}");
        // Padding keeps the pixels where they were and adds empty ones.
        assert_eq!(cams[0], PinholeCamera { height: 36, ..big });
        assert_eq!(&imgs[0][..1200], &images[0][..]);
        assert!(imgs[0][1200..].iter().all(|p| *p == [0.0; 3]) && msks[0][1200..].iter().all(|&m| m == 0.0));
        assert_eq!(cams[2], tall);
        // The small view, twice its size: a world point lands on the same spot.
        let p = DVec3::new(0.05, -0.03, 0.1);
        let (old, new) = (small.project(p).unwrap(), cams[1].project(p).unwrap());
        assert!((new.x * 0.5 - old.x).abs() < 1e-9 && (new.y * 0.5 - old.y).abs() < 1e-9);
        // Inside the clamped border it holds the old ramp at that spot; masks 0.5
        // inside, 0 in the padding.
        for (i, j) in [(5usize, 4usize), (20, 11), (33, 17)] {
            let (x, y) = ((i as f64 + 0.5) * 0.5, (j as f64 + 0.5) * 0.5);
            let got = imgs[1][j * 40 + i];
            assert!((f64::from(got[0]) - 0.01 * x).abs() < 1e-6, "{got:?} at {x}");
            assert!((f64::from(got[1]) - 0.02 * y).abs() < 1e-6, "{got:?} at {y}");
        }
        assert!((msks[1][5 * 40 + 5] - 0.5).abs() < 1e-6 && msks[1][30 * 40 + 5] == 0.0);
    }

    #[test]
    fn default_frame_turns_y_up_into_z_up() {
        let a = default_net_from_world();
        assert!((a * DVec3::Y).abs_diff_eq(DVec3::Z, 1e-12));
        assert!((a * DVec3::Z).abs_diff_eq(DVec3::NEG_Y, 1e-12));
    }

    #[test]
    fn views_reduce_toward_the_working_size_and_keep_projections() {
        assert_eq!(working_factor(192, 192, Some(64)), 3);
        assert_eq!(working_factor(512, 384, Some(64)), 6);
        assert_eq!(working_factor(48, 48, Some(64)), 1);
        assert_eq!(working_factor(512, 512, None), 1);
        let cam = PinholeCamera::look_at(DVec3::new(0.3, 0.1, 1.0), DVec3::ZERO, DVec3::Y, 97, 64, 0.6);
        // A 2 × 2 checker of 3-pixel cells: every 3 × 3 block is one colour.
        let image: Vec<[f32; 3]> = (0..97 * 64)
            .map(|i| [((i % 97 / 3 + i / 97 / 3) % 2) as f32, 0.5, 0.0])
            .collect();
        let mask = vec![1.0f32; 97 * 64];
        let (cams, images, masks) = reduce_views(&[cam], std::slice::from_ref(&image), &[mask], 3);
        // 97 is cropped to 32 whole blocks; the blocks average exactly.
        assert_eq!((cams[0].width, cams[0].height), (32, 21));
        assert_eq!(images[0].len(), 32 * 21);
        assert_eq!(images[0][1], image[3]);
        assert_eq!(images[0][32], image[3 * 97]);
        assert!(masks[0].iter().all(|&m| m == 1.0));
        // A point projects to the same place, in reduced pixels.
        let p = DVec3::new(0.02, -0.03, 0.01);
        let full = cam.project(p).unwrap();
        let reduced = cams[0].project(p).unwrap();
        assert!((full / 3.0 - reduced).length() < 1e-9);
        let (same, _, _) = reduce_views(&[cam], &[image], &[vec![1.0; 97 * 64]], 1);
        assert_eq!(same[0], cam);
    }

    #[test]
    fn crops_to_multiples_of_sixteen_and_masks_images() {
        let cams: Vec<PinholeCamera> = [0.0f64, 0.4]
            .iter()
            .map(|&a| {
                let eye = DVec3::new(a.sin(), 0.0, a.cos());
                PinholeCamera::look_at(eye, DVec3::ZERO, DVec3::Y, 40, 35, 0.5)
            })
            .collect();
        let images = vec![vec![[1.0f32, 2.0, 3.0]; 40 * 35]; 2];
        let masks = vec![vec![0.5f32; 40 * 35]; 2];
        let cap = NetCapture::new(&cams, &images, &masks, DVec3::ZERO, default_net_from_world()).unwrap();
        assert_eq!((cap.views.width, cap.views.height), (32, 32));
        assert_eq!(cap.views.images[..3], [0.5, 1.0, 1.5]);
        assert_eq!(cap.cameras[0].cx, cams[0].cx);
        // The network camera sees our points where ours do (mm, rotated frame).
        let p = DVec3::new(0.01, 0.02, -0.03);
        let want = cams[1].project(p).unwrap();
        let net = &cap.views.cameras[1];
        let g = crate::geometry::project_normalized(&net.projection(), 32, 32, cap.to_net_point(p));
        assert!((f64::from((g[0] + 1.0) * 16.0) - want.x).abs() < 1e-3);
        assert!((f64::from((g[1] + 1.0) * 16.0) - want.y).abs() < 1e-3);
        let bad = NetCapture::new(
            &cams[..1],
            &images[..1],
            &masks[..1],
            DVec3::ZERO,
            default_net_from_world(),
        );
        assert!(bad.is_err());
    }
}
