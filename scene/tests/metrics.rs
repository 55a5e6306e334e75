//! PSNR and SSIM against scikit-image 0.26 and ꟻLIP against NVIDIA's flip-evaluator
//! (`data/metrics/README.md`), on the
//! full 512 × 512 reference pair and on a non-square crop (which also checks border
//! handling and the masked variants), plus properties.

// Test helpers outside #[test] functions fail the test on setup errors by panicking.
#![allow(clippy::unwrap_used)]

use nelf_scene::metrics::{MetricError, psnr, psnr_masked, ssim, ssim_map, ssim_masked};

const ASTRONAUT: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../data/metrics/astronaut.png");
const ASTRONAUT_NOISY: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../data/metrics/astronaut_noisy.png");

/// 8-bit values / 255 (no sRGB decoding), row-major.
fn load(path: &str) -> (u32, u32, Vec<[f32; 3]>) {
    let image = image::open(path).unwrap().to_rgb8();
    let pixels = image
        .pixels()
        .map(|p| p.0.map(|v| f32::from(v) / 255.0))
        .collect();
    (image.width(), image.height(), pixels)
}

/// Rows `y0..y0+h`, columns `x0..x0+w` of a `width`-wide image.
fn crop(pixels: &[[f32; 3]], width: u32, x0: u32, y0: u32, w: u32, h: u32) -> Vec<[f32; 3]> {
    (y0..y0 + h)
        .flat_map(|y| (x0..x0 + w).map(move |x| (y * width + x) as usize))
        .map(|i| pixels[i])
        .collect()
}

#[test]
fn reproduces_scikit_image_on_the_reference_pair() {
    let (w, h, a) = load(ASTRONAUT);
    let (w2, h2, b) = load(ASTRONAUT_NOISY);
    assert_eq!((w, h, w2, h2), (512, 512, 512, 512));
    let p = psnr(&a, &b, 1.0).unwrap();
    let s = ssim(&a, &b, w, h, 1.0).unwrap();
    eprintln!(
        "astronaut vs astronaut_noisy: PSNR {p:.9} dB (reference 26.506175), SSIM {s:.9} (reference 0.549766)"
    );
    assert!((p - 26.506_175).abs() < 1e-4, "PSNR {p}");
    assert!((s - 0.549_766).abs() < 1e-4, "SSIM {s}");
}

#[test]
fn reproduces_scikit_image_on_a_non_square_crop_with_masks() {
    // Reference values from scikit-image 0.26 / numpy on a[100:137, 200:260] of both
    // images (/255 in float64): peak_signal_noise_ratio, structural_similarity(...,
    // gaussian_weights=True, sigma=1.5, use_sample_covariance=False, full=True);
    // masked figures with weights ((x + 2y) mod 3)/2 as this crate defines them (the
    // full SSIM map's channel mean, cropped by 5, weighted mean).
    let (width, _, a) = load(ASTRONAUT);
    let (_, _, b) = load(ASTRONAUT_NOISY);
    let (w, h) = (60u32, 37u32);
    let a = crop(&a, width, 200, 100, w, h);
    let b = crop(&b, width, 200, 100, w, h);
    let weights: Vec<f32> = (0..h)
        .flat_map(|y| (0..w).map(move |x| ((x + 2 * y) % 3) as f32 / 2.0))
        .collect();
    let close = |got: f64, want: f64, what: &str| {
        assert!((got - want).abs() < 1e-6, "{what}: {got} vs scikit-image {want}");
    };
    close(psnr(&a, &b, 1.0).unwrap(), 26.105_180_043_3, "PSNR");
    close(ssim(&a, &b, w, h, 1.0).unwrap(), 0.646_921_737_2, "SSIM");
    close(
        psnr_masked(&a, &b, &weights, 1.0).unwrap(),
        26.134_915_323_3,
        "masked PSNR",
    );
    close(
        ssim_masked(&a, &b, &weights, w, h, 1.0).unwrap(),
        0.646_832_689_0,
        "masked SSIM",
    );
    // The map's corner depends on the reflect border; an interior pixel on the window.
    let map = ssim_map(&a, &b, w, h, 1.0).unwrap();
    close(map[0], 0.901_158_949_4, "SSIM map (0, 0)");
    close(
        map[20 * w as usize + 33],
        0.664_740_972_8,
        "SSIM map (row 20, column 33)",
    );
}

