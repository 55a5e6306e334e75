//! The project's shared conventions, defined once (`docs/CONVENTIONS.md`):
//!
//! * **Environment maps** are lat-long images, rows from the zenith (+y) down.
//!   Row `i` of `H` covers polar angle `θ ∈ [iπ/H, (i+1)π/H]`, column `j` of `W`
//!   covers azimuth `φ ∈ [j·2π/W − π, (j+1)·2π/W − π]`, and the direction is
//!   `d(θ, φ) = (sin θ sin φ, cos θ, −sin θ cos φ)` (the image centre looks along −z).
//! * **Solid angles** are exact: `Ω_i = (2π/W)(cos θ_i − cos θ_{i+1})`. They are
//!   folded into light-transport vectors, so `radiance_c = Σ_k T[c][k] · L[c][k]`
//!   with `L` the texel's mean radiance.
//! * **Light transport layout**: 8 × 16 = 128 texels, index `k = row·16 + col`;
//!   a vector holds 3 × 128 numbers, channel-major: `T[c·128 + k]`.
//! * **Light frame**: an asset's texels are directions in its light frame;
//!   `world_from_light` rotates them into the world. Projecting a user's map
//!   (any resolution) into the asset's texels is [`project_envmap`].
//! * **Cameras**: OpenCV pinhole (x right, y down, z forward), world-to-camera
//!   `[R|t]`, intrinsics in pixels, pixel `(u, v)` centred at `(u + 0.5, v + 0.5)`.
//!   See [`PinholeCamera`].
//!
//! Geometry is computed in `f64`; radiance is stored in `f32`.

use std::f64::consts::PI;

use glam::{DMat3, DVec2, DVec3};

/// Rows of the light-transport basis (polar bands).
pub const ENV_H: usize = 8;
/// Columns of the light-transport basis (azimuth sectors).
pub const ENV_W: usize = 16;
/// Lighting directions in the light-transport basis.
pub const ENV_TEXELS: usize = ENV_H * ENV_W;
/// Length of one light-transport vector: RGB × [`ENV_TEXELS`], channel-major.
pub const LT_DIM: usize = 3 * ENV_TEXELS;

/// Index of channel `channel` and texel `(row, col)` in a light-transport vector.
pub const fn lt_index(channel: usize, row: usize, col: usize) -> usize {
    channel * ENV_TEXELS + row * ENV_W + col
}

/// Polar-angle bounds `[θ_i, θ_{i+1}]` of row `row` in a map with `height` rows.
pub fn row_theta_bounds(row: usize, height: usize) -> (f64, f64) {
    let h = height as f64;
    (row as f64 * PI / h, (row + 1) as f64 * PI / h)
}

/// Azimuth bounds `[φ_j, φ_{j+1}]` of column `col` in a map with `width` columns.
pub fn col_phi_bounds(col: usize, width: usize) -> (f64, f64) {
    let step = 2.0 * PI / width as f64;
    (col as f64 * step - PI, (col + 1) as f64 * step - PI)
}

/// Exact solid angle of any texel in row `row` of a `height × width` lat-long map.
pub fn texel_solid_angle(row: usize, height: usize, width: usize) -> f64 {
    let (t0, t1) = row_theta_bounds(row, height);
    (2.0 * PI / width as f64) * (t0.cos() - t1.cos())
}

/// Unit direction for polar angle `theta` (from +y) and azimuth `phi`.
pub fn direction(theta: f64, phi: f64) -> DVec3 {
    let (st, ct) = theta.sin_cos();
    let (sp, cp) = phi.sin_cos();
    DVec3::new(st * sp, ct, -st * cp)
}

/// `(θ, φ)` of a direction (need not be normalised), `θ ∈ [0, π]`, `φ ∈ (−π, π]`.
pub fn theta_phi(dir: DVec3) -> (f64, f64) {
    let d = dir.normalize_or_zero();
    (d.y.clamp(-1.0, 1.0).acos(), d.x.atan2(-d.z))
}

/// Direction through the centre of texel `(row, col)`: midpoint in θ and in φ.
pub fn texel_center_direction(row: usize, col: usize, height: usize, width: usize) -> DVec3 {
    let (t0, t1) = row_theta_bounds(row, height);
    let (p0, p1) = col_phi_bounds(col, width);
    direction(0.5 * (t0 + t1), 0.5 * (p0 + p1))
}

/// The texel `(row, col)` a direction falls in.
pub fn texel_of_direction(dir: DVec3, height: usize, width: usize) -> (usize, usize) {
    let (theta, phi) = theta_phi(dir);
    let row = ((theta / PI) * height as f64).floor() as isize;
    let col = (((phi + PI) / (2.0 * PI)) * width as f64).floor() as isize;
    (
        row.clamp(0, height as isize - 1) as usize,
        col.rem_euclid(width as isize) as usize,
    )
}

