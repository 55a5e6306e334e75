//! Emission–absorption ray marching of a brick grid (Max 1995, "Optical models for
//! direct volume rendering"), the numerical definition the GPU shaders mirror.
//!
//! **Rays.** One ray per pixel, through the pixel centre:
//! `(o, d) = PinholeCamera::pixel_ray(u, v)` (`d` unit length, so ray parameters are
//! metres). No jitter: the image is a deterministic function of its inputs. With
//! `pixel_grid = n > 1` (supersampling, for comparisons with antialiased ground
//! truth) a pixel is the mean of `n²` such rays through a regular sub-pixel grid;
//! visibility weights always use the pixel centres.
//!
//! **Interval.** The ray is clipped against the grid box `[bbox_min, bbox_max]` (slab
//! test in `f64`; an axis with `d_a = 0` keeps the whole line if `o_a` is inside the
//! slab, else misses): `t_entry = max(t_near, 0)`, `t_exit = t_far`. A ray with
//! `t_exit ≤ t_entry` sees nothing (rgb 0, alpha 0).
//!
//! **Samples.** With step `Δ = step_voxels · voxel_size` (metres), sample `i` sits at
//! `t_i = t_entry + (i + 0.5)·Δ`, `p_i = o + t_i d` (in `f64`), for every `i ≥ 0` with
//! `t_i < t_exit` — i.e. `N = max(0, ⌈(t_exit − t_entry)/Δ − 0.5⌉)` samples, each
//! standing for a full segment of length `Δ` (the last segment is not shortened at the
//! box exit). At each sample `σ_i` and the radiance `c_i` are interpolated trilinearly
//! and separately ([`crate::grid`]: the same 8 weights, missing voxels 0, weights not
//! renormalised).
//!
//! **Compositing** (front to back, `f32`): `s_i = exp(−σ_i Δ)`, `α_i = 1 − s_i`,
//! `w_i = T_i α_i`, `rgb += w_i c_i`, `T_{i+1} = T_i s_i`, `T_0 = 1`. A sample with
//! `σ_i = 0` changes nothing (its radiance is not even interpolated). **Early
//! termination**: right after a sample leaves `T < min_transmittance` the ray stops.
//! The pixel is premultiplied over black: `rgb = Σ w_i c_i`, `alpha = 1 − T_end`. For
//! constant radiance `c` this is `c · (1 − exp(−Σ σ_i Δ))`, the discretised
//! `c (1 − e^{−∫σ})`.
//!
//! **Empty-space skipping** never changes the image. When a sample's 8 trilinear corners
//! all lie in one missing brick, the value is 0 on that brick's *core box* (the brick box
//! shrunk by half a voxel, [`BrickGrid::empty_core_box`]) — every sample in it has σ = 0
//! and contributes nothing. The marcher computes the ray's exit `t_out` from that box and
//! resumes at lattice index `max(i + 1, ⌈(t_out − t_entry)/Δ − 0.5⌉ − 1)`: samples stay on
//! the lattice `t_entry + (i + 0.5)Δ` and only samples inside the core box are skipped
//! (resuming one sample early absorbs rounding of `t_out`). The result equals marching
//! every sample with independent per-corner lookups ([`render_volume_unskipped`]), bit for
//! bit (tested). A GPU mirror may skip differently (or not at all): only the lattice and
//! the per-sample arithmetic above define the image.
//!
//! **Visibility weights** (for PCA fitting): voxel `v` of the grid receives
//! `Σ_pixels Σ_i w_i · trilinear_weight_i(v)`, i.e. the derivative of the sum of the
//! image's channels with respect to that voxel's radiance. Hence for any per-voxel
//! scalar radiance `r`, `Σ_pixels rgb_c = Σ_v weight_v · r_v` (tested).

// The API passes `&MarchSettings` (fixed, and room for more fields than fit in 8 bytes).
#![allow(clippy::trivially_copy_pass_by_ref)]

use glam::{DVec2, DVec3};
use nelf_format::Asset;
use nelf_format::conventions::{LatLong, PinholeCamera};
use rayon::prelude::*;

use crate::error::RenderError;
use crate::fine::FineGrid;
use crate::grid::{BrickGrid, Lookup};
use crate::light::{project_light, voxel_radiance};
use crate::reflection::{FilteredEnvironment, ReflectionLobe, reflection_seen_from};
use crate::view::{project_view_light, radiance_seen_from, voxel_lobe_radiance};

