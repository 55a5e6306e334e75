//! Image metrics on linear float RGB images: PSNR and SSIM, reproducing
//! scikit-image 0.26's `peak_signal_noise_ratio` and `structural_similarity`
//! (`gaussian_weights=True, sigma=1.5, use_sample_covariance=False, channel_axis=-1`),
//! plus masked variants.
//!
//! * **PSNR** `= 10·log10(R² / MSE)`, MSE over every pixel and channel, `R` the data
//!   range. Identical images give `f64::INFINITY`.
//! * **SSIM** (Wang, Bovik, Sheikh, Simoncelli, "Image quality assessment: from error
//!   visibility to structural similarity", IEEE TIP 2004), per channel:
//!   `S = (2 μx μy + C1)(2 σxy + C2) / ((μx² + μy² + C1)(σx² + σy² + C2))`,
//!   `C1 = (0.01 R)²`, `C2 = (0.03 R)²`, with local means and population
//!   (co)variances (`σxy = E[xy] − μx μy`) taken under a Gaussian window of σ = 1.5
//!   truncated at 3.5 σ, i.e. radius `⌊3.5·1.5 + 0.5⌋ = 5` (11 × 11 taps, normalised
//!   to sum 1), applied separably with scipy's `mode='reflect'` border
//!   (`d c b a | a b c d | d c b a`). As in scikit-image, the SSIM map is then
//!   cropped by `(11 − 1)/2 = 5` pixels on every side and averaged; the result is the
//!   mean over the three channels. Images must be at least 11 × 11.
//!
//! All arithmetic is `f64` (scikit-image works in `float64` for 8-bit or `float64`
//! input). Images are row-major `[f32; 3]` slices, as in
//! `nelf_scene::render::RenderedImage::rgb`.
//!
//! **Masked variants** weight pixels by a per-pixel weight `w ≥ 0` (a mask, or
//! coverage): [`psnr_masked`] uses `MSE = Σ w·Σ_c (a − b)² / (3 Σ w)`;
//! [`ssim_masked`] computes the same SSIM map as [`ssim`] over the whole image
//! (windows near the mask's edge see pixels outside it, so composite both images
//! over the same background first) and averages it with weights `w` over the
//! cropped region only. With all weights equal they return exactly [`psnr`] and
//! [`ssim`].

/// Gaussian window standard deviation, pixels.
pub const SSIM_SIGMA: f64 = 1.5;
/// Gaussian window radius, pixels: `⌊3.5 σ + 0.5⌋` (scipy's `truncate = 3.5`).
pub const SSIM_RADIUS: usize = 5;
/// Window side, `2·radius + 1`; also the smallest image side SSIM accepts.
pub const SSIM_WINDOW: usize = 2 * SSIM_RADIUS + 1;
/// Luminance stabiliser constant: `C1 = (K1·R)²`.
pub const SSIM_K1: f64 = 0.01;
/// Contrast stabiliser constant: `C2 = (K2·R)²`.
pub const SSIM_K2: f64 = 0.03;

/// Errors from the metrics: mismatched or invalid inputs.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum MetricError {
    /// The two images, the mask, or the stated size disagree.
    #[error("size mismatch: {0}")]
    SizeMismatch(String),
    /// The image is smaller than the SSIM window.
    #[error("SSIM needs images of at least {SSIM_WINDOW}×{SSIM_WINDOW} pixels, got {width}×{height}")]
    TooSmall {
        /// Width in pixels.
        width: u32,
        /// Height in pixels.
        height: u32,
    },
    /// The images are empty.
    #[error("the images have no pixels")]
    Empty,
    /// `data_range` is not a positive finite number.
    #[error("data_range = {0} must be positive and finite")]
    BadDataRange(f64),
    /// A pixel value is NaN or infinite.
    #[error("{which} has a non-finite value at pixel {index}")]
    NonFinite {
        /// `first image`, `second image` or `mask`.
        which: &'static str,
        /// Row-major pixel index.
        index: usize,
    },
    /// A mask weight is negative.
    #[error("mask weight {value} at pixel {index} is negative")]
    NegativeWeight {
        /// Row-major pixel index.
        index: usize,
        /// The weight.
        value: f32,
    },
    /// The mask has no weight where the metric is averaged.
    #[error("the mask is empty{0}")]
    EmptyMask(&'static str),
}

