//! Field sources for a bake, behind `nelf_scene::field::FieldSource`: today the
//! exact ground-truth field of a mesh ([`MeshField`]: density from the signed
//! distance, light transport path-traced at the closest surface point). The NeLF
//! network implements the same trait in `nelf-field`.
//!
//! For a capture, the ground-truth mesh is either rebuilt from the capture's
//! `synth_config.json` (every synthetic capture has one; `synth_mesh` gives the
//! exact mesh and `trace_settings` the path tracer's settings) or loaded from a
//! mesh file in the capture's world frame. The density's shell is `shell_voxels`
//! voxels wide (the field's docs ask a baker for at least two).

use std::path::{Path, PathBuf};

use nelf_scene::field::{DensityProfile, MeshField};
use nelf_scene::mesh::Mesh;
use nelf_scene::mesh_io::{LoadOptions, load_mesh};
use nelf_scene::synth::{SynthConfig, synth_mesh};
use nelf_scene::tracer::TraceSettings;
use serde::{Deserialize, Serialize};

use crate::error::{BakeError, Result};

/// Overrides of the ground-truth path tracer's sample counts.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, clap::Args)]
pub struct TraceOverrides {
    /// Ground-truth tracer: interreflection bounces (default: the capture's
    /// `synth_config.json`, else the tracer's default, 2).
    #[arg(long)]
    pub bounces: Option<u32>,
    /// Ground-truth tracer: stratified samples per light texel (default: as for `--bounces`; 16).
    #[arg(long)]
    pub texel_samples: Option<u32>,
    /// Ground-truth tracer: indirect directions at the first surface point (default: as for `--bounces`; 128).
    #[arg(long)]
    pub indirect_samples: Option<u32>,
}

impl TraceOverrides {
    /// `base` with the overrides applied.
    pub fn apply(&self, base: TraceSettings) -> TraceSettings {
        TraceSettings {
            bounces: self.bounces.unwrap_or(base.bounces),
            texel_samples: self.texel_samples.unwrap_or(base.texel_samples),
            indirect_samples: self.indirect_samples.unwrap_or(base.indirect_samples),
            ..base
        }
    }
}

/// Where a ground-truth mesh comes from.
#[derive(Debug, Clone, PartialEq)]
pub enum GroundTruth {
    /// A synthetic capture's configuration (`synth_config.json`): its exact mesh and tracer settings.
    Synth {
        /// The file it was read from.
        path: PathBuf,
        /// The configuration.
        config: Box<SynthConfig>,
    },
    /// A mesh file, loaded with these options (`fit_height_m: None` keeps its placement).
    MeshFile {
        /// The file.
        path: PathBuf,
        /// How to load it.
        options: LoadOptions,
    },
}

/// Name of the synthetic capture configuration inside a capture folder.
pub const SYNTH_CONFIG_FILE: &str = "synth_config.json";

impl GroundTruth {
    /// Reads `dir/synth_config.json`.
    pub fn from_synth_capture(dir: &Path) -> Result<Self> {
        let path = dir.join(SYNTH_CONFIG_FILE);
        let text = std::fs::read_to_string(&path).map_err(|source| BakeError::Io {
            path: path.clone(),
            source,
        })?;
        let config: SynthConfig = serde_json::from_str(&text).map_err(|e| BakeError::Json {
            path: path.clone(),
            message: e.to_string(),
        })?;
        Ok(Self::Synth {
            path,
            config: Box::new(config),
        })
    }

    /// The mesh.
    pub fn mesh(&self) -> Result<Mesh> {
        match self {
            Self::Synth { config, .. } => Ok(synth_mesh(config)?),
            Self::MeshFile { path, options } => Ok(load_mesh(path, options)?),
        }
    }

    /// Path-tracer settings: the synthetic capture's, else the defaults.
    pub fn trace_settings(&self) -> TraceSettings {
        match self {
            Self::Synth { config, .. } => config.trace_settings(),
            Self::MeshFile { .. } => TraceSettings::default(),
        }
    }

    /// A description for the asset's metadata.
    pub fn describe(&self) -> serde_json::Value {
        match self {
            Self::Synth { path, config } => serde_json::json!({
                "kind": "synthetic-capture-mesh",
                "synth_config": path.display().to_string(),
                "mesh": config.mesh.as_ref().map(|p| p.display().to_string()),
                "head_seed": config.head_seed,
                "head_cells": config.head_cells,
            }),
            Self::MeshFile { path, options } => serde_json::json!({
                "kind": "mesh-file",
                "file": path.display().to_string(),
                "fit_height_m": options.fit_height_m,
                "rotate_y_deg": options.rotate_y_deg,
            }),
        }
    }
}

/// The ground-truth field of `mesh` for a grid of `voxel_size_m`: a density shell
/// `shell_voxels` voxels wide, light transport by `trace`.
pub fn mesh_field(
    mesh: &Mesh,
    trace: TraceSettings,
    voxel_size_m: f64,
    shell_voxels: f32,
) -> Result<MeshField> {
    let width = shell_voxels * voxel_size_m as f32;
    if !(width.is_finite() && width > 0.0) {
        return Err(BakeError::Settings(format!(
            "--shell-voxels {shell_voxels} must be positive"
        )));
    }
    Ok(MeshField::new(
        mesh,
        trace,
        DensityProfile::with_shell_width(width),
    )?)
}

/// Description of a ground-truth field for the metadata.
pub fn describe_trace(trace: &TraceSettings, shell_voxels: f32) -> serde_json::Value {
    serde_json::json!({
        "kind": "ground-truth-mesh-field",
        "bounces": trace.bounces,
        "texel_samples": trace.texel_samples,
        "indirect_samples": trace.indirect_samples,
        "bounce_texel_samples": trace.bounce_texel_samples,
        "specular_weight": trace.specular.map(|s| s.weight),
        "seed": trace.seed,
        "shell_voxels": shell_voxels,
    })
}
