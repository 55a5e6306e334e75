//! The network field's density carved to the visual hull of the capture's masks,
//! as a signed distance, so that a baked network keeps the silhouettes its input
//! photos show.
//!
//! **Why**: the network's density leaves a thin halo outside the true silhouette
//! once it is sampled on a grid of voxels about two pixels wide and box-filtered
//! (`nelf_pipeline::VoxelFiltered`): a baked head renders up to a pixel too
//! wide all round, where the network's own rendering does not. The masks bound the
//! subject exactly: no point outside the visual hull (Laurentini 1994) can be
//! occupied.
//!
//! **Signed distance to the hull.** Per view, the mask (foreground as
//! [`crate::hull`] has it, value > ½) is padded with one pixel of background on every side (pixels
//! outside the frame are background) and its exact Euclidean distance transform is
//! taken both ways (Felzenszwalb & Huttenlocher 2012, the separable lower envelope
//! of parabolas) in the image plane at unit depth, where a pixel is `1/f_x` wide and
//! `1/f_y` tall, so that `f_x ≠ f_y` stretches nothing. A pixel outside gets
//! `+(distance to the nearest foreground centre − ½ p)`, one inside `−(distance to
//! the nearest background centre − ½ p)`, `p = 1/√(f_x f_y)` the mean pixel size, so
//! the zero level runs midway between the two (exactly for `f_x = f_y`; else within
//! `½ |1/f_x − 1/f_y|` of it). A point `x` is projected into each view in front of
//! whose camera it lies, the signed distance `s_v` is read bilinearly (with the
//! excess beyond the padded frame added for points that project outside it) and
//! turned into metres at the point's depth, `d_v = (s_v − m·p) · z_v` with the
//! margin `m` (pixels). The hull is the
//! intersection of the views' cones, so `d(x) = max_v d_v`: exact in the
//! cone's cross-section near each silhouette, a lower bound of the true distance
//! elsewhere (which only carves less).
//!
//! **Carve**: the stored density (the signed function of `ln σ`,
//! `nelf_scene::signed_density::SignedLogDensity`) becomes `min(s_net(x), s(d(x)))` with
//! `s(d)` the same signed profile of a surface at distance `d`: inside the hull
//! nothing changes (beyond a voxel or two of it, `s(d)` is at its cap); outside, the
//! density falls as it does across any surface. Light transport is untouched.
//! [`HullCarved`] is an `nelf_scene::adapter::Adapter` over the signed density:
//! bounds and light frame are its.

use glam::{DVec3, Vec3};
use nelf_format::conventions::PinholeCamera;
use nelf_scene::adapter::{Adapted, Adapter};
use nelf_scene::field::{FieldError, FieldSource, ViewPolicy};
use nelf_scene::signed_density::SignedLogDensity;

use crate::error::{BakeError, Result};
use crate::hull::{check_mask_count, check_mask_size, is_foreground};

/// Squared-distance stand-in for "no such pixel" in the distance transform.
const FAR: f64 = 1e20;

/// One view's signed distance to its mask's silhouette in the image plane at unit
/// depth (units of `x/z`), on the padded pixel grid.
#[derive(Debug, Clone)]
struct ViewDistance {
    camera: PinholeCamera,
    /// A pixel's width and height at unit depth, `(1/f_x, 1/f_y)`.
    pixel: [f64; 2],
    /// Padded size `(width + 2, height + 2)`.
    width: usize,
    height: usize,
    /// Signed distance at the padded pixels' centres, units of `x/z` (positive outside).
    signed: Vec<f32>,
}

