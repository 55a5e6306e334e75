//! Geometry from photographs: the surface of the masks' visual hull (Laurentini
//! 1994), carved where multi-view stereo finds the surface deeper
//! ([`crate::photo::stereo`]), as a smooth triangle mesh.
//!
//! The signed distance to the hull ([`nelf_bake::HullDistance`]: per view, the
//! exact Euclidean distance transform of the mask at unit depth, scaled by the
//! point's depth; the maximum over views) is sampled on a regular grid over the
//! hull's box ([`nelf_bake::hull::hull_bounds`], grown by two cells), with the
//! grid's faces forced outside so that the surface closes where the views leave the
//! hull open (behind the head, below the neck). Its zero level becomes a mesh by
//! surface nets ([`nelf_scene::surface_nets`]), smoothed by Taubin's λ|μ steps so
//! that the cones' ridges and the grid's staircase do not show in the normals.

use std::time::Instant;

use glam::DVec3;
use nelf_bake::hull::{HullCarver, hull_bounds};
use nelf_bake::{HullDistance, LoadedCapture};
use nelf_scene::field::FieldSource;
use nelf_scene::mesh::{Albedo, Mesh};
use nelf_scene::surface_nets::{GridSamples, surface_net, taubin_smooth};
use rayon::prelude::*;
use serde::Serialize;

use crate::error::{Context as _, Result, invalid};
use crate::photo::stereo::{StereoReport, StereoSettings, depth_maps, fused_distance};

/// Most grid samples the hull is sampled at (about 0.4 GB of `f32`).
const MAX_SAMPLES: usize = 100_000_000;

/// How the hull's surface is made.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SurfaceSettings {
    /// Grid spacing, metres.
    pub spacing_m: f64,
    /// Taubin λ|μ smoothing iterations.
    pub smoothing_iterations: usize,
    /// Standard deviation of the Gaussian the stereo-carved signed distance is
    /// blurred with before meshing, metres (0: none).
    pub blur_m: f64,
    /// Largest distance of the hull from the capture's head centre, metres (where
    /// the views leave the hull unbounded).
    pub max_radius_m: f64,
    /// Carve the hull by multi-view stereo ([`crate::photo::stereo`]); `None`: the hull.
    pub stereo: Option<StereoSettings>,
}

/// What the geometry stage made.
#[derive(Debug, Clone, Serialize)]
pub struct SurfaceReport {
    /// The hull's box, metres.
    pub box_m: [[f64; 3]; 2],
    /// Grid samples per axis.
    pub grid: [usize; 3],
    /// Vertices and triangles of the mesh.
    pub vertices: usize,
    /// Triangles of the mesh.
    pub triangles: usize,
    /// The stereo stage, when it ran.
    pub stereo: Option<StereoReport>,
    /// Density evaluations (coarse to fine inside the hull; 0: no density).
    pub density_points: usize,
    /// How the hull was refined (what the settings and the density asked for).
    pub geometry: crate::config::PhotoGeometry,
    /// Why it was not refined as asked, when it was not.
    pub note: Option<String>,
    /// Seconds: sampling the distance, meshing and smoothing.
    pub seconds: f64,
}

/// A density field whose surface refines the hull ([`hull_surface`]): the solid is
/// where `σ ≥ level_per_m` (the NeLF network's density, `--photo-geometry network`).
pub struct DensitySurface<'a> {
    /// The field (only [`FieldSource::evaluate_density`] is called).
    pub field: &'a dyn FieldSource,
    /// The density at the surface, per metre.
    pub level_per_m: f32,
}

impl std::fmt::Debug for DensitySurface<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("DensitySurface")
            .field("level_per_m", &self.level_per_m)
            .finish_non_exhaustive()
    }
}

