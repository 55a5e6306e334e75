//! A glossy lobe about the mirror direction, as light transport: the reflection part
//! of a view-dependent asset (format 1.3, `VREF`/`VRCO`, SPEC.md §6; measured in
//! `docs/measurements/2026-11-27-reflection-lobe.md`).
//!
//! A highlight moves with the mirror direction `r = 2 (n·ω) n − ω` of the outgoing
//! direction `ω` about the surface normal `n`; a basis over `ω` in the world frame
//! (spherical harmonics of degree ≤ 2, lobes learned from them) is too smooth to follow
//! one 20–30° wide. Here the view-dependent part of a voxel's transport is one lobe,
//!
//! `T(x, ω)[c·128 + i] = T̄(x)[c·128 + i] + s(x) · (h_i(ω) − h̄_i(x))`,
//! `h_i(ω) = max(0, n·ω) g_i(r)`, `g_i(r) ≈ ∫_{texel i} max(0, r·ω')^λ dω'`
//!
//! (a Phong lobe, Lafortune & Willems 1994, without its normalisation, which `s`
//! absorbs; the cosine taken at the lobe's centre, `n·r = n·ω`), and
//! `h̄_i(x) = mean_e h_i(ω_e)` over the directions toward the eyes `T̄` was averaged over
//! (the capture's cameras): `T̄` already holds the lobe seen from there. Visibility is
//! not in `h` (the fitted `s` absorbs a voxel's average occlusion; measured, modulating
//! `h` by the voxel's own transport gains nothing).
//!
//! **The table.** `g_i` is tabulated once per exponent at the `64 × 128` nodes of a
//! lat-long table in the light frame ([`nelf_format::conventions::lobe_table_corners`]),
//! each node's texel integral a 3 × 3 midpoint rule in `(θ, φ)`, and interpolated
//! bilinearly between nodes (2.8° apart; the lobe at λ = 40 is 15° wide at half
//! maximum). Shading is linear in `g`, so the radiance is
//! `s · (max(0, n·ω) E(r) − Ē(x))` with `E(r) = Σ_i L_i g_i(r)` the environment filtered by
//! the lobe, tabulated at the same nodes once per lighting change
//! ([`FilteredEnvironment`]) and interpolated the same way: the fit of the bake, this
//! CPU renderer and the GPU's view pass (`shaders/reflect.wgsl`) use one model.

use glam::{DMat3, DVec3, Mat3, Vec3};
use nelf_format::conventions::{
    ENV_H, ENV_TEXELS, ENV_W, LOBE_TABLE_H, LOBE_TABLE_W, LatLong, col_phi_bounds, direction,
    lobe_table_corners, lobe_table_direction, row_theta_bounds,
};
use nelf_format::{Asset, Reflection};
use rayon::prelude::*;

/// Sub-directions per texel side in a node's texel integral.
const SUBDIVISIONS: usize = 3;

/// Nodes of the lobe table.
pub const LOBE_TABLE_NODES: usize = LOBE_TABLE_H * LOBE_TABLE_W;

/// Voxels per parallel work item (one brick).
const VOXELS_PER_TASK: usize = 512;

/// The mirror direction of `toward_eye` about the unit normal `n`: `2 (n·ω) n − ω`.
pub fn mirror(toward_eye: Vec3, n: Vec3) -> Vec3 {
    (2.0 * n.dot(toward_eye) * n - toward_eye).normalize_or_zero()
}

/// A Phong lobe of exponent `λ` over the 128 light texels, tabulated over directions.
#[derive(Debug, Clone)]
pub struct ReflectionLobe {
    exponent: f32,
    light_from_world: Mat3,
    /// `g_i` at every node, node-major (`LOBE_TABLE_NODES × 128`).
    table: Vec<f32>,
}