impl ViewDistance {
    fn new(camera: &PinholeCamera, mask: &[f32]) -> Result<Self> {
        camera
            .validate()
            .map_err(|e| BakeError::Hull(format!("a view's camera: {e}")))?;
        let (w, h) = (camera.width as usize, camera.height as usize);
        check_mask_size(mask, w, h)?;
        let (pw, ph) = (w + 2, h + 2);
        let inside: Vec<bool> = (0..pw * ph)
            .map(|i| {
                let (x, y) = (i % pw, i / pw);
                (1..=w).contains(&x) && (1..=h).contains(&y) && is_foreground(mask[(y - 1) * w + (x - 1)])
            })
            .collect();
        let pixel = [1.0 / camera.fx, 1.0 / camera.fy];
        let half = 0.5 * mean_pixel(camera);
        let to_inside = distance_transform(&inside, pw, ph, pixel);
        let outside: Vec<bool> = inside.iter().map(|i| !i).collect();
        let to_outside = distance_transform(&outside, pw, ph, pixel);
        let signed = inside
            .iter()
            .zip(to_inside.iter().zip(&to_outside))
            .map(|(&is_in, (&d_in, &d_out))| {
                if is_in {
                    -(d_out.sqrt() - half) as f32
                } else if d_in >= FAR {
                    // No foreground anywhere: every point is outside, far.
                    (pw as f64 * pixel[0] + ph as f64 * pixel[1]) as f32
                } else {
                    (d_in.sqrt() - half) as f32
                }
            })
            .collect();
        Ok(Self {
            camera: *camera,
            pixel,
            width: pw,
            height: ph,
            signed,
        })
    }

    /// Signed distance (units of `x/z`) at continuous image coordinates `(u, v)` of
    /// the unpadded image, bilinear between padded pixel centres; beyond the padded
    /// frame, the value at its edge plus the distance to it.
    fn signed_at(&self, u: f64, v: f64) -> f64 {
        // Padded pixel i's centre is at unpadded coordinate i − 0.5.
        let gx = u + 0.5;
        let gy = v + 0.5;
        let max_x = (self.width - 1) as f64;
        let max_y = (self.height - 1) as f64;
        let cx = gx.clamp(0.0, max_x);
        let cy = gy.clamp(0.0, max_y);
        let excess = ((gx - cx) * self.pixel[0]).hypot((gy - cy) * self.pixel[1]);
        let x0 = (cx.floor() as usize).min(self.width - 2);
        let y0 = (cy.floor() as usize).min(self.height - 2);
        let (tx, ty) = (cx - x0 as f64, cy - y0 as f64);
        let at = |x: usize, y: usize| f64::from(self.signed[y * self.width + x]);
        let top = at(x0, y0) * (1.0 - tx) + at(x0 + 1, y0) * tx;
        let bottom = at(x0, y0 + 1) * (1.0 - tx) + at(x0 + 1, y0 + 1) * tx;
        top * (1.0 - ty) + bottom * ty + excess
    }
}

/// The mean size of a camera's pixel at unit depth, `1/√(f_x f_y)`: what the hull's
/// margin and the half pixel between centres are counted in.
fn mean_pixel(camera: &PinholeCamera) -> f64 {
    1.0 / (camera.fx * camera.fy).sqrt()
}

/// Squared Euclidean distance from every pixel centre to the nearest pixel where
/// `target` is true (`FAR` where there is none), pixels `spacing[0]` wide and
/// `spacing[1]` tall: the separable exact transform.
fn distance_transform(target: &[bool], width: usize, height: usize, spacing: [f64; 2]) -> Vec<f64> {
    let mut grid: Vec<f64> = target.iter().map(|&t| if t { 0.0 } else { FAR }).collect();
    let mut line = Vec::new();
    let mut out = Vec::new();
    for y in 0..height {
        line.clear();
        line.extend_from_slice(&grid[y * width..(y + 1) * width]);
        lower_envelope(&line, spacing[0], &mut out);
        grid[y * width..(y + 1) * width].copy_from_slice(&out);
    }
    for x in 0..width {
        line.clear();
        line.extend((0..height).map(|y| grid[y * width + x]));
        lower_envelope(&line, spacing[1], &mut out);
        for (y, d) in out.iter().enumerate() {
            grid[y * width + x] = *d;
        }
    }
    grid
}