fn check_data_range(data_range: f64) -> Result<(), MetricError> {
    if data_range.is_finite() && data_range > 0.0 {
        Ok(())
    } else {
        Err(MetricError::BadDataRange(data_range))
    }
}

fn check_pair(a: &[[f32; 3]], b: &[[f32; 3]]) -> Result<(), MetricError> {
    if a.len() != b.len() {
        return Err(MetricError::SizeMismatch(format!(
            "the images have {} and {} pixels",
            a.len(),
            b.len()
        )));
    }
    if a.is_empty() {
        return Err(MetricError::Empty);
    }
    for (which, image) in [("first image", a), ("second image", b)] {
        if let Some(index) = image.iter().position(|p| !p.iter().all(|v| v.is_finite())) {
            return Err(MetricError::NonFinite { which, index });
        }
    }
    Ok(())
}

fn check_weights(weights: &[f32], pixels: usize) -> Result<(), MetricError> {
    if weights.len() != pixels {
        return Err(MetricError::SizeMismatch(format!(
            "the mask has {} weights for {pixels} pixels",
            weights.len()
        )));
    }
    for (index, &value) in weights.iter().enumerate() {
        if !value.is_finite() {
            return Err(MetricError::NonFinite { which: "mask", index });
        }
        if value < 0.0 {
            return Err(MetricError::NegativeWeight { index, value });
        }
    }
    Ok(())
}

fn psnr_from_mse(mse: f64, data_range: f64) -> f64 {
    if mse == 0.0 {
        f64::INFINITY
    } else {
        10.0 * (data_range * data_range / mse).log10()
    }
}

/// Mean squared error over every pixel and channel.
pub fn mse(a: &[[f32; 3]], b: &[[f32; 3]]) -> Result<f64, MetricError> {
    check_pair(a, b)?;
    Ok(squared_error_sum(a, b, None) / (3 * a.len()) as f64)
}

/// `Σ_p w_p Σ_c (a − b)²` (weights 1 when `None`).
fn squared_error_sum(a: &[[f32; 3]], b: &[[f32; 3]], weights: Option<&[f32]>) -> f64 {
    a.iter()
        .zip(b)
        .enumerate()
        .map(|(i, (pa, pb))| {
            let e: f64 = (0..3)
                .map(|c| {
                    let d = f64::from(pa[c]) - f64::from(pb[c]);
                    d * d
                })
                .sum();
            weights.map_or(e, |w| f64::from(w[i]) * e)
        })
        .sum()
}

/// Peak signal-to-noise ratio in dB, `10·log10(R² / MSE)` over all pixels and
/// channels; `f64::INFINITY` when the images are identical.
pub fn psnr(a: &[[f32; 3]], b: &[[f32; 3]], data_range: f64) -> Result<f64, MetricError> {
    check_data_range(data_range)?;
    Ok(psnr_from_mse(mse(a, b)?, data_range))
}

/// PSNR with the MSE weighted per pixel: `Σ w Σ_c (a − b)² / (3 Σ w)`. Weights must be
/// finite and ≥ 0 with a positive sum; `f64::INFINITY` when the images agree wherever
/// the weight is positive.
pub fn psnr_masked(
    a: &[[f32; 3]],
    b: &[[f32; 3]],
    weights: &[f32],
    data_range: f64,
) -> Result<f64, MetricError> {
    check_data_range(data_range)?;
    check_pair(a, b)?;
    check_weights(weights, a.len())?;
    let total: f64 = weights.iter().map(|&w| f64::from(w)).sum();
    if total <= 0.0 {
        return Err(MetricError::EmptyMask(""));
    }
    let mse = squared_error_sum(a, b, Some(weights)) / (3.0 * total);
    Ok(psnr_from_mse(mse, data_range))
}

/// The normalised 11-tap Gaussian (σ = 1.5), as scipy's `_gaussian_kernel1d`.
fn gaussian_kernel() -> [f64; SSIM_WINDOW] {
    let mut k = [0.0f64; SSIM_WINDOW];
    for (i, w) in k.iter_mut().enumerate() {
        let x = i as f64 - SSIM_RADIUS as f64;
        *w = (-0.5 * x * x / (SSIM_SIGMA * SSIM_SIGMA)).exp();
    }
    let sum: f64 = k.iter().sum();
    k.map(|w| w / sum)
}