impl ReflectionLobe {
    /// A lobe of exponent `exponent` (λ ≥ 1, sharper is larger) over the light texels of a
    /// frame turned by `world_from_light`.
    pub fn new(exponent: f32, world_from_light: DMat3) -> Self {
        let n = SUBDIVISIONS as f64;
        // Every texel's sub-directions and solid angles, in the light frame.
        let subs: Vec<[(Vec3, f32); SUBDIVISIONS * SUBDIVISIONS]> = (0..ENV_TEXELS)
            .map(|i| {
                let (row, col) = (i / ENV_W, i % ENV_W);
                let (t0, t1) = row_theta_bounds(row, ENV_H);
                let (p0, p1) = col_phi_bounds(col, ENV_W);
                std::array::from_fn(|k| {
                    let (a, b) = ((k / SUBDIVISIONS) as f64, (k % SUBDIVISIONS) as f64);
                    let (ta, tb) = (t0 + (t1 - t0) * a / n, t0 + (t1 - t0) * (a + 1.0) / n);
                    let phi = p0 + (p1 - p0) * (b + 0.5) / n;
                    let solid = (p1 - p0) / n * (ta.cos() - tb.cos());
                    let dir: DVec3 = direction(0.5 * (ta + tb), phi);
                    (dir.as_vec3(), solid as f32)
                })
            })
            .collect();
        let mut table = vec![0.0f32; LOBE_TABLE_NODES * ENV_TEXELS];
        table
            .par_chunks_mut(ENV_TEXELS)
            .enumerate()
            .for_each(|(node, g)| {
                let r = lobe_table_direction(node).as_vec3();
                for (gi, texel) in g.iter_mut().zip(&subs) {
                    *gi = texel
                        .iter()
                        .map(|(w, solid)| {
                            let c = r.dot(*w);
                            if c > 0.0 { c.powf(exponent) * solid } else { 0.0 }
                        })
                        .sum();
                }
            });
        Self {
            exponent,
            light_from_world: world_from_light.transpose().as_mat3(),
            table,
        }
    }

    /// The lobe's exponent λ.
    pub fn exponent(&self) -> f32 {
        self.exponent
    }

    /// `g_i(r)` for every light texel `i`, `r` a world direction.
    pub fn lobe(&self, r: Vec3) -> [f32; ENV_TEXELS] {
        let mut out = [0.0f32; ENV_TEXELS];
        for (node, w) in lobe_table_corners((self.light_from_world * r).to_array()) {
            if w > 0.0 {
                for (o, g) in out
                    .iter_mut()
                    .zip(&self.table[node * ENV_TEXELS..(node + 1) * ENV_TEXELS])
                {
                    *o += w * g;
                }
            }
        }
        out
    }

    /// Whether this is the lobe of exponent `exponent` over the frame `world_from_light`
    /// (as [`Self::new`] would build it).
    pub fn is_for(&self, exponent: f32, world_from_light: DMat3) -> bool {
        self.exponent == exponent && self.light_from_world == world_from_light.transpose().as_mat3()
    }

    /// `h_i(ω) = max(0, n·ω) g_i(r)` toward the world direction `toward_eye` (unit) at a
    /// surface of unit normal `n`.
    pub fn transport(&self, toward_eye: Vec3, n: Vec3) -> [f32; ENV_TEXELS] {
        let cos = n.dot(toward_eye);
        if cos <= 0.0 {
            return [0.0; ENV_TEXELS];
        }
        self.lobe(mirror(toward_eye, n)).map(|g| cos * g)
    }

    /// `h̄_i(x)`: the mean of `h_i` over the directions from `x` toward the eyes `eyes`.
    pub fn mean_transport(&self, x: Vec3, n: Vec3, eyes: &[Vec3]) -> [f32; ENV_TEXELS] {
        let mut mean = [0.0f32; ENV_TEXELS];
        let share = 1.0 / eyes.len().max(1) as f32;
        for eye in eyes {
            for (m, h) in mean
                .iter_mut()
                .zip(self.transport((*eye - x).normalize_or_zero(), n))
            {
                *m += h * share;
            }
        }
        mean
    }

