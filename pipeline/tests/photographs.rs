//! The photographs path end to end on material we did not make: the repository's
//! scanned head (`data/meshes/head.off`, the CGAL head) photographed by the path
//! tracer under a real HDRI, written exactly as a camera and COLMAP give it (8-bit
//! sRGB JPEG, PNG masks, a COLMAP text model, no lighting named), loaded, baked with
//! `--source photos` and scored at a held-aside view under another HDRI after one
//! exposure gain (the exposure of an unnamed lighting is unknowable), beside a flat
//! colour inside the true silhouette; and the same photographs as a camera with odd
//! intrinsics gives them (principal point off-centre, mixed non-square sizes,
//! `fy ≠ fx`) with soft masks.
#![allow(clippy::unwrap_used)] // Test helpers outside #[test] functions unwrap too.

use std::path::PathBuf;

use glam::DMat3;
use nelf_bake::eval::load_held_aside;
use nelf_bake::{
    BakeConfig, CaptureFormat, CaptureLoadOptions, LoadedCapture, Progress, ViewChoice, load_capture,
};
use nelf_format::conventions::PinholeCamera;
use nelf_pipeline::PipelineConfig;
use nelf_pipeline::config::PhotoSettings;
use nelf_pipeline::photo::as_photographs::write_as_photographs;
use nelf_pipeline::photo::bake_photographs;
use nelf_render::{MarchSettings, render_asset};
use nelf_scene::metrics::{Srgb8Scores, exposure_gain, srgb8_scores};
use nelf_scene::synth::{SynthConfig, write_synthetic_capture};

fn data(path: &str) -> PathBuf {
    PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../data")).join(path)
}

/// A capture's views as a camera with odd intrinsics takes them: each view padded
/// off-centre to its own size (principal point off the image centre, mixed and
/// non-square sizes), its rows squeezed by `squeeze` (`fy = squeeze · fx`, as
/// non-square pixels or an anamorphic lens give), bilinear resampling; masks
/// softened by a 3 × 3 box (fractional alpha along the silhouette, as matting tools
/// write them).
fn with_odd_intrinsics(capture: &LoadedCapture, squeeze: f64) -> LoadedCapture {
    let mut odd = capture.clone();
    for v in 0..capture.len() {
        let camera = capture.cameras[v];
        let (w, h) = (camera.width as usize, camera.height as usize);
        let (ox, oy) = (1.0 + 2.0 * v as f64, 5.0 - v as f64);
        let new_w = w + 3 + 2 * v;
        let new_h = (h as f64 * squeeze).round() as usize + 6 + v;
        let sample = |values: &[[f32; 3]], x: f64, y: f64| -> [f32; 3] {
            // Bilinear at continuous pixel coordinates; black outside.
            let (fx, fy) = (x - 0.5, y - 0.5);
            let (x0, y0) = (fx.floor(), fy.floor());
            let (tx, ty) = ((fx - x0) as f32, (fy - y0) as f32);
            let at = |xi: f64, yi: f64| {
                if xi < 0.0 || yi < 0.0 || xi >= w as f64 || yi >= h as f64 {
                    [0.0; 3]
                } else {
                    values[yi as usize * w + xi as usize]
                }
            };
            let (a, b, c, d) = (
                at(x0, y0),
                at(x0 + 1.0, y0),
                at(x0, y0 + 1.0),
                at(x0 + 1.0, y0 + 1.0),
            );
            std::array::from_fn(|k| {
                (a[k] * (1.0 - tx) + b[k] * tx) * (1.0 - ty) + (c[k] * (1.0 - tx) + d[k] * tx) * ty
            })
        };
        let as_rgb: Vec<[f32; 3]> = capture.masks[v].iter().map(|&m| [m; 3]).collect();
        let mut image = Vec::with_capacity(new_w * new_h);
        let mut mask = Vec::with_capacity(new_w * new_h);
        for j in 0..new_h {
            for i in 0..new_w {
                let x = i as f64 + 0.5 - ox;
                let y = (j as f64 + 0.5 - oy) / squeeze;
                image.push(sample(&capture.images[v], x, y));
                mask.push(sample(&as_rgb, x, y)[0]);
            }
        }
        let soft: Vec<f32> = (0..new_w * new_h)
            .map(|k| {
                let (i, j) = ((k % new_w) as i64, (k / new_w) as i64);
                let mut sum = 0.0;
                for (di, dj) in (-1..=1).flat_map(|di| (-1..=1).map(move |dj| (di, dj))) {
                    let (a, b) = (i + di, j + dj);
                    if a >= 0 && b >= 0 && (a as usize) < new_w && (b as usize) < new_h {
                        sum += mask[b as usize * new_w + a as usize];
                    }
                }
                sum / 9.0
            })
            .collect();
        odd.images[v] = image;
        odd.masks[v] = soft;
        odd.cameras[v] = PinholeCamera {
            width: new_w as u32,
            height: new_h as u32,
            fy: camera.fy * squeeze,
            cx: camera.cx + ox,
            cy: camera.cy * squeeze + oy,
            ..camera
        };
    }
    odd
}

