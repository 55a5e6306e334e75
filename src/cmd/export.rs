//! `nelf export shaders -o DIR`: the engine shaders (`nelf_export::shaders`).
//!
//! `nelf export web ASSET -o DIR`: a web page showing the asset (`nelf_export::web`):
//! the embedded web viewer, the asset, its environment map (`--envmap`, default the
//! built-in studio map) and the start view (`--orbit`, `--rotate-deg`, `--exposure`);
//! options and report saved as `DIR/export.json`.
//!
//! `nelf export vdb ASSET -o head.vdb`: writes a `.nelf` asset as one OpenVDB file
//! (`nelf_export::write_vdb`): the `density` grid, a colour grid relit under an
//! environment map (`color` for Blender, `--color-name Cd` for Houdini), and the PCA
//! coefficient grids `pca_00` … with the PCA mean and basis, `world_from_light` and the
//! env-map convention in the file metadata (`export/README.md`).
//!
//! Lighting of the colour grid: `--envmap FILE.exr|hdr` turned by `--rotate-deg` about
//! +y; without it, the capture's estimated light if the asset stores one (metadata
//! `estimated_light`), else the built-in studio map (`nelf view`'s "studio
//! (procedural)"). `--scale 100` writes centimetres; `--rank K` keeps the first K
//! components (the colour grid is relit with the same K). The options and the report
//! (grids, sizes, seconds) are saved beside the file as `<out>.export.json`.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Context;
use nelf_export::web::{WebEnvmap, WebPageOptions};
use nelf_export::{Compression, Lighting, VdbOptions, VdbReport, write_vdb};
use nelf_scene::envgen::EnvFamily;
use nelf_scene::shot::{LightingArgs, load_lighting};
use serde::{Deserialize, Serialize};

/// Options of `nelf export`.
#[derive(Debug, clap::Args)]
pub struct ExportArgs {
    #[command(subcommand)]
    pub command: ExportCommand,
}

/// Export formats.
#[derive(Debug, clap::Subcommand)]
pub enum ExportCommand {
    /// One OpenVDB file (OpenVDB 10): density, relit colour, PCA coefficient grids.
    Vdb(VdbArgs),
    /// The relight, march, display, view and reflect passes as GLSL 4.50 and HLSL
    /// (translated from our WGSL by naga), with `shaders.json` naming entry points and
    /// bindings.
    Shaders(ShadersArgs),
    /// A self-contained web page (the viewer built for the browser, WebGPU or WebGL2; the
    /// asset; its map) that any static file server can host.
    Web(WebArgs),
}

/// Options of `nelf export web`.
#[derive(Debug, Clone, clap::Args, Serialize, Deserialize)]
pub struct WebArgs {
    /// The .nelf asset.
    pub asset: PathBuf,
    /// Folder to write into (created if needed).
    #[arg(short, long, default_value = "web-out")]
    pub out: PathBuf,
    /// Environment map (.exr or .hdr) the page starts with; default: the built-in studio
    /// map (`nelf view`'s "studio (procedural)"), written as studio.exr.
    #[arg(long)]
    pub envmap: Option<PathBuf>,
    /// Turn the lighting about +y by this many degrees at start.
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    pub rotate_deg: f32,
    /// Orbit camera `AZ,EL[,DIST]` (degrees, degrees, metres) at start; default: the
    /// viewer's framing of the asset's box.
    #[arg(long, value_name = "AZ,EL[,DIST]", allow_hyphen_values = true)]
    pub orbit: Option<String>,
    /// Exposure at start (stops).
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    pub exposure: f32,
}

/// Options of `nelf export shaders`.
#[derive(Debug, Clone, clap::Args)]
pub struct ShadersArgs {
    /// Folder to write into (created if needed).
    #[arg(short, long, default_value = "shaders-out")]
    pub out: PathBuf,
}

/// Per-grid compression of `nelf export vdb`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, clap::ValueEnum, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum CompressionArg {
    /// Values stored raw (OpenVDB's "active values": only active values are stored).
    None,
    /// zlib per node, as OpenVDB's "zip + active values" (7–8× smaller here).
    #[default]
    Zip,
}

