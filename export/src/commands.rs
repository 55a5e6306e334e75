//! What each `nelf export` subcommand does, as one call taking the command's settings:
//! [`export_vdb`] (`nelf export vdb`: one OpenVDB file and its settings record, or the
//! Unreal preset's files), [`export_web`] (`nelf export web`: the web page and its
//! record) and, for `nelf export shaders`, [`crate::shaders::write_engine_shaders`].
//! Each result says what the command prints (`to_text`).
//!
//! Lighting of the OpenVDB colour grid: `envmap` turned by `rotate_deg` about +y;
//! without it, the capture's estimated light if the asset stores one (metadata
//! `estimated_light`), else the built-in studio map ([`studio_envmap`], `nelf view`'s
//! "studio (procedural)").

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use nelf_format::conventions::LatLong;
use nelf_scene::envgen::EnvFamily;
use nelf_scene::shot::{LightingArgs, load_lighting};
use serde::{Deserialize, Serialize};

use crate::openvdb::Compression;
use crate::unreal::{UnrealReport, write_unreal};
use crate::vdb::{Lighting, PcaGrids, VdbOptions, VdbReport, write_vdb};
use crate::web::{WebEnvmap, WebPageOptions, WebPageReport, url_encode, write_web_page};
use crate::{ExportError, write_atomic};

/// What the built-in studio map is called in reports.
const STUDIO_NAME: &str = "built-in studio map (procedural, seed 1)";

/// The built-in studio map: the procedural studio family, seed 1 (`nelf view`'s
/// "studio (procedural)").
#[must_use]
pub fn studio_envmap() -> LatLong {
    nelf_scene::envgen::builtin_envmap(EnvFamily::Studio)
}

/// Target presets of [`export_vdb`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum VdbPreset {
    /// Unreal Engine's Sparse Volume Texture importer ([`crate::unreal`]).
    Unreal,
}

/// The settings of `nelf export vdb` (saved as `config` in `<out>.export.json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct VdbExportConfig {
    /// The `.nelf` asset.
    pub asset: PathBuf,
    /// The OpenVDB file to write (`<out>.export.json` goes beside it).
    pub out: PathBuf,
    /// The colour grid's environment map and its rotation (see the module docs).
    #[serde(flatten)]
    pub lighting: LightingArgs,
    /// Export only the first K PCA components (`None`: all); the colour grid uses the same K.
    pub rank: Option<usize>,
    /// Scene units per metre: 1 writes metres, 100 centimetres.
    pub scale: f64,
    /// Name of the relit colour grid: `color` (Blender) or `Cd` (Houdini).
    pub color_name: String,
    /// Per-grid compression.
    pub compression: Compression,
    /// A preset writing other files instead of one OpenVDB file.
    pub preset: Option<VdbPreset>,
    /// One float grid per PCA component, or three per vec3s grid.
    #[serde(default)]
    pub pca_grids: PcaGrids,
}

/// What [`export_vdb`] wrote.
#[derive(Debug, Clone)]
pub enum VdbExported {
    /// One OpenVDB file and its settings record.
    File {
        /// The export's report.
        report: VdbReport,
        /// Bytes of the asset file.
        asset_file_size: u64,
        /// Seconds building, encoding and writing the file.
        write_seconds: f64,
        /// `<out>.export.json`.
        record_path: PathBuf,
    },
    /// The Unreal preset's files.
    Unreal {
        /// The preset's report.
        report: UnrealReport,
        /// Seconds writing them.
        seconds: f64,
    },
}