/// scipy `mode='reflect'` index for `i` in `[−radius, n + radius)`, `n > radius`.
fn reflect(i: isize, n: usize) -> usize {
    let n = n as isize;
    if i < 0 {
        (-i - 1) as usize
    } else if i >= n {
        (2 * n - i - 1) as usize
    } else {
        i as usize
    }
}

/// Separable Gaussian blur of a `width × height` row-major plane into `out` (`tmp` is scratch).
fn blur(
    src: &[f64],
    width: usize,
    height: usize,
    kernel: &[f64; SSIM_WINDOW],
    tmp: &mut [f64],
    out: &mut [f64],
) {
    let r = SSIM_RADIUS as isize;
    // Along rows (y) first, as scipy's gaussian_filter does axis 0 first.
    for y in 0..height {
        for x in 0..width {
            let mut acc = 0.0;
            for (k, w) in kernel.iter().enumerate() {
                let yy = reflect(y as isize + k as isize - r, height);
                acc += w * src[yy * width + x];
            }
            tmp[y * width + x] = acc;
        }
    }
    for y in 0..height {
        let row = &tmp[y * width..(y + 1) * width];
        for x in 0..width {
            let mut acc = 0.0;
            for (k, w) in kernel.iter().enumerate() {
                acc += w * row[reflect(x as isize + k as isize - r, width)];
            }
            out[y * width + x] = acc;
        }
    }
}

/// Checks sizes and returns `(width, height)` as `usize`.
fn check_ssim_inputs(
    a: &[[f32; 3]],
    b: &[[f32; 3]],
    width: u32,
    height: u32,
    data_range: f64,
) -> Result<(usize, usize), MetricError> {
    check_data_range(data_range)?;
    let (w, h) = (width as usize, height as usize);
    if a.len() != w * h {
        return Err(MetricError::SizeMismatch(format!(
            "a {width}×{height} image has {} pixels, got {}",
            w * h,
            a.len()
        )));
    }
    check_pair(a, b)?;
    if w < SSIM_WINDOW || h < SSIM_WINDOW {
        return Err(MetricError::TooSmall { width, height });
    }
    Ok((w, h))
}

/// Per-pixel SSIM averaged over the three channels, for the whole image (border included).
fn ssim_channel_mean_map(a: &[[f32; 3]], b: &[[f32; 3]], w: usize, h: usize, data_range: f64) -> Vec<f64> {
    let n = w * h;
    let kernel = gaussian_kernel();
    let c1 = (SSIM_K1 * data_range).powi(2);
    let c2 = (SSIM_K2 * data_range).powi(2);
    let mut map = vec![0.0f64; n];
    let mut tmp = vec![0.0f64; n];
    let mut planes: [Vec<f64>; 5] = std::array::from_fn(|_| vec![0.0f64; n]);
    let mut filtered: [Vec<f64>; 5] = std::array::from_fn(|_| vec![0.0f64; n]);
    for c in 0..3 {
        for (i, (pa, pb)) in a.iter().zip(b).enumerate() {
            let (x, y) = (f64::from(pa[c]), f64::from(pb[c]));
            planes[0][i] = x;
            planes[1][i] = y;
            planes[2][i] = x * x;
            planes[3][i] = y * y;
            planes[4][i] = x * y;
        }
        for (plane, out) in planes.iter().zip(filtered.iter_mut()) {
            blur(plane, w, h, &kernel, &mut tmp, out);
        }
        let [ux, uy, uxx, uyy, uxy] = &filtered;
        for i in 0..n {
            let (mx, my) = (ux[i], uy[i]);
            let vx = uxx[i] - mx * mx;
            let vy = uyy[i] - my * my;
            let vxy = uxy[i] - mx * my;
            let numerator = (2.0 * mx * my + c1) * (2.0 * vxy + c2);
            let denominator = (mx * mx + my * my + c1) * (vx + vy + c2);
            map[i] += numerator / denominator;
        }
    }
    for s in &mut map {
        *s /= 3.0;
    }
    map
}

/// Mean of `map` over the cropped region, weighted by `weights` when given.
fn cropped_mean(map: &[f64], w: usize, h: usize, weights: Option<&[f32]>) -> Result<f64, MetricError> {
    let pad = (SSIM_WINDOW - 1) / 2;
    let mut sum = 0.0f64;
    let mut total = 0.0f64;
    for y in pad..h - pad {
        for x in pad..w - pad {
            let i = y * w + x;
            let weight = weights.map_or(1.0, |wt| f64::from(wt[i]));
            sum += weight * map[i];
            total += weight;
        }
    }
    if total > 0.0 {
        Ok(sum / total)
    } else {
        Err(MetricError::EmptyMask(
            " inside the SSIM crop (5 pixels from each border)",
        ))
    }
}