/// Rotation by `angle_rad` about +y (right-handed). It maps `d(θ, φ)` to `d(θ, φ − angle)`.
pub fn rotation_y(angle_rad: f64) -> DMat3 {
    DMat3::from_rotation_y(angle_rad)
}

/// Whether `m` is a proper rotation (orthonormal, determinant +1) to `tol`.
pub fn is_rotation(m: DMat3, tol: f64) -> bool {
    let should_be_identity = m.transpose() * m;
    m.to_cols_array().iter().all(|v| v.is_finite())
        && should_be_identity.abs_diff_eq(DMat3::IDENTITY, tol)
        && (m.determinant() - 1.0).abs() < tol
}

/// Errors from the conventions helpers.
#[derive(Debug, thiserror::Error)]
pub enum ConventionError {
    /// Image dimensions are zero or the pixel count does not match.
    #[error("lat-long image is {width}×{height} but holds {len} texels")]
    BadImageSize {
        /// Width in texels.
        width: usize,
        /// Height in texels.
        height: usize,
        /// Texels supplied.
        len: usize,
    },
    /// A matrix that must be a rotation is not.
    #[error("{what} is not a rotation (orthonormal, det +1): {matrix:?}")]
    NotARotation {
        /// Which matrix.
        what: &'static str,
        /// Its columns.
        matrix: [f64; 9],
    },
    /// A camera parameter is out of range.
    #[error("invalid camera: {0}")]
    BadCamera(String),
}

/// A lat-long RGB image in linear radiance, any resolution, row 0 at the zenith.
#[derive(Debug, Clone, PartialEq)]
pub struct LatLong {
    width: usize,
    height: usize,
    texels: Vec<[f32; 3]>,
}

impl LatLong {
    /// Wraps row-major texels. Errors if the size is zero or does not match.
    pub fn new(width: usize, height: usize, texels: Vec<[f32; 3]>) -> Result<Self, ConventionError> {
        if width == 0 || height == 0 || texels.len() != width * height {
            return Err(ConventionError::BadImageSize {
                width,
                height,
                len: texels.len(),
            });
        }
        Ok(Self {
            width,
            height,
            texels,
        })
    }

    /// A map of one constant radiance.
    pub fn constant(width: usize, height: usize, rgb: [f32; 3]) -> Self {
        let (width, height) = (width.max(1), height.max(1));
        Self {
            width,
            height,
            texels: vec![rgb; width * height],
        }
    }

    /// A map of the light-transport basis size (8 × 16) from 128 RGB texels.
    pub fn basis(texels: [[f32; 3]; ENV_TEXELS]) -> Self {
        Self {
            width: ENV_W,
            height: ENV_H,
            texels: texels.to_vec(),
        }
    }

    /// Width in texels (azimuth).
    pub fn width(&self) -> usize {
        self.width
    }

    /// Height in texels (polar angle).
    pub fn height(&self) -> usize {
        self.height
    }

    /// Row-major texels.
    pub fn texels(&self) -> &[[f32; 3]] {
        &self.texels
    }

    /// Mutable row-major texels.
    pub fn texels_mut(&mut self) -> &mut [[f32; 3]] {
        &mut self.texels
    }

    /// Texel at `(row, col)`.
    pub fn get(&self, row: usize, col: usize) -> [f32; 3] {
        self.texels[row * self.width + col]
    }

    /// Radiance from direction `dir` (the texel it falls in: the map is piecewise constant).
    pub fn lookup(&self, dir: DVec3) -> [f32; 3] {
        let (row, col) = texel_of_direction(dir, self.height, self.width);
        self.get(row, col)
    }

    /// Radiant power per unit area over the sphere, `Σ Ω_i L_i` per channel (W/m² for radiance in W/m²/sr).
    pub fn integral(&self) -> [f64; 3] {
        let mut sum = [0.0f64; 3];
        for row in 0..self.height {
            let omega = texel_solid_angle(row, self.height, self.width);
            for col in 0..self.width {
                let t = self.get(row, col);
                for c in 0..3 {
                    sum[c] += omega * f64::from(t[c]);
                }
            }
        }
        sum
    }

    /// Mean radiance over the sphere, `Σ Ω_i L_i / 4π`, averaged over the three channels
    /// (unchanged by any rotation of the map).
    pub fn mean_radiance(&self) -> f64 {
        let [r, g, b] = self.integral();
        (r + g + b) / (3.0 * 4.0 * std::f64::consts::PI)
    }
}

