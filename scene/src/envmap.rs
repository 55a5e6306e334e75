//! Environment maps: loading lat-long HDR images (OpenEXR, including DWAB, and
//! Radiance `.hdr`) into [`LatLong`], projecting them into the 8 × 16
//! light-transport basis with [`nelf_format::conventions::project_envmap`], and
//! writing tone-mapped sRGB previews for people.
//!
//! Files are taken as stored: row 0 is the zenith and the image centre looks
//! along −z, which is the layout of standard equirectangular HDRIs (checked on
//! `data/envmaps/*.exr`: sky at the top). Radiance is linear; negative
//! values (DWA compression leaves small ones) and NaN/∞ become 0, so every map we
//! return is finite and non-negative.

use std::path::Path;

use nelf_format::conventions::{ENV_H, ENV_W, LatLong, project_envmap, rotation_y};
use nelf_format::envmap_file::{EnvmapKind, decode_envmap};

use crate::error::SceneError;
use crate::srgb::linear_to_srgb8;

pub use nelf_format::envmap_file::sanitize_radiance;

/// Loads a lat-long environment map from `.exr` (first layer with R, G, B
/// channels, largest resolution level; any compression the `exr` crate reads,
/// DWAB included) or `.hdr` (Radiance RGBE), sanitising every texel
/// ([`sanitize_radiance`]). The extension chooses the reader (any case); the bytes
/// are decoded by [`nelf_format::envmap_file::decode_envmap`], as in the web viewer.
pub fn load_envmap(path: impl AsRef<Path>) -> Result<LatLong, SceneError> {
    let path = path.as_ref();
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let kind = EnvmapKind::from_name(&name).map_err(|_| SceneError::UnsupportedExtension {
        path: path.to_path_buf(),
        expected: ".exr or .hdr",
    })?;
    let bytes = std::fs::read(path).map_err(|e| SceneError::io(path, e))?;
    decode_envmap(&bytes, kind).map_err(|e| SceneError::format(path, e.to_string()))
}

/// One file of [`envmaps_in_dir`]: its path, and its map or why it did not load.
pub type EnvmapFile = (std::path::PathBuf, Result<LatLong, SceneError>);

/// The environment maps in folder `dir` (its `.exr` and `.hdr` files, any case, in
/// name order), each loaded ([`load_envmap`]) or with the error that stopped it, so a
/// caller can keep the good ones and say which were skipped. An unreadable folder is
/// an error naming it.
pub fn envmaps_in_dir(dir: &Path) -> Result<Vec<EnvmapFile>, SceneError> {
    let mut files: Vec<std::path::PathBuf> = std::fs::read_dir(dir)
        .map_err(|e| SceneError::io(dir, e))?
        .filter_map(Result::ok)
        .map(|e| e.path())
        .filter(|p| {
            p.extension()
                .is_some_and(|e| e.eq_ignore_ascii_case("exr") || e.eq_ignore_ascii_case("hdr"))
        })
        .collect();
    files.sort();
    Ok(files
        .into_iter()
        .map(|path| {
            let env = load_envmap(&path);
            (path, env)
        })
        .collect())
}

/// Projects `env` (any resolution, in the world frame) into the 8 × 16 basis of a
/// light frame equal to the world frame, after turning the environment by
/// `rotate_y_deg` degrees about +y (right-handed; a feature at azimuth φ moves to
/// φ − angle). Area-weighted and exact for these rotations, so `Σ Ω L` is kept.
/// A non-finite angle is treated as 0.
pub fn envmap_to_basis(env: &LatLong, rotate_y_deg: f32) -> LatLong {
    let degrees = if rotate_y_deg.is_finite() {
        f64::from(rotate_y_deg)
    } else {
        0.0
    };
    // project_envmap wants env_from_light = world_from_envᵀ · world_from_light,
    // with world_from_env = R_y(angle) and world_from_light = I.
    let env_from_light = rotation_y(degrees.to_radians()).transpose();
    // A rotation about +y of a finite angle always passes project_envmap's check.
    project_envmap(env, env_from_light).unwrap_or_else(|_| LatLong::constant(ENV_W, ENV_H, [0.0; 3]))
}

