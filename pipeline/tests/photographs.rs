//! The photographs path end to end on material we did not make: the repository's
//! scanned head (`data/meshes/head.off`, the CGAL head) photographed by the path
//! tracer under a real HDRI, written exactly as a camera and COLMAP give it (8-bit
//! sRGB JPEG, PNG masks, a COLMAP text model, no lighting named), loaded, baked with
//! `--source photos` and scored at a held-aside view under another HDRI after one
//! exposure gain (the exposure of an unnamed lighting is unknowable), beside a flat
//! colour inside the true silhouette.
#![allow(clippy::unwrap_used)] // Test helpers outside #[test] functions unwrap too.

use std::path::PathBuf;

use glam::DMat3;
use nelf_bake::eval::load_held_aside;
use nelf_bake::{BakeConfig, CaptureFormat, CaptureLoadOptions, Progress, ViewChoice, load_capture};
use nelf_pipeline::PipelineConfig;
use nelf_pipeline::config::PhotoSettings;
use nelf_pipeline::photo::as_photographs::write_as_photographs;
use nelf_pipeline::photo::bake_photographs;
use nelf_render::{MarchSettings, render_asset};
use nelf_scene::metrics::{exposure_gain, srgb8_scores};
use nelf_scene::synth::{SynthConfig, write_synthetic_capture};

fn data(path: &str) -> PathBuf {
    PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../data")).join(path)
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

    let photographed_dir = tmp.path().join("photographed");
    write_as_photographs(&synthetic, &photographed_dir, 90).unwrap();
    for file in [
        "cameras.txt",
        "images.txt",
        "images/view_000.jpg",
        "masks/view_000.png",
    ] {
        assert!(photographed_dir.join(file).is_file(), "missing {file}");
    }
    let photographs = load_capture(
        &photographed_dir,
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

    let held = load_held_aside(synthetic.description().unwrap(), &synth_dir).unwrap();
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
    eprintln!("{scores:?}, gain {gain}");
    assert!(
        scores.foreground_psnr > scores.flat_foreground_psnr + 1.0,
        "photographs' bake {:.2} dB in the foreground, flat colour {:.2} dB",
        scores.foreground_psnr,
        scores.flat_foreground_psnr
    );
}