/// Largest [`MarchSettings::pixel_grid`] (256 rays per pixel).
pub const MAX_PIXEL_GRID: u32 = 16;

/// Ray-marching parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MarchSettings {
    /// Step between samples in voxels (`Δ = step_voxels · voxel_size`); default 0.5.
    pub step_voxels: f32,
    /// Rays stop once their transmittance falls below this; default 1e-3 (0 = never).
    pub min_transmittance: f32,
    /// Rays per pixel along each axis, `n`: a pixel averages the rgb and alpha of the
    /// `n²` rays through the sub-pixel points `(u + (i + ½)/n, v + (j + ½)/n)`;
    /// default 1 (the pixel centre). Ground-truth images are antialiased this way
    /// (their coverage uses 4 × 4 points), so a fair comparison renders with 4.
    pub pixel_grid: u32,
}

impl Default for MarchSettings {
    fn default() -> Self {
        Self {
            step_voxels: 0.5,
            min_transmittance: 1e-3,
            pixel_grid: 1,
        }
    }
}

impl MarchSettings {
    /// Checks `step_voxels` is finite and in `[1e-3, 64]`, `min_transmittance` in `[0, 1)`
    /// and `pixel_grid` in `1..=16`.
    pub fn validate(&self) -> Result<(), RenderError> {
        if !(self.step_voxels.is_finite() && (1e-3..=64.0).contains(&self.step_voxels)) {
            return Err(RenderError::BadSettings(format!(
                "step_voxels = {} must be in [0.001, 64]",
                self.step_voxels
            )));
        }
        if !(self.min_transmittance.is_finite() && (0.0..1.0).contains(&self.min_transmittance)) {
            return Err(RenderError::BadSettings(format!(
                "min_transmittance = {} must be in [0, 1)",
                self.min_transmittance
            )));
        }
        if !(1..=MAX_PIXEL_GRID).contains(&self.pixel_grid) {
            return Err(RenderError::BadSettings(format!(
                "pixel_grid = {} must be in 1..={MAX_PIXEL_GRID}",
                self.pixel_grid
            )));
        }
        Ok(())
    }

    /// Step `Δ` in metres for a grid.
    pub fn step_m(&self, grid: &BrickGrid) -> f64 {
        f64::from(self.step_voxels) * grid.geometry().voxel_size_m
    }
}

/// A premultiplied image, row-major from the top-left: `rgb = Σ w_i c_i` (over black),
/// `alpha = 1 − T_end`.
#[derive(Debug, Clone, PartialEq)]
pub struct Image {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Linear premultiplied radiance per pixel.
    pub rgb: Vec<[f32; 3]>,
    /// Coverage per pixel, `1 − transmittance`.
    pub alpha: Vec<f32>,
}

impl Image {
    /// A black, fully transparent image.
    pub fn new(width: u32, height: u32) -> Self {
        let n = width as usize * height as usize;
        Self {
            width,
            height,
            rgb: vec![[0.0; 3]; n],
            alpha: vec![0.0; n],
        }
    }

    /// Pixel `(u, v)`'s premultiplied radiance.
    pub fn rgb_at(&self, u: u32, v: u32) -> [f32; 3] {
        self.rgb[v as usize * self.width as usize + u as usize]
    }

    /// Pixel `(u, v)`'s alpha.
    pub fn alpha_at(&self, u: u32, v: u32) -> f32 {
        self.alpha[v as usize * self.width as usize + u as usize]
    }
}

/// Counters of one render (for benchmarks): samples taken and skipped.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct MarchStats {
    /// Samples whose trilinear lookup was evaluated.
    pub samples_evaluated: u64,
    /// Samples of the lattice jumped over by empty-space skipping.
    pub samples_skipped: u64,
    /// Evaluated samples with `σ > 0` (composited).
    pub samples_composited: u64,
}

impl std::ops::Add for MarchStats {
    type Output = Self;
    fn add(self, other: Self) -> Self {
        Self {
            samples_evaluated: self.samples_evaluated + other.samples_evaluated,
            samples_skipped: self.samples_skipped + other.samples_skipped,
            samples_composited: self.samples_composited + other.samples_composited,
        }
    }
}

/// Whether to jump over missing bricks.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Skipping {
    /// Jump over core boxes of missing bricks, fast single-brick lookups.
    On,
    /// Every sample, every corner looked up on its own.
    Off,
}

