//! `nelf render --field CAPTURE_DIR [--weights W]`: renders straight from the NeLF
//! network over a capture instead of an asset (`nelf_pipeline::render_field`), writes
//! the image and its `<out>.render.json` record. The options are `nelf render`'s
//! ([`super::render::RenderArgs`]).

use std::path::Path;

use anyhow::Context;
use nelf_scene::shot::camera_to_json;

use super::render::RenderArgs;

/// `--field CAPTURE [--weights W]`: renders every pixel straight from the NeLF network
/// (`nelf_pipeline::render_field`), writes it and its record.
pub fn run(args: &RenderArgs, capture_dir: &Path) -> anyhow::Result<()> {
    let (output, _) = super::render::checked_output_and_march(args)?;
    let rendered = nelf_pipeline::render_field(&nelf_pipeline::FieldRenderRequest {
        capture_dir,
        weights: args.weights.as_deref(),
        estimated_light: args.estimated_light,
        no_source_calibration: args.no_source_calibration,
        seed: args.field_seed,
        view: &args.view,
        lighting: &args.lighting,
    })?;
    let image = &rendered.image;
    let (width, height) = (image.width as u32, image.height as u32);
    output
        .write(&args.out, width, height, &image.rgb, args.exposure)
        .with_context(|| format!("cannot write {}", args.out.display()))?;
    let record = serde_json::json!({
        "config": args,
        "camera": camera_to_json(&rendered.camera),
        "envmap": rendered.light_name,
        "device": format!("nelf-network ({})", rendered.device),
        "world_from_light": rendered.world_from_light.to_cols_array(),
        "load_seconds": rendered.load_seconds,
        "render_seconds": rendered.render_seconds,
    });
    super::save_record(&args.out, "render", &record)?;
    println!(
        "rendered {width}×{height} from the NeLF network over {} (lighting: {}) in {:.1} s -> {}",
        capture_dir.display(),
        rendered.light_name,
        rendered.render_seconds,
        args.out.display()
    );
    Ok(())
}
