//! Reflectance from photographs: the diffuse albedo of each vertex of a
//! reconstructed surface, the colour the views see there divided by the shading
//! our path tracer computes there under the capture's lighting.
//!
//! For a Lambertian surface seen in view `v`, the pixel's linear colour is
//! `c_v = a · S(x)` with `S(x) = Σ_k T₁(x)_k L_k` the outgoing radiance of a white
//! surface (`T₁` the light transport with albedo 1: direct light over the 8 × 16
//! map's texels with the mesh's own shadows, [`nelf_scene::tracer::LtTracer`]), so
//!
//! `a(x) = Σ_v w_v c_v / (Σ_v w_v · S(x))`,
//!
//! with `w_v = max(0, n·ω_v)²` for the views that see `x` (in front of the camera,
//! inside its frame and mask, and no surface between: one shadow ray toward the
//! camera), so that grazing views, where a misplaced surface smears the image
//! most, count least. Vertices no view sees take the mean of their neighbours
//! (repeated until every vertex that touches a seen one has a value); the rest take
//! the mean albedo. Shading below 2 % of the median is held at that floor (a
//! point the lighting barely reaches says nothing about its albedo).
//!
//! Interreflection is left out of `S` when [`ReflectanceSettings::bounces`] is 0:
//! the bake then adds it back with the recovered albedo, which brightens concave
//! places a little (not yet measured).

use std::time::Instant;

use glam::Vec3;
use nelf_bake::LoadedCapture;
use nelf_format::conventions::{ENV_TEXELS, LT_DIM, LatLong};
use nelf_scene::mesh::{Albedo, Mesh};
use nelf_scene::surface_nets::vertex_neighbours;
use nelf_scene::tracer::{LtTracer, TraceSettings};
use rayon::prelude::*;
use serde::Serialize;

use crate::error::{Context as _, Result, invalid};
use crate::photo::pixels::{bilinear, bilinear_rgb};

/// How the reflectance is estimated.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReflectanceSettings {
    /// Direct-light samples per map texel for the shading (1 = 128 directions).
    pub texel_samples: u32,
    /// Interreflections in the shading (0: direct light only).
    pub bounces: u32,
    /// Cosine-weighted indirect directions when `bounces > 0`.
    pub indirect_samples: u32,
    /// Seed of the shading's samples.
    pub seed: u64,
    /// When the lighting's scale is unknown (estimated, not named): scale every
    /// albedo so that the 98th percentile of the brightest channel is this value.
    pub normalise_to: Option<f32>,
    /// Leave out views more than this fraction brighter than the median view at a
    /// point (specular highlights); `None`: every view counts.
    pub highlight_tolerance: Option<f32>,
}

impl Default for ReflectanceSettings {
    fn default() -> Self {
        Self {
            texel_samples: 1,
            bounces: 0,
            indirect_samples: 16,
            seed: 0,
            normalise_to: None,
            highlight_tolerance: Some(0.1),
        }
    }
}

/// What the reflectance stage found.
#[derive(Debug, Clone, Serialize)]
pub struct ReflectanceReport {
    /// Vertices at least one view sees.
    pub seen_vertices: usize,
    /// Vertices filled from their neighbours.
    pub filled_vertices: usize,
    /// Vertices given the mean albedo (no seen vertex reachable).
    pub defaulted_vertices: usize,
    /// Albedos above 1 in some channel before clamping (lighting too dim for the
    /// photographs, or a misplaced surface).
    pub clamped_vertices: usize,
    /// The factor every albedo was multiplied by ([`ReflectanceSettings::normalise_to`];
    /// 1 when the lighting's scale is known): the lighting's scale relative to the
    /// photographs is its inverse.
    pub albedo_gain: f32,
    /// Mean albedo of the seen vertices, linear RGB.
    pub mean_albedo: [f32; 3],
    /// Seconds.
    pub seconds: f64,
}

