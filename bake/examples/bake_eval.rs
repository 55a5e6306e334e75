//! Measures a baked asset against its capture (not a test): renders the asset with
//! the reference renderer at every source view under the capture's lighting and at
//! every held-aside target view under that target's lighting, at full resolution,
//! and prints PSNR, SSIM and render seconds against the capture's images
//! ([`nelf_bake::eval::score_view`]: both over black, data range = the reference
//! image's largest value), then the means over source and over target views.
//!
//! `cargo run --release -p nelf-bake --example bake_eval -- ASSET CAPTURE_DIR [--out DIR] [--json]`
//!
//! With `--out`, sRGB previews of each render and its reference are written there;
//! with `--json`, the rows are printed as one JSON object instead of a table.

use std::path::{Path, PathBuf};

use nelf_bake::eval::{ViewScore, data_range, read_linear_rgb, score_view};
use nelf_bake::{CaptureLoadOptions, load_capture};
use nelf_format::conventions::{LatLong, PinholeCamera};
use nelf_format::read_asset;
use nelf_scene::envmap::load_envmap;
use nelf_scene::image_io::write_png_srgb;

type Error = Box<dyn std::error::Error>;

fn measure(
    asset: &nelf_format::Asset,
    camera: &PinholeCamera,
    env: &LatLong,
    reference: &[[f32; 3]],
    name: &str,
    out: Option<&Path>,
) -> Result<ViewScore, Error> {
    let (score, image) = score_view(asset, camera, env, reference, name)?;
    if let Some(dir) = out {
        let stops = (0.5 / data_range(reference)).log2();
        for (suffix, rgb) in [("render", &image.rgb[..]), ("truth", reference)] {
            write_png_srgb(
                dir.join(format!("{name}_{suffix}.png")),
                camera.width,
                camera.height,
                rgb,
                stops,
            )?;
        }
    }
    Ok(score)
}

fn mean(scores: &[ViewScore]) -> Option<(f64, f64, f64)> {
    let n = scores.len() as f64;
    (!scores.is_empty()).then(|| {
        (
            scores.iter().map(|s| s.psnr_db).sum::<f64>() / n,
            scores.iter().map(|s| s.ssim).sum::<f64>() / n,
            scores.iter().map(|s| s.render_secs).sum::<f64>() / n,
        )
    })
}

fn main() -> Result<(), Error> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() < 2 {
        return Err("usage: bake_eval ASSET CAPTURE_DIR [--out DIR] [--json]".into());
    }
    let asset = read_asset(Path::new(&args[0]))?;
    let dir = PathBuf::from(&args[1]);
    let json = args.iter().any(|a| a == "--json");
    let out = args
        .iter()
        .position(|a| a == "--out")
        .and_then(|i| args.get(i + 1))
        .map(PathBuf::from);
    if let Some(o) = &out {
        std::fs::create_dir_all(o)?;
    }
    let capture = load_capture(&dir, &CaptureLoadOptions::default())?;
    let mut sources = Vec::new();
    if let Some(path) = capture.source_envmap_path() {
        let env = load_envmap(&path)?;
        for ((name, cam), img) in capture.names.iter().zip(&capture.cameras).zip(&capture.images) {
            sources.push(measure(&asset, cam, &env, img, name, out.as_deref())?);
        }
    }
    let mut targets = Vec::new();
    if let Some(desc) = capture.description() {
        for t in &desc.targets {
            let env = load_envmap(t.envmap_path(&dir))?;
            let (_, _, img) = read_linear_rgb(&t.image_path(&dir))?;
            targets.push(measure(&asset, &t.camera, &env, &img, &t.name, out.as_deref())?);
        }
    }
    if json {
        let summary = |s: &[ViewScore]| {
            mean(s).map(|(p, q, r)| serde_json::json!({"psnr_db": p, "ssim": q, "render_secs": r}))
        };
        let value = serde_json::json!({
            "sources": sources, "targets": targets,
            "mean_sources": summary(&sources), "mean_targets": summary(&targets),
        });
        println!("{}", serde_json::to_string_pretty(&value)?);
        return Ok(());
    }
    println!("| view | PSNR (dB) | SSIM | render (s) |");
    println!("| --- | --- | --- | --- |");
    for r in sources.iter().chain(&targets) {
        println!(
            "| {} | {:.2} | {:.4} | {:.3} |",
            r.name, r.psnr_db, r.ssim, r.render_secs
        );
    }
    for (label, rows) in [("mean of sources", &sources), ("mean of targets", &targets)] {
        if let Some((p, s, t)) = mean(rows) {
            println!("| {label} | {p:.2} | {s:.4} | {t:.3} |");
        }
    }
    Ok(())
}
