//! Measures a baked asset against its capture (not a test): renders the asset with
//! the reference renderer at every source view under the capture's lighting and at
//! every held-aside target view under that target's lighting, at full resolution,
//! and prints PSNR and SSIM against the capture's images (both over black; data
//! range = the reference image's largest value).
//!
//! `cargo run --release -p nelf-bake --example bake_eval -- ASSET CAPTURE_DIR [--out DIR]`
//!
//! With `--out`, sRGB previews of each render and its reference are written there.

use std::path::{Path, PathBuf};

use glam::DMat3;
use nelf_bake::{CaptureLoadOptions, load_capture};
use nelf_format::conventions::{LatLong, PinholeCamera};
use nelf_format::read_asset;
use nelf_render::{MarchSettings, render_asset};
use nelf_scene::envmap::load_envmap;
use nelf_scene::image_io::write_png_srgb;
use nelf_scene::metrics::{psnr, ssim};

type Error = Box<dyn std::error::Error>;

fn load_linear(path: &Path) -> Result<(u32, u32, Vec<[f32; 3]>), Error> {
    let img = image::open(path)?.to_rgb32f();
    Ok((img.width(), img.height(), img.pixels().map(|p| p.0).collect()))
}

struct Row {
    name: String,
    psnr: f64,
    ssim: f64,
}

fn measure(
    asset: &nelf_format::Asset,
    camera: &PinholeCamera,
    env: &LatLong,
    reference: &[[f32; 3]],
    name: &str,
    out: Option<&Path>,
) -> Result<Row, Error> {
    let image = render_asset(
        asset,
        camera,
        env,
        DMat3::IDENTITY,
        None,
        &MarchSettings::default(),
    )?;
    let range = reference
        .iter()
        .flatten()
        .fold(0.0f32, |m, &v| m.max(v))
        .max(1e-6);
    let p = psnr(&image.rgb, reference, f64::from(range))?;
    let s = ssim(
        &image.rgb,
        reference,
        camera.width,
        camera.height,
        f64::from(range),
    )?;
    if let Some(dir) = out {
        let stops = (0.5 / range).log2();
        write_png_srgb(
            dir.join(format!("{name}_render.png")),
            camera.width,
            camera.height,
            &image.rgb,
            stops,
        )?;
        write_png_srgb(
            dir.join(format!("{name}_truth.png")),
            camera.width,
            camera.height,
            reference,
            stops,
        )?;
    }
    Ok(Row {
        name: name.to_string(),
        psnr: p,
        ssim: s,
    })
}

fn main() -> Result<(), Error> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() < 2 {
        return Err("usage: bake_eval ASSET CAPTURE_DIR [--out DIR]".into());
    }
    let asset = read_asset(Path::new(&args[0]))?;
    let dir = PathBuf::from(&args[1]);
    let out = args
        .iter()
        .position(|a| a == "--out")
        .and_then(|i| args.get(i + 1))
        .map(PathBuf::from);
    if let Some(o) = &out {
        std::fs::create_dir_all(o)?;
    }
    let capture = load_capture(&dir, &CaptureLoadOptions::default())?;
    let mut rows = Vec::new();
    if let Some(path) = capture.source_envmap_path() {
        let env = load_envmap(&path)?;
        for ((name, cam), img) in capture.names.iter().zip(&capture.cameras).zip(&capture.images) {
            rows.push(measure(&asset, cam, &env, img, name, out.as_deref())?);
        }
    }
    if let Some(desc) = capture.description() {
        for t in &desc.targets {
            let env = load_envmap(t.envmap_path(&dir))?;
            let (_, _, img) = load_linear(&t.image_path(&dir))?;
            rows.push(measure(&asset, &t.camera, &env, &img, &t.name, out.as_deref())?);
        }
    }
    println!("| view | PSNR (dB) | SSIM |");
    println!("| --- | --- | --- |");
    for r in &rows {
        println!("| {} | {:.2} | {:.4} |", r.name, r.psnr, r.ssim);
    }
    Ok(())
}
