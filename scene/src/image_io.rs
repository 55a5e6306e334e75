//! Writing images people and programs read back: linear float RGB as OpenEXR,
//! tone-mapped sRGB previews and 8-bit masks as PNG. Every write is atomic
//! (`nelf_format::atomic`): a crash never leaves a half-written file under the
//! final name.

use std::fs::File;
use std::io::BufWriter;
use std::path::Path;

use image::{ImageBuffer, ImageFormat, Luma, Rgb};

use crate::error::SceneError;
use crate::mesh_io::linear_to_srgb8;

fn io_error(path: &Path, source: std::io::Error) -> SceneError {
    SceneError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// Encodes with `encode` into `path` atomically (`nelf_format::atomic`).
pub(crate) fn write_atomic(
    path: &Path,
    encode: impl FnOnce(&mut BufWriter<File>) -> Result<(), image::ImageError>,
) -> Result<(), SceneError> {
    let mut image_error = None;
    nelf_format::atomic::write_atomically(path, |w| {
        encode(w).map_err(|e| {
            let message = e.to_string();
            image_error = Some(e);
            std::io::Error::other(message)
        })
    })
    .map_err(|e| match image_error.take() {
        Some(source) => SceneError::Image {
            path: path.to_path_buf(),
            source,
        },
        None => io_error(path, e),
    })
}

fn size_error(path: &Path, width: u32, height: u32, len: usize) -> SceneError {
    SceneError::Format {
        path: path.to_path_buf(),
        message: format!("{width}×{height} image given {len} pixels"),
    }
}

/// Writes linear RGB radiance as a 32-bit float OpenEXR file.
pub fn write_exr_rgb(
    path: impl AsRef<Path>,
    width: u32,
    height: u32,
    rgb: &[[f32; 3]],
) -> Result<(), SceneError> {
    let path = path.as_ref();
    let data: Vec<f32> = rgb.iter().flatten().copied().collect();
    let buffer = ImageBuffer::<Rgb<f32>, _>::from_raw(width, height, data)
        .ok_or_else(|| size_error(path, width, height, rgb.len()))?;
    write_atomic(path, |w| buffer.write_to(w, ImageFormat::OpenExr))
}

/// Writes linear RGB as an 8-bit sRGB PNG after scaling by `2^exposure_stops`
/// (clamped to `[0, 1]`).
pub fn write_png_srgb(
    path: impl AsRef<Path>,
    width: u32,
    height: u32,
    rgb: &[[f32; 3]],
    exposure_stops: f32,
) -> Result<(), SceneError> {
    let path = path.as_ref();
    let buffer = srgb8(path, width, height, rgb, exposure_stops.exp2())?;
    write_atomic(path, |w| buffer.write_to(w, ImageFormat::Png))
}

/// Linear RGB scaled by `gain` as an 8-bit sRGB image buffer (clamped to `[0, 1]`).
fn srgb8(
    path: &Path,
    width: u32,
    height: u32,
    rgb: &[[f32; 3]],
    gain: f32,
) -> Result<ImageBuffer<Rgb<u8>, Vec<u8>>, SceneError> {
    let data: Vec<u8> = rgb.iter().flatten().map(|&v| linear_to_srgb8(v * gain)).collect();
    ImageBuffer::<Rgb<u8>, _>::from_raw(width, height, data)
        .ok_or_else(|| size_error(path, width, height, rgb.len()))
}

/// Writes linear RGB as an 8-bit sRGB JPEG of the given quality (1–100), as
/// scanners ship textures.
pub fn write_jpeg_srgb(
    path: impl AsRef<Path>,
    width: u32,
    height: u32,
    rgb: &[[f32; 3]],
    quality: u8,
) -> Result<(), SceneError> {
    let path = path.as_ref();
    let buffer = srgb8(path, width, height, rgb, 1.0)?;
    write_atomic(path, |w| {
        image::codecs::jpeg::JpegEncoder::new_with_quality(w, quality.clamp(1, 100)).encode_image(&buffer)
    })
}

/// Writes values in `[0, 1]` (a mask or coverage) as an 8-bit greyscale PNG.
pub fn write_png_gray(
    path: impl AsRef<Path>,
    width: u32,
    height: u32,
    values: &[f32],
) -> Result<(), SceneError> {
    let path = path.as_ref();
    let data: Vec<u8> = values
        .iter()
        .map(|&v| (v.clamp(0.0, 1.0) * 255.0).round() as u8)
        .collect();
    let buffer = ImageBuffer::<Luma<u8>, _>::from_raw(width, height, data)
        .ok_or_else(|| size_error(path, width, height, values.len()))?;
    write_atomic(path, |w| buffer.write_to(w, ImageFormat::Png))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exr_round_trips_exactly_and_png_is_written() {
        let dir = tempfile::tempdir().unwrap();
        let rgb: Vec<[f32; 3]> = (0..12).map(|i| [i as f32 * 0.37, 1e-3, 42.5]).collect();
        let exr = dir.path().join("a.exr");
        write_exr_rgb(&exr, 4, 3, &rgb).unwrap();
        let back = image::open(&exr).unwrap().into_rgb32f();
        assert_eq!((back.width(), back.height()), (4, 3));
        for (p, want) in back.pixels().zip(&rgb) {
            assert_eq!(p.0, *want);
        }
        let png = dir.path().join("m.png");
        write_png_gray(
            &png,
            4,
            3,
            &[0.0, 0.5, 1.0, 2.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0],
        )
        .unwrap();
        let mask = image::open(&png).unwrap().into_luma8();
        assert_eq!(mask.as_raw()[..4], [0, 128, 255, 255]);
        assert!(write_exr_rgb(dir.path().join("bad.exr"), 5, 3, &rgb).is_err());
        // Only the final files remain: no temporaries.
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 2);
    }
}