/// Resamples an environment map `env` (any resolution, lat-long in its own frame)
/// into the 8 × 16 texels of a light frame, area-weighted.
///
/// `env_from_light` maps light-frame directions into the map's frame: a light texel
/// with direction `d` sees radiance `env(env_from_light · d)`. For a world-frame map
/// rotated by the user by `world_from_env`, pass `world_from_envᵀ · world_from_light`.
///
/// Each output texel is the solid-angle-weighted mean radiance of the map over it.
/// When `env_from_light` is a rotation about +y (the common case: turning the
/// lighting) the overlap of every input texel with every output texel is computed
/// exactly in `(cos θ, φ)`; otherwise every input texel is split into a regular grid
/// of sub-texels (about 4 M in all) that are rotated into the light frame and
/// splatted with their solid angles, normalised per output texel. Either way a
/// constant map projects to that constant; an 8 × 16 map with the identity is
/// reproduced exactly.
pub fn project_envmap(env: &LatLong, env_from_light: DMat3) -> Result<LatLong, ConventionError> {
    if !is_rotation(env_from_light, 1e-6) {
        return Err(ConventionError::NotARotation {
            what: "env_from_light",
            matrix: env_from_light.to_cols_array(),
        });
    }
    // A rotation about +y by α has m = [[cos α, 0, sin α], [0, 1, 0], [−sin α, 0, cos α]].
    let cols = env_from_light.to_cols_array_2d();
    let about_y = (cols[1][1] - 1.0).abs() < 1e-12
        && cols[0][1].abs() < 1e-12
        && cols[2][1].abs() < 1e-12
        && cols[1][0].abs() < 1e-12
        && cols[1][2].abs() < 1e-12;
    let texels = if about_y {
        let alpha = cols[2][0].atan2(cols[0][0]);
        project_about_y(env, alpha)
    } else {
        project_splat(env, env_from_light)
    };
    LatLong::new(ENV_W, ENV_H, texels)
}

/// Length of the overlap of intervals `[a0, a1]` and `[b0, b1]`.
fn overlap(a0: f64, a1: f64, b0: f64, b1: f64) -> f64 {
    (a1.min(b1) - a0.max(b0)).max(0.0)
}

/// Exact area-weighted projection when the light frame is the map's frame turned by
/// `alpha` about +y: light texel `(θ, φ)` sees the map at `(θ, φ − α)`.
fn project_about_y(env: &LatLong, alpha: f64) -> Vec<[f32; 3]> {
    let two_pi = 2.0 * PI;
    // Row weights: overlap in cos θ (area element is d(cos θ) dφ).
    let row_weights: Vec<Vec<(usize, f64)>> = (0..ENV_H)
        .map(|out_row| {
            let (t0, t1) = row_theta_bounds(out_row, ENV_H);
            let (u_lo, u_hi) = (t1.cos(), t0.cos());
            (0..env.height)
                .filter_map(|in_row| {
                    let (s0, s1) = row_theta_bounds(in_row, env.height);
                    let w = overlap(u_lo, u_hi, s1.cos(), s0.cos());
                    (w > 0.0).then_some((in_row, w))
                })
                .collect()
        })
        .collect();
    // Column weights: overlap in φ of [φ0 − α, φ1 − α] with input columns, wrapping.
    let in_step = two_pi / env.width as f64;
    let col_weights: Vec<Vec<(usize, f64)>> = (0..ENV_W)
        .map(|out_col| {
            let (p0, p1) = col_phi_bounds(out_col, ENV_W);
            // Shift into [0, 2π) measured from φ = −π, so input column j covers [j·step, (j+1)·step).
            let start = (p0 - alpha + PI).rem_euclid(two_pi);
            let end = start + (p1 - p0);
            let first = (start / in_step).floor() as isize;
            let last = (end / in_step).ceil() as isize;
            (first..last)
                .filter_map(|j| {
                    let lo = j as f64 * in_step;
                    let w = overlap(start, end, lo, lo + in_step);
                    (w > 0.0).then(|| (j.rem_euclid(env.width as isize) as usize, w))
                })
                .collect()
        })
        .collect();
    let mut out = Vec::with_capacity(ENV_TEXELS);
    for rows in &row_weights {
        for columns in &col_weights {
            let mut acc = [0.0f64; 3];
            let mut total = 0.0f64;
            for &(r, wr) in rows {
                for &(c, wc) in columns {
                    let w = wr * wc;
                    let t = env.get(r, c);
                    for ch in 0..3 {
                        acc[ch] += w * f64::from(t[ch]);
                    }
                    total += w;
                }
            }
            out.push(acc.map(|a| (a / total) as f32));
        }
    }
    out
}

/// Sub-texels per input texel side so that about `TARGET` sub-texels cover the sphere.
fn splat_subdivisions(width: usize, height: usize) -> usize {
    const TARGET: f64 = 4.0e6;
    ((TARGET / (width * height) as f64).sqrt().ceil() as usize).clamp(1, 256)
}

