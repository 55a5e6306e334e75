//! The network's camera model and image sampling, in its own units (millimetres,
//! `f32`), reproducing the official `sample_point` and PyTorch's `grid_sample`:
//!
//! * projection: `p = K·[R|t]·[X; 1]`, `pix = p.xy / (p.z + 1e-6)`,
//!   `g = 2·pix/(W, H) − 1` (so pixel `i` covers `[i, i+1]`);
//! * bilinear lookup at `g` with `align_corners = false` and zero padding:
//!   `ix = ((g_x + 1)·W − 1)/2`, the four neighbours weighted by their opposite areas,
//!   neighbours outside the image contributing 0;
//! * masks (floats in `[0, 1]`, soft values kept) are dilated by a 7 × 7 max
//!   filter (stride 1, padding 3) before the visual-hull test [`hull_inside`].
//!
//! **The hull test** is the official one, `Σ_v sample_v == V` with exact `f32`
//! equality, `sample_v` the lookup above of view `v`'s dilated mask, summed in view
//! order. In exact arithmetic a view's sample is `1 − Σ_k w_k·(1 − m_k)` (weights
//! summing to 1, `m_k = 0` for zero padding), so the sum is `V` exactly when every
//! neighbour with a weight is inside the image and holds 1.0: a soft value below 1
//! excludes the point. In `f32` the official sum differs from that only by
//! rounding: an interior sample can come out as `1 − 2⁻²⁴`, which the sum absorbs
//! (the oracle README), and a deficit below about half an ulp of the running sum
//! (`w·(1 − m) ≲ 10⁻⁷`, a point within ~10⁻⁷ px of the edge of the full region) is
//! absorbed too. Equality is exact here because the lookups reproduce the official
//! ones bit for bit: `((g + 1)·W − 1)/2` equals PyTorch's `(g + 1)·(W/2) − 0.5`
//! (scaling by 2 commutes with rounding), `(x₀ + 1) − ix` equals its `1 − (ix − x₀)`
//! for `ix ≥ 0` (`ix − x₀` is exact), and the corners are summed in its order
//! (north-west, north-east, south-west, south-east); the seed-0 fixture's
//! projections and samples match with error 0 (a PyTorch build that fused the
//! multiply-adds could differ in the last ulp of a soft sample, which matters only
//! inside that ~10⁻⁷ band). The earlier test `Σ > V − 10⁻⁵`
//! (the README's suggestion, exact on its 0/1 masks, whose worst outside sum is
//! `V − 1.3·10⁻³`) let soft deficits up to 10⁻⁵ through, e.g. a 0.99 neighbour
//! with weight below 10⁻³ or a mask value of 0.999995, where the official model
//! gives σ = 0 (`tests/hull_soft_masks.rs`).

use glam::{DMat3, DVec3};
use nelf_format::conventions::PinholeCamera;

use crate::error::NetError;

/// The official visual-hull decision from one point's dilated-mask samples (one per
/// view): their `f32` sum, accumulated in view order, equals the number of views
/// exactly (module documentation).
pub fn hull_inside(samples: &[f32]) -> bool {
    samples.iter().fold(0.0f32, |sum, &s| sum + s) == samples.len() as f32
}

/// A pinhole camera as the network sees it: `K` and world-to-camera `[R|t]` in
/// millimetres (OpenCV axes), `f32`, and the image size.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NetCamera {
    /// Intrinsic matrix `K`, row-major.
    pub intrinsic: [[f32; 3]; 3],
    /// Extrinsic `[R|t]`, row-major, translation in millimetres.
    pub extrinsic: [[f32; 4]; 3],
    /// Image width in pixels.
    pub width: usize,
    /// Image height in pixels.
    pub height: usize,
}

impl NetCamera {
    /// The network camera of one of our cameras (metres, world frame): the network's
    /// world is `1000 · net_from_world · x` (millimetres, rotated), so
    /// `R_net = R·net_from_worldᵀ` and `t_net = 1000·t`.
    pub fn from_pinhole(camera: &PinholeCamera, net_from_world: DMat3) -> Self {
        let r = camera.rotation * net_from_world.transpose();
        let t = camera.translation * 1000.0;
        let row = |i: usize| {
            let v = r.row(i);
            [v.x as f32, v.y as f32, v.z as f32, t[i] as f32]
        };
        Self {
            intrinsic: [
                [camera.fx as f32, 0.0, camera.cx as f32],
                [0.0, camera.fy as f32, camera.cy as f32],
                [0.0, 0.0, 1.0],
            ],
            extrinsic: [row(0), row(1), row(2)],
            width: camera.width as usize,
            height: camera.height as usize,
        }
    }