/// The colour the views see at `x` (normal `n`), with its total weight: the
/// weighted mean over the views that see it, leaving out views more than
/// `highlight_tolerance` brighter (luminance) than the weighted median when three
/// or more see it — a specular highlight shows in one view and not the others.
fn seen_colour(
    tracer: &LtTracer,
    capture: &LoadedCapture,
    x: Vec3,
    n: Vec3,
    offset_m: f32,
    highlight_tolerance: Option<f32>,
) -> ([f64; 3], f64) {
    let mut seen: Vec<([f32; 3], f32)> = Vec::with_capacity(capture.cameras.len());
    for (v, camera) in capture.cameras.iter().enumerate() {
        let eye = camera.centre();
        let to_eye = eye - x.as_dvec3();
        let dist = to_eye.length();
        let dir = (to_eye / dist).as_vec3();
        let cosine = n.dot(dir);
        if cosine <= 0.0 {
            continue;
        }
        let Some(pixel) = camera.project(x.as_dvec3()) else {
            continue;
        };
        let (w, h) = (camera.width as usize, camera.height as usize);
        let mask = bilinear(&capture.masks[v], w, h, pixel, |m, k| {
            m.iter().zip(k).map(|(m, k)| m * k).sum()
        });
        if mask.is_none_or(|m| m < 0.5) {
            continue;
        }
        let origin = x + n * offset_m + dir * offset_m;
        if let Some(hit) = tracer.intersect(origin, dir)
            && f64::from(hit.t) < dist - 2.0 * f64::from(offset_m)
        {
            continue;
        }
        let Some(colour) = bilinear_rgb(&capture.images[v], w, h, pixel) else {
            continue;
        };
        seen.push((colour, cosine * cosine));
    }
    let luminance = |c: &[f32; 3]| (c[0] + c[1] + c[2]) / 3.0;
    let ceiling = match highlight_tolerance {
        Some(tolerance) if seen.len() >= 3 => {
            let mut by_luminance: Vec<(f32, f32)> = seen.iter().map(|(c, w)| (luminance(c), *w)).collect();
            by_luminance.sort_by(|a, b| a.0.total_cmp(&b.0));
            let half = 0.5 * by_luminance.iter().map(|(_, w)| w).sum::<f32>();
            let mut running = 0.0;
            let median = by_luminance
                .iter()
                .find(|(_, w)| {
                    running += w;
                    running >= half
                })
                .map_or(f32::INFINITY, |(l, _)| *l);
            median * (1.0 + tolerance)
        }
        _ => f32::INFINITY,
    };
    let mut sum = [0.0f64; 3];
    let mut total = 0.0f64;
    for (colour, weight) in seen.iter().filter(|(c, _)| luminance(c) <= ceiling) {
        for ch in 0..3 {
            sum[ch] += f64::from(*weight) * f64::from(colour[ch]);
        }
        total += f64::from(*weight);
    }
    (sum, total)
}

/// What the photographs show at each vertex of a surface, and how a white copy of
/// it responds to each texel of the 8 × 16 light basis: all the reflectance and
/// lighting stages need of the views and the geometry.
#[derive(Debug, Clone)]
pub struct Observations {
    /// Per vertex: the colour the views see there (linear RGB, see [`seen_colour`]),
    /// `None` where no view sees it.
    pub colour: Vec<Option<[f32; 3]>>,
    /// Per vertex seen: the outgoing radiance of a white surface there per unit
    /// radiance of each light texel (`ENV_TEXELS` values, the same in every
    /// channel); empty for vertices no view sees.
    pub transport: Vec<Vec<f32>>,
    /// Seconds.
    pub seconds: f64,
}

impl Observations {
    /// Vertices some view sees.
    pub fn seen(&self) -> usize {
        self.colour.iter().filter(|c| c.is_some()).count()
    }

    /// The shading of a white surface at vertex `i` under `lighting`.
    pub fn shading(&self, i: usize, lighting: &LatLong) -> [f32; 3] {
        let mut out = [0.0f32; 3];
        for (t, l) in self.transport[i].iter().zip(lighting.texels()) {
            for ch in 0..3 {
                out[ch] += t * l[ch];
            }
        }
        out
    }
}

