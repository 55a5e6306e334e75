//! Rows, points, images and an SVG check the report modules' tests share.

use std::path::Path;

use crate::rows::{ParetoRow, Scores, StabilityPoint};

pub(super) type TestResult = Result<(), Box<dyn std::error::Error>>;

pub(super) fn row(id: &str, bytes: u64, psnr: f64, frame: Option<f64>) -> ParetoRow {
    ParetoRow {
        id: id.into(),
        resolution: 128,
        rank: 16,
        encoding: "u8".into(),
        voxels: 1000,
        file_bytes: bytes,
        bake_secs: 2.5,
        scores: Scores {
            psnr_db: psnr,
            psnr_fg_db: psnr - 3.0,
            ssim: 0.9,
            ssim_fg: 0.8,
            flip: 0.1 - psnr / 1000.0,
            flip_fg: 0.2,
            baseline_psnr_db: 12.0,
            baseline_psnr_fg_db: 9.0,
            views: 4,
        },
        cpu_render_ms: 120.0,
        gpu_frame_ms_512: frame,
        gpu_frame_ms_1080p: None,
        gpu_adapter: frame.map(|_| "Test GPU".into()),
        thumbnail: None,
        front_bytes: false,
        front_frame: false,
    }
}

pub(super) fn point(axis: &str, value: f64, label: &str, psnr: f64) -> StabilityPoint {
    StabilityPoint {
        axis: axis.into(),
        value,
        label: label.into(),
        scores: Scores {
            psnr_db: psnr,
            psnr_fg_db: psnr - 2.0,
            baseline_psnr_db: 11.0,
            views: 3,
            ..Scores::default()
        },
        worst_psnr_db: psnr - 4.0,
        gallery: None,
        failure: None,
    }
}

/// Whether `svg` holds `text` as the content of a `<text>` element.
pub(super) fn has_text_element(svg: &str, text: &str) -> bool {
    svg.split("<text").skip(1).any(|element| {
        element
            .split_once('>')
            .and_then(|(_, rest)| rest.split_once("</text>"))
            .is_some_and(|(content, _)| content.trim() == text)
    })
}

pub(super) fn tiny_png(path: &Path) -> TestResult {
    let img = image::RgbImage::from_fn(2, 2, |x, y| image::Rgb([x as u8 * 200, y as u8 * 200, 7]));
    img.save(path)?;
    Ok(())
}
