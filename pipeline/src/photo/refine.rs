//! Shading-based refinement of the reconstructed surface: moves each vertex along its
//! normal so that the photographs' brightness matches `albedo × shading` under the
//! capture's lighting, where the albedo is held constant over a region of like
//! colour (the lighting fit's regions, [`super::lighting`]).
//!
//! The idea is shape from shading as a refinement of a coarse surface under
//! known low-frequency lighting (Wu, Wilburn, Matsushita & Theobalt, "High-quality
//! shape from multi-view stereo and shading under general illumination", CVPR 2011):
//! a Lambertian point's brightness is `ρ · V · E(n)`, and with `ρ` shared by a region
//! and the visibility `V` held from the current surface, what is left to explain a
//! vertex's brightness is its normal. Per vertex `v` with displacement `d_v` along
//! its starting normal,
//!
//! `r_v = ln ρ_g(v) + ln V_v + ln E(n_v(d)) − ln c_v`,
//!
//! `E(n)` the irradiance of the lighting's luminance as degree-0–2 spherical
//! harmonics convolved with the clamped cosine (Ramamoorthi & Hanrahan 2001,
//! `Â = π, 2π/3, π/4`, over π: the radiance of a white surface), `V_v` the ratio of
//! the traced shading (with the surface's own shadows) to `E` at the starting normal,
//! `c_v` the photographs' luminance, `ln ρ_g` the region's mean of
//! `ln c − ln V − ln E` (updated every step). The energy
//!
//! `Σ_v r_v² / N + α Σ_v (u_v − ū_v)² / N`, `u = d / spacing`, `ū` the neighbours' mean,
//!
//! is descended with analytic gradients (a vertex moves its own normal and its
//! neighbours'), each step clipped per vertex and growing while the energy falls,
//! halving when it rises; `|d|` is bounded.

use std::time::Instant;

use glam::{DVec3, Vec3};
use nelf_format::conventions::{
    ENV_H, ENV_W, LatLong, VIEW_HARMONICS, col_phi_bounds, direction, row_theta_bounds, view_harmonics,
};
use nelf_scene::mesh::Mesh;
use rayon::prelude::*;
use serde::Serialize;

use crate::error::{Result, invalid};
use crate::photo::lighting::albedo_regions;
use crate::photo::reflectance::Observations;

/// Default [`RefineSettings::smoothness`]: `--photo-refine-smoothness`'s.
pub const DEFAULT_SMOOTHNESS: f64 = crate::config::DEFAULT_PHOTO_REFINE_SMOOTHNESS;

/// Default [`RefineSettings::iterations`].
pub const DEFAULT_ITERATIONS: usize = 300;

/// How the surface is refined.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RefineSettings {
    /// Descent steps (0: no refinement).
    pub iterations: usize,
    /// Weight `α` of the displacement's roughness (see the module documentation).
    pub smoothness: f64,
    /// The largest displacement, in multiples of the mesh spacing.
    pub max_displacement: f64,
    /// The mesh's vertex spacing, metres.
    pub spacing_m: f64,
    /// Regions of like albedo: neighbours whose colours differ by less than this in
    /// log luminance (the lighting fit's rule).
    pub region_step: f64,
    /// Regions with fewer seen vertices take no part.
    pub region_min_vertices: usize,
}

impl Default for RefineSettings {
    fn default() -> Self {
        Self {
            iterations: DEFAULT_ITERATIONS,
            smoothness: DEFAULT_SMOOTHNESS,
            max_displacement: 2.0,
            spacing_m: 1.5e-3,
            region_step: 0.05,
            region_min_vertices: super::lighting::LightingFitSettings::default().region_min_vertices,
        }
    }
}

/// What the refinement did.
#[derive(Debug, Clone, Serialize)]
pub struct RefineReport {
    /// Vertices whose brightness took part.
    pub vertices: usize,
    /// Root-mean-square of `r` (log brightness) before and after.
    pub rms_log_residual: [f64; 2],
    /// Mean `|d|`, millimetres.
    pub mean_displacement_mm: f64,
    /// Largest `|d|`, millimetres.
    pub max_displacement_mm: f64,
    /// Steps taken (accepted).
    pub steps: usize,
    /// Seconds.
    pub seconds: f64,
}