    /// World-to-camera rotation `R`.
    pub fn rotation(&self) -> [[f32; 3]; 3] {
        let e = &self.extrinsic;
        [
            [e[0][0], e[0][1], e[0][2]],
            [e[1][0], e[1][1], e[1][2]],
            [e[2][0], e[2][1], e[2][2]],
        ]
    }

    /// `R` in `f64`.
    pub fn rotation_f64(&self) -> DMat3 {
        let r = self.rotation();
        DMat3::from_cols_array_2d(&r.map(|row| row.map(f64::from))).transpose()
    }

    /// Camera centre `−Rᵀ t`, millimetres.
    pub fn centre(&self) -> [f32; 3] {
        let e = &self.extrinsic;
        let mut c = [0.0f32; 3];
        for (j, cj) in c.iter_mut().enumerate() {
            *cj = -(e[0][j] * e[0][3] + e[1][j] * e[1][3] + e[2][j] * e[2][3]);
        }
        c
    }

    /// `K·[R|t]` (3 × 4).
    pub fn projection(&self) -> [[f32; 4]; 3] {
        let mut p = [[0.0f32; 4]; 3];
        for (i, row) in p.iter_mut().enumerate() {
            for (j, v) in row.iter_mut().enumerate() {
                *v = (0..3).map(|k| self.intrinsic[i][k] * self.extrinsic[k][j]).sum();
            }
        }
        p
    }

    /// Checks the parameters: positive size, finite values, positive focal lengths.
    pub fn validate(&self) -> Result<(), NetError> {
        let finite = self
            .intrinsic
            .iter()
            .flatten()
            .chain(self.extrinsic.iter().flatten())
            .all(|v| v.is_finite());
        if !finite
            || self.width == 0
            || self.height == 0
            || self.intrinsic[0][0] <= 0.0
            || self.intrinsic[1][1] <= 0.0
        {
            return Err(NetError::input(format!("unusable camera {self:?}")));
        }
        Ok(())
    }

    /// Unit ray direction (world, `Rᵀ K⁻¹ [x, y, 1]` normalised) through continuous
    /// pixel coordinates `(x, y)`, computed in `f64`.
    pub fn ray_direction(&self, x: f64, y: f64) -> DVec3 {
        let k = &self.intrinsic;
        let (fx, fy, s, cx, cy) = (
            f64::from(k[0][0]),
            f64::from(k[1][1]),
            f64::from(k[0][1]),
            f64::from(k[0][2]),
            f64::from(k[1][2]),
        );
        let yc = (y - cy) / fy;
        let xc = (x - cx - s * yc) / fx;
        (self.rotation_f64().transpose() * DVec3::new(xc, yc, 1.0)).normalize()
    }
}

/// Normalised image coordinates `g ∈ [−1, 1]²` of world point `x` (mm) under the
/// projection `proj = K·[R|t]` of an image `width × height`.
pub fn project_normalized(proj: &[[f32; 4]; 3], width: usize, height: usize, x: [f32; 3]) -> [f32; 2] {
    let p = proj.map(|row| row[0] * x[0] + row[1] * x[1] + row[2] * x[2] + row[3]);
    let z = p[2] + 1e-6;
    let (px, py) = (p[0] / z, p[1] / z);
    [2.0 * px / width as f32 - 1.0, 2.0 * py / height as f32 - 1.0]
}

/// The four bilinear neighbours of a lookup: flat indices `y·W + x` into a plane
/// and weights (0 for neighbours outside the plane, whose index is then 0).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Taps {
    /// Flat pixel indices.
    pub index: [u32; 4],
    /// Bilinear weights.
    pub weight: [f32; 4],
}

impl Taps {
    /// No contribution (a lookup entirely outside, or at a non-finite coordinate).
    pub const NONE: Self = Self {
        index: [0; 4],
        weight: [0.0; 4],
    };

