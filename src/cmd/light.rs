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

use anyhow::Context;
use nelf_pipeline::{LightRequest, estimate_light};
use nelf_scene::image_io::write_exr_rgb;

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
    let estimate = estimate_light(&LightRequest {
        capture_dir: &args.capture,
        weights: args.weights.as_deref(),
        width: args.width,
        light_frame: args.light_frame,
    })?;
    if estimate.source_relative {
        eprintln!(
            "note: {} estimates lightings relative to their own power (mean radiance about 1): \
             images cannot tell a bright head under a dim light from a dim head under a bright one",
            estimate.weights_name
        );
    }
    let map = &estimate.map;
    write_exr_rgb(&args.out, map.width() as u32, map.height() as u32, map.texels())
        .with_context(|| format!("writing {}", args.out.display()))?;
    let power = map.integral();
    if args.json {
        let summary = serde_json::json!({
            "out": args.out,
            "frame": estimate.frame,
            "width": map.width(),
            "height": map.height(),
            "world_from_light": estimate.world_from_light.to_cols_array(),
            "power_rgb": power,
            "views": estimate.views,
            "image_size": estimate.image_size,
            "seconds": estimate.seconds,
            "device": estimate.device,
            "weights": estimate.weights_name,
        });
        println!("{}", serde_json::to_string_pretty(&summary)?);
    } else {
        println!(
            "wrote {} ({}×{}, {} frame) from {} views of {}×{} in {:.1} s; ∫L dω = [{:.3}, {:.3}, {:.3}]",
            args.out.display(),
            map.width(),
            map.height(),
            estimate.frame,
            estimate.views,
            estimate.image_size[0],
            estimate.image_size[1],
            estimate.seconds,
            power[0],
            power[1],
            power[2]
        );
    }
    Ok(())
}