/// Observes every vertex of `mesh` in `capture`'s photographs (see
/// [`Observations`]). `offset_m` moves shadow-ray origins off the surface (about
/// the mesh's spacing).
pub fn observe(
    mesh: &Mesh,
    capture: &LoadedCapture,
    settings: &ReflectanceSettings,
    offset_m: f32,
) -> Result<Observations> {
    let start = Instant::now();
    let white = Mesh {
        albedo: Albedo::Uniform([1.0; 3]),
        ..mesh.clone()
    };
    let trace = TraceSettings {
        bounces: settings.bounces,
        texel_samples: settings.texel_samples.max(1),
        indirect_samples: settings.indirect_samples,
        seed: settings.seed,
        ..TraceSettings::default()
    };
    let tracer = LtTracer::new(&white, trace).context("tracing the reconstructed surface")?;
    let normals = mesh.vertex_normals();
    let (colour, transport): (Vec<Option<[f32; 3]>>, Vec<Vec<f32>>) = (0..mesh.positions.len())
        .into_par_iter()
        .map(|i| {
            let (x, n) = (mesh.positions[i], normals[i]);
            if n == Vec3::ZERO {
                return (None, Vec::new());
            }
            let (sum, total) = seen_colour(&tracer, capture, x, n, offset_m, settings.highlight_tolerance);
            if total <= 0.0 {
                // No view sees it: its shading would go unused.
                return (None, Vec::new());
            }
            let sp = nelf_scene::tracer::SurfacePoint {
                position: x + n * offset_m,
                geometric_normal: n,
                shading_normal: n,
                albedo: [1.0; 3],
            };
            let mut rng = tracer.rng(i as u64);
            let mut lt = [0.0f32; LT_DIM];
            tracer.light_transport_averaged(&sp, &[], &mut rng, &mut lt);
            (Some(sum.map(|s| (s / total) as f32)), lt[..ENV_TEXELS].to_vec())
        })
        .unzip();
    if colour.iter().all(Option::is_none) {
        return Err(invalid(format!(
            "{}: no view sees the reconstructed surface (do the masks and cameras agree?)",
            capture.camera_file.display()
        )));
    }
    Ok(Observations {
        colour,
        transport,
        seconds: start.elapsed().as_secs_f64(),
    })
}

/// The diffuse albedo of every vertex of `mesh` from `capture`'s photographs under
/// `lighting` (an 8 × 16 map in the world frame, the photographs' units): [`observe`]
/// then [`albedo_from_observations`].
pub fn estimate_reflectance(
    mesh: &Mesh,
    capture: &LoadedCapture,
    lighting: &LatLong,
    settings: &ReflectanceSettings,
    offset_m: f32,
) -> Result<(Vec<[f32; 3]>, ReflectanceReport)> {
    let observations = observe(mesh, capture, settings, offset_m)?;
    albedo_from_observations(&observations, &mesh.triangles, lighting, settings)
}

