//! A glossy lobe about the mirror direction, as light transport: the candidate
//! view-dependent representation that follows a highlight (issue 17; measured in
//! `bake/examples/view_reflect.rs`).
//!
//! A highlight moves with the mirror direction `r = 2 (n·ω_o) n − ω_o` of the outgoing
//! direction `ω_o` about the surface normal `n`; a basis over `ω_o` in the world frame
//! (spherical harmonics of degree ≤ 2, lobes learned from them) is too smooth to follow
//! one 20–30° wide. Here the view-dependent part of a voxel's transport is one lobe,
//!
//! `T(x, ω_o)[c·128 + i] = T̄(x)[c·128 + i] + s_c(x) · (h_i(r) − h̄_i(x))`,
//!
//! `h_i(r) = ∫_{texel i} max(0, r·ω)^λ max(0, n·ω) dω` (a modified-Phong lobe, Lafortune &
//! Willems 1994, without its normalisation, which `s_c` absorbs), and
//! `h̄_i(x) = mean_e h_i(r_e)` over the directions toward the eyes `T̄` was averaged over
//! (the capture's cameras): `T̄` already holds the lobe seen from there. Visibility is not
//! in `h` (the fitted `s_c` absorbs a voxel's average occlusion; measured, modulating `h`
//! by the voxel's own transport gains nothing). So the shaded radiance is
//! `s_c (Σ_i L_i h_i(r) − Σ_i L_i h̄_i)`: the environment map filtered by the lobe, looked
//! up per voxel per camera move.
//!
//! The texel integral is a 3 × 3 midpoint rule in `(θ, φ)` (a texel is 22.5° wide, the
//! lobe at λ = 20 about 30° at half maximum).

use glam::{DMat3, DVec3, Vec3};
use nelf_format::conventions::{
    ENV_H, ENV_TEXELS, ENV_W, col_phi_bounds, direction, row_theta_bounds, texel_center_direction,
};

/// Sub-directions per texel side in the lobe's texel integral.
const SUBDIVISIONS: usize = 3;

/// Texels whose centre is farther than this from `r` (cosine) are skipped: their
/// corners are within 17° of the centre and `cos^λ < 10⁻³` beyond 60° for `λ ≥ 10`.
const SKIP_BELOW_COS: f32 = 0.2;

/// The mirror direction of `toward_eye` about the unit normal `n`: `2 (n·ω) n − ω`.
pub fn mirror(toward_eye: Vec3, n: Vec3) -> Vec3 {
    (2.0 * n.dot(toward_eye) * n - toward_eye).normalize_or_zero()
}

/// One light texel: its centre and sub-directions with their solid angles, in the world.
#[derive(Debug, Clone)]
struct Texel {
    centre: Vec3,
    subs: [(Vec3, f32); SUBDIVISIONS * SUBDIVISIONS],
}

/// A Phong lobe of exponent `λ` over the 128 light texels of a light frame.
#[derive(Debug, Clone)]
pub struct ReflectionLobe {
    exponent: f32,
    texels: Vec<Texel>,
}

impl ReflectionLobe {
    /// A lobe of exponent `exponent` (λ ≥ 10, sharper is larger) over the light texels of
    /// a frame turned by `world_from_light`.
    pub fn new(exponent: f32, world_from_light: DMat3) -> Self {
        let n = SUBDIVISIONS as f64;
        let texels = (0..ENV_TEXELS)
            .map(|i| {
                let (row, col) = (i / ENV_W, i % ENV_W);
                let centre = (world_from_light * texel_center_direction(row, col, ENV_H, ENV_W)).as_vec3();
                let (t0, t1) = row_theta_bounds(row, ENV_H);
                let (p0, p1) = col_phi_bounds(col, ENV_W);
                let subs = std::array::from_fn(|k| {
                    let (a, b) = ((k / SUBDIVISIONS) as f64, (k % SUBDIVISIONS) as f64);
                    let (ta, tb) = (t0 + (t1 - t0) * a / n, t0 + (t1 - t0) * (a + 1.0) / n);
                    let phi = p0 + (p1 - p0) * (b + 0.5) / n;
                    let solid = (p1 - p0) / n * (ta.cos() - tb.cos());
                    let dir: DVec3 = world_from_light * direction(0.5 * (ta + tb), phi);
                    (dir.as_vec3(), solid as f32)
                });
                Texel { centre, subs }
            })
            .collect();
        Self { exponent, texels }
    }