impl VdbExported {
    /// The lines `nelf export vdb` prints for `config`.
    #[must_use]
    pub fn to_text(&self, config: &VdbExportConfig) -> String {
        let mut text = String::new();
        match self {
            Self::File {
                report,
                asset_file_size,
                write_seconds,
                record_path,
            } => {
                // The voxels of the colour grid: a fine density has `F³` times as many.
                let voxels = report
                    .grids
                    .iter()
                    .find(|g| g.name == config.color_name)
                    .map_or(0, |g| g.active_voxels);
                let coefficient_grids = config.pca_grids.names(report.rank);
                let _ = writeln!(
                    text,
                    "exported {} ({} voxels, {} grids: density, {}, {}..{}; rank {} of {}) in {write_seconds:.2} s -> {} ({} bytes; asset {} bytes)",
                    config.asset.display(),
                    voxels,
                    report.grids.len(),
                    config.color_name,
                    coefficient_grids.first().map_or("", String::as_str),
                    coefficient_grids.last().map_or("", String::as_str),
                    report.rank,
                    report.stored_rank,
                    config.out.display(),
                    report.file_size,
                    asset_file_size,
                );
                if let (Some(factor), Some(density)) = (report.density_factor, report.grids.first()) {
                    let _ = writeln!(
                        text,
                        "  density: the asset's fine density, {factor} times finer per axis ({} fine voxels of {} scene units)",
                        density.active_voxels,
                        report.voxel_size / f64::from(factor),
                    );
                }
                let _ = writeln!(text, "  colour lit by: {}", report.lighting);
                let _ = writeln!(text, "  settings and report: {}", record_path.display());
            }
            Self::Unreal { report, seconds } => {
                let files: Vec<&str> = report.files.iter().map(|f| f.file.as_str()).collect();
                let density = match (&report.density_file, report.density_factor) {
                    (Some(file), Some(factor)) => format!(
                        "; the fine density ({factor} times finer per axis) in its own SVT, {}",
                        file.file
                    ),
                    _ => String::new(),
                };
                let _ = writeln!(
                    text,
                    "exported {} for Unreal ({}{} PCA channels in {} SVT files: {}{density}) in {:.2} s; channel map, HLSL and projected light beside them ({}, {}, {})",
                    config.asset.display(),
                    if report.density_file.is_some() {
                        ""
                    } else {
                        "density + "
                    },
                    report.rank,
                    files.len(),
                    files.join(", "),
                    seconds,
                    report.hlsl_file,
                    report.projected_light_file,
                    report.manifest_file,
                );
            }
        }
        text
    }
}

/// What `<out>.export.json` holds.
#[derive(Debug, Serialize)]
struct VdbRecord<'a> {
    config: &'a VdbExportConfig,
    report: &'a VdbReport,
    asset_file_size: u64,
    load_seconds: f64,
    write_seconds: f64,
}

/// `nelf export vdb`: reads the asset, picks the lighting (module docs) and writes
/// `config.out` ([`write_vdb`]) with the settings and report beside it in
/// `<out>.export.json`, or with [`VdbPreset::Unreal`] the preset's files
/// ([`write_unreal`], no record). Every file is written atomically.
pub fn export_vdb(config: &VdbExportConfig) -> Result<VdbExported, ExportError> {
    let asset_name = config.asset.display();
    let start = Instant::now();
    let asset = nelf_format::read_asset(&config.asset).map_err(|source| ExportError::ReadAsset {
        path: config.asset.clone(),
        source,
    })?;
    let lighting = vdb_lighting(config, &asset)?;
    let load_seconds = start.elapsed().as_secs_f64();
    let options = VdbOptions {
        scale: config.scale,
        rank: config.rank,
        color_name: config.color_name.clone(),
        compression: config.compression,
        pca_grids: config.pca_grids,
    };
    if config.preset == Some(VdbPreset::Unreal) {
        if config.pca_grids != PcaGrids::Float {
            return Err(ExportError::BadOption(
                "--pca-grids applies to one OpenVDB file; the Unreal preset packs its own channels".into(),
            ));
        }
        let start = Instant::now();
        let report = write_unreal(&config.out, &asset, &lighting, &options).map_err(ExportError::step(
            format!("cannot export {asset_name} for Unreal"),
        ))?;
        let seconds = start.elapsed().as_secs_f64();
        return Ok(VdbExported::Unreal { report, seconds });
    }
    let start = Instant::now();
    let report = write_vdb(&config.out, &asset, &lighting, &options).map_err(ExportError::step(format!(
        "cannot export {asset_name} to {}",
        config.out.display()
    )))?;
    let write_seconds = start.elapsed().as_secs_f64();
    let asset_file_size = std::fs::metadata(&config.asset)
        .map_err(|source| ExportError::Stat {
            path: config.asset.clone(),
            source,
        })?
        .len();
    let record = VdbRecord {
        config,
        report: &report,
        asset_file_size,
        load_seconds,
        write_seconds,
    };
    let record_path = write_record(&config.out, "export", &record)?;
    Ok(VdbExported::File {
        report,
        asset_file_size,
        write_seconds,
        record_path,
    })
}