/// Writes `capture` as JPEG + PNG masks + COLMAP into `dir`, loads it back, bakes
/// it from its photographs alone and scores the held-aside view of `synth_dir`
/// after one exposure gain.
fn bake_photographed_and_score(
    capture: &LoadedCapture,
    dir: &std::path::Path,
    synth_dir: &std::path::Path,
) -> Srgb8Scores {
    write_as_photographs(capture, dir, 90).unwrap();
    for file in [
        "cameras.txt",
        "images.txt",
        "images/view_000.jpg",
        "masks/view_000.png",
    ] {
        assert!(dir.join(file).is_file(), "missing {file}");
    }
    let photographs = load_capture(
        dir,
        &CaptureLoadOptions {
            format: CaptureFormat::Colmap,
            ..CaptureLoadOptions::default()
        },
    )
    .unwrap();
    assert!(
        photographs.description().is_none(),
        "a COLMAP capture names no lighting"
    );
    for (loaded, written) in photographs.cameras.iter().zip(&capture.cameras) {
        assert_eq!((loaded.width, loaded.height), (written.width, written.height));
        assert!((loaded.fy - written.fy).abs() < 1e-6 && (loaded.cy - written.cy).abs() < 1e-6);
    }
    let config = PipelineConfig::from(BakeConfig {
        resolution: 32,
        view_dependence: ViewChoice::Off,
        ..BakeConfig::default()
    });
    let baked = bake_photographs(
        &photographs,
        None,
        &PhotoSettings::default(),
        &config,
        Progress::hidden(),
    )
    .unwrap();
    assert_eq!(baked.reconstruction.report.lighting.source, "fit");
    assert!(baked.output.asset.validate().is_ok());
    assert!(
        baked.reconstruction.report.surface.note.is_none(),
        "{:?}",
        baked.reconstruction.report.surface.note
    );

    let synthetic = load_capture(synth_dir, &CaptureLoadOptions::default()).unwrap();
    let held = load_held_aside(synthetic.description().unwrap(), synth_dir).unwrap();
    let render = render_asset(
        &baked.output.asset,
        &held.cameras[0],
        &held.envs[0],
        DMat3::IDENTITY,
        None,
        &MarchSettings::default(),
    )
    .unwrap();
    let gain = exposure_gain(std::slice::from_ref(&render.rgb), &held.images, &held.masks) as f32;
    let scaled: Vec<[f32; 3]> = render.rgb.iter().map(|p| p.map(|v| v * gain)).collect();
    let (w, h) = (held.cameras[0].width, held.cameras[0].height);
    let scores = srgb8_scores(&scaled, &held.images[0], &held.masks[0], w, h).unwrap();
    eprintln!("{}: {scores:?}, gain {gain}", dir.display());
    scores
}

#[test]
fn a_scanned_head_photographed_as_jpeg_and_colmap_bakes_above_a_flat_colour() {
    let tmp = tempfile::tempdir().unwrap();
    let synth_dir = tmp.path().join("synthetic");
    let synth = SynthConfig {
        mesh: Some(data("meshes/head.off")),
        mesh_rotate_y_deg: 90.0,
        envmap: Some(data("envmaps/studio.exr")),
        target_envmap: vec![data("envmaps/forest.exr")],
        views: 5,
        targets: 1,
        width: 96,
        height: 96,
        texel_samples: 1,
        indirect_samples: 4,
        bounces: 0,
        ..SynthConfig::default()
    };
    write_synthetic_capture(&synth, &synth_dir, &indicatif::ProgressBar::hidden()).unwrap();
    let synthetic = load_capture(&synth_dir, &CaptureLoadOptions::default()).unwrap();

    let plain = bake_photographed_and_score(&synthetic, &tmp.path().join("photographed"), &synth_dir);
    assert!(
        plain.foreground_psnr > plain.flat_foreground_psnr + 1.0,
        "photographs' bake {:.2} dB in the foreground, flat colour {:.2} dB",
        plain.foreground_psnr,
        plain.flat_foreground_psnr
    );
    // The same photographs as a camera with odd intrinsics and soft masks give
    // them: the same asset, nearly.
    let odd = with_odd_intrinsics(&synthetic, 0.85);
    let odd = bake_photographed_and_score(&odd, &tmp.path().join("odd-intrinsics"), &synth_dir);
    assert!(
        odd.foreground_psnr > plain.foreground_psnr - 1.0
            && odd.foreground_psnr > odd.flat_foreground_psnr + 1.0,
        "odd intrinsics and soft masks: {:.2} dB in the foreground, square centred views {:.2} dB, flat colour {:.2} dB",
        odd.foreground_psnr,
        plain.foreground_psnr,
        odd.flat_foreground_psnr
    );
}