/// Rec. 709 luminance of a linear RGB radiance.
pub fn luminance(rgb: [f32; 3]) -> f32 {
    0.2126 * rgb[0] + 0.7152 * rgb[1] + 0.0722 * rgb[2]
}

/// An exposure (stops) for previews: maps the solid-angle-weighted mean luminance
/// of `env` to 0.18 (mid grey). 0 for a black map.
pub fn auto_exposure(env: &LatLong) -> f32 {
    let [r, g, b] = env.integral();
    let mean = luminance([r as f32, g as f32, b as f32]) / (4.0 * std::f32::consts::PI);
    if mean > 0.0 && mean.is_finite() {
        (0.18 / mean).log2()
    } else {
        0.0
    }
}

/// Tone-maps `env` for a person: radiance × 2^`exposure_stops`, clamped to
/// `[0, 1]`, sRGB-encoded, 8 bits, at the map's own resolution.
pub fn envmap_preview_rgb8(env: &LatLong, exposure_stops: f32) -> image::RgbImage {
    let gain = exposure_stops.exp2();
    let mut out = image::RgbImage::new(env.width() as u32, env.height() as u32);
    for (pixel, texel) in out.pixels_mut().zip(env.texels()) {
        pixel.0 = texel.map(|v| linear_to_srgb8(v * gain));
    }
    out
}

/// Writes a tone-mapped sRGB PNG preview of `env` ([`envmap_preview_rgb8`]).
/// Maps narrower than 256 texels are enlarged by an integer factor (nearest) so
/// that the 8 × 16 basis is visible; larger ones are written at their resolution.
pub fn save_envmap_preview(
    path: impl AsRef<Path>,
    env: &LatLong,
    exposure_stops: f32,
) -> Result<(), SceneError> {
    let path = path.as_ref();
    let mut preview = envmap_preview_rgb8(env, exposure_stops);
    let factor = 256usize.div_ceil(env.width()).max(1) as u32;
    if factor > 1 {
        preview = image::imageops::resize(
            &preview,
            preview.width() * factor,
            preview.height() * factor,
            image::imageops::FilterType::Nearest,
        );
    }
    let format = image::ImageFormat::from_path(path).map_err(|source| SceneError::Image {
        path: path.to_path_buf(),
        source,
    })?;
    nelf_format::atomic::write_atomically(path, |w| {
        preview.write_to(w, format).map_err(std::io::Error::other)
    })
    .map_err(|e| crate::image_io::image_write_error(path, e))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::srgb::linear_to_srgb;

    #[test]
    fn sanitize_clamps_bad_values() {
        assert_eq!(sanitize_radiance(-1e-3), 0.0);
        assert_eq!(sanitize_radiance(f32::NAN), 0.0);
        assert_eq!(sanitize_radiance(f32::INFINITY), 0.0);
        assert_eq!(sanitize_radiance(2.5), 2.5);
    }

    #[test]
    fn basis_turn_moves_features_to_smaller_azimuth() {
        // One bright column at φ ∈ [0, 2π/16) (col 8 of 16); turning by one column
        // (22.5°) moves it to col 7.
        let mut texels = vec![[0.0f32; 3]; ENV_W * ENV_H];
        for row in 0..ENV_H {
            texels[row * ENV_W + 8] = [1.0; 3];
        }
        let env = LatLong::new(ENV_W, ENV_H, texels).unwrap();
        let turned = envmap_to_basis(&env, 22.5);
        for row in 0..ENV_H {
            assert!((turned.get(row, 7)[0] - 1.0).abs() < 1e-5);
            assert!(turned.get(row, 8)[0].abs() < 1e-5);
        }
    }

    #[test]
    fn auto_exposure_maps_constant_to_mid_grey() {
        let env = LatLong::constant(8, 4, [2.0; 3]);
        let stops = auto_exposure(&env);
        assert!((2.0 * stops.exp2() - 0.18).abs() < 1e-4);
        let preview = envmap_preview_rgb8(&env, stops);
        let expected = (linear_to_srgb(0.18) * 255.0).round() as u8;
        assert!(preview.pixels().all(|p| p.0 == [expected; 3]));
    }
}