    /// The environment `light` (8 × 16, already in the asset's light frame, the map the
    /// PCA part is shaded with) filtered by the lobe: `E(r) = Σ_i L_i g_i(r)` at every node.
    pub fn filter(&self, light: &LatLong) -> FilteredEnvironment {
        let texels = light.texels();
        let mut nodes = vec![[0.0f32; 3]; LOBE_TABLE_NODES];
        nodes.par_iter_mut().enumerate().for_each(|(node, e)| {
            let g = &self.table[node * ENV_TEXELS..(node + 1) * ENV_TEXELS];
            let mut sum = [0.0f64; 3];
            for (gi, l) in g.iter().zip(texels) {
                for c in 0..3 {
                    sum[c] += f64::from(*gi) * f64::from(l[c]);
                }
            }
            *e = sum.map(|v| v as f32);
        });
        FilteredEnvironment {
            light_from_world: self.light_from_world,
            nodes,
        }
    }
}

/// The environment filtered by a reflection lobe, `E(r)` at the nodes of the lobe table
/// (rebuilt per lighting change; the GPU uploads [`Self::nodes`]).
#[derive(Debug, Clone)]
pub struct FilteredEnvironment {
    light_from_world: Mat3,
    nodes: Vec<[f32; 3]>,
}

impl FilteredEnvironment {
    /// `E(r)` at world direction `r`, interpolated bilinearly.
    pub fn at(&self, r: Vec3) -> [f32; 3] {
        let mut out = [0.0f32; 3];
        for (node, w) in lobe_table_corners((self.light_from_world * r).to_array()) {
            for (o, e) in out.iter_mut().zip(self.nodes[node]) {
                *o += w * e;
            }
        }
        out
    }

    /// `max(0, n·ω) E(r)`, the lobe's radiance toward `toward_eye` (unit) per unit scale.
    pub fn toward(&self, toward_eye: Vec3, n: Vec3) -> [f32; 3] {
        let cos = n.dot(toward_eye);
        if cos <= 0.0 {
            return [0.0; 3];
        }
        self.at(mirror(toward_eye, n)).map(|e| cos * e)
    }

    /// The table, row-major (`64 × 128` RGB).
    pub fn nodes(&self) -> &[[f32; 3]] {
        &self.nodes
    }

    /// `light_from_world`, the table's frame.
    pub fn light_from_world(&self) -> Mat3 {
        self.light_from_world
    }
}