/// The visual hull of `capture`'s masks as a closed mesh (albedo a uniform grey, to
/// be replaced by the reflectance stage), intersected with the solid of `density`
/// when given and carved by stereo when `settings.stereo` asks (with a density, only
/// where a second view confirms a depth).
pub fn hull_surface(
    capture: &LoadedCapture,
    settings: &SurfaceSettings,
    density: Option<&DensitySurface<'_>>,
) -> Result<(Mesh, SurfaceReport)> {
    let start = Instant::now();
    if !(settings.spacing_m.is_finite() && settings.spacing_m > 0.0) {
        return Err(invalid(format!(
            "the surface's grid spacing {} m must be positive",
            settings.spacing_m
        )));
    }
    let carver = HullCarver::new(&capture.cameras, &capture.masks, 0)?;
    let (lo, hi) = hull_bounds(&carver, capture.head_centre_m, settings.max_radius_m)
        .context("bounding the masks' visual hull")?;
    let distance = HullDistance::new(&capture.cameras, &capture.masks, 0.0)?;
    let h = settings.spacing_m;
    let origin = lo - DVec3::splat(2.0 * h);
    let extent = hi - lo + DVec3::splat(4.0 * h);
    let dims = extent.to_array().map(|e| (e / h).ceil() as usize + 1);
    let count = dims.iter().product::<usize>();
    if count > MAX_SAMPLES {
        return Err(invalid(format!(
            "the hull's box {:.3} × {:.3} × {:.3} m at {:.2} mm needs {count} samples (at most {MAX_SAMPLES}): use a coarser spacing",
            extent.x,
            extent.y,
            extent.z,
            h * 1e3
        )));
    }
    let point = |i: usize| {
        let [nx, ny, _] = dims;
        origin + DVec3::new((i % nx) as f64, ((i / nx) % ny) as f64, (i / (nx * ny)) as f64) * h
    };
    let values_of = |field: &(dyn Fn(DVec3) -> f64 + Sync)| {
        let [nx, ny, nz] = dims;
        let mut values = vec![0.0f32; count];
        values.par_chunks_mut(nx * ny).enumerate().for_each(|(z, slab)| {
            for y in 0..ny {
                for x in 0..nx {
                    let face = x == 0 || y == 0 || z == 0 || x + 1 == nx || y + 1 == ny || z + 1 == nz;
                    let d = field(origin + DVec3::new(x as f64, y as f64, z as f64) * h);
                    slab[y * nx + x] = if face {
                        h as f32
                    } else if d == f64::NEG_INFINITY {
                        -(h as f32)
                    } else {
                        d as f32
                    };
                }
            }
        });
        values
    };
    let mesh_of = |mut values: Vec<f32>, blur_cells: f64| {
        if blur_cells > 0.0 {
            gaussian_blur(&mut values, dims, blur_cells);
        }
        surface_net(&GridSamples {
            values: &values,
            dims,
            origin_m: origin,
            spacing_m: h,
        })
    };
    let empty = || {
        invalid(format!(
            "{}: the masks' visual hull is empty (do the masks and cameras agree?)",
            capture.camera_file.display()
        ))
    };
    let hull_values = values_of(&|p| distance.distance_m(p));
    let mut net = mesh_of(hull_values.clone(), 0.0);
    if net.triangles.is_empty() {
        return Err(empty());
    }
    let mut stereo_report = None;
    let mut density_points = 0;
    // max(hull, density band): the hull's solid intersected with the field's, the
    // field's term `h·(level − σ)/level` clamped to one cell either side so that the
    // blur treats it like a truncated distance.
    let band_values = match density {
        Some(surface) => {
            let (values, evaluated) = density_band(surface, &hull_values, dims, &point, h)?;
            density_points = evaluated;
            Some(values)
        }
        None => None,
    };
    let refined = if let Some(stereo) = &settings.stereo {
        let hull_mesh = Mesh {
            positions: net.positions.clone(),
            triangles: net.triangles.clone(),
            albedo: Albedo::Uniform([0.5; 3]),
        };
        // With a density to fall back on, only the depths a second view confirms
        // vote; the rest is the density's.
        let stereo = StereoSettings {
            fill: band_values.is_none(),
            ..*stereo
        };
        let (maps, report) = depth_maps(capture, &hull_mesh, &stereo);
        stereo_report = Some(report);
        let tau = stereo.truncation_m;
        let fused = values_of(&|p| {
            fused_distance(capture, &maps, p, tau).map_or(f64::NAN, |fused| distance.distance_m(p).max(fused))
        });
        let fallback = band_values.as_ref().unwrap_or(&hull_values);
        Some(
            fused
                .iter()
                .zip(fallback)
                .map(|(v, f)| if v.is_nan() { *f } else { *v })
                .collect(),
        )
    } else {
        band_values
    };
    let mut note = None;
    if let Some(values) = refined {
        let refined_net = mesh_of(values, settings.blur_m / h);
        if !refined_net.triangles.is_empty() {
            net = refined_net;
        } else if density.is_some() {
            // The density is low everywhere inside the hull (views that disagree,
            // poses off by degrees): the hull, reported, rather than nothing.
            note = Some(
                "the density left nothing inside the masks' visual hull (do the poses and masks agree?): the hull as it is"
                    .to_string(),
            );
        } else {
            return Err(empty());
        }
    }
    let mut positions = net.positions;
    taubin_smooth(&mut positions, &net.triangles, settings.smoothing_iterations);
    let mesh = Mesh {
        positions,
        triangles: net.triangles,
        albedo: Albedo::Uniform([0.5; 3]),
    };
    mesh.validate().context("the hull's mesh")?;
    let report = SurfaceReport {
        box_m: [lo.to_array(), hi.to_array()],
        grid: dims,
        vertices: mesh.positions.len(),
        triangles: mesh.triangles.len(),
        stereo: stereo_report,
        density_points,
        geometry: if settings.stereo.is_some() && density.is_some() {
            crate::config::PhotoGeometry::Fused
        } else if settings.stereo.is_some() {
            crate::config::PhotoGeometry::Stereo
        } else if density.is_some() {
            crate::config::PhotoGeometry::Network
        } else {
            crate::config::PhotoGeometry::Hull
        },
        note,
        seconds: start.elapsed().as_secs_f64(),
    };
    Ok((mesh, report))
}