/// Structural similarity (mean SSIM) of two `width × height` row-major RGB images,
/// as scikit-image's `structural_similarity(a, b, data_range=R, channel_axis=-1,
/// gaussian_weights=True, sigma=1.5, use_sample_covariance=False)`. Identical images
/// give exactly 1. Images must be at least 11 × 11.
pub fn ssim(
    a: &[[f32; 3]],
    b: &[[f32; 3]],
    width: u32,
    height: u32,
    data_range: f64,
) -> Result<f64, MetricError> {
    let (w, h) = check_ssim_inputs(a, b, width, height, data_range)?;
    let map = ssim_channel_mean_map(a, b, w, h, data_range);
    cropped_mean(&map, w, h, None)
}

/// SSIM averaged with per-pixel weights over the cropped region (see the module
/// docs). Weights must be finite and ≥ 0 with a positive sum inside the crop.
pub fn ssim_masked(
    a: &[[f32; 3]],
    b: &[[f32; 3]],
    weights: &[f32],
    width: u32,
    height: u32,
    data_range: f64,
) -> Result<f64, MetricError> {
    let (w, h) = check_ssim_inputs(a, b, width, height, data_range)?;
    check_weights(weights, a.len())?;
    let map = ssim_channel_mean_map(a, b, w, h, data_range);
    cropped_mean(&map, w, h, Some(weights))
}

