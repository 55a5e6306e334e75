//! Writing images people and programs read back: linear float RGB as OpenEXR,
//! tone-mapped sRGB previews and 8-bit masks as PNG. Every write is atomic
//! (`nelf_format::atomic`): a crash never leaves a half-written file under the
//! final name.

use std::io::Error as IoError;
use std::path::Path;

use image::{ImageBuffer, ImageFormat, Luma, Rgb};
use nelf_format::atomic::write_atomically;

use crate::error::SceneError;
use crate::srgb::linear_to_srgb8;

/// The error of an image written through `nelf_format::atomic`, naming `path`: the
/// encoder's own failure (passed through as [`std::io::Error::other`]) as
/// [`SceneError::Image`], any other I/O failure as [`SceneError::Io`].
pub(crate) fn image_write_error(path: &Path, error: std::io::Error) -> SceneError {
    match error.downcast::<image::ImageError>() {
        Ok(source) => SceneError::Image {
            path: path.to_path_buf(),
            source,
        },
        Err(error) => SceneError::io(path, error),
    }
}

fn size_error(path: &Path, width: u32, height: u32, len: usize) -> SceneError {
    SceneError::Format {
        path: path.to_path_buf(),
        message: format!("{width}×{height} image given {len} pixels"),
    }
}

/// The two kinds of image a render is written as, chosen by the file's extension.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RenderImageKind {
    /// `.png`: 8-bit sRGB, scaled by `2^exposure` and clamped ([`write_png_srgb`]).
    Png,
    /// `.exr`: the linear radiance as rendered, exposure not applied ([`write_exr_rgb`]).
    Exr,
}

impl RenderImageKind {
    /// The kind `path`'s extension names (case-insensitive), or an error naming the
    /// file: checked before anything is rendered.
    pub fn of_path(path: &Path) -> Result<Self, SceneError> {
        match path
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase)
            .as_deref()
        {
            Some("png") => Ok(Self::Png),
            Some("exr") => Ok(Self::Exr),
            _ => Err(SceneError::UnsupportedExtension {
                path: path.to_path_buf(),
                expected: ".png or .exr",
            }),
        }
    }

    /// Writes linear RGB (`width × height`) to `path` as this kind.
    pub fn write(
        self,
        path: &Path,
        width: u32,
        height: u32,
        rgb: &[[f32; 3]],
        exposure_stops: f32,
    ) -> Result<(), SceneError> {
        match self {
            Self::Png => write_png_srgb(path, width, height, rgb, exposure_stops),
            Self::Exr => write_exr_rgb(path, width, height, rgb),
        }
    }
}

/// Writes linear RGB radiance as a 32-bit float OpenEXR file. Its blocks are
/// compressed one after another (`non_parallel`): the `image` crate's encoder
/// compresses them on several threads and stores them in the order they finish,
/// so the same pixels gave different bytes from run to run.
pub fn write_exr_rgb(
    path: impl AsRef<Path>,
    width: u32,
    height: u32,
    rgb: &[[f32; 3]],
) -> Result<(), SceneError> {
    use exr::prelude::{Image, SpecificChannels, WritableImage};
    let path = path.as_ref();
    if rgb.len() != width as usize * height as usize {
        return Err(size_error(path, width, height, rgb.len()));
    }
    let w = width as usize;
    let image = Image::from_channels(
        (w, height as usize),
        SpecificChannels::rgb(|p: exr::math::Vec2<usize>| {
            let [r, g, b] = rgb[p.y() * w + p.x()];
            (r, g, b)
        }),
    );
    write_atomically(path, |out| {
        image
            .write()
            .non_parallel()
            .to_buffered(out)
            .map_err(IoError::other)
    })
    .map_err(|e| image_write_error(path, e))
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
    write_atomically(path, |w| {
        buffer.write_to(w, ImageFormat::Png).map_err(IoError::other)
    })
    .map_err(|e| image_write_error(path, e))
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
    write_atomically(path, |w| {
        image::codecs::jpeg::JpegEncoder::new_with_quality(w, quality.clamp(1, 100))
            .encode_image(&buffer)
            .map_err(IoError::other)
    })
    .map_err(|e| image_write_error(path, e))
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
    write_atomically(path, |w| {
        buffer.write_to(w, ImageFormat::Png).map_err(IoError::other)
    })
    .map_err(|e| image_write_error(path, e))
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

    #[test]
    fn write_errors_name_the_file_and_keep_the_encoder_error() {
        let dir = tempfile::tempdir().unwrap();
        // The PNG encoder refuses an empty image: an image error, naming the file.
        let empty = dir.path().join("empty.png");
        let err = write_png_gray(&empty, 0, 0, &[]).unwrap_err();
        assert!(
            matches!(&err, SceneError::Image { path, .. } if *path == empty),
            "{err:?}"
        );
        assert!(err.to_string().starts_with(&empty.display().to_string()), "{err}");
        // A missing folder: an I/O error, naming the file.
        let missing = dir.path().join("no/such/mask.png");
        let err = write_png_gray(&missing, 1, 1, &[0.5]).unwrap_err();
        assert!(
            matches!(&err, SceneError::Io(nelf_format::io_error::FileIoError { path, .. }) if *path == missing),
            "{err:?}"
        );
        assert_eq!(
            std::fs::read_dir(dir.path()).unwrap().count(),
            0,
            "no temporaries"
        );
    }
}