    /// `grid_sample` taps at normalised `(gx, gy)` in a `width × height` plane.
    pub fn bilinear(gx: f32, gy: f32, width: usize, height: usize) -> Self {
        let ix = ((gx + 1.0) * width as f32 - 1.0) / 2.0;
        let iy = ((gy + 1.0) * height as f32 - 1.0) / 2.0;
        if !(ix.is_finite() && iy.is_finite()) || ix <= -1.0 || iy <= -1.0 {
            return Self::NONE;
        }
        if ix >= width as f32 || iy >= height as f32 {
            return Self::NONE;
        }
        let (x0, y0) = (ix.floor(), iy.floor());
        let (x1, y1) = (x0 + 1.0, y0 + 1.0);
        let weights = [
            (x1 - ix) * (y1 - iy),
            (ix - x0) * (y1 - iy),
            (x1 - ix) * (iy - y0),
            (ix - x0) * (iy - y0),
        ];
        let corners = [(x0, y0), (x1, y0), (x0, y1), (x1, y1)];
        let mut taps = Self::NONE;
        for (k, ((cx, cy), w)) in corners.iter().zip(weights).enumerate() {
            if *cx >= 0.0 && *cy >= 0.0 && *cx < width as f32 && *cy < height as f32 {
                taps.index[k] = (*cy as u32) * width as u32 + *cx as u32;
                taps.weight[k] = w;
            }
        }
        taps
    }

    /// Bilinear sample of a channel-last plane `plane[(y·W + x)·C + c]` into `out` (`C` values).
    pub fn sample_into(&self, plane: &[f32], out: &mut [f32]) {
        let channels = out.len();
        out.fill(0.0);
        for (idx, w) in self.index.iter().zip(self.weight) {
            if w != 0.0 {
                let base = *idx as usize * channels;
                for (o, v) in out.iter_mut().zip(&plane[base..base + channels]) {
                    *o += w * v;
                }
            }
        }
    }

    /// Bilinear sample of a single-channel plane.
    pub fn sample_scalar(&self, plane: &[f32]) -> f32 {
        self.index
            .iter()
            .zip(self.weight)
            .filter(|(_, w)| *w != 0.0)
            .map(|(i, w)| w * plane[*i as usize])
            .sum()
    }
}