/// The per-pixel SSIM map, averaged over the three channels, for every pixel
/// (the 5-pixel border that [`ssim`] leaves out included), row-major. For pictures
/// of where two images differ.
pub fn ssim_map(
    a: &[[f32; 3]],
    b: &[[f32; 3]],
    width: u32,
    height: u32,
    data_range: f64,
) -> Result<Vec<f64>, MetricError> {
    let (w, h) = check_ssim_inputs(a, b, width, height, data_range)?;
    Ok(ssim_channel_mean_map(a, b, w, h, data_range))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_exposure_gain_recovers_a_scale_inside_the_masks_only() {
        let truth = vec![
            vec![[0.2f32, 0.4, 0.6], [0.5, 0.5, 0.5]],
            vec![[0.1, 0.1, 0.3], [9.0, 9.0, 9.0]],
        ];
        let renders: Vec<Vec<[f32; 3]>> = vec![
            truth[0].iter().map(|p| p.map(|v| v / 2.5)).collect(),
            vec![[0.04, 0.04, 0.12], [0.0, 0.0, 0.0]],
        ];
        // The last pixel is outside its mask: its mismatch must not count.
        let masks = vec![vec![1.0f32, 1.0], vec![1.0, 0.0]];
        let gain = exposure_gain(&renders, &truth, &masks);
        assert!((gain - 2.5).abs() < 1e-5, "gain {gain}");
        let black = vec![vec![[0.0f32; 3]; 2]; 2];
        assert_eq!(exposure_gain(&black, &truth, &masks), 1.0);
    }

    #[test]
    fn srgb8_scores_compare_with_the_flat_colour_baseline() {
        // A 16 × 16 view: a 8 × 8 square of two colours (mean 0.3, 0.2, 0.1) on black.
        let (w, h) = (16u32, 16u32);
        let mask: Vec<f32> = (0..256)
            .map(|i| {
                f32::from(u8::from(
                    (4..12).contains(&(i % 16)) && (4..12).contains(&(i / 16)),
                ))
            })
            .collect();
        let truth: Vec<[f32; 3]> = (0..256)
            .map(|i| {
                let bright = if i % 2 == 0 { 0.1 } else { -0.1 };
                if mask[i] > 0.5 {
                    [0.3 + bright, 0.2, 0.1]
                } else {
                    [0.0; 3]
                }
            })
            .collect();
        let flat = flat_colour_baseline(&truth, &mask);
        assert!(
            flat[4 * 16 + 4]
                .iter()
                .zip([0.3, 0.2, 0.1])
                .all(|(a, b)| (a - b).abs() < 1e-6)
        );
        assert_eq!(flat[0], [0.0; 3]);
        // The truth scores perfectly; the baseline scores itself perfectly.
        let exact = srgb8_scores(&truth, &truth, &mask, w, h).unwrap();
        assert!(exact.psnr.is_infinite() && exact.foreground_psnr.is_infinite());
        assert!((exact.ssim - 1.0).abs() < 1e-12);
        assert!(exact.flip == 0.0 && exact.foreground_flip == 0.0);
        let baseline = srgb8_scores(&flat, &truth, &mask, w, h).unwrap();
        assert_eq!(baseline.psnr, baseline.flat_psnr);
        assert_eq!(baseline.foreground_psnr, baseline.flat_foreground_psnr);
        assert_eq!(baseline.ssim, baseline.flat_ssim);
        assert_eq!(baseline.flip, baseline.flat_flip);
        assert_eq!(baseline.foreground_flip, baseline.flat_foreground_flip);
        // The black outside is right, so the foreground's ꟻLIP is the larger.
        assert!(baseline.foreground_flip > baseline.flip && baseline.flip > 0.0);
        // Outside the mask both are black, so the whole image scores higher than the
        // foreground alone.
        assert!(baseline.psnr > baseline.foreground_psnr);
        // A black image is worse than the baseline.
        let black = srgb8_scores(&vec![[0.0; 3]; 256], &truth, &mask, w, h).unwrap();
        assert!(black.foreground_psnr < baseline.foreground_psnr);
        assert!(black.foreground_flip > baseline.foreground_flip);
    }

    #[test]
    fn kernel_matches_scipy_radius_and_normalisation() {
        assert_eq!(SSIM_RADIUS, (3.5 * SSIM_SIGMA + 0.5) as usize);
        let k = gaussian_kernel();
        assert!((k.iter().sum::<f64>() - 1.0).abs() < 1e-15);
        assert_eq!(k[0], k[10]);
        assert!(k[5] > k[4] && k[4] > k[0]);
    }

    #[test]
    fn reflect_repeats_the_edge_sample() {
        let got: Vec<usize> = (-3..9).map(|i| reflect(i, 6)).collect();
        assert_eq!(got, [2, 1, 0, 0, 1, 2, 3, 4, 5, 5, 4, 3]);
    }

    #[test]
    fn blur_keeps_constants_and_is_separable() {
        let (w, h) = (13, 12);
        let kernel = gaussian_kernel();
        let src = vec![0.7; w * h];
        let (mut tmp, mut out) = (vec![0.0; w * h], vec![0.0; w * h]);
        blur(&src, w, h, &kernel, &mut tmp, &mut out);
        assert!(out.iter().all(|v| (v - 0.7).abs() < 1e-15));
        // An impulse far from the borders spreads into the outer product of the kernel.
        let mut src = vec![0.0; w * h];
        src[6 * w + 6] = 1.0;
        blur(&src, w, h, &kernel, &mut tmp, &mut out);
        assert!((out[4 * w + 7] - kernel[3] * kernel[6]).abs() < 1e-17);
    }
}

/// Scores of a rendering in 8-bit sRGB (values 0–255 after clamping to [0, 1] and
/// encoding, as a viewer shows them), beside the flat-colour baseline of the same
/// view: the true foreground's mean linear colour inside the true silhouette, black
/// outside. See [`srgb8_scores`].
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Srgb8Scores {
    /// Whole-image PSNR, dB.
    pub psnr: f64,
    /// PSNR inside the mask (`mask > 0.5`), dB.
    pub foreground_psnr: f64,
    /// Whole-image SSIM.
    pub ssim: f64,
    /// The flat-colour baseline's whole-image PSNR, dB.
    pub flat_psnr: f64,
    /// The flat-colour baseline's PSNR inside the mask, dB.
    pub flat_foreground_psnr: f64,
    /// The flat-colour baseline's SSIM.
    pub flat_ssim: f64,
    /// Whole-image mean ꟻLIP ([`crate::flip`], the default observer; lower is better).
    pub flip: f64,
    /// Mean ꟻLIP inside the mask.
    pub foreground_flip: f64,
    /// The flat-colour baseline's whole-image mean ꟻLIP.
    pub flat_flip: f64,
    /// The flat-colour baseline's mean ꟻLIP inside the mask.
    pub flat_foreground_flip: f64,
}