/// The albedo of every vertex: its observed colour divided by its shading under
/// `lighting`, unseen vertices filled from their neighbours (see the module
/// documentation). `triangles` are the surface's.
pub fn albedo_from_observations(
    observations: &Observations,
    triangles: &[[u32; 3]],
    lighting: &LatLong,
    settings: &ReflectanceSettings,
) -> Result<(Vec<[f32; 3]>, ReflectanceReport)> {
    let start = Instant::now();
    if lighting.texels().len() * 3 != LT_DIM {
        return Err(invalid(format!(
            "the reflectance stage needs the lighting as an 8 × 16 map, not {} × {}",
            lighting.width(),
            lighting.height()
        )));
    }
    let per_vertex: Vec<(Option<[f32; 3]>, [f32; 3])> = observations
        .colour
        .iter()
        .enumerate()
        .map(|(i, c)| (*c, c.map_or([0.0; 3], |_| observations.shading(i, lighting))))
        .collect();
    let mut shading_lum: Vec<f32> = per_vertex
        .iter()
        .filter(|(c, _)| c.is_some())
        .map(|(_, s)| (s[0] + s[1] + s[2]) / 3.0)
        .collect();
    if shading_lum.is_empty() {
        return Err(invalid("no view sees the reconstructed surface".to_string()));
    }
    let mid = shading_lum.len() / 2;
    let (_, median, _) = shading_lum.select_nth_unstable_by(mid, f32::total_cmp);
    let floor = (0.02 * *median).max(1e-12);
    let raw: Vec<Option<[f32; 3]>> = per_vertex
        .iter()
        .map(|(colour, s)| colour.map(|c| std::array::from_fn(|ch| (c[ch] / s[ch].max(floor)).max(0.0))))
        .collect();
    let albedo_gain = match settings.normalise_to {
        Some(target) => {
            let mut brightest: Vec<f32> = raw.iter().flatten().map(|a| a[0].max(a[1]).max(a[2])).collect();
            let k = (brightest.len() * 98 / 100).min(brightest.len() - 1);
            let (_, p98, _) = brightest.select_nth_unstable_by(k, f32::total_cmp);
            if *p98 > 0.0 { target / *p98 } else { 1.0 }
        }
        None => 1.0,
    };
    let mut clamped = 0;
    let mut albedo: Vec<Option<[f32; 3]>> = raw
        .iter()
        .map(|a| {
            a.map(|a| {
                let a = a.map(|v| v * albedo_gain);
                if a.iter().any(|&v| v > 1.0) {
                    clamped += 1;
                }
                a.map(|v| v.min(1.0))
            })
        })
        .collect();
    let seen = albedo.iter().filter(|a| a.is_some()).count();
    let mut mean = [0.0f64; 3];
    for a in albedo.iter().flatten() {
        for ch in 0..3 {
            mean[ch] += f64::from(a[ch]) / seen as f64;
        }
    }
    let mean = mean.map(|m| m as f32);
    let filled = fill_from_neighbours(&mut albedo, triangles);
    let defaulted = albedo.iter().filter(|a| a.is_none()).count();
    let albedo = albedo.into_iter().map(|a| a.unwrap_or(mean)).collect();
    let report = ReflectanceReport {
        seen_vertices: seen,
        filled_vertices: filled,
        defaulted_vertices: defaulted,
        clamped_vertices: clamped,
        albedo_gain,
        mean_albedo: mean,
        seconds: observations.seconds + start.elapsed().as_secs_f64(),
    };
    Ok((albedo, report))
}