/// Per-voxel density as the marcher reads it: plain `σ`, or `[σ, r, g, b]` interleaved so
/// that one sample's density and radiance share cache lines.
trait DensityAt: Sync {
    fn density_at(&self, voxel: usize) -> f32;
}

impl DensityAt for [f32] {
    #[inline]
    fn density_at(&self, voxel: usize) -> f32 {
        self[voxel]
    }
}

impl DensityAt for [[f32; 4]] {
    #[inline]
    fn density_at(&self, voxel: usize) -> f32 {
        self[voxel][0]
    }
}

/// One ray marcher over a grid and its densities.
struct Marcher<'a, D: DensityAt + ?Sized> {
    grid: &'a BrickGrid,
    density: &'a D,
    step_m: f64,
    step_m_f32: f32,
    min_transmittance: f32,
    skipping: Skipping,
}

impl<'a, D: DensityAt + ?Sized> Marcher<'a, D> {
    fn new(grid: &'a BrickGrid, density: &'a D, settings: MarchSettings, skipping: Skipping) -> Self {
        let step_m = settings.step_m(grid);
        Self {
            grid,
            density,
            step_m,
            step_m_f32: step_m as f32,
            min_transmittance: settings.min_transmittance,
            skipping,
        }
    }

    /// Marches one ray; calls `visit(w_i, corners, p_i)` for every sample with `σ_i > 0`
    /// and returns the final transmittance.
    fn march(
        &self,
        origin: DVec3,
        dir: DVec3,
        stats: &mut MarchStats,
        mut visit: impl FnMut(f32, &[(usize, f32)], DVec3),
    ) -> f32 {
        let Some((t_near, t_far)) = ray_box(origin, dir, self.grid.bbox_min(), self.grid.bbox_max()) else {
            return 1.0;
        };
        let t_entry = t_near.max(0.0);
        let count = ((t_far - t_entry) / self.step_m - 0.5).ceil();
        if count.is_nan() || count <= 0.0 {
            return 1.0;
        }
        let count = count.min(1e15) as u64;
        let lattice_index = |t: f64| ((t - t_entry) / self.step_m - 0.5).ceil();
        let mut transmittance = 1.0f32;
        let mut corners = [(0usize, 0.0f32); 8];
        let mut i = 0u64;
        while i < count {
            let t = t_entry + (i as f64 + 0.5) * self.step_m;
            let p = origin + dir * t;
            let n = match self.skipping {
                Skipping::Off => self.grid.trilinear_general(p, &mut corners),
                Skipping::On => match self.grid.lookup_trilinear(p, &mut corners) {
                    Lookup::Corners(n) => n,
                    Lookup::EmptyBrick(brick) => {
                        stats.samples_evaluated += 1;
                        let (lo, hi) = self.grid.empty_core_box(brick);
                        let resume =
                            ray_box(origin, dir, lo, hi).map_or(0.0, |(_, t_out)| lattice_index(t_out) - 1.0);
                        let next = if resume > (i + 1) as f64 {
                            (resume.min(count as f64)) as u64
                        } else {
                            i + 1
                        };
                        stats.samples_skipped += next - i - 1;
                        i = next;
                        continue;
                    }
                },
            };
            stats.samples_evaluated += 1;
            i += 1;
            let sigma: f32 = corners[..n]
                .iter()
                .map(|&(v, w)| w * self.density.density_at(v))
                .sum();
            if sigma > 0.0 {
                stats.samples_composited += 1;
                let survive = (-sigma * self.step_m_f32).exp();
                visit(transmittance * (1.0 - survive), &corners[..n], p);
                transmittance *= survive;
                if transmittance < self.min_transmittance {
                    break;
                }
            }
        }
        transmittance
    }
}

/// Ray–box intersection `(t_near, t_far)` of the line `o + t d` (slab test); `None` if the
/// line misses the box, only touches it (`t_far = t_near`) or the box is behind (`t_far ≤ 0`).
pub fn ray_box(o: DVec3, d: DVec3, lo: DVec3, hi: DVec3) -> Option<(f64, f64)> {
    let mut t_near = f64::NEG_INFINITY;
    let mut t_far = f64::INFINITY;
    for a in 0..3 {
        if d[a] == 0.0 {
            if o[a] < lo[a] || o[a] > hi[a] {
                return None;
            }
            continue;
        }
        let t0 = (lo[a] - o[a]) / d[a];
        let t1 = (hi[a] - o[a]) / d[a];
        t_near = t_near.max(t0.min(t1));
        t_far = t_far.min(t0.max(t1));
    }
    (t_near < t_far && t_far > 0.0).then_some((t_near, t_far))
}

