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
//!
//! **Where the shell sits.** `MeshField`'s own profile centres the density ramp on
//! the surface, `σ(d) = σ_max·clamp(½ − d/w, 0, 1)` (`d` signed distance, negative
//! inside). Sampled on a grid and interpolated trilinearly, that density reaches
//! optical depth 1 one to two voxels *outside* the mesh (the ramp is 50 optical
//! depths steep), so a baked head renders visibly swollen. [`InsetMeshField`]
//! (the default, [`ShellPlacement::Inside`]) puts the whole ramp inside,
//! `σ(d) = σ_max·clamp(−d/w, 0, 1)` with `σ_max = 100/w`, which puts the rendered
//! surface within about a third of a voxel of the mesh; its light transport is
//! `MeshField`'s (the closest surface point's).

use std::path::{Path, PathBuf};

use glam::{DMat3, Vec3};
use nelf_format::conventions::LT_DIM;
use nelf_scene::field::{DensityProfile, FieldError, FieldSource, MeshField, ViewPolicy};
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

/// Where the ground-truth density's shell sits relative to the mesh surface.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum ShellPlacement {
    /// The ramp lies inside the surface ([`InsetMeshField`]).
    #[default]
    Inside,
    /// The ramp is centred on the surface (`MeshField`'s own profile).
    Centred,
}

/// A mesh's ground-truth field whose density ramps from 0 at the surface to `σ_max`
/// at depth `w` inside (module docs); light transport as [`MeshField`]'s.
#[derive(Debug, Clone)]
pub struct InsetMeshField {
    inner: MeshField,
    sigma_max_per_m: f32,
    width_m: f32,
}

impl InsetMeshField {
    /// The field of `inner`'s mesh with an inside ramp `width_m` wide reaching
    /// `σ_max = 100 / width_m` (optical depth 50 across it, as `MeshField`'s).
    pub fn new(inner: MeshField, width_m: f32) -> Result<Self> {
        if !(width_m.is_finite() && width_m > 0.0) {
            return Err(BakeError::Settings(format!(
                "shell width {width_m} m must be positive"
            )));
        }
        Ok(Self {
            inner,
            sigma_max_per_m: 100.0 / width_m,
            width_m,
        })
    }

    /// Density at `x`, 1/m.
    pub fn density(&self, x: Vec3) -> f32 {
        let bvh = self.inner.tracer().bvh();
        let inside = || bvh.winding_number(x) >= 0.5;
        match bvh.closest_point(x, self.width_m) {
            Some(cp) if inside() => self.sigma_max_per_m * (cp.distance / self.width_m).clamp(0.0, 1.0),
            None if inside() => self.sigma_max_per_m,
            Some(_) | None => 0.0,
        }
    }
}

impl FieldSource for InsetMeshField {
    fn evaluate(
        &self,
        points: &[Vec3],
        view: &ViewPolicy,
        density: &mut [f32],
        lt: &mut [f32],
    ) -> Result<(), FieldError> {
        self.inner.evaluate(points, view, density, lt)?;
        self.evaluate_density(points, density)
    }

    fn bounds(&self) -> (Vec3, Vec3) {
        self.inner.bounds()
    }

    fn world_from_light(&self) -> DMat3 {
        self.inner.world_from_light()
    }

    fn evaluate_density(&self, points: &[Vec3], density: &mut [f32]) -> Result<(), FieldError> {
        use rayon::prelude::*;
        if density.len() != points.len() {
            return Err(FieldError::LengthMismatch {
                points: points.len(),
                density: density.len(),
                lt: 0,
                lt_needed: points.len() * LT_DIM,
            });
        }
        if let Some(index) = points.iter().position(|p| !p.is_finite()) {
            return Err(FieldError::NotFinite { index });
        }
        points
            .par_iter()
            .zip(density.par_iter_mut())
            .for_each(|(x, d)| *d = self.density(*x));
        Ok(())
    }
}

/// The ground-truth field of `mesh` for a grid of `voxel_size_m`: a density shell
/// `shell_voxels` voxels wide placed by `placement`, light transport by `trace`.
pub fn mesh_field(
    mesh: &Mesh,
    trace: TraceSettings,
    voxel_size_m: f64,
    shell_voxels: f32,
    placement: ShellPlacement,
) -> Result<Box<dyn FieldSource>> {
    let width = shell_voxels * voxel_size_m as f32;
    if !(width.is_finite() && width > 0.0) {
        return Err(BakeError::Settings(format!(
            "--shell-voxels {shell_voxels} must be positive"
        )));
    }
    let field = MeshField::new(mesh, trace, DensityProfile::with_shell_width(width))?;
    Ok(match placement {
        ShellPlacement::Centred => Box::new(field),
        ShellPlacement::Inside => Box::new(InsetMeshField::new(field, width)?),
    })
}

/// Description of a ground-truth field for the metadata.
pub fn describe_trace(
    trace: &TraceSettings,
    shell_voxels: f32,
    placement: ShellPlacement,
) -> serde_json::Value {
    serde_json::json!({
        "kind": "ground-truth-mesh-field",
        "bounces": trace.bounces,
        "texel_samples": trace.texel_samples,
        "indirect_samples": trace.indirect_samples,
        "bounce_texel_samples": trace.bounce_texel_samples,
        "specular_weight": trace.specular.map(|s| s.weight),
        "seed": trace.seed,
        "shell_voxels": shell_voxels,
        "shell_placement": placement,
    })
}