/// General rotation: normalised splat of solid-angle-weighted sub-texels.
fn project_splat(env: &LatLong, env_from_light: DMat3) -> Vec<[f32; 3]> {
    let light_from_env = env_from_light.transpose();
    let n = splat_subdivisions(env.width, env.height);
    let mut acc = vec![[0.0f64; 3]; ENV_TEXELS];
    let mut weight = vec![0.0f64; ENV_TEXELS];
    for row in 0..env.height {
        let (t0, t1) = row_theta_bounds(row, env.height);
        let (u0, u1) = (t0.cos(), t1.cos());
        let sub_omega = texel_solid_angle(row, env.height, env.width) / (n * n) as f64;
        for col in 0..env.width {
            let (p0, p1) = col_phi_bounds(col, env.width);
            let radiance = env.get(row, col);
            for a in 0..n {
                // Uniform in cos θ: equal solid angle per sub-texel.
                let u = u0 + (u1 - u0) * (a as f64 + 0.5) / n as f64;
                let theta = u.clamp(-1.0, 1.0).acos();
                for b in 0..n {
                    let phi = p0 + (p1 - p0) * (b as f64 + 0.5) / n as f64;
                    let d_light = light_from_env * direction(theta, phi);
                    let (r, c) = texel_of_direction(d_light, ENV_H, ENV_W);
                    let k = r * ENV_W + c;
                    for ch in 0..3 {
                        acc[k][ch] += sub_omega * f64::from(radiance[ch]);
                    }
                    weight[k] += sub_omega;
                }
            }
        }
    }
    acc.iter()
        .zip(&weight)
        .map(|(a, &w)| {
            if w > 0.0 {
                a.map(|v| (v / w) as f32)
            } else {
                [0.0; 3]
            }
        })
        .collect()
}

/// Number of outgoing-direction functions a view-dependent asset's lobes are built from:
/// the real spherical harmonics of degrees 0, 1 and 2 ([`view_harmonics`]).
pub const VIEW_HARMONICS: usize = 9;

/// The real spherical harmonics of degrees 0–2 at the outgoing direction `ω` (world
/// frame, from the point toward the viewer), orthonormal over the sphere
/// (`∫ y_a y_b dω = δ_ab`). The constant `y_0` lets a lobe correct the view-independent
/// part for the directions a voxel is seen from. With `ω = (x, y, z)` normalised first:
///
/// `y = (c₀, a·y, a·z, a·x, b·xy, b·yz, c·(3z² − 1), b·xz, b/2·(x² − y²))`,
/// `c₀ = 1/(2√π)`, `a = √(3/4π)`, `b = √(15/4π)`, `c = √(5/16π)` (degree by degree, the
/// usual order `m = −l … l` with the physics convention's z axis; SPEC.md §6 `VDEP`).
/// A zero or non-finite `ω` gives zeros.
pub fn view_harmonics(omega: [f32; 3]) -> [f32; VIEW_HARMONICS] {
    const C0: f32 = 0.282_094_8; // 1/(2√π)
    const A: f32 = 0.488_602_5; // √(3/4π)
    const B: f32 = 1.092_548_4; // √(15/4π)
    const C: f32 = 0.315_391_57; // √(5/16π)
    let len = (omega[0] * omega[0] + omega[1] * omega[1] + omega[2] * omega[2]).sqrt();
    if !(len > 0.0 && len.is_finite()) {
        return [0.0; VIEW_HARMONICS];
    }
    let [x, y, z] = omega.map(|v| v / len);
    [
        C0,
        A * y,
        A * z,
        A * x,
        B * x * y,
        B * y * z,
        C * (3.0 * z * z - 1.0),
        B * x * z,
        0.5 * B * (x * x - y * y),
    ]
}

/// Outgoing radiance `radiance_c = Σ_k T[c·128 + k] · L_k[c]` of one light-transport
/// vector under an 8 × 16 map in the same light frame.
pub fn shade(lt: &[f32], light: &LatLong) -> [f32; 3] {
    debug_assert_eq!(lt.len(), LT_DIM);
    debug_assert_eq!(light.texels.len(), ENV_TEXELS);
    let mut out = [0.0f32; 3];
    for (c, o) in out.iter_mut().enumerate() {
        *o = lt[c * ENV_TEXELS..(c + 1) * ENV_TEXELS]
            .iter()
            .zip(&light.texels)
            .map(|(t, l)| t * l[c])
            .sum();
    }
    out
}

/// A pinhole camera in the OpenCV convention: x right, y down, z forward;
/// `camera_from_world(p) = R·p + t`; a pixel `(u, v)` covers `[u, u+1] × [v, v+1]`
/// and has its centre at `(u + 0.5, v + 0.5)`. Lengths in metres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PinholeCamera {
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Focal length along x, in pixels.
    pub fx: f64,
    /// Focal length along y, in pixels.
    pub fy: f64,
    /// Principal point x, in pixels (continuous coordinates).
    pub cx: f64,
    /// Principal point y, in pixels.
    pub cy: f64,
    /// World-to-camera rotation `R`.
    pub rotation: DMat3,
    /// World-to-camera translation `t`, metres.
    pub translation: DVec3,
}