/// The `n²` rays of pixel `(col, row)` (module docs, `pixel_grid`): through the
/// centres of an `n × n` sub-pixel grid, x fastest (for `n = 1`, exactly
/// `PinholeCamera::pixel_ray`: the offset is `½`).
fn pixel_rays(
    camera: &PinholeCamera,
    col: usize,
    row: usize,
    n: u32,
) -> impl Iterator<Item = (DVec3, DVec3)> {
    let sub = move |p: usize, k: u32| p as f64 + (f64::from(k) + 0.5) / f64::from(n);
    (0..n).flat_map(move |j| {
        (0..n).map(move |i| {
            (
                camera.centre(),
                camera.ray_direction(DVec2::new(sub(col, i), sub(row, j))),
            )
        })
    })
}

/// Checks the inputs shared by [`render_volume`] and [`visibility_weights`].
fn check_inputs(
    grid: &BrickGrid,
    density: &[f32],
    camera: &PinholeCamera,
    settings: &MarchSettings,
) -> Result<(), RenderError> {
    settings.validate()?;
    camera.validate()?;
    if density.len() != grid.voxel_count() {
        return Err(RenderError::LengthMismatch {
            what: "density",
            expected: grid.voxel_count(),
            found: density.len(),
        });
    }
    Ok(())
}

/// Ray-marches density (1/m, per voxel) and radiance (per voxel) through the pixel
/// centres of `camera`: ray–box clipping, empty-space skipping over missing bricks,
/// trilinear σ and radiance, `α_i = 1 − exp(−σ_i Δ)`, front-to-back compositing, early
/// termination below `min_transmittance` (module docs give every detail). Deterministic,
/// rows in parallel.
pub fn render_volume(
    grid: &BrickGrid,
    density: &[f32],
    radiance: &[[f32; 3]],
    camera: &PinholeCamera,
    settings: &MarchSettings,
) -> Result<Image, RenderError> {
    render_volume_with(grid, density, radiance, camera, settings, Skipping::On, None).map(|(image, _)| image)
}

/// A per-sample factor on the interpolated radiance: `factor(p)` at the sample's
/// world position (the fine reflectance layer).
pub type SampleFactor<'a> = &'a (dyn Fn(DVec3) -> [f32; 3] + Sync);

/// [`render_volume`] with each sample's interpolated radiance multiplied by
/// `factor(p)`, `p` the sample's world position.
pub fn render_volume_factored(
    grid: &BrickGrid,
    density: &[f32],
    radiance: &[[f32; 3]],
    factor: SampleFactor<'_>,
    camera: &PinholeCamera,
    settings: &MarchSettings,
) -> Result<Image, RenderError> {
    render_volume_with(
        grid,
        density,
        radiance,
        camera,
        settings,
        Skipping::On,
        Some(factor),
    )
    .map(|(image, _)| image)
}

/// [`render_volume`] that also counts samples evaluated and skipped.
pub fn render_volume_stats(
    grid: &BrickGrid,
    density: &[f32],
    radiance: &[[f32; 3]],
    camera: &PinholeCamera,
    settings: &MarchSettings,
) -> Result<(Image, MarchStats), RenderError> {
    render_volume_with(grid, density, radiance, camera, settings, Skipping::On, None)
}

/// [`render_volume`] without empty-space skipping and without the single-brick fast path:
/// every lattice sample is evaluated and every trilinear corner looked up on its own.
/// Slow; it exists to show (and test) that skipping changes nothing.
pub fn render_volume_unskipped(
    grid: &BrickGrid,
    density: &[f32],
    radiance: &[[f32; 3]],
    camera: &PinholeCamera,
    settings: &MarchSettings,
) -> Result<Image, RenderError> {
    render_volume_with(grid, density, radiance, camera, settings, Skipping::Off, None).map(|(image, _)| image)
}

