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
//! "8-bit PSNR" is the PSNR of those previews as 8-bit sRGB values (exposure putting
//! the reference's largest value at 0.5, as written), what a person looking at the
//! PNGs compares; "ꟻLIP" the mean ꟻLIP error (NVIDIA's LDR ꟻLIP, default observer) of the
//! same 8-bit images, 0 = identical.

use std::path::{Path, PathBuf};

use nelf_bake::eval::{ErrorBreakdown, ViewScore, data_range, error_breakdown, load_held_aside, score_view};
use nelf_bake::{CaptureLoadOptions, load_capture};
use nelf_format::conventions::{LatLong, PinholeCamera};
use nelf_format::read_asset;
use nelf_scene::envmap::load_envmap;
use nelf_scene::flip::{DEFAULT_PIXELS_PER_DEGREE, flip_map, pooled_mean};
use nelf_scene::image_io::write_png_srgb;
use nelf_scene::mesh_io::linear_to_srgb8;
use nelf_scene::metrics::psnr;

type Error = Box<dyn std::error::Error>;

fn measure(
    asset: &nelf_format::Asset,
    camera: &PinholeCamera,
    env: &LatLong,
    reference: &[[f32; 3]],
    mask: &[f32],
    name: &str,
    out: Option<&Path>,
) -> Result<Row, Error> {
    let (score, image) = score_view(asset, camera, env, reference, name)?;
    let breakdown = error_breakdown(&image, reference, mask, f64::from(data_range(reference)))?;
    let stops = (0.5 / data_range(reference)).log2();
    let gain = stops.exp2();
    let to_8bit = |rgb: &[[f32; 3]]| -> Vec<[f32; 3]> {
        rgb.iter()
            .map(|p| p.map(|v| f32::from(linear_to_srgb8(v * gain))))
            .collect()
    };
    let psnr_8bit = psnr(&to_8bit(&image.rgb), &to_8bit(reference), 255.0)?;
    let exposed = |rgb: &[[f32; 3]]| -> Vec<[f32; 3]> { rgb.iter().map(|p| p.map(|v| v * gain)).collect() };
    let flip_error = flip_map(
        &exposed(reference),
        &exposed(&image.rgb),
        camera.width,
        camera.height,
        DEFAULT_PIXELS_PER_DEGREE,
    )?;
    let flip = pooled_mean(&flip_error, None)?.ok_or("an empty image has no ꟻLIP")?;
    if let Some(dir) = out {
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
    Ok((score, breakdown, psnr_8bit, flip))
}

/// A view's score, error breakdown, 8-bit PSNR and mean ꟻLIP.
type Row = (ViewScore, ErrorBreakdown, f64, f64);

fn mean(rows: &[Row]) -> Option<[f64; 8]> {
    let n = rows.len() as f64;
    (!rows.is_empty()).then(|| {
        let mut m = [0.0; 8];
        for (s, b, p8, flip) in rows {
            let v = [
                s.psnr_db,
                s.ssim,
                s.render_secs,
                b.edge_share,
                b.interior_psnr_db,
                b.coverage_error,
                *p8,
                *flip,
            ];
            for (a, x) in m.iter_mut().zip(v) {
                *a += x / n;
            }
        }
        m
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
        for (((name, cam), img), mask) in capture
            .names
            .iter()
            .zip(&capture.cameras)
            .zip(&capture.images)
            .zip(&capture.masks)
        {
            sources.push(measure(&asset, cam, &env, img, mask, name, out.as_deref())?);
        }
    }
    let mut targets = Vec::new();
    if let Some(desc) = capture.description() {
        let held = load_held_aside(desc, &dir)?;
        for i in 0..held.len() {
            targets.push(measure(
                &asset,
                &held.cameras[i],
                &held.envs[i],
                &held.images[i],
                &held.masks[i],
                &held.names[i],
                out.as_deref(),
            )?);
        }
    }
    if json {
        let summary = |s: &[Row]| {
            mean(s).map(|m| {
                serde_json::json!({"psnr_db": m[0], "ssim": m[1], "render_secs": m[2],
                    "edge_share": m[3], "interior_psnr_db": m[4], "coverage_error": m[5],
                    "psnr_8bit_db": m[6], "flip": m[7]})
            })
        };
        let rows = |s: &[Row]| {
            s.iter()
                .map(|(v, b, p8, flip)| {
                    serde_json::json!({"score": v, "breakdown": b, "psnr_8bit_db": p8, "flip": flip})
                })
                .collect::<Vec<_>>()
        };
        let value = serde_json::json!({
            "sources": rows(&sources), "targets": rows(&targets),
            "mean_sources": summary(&sources), "mean_targets": summary(&targets),
        });
        println!("{}", serde_json::to_string_pretty(&value)?);
        return Ok(());
    }
    println!(
        "| view | PSNR (dB) | SSIM | render (s) | edge share | interior PSNR (dB) | coverage error | 8-bit PSNR (dB) | ꟻLIP |"
    );
    println!("| --- | --- | --- | --- | --- | --- | --- | --- | --- |");
    for (r, b, p8, flip) in sources.iter().chain(&targets) {
        println!(
            "| {} | {:.2} | {:.4} | {:.3} | {:.2} | {:.2} | {:.4} | {p8:.2} | {flip:.4} |",
            r.name, r.psnr_db, r.ssim, r.render_secs, b.edge_share, b.interior_psnr_db, b.coverage_error
        );
    }
    for (label, rows) in [("mean of sources", &sources), ("mean of targets", &targets)] {
        if let Some(m) = mean(rows) {
            println!(
                "| {label} | {:.2} | {:.4} | {:.3} | {:.2} | {:.2} | {:.4} | {:.2} | {:.4} |",
                m[0], m[1], m[2], m[3], m[4], m[5], m[6], m[7]
            );
        }
    }
    Ok(())
}
