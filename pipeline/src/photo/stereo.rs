//! Multi-view stereo inside the visual hull: per-view depth maps by a plane sweep
//! along each pixel's ray, scored by normalised cross-correlation of image patches
//! against the other views (the views share one lighting, so a Lambertian surface
//! looks alike in all of them), fused into a truncated signed distance (Curless &
//! Levoy 1996) that carves the hull where the photographs show the surface lies
//! deeper.
//!
//! **Depth maps.** For each foreground pixel of view `r` whose 5 × 5 neighbourhood
//! is all foreground, the ray enters the hull's mesh at `t₀`; depths `t₀ + k·step`
//! up to `max_depth` behind it are tried, every second one first, then the two
//! beside the best. At each, the 25 pixels' rays are cut at the same `t` (a
//! fronto-parallel patch; the views are narrow), projected into every other view
//! and sampled bilinearly. The score of a depth is the mean of the two best NCCs
//! (RGB, each channel's mean removed, over 75 values) among those views; the pixel
//! keeps the best depth when its score reaches [`StereoSettings::min_ncc`].
//!
//! **Cleaning.** A depth stays only when another view's depth map puts the surface
//! within two steps of the same point (geometric consistency). Foreground pixels
//! within two pixels of the silhouette get no depth: the view does not vote there
//! (the hull's depth, tried first, lies 5–16 mm in front of the surface there on
//! average, measured against the truth, and kept the hull's bulge standing). The
//! other foreground pixels left without a depth take their neighbours'
//! (repeatedly), and the map is median-filtered. [`DepthMap::origin`] says which
//! pixel got its depth how.
//!
//! **Fusion.** A grid point `x` seen by view `v` at pixel `p` with a depth `D_v(p)`
//! gets `s_v = D_v(p) − t_v(x)` (positive in front of the surface, `t_v` the
//! distance along the pixel's ray), kept when `s_v > −τ` and clamped to `τ`. The
//! fused distance is the mean of the kept `s_v` (positive outside, as the mesher
//! wants); points no view has a depth for keep the hull's distance, and every point
//! takes the larger (more outside) of the two, so silhouettes stay exactly the
//! masks'.
//!
//! Measured in `docs/measurements/2026-12-06-photographs.md`.

use glam::{DVec2, DVec3};
use nelf_bake::LoadedCapture;
use nelf_scene::bvh::Bvh;
use nelf_scene::mesh::Mesh;
use rayon::prelude::*;
use serde::Serialize;

use crate::photo::pixels::bilinear_rgb;

/// Stereo settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StereoSettings {
    /// Deepest depth behind the hull tried, metres.
    pub max_depth_m: f64,
    /// Step between tried depths, metres.
    pub step_m: f64,
    /// Least score a depth needs to be kept.
    pub min_ncc: f64,
    /// Truncation of the fused distance, metres.
    pub truncation_m: f64,
    /// Half-width of the depth maps' median filter, pixels.
    pub median_radius: i64,
    /// Give foreground pixels without a confirmed depth their neighbours' (else
    /// they stay unknown and the view does not vote there).
    pub fill: bool,
}

impl Default for StereoSettings {
    fn default() -> Self {
        Self {
            max_depth_m: 0.08,
            step_m: 0.001,
            min_ncc: 0.7,
            truncation_m: 0.008,
            median_radius: 7,
            fill: true,
        }
    }
}

/// One view's depth map: distance along each pixel's ray (NaN where unknown).
#[derive(Debug, Clone)]
pub struct DepthMap {
    /// Row-major distances, metres.
    pub depth_m: Vec<f32>,
    /// Where each pixel's depth came from.
    pub origin: Vec<DepthOrigin>,
}

/// Where a depth-map pixel's depth came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DepthOrigin {
    /// No depth (background, or within two pixels of the silhouette).
    None,
    /// Stereo, confirmed by another view.
    Stereo,
    /// Filled from its neighbours.
    Filled,
}