/// A deterministic pseudo-random image (xorshift).
fn noise_image(pixels: usize, seed: u32) -> Vec<[f32; 3]> {
    let mut state = seed.wrapping_mul(2_654_435_761).max(1);
    let mut next = || {
        state ^= state << 13;
        state ^= state >> 17;
        state ^= state << 5;
        state as f32 / u32::MAX as f32
    };
    (0..pixels).map(|_| [next(), next(), next()]).collect()
}

#[test]
fn identical_images_and_symmetry() {
    let (w, h) = (23u32, 17u32);
    let a = noise_image((w * h) as usize, 1);
    let b: Vec<[f32; 3]> = a
        .iter()
        .zip(noise_image(a.len(), 2))
        .map(|(p, n)| p.map(|v| v + 0.1 * n[0]))
        .collect();
    assert_eq!(psnr(&a, &a, 1.0).unwrap(), f64::INFINITY);
    assert_eq!(ssim(&a, &a, w, h, 1.0).unwrap(), 1.0);
    let ones = vec![1.0f32; a.len()];
    assert_eq!(psnr_masked(&a, &a, &ones, 1.0).unwrap(), f64::INFINITY);
    assert_eq!(ssim_masked(&a, &a, &ones, w, h, 1.0).unwrap(), 1.0);
    // Symmetric, bit for bit.
    assert_eq!(psnr(&a, &b, 1.0).unwrap(), psnr(&b, &a, 1.0).unwrap());
    assert_eq!(ssim(&a, &b, w, h, 1.0).unwrap(), ssim(&b, &a, w, h, 1.0).unwrap());
    let s = ssim(&a, &b, w, h, 1.0).unwrap();
    assert!(s < 1.0 && s > 0.0, "{s}");
    // All-equal weights give exactly the unmasked figures.
    let halves = vec![0.5f32; a.len()];
    assert_eq!(
        psnr_masked(&a, &b, &halves, 1.0).unwrap(),
        psnr(&a, &b, 1.0).unwrap()
    );
    assert_eq!(ssim_masked(&a, &b, &halves, w, h, 1.0).unwrap(), s);
}

#[test]
fn psnr_of_a_known_error_and_data_range() {
    // Every value off by 0.125 (exact in f32): MSE = 1/64, PSNR = 10·log10(64) for R = 1.
    let a = vec![[0.25f32, 0.5, 0.75]; 50];
    let b: Vec<[f32; 3]> = a.iter().map(|p| p.map(|v| v + 0.125)).collect();
    let want = 10.0 * 64f64.log10();
    assert!((psnr(&a, &b, 1.0).unwrap() - want).abs() < 1e-12);
    // Doubling the data range adds 20·log10(2) dB.
    assert!((psnr(&a, &b, 2.0).unwrap() - want - 20.0 * 2f64.log10()).abs() < 1e-12);
    // Errors outside the mask do not count.
    let mut c = a.clone();
    c[7] = [9.0; 3];
    let mut mask = vec![1.0f32; a.len()];
    mask[7] = 0.0;
    assert_eq!(psnr_masked(&a, &c, &mask, 1.0).unwrap(), f64::INFINITY);
}

#[test]
fn ssim_is_invariant_under_transposing_both_images() {
    // The window is isotropic and the border symmetric: catches width/height mix-ups.
    let (w, h) = (29u32, 13u32);
    let a = noise_image((w * h) as usize, 3);
    let b = noise_image((w * h) as usize, 4);
    let transpose = |img: &[[f32; 3]]| -> Vec<[f32; 3]> {
        (0..w)
            .flat_map(|x| (0..h).map(move |y| (y * w + x) as usize))
            .map(|i| img[i])
            .collect()
    };
    let s = ssim(&a, &b, w, h, 1.0).unwrap();
    let t = ssim(&transpose(&a), &transpose(&b), h, w, 1.0).unwrap();
    assert!((s - t).abs() < 1e-12, "{s} vs {t}");
}