/// The lighting's luminance irradiance as 9 spherical-harmonic coefficients, scaled
/// so that `Σ e_k y_k(n)` is the radiance of a white surface with normal `n`.
fn irradiance_harmonics(light: &LatLong) -> [f64; VIEW_HARMONICS] {
    const SUB: usize = 4;
    let mut coefficients = [0.0f64; VIEW_HARMONICS];
    for row in 0..ENV_H {
        let (t0, t1) = row_theta_bounds(row, ENV_H);
        for col in 0..ENV_W {
            let (p0, p1) = col_phi_bounds(col, ENV_W);
            let l = light.get(row, col);
            let lum = f64::from(l[0] + l[1] + l[2]) / 3.0;
            for a in 0..SUB {
                let (ta, tb) = (
                    t0 + (t1 - t0) * a as f64 / SUB as f64,
                    t0 + (t1 - t0) * (a + 1) as f64 / SUB as f64,
                );
                let theta = 0.5 * (ta + tb);
                let omega = (p1 - p0) / SUB as f64 * (ta.cos() - tb.cos());
                for b in 0..SUB {
                    let phi = p0 + (p1 - p0) * (b as f64 + 0.5) / SUB as f64;
                    let y = view_harmonics(direction(theta, phi).as_vec3().to_array());
                    for (c, yk) in coefficients.iter_mut().zip(y) {
                        *c += lum * omega * f64::from(yk);
                    }
                }
            }
        }
    }
    // Clamped-cosine convolution over π: 1, 2/3, 1/4 for degrees 0, 1, 2.
    for (k, c) in coefficients.iter_mut().enumerate() {
        *c *= match k {
            0 => 1.0,
            1..=3 => 2.0 / 3.0,
            _ => 0.25,
        };
    }
    coefficients
}

/// The constant harmonic `1/(2√π)`: `e[0] · Y0` is the mean radiance a white
/// surface reflects.
const Y0: f64 = 0.282_094_8;

fn irradiance(e: &[f64; VIEW_HARMONICS], n: DVec3) -> f64 {
    irradiance_and_gradient(e, n).0
}

/// `E(n)` and its gradient as a polynomial in `n = (x, y, z)` (unit), with the
/// harmonics of [`view_harmonics`].
fn irradiance_and_gradient(e: &[f64; VIEW_HARMONICS], n: DVec3) -> (f64, DVec3) {
    const A: f64 = 0.488_602_5;
    const B: f64 = 1.092_548_4;
    const C: f64 = 0.315_391_57;
    let (x, y, z) = (n.x, n.y, n.z);
    let value = e[0] * Y0
        + A * (e[1] * y + e[2] * z + e[3] * x)
        + B * (e[4] * x * y + e[5] * y * z + e[7] * x * z + 0.5 * e[8] * (x * x - y * y))
        + C * e[6] * (3.0 * z * z - 1.0);
    let slope = DVec3::new(
        A * e[3] + B * (e[4] * y + e[7] * z + e[8] * x),
        A * e[1] + B * (e[4] * x + e[5] * z - e[8] * y),
        A * e[2] + B * (e[5] * y + e[7] * x) + 6.0 * C * e[6] * z,
    );
    (value, slope)
}

/// The mesh's connectivity: each vertex's triangles and neighbours.
struct Topology {
    triangles_of: Vec<Vec<u32>>,
    neighbours: Vec<Vec<u32>>,
}

impl Topology {
    fn new(vertices: usize, triangles: &[[u32; 3]]) -> Self {
        let mut triangles_of = vec![Vec::new(); vertices];
        let mut neighbours = vec![Vec::new(); vertices];
        for (t, tri) in triangles.iter().enumerate() {
            for k in 0..3 {
                let (a, b) = (tri[k] as usize, tri[(k + 1) % 3] as usize);
                triangles_of[a].push(t as u32);
                neighbours[a].push(b as u32);
                neighbours[b].push(a as u32);
            }
        }
        for n in &mut neighbours {
            n.sort_unstable();
            n.dedup();
        }
        Self {
            triangles_of,
            neighbours,
        }
    }
}

impl Topology {
    /// Vertex `v`'s area-weighted normal, unnormalised (the sum of its triangles'
    /// edge cross products, as [`Mesh::vertex_normals`] before it normalises).
    fn area_normal(&self, triangles: &[[u32; 3]], positions: &[DVec3], v: usize) -> DVec3 {
        let mut m = DVec3::ZERO;
        for &t in &self.triangles_of[v] {
            let [a, b, c] = triangles[t as usize].map(|i| positions[i as usize]);
            m += (b - a).cross(c - a);
        }
        m
    }
}

