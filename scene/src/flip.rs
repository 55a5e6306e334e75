//! ꟻLIP, the perceptual difference of two images as a person flipping between them
//! sees it (Andersson, Nilsson, Akenine-Möller, Oskarsson, Åström, Fairchild, "FLIP: A
//! Difference Evaluator for Alternating Images", HPG 2020), LDR version: a per-pixel
//! error in `[0, 1]` combining a colour term (in a perceptually uniform space, after
//! spatial filtering by the eye's contrast sensitivity at `pixels_per_degree`) and a
//! feature term (edges and points). The arithmetic is NVIDIA's own implementation,
//! through the `nv-flip` crate; this module converts our linear images to 8-bit sRGB
//! (as every preview is written), checks sizes, and pools the map (mean, or a mean
//! weighted by a mask for foreground-only figures).
//!
//! Checked against NVIDIA's Python package (`pip install flip-evaluator`) on the
//! committed metric fixture (`data/metrics`, see its README).

use crate::metrics::MetricError;
use crate::srgb::linear_to_srgb8;

/// Pixels per degree of visual angle the error is computed for: ꟻLIP's default
/// observer, 0.7 m from a 0.7 m wide 3840-pixel monitor,
/// `0.7 · 3840 / 0.7 · π / 180 = 67.0206` (NVIDIA's tools compute it; `nv-flip`'s own
/// constant rounds it to 67.0, which moves the mean error in the fifth digit).
pub const DEFAULT_PIXELS_PER_DEGREE: f32 = 0.7 * (3840.0 / 0.7) * (std::f32::consts::PI / 180.0);

/// The ꟻLIP error map of two 8-bit sRGB images (row-major RGB, `width × height`).
pub fn flip_map_srgb8(
    reference: &[u8],
    test: &[u8],
    width: u32,
    height: u32,
    pixels_per_degree: f32,
) -> Result<Vec<f32>, MetricError> {
    let n = width as usize * height as usize * 3;
    if n == 0 {
        return Err(MetricError::Empty);
    }
    if reference.len() != n || test.len() != n {
        return Err(MetricError::SizeMismatch(format!(
            "{width}×{height} RGB needs {n} bytes, got {} and {}",
            reference.len(),
            test.len()
        )));
    }
    if !(pixels_per_degree.is_finite() && pixels_per_degree > 0.0) {
        return Err(MetricError::BadDataRange(f64::from(pixels_per_degree)));
    }
    let reference = nv_flip::FlipImageRgb8::with_data(width, height, reference);
    let test = nv_flip::FlipImageRgb8::with_data(width, height, test);
    Ok(nv_flip::flip(reference, test, pixels_per_degree).to_vec())
}

/// Linear RGB → 8-bit sRGB bytes (rounded, clamped), as previews are written.
pub fn to_srgb8(rgb: &[[f32; 3]]) -> Vec<u8> {
    rgb.iter().flatten().map(|&v| linear_to_srgb8(v)).collect()
}

/// The ꟻLIP error map of two linear RGB images, each shown as 8-bit sRGB.
pub fn flip_map(
    reference: &[[f32; 3]],
    test: &[[f32; 3]],
    width: u32,
    height: u32,
    pixels_per_degree: f32,
) -> Result<Vec<f32>, MetricError> {
    flip_map_srgb8(
        &to_srgb8(reference),
        &to_srgb8(test),
        width,
        height,
        pixels_per_degree,
    )
}

/// Mean of an error map, optionally weighted per pixel (a mask or coverage, `w ≥ 0`):
/// `Σ w·e / Σ w`. `None` if the weights sum to zero.
pub fn pooled_mean(map: &[f32], weights: Option<&[f32]>) -> Result<Option<f64>, MetricError> {
    let (sum, total) = match weights {
        None => (map.iter().map(|&e| f64::from(e)).sum::<f64>(), map.len() as f64),
        Some(w) => {
            if w.len() != map.len() {
                return Err(MetricError::SizeMismatch(format!(
                    "{} weights for {} pixels",
                    w.len(),
                    map.len()
                )));
            }
            if let Some(index) = w.iter().position(|v| !v.is_finite() || *v < 0.0) {
                return Err(MetricError::NonFinite { which: "mask", index });
            }
            map.iter().zip(w).fold((0.0, 0.0), |(s, t), (&e, &w)| {
                (s + f64::from(w) * f64::from(e), t + f64::from(w))
            })
        }
    };
    Ok((total > 0.0).then(|| sum / total))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn identical_images_have_zero_error_and_sizes_are_checked() {
        let img: Vec<[f32; 3]> = (0..32 * 24).map(|i| [(i % 7) as f32 / 7.0, 0.3, 0.5]).collect();
        let map = flip_map(&img, &img, 32, 24, DEFAULT_PIXELS_PER_DEGREE).unwrap();
        assert!(map.iter().all(|&e| e == 0.0));
        assert!(flip_map(&img, &img[1..], 32, 24, DEFAULT_PIXELS_PER_DEGREE).is_err());
        assert!(flip_map(&img, &img, 32, 24, 0.0).is_err());
        assert_eq!(
            pooled_mean(&[0.2, 0.4], Some(&[1.0, 3.0])).unwrap(),
            Some((0.2f32 as f64 + 3.0 * 0.4f32 as f64) / 4.0)
        );
        assert_eq!(pooled_mean(&[0.2, 0.4], Some(&[0.0, 0.0])).unwrap(), None);
        assert!(pooled_mean(&[0.2], Some(&[f32::NAN])).is_err());
    }
}
