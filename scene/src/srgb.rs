//! The sRGB transfer function (IEC 61966-2-1) between linear values and encoded
//! ones: what 8-bit textures, vertex colours, previews and ꟻLIP inputs are in. A
//! leaf module: the mesh loaders and every image writer use it.

/// sRGB-encoded value in `[0, 1]` to linear (IEC 61966-2-1).
pub fn srgb_to_linear(encoded: f32) -> f32 {
    let c = encoded.clamp(0.0, 1.0);
    if c <= 0.040_45 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// Linear value to sRGB-encoded in `[0, 1]` (IEC 61966-2-1), clamping.
pub fn linear_to_srgb(linear: f32) -> f32 {
    let c = if linear.is_nan() {
        0.0
    } else {
        linear.clamp(0.0, 1.0)
    };
    if c <= 0.003_130_8 {
        12.92 * c
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    }
}

/// Linear value to an 8-bit sRGB code (rounded; clamped like [`linear_to_srgb`]): the
/// byte every preview, JPEG texture and ꟻLIP input holds.
pub fn linear_to_srgb8(linear: f32) -> u8 {
    (linear_to_srgb(linear) * 255.0).round() as u8
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn srgb_round_trip() {
        for i in 0..=20 {
            let x = i as f32 / 20.0;
            assert!((linear_to_srgb(srgb_to_linear(x)) - x).abs() < 1e-5);
        }
        assert!((srgb_to_linear(0.5) - 0.214).abs() < 1e-3);
    }
}