/// Gives every unknown vertex that borders known ones their mean, in rounds, until
/// no round adds any; returns how many were filled.
fn fill_from_neighbours(values: &mut [Option<[f32; 3]>], triangles: &[[u32; 3]]) -> usize {
    let n = values.len();
    let neighbours = vertex_neighbours(n, triangles);
    let mut filled = 0;
    loop {
        let updates: Vec<(usize, [f32; 3])> = (0..n)
            .filter(|&i| values[i].is_none())
            .filter_map(|i| {
                let known: Vec<[f32; 3]> = neighbours[i].iter().filter_map(|&j| values[j as usize]).collect();
                (!known.is_empty()).then(|| {
                    let k = known.len() as f32;
                    (
                        i,
                        std::array::from_fn(|ch| known.iter().map(|a| a[ch]).sum::<f32>() / k),
                    )
                })
            })
            .collect();
        if updates.is_empty() {
            return filled;
        }
        filled += updates.len();
        for (i, a) in updates {
            values[i] = Some(a);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::photo::geometry::tests::sphere_capture;
    use crate::photo::geometry::{SurfaceSettings, hull_surface};

    #[test]
    fn a_grey_convex_object_under_uniform_light_gets_its_albedo_back() {
        // Photographs of a Lambertian albedo 0.4 under uniform radiance 1: every
        // pixel reads 0.4, the shading of a white convex surface is 1.
        let mut capture = sphere_capture(0.1);
        for image in &mut capture.images {
            for p in image.iter_mut() {
                *p = p.map(|v| 0.4 * v);
            }
        }
        let settings = SurfaceSettings {
            spacing_m: 0.005,
            smoothing_iterations: 5,
            blur_m: 0.0,
            max_radius_m: 0.5,
            stereo: None,
        };
        let (mesh, _) = hull_surface(&capture, &settings, None).expect("a hull");
        let light = LatLong::constant(16, 8, [1.0; 3]);
        let (albedo, report) =
            estimate_reflectance(&mesh, &capture, &light, &ReflectanceSettings::default(), 0.005)
                .expect("albedo");
        assert_eq!(report.defaulted_vertices, 0);
        assert!(report.seen_vertices > mesh.positions.len() * 9 / 10, "{report:?}");
        let mean = albedo.iter().map(|a| f64::from(a[1])).sum::<f64>() / albedo.len() as f64;
        assert!((mean - 0.4).abs() < 0.03, "mean albedo {mean}");
        // Unknown lighting scale: the brightest albedos are put at the target.
        let normalised = ReflectanceSettings {
            normalise_to: Some(0.8),
            ..ReflectanceSettings::default()
        };
        let (scaled, report) =
            estimate_reflectance(&mesh, &capture, &light, &normalised, 0.005).expect("albedo");
        let p98 = {
            let mut g: Vec<f32> = scaled.iter().map(|a| a[1]).collect();
            g.sort_by(f32::total_cmp);
            g[g.len() * 98 / 100]
        };
        assert!(
            (p98 - 0.8).abs() < 0.02,
            "98th percentile {p98}, gain {}",
            report.albedo_gain
        );
        // The lighting must be the 8 × 16 basis.
        let wrong = LatLong::constant(32, 16, [1.0; 3]);
        assert!(
            estimate_reflectance(&mesh, &capture, &wrong, &ReflectanceSettings::default(), 0.005).is_err()
        );
    }

    #[test]
    fn a_highlight_in_one_view_is_left_out_where_three_views_see_the_point() {
        // Five views in a 35° cone of a sphere showing albedo 0.4 under uniform
        // light; the first view (along +z) reads twice that about the centre.
        let eyes: Vec<glam::DVec3> = [(0.0, 0.0), (0.6, 0.2), (-0.6, 0.2), (0.2, 0.6), (-0.2, -0.6)]
            .iter()
            .map(|&(x, y)| glam::DVec3::new(x, y, 1.0).normalize())
            .collect();
        let mut capture = crate::photo::geometry::tests::sphere_views(0.1, &eyes, 64, 0.3, |_| [0.4; 3]);
        for (i, p) in capture.images[0].iter_mut().enumerate() {
            let (x, y) = ((i % 64) as f64 - 31.5, (i / 64) as f64 - 31.5);
            if x * x + y * y < 25.0 {
                *p = p.map(|v| 2.0 * v);
            }
        }
        let settings = SurfaceSettings {
            spacing_m: 0.004,
            smoothing_iterations: 5,
            blur_m: 0.0,
            max_radius_m: 0.5,
            stereo: None,
        };
        let (mesh, _) = hull_surface(&capture, &settings, None).expect("a hull");
        let light = LatLong::constant(16, 8, [1.0; 3]);
        let front = |settings: &ReflectanceSettings| {
            let (albedo, _) = estimate_reflectance(&mesh, &capture, &light, settings, 0.004).expect("albedo");
            // The vertices nearest the +z axis, in front.
            albedo
                .iter()
                .zip(&mesh.positions)
                .filter(|(_, p)| p.z > 0.0 && p.x.hypot(p.y) < 0.004)
                .map(|(a, _)| a[1])
                .fold(0.0f32, f32::max)
        };
        let kept = front(&ReflectanceSettings::default());
        let all_views = front(&ReflectanceSettings {
            highlight_tolerance: None,
            ..ReflectanceSettings::default()
        });
        assert!(
            (kept - 0.4).abs() < 0.03 && all_views > 0.45,
            "front albedo {kept} (every view: {all_views})"
        );
    }
}