/// 7 × 7 max filter (stride 1, padding 3 that never wins) of each `height × width`
/// plane in `planes` (a whole number of planes).
pub fn dilate_masks(planes: &[f32], width: usize, height: usize) -> Vec<f32> {
    const RADIUS: usize = 3;
    let plane_len = width * height;
    let mut rows = vec![0.0f32; planes.len()];
    let mut out = vec![0.0f32; planes.len()];
    for (src, dst) in planes.chunks(plane_len).zip(rows.chunks_mut(plane_len)) {
        for y in 0..height {
            let line = &src[y * width..(y + 1) * width];
            for x in 0..width {
                let lo = x.saturating_sub(RADIUS);
                let hi = (x + RADIUS).min(width - 1);
                dst[y * width + x] = line[lo..=hi].iter().copied().fold(f32::NEG_INFINITY, f32::max);
            }
        }
    }
    for (src, dst) in rows.chunks(plane_len).zip(out.chunks_mut(plane_len)) {
        for y in 0..height {
            let lo = y.saturating_sub(RADIUS);
            let hi = (y + RADIUS).min(height - 1);
            for x in 0..width {
                dst[y * width + x] = (lo..=hi)
                    .map(|yy| src[yy * width + x])
                    .fold(f32::NEG_INFINITY, f32::max);
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn taps_hit_pixel_centres_exactly() {
        // Pixel i covers [i, i+1]: its centre i + 0.5 maps to g = 2(i + 0.5)/W − 1.
        let (w, h) = (8usize, 4usize);
        let gx = 2.0 * 3.5 / w as f32 - 1.0;
        let gy = 2.0 * 1.5 / h as f32 - 1.0;
        let taps = Taps::bilinear(gx, gy, w, h);
        assert_eq!(taps.index[0], 8 + 3);
        assert!((taps.weight[0] - 1.0).abs() < 1e-6);
        assert!(taps.weight[1..].iter().all(|v| v.abs() < 1e-6));
    }

    #[test]
    fn taps_outside_contribute_zero_padding() {
        // Half a pixel left of the first centre: half of pixel 0, half of zero padding.
        let taps = Taps::bilinear(-1.0, 0.0, 4, 4);
        let plane: Vec<f32> = (0..16).map(|v| v as f32 + 1.0).collect();
        let v = taps.sample_scalar(&plane);
        // Rows 1 and 2 straddle gy = 0: mean of pixel (0,1)=5 and (0,2)=9, halved.
        assert!((v - 0.5 * 7.0).abs() < 1e-6, "{v}");
        assert_eq!(Taps::bilinear(f32::NAN, 0.0, 4, 4), Taps::NONE);
        assert_eq!(Taps::bilinear(1.5, 0.0, 4, 4), Taps::NONE);
    }

    #[test]
    fn hull_needs_every_sample_to_be_one() {
        // Pooled mask: columns 0–3 hold 1.0, column 4 holds 0.99.
        let (w, h) = (6usize, 4usize);
        let plane: Vec<f32> = (0..w * h)
            .map(|i| [1.0, 1.0, 1.0, 1.0, 0.99, 0.3][i % w])
            .collect();
        let sample = |ix: f32, iy: f32| {
            let g = [
                (2.0 * ix + 1.0) / w as f32 - 1.0,
                (2.0 * iy + 1.0) / h as f32 - 1.0,
            ];
            Taps::bilinear(g[0], g[1], w, h).sample_scalar(&plane)
        };
        let full = sample(3.0, 1.5);
        assert_eq!(full, 1.0);
        assert!(hull_inside(&[full; 4]));
        // 1/1024 px toward column 4: 1 − 0.01/1024 ≈ 1 − 9.8e-6. The old tolerance
        // (Σ > V − 1e-5) let it through; the official equality does not.
        let soft = sample(3.0 + 1.0 / 1024.0, 1.5);
        assert!((soft - (1.0 - 0.01 / 1024.0)).abs() < 1e-7, "{soft}");
        assert!([full, full, soft].iter().sum::<f32>() > 3.0 - 1e-5);
        assert!(!hull_inside(&[full, full, soft]) && !hull_inside(&[soft, full, full]));
        assert!(!hull_inside(&[full, 0.999_995]) && !hull_inside(&[full, sample(4.5, 1.5)]));
        // Half a pixel past the last row, half of the footprint is zero padding.
        assert!((sample(1.0, 3.5) - 0.5).abs() < 1e-6);
        // Interior samples of 1 − 2⁻²⁴ vanish in the f32 sum, as in the official model.
        let below = 1.0 - f32::EPSILON / 2.0;
        assert!(hull_inside(&[1.0, 1.0, 1.0, below]) && hull_inside(&[1.0, below]));
    }

    #[test]
    fn dilation_is_a_seven_wide_max() {
        let (w, h) = (12, 9);
        let mut plane = vec![0.0f32; w * h];
        plane[4 * w + 5] = 1.0;
        let d = dilate_masks(&plane, w, h);
        for y in 0..h {
            for x in 0..w {
                let inside = (x as isize - 5).abs() <= 3 && (y as isize - 4).abs() <= 3;
                assert_eq!(d[y * w + x], if inside { 1.0 } else { 0.0 }, "({x},{y})");
            }
        }
    }

    #[test]
    fn net_camera_matches_pinhole_projection() {
        let mut cam = PinholeCamera::look_at(DVec3::new(0.2, 0.1, 1.2), DVec3::ZERO, DVec3::Y, 64, 48, 0.7);
        cam.fy *= 1.2;
        cam.cy += 2.0;
        let rot = DMat3::from_rotation_x(std::f64::consts::FRAC_PI_2);
        let net = NetCamera::from_pinhole(&cam, rot);
        let x_world = DVec3::new(0.03, -0.02, 0.05);
        let want = cam.project(x_world).unwrap();
        let x_net = (rot * x_world * 1000.0).as_vec3().to_array();
        let g = project_normalized(&net.projection(), 64, 48, x_net);
        let pix = [(g[0] + 1.0) * 32.0, (g[1] + 1.0) * 24.0];
        assert!((f64::from(pix[0]) - want.x).abs() < 1e-3 && (f64::from(pix[1]) - want.y).abs() < 1e-3);
        let c = net.centre();
        let want_c = rot * cam.centre() * 1000.0;
        assert!((f64::from(c[0]) - want_c.x).abs() < 1e-3 && (f64::from(c[2]) - want_c.z).abs() < 1e-3);
    }
}