fn render_volume_with(
    grid: &BrickGrid,
    density: &[f32],
    radiance: &[[f32; 3]],
    camera: &PinholeCamera,
    settings: &MarchSettings,
    skipping: Skipping,
    factor: Option<SampleFactor<'_>>,
) -> Result<(Image, MarchStats), RenderError> {
    check_inputs(grid, density, camera, settings)?;
    if radiance.len() != grid.voxel_count() {
        return Err(RenderError::LengthMismatch {
            what: "radiance",
            expected: grid.voxel_count(),
            found: radiance.len(),
        });
    }
    let voxels: Vec<[f32; 4]> = density
        .iter()
        .zip(radiance)
        .map(|(&s, c)| [s, c[0], c[1], c[2]])
        .collect();
    let marcher = Marcher::new(grid, voxels.as_slice(), *settings, skipping);
    Ok(composite(&marcher, camera, settings, |corners, p| {
        let mut c = [0.0f32; 3];
        for &(v, cw) in corners {
            let r = voxels[v];
            for ch in 0..3 {
                c[ch] += cw * r[ch + 1];
            }
        }
        if let Some(factor) = factor {
            let f = factor(p);
            for ch in 0..3 {
                c[ch] *= f[ch];
            }
        }
        c
    }))
}

/// Ray-marches an asset's fine density (format 1.4, [`FineGrid`]) with the radiance
/// (per voxel of `grid`, the asset's own grid) interpolated at each sample from the
/// voxels: σ from the fine lattice, everything else as [`render_volume`] (SPEC §8,
/// "Fine density"). The step is `settings.step_voxels` fine voxels.
pub fn render_volume_fine(
    grid: &BrickGrid,
    radiance: &[[f32; 3]],
    fine: &FineGrid,
    camera: &PinholeCamera,
    settings: &MarchSettings,
) -> Result<Image, RenderError> {
    check_inputs(&fine.grid, &fine.density, camera, settings)?;
    if radiance.len() != grid.voxel_count() {
        return Err(RenderError::LengthMismatch {
            what: "radiance",
            expected: grid.voxel_count(),
            found: radiance.len(),
        });
    }
    let marcher = Marcher::new(&fine.grid, fine.density.as_slice(), *settings, Skipping::On);
    let (image, _) = composite(&marcher, camera, settings, |_, p| {
        let mut corners = [(0usize, 0.0f32); 8];
        let n = grid.trilinear(p, &mut corners);
        let mut c = [0.0f32; 3];
        for &(v, cw) in &corners[..n] {
            let r = radiance[v];
            for ch in 0..3 {
                c[ch] += cw * r[ch];
            }
        }
        c
    });
    Ok(image)
}

/// Front-to-back compositing of every pixel's rays through `marcher`, the colour of a
/// sample given by `shade(corners, p)` (its trilinear corners in the marched grid and
/// its world position); rows in parallel, deterministic.
fn composite<D: DensityAt + ?Sized>(
    marcher: &Marcher<'_, D>,
    camera: &PinholeCamera,
    settings: &MarchSettings,
    shade: impl Fn(&[(usize, f32)], DVec3) -> [f32; 3] + Sync,
) -> (Image, MarchStats) {
    let (mut images, stats) = composite_many(marcher, camera, settings, 1, |corners, p, out| {
        out[0] = shade(corners, p);
    });
    let image = images
        .pop()
        .unwrap_or_else(|| Image::new(camera.width, camera.height));
    (image, stats)
}

/// One row of each of [`composite_many`]'s images, its coverage and its counters.
type RowOfImages = (Vec<Vec<[f32; 3]>>, Vec<f32>, MarchStats);