/// Options of `nelf export vdb`.
#[derive(Debug, Clone, clap::Args, Serialize, Deserialize)]
#[command(mut_arg("envmap", |envmap| envmap.help(
    "Environment map (.exr or .hdr, lat-long, any resolution) for the colour grid; \
     default: the capture's estimated light stored in the asset, else a built-in studio map"
)))]
pub struct VdbArgs {
    /// The .nelf asset.
    pub asset: PathBuf,
    /// The OpenVDB file to write (`<out>.export.json` goes beside it).
    #[arg(short, long, default_value = "head.vdb")]
    pub out: PathBuf,
    /// The colour grid's environment map (`--envmap`) and its rotation (`--rotate-deg`).
    #[command(flatten)]
    #[serde(flatten)]
    pub lighting: LightingArgs,
    /// Export only the first K PCA components (default: all); the colour grid uses the same K.
    #[arg(long)]
    pub rank: Option<usize>,
    /// Scene units per metre: 1 writes metres, 100 centimetres (lengths × scale, density ÷ scale).
    #[arg(long, default_value_t = 1.0)]
    pub scale: f64,
    /// Name of the relit colour grid: `color` (Blender) or `Cd` (Houdini).
    #[arg(long, default_value = nelf_export::vdb::DEFAULT_COLOR_GRID)]
    pub color_name: String,
    /// Per-grid compression.
    #[arg(long, value_enum, default_value_t)]
    pub compression: CompressionArg,
    /// `unreal`: instead of one file, Sparse Volume Texture files of at most 8
    /// channels each (density + PCA coefficients) named `<out stem>_svtN.vdb`, with
    /// `<stem>.unreal.json` (channel map), `<stem>.relight.hlsl` (Custom node) and
    /// `<stem>.projected_light.exr` (export/UNREAL.md).
    #[arg(long, value_enum)]
    pub preset: Option<PresetArg>,
}

/// Target presets of `nelf export vdb`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum PresetArg {
    /// Unreal Engine's Sparse Volume Texture importer.
    Unreal,
}

/// What `<out>.export.json` holds.
#[derive(Debug, Serialize)]
struct ExportRecord<'a> {
    config: &'a VdbArgs,
    report: &'a VdbReport,
    asset_file_size: u64,
    load_seconds: f64,
    write_seconds: f64,
}

/// Runs `nelf export`.
pub fn run(args: &ExportArgs) -> anyhow::Result<()> {
    match &args.command {
        ExportCommand::Vdb(vdb) => run_vdb(vdb),
        ExportCommand::Shaders(shaders) => run_shaders(shaders),
        ExportCommand::Web(web) => run_web(web),
    }
}

fn run_web(args: &WebArgs) -> anyhow::Result<()> {
    let mut start_query = Vec::new();
    if let Some(orbit) = &args.orbit {
        start_query.push(format!("orbit={}", nelf_export::web::url_encode(orbit)));
    }
    if args.rotate_deg != 0.0 {
        start_query.push(format!("rotate={}", args.rotate_deg));
    }
    if args.exposure != 0.0 {
        start_query.push(format!("exposure={}", args.exposure));
    }
    let start_query = start_query.join("&");
    // The page parses its parameters the same way: refuse here what it would refuse.
    nelf_web::params::WebParams::parse(&start_query).context("nelf export web: start view")?;
    let envmap = match &args.envmap {
        Some(path) => WebEnvmap::File(path.clone()),
        None => WebEnvmap::Generated {
            name: "studio".into(),
            env: studio_envmap(),
        },
    };
    let options = WebPageOptions {
        asset: args.asset.clone(),
        envmap,
        start_query,
    };
    let report = nelf_export::web::write_web_page(&options, &args.out).with_context(|| {
        format!(
            "cannot write the web page of {} to {}",
            args.asset.display(),
            args.out.display()
        )
    })?;
    let record_path = args.out.join("export.json");
    let record = serde_json::json!({ "config": args, "report": &report });
    let text = serde_json::to_string_pretty(&record).context("export record")?;
    nelf_export::write_atomic(&record_path, text.as_bytes())?;
    for (name, bytes) in &report.files {
        println!("  {name}: {bytes} bytes");
    }
    println!(
        "web page written to {} (viewer {} bytes; start: ?{}); serve the folder, e.g. \
         `python3 -m http.server -d {}`, and open index.html (WebGPU, or WebGL2 with the relight \
         on the CPU)",
        args.out.display(),
        report.viewer_bytes,
        report.defaults,
        args.out.display()
    );
    Ok(())
}