/// `out[q] = min_p (s·(q − p))² + f[p]` for sites `spacing = s` apart: the lower
/// envelope of parabolas rooted at every `p` (Felzenszwalb & Huttenlocher), in O(n).
/// Sites with `f = FAR` are left out.
fn lower_envelope(f: &[f64], spacing: f64, out: &mut Vec<f64>) {
    let n = f.len();
    out.clear();
    let sites: Vec<usize> = (0..n).filter(|&p| f[p] < FAR).collect();
    if sites.is_empty() {
        out.resize(n, FAR);
        return;
    }
    // Parabola roots kept (v) and the boundaries between them (z).
    let mut v: Vec<usize> = Vec::with_capacity(sites.len());
    let mut z: Vec<f64> = Vec::with_capacity(sites.len() + 1);
    // Where the parabolas of sites p < q meet, in units of the index.
    let s2 = spacing * spacing;
    let meet = |p: usize, q: usize| {
        let (p_f, q_f) = (p as f64, q as f64);
        ((f[q] / s2 + q_f * q_f) - (f[p] / s2 + p_f * p_f)) / (2.0 * (q_f - p_f))
    };
    for &q in &sites {
        while let Some(&last) = v.last() {
            let s = meet(last, q);
            if z.last().is_some_and(|&zl| s <= zl) {
                v.pop();
                z.pop();
            } else {
                v.push(q);
                z.push(s);
                break;
            }
        }
        if v.is_empty() {
            v.push(q);
        }
    }
    // z[i] is the boundary between v[i] and v[i + 1].
    let mut k = 0;
    for q in 0..n {
        while k < z.len() && z[k] < q as f64 {
            k += 1;
        }
        let p = v[k];
        let d = (q as f64 - p as f64) * spacing;
        out.push(d * d + f[p]);
    }
}

/// Signed distance (metres, positive outside) to the visual hull of a capture's
/// masks grown by a margin; see the module documentation.
#[derive(Debug, Clone)]
pub struct HullDistance {
    views: Vec<ViewDistance>,
    margin_px: f64,
}

impl HullDistance {
    /// The hull of `masks` (one per camera, row-major, values in `[0, 1]`, the size
    /// of its camera's image), each grown by `margin_px` pixels.
    ///
    /// # Errors
    /// Cameras and masks disagree in number or size, or the margin is not finite.
    pub fn new(cameras: &[PinholeCamera], masks: &[Vec<f32>], margin_px: f64) -> Result<Self> {
        check_mask_count(cameras, masks)?;
        if !margin_px.is_finite() {
            return Err(BakeError::Hull(format!(
                "the hull's margin {margin_px} px is not finite"
            )));
        }
        let views = cameras
            .iter()
            .zip(masks)
            .map(|(c, m)| ViewDistance::new(c, m))
            .collect::<Result<Vec<_>>>()?;
        Ok(Self { views, margin_px })
    }

    /// Signed distance of `x` to the hull, metres (positive outside); `−∞` when `x`
    /// lies behind every camera (nothing bounds it).
    pub fn distance_m(&self, x: DVec3) -> f64 {
        self.views
            .iter()
            .filter_map(|view| {
                let p = view.camera.camera_from_world(x);
                (p.z > 0.0).then(|| {
                    let u = view.camera.fx * p.x / p.z + view.camera.cx;
                    let v = view.camera.fy * p.y / p.z + view.camera.cy;
                    (view.signed_at(u, v) - self.margin_px * mean_pixel(&view.camera)) * p.z
                })
            })
            .fold(f64::NEG_INFINITY, f64::max)
    }
}

/// A network field's signed density carved to the visual hull ([`HullDistance`]):
/// `min(s_net(x), s(d(x)))`, light transport unchanged. Its constructor returns it
/// [`Adapted`] (a [`FieldSource`]).
pub struct HullCarved<'a> {
    signed: &'a Adapted<SignedLogDensity<'a>>,
    hull: HullDistance,
}

impl std::fmt::Debug for HullCarved<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("HullCarved")
            .field("views", &self.hull.views.len())
            .field("margin_px", &self.hull.margin_px)
            .finish_non_exhaustive()
    }
}

impl<'a> HullCarved<'a> {
    /// `signed` carved to `hull`.
    pub fn new(signed: &'a Adapted<SignedLogDensity<'a>>, hull: HullDistance) -> Adapted<Self> {
        Adapted(Self { signed, hull })
    }

    fn carve(&self, points: &[Vec3], density: &mut [f32]) {
        for (x, d) in points.iter().zip(density.iter_mut()) {
            let to_hull = self.hull.distance_m(x.as_dvec3());
            if to_hull.is_finite() {
                *d = d.min(self.signed.encode_distance(to_hull as f32));
            }
        }
    }
}