/// [`composite`] of `count` colours per sample (`shade(corners, p, out)` writes them to
/// `out`, `count` long) with the same samples and weights: `count` images.
fn composite_many<D: DensityAt + ?Sized>(
    marcher: &Marcher<'_, D>,
    camera: &PinholeCamera,
    settings: &MarchSettings,
    count: usize,
    shade: impl Fn(&[(usize, f32)], DVec3, &mut [[f32; 3]]) + Sync,
) -> (Vec<Image>, MarchStats) {
    let width = camera.width as usize;
    let rows: Vec<RowOfImages> = (0..camera.height as usize)
        .into_par_iter()
        .map(|row| {
            let mut stats = MarchStats::default();
            let n = settings.pixel_grid;
            let share = 1.0 / (n * n) as f32;
            let mut rgb_rows = vec![vec![[0.0f32; 3]; width]; count];
            let mut alpha_row = vec![0.0f32; width];
            let mut colours = vec![[0.0f32; 3]; count];
            let mut sums = vec![[0.0f32; 3]; count];
            let mut pixel_rgb = vec![[0.0f32; 3]; count];
            for (col, alpha) in alpha_row.iter_mut().enumerate() {
                pixel_rgb.fill([0.0; 3]);
                let mut pixel_alpha = 0.0f32;
                for (origin, dir) in pixel_rays(camera, col, row, n) {
                    sums.fill([0.0; 3]);
                    let t_end = marcher.march(origin, dir, &mut stats, |w, corners, p| {
                        shade(corners, p, &mut colours);
                        for (sum, c) in sums.iter_mut().zip(&colours) {
                            for ch in 0..3 {
                                sum[ch] += w * c[ch];
                            }
                        }
                    });
                    // For n = 1, share = 1 and 0 + 1·x = x: the plain render, bit for bit.
                    for (pixel, sum) in pixel_rgb.iter_mut().zip(&sums) {
                        for ch in 0..3 {
                            pixel[ch] += share * sum[ch];
                        }
                    }
                    pixel_alpha += share * (1.0 - t_end);
                }
                for (rgb_row, pixel) in rgb_rows.iter_mut().zip(&pixel_rgb) {
                    rgb_row[col] = *pixel;
                }
                *alpha = pixel_alpha;
            }
            (rgb_rows, alpha_row, stats)
        })
        .collect();
    let mut images: Vec<Image> = (0..count)
        .map(|_| Image::new(camera.width, camera.height))
        .collect();
    let mut stats = MarchStats::default();
    for (row, (rgb_rows, alpha_row, row_stats)) in rows.into_iter().enumerate() {
        let span = row * width..(row + 1) * width;
        for (image, rgb_row) in images.iter_mut().zip(rgb_rows) {
            image.rgb[span.clone()].copy_from_slice(&rgb_row);
            image.alpha[span.clone()].copy_from_slice(&alpha_row);
        }
        stats = stats + row_stats;
    }
    (images, stats)
}

/// Renders an arbitrary per-voxel feature vector (`dim` floats per voxel, voxel-major)
/// with the same samples and compositing weights as [`render_volume`]: per pixel
/// `Σ_i w_i · Σ_corners weight · f_v` (premultiplied over 0), `dim` floats per pixel,
/// row-major. Since a render is linear in the radiance for a fixed density, the image
/// of any radiance that is a linear map of the features (e.g. `mean + Σ_k c_k P_k`,
/// the PCA reconstruction shaded by some lighting) is that map applied to these
/// pixels: one feature render serves every lighting and every rank.
pub fn render_features(
    grid: &BrickGrid,
    density: &[f32],
    features: &[f32],
    dim: usize,
    camera: &PinholeCamera,
    settings: &MarchSettings,
) -> Result<Vec<f32>, RenderError> {
    check_inputs(grid, density, camera, settings)?;
    if dim == 0 || features.len() != grid.voxel_count() * dim {
        return Err(RenderError::LengthMismatch {
            what: "features",
            expected: grid.voxel_count() * dim.max(1),
            found: features.len(),
        });
    }
    let marcher = Marcher::new(grid, density, *settings, Skipping::On);
    let width = camera.width as usize;
    let n = settings.pixel_grid;
    let share = 1.0 / (n * n) as f32;
    let mut out = vec![0.0f32; width * camera.height as usize * dim];
    out.par_chunks_mut(width * dim)
        .enumerate()
        .for_each(|(row, out_row)| {
            let mut stats = MarchStats::default();
            for (col, pixel) in out_row.chunks_exact_mut(dim).enumerate() {
                for (origin, dir) in pixel_rays(camera, col, row, n) {
                    marcher.march(origin, dir, &mut stats, |w, corners, _| {
                        for &(v, cw) in corners {
                            let weight = share * w * cw;
                            for (p, f) in pixel.iter_mut().zip(&features[v * dim..(v + 1) * dim]) {
                                *p += weight * f;
                            }
                        }
                    });
                }
            }
        });
    Ok(out)
}

/// Rows per band of [`visibility_weights`]: rows `r` with `r mod BANDS = b` form band `b`,
/// each accumulated on its own and summed in band order (deterministic).
const VISIBILITY_BANDS: usize = 8;