    /// The lobe's exponent λ.
    pub fn exponent(&self) -> f32 {
        self.exponent
    }

    /// `h_i(r)` for every light texel `i`, at a surface of unit normal `n` (world).
    pub fn transport(&self, r: Vec3, n: Vec3) -> [f32; ENV_TEXELS] {
        let mut out = [0.0f32; ENV_TEXELS];
        for (h, texel) in out.iter_mut().zip(&self.texels) {
            if r.dot(texel.centre) < SKIP_BELOW_COS {
                continue;
            }
            *h = texel
                .subs
                .iter()
                .map(|(w, solid)| {
                    let cos_r = r.dot(*w);
                    if cos_r > 0.0 {
                        cos_r.powf(self.exponent) * n.dot(*w).max(0.0) * solid
                    } else {
                        0.0
                    }
                })
                .sum();
        }
        out
    }

    /// `h_i` seen from the eye at `eye` by a voxel at `x` with unit normal `n`.
    pub fn transport_seen_from(&self, x: Vec3, n: Vec3, eye: Vec3) -> [f32; ENV_TEXELS] {
        self.transport(mirror((eye - x).normalize_or_zero(), n), n)
    }

    /// `h̄_i(x)`: the mean of `h_i` over the eyes at `eyes` (those `T̄` was averaged over).
    pub fn mean_transport(&self, x: Vec3, n: Vec3, eyes: &[Vec3]) -> [f32; ENV_TEXELS] {
        let mut mean = [0.0f32; ENV_TEXELS];
        let share = 1.0 / eyes.len().max(1) as f32;
        for eye in eyes {
            for (m, h) in mean.iter_mut().zip(self.transport_seen_from(x, n, *eye)) {
                *m += h * share;
            }
        }
        mean
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_mirror_direction_reflects_about_the_normal() {
        let n = Vec3::Y;
        let toward = Vec3::new(1.0, 1.0, 0.0).normalize();
        let r = mirror(toward, n);
        assert!((r - Vec3::new(-1.0, 1.0, 0.0).normalize()).length() < 1e-6);
        // Along the normal the mirror is the normal itself.
        assert!((mirror(n, n) - n).length() < 1e-6);
    }

    #[test]
    fn the_lobe_peaks_toward_the_mirror_direction_and_integrates_like_phong() {
        let lobe = ReflectionLobe::new(20.0, DMat3::IDENTITY);
        // Straight up, normal up: the lobe's integral is ∫ cos^λ cos dω = 2π / (λ + 2).
        let h = lobe.transport(Vec3::Y, Vec3::Y);
        let total: f32 = h.iter().sum();
        let exact = 2.0 * std::f32::consts::PI / 22.0;
        assert!((total - exact).abs() < 0.03 * exact, "{total} vs {exact}");
        // Only the top rows see it, and nothing below the horizon.
        assert!(h[ENV_TEXELS / 2..].iter().all(|&v| v == 0.0));
        // Turned (with the normal along it, so that the cosine does not pull the lobe
        // toward the normal): the largest texel is the one the mirror direction falls in.
        let r = Vec3::new(0.6, 0.3, -0.74).normalize();
        let h = lobe.transport(r, r);
        let best = (0..ENV_TEXELS)
            .max_by(|&a, &b| h[a].total_cmp(&h[b]))
            .unwrap_or(0);
        let (row, col) = nelf_format::conventions::texel_of_direction(r.as_dvec3(), ENV_H, ENV_W);
        assert_eq!(best, row * ENV_W + col);
    }

    #[test]
    fn the_light_frame_turns_the_texels() {
        // A lobe in a frame turned 90° about y is the unturned lobe of the turned direction.
        let turn = nelf_format::conventions::rotation_y(std::f64::consts::FRAC_PI_2);
        let turned = ReflectionLobe::new(20.0, turn);
        let plain = ReflectionLobe::new(20.0, DMat3::IDENTITY);
        let r = Vec3::new(0.3, 0.5, 0.81).normalize();
        let back = (turn.transpose() * r.as_dvec3()).as_vec3();
        let a = turned.transport(r, Vec3::Y);
        let b = plain.transport(back, Vec3::Y);
        for (x, y) in a.iter().zip(b) {
            assert!((x - y).abs() < 1e-5, "{x} vs {y}");
        }
    }
}