/// What the stereo stage found.
#[derive(Debug, Clone, Serialize)]
pub struct StereoReport {
    /// Pixels with a depth, per view.
    pub pixels_with_depth: Vec<usize>,
    /// Pixels whose depth another view confirms, per view.
    pub consistent_pixels: Vec<usize>,
    /// Foreground pixels tried, per view.
    pub pixels_tried: Vec<usize>,
    /// Mean depth behind the hull of the kept pixels, millimetres.
    pub mean_behind_hull_mm: f64,
}

const HALF: i64 = 2;

fn ncc(a: &[[f32; 3]], b: &[[f32; 3]]) -> f64 {
    let n = a.len() as f64;
    let mut total = (0.0, 0.0, 0.0);
    for c in 0..3 {
        let ma = a.iter().map(|p| f64::from(p[c])).sum::<f64>() / n;
        let mb = b.iter().map(|p| f64::from(p[c])).sum::<f64>() / n;
        for (p, q) in a.iter().zip(b) {
            let (x, y) = (f64::from(p[c]) - ma, f64::from(q[c]) - mb);
            total.0 += x * y;
            total.1 += x * x;
            total.2 += y * y;
        }
    }
    let denom = (total.1 * total.2).sqrt();
    if denom > 1e-12 { total.0 / denom } else { 0.0 }
}