/// Per-voxel radiance of an asset with a reflection part toward an eye at `eye` (metres,
/// world): `base[v] + s_v · (max(0, n_v·ω) E(r) − mean_e max(0, n_v·ω_e) E(r_e))`, with
/// `ω = normalize(eye − centre_v)` per voxel (as [`crate::view`] takes it) and
/// `filtered` the lighting filtered by the part's lobe; `base` is the PCA part's radiance.
pub fn reflection_seen_from(
    asset: &Asset,
    reflection: &Reflection,
    base: &[[f32; 3]],
    filtered: &FilteredEnvironment,
    eye: DVec3,
) -> Vec<[f32; 3]> {
    let eyes: Vec<DVec3> = reflection
        .eyes_m
        .iter()
        .map(|e| DVec3::from_array(e.map(f64::from)))
        .collect();
    let voxels = base.len().min(reflection.coefficients.voxel_count());
    let mut out = base.to_vec();
    out[..voxels]
        .par_chunks_mut(VOXELS_PER_TASK)
        .enumerate()
        .for_each(|(task, chunk)| {
            for (i, rgb) in chunk.iter_mut().enumerate() {
                let v = task * VOXELS_PER_TASK + i;
                let (n, s) = reflection.voxel(v);
                if s <= 0.0 {
                    continue;
                }
                let n = Vec3::from_array(n);
                let x = asset.voxel_position_m(v);
                let seen = filtered.toward((eye - x).normalize_or_zero().as_vec3(), n);
                let share = 1.0 / eyes.len().max(1) as f32;
                let mut mean = [0.0f32; 3];
                for e in &eyes {
                    let m = filtered.toward((*e - x).normalize_or_zero().as_vec3(), n);
                    for c in 0..3 {
                        mean[c] += share * m[c];
                    }
                }
                for c in 0..3 {
                    rgb[c] += s * (seen[c] - mean[c]);
                }
            }
        });
    out
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
        // Straight up: the lobe's integral is ∫ cos^λ dω = 2π / (λ + 1) over the upper
        // hemisphere.
        let g = lobe.lobe(Vec3::Y);
        let total: f32 = g.iter().sum();
        let exact = 2.0 * std::f32::consts::PI / 21.0;
        assert!((total - exact).abs() < 0.03 * exact, "{total} vs {exact}");
        // Only the top rows see it, and nothing below the horizon.
        assert!(g[ENV_TEXELS / 2..].iter().all(|&v| v == 0.0));
        // Turned: the largest texel is the one the mirror direction falls in.
        let r = Vec3::new(0.6, 0.3, -0.74).normalize();
        let g = lobe.lobe(r);
        let best = (0..ENV_TEXELS)
            .max_by(|&a, &b| g[a].total_cmp(&g[b]))
            .unwrap_or(0);
        let (row, col) = nelf_format::conventions::texel_of_direction(r.as_dvec3(), ENV_H, ENV_W);
        assert_eq!(best, row * ENV_W + col);
        // Between nodes the table stays within 3 % of the lobe integrated there directly.
        let direct: f32 = {
            let mut sum = 0.0f64;
            for row in 0..256 {
                for col in 0..512 {
                    let (t0, t1) = row_theta_bounds(row, 256);
                    let (p0, p1) = col_phi_bounds(col, 512);
                    let w = direction(0.5 * (t0 + t1), 0.5 * (p0 + p1)).as_vec3();
                    let c = r.dot(w).max(0.0);
                    sum += f64::from(c.powf(20.0)) * (p1 - p0) * (t0.cos() - t1.cos());
                }
            }
            sum as f32
        };
        let tabled: f32 = g.iter().sum();
        assert!((tabled - direct).abs() < 0.03 * direct, "{tabled} vs {direct}");
    }

    #[test]
    fn the_filtered_environment_is_the_lobe_dotted_with_the_light() {
        let turn = nelf_format::conventions::rotation_y(0.7);
        let lobe = ReflectionLobe::new(10.0, turn);
        let texels: Vec<[f32; 3]> = (0..ENV_TEXELS)
            .map(|i| [i as f32 * 0.01, 1.0, (i % 7) as f32])
            .collect();
        let light = LatLong::new(ENV_W, ENV_H, texels.clone()).unwrap();
        let filtered = lobe.filter(&light);
        for r in [Vec3::Y, Vec3::new(0.3, -0.2, 0.9).normalize(), -Vec3::X] {
            let g = lobe.lobe(r);
            let e = filtered.at(r);
            for c in 0..3 {
                let want: f32 = g.iter().zip(&texels).map(|(g, l)| g * l[c]).sum();
                assert!(
                    (e[c] - want).abs() <= 1e-4 * want.abs().max(1.0),
                    "{e:?} vs {want}"
                );
            }
            // And toward an eye it is the cosine times E at the mirror direction.
            let n = (r + Vec3::Z).normalize();
            let toward = (2.0 * n.dot(r) * n - r).normalize();
            let h = lobe.transport(toward, n);
            let seen = filtered.toward(toward, n);
            let want: f32 = h.iter().zip(&texels).map(|(h, l)| h * l[1]).sum();
            assert!(
                (seen[1] - want).abs() <= 1e-4 * want.max(1.0),
                "{seen:?} vs {want}"
            );
        }
    }

    #[test]
    fn the_light_frame_turns_the_texels() {
        // A lobe in a frame turned 90° about y is the unturned lobe of the turned direction.
        let turn = nelf_format::conventions::rotation_y(std::f64::consts::FRAC_PI_2);
        let turned = ReflectionLobe::new(20.0, turn);
        let plain = ReflectionLobe::new(20.0, DMat3::IDENTITY);
        let r = Vec3::new(0.3, 0.5, 0.81).normalize();
        let back = (turn.transpose() * r.as_dvec3()).as_vec3();
        let a = turned.lobe(r);
        let b = plain.lobe(back);
        for (x, y) in a.iter().zip(b) {
            assert!((x - y).abs() < 1e-5, "{x} vs {y}");
        }
    }
}
