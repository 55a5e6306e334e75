//! The outgoing directions the view stage samples every band voxel's transport toward
//! (a Fibonacci sphere), how much each counts at a voxel (facing its outward normal,
//! most near the views' eyes), and that normal (`−∇σ` of the trilinear density).

use glam::{DVec3, Vec3};
use nelf_render::BrickGrid;

/// Outgoing directions sampled per voxel.
pub const VIEW_DIRECTIONS: usize = 64;

/// Concentration of the direction weights around the directions toward the views'
/// eyes: `exp(κ (c·ω − 1))`, κ = 4 (a von Mises–Fisher kernel ≈ 30° wide).
const VIEW_KERNEL: f64 = 8.0;

/// Weight every seen direction keeps however far from the views (relative to a
/// direction right at one).
const VIEW_WEIGHT_FLOOR: f64 = 0.02;

/// The fixed outgoing directions (a Fibonacci sphere of [`VIEW_DIRECTIONS`] points).
/// Sampling only a cap around the capture's views was measured no better
/// (`docs/measurements/settings.md`).
pub fn sample_directions() -> Vec<Vec3> {
    let n = VIEW_DIRECTIONS as f64;
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    (0..VIEW_DIRECTIONS)
        .map(|i| {
            let y = 1.0 - 2.0 * (i as f64 + 0.5) / n;
            let r = (1.0 - y * y).max(0.0).sqrt();
            let phi = golden * i as f64;
            DVec3::new(r * phi.cos(), y, r * phi.sin()).as_vec3()
        })
        .collect()
}

/// Outward unit normal `−∇σ/|∇σ|` of the trilinear density at `p` (zero where flat).
pub(super) fn density_normal(grid: &BrickGrid, density: &[f32], p: DVec3) -> DVec3 {
    let h = 0.5 * grid.geometry().voxel_size_m;
    let mut corners = [(0usize, 0.0f32); 8];
    let mut sample = |q: DVec3| -> f64 {
        let n = grid.trilinear(q, &mut corners);
        corners[..n].iter().map(|&(v, w)| f64::from(w * density[v])).sum()
    };
    let gradient = DVec3::new(
        sample(p + DVec3::X * h) - sample(p - DVec3::X * h),
        sample(p + DVec3::Y * h) - sample(p - DVec3::Y * h),
        sample(p + DVec3::Z * h) - sample(p - DVec3::Z * h),
    );
    (-gradient).normalize_or_zero()
}

/// How much each outgoing direction counts at a voxel at `x` with outward normal `n`
/// (zero: unknown, every direction faces): `max(0, n·ω) · (mean_e exp(κ (e·ω − 1)) +
/// floor)`, `e` the directions toward `eyes`: the directions the voxel is seen from, most
/// near the views.
pub fn seen_weights(x: DVec3, n: DVec3, eyes: &[DVec3], directions: &[Vec3]) -> Vec<f64> {
    let toward: Vec<DVec3> = eyes.iter().map(|e| (*e - x).normalize_or_zero()).collect();
    directions
        .iter()
        .map(|d| {
            let d = d.as_dvec3();
            let facing = if n == DVec3::ZERO { 1.0 } else { n.dot(d).max(0.0) };
            let near: f64 = toward
                .iter()
                .map(|c| (VIEW_KERNEL * (c.dot(d) - 1.0)).exp())
                .sum();
            facing * (near / toward.len().max(1) as f64 + VIEW_WEIGHT_FLOOR)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn directions_cover_the_sphere_evenly() {
        let d = sample_directions();
        let mean: Vec3 = d.iter().copied().sum::<Vec3>() / d.len() as f32;
        assert!(mean.length() < 0.02, "{mean}");
        for v in &d {
            assert!((v.length() - 1.0).abs() < 1e-5);
        }
    }
}
