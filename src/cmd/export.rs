//! `nelf export vdb ASSET -o head.vdb`: one OpenVDB file (density, relit colour, PCA
//! coefficient grids; `export/README.md`), or `--preset unreal`'s files, with the
//! settings and report beside it in `<out>.export.json` (`nelf_export::export_vdb`,
//! whose docs say what lights the colour grid).
//!
//! `nelf export shaders -o DIR`: the engine shaders (`nelf_export::shaders`).
//!
//! `nelf export web ASSET -o DIR`: a web page showing the asset, its environment map
//! (default the built-in studio map) and start view, with the options and report in
//! `DIR/export.json` (`nelf_export::export_web`); the start view is first checked by
//! the page's own parser (`nelf_web::params`).

use std::path::PathBuf;

use anyhow::Context;
use nelf_export::{Compression, VdbExportConfig, VdbPreset, WebExportConfig};
use nelf_scene::shot::LightingArgs;

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
#[derive(Debug, Clone, clap::Args)]
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
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, clap::ValueEnum)]
pub enum CompressionArg {
    /// Values stored raw (OpenVDB's "active values": only active values are stored).
    None,
    /// zlib per node, as OpenVDB's "zip + active values" (7–8× smaller here).
    #[default]
    Zip,
}

/// Options of `nelf export vdb`.
#[derive(Debug, Clone, clap::Args)]
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
    /// `float`: one grid per PCA component (`pca_00` …, what OpenVDB's tools and Houdini
    /// expect); `vec3`: three components per vec3s grid (`pca3_00` …), a third of the
    /// texture lookups for Blender's add-on (export/BLENDER.md).
    #[arg(long, value_enum, default_value_t)]
    pub pca_grids: PcaGridsArg,
}

/// `--pca-grids` of `nelf export vdb`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, clap::ValueEnum)]
pub enum PcaGridsArg {
    /// One float grid per component.
    #[default]
    Float,
    /// Three components per vec3s grid.
    Vec3,
}

/// Target presets of `nelf export vdb`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum PresetArg {
    /// Unreal Engine's Sparse Volume Texture importer.
    Unreal,
}

/// Runs `nelf export`.
pub fn run(args: &ExportArgs) -> anyhow::Result<()> {
    match &args.command {
        ExportCommand::Vdb(vdb) => {
            let config = vdb.config();
            print!("{}", nelf_export::export_vdb(&config)?.to_text(&config));
        }
        ExportCommand::Shaders(shaders) => {
            let report = nelf_export::shaders::write_engine_shaders(&shaders.out)
                .with_context(|| format!("cannot write engine shaders to {}", shaders.out.display()))?;
            print!("{}", report.to_text(&shaders.out));
        }
        ExportCommand::Web(web) => {
            let config = web.config();
            // The page parses its parameters the same way: refuse here what it would refuse.
            nelf_web::params::WebParams::parse(&config.start_query())
                .context("nelf export web: start view")?;
            print!("{}", nelf_export::export_web(&config)?.to_text(&config.out));
        }
    }
    Ok(())
}

impl VdbArgs {
    fn config(&self) -> VdbExportConfig {
        VdbExportConfig {
            asset: self.asset.clone(),
            out: self.out.clone(),
            lighting: self.lighting.clone(),
            rank: self.rank,
            scale: self.scale,
            color_name: self.color_name.clone(),
            compression: match self.compression {
                CompressionArg::None => Compression::None,
                CompressionArg::Zip => Compression::Zip,
            },
            preset: self.preset.map(|PresetArg::Unreal| VdbPreset::Unreal),
            pca_grids: match self.pca_grids {
                PcaGridsArg::Float => nelf_export::vdb::PcaGrids::Float,
                PcaGridsArg::Vec3 => nelf_export::vdb::PcaGrids::Vec3,
            },
        }
    }
}

impl WebArgs {
    fn config(&self) -> WebExportConfig {
        WebExportConfig {
            asset: self.asset.clone(),
            out: self.out.clone(),
            envmap: self.envmap.clone(),
            rotate_deg: self.rotate_deg,
            orbit: self.orbit.clone(),
            exposure: self.exposure,
        }
    }
}