/// Refines `mesh` (see the module documentation) from `observations` of it under
/// `light`; returns the moved mesh (same triangles and albedo) and what was done.
pub fn refine_surface(
    mesh: &Mesh,
    observations: &Observations,
    light: &LatLong,
    settings: &RefineSettings,
) -> Result<(Mesh, RefineReport)> {
    let start_time = Instant::now();
    let n = mesh.positions.len();
    if observations.colour.len() != n {
        return Err(invalid(format!(
            "refining the surface: {} observations for {} vertices",
            observations.colour.len(),
            n
        )));
    }
    let e = irradiance_harmonics(light);
    let normals0: Vec<DVec3> = mesh.vertex_normals().iter().map(|v| v.as_dvec3()).collect();
    let (region, sizes) = albedo_regions(
        observations,
        &mesh.triangles,
        settings.region_step,
        settings.region_min_vertices,
    );
    // Per data vertex: ln V and ln c; the rest take no part.
    let mut log_visibility = vec![f64::NAN; n];
    let mut log_colour = vec![f64::NAN; n];
    let mean_e = e[0] * Y0;
    for v in 0..n {
        let Some(c) = observations.colour[v] else { continue };
        if region[v] == usize::MAX || normals0[v] == DVec3::ZERO {
            continue;
        }
        let lum = f64::from(c[0] + c[1] + c[2]) / 3.0;
        let s = observations.shading(v, light);
        let traced = f64::from(s[0] + s[1] + s[2]) / 3.0;
        let unshadowed = irradiance(&e, normals0[v]);
        if !(lum > 0.0 && traced > 0.05 * mean_e && unshadowed > 0.05 * mean_e) {
            continue;
        }
        let visibility = traced / unshadowed;
        if !(0.2..=1.5).contains(&visibility) {
            continue;
        }
        log_visibility[v] = visibility.ln();
        log_colour[v] = lum.ln();
    }
    let data: Vec<usize> = (0..n).filter(|&v| log_colour[v].is_finite()).collect();
    let mut report = RefineReport {
        vertices: data.len(),
        rms_log_residual: [0.0; 2],
        mean_displacement_mm: 0.0,
        max_displacement_mm: 0.0,
        steps: 0,
        seconds: 0.0,
    };
    if data.is_empty() || settings.iterations == 0 {
        report.seconds = start_time.elapsed().as_secs_f64();
        return Ok((mesh.clone(), report));
    }
    let topology = Topology::new(n, &mesh.triangles);
    // The vertices displaced by `u` spacings along their starting normals.
    let positions_at = |u: &[f64]| -> Vec<DVec3> {
        (0..n)
            .map(|v| mesh.positions[v].as_dvec3() + normals0[v] * (u[v] * settings.spacing_m))
            .collect()
    };
    let groups = sizes.len();
    // ln(V E(n)) − ln c at vertex v.
    let log_error = |positions: &[DVec3], v: usize| {
        let normal = topology
            .area_normal(&mesh.triangles, positions, v)
            .normalize_or_zero();
        log_visibility[v] + irradiance(&e, normal).max(1e-4 * mean_e).ln() - log_colour[v]
    };
    let region_means = |u: &[f64]| {
        let positions = positions_at(u);
        let mut sum = vec![(0.0f64, 0usize); groups];
        for &v in &data {
            let s = &mut sum[region[v]];
            s.0 += log_error(&positions, v);
            s.1 += 1;
        }
        sum.iter()
            .map(|(s, k)| -s / (*k).max(1) as f64)
            .collect::<Vec<f64>>()
    };
    let roughness_of = |u: &[f64], v: usize| {
        let nb = &topology.neighbours[v];
        if nb.is_empty() {
            return 0.0;
        }
        u[v] - nb.iter().map(|&w| u[w as usize]).sum::<f64>() / nb.len() as f64
    };
    let energy = |u: &[f64], log_albedo: &[f64]| {
        let positions = positions_at(u);
        let data_term: f64 = data
            .par_iter()
            .map(|&v| (log_albedo[region[v]] + log_error(&positions, v)).powi(2))
            .sum::<f64>()
            / data.len() as f64;
        let rough: f64 = (0..n)
            .into_par_iter()
            .map(|v| roughness_of(u, v).powi(2))
            .sum::<f64>()
            / n as f64;
        (data_term, data_term + settings.smoothness * rough)
    };
    let is_data: Vec<bool> = (0..n).map(|v| log_colour[v].is_finite()).collect();
    let mut u = vec![0.0f64; n];
    let mut log_albedo = region_means(&u);
    let (first_data, mut current) = energy(&u, &log_albedo);
    report.rms_log_residual[0] = first_data.sqrt();
    let mut step = 0.5;
    let bound = settings.max_displacement.max(0.0);
    for _ in 0..settings.iterations {
        // ∂E/∂u_k. Data: per data vertex v, g_v = ∂(r_v²/N)/∂m_v with m_v the
        // unnormalised normal (Σ of its triangles' edge cross products), then
        // ∂m_v/∂u_k = s Σ_{t ∋ v, k} n0_k × (x_next(k) − x_prev(k)). Roughness
        // analytically.
        let positions = positions_at(&u);
        let g_data: Vec<DVec3> = (0..n)
            .into_par_iter()
            .map(|v| {
                if !is_data[v] {
                    return DVec3::ZERO;
                }
                let m = topology.area_normal(&mesh.triangles, &positions, v);
                let length = m.length();
                if length <= 0.0 {
                    return DVec3::ZERO;
                }
                let normal = m / length;
                let (value, slope) = irradiance_and_gradient(&e, normal);
                if value <= 1e-4 * mean_e {
                    return DVec3::ZERO;
                }
                let r = log_albedo[region[v]] + log_visibility[v] + value.ln() - log_colour[v];
                let d_ln_e = slope / value;
                // Project out the normal's own direction (|n| = 1), divide by |m|.
                let d_m = (d_ln_e - normal * normal.dot(d_ln_e)) / length;
                d_m * (2.0 * r / data.len() as f64)
            })
            .collect();
        let gradient: Vec<f64> = (0..n)
            .into_par_iter()
            .map(|k| {
                let mut g = 0.0;
                for &t in &topology.triangles_of[k] {
                    let tri = mesh.triangles[t as usize];
                    let Some(at) = tri.iter().position(|&i| i as usize == k) else {
                        continue;
                    };
                    let next = positions[tri[(at + 1) % 3] as usize];
                    let prev = positions[tri[(at + 2) % 3] as usize];
                    let dm = normals0[k].cross(next - prev) * settings.spacing_m;
                    for &v in &tri {
                        g += g_data[v as usize].dot(dm);
                    }
                }
                // Roughness: d/du_k Σ_v (u_v − ū_v)².
                let mut r = roughness_of(&u, k);
                for &w in &topology.neighbours[k] {
                    let w = w as usize;
                    r -= roughness_of(&u, w) / topology.neighbours[w].len().max(1) as f64;
                }
                g + settings.smoothness * 2.0 * r / n as f64
            })
            .collect();
        let norm = gradient.iter().map(|g| g * g).sum::<f64>().sqrt();
        // A step of `step` spacings for every vertex whose gradient reaches the 95th
        // percentile, less for the rest (a clipped descent direction: one sliver
        // triangle's vertex cannot hold every other vertex still).
        let mut magnitudes: Vec<f64> = gradient.iter().map(|g| g.abs()).collect();
        let at = (magnitudes.len() * 95 / 100).min(magnitudes.len() - 1);
        let (_, scale, _) = magnitudes.select_nth_unstable_by(at, f64::total_cmp);
        let scale = scale.max(1e-12 * norm);
        let mut accepted = false;
        for _ in 0..12 {
            let trial: Vec<f64> = u
                .iter()
                .zip(&gradient)
                .map(|(x, g)| (x - step * (g / scale).clamp(-1.0, 1.0)).clamp(-bound, bound))
                .collect();
            let (_, total) = energy(&trial, &log_albedo);
            if total < current {
                u = trial;
                step *= 1.2;
                accepted = true;
                break;
            }
            step *= 0.5;
        }
        if !accepted {
            break;
        }
        report.steps += 1;
        log_albedo = region_means(&u);
        current = energy(&u, &log_albedo).1;
    }
    let (last_data, _) = energy(&u, &log_albedo);
    report.rms_log_residual[1] = last_data.sqrt();
    let positions: Vec<Vec3> = positions_at(&u).iter().map(|p| p.as_vec3()).collect();
    let displacement_mm: Vec<f64> = u.iter().map(|x| x.abs() * settings.spacing_m * 1e3).collect();
    report.mean_displacement_mm = displacement_mm.iter().sum::<f64>() / n.max(1) as f64;
    report.max_displacement_mm = displacement_mm.iter().fold(0.0, |m: f64, d| m.max(*d));
    report.seconds = start_time.elapsed().as_secs_f64();
    let refined = Mesh {
        positions,
        ..mesh.clone()
    };
    Ok((refined, report))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::photo::test_support::{convex_observations, convex_transport, sun_and_sky, texel_direction};
    use nelf_scene::shapes::uv_sphere;

    #[test]
    fn irradiance_of_a_uniform_light_is_its_radiance() {
        // A white surface under uniform radiance 1 reflects radiance 1 whatever its normal.
        let e = irradiance_harmonics(&LatLong::constant(ENV_W, ENV_H, [1.0; 3]));
        for n in [
            DVec3::X,
            DVec3::Y,
            -DVec3::Z,
            DVec3::new(1.0, 2.0, -3.0).normalize(),
        ] {
            assert!((irradiance(&e, n) - 1.0).abs() < 1e-3, "{}", irradiance(&e, n));
        }
    }

    #[test]
    fn the_irradiance_gradient_matches_finite_differences() {
        let e = irradiance_harmonics(&sun_and_sky(21));
        for n in [DVec3::new(0.3, -0.5, 0.8), DVec3::new(-0.9, 0.1, 0.2), DVec3::Y] {
            let n = n.normalize();
            let (_, slope) = irradiance_and_gradient(&e, n);
            for axis in [DVec3::X, DVec3::Y, DVec3::Z] {
                let h = 1e-5;
                let numeric = (irradiance_and_gradient(&e, n + axis * h).0
                    - irradiance_and_gradient(&e, n - axis * h).0)
                    / (2.0 * h);
                assert!(
                    (numeric - slope.dot(axis)).abs() < 1e-6,
                    "{numeric} vs {}",
                    slope.dot(axis)
                );
            }
        }
    }

    /// Mean angle (degrees) between the mesh's normals and the sphere's radial ones
    /// over the vertices the sun lights.
    fn normal_error_deg(mesh: &Mesh, sun: DVec3) -> f64 {
        let normals = mesh.vertex_normals();
        let (mut sum, mut count) = (0.0, 0usize);
        for (p, n) in mesh.positions.iter().zip(&normals) {
            let radial = p.as_dvec3().normalize();
            if radial.dot(sun) > 0.2 {
                sum += n.as_dvec3().dot(radial).clamp(-1.0, 1.0).acos().to_degrees();
                count += 1;
            }
        }
        sum / count as f64
    }

    #[test]
    fn shading_flattens_lumps_the_photographs_do_not_show() {
        // The photographs show a round ball (one albedo) under a sun; the surface
        // starts with lumps (0.3 mm high, 12 mm apart).
        // Refining must take a share of them out, and leave the round ball as it is.
        let sun_texel = 4 * ENV_W + 8;
        let sun = texel_direction(sun_texel);
        let light = sun_and_sky(sun_texel);
        let round = uv_sphere(Vec3::ZERO, 0.05, 96, 192, [0.6; 3]);
        let lump = |p: Vec3| {
            let f = 2.0 * std::f32::consts::PI / 0.012;
            let height = 0.3e-3 * (f * p.x).sin() * (f * p.y).sin() * (f * p.z).sin();
            p + p.normalize() * height
        };
        let flat = Mesh {
            positions: round.positions.iter().map(|&p| lump(p)).collect(),
            ..round.clone()
        };
        let settings = RefineSettings {
            iterations: 300,
            smoothness: DEFAULT_SMOOTHNESS,
            max_displacement: 20.0,
            spacing_m: 0.05 * std::f64::consts::PI / 96.0,
            region_step: 0.05,
            region_min_vertices: 200,
        };
        let radial: Vec<DVec3> = round.positions.iter().map(|p| p.as_dvec3().normalize()).collect();
        let seen_as = |start: &Mesh| {
            let mut observations = convex_observations(radial.iter().map(|&n| (n, [0.6; 3])), &light);
            observations.transport = start
                .vertex_normals()
                .iter()
                .map(|n| convex_transport(n.as_dvec3()))
                .collect();
            observations
        };
        let before = normal_error_deg(&flat, sun);
        let (refined, report) = refine_surface(&flat, &seen_as(&flat), &light, &settings).expect("refines");
        let after = normal_error_deg(&refined, sun);
        assert!(report.vertices > 1000, "{report:?}");
        assert!(
            report.rms_log_residual[1] < 0.8 * report.rms_log_residual[0],
            "{report:?}"
        );
        // 3.1° → 2.3° at the default smoothness (1.9° at a tenth of it).
        assert!(after < 0.8 * before, "normal error {before:.2}° → {after:.2}°");
        let exact = normal_error_deg(&round, sun);
        let (kept, _) = refine_surface(&round, &seen_as(&round), &light, &settings).expect("refines");
        let drift = normal_error_deg(&kept, sun);
        assert!(
            drift < exact + 0.5,
            "the round ball drifted: {exact:.2}° → {drift:.2}°"
        );
    }
}
