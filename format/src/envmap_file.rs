//! Environment-map files decoded from bytes into a [`LatLong`]: OpenEXR (the first
//! layer with R, G, B channels, its largest resolution level, any compression the `exr`
//! crate reads, DWAB included) and Radiance RGBE (`.hdr`). Every texel is sanitised
//! ([`sanitize_radiance`]): NaN, ±∞ and negatives (DWA leaves small ones) become 0.
//!
//! Bytes, not paths, so that every reader of a map decodes it the same way: the native
//! tools (`nelf_scene::envmap::load_envmap` reads the file and calls [`decode_envmap`])
//! and the web viewer, which receives maps by fetch or drag-and-drop.

use std::io::Cursor;

use exr::prelude::{ReadChannels, ReadLayers};

use crate::conventions::LatLong;

/// Why an environment-map file could not be decoded.
#[derive(Debug, thiserror::Error)]
pub enum EnvmapFileError {
    /// The name does not end in `.exr` or `.hdr`.
    #[error("unsupported environment map {name:?} (expected .exr or .hdr)")]
    UnsupportedExtension {
        /// The file name given.
        name: String,
    },
    /// The OpenEXR decoder failed.
    #[error("{0}")]
    Exr(#[from] exr::error::Error),
    /// The Radiance HDR decoder failed.
    #[error("{0}")]
    Image(#[from] image::ImageError),
    /// The image decoded but is no usable lat-long map (e.g. empty).
    #[error("not a usable lat-long image: {0}")]
    NotLatLong(String),
}

/// The two file kinds we read.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EnvmapKind {
    /// OpenEXR.
    Exr,
    /// Radiance RGBE.
    RadianceHdr,
}

impl EnvmapKind {
    /// The kind a file name's extension names (any case).
    pub fn from_name(name: &str) -> Result<Self, EnvmapFileError> {
        let extension = std::path::Path::new(name).extension().and_then(|e| e.to_str());
        match extension {
            Some(e) if e.eq_ignore_ascii_case("exr") => Ok(Self::Exr),
            Some(e) if e.eq_ignore_ascii_case("hdr") => Ok(Self::RadianceHdr),
            _ => Err(EnvmapFileError::UnsupportedExtension {
                name: name.to_owned(),
            }),
        }
    }
}

/// A radiance value made usable: NaN, ±∞ and negatives become 0.
pub fn sanitize_radiance(value: f32) -> f32 {
    if value.is_finite() && value > 0.0 {
        value
    } else {
        0.0
    }
}

/// Decodes an environment map of the given kind from the file's bytes.
pub fn decode_envmap(bytes: &[u8], kind: EnvmapKind) -> Result<LatLong, EnvmapFileError> {
    let (width, height, texels) = match kind {
        EnvmapKind::Exr => decode_exr(bytes)?,
        EnvmapKind::RadianceHdr => decode_radiance_hdr(bytes)?,
    };
    LatLong::new(width, height, texels).map_err(|e| EnvmapFileError::NotLatLong(e.to_string()))
}

/// Pixels of an EXR being read: width, row-major RGB.
struct ExrPixels {
    width: usize,
    texels: Vec<[f32; 3]>,
}

/// Storage for an EXR of `resolution` pixels.
fn new_exr_pixels(resolution: exr::math::Vec2<usize>, _channels: &exr::prelude::RgbaChannels) -> ExrPixels {
    ExrPixels {
        width: resolution.width(),
        texels: vec![[0.0; 3]; resolution.width() * resolution.height()],
    }
}

/// Stores one EXR pixel, sanitised.
fn set_exr_pixel(
    pixels: &mut ExrPixels,
    position: exr::math::Vec2<usize>,
    (r, g, b, _a): (f32, f32, f32, f32),
) {
    let index = position.y() * pixels.width + position.x();
    if let Some(texel) = pixels.texels.get_mut(index) {
        *texel = [r, g, b].map(sanitize_radiance);
    }
}

/// The first RGB(A) layer of an OpenEXR file, largest level.
fn decode_exr(bytes: &[u8]) -> Result<(usize, usize, Vec<[f32; 3]>), EnvmapFileError> {
    let image = exr::prelude::read()
        .no_deep_data()
        .largest_resolution_level()
        .rgba_channels(new_exr_pixels, set_exr_pixel)
        .first_valid_layer()
        .all_attributes()
        .from_buffered(Cursor::new(bytes))?;
    let size = image.layer_data.size;
    Ok((
        size.width(),
        size.height(),
        image.layer_data.channel_data.pixels.texels,
    ))
}

/// A Radiance RGBE file, with the `image` crate.
fn decode_radiance_hdr(bytes: &[u8]) -> Result<(usize, usize, Vec<[f32; 3]>), EnvmapFileError> {
    let image = image::load_from_memory_with_format(bytes, image::ImageFormat::Hdr)?.into_rgb32f();
    let (width, height) = (image.width() as usize, image.height() as usize);
    let texels = image.pixels().map(|p| p.0.map(sanitize_radiance)).collect();
    Ok((width, height, texels))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_extension_chooses_the_decoder_and_others_are_refused() {
        assert_eq!(EnvmapKind::from_name("studio.EXR").ok(), Some(EnvmapKind::Exr));
        assert_eq!(
            EnvmapKind::from_name("a/b.hdr").ok(),
            Some(EnvmapKind::RadianceHdr)
        );
        let err = EnvmapKind::from_name("sky.png").unwrap_err().to_string();
        assert!(err.contains("sky.png") && err.contains(".exr"), "{err}");
    }

    #[test]
    fn damaged_bytes_are_errors_not_panics() {
        for kind in [EnvmapKind::Exr, EnvmapKind::RadianceHdr] {
            assert!(decode_envmap(b"not an image at all", kind).is_err());
            assert!(decode_envmap(&[], kind).is_err());
        }
    }

    #[test]
    fn sanitising_keeps_only_finite_positive_radiance() {
        assert_eq!(sanitize_radiance(2.5), 2.5);
        for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY, -1e-3, 0.0] {
            assert_eq!(sanitize_radiance(bad), 0.0);
        }
    }
}
