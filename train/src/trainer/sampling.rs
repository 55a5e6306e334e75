//! Where a step looks: the generator of its random choices ([`step_rng`]), the
//! pixels of a target view it renders ([`pick_pixels`]: mostly inside the padded box
//! around the foreground), their rays, the samples along each ray (stratified coarse
//! depths, then importance samples of the coarse weights), and the coarse and fine
//! passes rendered through them ([`render_passes`]).

use candle_core::Tensor;
use nelf_field::render::{NetRay, importance_depths};
use nelf_field::{Model, Stage};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

use super::prepare::{PreparedHead, PreparedTarget};
use crate::config::TrainConfig;
use crate::error::TrainError;
use crate::forward::{Encoded, RayPass, render_rays};

/// The generator of step `step`'s random choices.
pub fn step_rng(seed: u64, step: u64) -> Pcg64 {
    Pcg64::seed_from_u64(seed ^ step.wrapping_mul(0x9E37_79B9_7F4A_7C15))
}

/// Picks `count` pixels of a target: 80 % inside the padded box around its
/// foreground, the rest anywhere.
pub(super) fn pick_pixels(
    target: &PreparedTarget,
    width: usize,
    count: usize,
    rng: &mut Pcg64,
) -> Vec<usize> {
    let height = target.alpha.len() / width.max(1);
    let (mut x0, mut y0, mut x1, mut y1) = (width, height, 0usize, 0usize);
    for (i, a) in target.alpha.iter().enumerate() {
        if *a > 0.0 {
            let (x, y) = (i % width, i / width);
            x0 = x0.min(x);
            y0 = y0.min(y);
            x1 = x1.max(x + 1);
            y1 = y1.max(y + 1);
        }
    }
    let pad = width / 16;
    let boxed = x1 > x0 && y1 > y0;
    let (x0, y0) = (x0.saturating_sub(pad), y0.saturating_sub(pad));
    let (x1, y1) = ((x1 + pad).min(width), (y1 + pad).min(height));
    (0..count)
        .map(|_| {
            if boxed && rng.random::<f32>() < 0.8 {
                rng.random_range(y0..y1) * width + rng.random_range(x0..x1)
            } else {
                rng.random_range(0..width * height)
            }
        })
        .collect()
}

/// Where samples fall in their bins: drawn at random (training) or at the middle
/// of each bin with evenly spaced CDF levels (validation: no noise).
#[derive(Debug)]
pub enum Jitter<'a> {
    /// Uniform draws from this generator.
    Random(&'a mut Pcg64),
    /// Bin middles, levels `(k + ½)/n`.
    Centred,
}

impl Jitter<'_> {
    /// `n` offsets in `[0, 1)` within bins.
    fn offsets(&mut self, n: usize) -> Vec<f32> {
        match self {
            Self::Random(rng) => (0..n).map(|_| rng.random::<f32>()).collect(),
            Self::Centred => vec![0.5; n],
        }
    }

    /// `n` CDF levels in `[0, 1)`.
    fn levels(&mut self, n: usize) -> Vec<f32> {
        match self {
            Self::Random(rng) => (0..n).map(|_| rng.random::<f32>()).collect(),
            Self::Centred => (0..n).map(|k| (k as f32 + 0.5) / n as f32).collect(),
        }
    }
}

/// The rays of `target`'s pixels `pixels` (through their centres).
pub fn target_rays(
    target: &PreparedTarget,
    pixels: &[usize],
    centre: [f32; 3],
    radius_mm: f32,
) -> Vec<NetRay> {
    let width = target.camera.width;
    pixels
        .iter()
        .map(|&p| {
            NetRay::through_pixel(
                &target.camera,
                (p % width) as f64 + 0.5,
                (p / width) as f64 + 0.5,
                centre,
                radius_mm,
            )
        })
        .collect()
}

/// Coarse depths `(R, S)` of `rays`, one per bin of `[near, far]`.
fn coarse_depths(rays: &[NetRay], samples: usize, jitter: &mut Jitter<'_>) -> Vec<f32> {
    rays.iter()
        .flat_map(|ray| {
            let offsets = jitter.offsets(samples);
            (0..samples)
                .map(|k| {
                    let z = (k as f32 + offsets[k]) / samples as f32;
                    ray.near * (1.0 - z) + ray.far * z
                })
                .collect::<Vec<_>>()
        })
        .collect()
}

/// The fine pass's depths: coarse ones plus `fine` importance samples, sorted.
fn fine_depths(
    rays: &[NetRay],
    coarse: &[f32],
    weights: &[f32],
    fine: usize,
    jitter: &mut Jitter<'_>,
) -> Vec<f32> {
    let s = coarse.len() / rays.len().max(1);
    let mut out = Vec::with_capacity(rays.len() * (s + fine));
    for (r, ray) in rays.iter().enumerate() {
        let u = jitter.levels(fine);
        let offsets = jitter.offsets(fine);
        let mut d = importance_depths(&weights[r * s..(r + 1) * s], ray.near, ray.far, &u, &offsets);
        d.extend_from_slice(&coarse[r * s..(r + 1) * s]);
        d.sort_by(f32::total_cmp);
        out.extend(d);
    }
    out
}

/// The coarse pass over `rays` and, when the configuration has importance samples,
/// the fine pass, under `irradiance` (`(3, 128)`).
pub fn render_passes(
    model: &Model,
    encoded: &Encoded,
    head: &PreparedHead,
    rays: &[NetRay],
    irradiance: &Tensor,
    config: &TrainConfig,
    jitter: &mut Jitter<'_>,
) -> Result<(RayPass, Option<RayPass>), TrainError> {
    let coarse_d = coarse_depths(rays, config.coarse_samples, jitter);
    let coarse = render_rays(
        model,
        encoded,
        &head.geometry,
        rays,
        &coarse_d,
        Stage::Coarse,
        irradiance,
    )?;
    let fine = if config.fine_samples > 0 {
        let d = fine_depths(rays, &coarse_d, &coarse.weights, config.fine_samples, jitter);
        Some(render_rays(
            model,
            encoded,
            &head.geometry,
            rays,
            &d,
            Stage::Fine,
            irradiance,
        )?)
    } else {
        None
    };
    Ok((coarse, fine))
}