impl PinholeCamera {
    /// Checks the parameters: positive size and focal lengths, finite values, `R` a rotation.
    pub fn validate(&self) -> Result<(), ConventionError> {
        let bad = |msg: String| Err(ConventionError::BadCamera(msg));
        if self.width == 0 || self.height == 0 {
            return bad(format!("image size {}×{}", self.width, self.height));
        }
        for (name, v) in [("fx", self.fx), ("fy", self.fy)] {
            if !(v.is_finite() && v > 0.0) {
                return bad(format!("{name} = {v} must be positive and finite"));
            }
        }
        for (name, v) in [("cx", self.cx), ("cy", self.cy)] {
            if !v.is_finite() {
                return bad(format!("{name} = {v} is not finite"));
            }
        }
        if !self.translation.is_finite() {
            return bad(format!("translation {:?} is not finite", self.translation));
        }
        if !is_rotation(self.rotation, 1e-5) {
            return bad(format!("R {:?} is not a rotation", self.rotation.to_cols_array()));
        }
        Ok(())
    }

    /// A camera at `eye` looking at `target`, with `up` pointing up in the image
    /// (image y, which points down, is along `−up`), and a horizontal field of view.
    pub fn look_at(eye: DVec3, target: DVec3, up: DVec3, width: u32, height: u32, fov_x_rad: f64) -> Self {
        let z = (target - eye).normalize();
        let x = z.cross(up).normalize();
        let y = z.cross(x);
        // Rows of R are the camera axes in world coordinates.
        let rotation = DMat3::from_cols(x, y, z).transpose();
        let fx = 0.5 * f64::from(width) / (0.5 * fov_x_rad).tan();
        Self {
            width,
            height,
            fx,
            fy: fx,
            cx: 0.5 * f64::from(width),
            cy: 0.5 * f64::from(height),
            rotation,
            translation: -(rotation * eye),
        }
    }

    /// A point in camera coordinates.
    pub fn camera_from_world(&self, p_world: DVec3) -> DVec3 {
        self.rotation * p_world + self.translation
    }

    /// Camera centre in world coordinates, `−Rᵀ t`.
    pub fn centre(&self) -> DVec3 {
        -(self.rotation.transpose() * self.translation)
    }

    /// Unit viewing axis (+z of the camera) in world coordinates.
    pub fn forward(&self) -> DVec3 {
        self.rotation.row(2)
    }

    /// Continuous pixel coordinates of a world point, or `None` behind the camera.
    pub fn project(&self, p_world: DVec3) -> Option<DVec2> {
        let p = self.camera_from_world(p_world);
        (p.z > 0.0).then(|| DVec2::new(self.fx * p.x / p.z + self.cx, self.fy * p.y / p.z + self.cy))
    }

    /// Unit world direction of the ray through continuous pixel coordinates `pixel`.
    pub fn ray_direction(&self, pixel: DVec2) -> DVec3 {
        let d_cam = DVec3::new((pixel.x - self.cx) / self.fx, (pixel.y - self.cy) / self.fy, 1.0);
        (self.rotation.transpose() * d_cam).normalize()
    }

    /// World ray `(origin, unit direction)` through the centre of pixel `(u, v)`.
    pub fn pixel_ray(&self, u: u32, v: u32) -> (DVec3, DVec3) {
        (
            self.centre(),
            self.ray_direction(DVec2::new(f64::from(u) + 0.5, f64::from(v) + 0.5)),
        )
    }
}

/// The least-squares point nearest every camera's optical axis,
/// `argmin_c Σ_i |(I − a_i a_iᵀ)(c − o_i)|²` with `o_i` the centre and `a_i` the unit
/// viewing axis of camera `i` — where a capture's cameras look, i.e. the head
/// centre. `None` when the axes are (nearly) parallel: the normal matrix
/// `Σ (I − a aᵀ)` then has an eigenvalue ≈ 0, tested scale-free as
/// `det ≤ 1e-6 · n³` (n³ is the largest possible determinant).
pub fn nearest_point_to_axes(cameras: &[PinholeCamera]) -> Option<DVec3> {
    let mut a = DMat3::ZERO;
    let mut b = DVec3::ZERO;
    for cam in cameras {
        let d = cam.forward().normalize();
        let projector = DMat3::IDENTITY - DMat3::from_cols(d * d.x, d * d.y, d * d.z);
        a += projector;
        b += projector * cam.centre();
    }
    let n = cameras.len() as f64;
    if a.determinant().partial_cmp(&(1e-6 * n * n * n)) != Some(std::cmp::Ordering::Greater) {
        return None;
    }
    let c = a.inverse() * b;
    c.is_finite().then_some(c)
}