/// Linear RGB as 8-bit sRGB values (0–255, rounded).
pub fn srgb8_values(image: &[[f32; 3]]) -> Vec<[f32; 3]> {
    image
        .iter()
        .map(|c| c.map(|v| (crate::srgb::linear_to_srgb(v.clamp(0.0, 1.0)) * 255.0).round()))
        .collect()
}

/// The one gain `g` minimising `Σ m (g·r − t)²` over every target's pixels and
/// channels (renders `r`, truths `t`, masks `m`): the exposure of an asset whose
/// lighting's scale is unknown. 1 when the renders are black.
pub fn exposure_gain(renders: &[Vec<[f32; 3]>], truths: &[Vec<[f32; 3]>], masks: &[Vec<f32>]) -> f64 {
    let (mut rt, mut rr) = (0.0f64, 0.0f64);
    for ((render, truth), mask) in renders.iter().zip(truths).zip(masks) {
        for ((r, t), m) in render.iter().zip(truth).zip(mask) {
            for c in 0..3 {
                rt += f64::from(*m) * f64::from(r[c]) * f64::from(t[c]);
                rr += f64::from(*m) * f64::from(r[c]) * f64::from(r[c]);
            }
        }
    }
    if rr > 0.0 { rt / rr } else { 1.0 }
}

/// The flat-colour baseline of `truth` (linear, premultiplied over black): the mean
/// of `truth` where `mask > 0.5`, there, and black elsewhere.
pub fn flat_colour_baseline(truth: &[[f32; 3]], mask: &[f32]) -> Vec<[f32; 3]> {
    let inside = mask.iter().filter(|m| **m > 0.5).count().max(1) as f64;
    let mut mean = [0.0f64; 3];
    for (c, m) in truth.iter().zip(mask) {
        if *m > 0.5 {
            for k in 0..3 {
                mean[k] += f64::from(c[k]) / inside;
            }
        }
    }
    let mean = mean.map(|v| v as f32);
    mask.iter()
        .map(|m| if *m > 0.5 { mean } else { [0.0; 3] })
        .collect()
}

/// Scores `image` against `truth` (both linear RGB, `width × height`) in 8-bit sRGB,
/// with `mask` (the true silhouette, > 0.5 inside) for the foreground PSNR and the
/// flat-colour baseline ([`Srgb8Scores`]).
pub fn srgb8_scores(
    image: &[[f32; 3]],
    truth: &[[f32; 3]],
    mask: &[f32],
    width: u32,
    height: u32,
) -> Result<Srgb8Scores, MetricError> {
    let binary: Vec<f32> = mask.iter().map(|m| if *m > 0.5 { 1.0 } else { 0.0 }).collect();
    let want = srgb8_values(truth);
    let flat = srgb8_values(&flat_colour_baseline(truth, mask));
    let got = srgb8_values(image);
    // ꟻLIP of the same 8-bit values (whole numbers 0–255, so the cast is exact).
    let bytes = |values: &[[f32; 3]]| -> Vec<u8> { values.iter().flatten().map(|&v| v as u8).collect() };
    let want_bytes = bytes(&want);
    let flip_of = |values: &[[f32; 3]]| -> Result<(f64, f64), MetricError> {
        let map = crate::flip::flip_map_srgb8(
            &want_bytes,
            &bytes(values),
            width,
            height,
            crate::flip::DEFAULT_PIXELS_PER_DEGREE,
        )?;
        let whole = crate::flip::pooled_mean(&map, None)?.unwrap_or(0.0);
        let foreground = crate::flip::pooled_mean(&map, Some(&binary))?.unwrap_or(0.0);
        Ok((whole, foreground))
    };
    let (flip, foreground_flip) = flip_of(&got)?;
    let (flat_flip, flat_foreground_flip) = flip_of(&flat)?;
    Ok(Srgb8Scores {
        psnr: psnr(&got, &want, 255.0)?,
        foreground_psnr: psnr_masked(&got, &want, &binary, 255.0)?,
        ssim: ssim(&got, &want, width, height, 255.0)?,
        flat_psnr: psnr(&flat, &want, 255.0)?,
        flat_foreground_psnr: psnr_masked(&flat, &want, &binary, 255.0)?,
        flat_ssim: ssim(&flat, &want, width, height, 255.0)?,
        flip,
        foreground_flip,
        flat_flip,
        flat_foreground_flip,
    })
}
