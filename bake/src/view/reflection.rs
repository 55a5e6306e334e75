//! The reflection part of view dependence (`--view-dependence reflect`, format 1.2):
//! per band voxel, a normal and a scale of one lobe about the mirror direction
//! ([`nelf_render::reflection`]), fitted by weighted least squares to the residual
//! `T(x, ω) − T̄(x)` toward the sampled directions.

use glam::Vec3;
use nelf_format::conventions::{ENV_TEXELS, LT_DIM};

/// Lobe exponents the reflection part tries (`--view-dependence reflect` and `auto`); the
/// normal is chosen with the middle one.
pub const REFLECT_EXPONENTS: [f32; 3] = [10.0, 20.0, 40.0];

/// How far (degrees) from the density's normal the reflection fit looks for the normal
/// whose lobe explains most: a mesh shaded with interpolated normals differs from its
/// flat triangles' density gradient by a few degrees, and a highlight moves by twice
/// that (the scan: 96 % of the exact view dependence with it, 73 % without).
pub const REFLECT_NORMAL_SEARCH_DEG: f32 = 12.0;

/// The normal search of [`fit_reflection_voxel`] uses the directions whose weight is at
/// least this share of the heaviest's: on the CGAL capture's five views about half of
/// the seen directions, holding 90–95 % of the weight.
pub const REFLECT_SEARCH_WEIGHT: f64 = 0.05;

/// What the reflection part is fitted against: the eyes `T̄` averages over and the light
/// frame.
#[derive(Debug, Clone)]
pub struct ReflectionTarget {
    /// The eyes (world, metres), at most [`nelf_format::asset::MAX_REFLECTION_EYES`].
    pub eyes: Vec<Vec3>,
    /// The asset's light frame.
    pub world_from_light: glam::DMat3,
}

/// A voxel's reflection-lobe fit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReflectionFit {
    /// The scales `s_c ≥ 0` (all three equal for a colourless fit).
    pub scales: [f32; 3],
    /// How much of the weighted squared residual they remove (`Σ_c s_c · num_c`, the
    /// least-squares reduction): comparable between normals of one voxel.
    pub explained: f64,
}

/// `n` and, for a search angle `deg > 0`, six normals at `deg / 2` and six at `deg`
/// around it.
pub fn normal_candidates(n: Vec3, deg: f32) -> Vec<Vec3> {
    let mut out = vec![n];
    if deg > 0.0 {
        let (t, b) = n.any_orthonormal_pair();
        for ring in [0.5 * deg, deg] {
            let (sin, cos) = ring.to_radians().sin_cos();
            for k in 0..6 {
                let phi = k as f32 * std::f32::consts::TAU / 6.0 + ring.to_radians();
                out.push((cos * n + sin * (phi.cos() * t + phi.sin() * b)).normalize());
            }
        }
    }
    out
}

/// The reflection part's per-voxel fit ([`nelf_render::reflection`]): the scales
/// `s_c ≥ 0` minimising `Σ_d w_d Σ_i (R_d[c·128 + i] − s_c (h_i(ω_d) − h̄_i))²`, `R_d` the
/// residual `T(x, ω_d) − T̄(x)` toward `directions[d]` (`residual`, `D × 384`), `h` the
/// lobe at a surface of unit outward normal `n`, `h̄` its mean over the directions toward
/// `eyes` (those `T̄` averages over) and `w_d` = `weights[d]` ([`seen_weights`]). Zero
/// where nothing is seen or the lobe explains nothing. `colourless`: one scale for the
/// three channels (the sum of their squared errors), as the format stores.
#[allow(clippy::too_many_arguments)] // a voxel, its samples and the lobe
pub fn fit_reflection(
    lobe: &nelf_render::ReflectionLobe,
    x: Vec3,
    n: Vec3,
    eyes: &[Vec3],
    directions: &[Vec3],
    weights: &[f64],
    residual: &[f32],
    colourless: bool,
) -> ReflectionFit {
    if colourless {
        let summed = channel_sums(residual);
        let (scale, explained) = fit_summed_scale(lobe, x, n, eyes, directions, weights, &summed);
        return ReflectionFit {
            scales: [scale; 3],
            explained,
        };
    }
    let mean = lobe.mean_transport(x, n, eyes);
    let (mut num, mut den) = ([0.0f64; 3], [0.0f64; 3]);
    for ((d, w), r) in directions.iter().zip(weights).zip(residual.chunks_exact(LT_DIM)) {
        if *w <= 0.0 {
            continue;
        }
        let h = lobe.transport(*d, n);
        for c in 0..3 {
            for (i, (h, m)) in h.iter().zip(&mean).enumerate() {
                let dh = f64::from(h - m);
                num[c] += w * dh * f64::from(r[c * ENV_TEXELS + i]);
                den[c] += w * dh * dh;
            }
        }
    }
    let scales: [f64; 3] = std::array::from_fn(|c| {
        if den[c] > 0.0 {
            (num[c] / den[c]).max(0.0)
        } else {
            0.0
        }
    });
    ReflectionFit {
        scales: scales.map(|s| s as f32),
        explained: (0..3).map(|c| scales[c] * num[c]).sum(),
    }
}