/// Octahedral decoding of a unit vector (format 1.3, `VRCO`; Meyer et al. 2010, "On
/// floating-point normal vectors"): `(u, v) ∈ [−1, 1]²` (values outside are clamped)
/// maps to `p = (u, v, 1 − |u| − |v|)`, whose `x, y` fold to
/// `((1 − |v|) sgn u, (1 − |u|) sgn v)` where `p.z < 0` (`sgn 0 = +1`), normalised.
pub fn octahedral_decode(u: f32, v: f32) -> [f32; 3] {
    let (u, v) = (u.clamp(-1.0, 1.0), v.clamp(-1.0, 1.0));
    let z = 1.0 - u.abs() - v.abs();
    let sign = |a: f32| if a >= 0.0 { 1.0 } else { -1.0 };
    let (x, y) = if z < 0.0 {
        ((1.0 - v.abs()) * sign(u), (1.0 - u.abs()) * sign(v))
    } else {
        (u, v)
    };
    let len = (x * x + y * y + z * z).sqrt();
    [x / len, y / len, z / len]
}

/// Octahedral encoding, the inverse of [`octahedral_decode`]: `(u, v) ∈ [−1, 1]²` of a
/// direction (normalised here; zero or non-finite gives `(0, 0)`, which decodes to +z).
pub fn octahedral_encode(n: [f32; 3]) -> (f32, f32) {
    let l1 = n[0].abs() + n[1].abs() + n[2].abs();
    if !(l1 > 0.0 && l1.is_finite()) {
        return (0.0, 0.0);
    }
    let (x, y, z) = (n[0] / l1, n[1] / l1, n[2] / l1);
    let sign = |a: f32| if a >= 0.0 { 1.0 } else { -1.0 };
    if z < 0.0 {
        ((1.0 - y.abs()) * sign(x), (1.0 - x.abs()) * sign(y))
    } else {
        (x, y)
    }
}

/// Rows of the reflection lobe's direction table (format 1.3, SPEC.md §6 `VREF`).
pub const LOBE_TABLE_H: usize = 64;
/// Columns of the reflection lobe's direction table.
pub const LOBE_TABLE_W: usize = 128;

/// The four table nodes (row-major index `row·W + col`) and bilinear weights of a
/// light-frame direction `d` in the reflection lobe's `LOBE_TABLE_H × LOBE_TABLE_W`
/// lat-long table, whose node `(row, col)` sits at `θ = (row + ½)π/H`,
/// `φ = (col + ½)2π/W − π` (the texel centres of a map that size): with `(θ, φ)` of `d`
/// ([`theta_phi`]), `t = θH/π − ½` clamped to `[0, H − 1]`, `s = (φ + π)W/2π − ½`
/// wrapping in `φ`; `f32` throughout. SPEC.md §6 and `shaders/reflect.wgsl` do the same.
pub fn lobe_table_corners(d: [f32; 3]) -> [(usize, f32); 4] {
    let (h, w) = (LOBE_TABLE_H as f32, LOBE_TABLE_W as f32);
    let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
    let (x, y, z) = if len > 0.0 && len.is_finite() {
        (d[0] / len, d[1] / len, d[2] / len)
    } else {
        (0.0, 1.0, 0.0)
    };
    let theta = y.clamp(-1.0, 1.0).acos();
    let phi = x.atan2(-z);
    let t = (theta * h / std::f32::consts::PI - 0.5).clamp(0.0, h - 1.0);
    let s = (phi + std::f32::consts::PI) * w / std::f32::consts::TAU - 0.5;
    let (t0, s0) = (t.floor(), s.floor());
    let (ft, fs) = (t - t0, s - s0);
    let row0 = t0 as usize;
    let row1 = (row0 + 1).min(LOBE_TABLE_H - 1);
    let col0 = (s0 as isize).rem_euclid(LOBE_TABLE_W as isize) as usize;
    let col1 = (col0 + 1) % LOBE_TABLE_W;
    [
        (row0 * LOBE_TABLE_W + col0, (1.0 - ft) * (1.0 - fs)),
        (row0 * LOBE_TABLE_W + col1, (1.0 - ft) * fs),
        (row1 * LOBE_TABLE_W + col0, ft * (1.0 - fs)),
        (row1 * LOBE_TABLE_W + col1, ft * fs),
    ]
}