#[test]
fn rejects_invalid_inputs() {
    let a = noise_image(12 * 11, 5);
    let b = noise_image(12 * 11, 6);
    assert!(matches!(
        psnr(&a, &b[1..], 1.0),
        Err(MetricError::SizeMismatch(_))
    ));
    assert!(matches!(
        ssim(&a, &b, 11, 11, 1.0),
        Err(MetricError::SizeMismatch(_))
    ));
    assert_eq!(
        ssim(&a[..100], &b[..100], 10, 10, 1.0),
        Err(MetricError::TooSmall {
            width: 10,
            height: 10
        })
    );
    assert!(ssim(&a, &b, 12, 11, 1.0).is_ok());
    assert_eq!(psnr(&a, &b, 0.0), Err(MetricError::BadDataRange(0.0)));
    assert!(matches!(psnr(&[], &[], 1.0), Err(MetricError::Empty)));
    let mut nan = b.clone();
    nan[5][1] = f32::NAN;
    assert_eq!(
        ssim(&a, &nan, 12, 11, 1.0),
        Err(MetricError::NonFinite {
            which: "second image",
            index: 5
        })
    );
    let mut weights = vec![1.0f32; a.len()];
    weights[3] = -1.0;
    assert!(matches!(
        psnr_masked(&a, &b, &weights, 1.0),
        Err(MetricError::NegativeWeight { index: 3, .. })
    ));
    assert!(matches!(
        psnr_masked(&a, &b, &[0.0; 132], 1.0),
        Err(MetricError::EmptyMask(_))
    ));
    // Weight only in the 5-pixel border that SSIM crops away.
    let mut border = vec![0.0f32; a.len()];
    border[0] = 1.0;
    assert!(matches!(
        ssim_masked(&a, &b, &border, 12, 11, 1.0),
        Err(MetricError::EmptyMask(_))
    ));
}

/// ꟻLIP (LDR) against NVIDIA's own Python package, flip-evaluator 1.7
/// (`flip_evaluator.evaluate(reference, test, "LDR")`: mean 0.10292140 at 67.0206 ppd),
/// on the 8-bit sRGB bytes of the reference pair; and a mask pools the same map.
#[test]
fn flip_reproduces_nvidia_flip_evaluator_on_the_reference_pair() {
    use nelf_scene::flip::{DEFAULT_PIXELS_PER_DEGREE, flip_map_srgb8, pooled_mean};
    let bytes = |path: &str| {
        let image = image::open(path).unwrap().to_rgb8();
        (image.width(), image.height(), image.into_raw())
    };
    let (w, h, a) = bytes(ASTRONAUT);
    let (_, _, b) = bytes(ASTRONAUT_NOISY);
    assert!((DEFAULT_PIXELS_PER_DEGREE - 67.020_645).abs() < 1e-4);
    let map = flip_map_srgb8(&a, &b, w, h, DEFAULT_PIXELS_PER_DEGREE).unwrap();
    let mean = pooled_mean(&map, None).unwrap().unwrap();
    eprintln!("astronaut vs astronaut_noisy: FLIP {mean:.8} (flip-evaluator 1.7: 0.10292140)");
    // nv-flip bundles an older FLIP C++ release than flip-evaluator 1.7 and pools in
    // f64 here: they agree to 1e-6; 1e-5 leaves room for either to change rounding.
    assert!((mean - 0.102_921_40).abs() < 1e-5, "FLIP {mean}");
    // Identical images: zero error everywhere.
    assert!(
        flip_map_srgb8(&a, &a, w, h, DEFAULT_PIXELS_PER_DEGREE)
            .unwrap()
            .iter()
            .all(|&e| e == 0.0)
    );
    // Foreground-only: the left half as a mask is the left half's mean.
    let mask: Vec<f32> = (0..w * h)
        .map(|i| if i % w < w / 2 { 1.0 } else { 0.0 })
        .collect();
    let left = pooled_mean(&map, Some(&mask)).unwrap().unwrap();
    let direct = (0..(w * h) as usize)
        .filter(|i| (*i as u32) % w < w / 2)
        .map(|i| f64::from(map[i]))
        .sum::<f64>()
        / f64::from(w / 2 * h);
    assert!((left - direct).abs() < 1e-12);
}