/// Depth maps of every view of `capture`, starting where each ray enters `hull`.
pub fn depth_maps(
    capture: &LoadedCapture,
    hull: &Mesh,
    settings: &StereoSettings,
) -> (Vec<DepthMap>, StereoReport) {
    let bvh = Bvh::new(&hull.positions, &hull.triangles);
    let steps = (settings.max_depth_m / settings.step_m).round().max(1.0) as usize;
    let mut raw: Vec<Vec<(f32, Option<f64>)>> = Vec::new();
    let mut with_depth = Vec::new();
    let mut tried = Vec::new();
    let mut behind = (0.0f64, 0usize);
    for (r, camera) in capture.cameras.iter().enumerate() {
        let (w, h) = (camera.width as usize, camera.height as usize);
        let mask = &capture.masks[r];
        let image = &capture.images[r];
        let centre = camera.centre();
        let results: Vec<(f32, Option<f64>)> = (0..w * h)
            .into_par_iter()
            .map(|i| {
                let (x, y) = ((i % w) as i64, (i / w) as i64);
                let all_fg = (-HALF..=HALF).all(|dy| {
                    (-HALF..=HALF).all(|dx| {
                        let (u, v) = (x + dx, y + dy);
                        u >= 0
                            && v >= 0
                            && (u as usize) < w
                            && (v as usize) < h
                            && mask[v as usize * w + u as usize] >= 0.5
                    })
                });
                if mask[i] < 0.5 {
                    return (f32::NAN, None);
                }
                let dir = camera.ray_direction(DVec2::new(x as f64 + 0.5, y as f64 + 0.5));
                let Some(hit) = bvh.closest_hit(centre.as_vec3(), dir.as_vec3(), 0.0, f32::INFINITY) else {
                    return (f32::NAN, None);
                };
                if !all_fg {
                    // Within two pixels of the silhouette: no whole patch. The hull's
                    // depth there lies 5–16 mm in front of the surface (measured), so
                    // the pixel is left without one.
                    return (f32::NAN, None);
                }
                let t0 = f64::from(hit.t);
                let mut reference = Vec::with_capacity(25);
                let mut rays = Vec::with_capacity(25);
                for dy in -HALF..=HALF {
                    for dx in -HALF..=HALF {
                        let (u, v) = ((x + dx) as usize, (y + dy) as usize);
                        reference.push(image[v * w + u]);
                        rays.push(camera.ray_direction(DVec2::new(u as f64 + 0.5, v as f64 + 0.5)));
                    }
                }
                let mut sample = Vec::with_capacity(25);
                let mut score_at = |t: f64| -> f64 {
                    let mut scores: Vec<f64> = Vec::with_capacity(capture.len());
                    for (n, other) in capture.cameras.iter().enumerate() {
                        if n == r {
                            continue;
                        }
                        let (ow, oh) = (other.width as usize, other.height as usize);
                        sample.clear();
                        for ray in &rays {
                            let p = centre + *ray * t;
                            let Some(px) = other.project(p) else { break };
                            let Some(c) = bilinear_rgb(&capture.images[n], ow, oh, px) else {
                                break;
                            };
                            sample.push(c);
                        }
                        if sample.len() == rays.len() {
                            scores.push(ncc(&reference, &sample));
                        }
                    }
                    if scores.len() < 2 {
                        return f64::NEG_INFINITY;
                    }
                    scores.sort_by(|a, b| b.total_cmp(a));
                    0.5 * (scores[0] + scores[1])
                };
                // Coarse sweep at twice the step, then the step around the best.
                let mut best = (f64::NEG_INFINITY, t0);
                for k in (0..=steps).step_by(2) {
                    let t = t0 + k as f64 * settings.step_m;
                    let score = score_at(t);
                    if score > best.0 {
                        best = (score, t);
                    }
                }
                let coarse = best.1;
                for t in [coarse - settings.step_m, coarse + settings.step_m] {
                    let score = score_at(t);
                    if t >= t0 && score > best.0 {
                        best = (score, t);
                    }
                }
                if best.0 >= settings.min_ncc {
                    (best.1 as f32, Some(best.1 - t0))
                } else {
                    (f32::NAN, Some(f64::NAN))
                }
            })
            .collect();
        tried.push(results.iter().filter(|(_, b)| b.is_some()).count());
        with_depth.push(results.iter().filter(|(d, _)| d.is_finite()).count());
        for (_, b) in &results {
            if let Some(b) = b
                && b.is_finite()
            {
                behind.0 += b;
                behind.1 += 1;
            }
        }
        raw.push(results);
    }
    // Geometric consistency: a stereo depth stays only when another view's depth map
    // puts the surface within `2·step` of the same point.
    let consistent: Vec<Vec<bool>> = (0..capture.len())
        .map(|r| {
            let camera = &capture.cameras[r];
            let w = camera.width as usize;
            raw[r]
                .par_iter()
                .enumerate()
                .map(|(i, (d, _))| {
                    if !d.is_finite() {
                        return false;
                    }
                    let dir = camera.ray_direction(DVec2::new((i % w) as f64 + 0.5, (i / w) as f64 + 0.5));
                    let p = camera.centre() + dir * f64::from(*d);
                    capture.cameras.iter().enumerate().any(|(n, other)| {
                        if n == r {
                            return false;
                        }
                        let Some(q) = other.project(p) else { return false };
                        let (ow, oh) = (other.width as i64, other.height as i64);
                        let (u, v) = (q.x.floor() as i64, q.y.floor() as i64);
                        if u < 0 || v < 0 || u >= ow || v >= oh {
                            return false;
                        }
                        let dn = raw[n][(v * ow + u) as usize].0;
                        dn.is_finite()
                            && (f64::from(dn) - (p - other.centre()).length()).abs() < 2.0 * settings.step_m
                    })
                })
                .collect()
        })
        .collect();
    let mut maps = Vec::new();
    for (r, camera) in capture.cameras.iter().enumerate() {
        let (w, h) = (camera.width as usize, camera.height as usize);
        let mask = &capture.masks[r];
        let results = &raw[r];
        // Foreground pixels stereo left without a depth take their neighbours' (an
        // unknown one would leave the hull standing in front of the surface there);
        // pixels within two of the silhouette have none: the view does not vote there.
        let mut depth: Vec<f32> = results
            .iter()
            .enumerate()
            .map(|(i, (d, _))| {
                if d.is_finite() && consistent[r][i] {
                    *d
                } else {
                    f32::NAN
                }
            })
            .collect();
        let mut origin: Vec<DepthOrigin> = depth
            .iter()
            .map(|d| {
                if d.is_finite() {
                    DepthOrigin::Stereo
                } else {
                    DepthOrigin::None
                }
            })
            .collect();
        let mut unknown: Vec<usize> = (0..w * h)
            .filter(|&i| mask[i] >= 0.5 && !depth[i].is_finite() && results[i].1.is_some())
            .collect();
        if !settings.fill {
            unknown.clear();
        }
        while !unknown.is_empty() {
            let updates: Vec<(usize, f32)> = unknown
                .iter()
                .filter_map(|&i| {
                    let (x, y) = (i % w, i / w);
                    let mut sum = 0.0f32;
                    let mut n = 0;
                    for (dx, dy) in [(-1i64, 0i64), (1, 0), (0, -1), (0, 1)] {
                        let (u, v) = (x as i64 + dx, y as i64 + dy);
                        if u >= 0 && v >= 0 && (u as usize) < w && (v as usize) < h {
                            let d = depth[v as usize * w + u as usize];
                            if d.is_finite() {
                                sum += d;
                                n += 1;
                            }
                        }
                    }
                    (n > 0).then(|| (i, sum / n as f32))
                })
                .collect();
            if updates.is_empty() {
                break;
            }
            for (i, d) in &updates {
                depth[*i] = *d;
                origin[*i] = DepthOrigin::Filled;
            }
            unknown.retain(|&i| !depth[i].is_finite());
        }
        maps.push(DepthMap {
            depth_m: median_filtered(&depth, w, h, settings.median_radius),
            origin,
        });
    }
    let report = StereoReport {
        consistent_pixels: consistent
            .iter()
            .map(|c| c.iter().filter(|&&k| k).count())
            .collect(),
        pixels_with_depth: with_depth,
        pixels_tried: tried,
        mean_behind_hull_mm: 1e3 * behind.0 / behind.1.max(1) as f64,
    };
    (maps, report)
}

