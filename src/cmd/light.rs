//! `nelf light CAPTURE [--weights W.safetensors] -o light.exr`: the NeLF network's
//! (the shipped one unless `--weights` names another)
//! estimate of the lighting a capture was taken under (`nelf_field`: per-view
//! estimates from the encoder's light head, rotated into view 0 and
//! confidence-weighted), written as a lat-long EXR in the project's env-map
//! conventions **in the world frame**, so the viewer can start from the capture's
//! own lighting and rotate it.
//!
//! The network's 8 × 16 estimate lives in the light frame `world_from_light =
//! R₀ᵀ·diag(−1, −1, 1)` (view 0's camera; `nelf_field::light`); it is written at
//! `--width × width/2` by looking up that piecewise-constant map (4 × 4 equal-area
//! sub-samples per output texel), so projecting the file back into the light frame
//! recovers the estimate. `--light-frame` writes the raw 8 × 16 light-frame map
//! instead. Radiance is the network's (linear, the images' scale).

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Context;
use nelf_field::NelfConfig;
use nelf_field::capture::{default_net_from_world, load_capture_dir_for_model};
use nelf_field::light::{light_map_in_world, net_light_to_latlong};
use nelf_field::shipped::load_or_shipped;
use nelf_format::conventions::LatLong;
use nelf_scene::image_io::write_exr_rgb;

/// Options of `nelf light`.
#[derive(Debug, clap::Args)]
pub struct LightArgs {
    /// Capture folder (cameras.json, images, masks).
    pub capture: PathBuf,
    /// NeLF weights: safetensors with the official checkpoint's key names
    /// (field/CHECKPOINT.md; default: the shipped network, models/nelf-small.safetensors, built in).
    #[arg(long)]
    pub weights: Option<PathBuf>,
    /// Output lat-long EXR (linear RGB radiance).
    #[arg(short, long, default_value = "light.exr")]
    pub out: PathBuf,
    /// Width of the written world-frame map (height is half).
    #[arg(long, default_value_t = 256)]
    pub width: u32,
    /// Write the raw 8 × 16 map in the network's light frame instead of the world frame.
    #[arg(long)]
    pub light_frame: bool,
    /// Print a JSON summary.
    #[arg(long)]
    pub json: bool,
}

pub fn run(args: &LightArgs) -> anyhow::Result<()> {
    let start = Instant::now();
    let device = nelf_field::default_device();
    let (model, weights_name) =
        load_or_shipped(args.weights.as_deref(), NelfConfig::for_device(&device), &device)
            .context("loading the network's weights")?;
    let (capture, _) = load_capture_dir_for_model(&args.capture, default_net_from_world(), &model)
        .with_context(|| format!("loading the capture {}", args.capture.display()))?;
    let encoded = model.encode(&capture.views).context("running the encoder")?;
    let light = net_light_to_latlong(&encoded.light().source_light)?;
    if model.source_relative_light() {
        eprintln!(
            "note: {weights_name} estimates lightings relative to their own power (mean radiance about 1): \
             images cannot tell a bright head under a dim light from a dim head under a bright one"
        );
    }
    let world_from_light = capture.world_from_light();
    let map: LatLong = if args.light_frame {
        light.clone()
    } else {
        let width = args.width.max(2) as usize;
        light_map_in_world(&light, world_from_light, width, width / 2)?
    };
    write_exr_rgb(&args.out, map.width() as u32, map.height() as u32, map.texels())
        .with_context(|| format!("writing {}", args.out.display()))?;
    let power = map.integral();
    let frame = if args.light_frame { "light" } else { "world" };
    if args.json {
        let summary = serde_json::json!({
            "out": args.out,
            "frame": frame,
            "width": map.width(),
            "height": map.height(),
            "world_from_light": world_from_light.to_cols_array(),
            "power_rgb": power,
            "views": capture.cameras.len(),
            "image_size": [capture.views.width, capture.views.height],
            "seconds": start.elapsed().as_secs_f64(),
            "device": nelf_field::device_name(&device),
            "weights": weights_name,
        });
        println!("{}", serde_json::to_string_pretty(&summary)?);
    } else {
        println!(
            "wrote {} ({}×{}, {frame} frame) from {} views of {}×{} in {:.1} s; ∫L dω = [{:.3}, {:.3}, {:.3}]",
            args.out.display(),
            map.width(),
            map.height(),
            capture.cameras.len(),
            capture.views.width,
            capture.views.height,
            start.elapsed().as_secs_f64(),
            power[0],
            power[1],
            power[2]
        );
    }
    Ok(())
}