/// `max(hull, band)` over the grid, the density's band term `h·(level − σ)/level`
/// clamped to one cell either side (see [`hull_surface`]), with the density
/// evaluated coarse to fine: first at every other grid point (per axis) near or
/// inside the hull, then at the fine points of the coarse cells whose corners
/// disagree about the level (the surface passes there); elsewhere the clamped band
/// is interpolated from the corners (where they agree it is ±h, or nearly).
/// Returns the values and the number of density evaluations (about a fifth of
/// every point inside the hull on a head).
fn density_band(
    surface: &DensitySurface<'_>,
    hull_values: &[f32],
    dims: [usize; 3],
    point: &(dyn Fn(usize) -> DVec3 + Sync),
    h: f64,
) -> Result<(Vec<f32>, usize)> {
    let [nx, ny, nz] = dims;
    let index = |x: usize, y: usize, z: usize| (z * ny + y) * nx + x;
    let level = surface.level_per_m.max(f32::MIN_POSITIVE);
    let band_of = |s: f32| (h as f32 * (level - s) / level).clamp(-(h as f32), h as f32);
    let evaluate = |indices: &[usize]| -> Result<Vec<f32>> {
        let points: Vec<glam::Vec3> = indices.iter().map(|&i| point(i).as_vec3()).collect();
        let mut sigma = vec![0.0f32; points.len()];
        surface
            .field
            .evaluate_density(&points, &mut sigma)
            .map_err(|e| invalid(format!("the density of the surface: {e}")))?;
        Ok(sigma.into_iter().map(band_of).collect())
    };
    // Coarse lattice: even fine indices per axis, plus the last index.
    let coarse_axis = |n: usize| -> Vec<usize> {
        let mut v: Vec<usize> = (0..n).step_by(2).collect();
        if v.last() != Some(&(n - 1)) {
            v.push(n - 1);
        }
        v
    };
    let (cx, cy, cz) = (coarse_axis(nx), coarse_axis(ny), coarse_axis(nz));
    // Coarse points within reach of the hull's inside (a coarse cell's diagonal).
    let reach = (2.0 * 3f64.sqrt() * h) as f32;
    let mut coarse_points = Vec::new();
    for &z in &cz {
        for &y in &cy {
            for &x in &cx {
                let i = index(x, y, z);
                if hull_values[i] < reach {
                    coarse_points.push(i);
                }
            }
        }
    }
    let coarse_band = evaluate(&coarse_points)?;
    let mut coarse = vec![f32::NAN; hull_values.len()];
    for (&i, &b) in coarse_points.iter().zip(&coarse_band) {
        coarse[i] = b;
    }
    // The coarse cell of a fine coordinate: the coarse indices below and above it.
    let bracket = |axis: &[usize], v: usize| -> (usize, usize) {
        let k = axis.partition_point(|&a| a <= v).saturating_sub(1);
        let lo = axis[k];
        let hi = axis.get(k + 1).copied().unwrap_or(lo);
        (lo, hi)
    };
    let mut values = hull_values.to_vec();
    let mut fine = Vec::new();
    for z in 0..nz {
        let (z0, z1) = bracket(&cz, z);
        for y in 0..ny {
            let (y0, y1) = bracket(&cy, y);
            for x in 0..nx {
                let i = index(x, y, z);
                if hull_values[i] >= 0.0 {
                    continue;
                }
                let (x0, x1) = bracket(&cx, x);
                let corners = [
                    coarse[index(x0, y0, z0)],
                    coarse[index(x1, y0, z0)],
                    coarse[index(x0, y1, z0)],
                    coarse[index(x1, y1, z0)],
                    coarse[index(x0, y0, z1)],
                    coarse[index(x1, y0, z1)],
                    coarse[index(x0, y1, z1)],
                    coarse[index(x1, y1, z1)],
                ];
                let agree = corners.iter().all(|c| c.is_finite())
                    && (corners.iter().all(|&c| c > 0.0) || corners.iter().all(|&c| c < 0.0));
                if !agree {
                    fine.push(i);
                    continue;
                }
                let t = |v: usize, a: usize, b: usize| {
                    if b > a {
                        (v - a) as f32 / (b - a) as f32
                    } else {
                        0.0
                    }
                };
                let (tx, ty, tz) = (t(x, x0, x1), t(y, y0, y1), t(z, z0, z1));
                let lerp = |a: f32, b: f32, t: f32| a + (b - a) * t;
                let band = lerp(
                    lerp(
                        lerp(corners[0], corners[1], tx),
                        lerp(corners[2], corners[3], tx),
                        ty,
                    ),
                    lerp(
                        lerp(corners[4], corners[5], tx),
                        lerp(corners[6], corners[7], tx),
                        ty,
                    ),
                    tz,
                );
                values[i] = values[i].max(band);
            }
        }
    }
    let fine_band = evaluate(&fine)?;
    for (&i, &b) in fine.iter().zip(&fine_band) {
        values[i] = values[i].max(b);
    }
    Ok((values, coarse_points.len() + fine.len()))
}