impl Adapter for HullCarved<'_> {
    fn base(&self) -> &dyn FieldSource {
        self.signed
    }

    fn evaluate(
        &self,
        points: &[Vec3],
        view: &ViewPolicy,
        density: &mut [f32],
        lt: &mut [f32],
    ) -> std::result::Result<(), FieldError> {
        self.signed.evaluate(points, view, density, lt)?;
        self.carve(points, density);
        Ok(())
    }

    fn evaluate_density(&self, points: &[Vec3], density: &mut [f32]) -> std::result::Result<(), FieldError> {
        self.signed.evaluate_density(points, density)?;
        self.carve(points, density);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn brute_force(target: &[bool], width: usize, height: usize, spacing: [f64; 2]) -> Vec<f64> {
        (0..width * height)
            .map(|i| {
                let (x, y) = ((i % width) as f64, (i / width) as f64);
                (0..width * height)
                    .filter(|&j| target[j])
                    .map(|j| {
                        (((j % width) as f64 - x) * spacing[0]).powi(2)
                            + (((j / width) as f64 - y) * spacing[1]).powi(2)
                    })
                    .fold(FAR, f64::min)
            })
            .collect()
    }

    #[test]
    fn distance_transform_is_exact() {
        // A fixed pseudo-random pattern, sparse and dense rows, an empty column.
        let (w, h) = (13, 9);
        let target: Vec<bool> = (0..w * h)
            .map(|i| (i * 2_654_435_761_usize) % 97 < 9 && i % w != 4)
            .collect();
        assert!(target.iter().any(|&t| t));
        // Square pixels, and pixels at unit depth of a camera with f_x ≠ f_y.
        for spacing in [[1.0, 1.0], [1.0 / 70.0, 1.0 / 52.0], [0.3, 2.5]] {
            let fast = distance_transform(&target, w, h, spacing);
            let slow = brute_force(&target, w, h, spacing);
            let scale = spacing[0].max(spacing[1]).powi(2);
            for (a, b) in fast.iter().zip(&slow) {
                assert!((a - b).abs() < 1e-9 * scale, "{spacing:?}: {a} vs {b}");
            }
        }
        assert!(
            distance_transform(&[false; 6], 3, 2, [1.0, 1.0])
                .iter()
                .all(|&d| d >= FAR)
        );
    }

    /// A camera on +z looking at the origin, 40 px square, 30° field of view.
    fn camera() -> PinholeCamera {
        PinholeCamera::look_at(
            DVec3::new(0.0, 0.0, 2.0),
            DVec3::ZERO,
            DVec3::Y,
            40,
            40,
            30f64.to_radians(),
        )
    }

    /// The mask of a disc of `radius_m` about the origin seen by [`camera`].
    fn disc_mask(camera: &PinholeCamera, radius_m: f64) -> Vec<f32> {
        let r_px = radius_m / 2.0 * camera.fx;
        (0..40 * 40)
            .map(|i| {
                let (x, y) = ((i % 40) as f64 + 0.5 - 20.0, (i / 40) as f64 + 0.5 - 20.0);
                f32::from(u8::from(x.hypot(y) < r_px))
            })
            .collect()
    }

    #[test]
    fn distance_follows_the_silhouette_in_metres() -> Result<()> {
        let cam = camera();
        let radius_m = 0.2;
        let hull = HullDistance::new(&[cam], &[disc_mask(&cam, radius_m)], 0.0)?;
        // One pixel at 2 m is 2/fx metres; the pixel grid puts the level within ~½ px.
        let px_m = 2.0 / cam.fx;
        // Deep inside, the pixel grid's distances are only a bound (never carved).
        assert!(hull.distance_m(DVec3::ZERO) < -0.15);
        for r in [0.15, 0.19, 0.21, 0.3, 0.5] {
            let d = hull.distance_m(DVec3::new(r, 0.0, 0.0));
            assert!(
                (d - (r - radius_m)).abs() < 0.75 * px_m,
                "r {r}: {d} m vs {}",
                r - radius_m
            );
        }
        // Along the ray (the cone's axis) the distance does not change with depth
        // beyond the perspective scale.
        // Nearer the camera (depth 1.5 m) the same offset lies further out of the
        // cone: (0.3/1.5 − 0.2/2) · 1.5 m = 0.15 m.
        let near = hull.distance_m(DVec3::new(0.3, 0.0, 0.5));
        assert!((near - 0.15).abs() < 0.75 * px_m, "{near}");
        // Outside the frame: background, and growing.
        let (a, b) = (
            hull.distance_m(DVec3::new(2.0, 0.0, 0.0)),
            hull.distance_m(DVec3::new(3.0, 0.0, 0.0)),
        );
        assert!(a > 1.0 && b > a, "{a} {b}");
        // Behind the camera: unbounded.
        assert_eq!(hull.distance_m(DVec3::new(0.0, 0.0, 3.0)), f64::NEG_INFINITY);
        // The margin moves the level out by that many pixels.
        let grown = HullDistance::new(&[cam], &[disc_mask(&cam, radius_m)], 2.0)?;
        let x = DVec3::new(0.3, 0.0, 0.0);
        assert!((hull.distance_m(x) - grown.distance_m(x) - 2.0 * px_m).abs() < 1e-9);
        Ok(())
    }

    #[test]
    fn soft_masks_odd_intrinsics_and_non_square_frames() -> Result<()> {
        // 48 × 32, fx ≠ fy, the principal point off centre; a 0.2 m disc facing the
        // camera, its mask soft over a band about two pixels wide (½ on the ellipse).
        let mut cam = camera();
        (cam.width, cam.height) = (48, 32);
        (cam.fx, cam.fy, cam.cx, cam.cy) = (70.0, 52.0, 21.3, 17.6);
        let (a, b) = (cam.fx * 0.1, cam.fy * 0.1);
        let mask: Vec<f32> = (0..48 * 32)
            .map(|i| {
                let (u, v) = ((i % 48) as f64 + 0.5, (i / 48) as f64 + 0.5);
                let rho = (((u - cam.cx) / a).powi(2) + ((v - cam.cy) / b).powi(2)).sqrt();
                (0.5 + (1.0 - rho) * 0.5 * a).clamp(0.0, 1.0) as f32
            })
            .collect();
        assert!(mask.iter().any(|&m| m > 0.05 && m < 0.95));
        let hull = HullDistance::new(&[cam], &[mask], 0.0)?;
        // Two pixels in from the silhouette and two out, along image x and y (image y
        // points along −world y for this camera).
        for (axis, f) in [(DVec3::X, cam.fx), (DVec3::Y, cam.fy)] {
            for sign in [1.0, -1.0] {
                let step = 2.0 * 2.0 / f;
                let inside = hull.distance_m(sign * (0.2 - step) * axis);
                let outside = hull.distance_m(sign * (0.2 + step) * axis);
                assert!(inside < 0.0 && outside > 0.0, "{axis} {sign}: {inside} {outside}");
            }
        }
        // Off the frame: outside.
        assert!(hull.distance_m(DVec3::new(1.0, 0.0, 0.0)) > 0.2);
        Ok(())
    }

    #[test]
    fn distances_follow_each_axis_focal_length() -> Result<()> {
        // f_x = 1.5 f_y, principal point off centre. A straight silhouette along a
        // pixel column (foreground left of u = 40) and one along a row (foreground
        // above v = 30): k pixels off either edge lie k/f_x resp. k/f_y (× depth) off
        // the hull, to within the half pixel's ½ |1/f_x − 1/f_y| (0.11 px along x,
        // 0.09 px along y here). A single focal length √(f_x f_y) for both axes
        // is 0.22 px off per pixel along x and 0.18 along y: 0.9 px at 4 px out.
        let mut cam = camera();
        (cam.width, cam.height) = (64, 48);
        (cam.fx, cam.fy, cam.cx, cam.cy) = (90.0, 60.0, 31.7, 23.2);
        let z = 2.0;
        let at = |u: f64, v: f64| DVec3::new((u - cam.cx) / cam.fx * z, -(v - cam.cy) / cam.fy * z, 0.0);
        let column_edge: Vec<f32> = (0..64 * 48).map(|i| f32::from(u8::from(i % 64 < 40))).collect();
        let row_edge: Vec<f32> = (0..64 * 48).map(|i| f32::from(u8::from(i / 64 < 30))).collect();
        let by_column = HullDistance::new(&[cam], &[column_edge], 0.0)?;
        let by_row = HullDistance::new(&[cam], &[row_edge], 0.0)?;
        for k in [-4.0, -2.5, -1.0, 1.0, 2.5, 4.0] {
            let d = by_column.distance_m(at(40.0 + k, 20.0)) / z * cam.fx;
            assert!((d - k).abs() < 0.15, "column edge, {k} px: {d} px");
            let d = by_row.distance_m(at(32.0, 30.0 + k)) / z * cam.fy;
            assert!((d - k).abs() < 0.2, "row edge, {k} px: {d} px");
        }
        Ok(())
    }

    /// A ball of radius `radius_m` about the origin, uniformly dense, with light
    /// transport 1 everywhere: a network's field that spills past the silhouettes.
    struct Ball {
        radius_m: f32,
    }

    impl FieldSource for Ball {
        fn evaluate(
            &self,
            points: &[Vec3],
            _view: &ViewPolicy,
            density: &mut [f32],
            lt: &mut [f32],
        ) -> std::result::Result<(), FieldError> {
            self.evaluate_density(points, density)?;
            lt.fill(1.0);
            Ok(())
        }

        fn bounds(&self) -> (Vec3, Vec3) {
            (Vec3::splat(-self.radius_m), Vec3::splat(self.radius_m))
        }

        fn evaluate_density(
            &self,
            points: &[Vec3],
            density: &mut [f32],
        ) -> std::result::Result<(), FieldError> {
            for (p, d) in points.iter().zip(density.iter_mut()) {
                *d = if p.length() < self.radius_m { 5_000.0 } else { 0.0 };
            }
            Ok(())
        }
    }

    #[test]
    fn the_carve_trims_density_outside_the_hull_and_keeps_the_rest() -> Result<()> {
        // Three views of a 0.2 m disc silhouette (a 0.2 m ball), a 0.3 m ball field.
        let cams: Vec<PinholeCamera> = [0.0f64, 40.0, -40.0]
            .iter()
            .map(|deg| {
                let eye = 2.0 * DVec3::new(deg.to_radians().sin(), 0.0, deg.to_radians().cos());
                PinholeCamera::look_at(eye, DVec3::ZERO, DVec3::Y, 40, 40, 30f64.to_radians())
            })
            .collect();
        let masks: Vec<Vec<f32>> = cams.iter().map(|c| disc_mask(c, 0.2)).collect();
        let ball = Ball { radius_m: 0.3 };
        let voxel_m = 0.01;
        let signed = SignedLogDensity::with_skin(&ball, 0.001, 0.25 * voxel_m, voxel_m)
            .map_err(|e| BakeError::Hull(e.to_string()))?;
        let carved = HullCarved::new(&signed, HullDistance::new(&cams, &masks, 0.0)?);
        let points = [
            Vec3::ZERO,
            Vec3::new(0.1, 0.05, 0.0),
            Vec3::new(0.25, 0.0, 0.0),
            Vec3::new(0.0, 0.26, 0.0),
        ];
        let mut before = [0.0f32; 4];
        let mut after = [0.0f32; 4];
        let mut lt = vec![0.0f32; 4 * nelf_format::conventions::LT_DIM];
        signed
            .evaluate_density(&points, &mut before)
            .map_err(|e| BakeError::Hull(e.to_string()))?;
        carved
            .evaluate(&points, &ViewPolicy::Direction(Vec3::Z), &mut after, &mut lt)
            .map_err(|e| BakeError::Hull(e.to_string()))?;
        // Inside the hull, well away from it: untouched; light transport untouched.
        assert_eq!(after[..2], before[..2]);
        assert!(before.iter().all(|&d| d > 0.0));
        assert!(lt.iter().all(|&t| t == 1.0));
        // Inside the ball, outside the silhouettes: no density left (clipped at 0).
        assert!(after[2] < 0.0 && after[3] < 0.0, "{after:?}");
        Ok(())
    }

    #[test]
    fn bad_inputs_are_errors() {
        let cam = camera();
        assert!(HullDistance::new(&[cam], &[vec![1.0; 10]], 0.0).is_err());
        assert!(HullDistance::new(&[cam], &[], 0.0).is_err());
        assert!(HullDistance::new(&[cam], &[disc_mask(&cam, 0.2)], f64::NAN).is_err());
        for (fx, fy) in [(0.0, 50.0), (50.0, f64::NAN), (-50.0, 50.0)] {
            let odd = PinholeCamera { fx, fy, ..cam };
            assert!(
                HullDistance::new(&[odd], &[disc_mask(&cam, 0.2)], 0.0).is_err(),
                "{fx} {fy}"
            );
        }
        let empty = HullDistance::new(&[cam], &[vec![0.0; 1600]], 0.0);
        assert!(empty.is_ok_and(|h| h.distance_m(DVec3::ZERO) > 1.0));
    }
}