/// The built-in studio map (`nelf view`'s "studio (procedural)").
fn studio_envmap() -> nelf_format::conventions::LatLong {
    super::view::builtin_envmap(EnvFamily::Studio)
}

fn run_shaders(args: &ShadersArgs) -> anyhow::Result<()> {
    let report = nelf_export::shaders::write_engine_shaders(&args.out)
        .with_context(|| format!("cannot write engine shaders to {}", args.out.display()))?;
    for pass in &report.passes {
        let entries: Vec<String> = pass
            .entries
            .iter()
            .map(|e| format!("{} ({})", e.name, e.stage))
            .collect();
        println!("{}: {}", pass.pass, entries.join(", "));
    }
    println!(
        "GLSL {} and HLSL SM {} written to {} (bindings: {})",
        report.glsl_version,
        report.hlsl_shader_model,
        args.out.display(),
        args.out.join("shaders.json").display()
    );
    Ok(())
}

fn run_vdb(args: &VdbArgs) -> anyhow::Result<()> {
    let start = Instant::now();
    let asset = nelf_format::read_asset(&args.asset)
        .with_context(|| format!("cannot read {}", args.asset.display()))?;
    let lighting = lighting(args, &asset)?;
    let load_seconds = start.elapsed().as_secs_f64();
    let options = VdbOptions {
        scale: args.scale,
        rank: args.rank,
        color_name: args.color_name.clone(),
        compression: match args.compression {
            CompressionArg::None => Compression::None,
            CompressionArg::Zip => Compression::Zip,
        },
    };
    if args.preset == Some(PresetArg::Unreal) {
        let start = Instant::now();
        let report = nelf_export::unreal::write_unreal(&args.out, &asset, &lighting, &options)
            .with_context(|| format!("cannot export {} for Unreal", args.asset.display()))?;
        let files: Vec<&str> = report.files.iter().map(|f| f.file.as_str()).collect();
        println!(
            "exported {} for Unreal (density + {} PCA channels in {} SVT files: {}) in {:.2} s; channel map, HLSL and projected light beside them ({}, {}, {})",
            args.asset.display(),
            report.rank,
            files.len(),
            files.join(", "),
            start.elapsed().as_secs_f64(),
            report.hlsl_file,
            report.projected_light_file,
            report.manifest_file,
        );
        return Ok(());
    }
    let start = Instant::now();
    let report = write_vdb(&args.out, &asset, &lighting, &options)
        .with_context(|| format!("cannot export {} to {}", args.asset.display(), args.out.display()))?;
    let write_seconds = start.elapsed().as_secs_f64();
    let asset_file_size = std::fs::metadata(&args.asset)
        .with_context(|| format!("cannot stat {}", args.asset.display()))?
        .len();
    let record = ExportRecord {
        config: args,
        report: &report,
        asset_file_size,
        load_seconds,
        write_seconds,
    };
    let record_path = super::save_record(&args.out, "export", &record)?;
    let voxels = report.grids.first().map_or(0, |g| g.active_voxels);
    println!(
        "exported {} ({} voxels, {} grids: density, {}, pca_00..pca_{:02}; rank {} of {}) in {write_seconds:.2} s -> {} ({} bytes; asset {} bytes)",
        args.asset.display(),
        voxels,
        report.grids.len(),
        args.color_name,
        report.rank.saturating_sub(1),
        report.rank,
        report.stored_rank,
        args.out.display(),
        report.file_size,
        asset_file_size,
    );
    println!("  colour lit by: {}", report.lighting);
    println!("  settings and report: {}", record_path.display());
    Ok(())
}

/// `--envmap` turned by `--rotate-deg`; else the asset's stored estimated light; else
/// the built-in studio map.
fn lighting(args: &VdbArgs, asset: &nelf_format::Asset) -> anyhow::Result<Lighting> {
    let rotate_deg = args.lighting.rotate_deg;
    if let Some(path) = &args.lighting.envmap {
        let (env, name) = load_lighting(Some(path), None)?;
        return Ok(Lighting::world(env, rotate_deg, &name));
    }
    if let Some(stored) = Lighting::stored(asset, rotate_deg)
        .with_context(|| format!("{}: stored lighting", args.asset.display()))?
    {
        return Ok(stored);
    }
    Ok(Lighting::world(
        studio_envmap(),
        rotate_deg,
        "built-in studio map (procedural, seed 1)",
    ))
}
