//! Source-view self-calibration: one gain on the network's light transport, chosen
//! so that the network, relighting its own source views under the lighting they were
//! taken in, reproduces them.
//!
//! A capture whose source lighting `L_S` is known (a synthetic capture, or one shot
//! with a light probe) gives a consistency check that needs no held-aside view: the
//! network's rendering `I_v(g) = g · Σ_k w_k · rgb_v · (T·L_S)` of each source camera
//! `v` should equal the photo `P_v`. Our trained networks miss it by a per-capture
//! factor (their light transport is 0.9–1.9× too dark on held-out heads: they
//! misjudge how strongly the source lighting lit the face), and the same factor
//! darkens their novel-light renderings, so the gain
//!
//! `g* = argmin_g Σ_{v, p: m_v(p) ≥ 0.99} ‖srgb(g · I_v(p)) − srgb(P_v(p))‖²`
//!
//! (8-bit-display error, colours clamped to `[0, 1]`, over an even subsample of the
//! pixels fully inside the masks, searched over `ln g` in `[ln ¼, ln 4]`) is applied to `T` for every lighting.
//! Measured in `field/README.md` ("Source-view calibration"). The network's own light
//! estimate is too poor to stand in for `L_S` (it lowered held-out foreground PSNR;
//! `field/README.md`), so a capture without a known lighting is not calibrated.

use nelf_scene::mesh_io::linear_to_srgb;

use crate::error::NetError;
use crate::model::Model;
use crate::render::{NetRay, RayUniforms, render_rays};
use crate::views::EncodedViews;

/// Smallest and largest gain searched.
pub const GAIN_RANGE: (f32, f32) = (0.25, 4.0);

/// Mask value from which a source pixel counts as fully inside (edge pixels mix the
/// head with the black background and would bias the fit).
pub const INSIDE_MASK: f32 = 0.99;

/// Fewest fully-inside source pixels a gain is fitted to.
pub const MIN_PIXELS: usize = 64;

/// Steps of the grid over `ln g` (then refined once around the best step).
const GRID_STEPS: usize = 200;

/// A fitted source-view gain.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SourceGain {
    /// The gain applied to the light transport.
    pub gain: f32,
    /// Source pixels it was fitted to.
    pub pixels: usize,
    /// RMS sRGB error of the re-rendered source views before the gain (0–1 scale).
    pub rmse_before: f64,
    /// The same after it.
    pub rmse_after: f64,
}

/// Squared sRGB error of `gain · rendered` against `truth`, summed.
fn srgb_error(pairs: &[([f32; 3], [f32; 3])], gain: f32) -> f64 {
    let enc = |x: f32| linear_to_srgb(x.clamp(0.0, 1.0));
    pairs
        .iter()
        .map(|(truth, rendered)| {
            (0..3)
                .map(|k| f64::from(enc(truth[k]) - enc(rendered[k] * gain)).powi(2))
                .sum::<f64>()
        })
        .sum()
}

/// The gain in [`GAIN_RANGE`] minimising the squared sRGB error between
/// `gain · rendered` and `truth` over `(truth, rendered)` linear-RGB pairs: a grid
/// over `ln g`, refined once. `None` for fewer than [`MIN_PIXELS`] pairs.
pub fn fit_srgb_gain(pairs: &[([f32; 3], [f32; 3])]) -> Option<SourceGain> {
    if pairs.len() < MIN_PIXELS {
        return None;
    }
    let (lo, hi) = (GAIN_RANGE.0.ln(), GAIN_RANGE.1.ln());
    let step = (hi - lo) / GRID_STEPS as f32;
    let best_on = |from: f32, step: f32, steps: usize| {
        (0..=steps)
            .map(|i| (from + step * i as f32).exp())
            .map(|g| (g, srgb_error(pairs, g)))
            .fold(
                (1.0f32, f64::INFINITY),
                |best, c| if c.1 < best.1 { c } else { best },
            )
    };
    let (coarse, _) = best_on(lo, step, GRID_STEPS);
    let from = (coarse.ln() - step).max(lo);
    let (gain, error) = best_on(from, step / 10.0, 20);
    let n = (pairs.len() * 3) as f64;
    Some(SourceGain {
        gain,
        pixels: pairs.len(),
        rmse_before: (srgb_error(pairs, 1.0) / n).sqrt(),
        rmse_after: (error / n).sqrt(),
    })
}

/// Source pixels the gain is fitted to at most (an even subsample of those fully
/// inside the masks): one number needs few, and each costs a ray through the network.
pub const MAX_PIXELS: usize = 1536;

/// Coarse and fine samples per ray of the calibration's renderings (those of
/// training). Every inside pixel at the model's 64 + 128 samples changes the bake
/// little at many times the cost (`field/README.md`, "Source-view calibration").
pub const SAMPLES: (usize, usize) = (32, 32);