/// Per direction, the residual summed over the three channels (`D × 128` of `D × 384`).
fn channel_sums(residual: &[f32]) -> Vec<f32> {
    residual
        .chunks_exact(LT_DIM)
        .flat_map(|r| (0..ENV_TEXELS).map(move |i| r[i] + r[ENV_TEXELS + i] + r[2 * ENV_TEXELS + i]))
        .collect()
}

/// The colourless fit of [`fit_reflection`] from channel-summed residuals (`D × 128`):
/// `s = Σ w dh·ΣR / (3 Σ w dh²)`, clamped at 0, and what it explains.
fn fit_summed_scale(
    lobe: &nelf_render::ReflectionLobe,
    x: Vec3,
    n: Vec3,
    eyes: &[Vec3],
    directions: &[Vec3],
    weights: &[f64],
    summed: &[f32],
) -> (f32, f64) {
    let mean = lobe.mean_transport(x, n, eyes);
    let (mut num, mut den) = (0.0f64, 0.0f64);
    for ((d, w), r) in directions
        .iter()
        .zip(weights)
        .zip(summed.chunks_exact(ENV_TEXELS))
    {
        if *w <= 0.0 {
            continue;
        }
        let h = lobe.transport(*d, n);
        let (mut a, mut b) = (0.0f32, 0.0f32);
        for ((h, m), r) in h.iter().zip(&mean).zip(r) {
            let dh = h - m;
            a += dh * r;
            b += dh * dh;
        }
        num += w * f64::from(a);
        den += w * f64::from(b);
    }
    den *= 3.0;
    let scale = if den > 0.0 { (num / den).max(0.0) } else { 0.0 };
    (scale as f32, scale * num)
}