/// Median of the known depths over a `(2r+1)²` window (a pixel stays unknown when it was).
fn median_filtered(depth: &[f32], w: usize, h: usize, r: i64) -> Vec<f32> {
    (0..w * h)
        .map(|i| {
            if !depth[i].is_finite() {
                return f32::NAN;
            }
            let (x, y) = ((i % w) as i64, (i / w) as i64);
            let mut known: Vec<f32> = Vec::with_capacity(((2 * r + 1) * (2 * r + 1)) as usize);
            for dy in -r..=r {
                for dx in -r..=r {
                    let (u, v) = (x + dx, y + dy);
                    if u >= 0 && v >= 0 && (u as usize) < w && (v as usize) < h {
                        let d = depth[v as usize * w + u as usize];
                        if d.is_finite() {
                            known.push(d);
                        }
                    }
                }
            }
            known.sort_by(f32::total_cmp);
            known[known.len() / 2]
        })
        .collect()
}

/// The fused signed distance at `x` (negative inside), or `None` where no view has
/// a depth near it.
pub fn fused_distance(
    capture: &LoadedCapture,
    maps: &[DepthMap],
    x: DVec3,
    truncation_m: f64,
) -> Option<f64> {
    let mut sum = 0.0;
    let mut count = 0usize;
    for (v, camera) in capture.cameras.iter().enumerate() {
        let Some(px) = camera.project(x) else { continue };
        let (w, h) = (camera.width as i64, camera.height as i64);
        let (u, y) = (px.x.floor() as i64, px.y.floor() as i64);
        if u < 0 || y < 0 || u >= w || y >= h {
            continue;
        }
        let d = maps[v].depth_m[(y * w + u) as usize];
        if !d.is_finite() {
            continue;
        }
        let t = (x - camera.centre()).length();
        let s = f64::from(d) - t;
        if s > -truncation_m {
            sum += s.min(truncation_m);
            count += 1;
        }
    }
    (count > 0).then(|| sum / count as f64)
}