/// Renders the source views encoded in `encoded` through `model` under `light_net`
/// (network layout and units, e.g. [`crate::NelfField::net_light`] of the known
/// source lighting) at an even subsample of at most [`MAX_PIXELS`] of the pixels
/// fully inside their masks `masks` (`(V, H, W)`, the views' own, not dilated), and
/// fits the gain that matches them to the photos ([`fit_srgb_gain`]).
///
/// # Errors
/// Masks of the wrong size, rendering errors, or fewer than [`MIN_PIXELS`] such
/// pixels.
pub fn source_view_gain(
    model: &Model,
    encoded: &EncodedViews,
    masks: &[f32],
    light_net: &[f32],
    head_centre_mm: [f32; 3],
) -> Result<SourceGain, NetError> {
    let (width, pixels) = (encoded.width, encoded.width * encoded.height);
    if masks.len() != encoded.views() * pixels {
        return Err(NetError::input(format!(
            "{} mask values for {} views of {}×{}",
            masks.len(),
            encoded.views(),
            encoded.width,
            encoded.height
        )));
    }
    let inside: Vec<usize> = (0..masks.len()).filter(|&i| masks[i] >= INSIDE_MASK).collect();
    if inside.len() < MIN_PIXELS {
        return Err(NetError::input(format!(
            "{} source pixels lie fully inside the masks; at least {MIN_PIXELS} are needed to calibrate",
            inside.len()
        )));
    }
    let stride = inside.len().div_ceil(MAX_PIXELS);
    let chosen: Vec<usize> = inside.into_iter().step_by(stride).collect();
    let model = model.clone().with_samples(SAMPLES.0, SAMPLES.1);
    let radius = model.config().head_radius_mm;
    let mut pairs = Vec::with_capacity(chosen.len());
    // `chosen` is in view order: each run of one view's pixels renders through its camera.
    for view_pixels in chosen.chunk_by(|a, b| a / pixels == b / pixels) {
        let camera = &encoded.cameras[view_pixels[0] / pixels];
        for chunk in view_pixels.chunks(512) {
            let rays: Vec<NetRay> = chunk
                .iter()
                .map(|&i| {
                    let p = i % pixels;
                    let (x, y) = ((p % width) as f64 + 0.5, (p / width) as f64 + 0.5);
                    NetRay::through_pixel(camera, x, y, head_centre_mm, radius)
                })
                .collect();
            let uniforms = RayUniforms::stratified(rays.len(), SAMPLES.0, SAMPLES.1);
            let out = render_rays(&model, encoded, &rays, &uniforms, light_net)?;
            for (&i, rendered) in chunk.iter().zip(out.fine.rgb.chunks(3)) {
                let truth = [
                    encoded.images[i * 3],
                    encoded.images[i * 3 + 1],
                    encoded.images[i * 3 + 2],
                ];
                pairs.push((truth, [rendered[0], rendered[1], rendered[2]]));
            }
        }
    }
    fit_srgb_gain(&pairs).ok_or_else(|| NetError::input("too few source pixels to calibrate"))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Deterministic colours in (0.02, 0.62).
    fn colours(n: usize) -> Vec<[f32; 3]> {
        (0..n)
            .map(|i| {
                let f = |k: usize| 0.02 + 0.6 * (((i * 7 + k * 13) % 97) as f32 / 97.0);
                [f(0), f(1), f(2)]
            })
            .collect()
    }

    #[test]
    fn a_uniformly_darkened_rendering_gets_its_gain_back() {
        let truth = colours(500);
        for dark in [0.5f32, 0.8, 1.3] {
            let pairs: Vec<_> = truth.iter().map(|t| (*t, t.map(|x| x * dark))).collect();
            let fit = fit_srgb_gain(&pairs).unwrap();
            assert!(
                (fit.gain * dark - 1.0).abs() < 0.01,
                "dark {dark}: gain {}",
                fit.gain
            );
            assert!(fit.rmse_after < 1e-3 && fit.rmse_before > 0.01, "{fit:?}");
        }
    }

    #[test]
    fn the_gain_never_raises_the_error_and_stays_in_range() {
        let truth = colours(300);
        // Noisy and far too bright: the best gain is below 1 and clamped at ¼ at worst.
        let pairs: Vec<_> = truth
            .iter()
            .enumerate()
            .map(|(i, t)| (*t, t.map(|x| x * 9.0 + (i % 5) as f32 * 0.01)))
            .collect();
        let fit = fit_srgb_gain(&pairs).unwrap();
        assert!(fit.rmse_after <= fit.rmse_before);
        assert!((GAIN_RANGE.0..=GAIN_RANGE.1).contains(&fit.gain), "{fit:?}");
        assert!((fit.gain - GAIN_RANGE.0).abs() < 1e-4, "{fit:?}");
    }

    #[test]
    fn too_few_pixels_give_no_gain() {
        let pairs: Vec<_> = colours(MIN_PIXELS - 1).into_iter().map(|t| (t, t)).collect();
        assert!(fit_srgb_gain(&pairs).is_none());
    }
}