/// Light-frame direction of node `index` (`row·W + col`) of the lobe table.
pub fn lobe_table_direction(index: usize) -> DVec3 {
    let (row, col) = (index / LOBE_TABLE_W, index % LOBE_TABLE_W);
    texel_center_direction(row, col, LOBE_TABLE_H, LOBE_TABLE_W)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn random_map(width: usize, height: usize, seed: u32) -> LatLong {
        let mut state = seed.wrapping_mul(2_654_435_761).max(1);
        let mut next = || {
            state ^= state << 13;
            state ^= state >> 17;
            state ^= state << 5;
            f64::from(state) as f32 / u32::MAX as f32
        };
        let texels = (0..width * height).map(|_| [next(), next(), next()]).collect();
        LatLong::new(width, height, texels).unwrap()
    }

    #[test]
    fn solid_angles_sum_to_four_pi() {
        for (h, w) in [(ENV_H, ENV_W), (3, 7), (512, 1024)] {
            let total: f64 = (0..h).map(|r| texel_solid_angle(r, h, w) * w as f64).sum();
            assert!((total - 4.0 * PI).abs() < 1e-6, "{h}×{w}: {total}");
        }
    }

    #[test]
    fn direction_conventions() {
        // Image centre (θ = π/2, φ = 0) looks along −z; the zenith is +y.
        assert!(direction(PI / 2.0, 0.0).abs_diff_eq(DVec3::NEG_Z, 1e-12));
        assert!(direction(0.0, 1.0).abs_diff_eq(DVec3::Y, 1e-12));
        assert!(direction(PI / 2.0, PI / 2.0).abs_diff_eq(DVec3::X, 1e-12));
        for row in 0..ENV_H {
            for col in 0..ENV_W {
                let d = texel_center_direction(row, col, ENV_H, ENV_W);
                assert!((d.length() - 1.0).abs() < 1e-12);
                assert_eq!(texel_of_direction(d, ENV_H, ENV_W), (row, col));
            }
        }
    }

    #[test]
    fn rotation_about_y_shifts_azimuth() {
        let alpha = 0.3;
        let d = rotation_y(alpha) * direction(1.0, 0.7);
        assert!(d.abs_diff_eq(direction(1.0, 0.7 - alpha), 1e-12));
    }

    #[test]
    fn identity_projection_of_basis_map_is_exact() {
        let env = random_map(ENV_W, ENV_H, 7);
        let out = project_envmap(&env, DMat3::IDENTITY).unwrap();
        assert_eq!(out, env);
    }

    #[test]
    fn rotation_by_one_column_is_a_column_shift() {
        let env = random_map(ENV_W, ENV_H, 11);
        let step = 2.0 * PI / ENV_W as f64;
        for shift in [1usize, 3, 15] {
            let out = project_envmap(&env, rotation_y(step * shift as f64)).unwrap();
            for row in 0..ENV_H {
                for col in 0..ENV_W {
                    let expected = env.get(row, (col + ENV_W - shift) % ENV_W);
                    let got = out.get(row, col);
                    for c in 0..3 {
                        assert!((got[c] - expected[c]).abs() < 1e-6, "shift {shift} ({row},{col})");
                    }
                }
            }
        }
    }

    #[test]
    fn constant_map_projects_to_constant() {
        let env = LatLong::constant(37, 19, [0.25, 1.5, 3.0]);
        let tilted = DMat3::from_rotation_x(0.4) * DMat3::from_rotation_z(-1.1);
        for rot in [DMat3::IDENTITY, rotation_y(0.123), tilted] {
            let out = project_envmap(&env, rot).unwrap();
            for t in out.texels() {
                for (got, want) in t.iter().zip([0.25f32, 1.5, 3.0]) {
                    assert!((got - want).abs() < 1e-5 * want, "{got} vs {want}");
                }
            }
        }
    }

    #[test]
    fn projection_preserves_power() {
        // Area weighting keeps Σ Ω L: exactly (up to f32 output) for y-rotations, to splat accuracy otherwise.
        let env = random_map(128, 64, 3);
        let want = env.integral();
        let cases = [(rotation_y(0.77), 1e-6), (DMat3::from_rotation_x(0.5), 2e-3)];
        for (rot, rel) in cases {
            let got = project_envmap(&env, rot).unwrap().integral();
            for c in 0..3 {
                assert!((got[c] - want[c]).abs() < rel * want[c], "{got:?} vs {want:?}");
            }
        }
    }

    #[test]
    fn general_rotation_matches_y_path() {
        // The splat path, forced by a tiny tilt, agrees with the exact y path.
        let env = random_map(64, 32, 5);
        let exact = project_envmap(&env, rotation_y(0.5)).unwrap();
        let splat = LatLong::new(ENV_W, ENV_H, project_splat(&env, rotation_y(0.5))).unwrap();
        for (a, b) in exact.texels().iter().zip(splat.texels()) {
            for c in 0..3 {
                assert!((a[c] - b[c]).abs() < 0.02, "{a:?} vs {b:?}");
            }
        }
    }

    #[test]
    fn rejects_non_rotation() {
        let env = LatLong::constant(4, 2, [1.0; 3]);
        assert!(project_envmap(&env, DMat3::from_diagonal(DVec3::new(1.0, 1.0, -1.0))).is_err());
        assert!(LatLong::new(4, 2, vec![[0.0; 3]; 7]).is_err());
    }

    #[test]
    fn shade_is_a_dot_product() {
        let light = random_map(ENV_W, ENV_H, 9);
        let mut lt = vec![0.0f32; LT_DIM];
        lt[lt_index(1, 2, 3)] = 2.0;
        let rgb = shade(&lt, &light);
        assert_eq!(rgb, [0.0, 2.0 * light.get(2, 3)[1], 0.0]);
    }

    #[test]
    fn cameras_looking_at_a_point_meet_there() {
        let target = DVec3::new(0.1, -0.2, 0.3);
        let cams: Vec<PinholeCamera> = [
            DVec3::new(0.0, 0.0, 2.0),
            DVec3::new(1.5, 0.3, 1.0),
            DVec3::new(-1.0, 1.0, 1.5),
        ]
        .iter()
        .map(|&eye| PinholeCamera::look_at(eye, target, DVec3::Y, 32, 32, 0.5))
        .collect();
        assert!(nearest_point_to_axes(&cams).unwrap().abs_diff_eq(target, 1e-9));
        assert!(nearest_point_to_axes(&[cams[0], cams[0]]).is_none());
        // Two distinct cameras looking the same way (offset sideways): no centre.
        let parallel = [
            PinholeCamera::look_at(DVec3::new(0.0, 0.0, 2.0), DVec3::ZERO, DVec3::Y, 32, 32, 0.8),
            PinholeCamera::look_at(
                DVec3::new(0.5, 0.0, 2.0),
                DVec3::new(0.5, 0.0, 0.0),
                DVec3::Y,
                32,
                32,
                0.8,
            ),
        ];
        assert!(nearest_point_to_axes(&parallel).is_none());
    }

    #[test]
    fn camera_projects_and_unprojects() {
        let mut cam = PinholeCamera::look_at(DVec3::new(0.3, 0.2, 1.5), DVec3::ZERO, DVec3::Y, 64, 48, 0.6);
        cam.fy *= 1.1;
        cam.cx += 3.0;
        cam.validate().unwrap();
        assert!(cam.centre().abs_diff_eq(DVec3::new(0.3, 0.2, 1.5), 1e-12));
        // The target projects to the principal point.
        let c = cam.project(DVec3::ZERO).unwrap();
        assert!(c.abs_diff_eq(DVec2::new(cam.cx, cam.cy), 1e-9));
        // World up appears as image up (smaller v).
        assert!(cam.project(DVec3::new(0.0, 0.1, 0.0)).unwrap().y < cam.cy);
        // Pixel centre ray hits a point that projects back to the pixel centre.
        let (o, d) = cam.pixel_ray(10, 5);
        let back = cam.project(o + 2.0 * d).unwrap();
        assert!(back.abs_diff_eq(DVec2::new(10.5, 5.5), 1e-9));
        assert!(cam.project(o - d).is_none());
        let mut broken = cam;
        broken.fx = f64::NAN;
        assert!(broken.validate().is_err());
    }

    #[test]
    fn octahedral_normals_round_trip_and_8_bit_codes_stay_within_a_degree() {
        for i in 0..500 {
            let z = 1.0 - 2.0 * (i as f32 + 0.5) / 500.0;
            let phi = i as f32 * 2.399_963;
            let r = (1.0 - z * z).sqrt();
            let n = [r * phi.cos(), r * phi.sin(), z];
            let (u, v) = octahedral_encode(n);
            let back = octahedral_decode(u, v);
            let dot: f32 = n.iter().zip(back).map(|(a, b)| a * b).sum();
            assert!(dot > 1.0 - 1e-6, "{n:?} -> {back:?}");
            // Quantized to 255 steps over [−1, 1] as VRCO stores them.
            let q = |a: f32| ((a + 1.0) * 127.5).round() / 127.5 - 1.0;
            let coarse = octahedral_decode(q(u), q(v));
            let dot: f32 = n.iter().zip(coarse).map(|(a, b)| a * b).sum();
            assert!(dot > 1.0_f32.to_radians().cos(), "{n:?} -> {coarse:?}");
        }
    }

    #[test]
    fn lobe_table_corners_hit_nodes_and_wrap_in_azimuth() {
        for index in [0, 77, LOBE_TABLE_W * 20 + 5, LOBE_TABLE_H * LOBE_TABLE_W - 1] {
            let d = lobe_table_direction(index).as_vec3().to_array();
            let corners = lobe_table_corners(d);
            let (best, w) = corners
                .iter()
                .copied()
                .max_by(|a, b| a.1.total_cmp(&b.1))
                .unwrap();
            assert_eq!(best, index);
            assert!(w > 0.999, "{corners:?}");
        }
        // Just past φ = π the right neighbour is column 0 of the same row.
        let d = direction(0.5 * PI, PI - 0.001).as_vec3().to_array();
        let corners = lobe_table_corners(d);
        let row = LOBE_TABLE_H / 2 - 1;
        assert!(
            corners
                .iter()
                .any(|&(i, _)| i == row * LOBE_TABLE_W + LOBE_TABLE_W - 1)
        );
        assert!(
            corners
                .iter()
                .any(|&(i, w)| i == (row + 1) * LOBE_TABLE_W && w >= 0.0)
        );
        let total: f32 = corners.iter().map(|c| c.1).sum();
        assert!((total - 1.0).abs() < 1e-6);
    }
}