/// Blurs a grid of `dims` samples (x fastest) in place by a Gaussian of standard
/// deviation `sigma_cells` along each axis in turn (separable); the kernel is cut
/// at three deviations and renormalised at the grid's faces.
fn gaussian_blur(values: &mut [f32], dims: [usize; 3], sigma_cells: f64) {
    let radius = (3.0 * sigma_cells).ceil() as usize;
    let kernel: Vec<f32> = (0..=radius)
        .map(|k| (-0.5 * (k as f64 / sigma_cells).powi(2)).exp() as f32)
        .collect();
    let strides = [1, dims[0], dims[0] * dims[1]];
    for axis in 0..3 {
        let (n, stride) = (dims[axis], strides[axis]);
        // Every line along `axis`: its first sample's index.
        let starts: Vec<usize> = (0..values.len()).filter(|&i| (i / stride) % n == 0).collect();
        let lines: Vec<Vec<f32>> = starts
            .par_iter()
            .map(|&start| {
                (0..n)
                    .map(|j| {
                        let (mut sum, mut weight) = (0.0f32, 0.0f32);
                        for (k, w) in kernel.iter().enumerate() {
                            for side in [j.checked_sub(k), (k > 0).then_some(j + k)] {
                                if let Some(m) = side.filter(|&m| m < n) {
                                    sum += w * values[start + m * stride];
                                    weight += w;
                                }
                            }
                        }
                        sum / weight
                    })
                    .collect()
            })
            .collect();
        for (start, line) in starts.iter().zip(lines) {
            for (j, v) in line.into_iter().enumerate() {
                values[start + j * stride] = v;
            }
        }
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use nelf_bake::capture_in::CaptureSource;
    use nelf_format::conventions::PinholeCamera;
    use std::path::PathBuf;

    /// Six views along ±x, ±y, ±z of a sphere of radius `r` at the origin, with
    /// exact masks (a pixel is foreground when its ray meets the sphere).
    pub(crate) fn sphere_capture(r: f64) -> LoadedCapture {
        let eyes = [DVec3::X, -DVec3::X, DVec3::Y, -DVec3::Y, DVec3::Z, -DVec3::Z];
        sphere_views(r, &eyes, 64, 0.3, |_| [1.0; 3])
    }

    /// Views from `eyes` (looking at the origin) of a sphere of radius `r` whose
    /// surface shows `colour(point)` (no shading), with exact masks.
    pub(crate) fn sphere_views(
        r: f64,
        eyes: &[DVec3],
        size: u32,
        fov_rad: f64,
        colour: impl Fn(DVec3) -> [f32; 3],
    ) -> LoadedCapture {
        let cameras: Vec<PinholeCamera> = eyes
            .iter()
            .map(|&e| {
                let up = if e.normalize().y.abs() > 0.9 {
                    DVec3::Z
                } else {
                    DVec3::Y
                };
                PinholeCamera::look_at(e, DVec3::ZERO, up, size, size, fov_rad)
            })
            .collect();
        let hit = |c: &PinholeCamera, i: u32| {
            let (origin, dir) = c.pixel_ray(i % size, i / size);
            let b = origin.dot(dir);
            let disc = b * b - (origin.length_squared() - r * r);
            (disc > 0.0).then(|| origin + dir * (-b - disc.sqrt()))
        };
        let masks: Vec<Vec<f32>> = cameras
            .iter()
            .map(|c| {
                (0..size * size)
                    .map(|i| if hit(c, i).is_some() { 1.0 } else { 0.0 })
                    .collect()
            })
            .collect();
        let images: Vec<Vec<[f32; 3]>> = cameras
            .iter()
            .map(|c| {
                (0..size * size)
                    .map(|i| hit(c, i).map_or([0.0; 3], &colour))
                    .collect()
            })
            .collect();
        let n = eyes.len();
        LoadedCapture {
            dir: PathBuf::from("sphere"),
            camera_file: PathBuf::from("sphere/cameras.json"),
            source: CaptureSource::Colmap {
                model_dir: PathBuf::from("sphere"),
            },
            names: (0..n).map(|i| format!("view_{i}")).collect(),
            image_files: (0..n).map(|i| PathBuf::from(format!("view_{i}.png"))).collect(),
            images,
            masks,
            cameras,
            head_centre_m: DVec3::ZERO,
            notes: Vec::new(),
        }
    }

    #[test]
    fn the_hull_of_a_sphere_seen_along_the_axes_is_a_closed_surface_around_it() {
        let r = 0.1;
        let capture = sphere_capture(r);
        let settings = SurfaceSettings {
            spacing_m: 0.005,
            smoothing_iterations: 5,
            blur_m: 0.0,
            max_radius_m: 0.5,
            stereo: None,
        };
        let (mesh, report) = hull_surface(&capture, &settings, None).expect("a hull");
        assert!(report.triangles > 1000, "{report:?}");
        // The hull holds the sphere and lies inside the three cylinders' intersection,
        // whose farthest points are at r·√(3/2); one pixel at the views' distance is
        // about 4.7 mm.
        for p in &mesh.positions {
            let d = f64::from(p.length());
            assert!(d > r - 0.008, "a vertex {d} m from the centre, inside the sphere");
            assert!(d < r * 1.5f64.sqrt() + 0.008, "a vertex {d} m from the centre");
        }
        // Closed and outward: the enclosed volume is positive, between the sphere's and
        // the tricylinder's (8 (2 − √2) r³).
        let volume: f64 = mesh
            .triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| mesh.positions[i as usize].as_dvec3());
                a.dot(b.cross(c)) / 6.0
            })
            .sum();
        let sphere = 4.0 / 3.0 * std::f64::consts::PI * r.powi(3);
        let tricylinder = 8.0 * (2.0 - 2f64.sqrt()) * r.powi(3);
        assert!(
            volume > 0.95 * sphere && volume < 1.05 * tricylinder,
            "volume {volume}"
        );
    }

    #[test]
    fn stereo_carves_the_hull_of_a_textured_sphere_seen_from_a_narrow_cone() {
        // Five views within 35° of +z, as a portrait capture has them: the hull bulges
        // in front of the sphere; the texture lets stereo find the surface.
        let r = 0.1;
        let eyes: Vec<DVec3> = [(0.0, 0.0), (0.6, 0.2), (-0.6, 0.2), (0.2, 0.6), (-0.2, -0.6)]
            .iter()
            .map(|&(x, y)| DVec3::new(x, y, 1.0).normalize())
            .collect();
        let texture = |p: DVec3| {
            let v =
                0.5 + 0.4 * ((p.x * 150.0).sin() * (p.y * 130.0).cos() + 0.3 * (p.z * 170.0).sin()) as f32;
            [v, 0.6 * v + 0.2, 1.0 - v]
        };
        let capture = sphere_views(r, &eyes, 96, 0.3, texture);
        let front_error = |mesh: &Mesh| {
            // Mean radial error over the vertices every view faces.
            let (mut sum, mut n) = (0.0f64, 0usize);
            for p in &mesh.positions {
                let p = p.as_dvec3();
                if p.z > 0.7 * r {
                    sum += (p.length() - r).abs();
                    n += 1;
                }
            }
            sum / n.max(1) as f64
        };
        let hull_settings = SurfaceSettings {
            spacing_m: 0.003,
            smoothing_iterations: 10,
            blur_m: 0.0,
            max_radius_m: 0.5,
            stereo: None,
        };
        let (hull, _) = hull_surface(&capture, &hull_settings, None).expect("a hull");
        let stereo_settings = SurfaceSettings {
            stereo: Some(StereoSettings::default()),
            blur_m: 0.003,
            ..hull_settings
        };
        let (carved, report) = hull_surface(&capture, &stereo_settings, None).expect("a carved hull");
        let (hull_error, carved_error) = (front_error(&hull), front_error(&carved));
        assert!(
            carved_error < 0.5 * hull_error,
            "front error: hull {hull_error} m, stereo {carved_error} m ({report:?})"
        );
    }

    #[test]
    fn the_blur_keeps_constants_everywhere_and_planes_away_from_the_faces() {
        let dims = [12, 10, 9];
        let count = dims.iter().product::<usize>();
        let index = |x: usize, y: usize, z: usize| (z * dims[1] + y) * dims[0] + x;
        let mut constant = vec![0.25f32; count];
        gaussian_blur(&mut constant, dims, 1.5);
        assert!(constant.iter().all(|v| (v - 0.25).abs() < 1e-6));
        // A signed distance to a tilted plane: linear, so a symmetric kernel keeps it
        // where the kernel fits inside the grid (radius ⌈3σ⌉ = 3 cells).
        let plane = |x: usize, y: usize, z: usize| 0.3 * x as f32 - 0.5 * y as f32 + 0.8 * z as f32 - 2.0;
        let mut values = vec![0.0f32; count];
        for z in 0..dims[2] {
            for y in 0..dims[1] {
                for x in 0..dims[0] {
                    values[index(x, y, z)] = plane(x, y, z);
                }
            }
        }
        gaussian_blur(&mut values, dims, 1.0);
        for z in 3..dims[2] - 3 {
            for y in 3..dims[1] - 3 {
                for x in 3..dims[0] - 3 {
                    let got = values[index(x, y, z)];
                    assert!((got - plane(x, y, z)).abs() < 1e-4, "({x}, {y}, {z}): {got}");
                }
            }
        }
        // A spike is spread out and keeps its sum (away from the faces).
        let mut spike = vec![0.0f32; count];
        spike[index(6, 5, 4)] = 1.0;
        gaussian_blur(&mut spike, dims, 1.0);
        let sum: f32 = spike.iter().sum();
        assert!(
            (sum - 1.0).abs() < 0.02 && spike[index(6, 5, 4)] < 0.1,
            "sum {sum}"
        );
    }

    /// σ = `sigma` where `z < below_z`, 0 elsewhere.
    struct Slab {
        sigma: f32,
        below_z: f32,
    }

    impl FieldSource for Slab {
        fn evaluate(
            &self,
            points: &[glam::Vec3],
            _view: &nelf_scene::field::ViewPolicy,
            density: &mut [f32],
            lt: &mut [f32],
        ) -> std::result::Result<(), nelf_scene::field::FieldError> {
            for (p, d) in points.iter().zip(density.iter_mut()) {
                *d = if p.z < self.below_z { self.sigma } else { 0.0 };
            }
            lt.fill(0.0);
            Ok(())
        }

        fn bounds(&self) -> (glam::Vec3, glam::Vec3) {
            (glam::Vec3::splat(-1.0), glam::Vec3::splat(1.0))
        }
    }

    #[test]
    fn a_density_cuts_the_hull_or_leaves_it_with_a_note() {
        let capture = sphere_capture(0.1);
        let settings = SurfaceSettings {
            spacing_m: 0.005,
            smoothing_iterations: 0,
            blur_m: 0.0,
            max_radius_m: 0.5,
            stereo: None,
        };
        // A solid below z = 0.05 m: the hull (about the sphere) is cut there.
        let slab = Slab {
            sigma: 1000.0,
            below_z: 0.05,
        };
        let density = DensitySurface {
            field: &slab,
            level_per_m: 200.0,
        };
        let (cut, report) = hull_surface(&capture, &settings, Some(&density)).expect("a cut hull");
        let top = cut
            .positions
            .iter()
            .map(|p| p.z)
            .fold(f32::NEG_INFINITY, f32::max);
        assert!((top - 0.05).abs() < 0.006, "top at {top} m");
        assert!(report.density_points > 0 && report.note.is_none(), "{report:?}");
        // A density that is nowhere above the level: the hull, with a note.
        let empty = Slab {
            sigma: 10.0,
            below_z: 1.0,
        };
        let density = DensitySurface {
            field: &empty,
            level_per_m: 200.0,
        };
        let (hull, report) = hull_surface(&capture, &settings, Some(&density)).expect("the hull");
        let top = hull
            .positions
            .iter()
            .map(|p| p.z)
            .fold(f32::NEG_INFINITY, f32::max);
        assert!(top > 0.09, "top at {top} m");
        assert!(
            report
                .note
                .as_deref()
                .is_some_and(|n| n.contains("the hull as it is")),
            "{report:?}"
        );
    }

    #[test]
    fn a_bad_spacing_and_an_empty_hull_are_errors() {
        let capture = sphere_capture(0.1);
        let bad = SurfaceSettings {
            spacing_m: 0.0,
            smoothing_iterations: 0,
            blur_m: 0.0,
            max_radius_m: 0.5,
            stereo: None,
        };
        assert!(hull_surface(&capture, &bad, None).is_err());
        let mut empty = capture;
        for m in &mut empty.masks {
            m.fill(0.0);
        }
        let settings = SurfaceSettings {
            spacing_m: 0.005,
            ..bad
        };
        assert!(hull_surface(&empty, &settings, None).is_err());
    }
}