/// How much each voxel shows in `camera`'s image: **adds** to `out[v]` (one entry per
/// voxel) `Σ_pixels Σ_i w_i · trilinear_weight_i(v)` — compositing weight times trilinear
/// weight of every sample (module docs). Call once per camera on the same buffer to
/// accumulate views; zero it first for one view. Deterministic (rows are split into 8
/// fixed bands accumulated separately, which takes 8 × 4 bytes of scratch per voxel).
pub fn visibility_weights(
    grid: &BrickGrid,
    density: &[f32],
    camera: &PinholeCamera,
    settings: &MarchSettings,
    out: &mut [f32],
) -> Result<(), RenderError> {
    check_inputs(grid, density, camera, settings)?;
    if out.len() != grid.voxel_count() {
        return Err(RenderError::LengthMismatch {
            what: "visibility weights",
            expected: grid.voxel_count(),
            found: out.len(),
        });
    }
    let marcher = Marcher::new(grid, density, *settings, Skipping::On);
    let bands = VISIBILITY_BANDS.min(camera.height as usize);
    let partial: Vec<Vec<f32>> = (0..bands)
        .into_par_iter()
        .map(|band| {
            let mut acc = vec![0.0f32; out.len()];
            let mut stats = MarchStats::default();
            for row in (band..camera.height as usize).step_by(bands) {
                for col in 0..camera.width {
                    let (origin, dir) = camera.pixel_ray(col, row as u32);
                    marcher.march(origin, dir, &mut stats, |w, corners, _| {
                        for &(v, cw) in corners {
                            acc[v] += w * cw;
                        }
                    });
                }
            }
            acc
        })
        .collect();
    for band in &partial {
        for (o, a) in out.iter_mut().zip(band) {
            *o += a;
        }
    }
    Ok(())
}

/// Density σ (1/m) of every voxel of an asset, as `f32`.
pub fn asset_density(asset: &Asset) -> Vec<f32> {
    asset.density.iter().map(|d| d.to_f32()).collect()
}

/// The lighting `env` (turned by `world_from_env`) filtered by the lobe of an asset's
/// reflection part ([`crate::reflection`]), once per lighting change.
pub fn filtered_environment(
    asset: &Asset,
    reflection: &nelf_format::Reflection,
    env: &LatLong,
    world_from_env: glam::DMat3,
) -> Result<FilteredEnvironment, RenderError> {
    if !nelf_format::conventions::is_rotation(world_from_env, 1e-5) {
        return Err(RenderError::NotARotation {
            what: "world_from_env",
            matrix: world_from_env.to_cols_array(),
        });
    }
    filtered_environment_with(
        &ReflectionLobe::new(reflection.exponent, asset.world_from_light),
        asset,
        env,
        world_from_env,
    )
}

/// [`filtered_environment`] with the lobe already built (`lobe`, of the reflection
/// part's exponent in the asset's light frame): for many lightings or views of one part.
pub fn filtered_environment_with(
    lobe: &ReflectionLobe,
    asset: &Asset,
    env: &LatLong,
    world_from_env: glam::DMat3,
) -> Result<FilteredEnvironment, RenderError> {
    if !nelf_format::conventions::is_rotation(world_from_env, 1e-5) {
        return Err(RenderError::NotARotation {
            what: "world_from_env",
            matrix: world_from_env.to_cols_array(),
        });
    }
    let light =
        nelf_format::conventions::project_envmap(env, world_from_env.transpose() * asset.world_from_light)?;
    Ok(lobe.filter(&light))
}

/// Everything for one asset, camera and lighting: checks the asset, projects `env`
/// (turned by `world_from_env`) onto its basis, computes per-voxel radiance with the
/// first `rank` components (default all), adds a view-dependent asset's lobes toward the
/// camera centre ([`crate::view`], [`crate::reflection`]) and ray-marches (through the
/// fine density where the asset has one, [`render_volume_fine`]).
pub fn render_asset(
    asset: &Asset,
    camera: &PinholeCamera,
    env: &LatLong,
    world_from_env: glam::DMat3,
    rank: Option<usize>,
    settings: &MarchSettings,
) -> Result<Image, RenderError> {
    let radiance = asset_radiance(asset, camera, env, world_from_env, rank)?;
    let grid = BrickGrid::from_asset(asset)?;
    match FineGrid::from_asset(asset)? {
        Some(fine) => render_volume_fine(&grid, &radiance, &fine, camera, settings),
        None => render_volume(&grid, &asset_density(asset), &radiance, camera, settings),
    }
}