/// `envmap` turned by `rotate_deg`; else the asset's stored estimated light; else the
/// built-in studio map.
fn vdb_lighting(config: &VdbExportConfig, asset: &nelf_format::Asset) -> Result<Lighting, ExportError> {
    let rotate_deg = config.lighting.rotate_deg;
    if let Some(path) = &config.lighting.envmap {
        let (env, name) = load_lighting(Some(path), None).map_err(|e| ExportError::Lighting(Box::new(e)))?;
        return Ok(Lighting::world(env, rotate_deg, &name));
    }
    if let Some(stored) = Lighting::stored(asset, rotate_deg).map_err(ExportError::step(format!(
        "{}: stored lighting",
        config.asset.display()
    )))? {
        return Ok(stored);
    }
    Ok(Lighting::world(studio_envmap(), rotate_deg, STUDIO_NAME))
}

/// Saves settings and report as pretty JSON (with a final line feed) beside `out`, in
/// `<out>.<kind>.json`, atomically; returns that path.
fn write_record(out: &Path, kind: &str, record: &impl Serialize) -> Result<PathBuf, ExportError> {
    let mut name = out.as_os_str().to_owned();
    name.push(format!(".{kind}.json"));
    let path = PathBuf::from(name);
    let text = serde_json::to_string_pretty(record).map_err(|e| ExportError::Metadata(e.to_string()))? + "\n";
    nelf_format::atomic::write_bytes_atomically(&path, text.as_bytes()).map_err(|source| {
        ExportError::WriteRecord {
            path: path.clone(),
            source,
        }
    })?;
    Ok(path)
}

/// The settings of `nelf export web` (saved as `config` in `DIR/export.json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WebExportConfig {
    /// The `.nelf` asset.
    pub asset: PathBuf,
    /// Folder to write into (created if needed).
    pub out: PathBuf,
    /// Environment map (.exr or .hdr) the page starts with; `None`: the built-in studio
    /// map ([`studio_envmap`]), written as `studio.exr`.
    pub envmap: Option<PathBuf>,
    /// Turn the lighting about +y by this many degrees at start.
    pub rotate_deg: f32,
    /// Orbit camera `AZ,EL[,DIST]` (degrees, degrees, metres) at start; `None`: the
    /// viewer's framing of the asset's box.
    pub orbit: Option<String>,
    /// Exposure at start (stops).
    pub exposure: f32,
}

impl WebExportConfig {
    /// The URL parameters of the start view (`orbit=…&rotate=…&exposure=…`, each only
    /// when set), without the asset and map. The page parses them with
    /// `nelf_web::params`; a caller checks them there before [`export_web`].
    #[must_use]
    pub fn start_query(&self) -> String {
        let mut start_query = Vec::new();
        if let Some(orbit) = &self.orbit {
            start_query.push(format!("orbit={}", url_encode(orbit)));
        }
        if self.rotate_deg != 0.0 {
            start_query.push(format!("rotate={}", self.rotate_deg));
        }
        if self.exposure != 0.0 {
            start_query.push(format!("exposure={}", self.exposure));
        }
        start_query.join("&")
    }
}

/// `nelf export web`: writes the page ([`write_web_page`]) into `config.out` with the
/// settings and report in `export.json` there (atomically).
pub fn export_web(config: &WebExportConfig) -> Result<WebPageReport, ExportError> {
    let envmap = match &config.envmap {
        Some(path) => WebEnvmap::File(path.clone()),
        None => WebEnvmap::Generated {
            name: "studio".into(),
            env: studio_envmap(),
        },
    };
    let options = WebPageOptions {
        asset: config.asset.clone(),
        envmap,
        start_query: config.start_query(),
    };
    let report = write_web_page(&options, &config.out).map_err(ExportError::step(format!(
        "cannot write the web page of {} to {}",
        config.asset.display(),
        config.out.display()
    )))?;
    let record = serde_json::json!({ "config": config, "report": &report });
    let text = serde_json::to_string_pretty(&record)
        .map_err(|e| ExportError::Metadata(format!("export record: {e}")))?;
    write_atomic(&config.out.join("export.json"), text.as_bytes())?;
    Ok(report)
}