/// One band voxel's reflection part: the normal (of the density's and those around it,
/// [`normal_candidates`], the one whose lobe at the middle exponent explains most) and
/// its scale under each of `lobes`.
#[allow(clippy::too_many_arguments)] // a voxel, its samples and the lobes
pub(super) fn fit_reflection_voxel(
    lobes: &[nelf_render::ReflectionLobe],
    x: Vec3,
    density_normal: Vec3,
    eyes: &[Vec3],
    directions: &[Vec3],
    weights: &[f64],
    summed: &[f32],
) -> ([f32; 3], Vec<f32>) {
    if density_normal == Vec3::ZERO || lobes.is_empty() {
        return ([0.0, 0.0, 1.0], vec![0.0; lobes.len()]);
    }
    let middle = &lobes[lobes.len() / 2];
    // The search looks only at the directions that weigh most (about half of those
    // seen: the rest hold a few per cent of the weight); the scales use them all.
    let heaviest = weights.iter().copied().fold(0.0f64, f64::max);
    let keep: Vec<usize> = (0..weights.len())
        .filter(|&d| weights[d] > 0.0 && weights[d] >= REFLECT_SEARCH_WEIGHT * heaviest)
        .collect();
    let search_directions: Vec<Vec3> = keep.iter().map(|&d| directions[d]).collect();
    let search_weights: Vec<f64> = keep.iter().map(|&d| weights[d]).collect();
    let search_summed: Vec<f32> = keep
        .iter()
        .flat_map(|&d| summed[d * ENV_TEXELS..(d + 1) * ENV_TEXELS].iter().copied())
        .collect();
    let mut best = (density_normal, f64::NEG_INFINITY);
    // Rings at 6° and 12° around the density's normal, then one at 2.4° around the
    // best of those (measured on a sphere whose normal is known, `bake/tests/view.rs`:
    // 1.1° median error against 2.8° with the first search alone and 0.9° with rings at
    // 1.5° and 3°, which cost 6 more lobe fits per voxel for 0.002 dB on the CGAL head).
    let try_normals = |candidates: Vec<Vec3>, best: &mut (Vec3, f64)| {
        for n in candidates {
            let (_, explained) = fit_summed_scale(
                middle,
                x,
                n,
                eyes,
                &search_directions,
                &search_weights,
                &search_summed,
            );
            if explained > best.1 {
                *best = (n, explained);
            }
        }
    };
    try_normals(
        normal_candidates(density_normal, REFLECT_NORMAL_SEARCH_DEG),
        &mut best,
    );
    let coarse = best.0;
    try_normals(
        normal_candidates(coarse, 0.4 * REFLECT_NORMAL_SEARCH_DEG)[1..7].to_vec(),
        &mut best,
    );
    let n = best.0;
    let scales = lobes
        .iter()
        .map(|lobe| fit_summed_scale(lobe, x, n, eyes, directions, weights, summed).0)
        .collect();
    (n.to_array(), scales)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::view::directions::{sample_directions, seen_weights};

    #[test]
    fn the_reflection_scale_recovers_a_known_lobe() {
        // A voxel facing +z seen from three eyes in front; its residual toward every
        // direction is exactly a lobe of scales (0.3, 0.2, 0.1) about the mirror
        // direction, minus the lobe's mean over the eyes.
        let lobe = nelf_render::ReflectionLobe::new(20.0, glam::DMat3::IDENTITY);
        let (x, n) = (Vec3::ZERO, Vec3::Z);
        let eyes = [
            Vec3::new(0.0, 0.0, 1.0),
            Vec3::new(0.5, 0.1, 0.9),
            Vec3::new(-0.4, -0.2, 0.9),
        ];
        let dirs = sample_directions();
        let weights = seen_weights(x.as_dvec3(), n.as_dvec3(), &eyes.map(Vec3::as_dvec3), &dirs);
        let scales = [0.3f32, 0.2, 0.1];
        let mean = lobe.mean_transport(x, n, &eyes);
        let residual: Vec<f32> = dirs
            .iter()
            .flat_map(|d| {
                let h = lobe.transport(*d, n);
                let mean = &mean;
                scales
                    .into_iter()
                    .flat_map(move |s| (0..ENV_TEXELS).map(move |i| s * (h[i] - mean[i])))
            })
            .collect();
        let fit = fit_reflection(&lobe, x, n, &eyes, &dirs, &weights, &residual, false).scales;
        for (a, b) in fit.iter().zip(scales) {
            assert!((a - b).abs() < 1e-4 * b, "{fit:?}");
        }
        // The true normal explains more of the residual than one turned 10° away.
        let turned = (Vec3::Z + 0.176 * Vec3::X).normalize();
        let at = |m: Vec3| fit_reflection(&lobe, x, m, &eyes, &dirs, &weights, &residual, false).explained;
        assert!(at(n) > 1.2 * at(turned), "{} vs {}", at(n), at(turned));
        // One scale for all three: their mean here (the channels' lobes are the same).
        let grey = fit_reflection(&lobe, x, n, &eyes, &dirs, &weights, &residual, true).scales;
        assert!(grey.iter().all(|g| (g - 0.2).abs() < 1e-4), "{grey:?}");
        // A view-independent voxel (no residual) gets no lobe; nor does a lobe pointing
        // the other way (negative scales clamp to zero).
        let zero = vec![0.0f32; residual.len()];
        assert_eq!(
            fit_reflection(&lobe, x, n, &eyes, &dirs, &weights, &zero, false).scales,
            [0.0; 3]
        );
        let negative: Vec<f32> = residual.iter().map(|r| -r).collect();
        assert_eq!(
            fit_reflection(&lobe, x, n, &eyes, &dirs, &weights, &negative, false).scales,
            [0.0; 3]
        );
    }
}