/// The radiance of every voxel of `asset` as [`render_asset`] marches it: checks the
/// asset, projects `env` (turned by `world_from_env`), shades with the first `rank`
/// components (default all) and adds the view and reflection parts seen from the
/// camera's centre.
pub fn asset_radiance(
    asset: &Asset,
    camera: &PinholeCamera,
    env: &LatLong,
    world_from_env: glam::DMat3,
    rank: Option<usize>,
) -> Result<Vec<[f32; 3]>, RenderError> {
    asset_radiance_with(asset, camera, env, world_from_env, rank, None)
}

/// [`asset_radiance`] with the reflection part's lobe table already built (`lobe`, used
/// where it is the part's: [`ReflectionLobe::is_for`]; built otherwise), so that many
/// views of one asset build it once.
pub fn asset_radiance_with(
    asset: &Asset,
    camera: &PinholeCamera,
    env: &LatLong,
    world_from_env: glam::DMat3,
    rank: Option<usize>,
    lobe: Option<&ReflectionLobe>,
) -> Result<Vec<[f32; 3]>, RenderError> {
    asset.validate()?;
    let light = project_light(&asset.pca, asset.world_from_light, env, world_from_env)?;
    let mut radiance = voxel_radiance(asset, &light, rank);
    if let Some(view) = &asset.view {
        let view_light = project_view_light(view, asset.world_from_light, env, world_from_env)?;
        let lobes = voxel_lobe_radiance(view, &view_light, radiance.len());
        radiance = radiance_seen_from(asset, &radiance, &lobes, camera.centre());
    }
    if let Some(reflection) = &asset.reflection {
        let filtered = match lobe.filter(|l| l.is_for(reflection.exponent, asset.world_from_light)) {
            Some(lobe) => filtered_environment_with(lobe, asset, env, world_from_env)?,
            None => filtered_environment(asset, reflection, env, world_from_env)?,
        };
        radiance = reflection_seen_from(asset, reflection, &radiance, &filtered, camera.centre());
    }
    Ok(radiance)
}

/// Marches `asset`'s density (its fine density where it has one) once and composites
/// each of `radiances` (per voxel of the asset, e.g. [`asset_radiance`] of variants of
/// it that differ only in their view or reflection parts) with the same samples and
/// weights: image `k` equals [`render_asset`]'s for the radiance `radiances[k]`, bit for
/// bit, at about the cost of one render (the march, not the shading, is what costs).
pub fn render_asset_radiances(
    asset: &Asset,
    radiances: &[Vec<[f32; 3]>],
    camera: &PinholeCamera,
    settings: &MarchSettings,
) -> Result<Vec<Image>, RenderError> {
    asset.validate()?;
    let grid = BrickGrid::from_asset(asset)?;
    for radiance in radiances {
        if radiance.len() != grid.voxel_count() {
            return Err(RenderError::LengthMismatch {
                what: "radiance",
                expected: grid.voxel_count(),
                found: radiance.len(),
            });
        }
    }
    let shade = |corners: &[(usize, f32)], out: &mut [[f32; 3]]| {
        for (c, radiance) in out.iter_mut().zip(radiances) {
            *c = [0.0; 3];
            for &(v, cw) in corners {
                let r = radiance[v];
                for ch in 0..3 {
                    c[ch] += cw * r[ch];
                }
            }
        }
    };
    if let Some(fine) = FineGrid::from_asset(asset)? {
        check_inputs(&fine.grid, &fine.density, camera, settings)?;
        let marcher = Marcher::new(&fine.grid, fine.density.as_slice(), *settings, Skipping::On);
        let (images, _) = composite_many(&marcher, camera, settings, radiances.len(), |_, p, out| {
            let mut corners = [(0usize, 0.0f32); 8];
            let n = grid.trilinear(p, &mut corners);
            shade(&corners[..n], out);
        });
        return Ok(images);
    }
    let density = asset_density(asset);
    check_inputs(&grid, &density, camera, settings)?;
    let marcher = Marcher::new(&grid, density.as_slice(), *settings, Skipping::On);
    let (images, _) = composite_many(&marcher, camera, settings, radiances.len(), |corners, _, out| {
        shade(corners, out);
    });
    Ok(images)
}
