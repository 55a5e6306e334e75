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
//! depths steep), so a baked head renders visibly swollen. [`ShellProfile::Inside`]
//! puts the whole ramp inside, `σ(d) = σ_max·clamp(−d/w, 0, 1)` with `σ_max = 100/w`;
//! but every voxel centre outside the surface then holds 0 whatever its distance, so
//! the rendered surface snaps to the voxel lattice (a staircase up to a voxel deep
//! at silhouettes). The default, [`ShellProfile::Signed`], stores a *signed* linear
//! function of `d` (negative outside, SPEC's signed-density flag): trilinear
//! interpolation reproduces it exactly near a locally flat surface and the renderer
//! clips it at 0 after interpolating, so the surface lands where the mesh is, to a
//! small fraction of a voxel. Light transport is `MeshField`'s (the closest surface
//! point's) in every case.

use std::path::{Path, PathBuf};

use glam::{DMat3, Vec3};
use nelf_scene::field::{
    DensityProfile, FieldError, FieldSource, MeshField, ViewPolicy, check_density_batch,
};
use nelf_scene::mesh::Mesh;
use nelf_scene::mesh_io::{LoadOptions, load_mesh};
use nelf_scene::synth::{SynthConfig, synth_mesh};
use nelf_scene::tracer::TraceSettings;
use serde::{Deserialize, Serialize};

use crate::error::{BakeError, Result};
use crate::pipeline::BakeConfig;

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
    /// A signed linear ramp through the surface, negative outside ([`ShellProfile::Signed`]).
    #[default]
    Signed,
    /// The ramp lies inside the surface ([`ShellProfile::Inside`]).
    Inside,
    /// The ramp is centred on the surface (`MeshField`'s own profile).
    Centred,
}

/// How [`ShellMeshField`] turns signed distance `d` (negative inside) into density.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ShellProfile {
    /// `σ = σ_max · clamp(−d/w, 0, 1)`: 0 at the surface, `σ_max = 100/w` at depth `w`.
    Inside {
        /// Ramp width `w`, metres.
        width_m: f32,
    },
    /// `σ = clamp(s · (ℓ − d), −σ_cap, σ_cap)`: zero at the *lead* `ℓ` outside the
    /// surface, slope `s = 2 ln 2 / ℓ²` so that a ray arriving along the normal has
    /// optical depth `ln 2` (transmittance ½) exactly at the surface, and linear over
    /// `ℓ` plus two voxels on either side of the zero (`σ_cap = s · (ℓ + 2Δ)`).
    /// Trilinear interpolation reproduces an affine function exactly, and the
    /// renderer takes `max(0, ·)` of the interpolated value (SPEC §8), so a plane
    /// renders at its true position whatever its offset from the voxel lattice: no
    /// voxel staircase.
    Signed {
        /// Lead `ℓ`, metres.
        lead_m: f32,
        /// Voxel edge `Δ`, metres.
        voxel_m: f32,
    },
}

impl ShellProfile {
    /// Density at signed distance `d_m`, 1/m; `None` for `d_m` (the distance is only
    /// known within [`Self::reach_m`]) gives the deep value of the side `inside`.
    pub fn density(&self, d_m: Option<f32>, inside: bool) -> f32 {
        match *self {
            Self::Inside { width_m } => {
                let sigma_max = 100.0 / width_m;
                match d_m {
                    Some(d) if inside => sigma_max * (d.abs() / width_m).clamp(0.0, 1.0),
                    None if inside => sigma_max,
                    _ => 0.0,
                }
            }
            Self::Signed { lead_m, voxel_m } => {
                let slope = 2.0 * std::f32::consts::LN_2 / (lead_m * lead_m);
                let cap = slope * (lead_m + 2.0 * voxel_m);
                let signed_d = match d_m {
                    Some(d) => {
                        if inside {
                            -d.abs()
                        } else {
                            d.abs()
                        }
                    }
                    None => return if inside { cap } else { -cap },
                };
                (slope * (lead_m - signed_d)).clamp(-cap, cap)
            }
        }
    }

    /// Distance from the surface beyond which the density is constant, metres.
    pub fn reach_m(&self) -> f32 {
        match *self {
            Self::Inside { width_m } => width_m,
            Self::Signed { lead_m, voxel_m } => 2.0 * lead_m + 2.0 * voxel_m,
        }
    }

    fn validate(&self) -> Result<()> {
        let ok = |v: f32| v.is_finite() && v > 0.0;
        let good = match *self {
            Self::Inside { width_m } => ok(width_m),
            Self::Signed { lead_m, voxel_m } => ok(lead_m) && ok(voxel_m),
        };
        if good {
            Ok(())
        } else {
            Err(BakeError::Settings(format!(
                "density shell {self:?} needs positive, finite sizes"
            )))
        }
    }
}

/// A mesh's ground-truth field with its density shaped by a [`ShellProfile`];
/// light transport as [`MeshField`]'s.
#[derive(Debug, Clone)]
pub struct ShellMeshField {
    inner: MeshField,
    profile: ShellProfile,
}

impl ShellMeshField {
    /// The field of `inner`'s mesh with density `profile`.
    pub fn new(inner: MeshField, profile: ShellProfile) -> Result<Self> {
        profile.validate()?;
        Ok(Self { inner, profile })
    }

    /// Density at `x`, 1/m.
    pub fn density(&self, x: Vec3) -> f32 {
        let bvh = self.inner.tracer().bvh();
        let inside = bvh.winding_number(x) >= 0.5;
        let d = bvh.closest_point(x, self.profile.reach_m()).map(|cp| cp.distance);
        self.profile.density(d, inside)
    }
}

impl FieldSource for ShellMeshField {
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
        let (lo, hi) = self.inner.bounds();
        let pad = Vec3::splat(self.profile.reach_m());
        (lo.min(lo - pad), hi.max(hi + pad))
    }

    fn world_from_light(&self) -> DMat3 {
        self.inner.world_from_light()
    }

    fn evaluate_density(&self, points: &[Vec3], density: &mut [f32]) -> Result<(), FieldError> {
        use rayon::prelude::*;
        check_density_batch(points, density)?;
        points
            .par_iter()
            .zip(density.par_iter_mut())
            .for_each(|(x, d)| *d = self.density(*x));
        Ok(())
    }
}

/// The ground-truth field of `mesh` for a grid of `voxel_size_m`: a density shell
/// placed by `placement` (`shell_voxels` wide for `Inside`/`Centred`, a lead of
/// `lead_voxels` for `Signed`), light transport by `trace`.
pub fn mesh_field(
    mesh: &Mesh,
    trace: TraceSettings,
    voxel_size_m: f64,
    placement: ShellPlacement,
    shell_voxels: f32,
    lead_voxels: f32,
) -> Result<Box<dyn FieldSource>> {
    let voxel = voxel_size_m as f32;
    let width = shell_voxels * voxel;
    if !(width.is_finite() && width > 0.0) {
        return Err(BakeError::Settings(format!(
            "--shell-voxels {shell_voxels} must be positive"
        )));
    }
    let field = MeshField::new(mesh, trace, DensityProfile::with_shell_width(width))?;
    Ok(match placement {
        ShellPlacement::Centred => Box::new(field),
        ShellPlacement::Inside => Box::new(ShellMeshField::new(
            field,
            ShellProfile::Inside { width_m: width },
        )?),
        ShellPlacement::Signed => Box::new(ShellMeshField::new(
            field,
            ShellProfile::Signed {
                lead_m: lead_voxels * voxel,
                voxel_m: voxel,
            },
        )?),
    })
}

/// Description of a ground-truth field for the metadata.
pub fn describe_trace(trace: &TraceSettings, config: &BakeConfig) -> serde_json::Value {
    serde_json::json!({
        "kind": "ground-truth-mesh-field",
        "bounces": trace.bounces,
        "texel_samples": trace.texel_samples,
        "indirect_samples": trace.indirect_samples,
        "bounce_texel_samples": trace.bounce_texel_samples,
        "specular_weight": trace.specular.map(|s| s.weight),
        "seed": trace.seed,
        "shell_placement": config.shell_placement,
        "shell_voxels": config.shell_voxels,
        "lead_voxels": config.lead_voxels,
    })
}

#[cfg(test)]
mod tests {
    use glam::DVec3;
    use nelf_scene::shapes::uv_sphere;

    use super::*;
    use crate::grid::{PROBE_RESOLUTION, occupied_box};
    use crate::progress::Progress;

    #[test]
    fn signed_profile_puts_half_transmittance_at_the_surface() {
        let (lead, voxel) = (0.25e-3f32, 1e-3f32);
        let p = ShellProfile::Signed {
            lead_m: lead,
            voxel_m: voxel,
        };
        // Zero at the lead outside, negative beyond, linear through the surface.
        assert!(p.density(Some(lead), false).abs() < 1e-2);
        assert!(p.density(Some(0.8e-3), false) < 0.0);
        let slope = (p.density(Some(0.5e-3), true) - p.density(Some(0.0), true)) / 0.5e-3;
        let on_surface = p.density(Some(0.0), false);
        assert!((on_surface - slope * lead).abs() < 1e-3 * on_surface);
        // Optical depth from the zero crossing to the surface, along the normal: ln 2.
        let tau = 0.5 * slope * lead * lead;
        assert!((tau - std::f32::consts::LN_2).abs() < 1e-4, "{tau}");
        // Far from the surface (distance unknown): the caps, ± slope·(lead + 2 voxels).
        let cap = slope * (lead + 2.0 * voxel);
        assert!((p.density(None, true) - cap).abs() < 1e-3 * cap);
        assert!((p.density(None, false) + cap).abs() < 1e-3 * cap);
        assert!((p.density(Some(0.01), true) - cap).abs() < 1e-3 * cap);
        // The inside ramp is 0 everywhere outside.
        let inside = ShellProfile::Inside { width_m: 2e-3 };
        assert_eq!(inside.density(Some(0.5e-3), false), 0.0);
        assert!((inside.density(Some(1e-3), true) - 0.5 * 100.0 / 2e-3).abs() < 1.0);
    }

    #[test]
    fn occupied_box_is_the_dense_region_not_the_search_box() {
        let radius = 0.05f32;
        let mesh = uv_sphere(Vec3::new(0.01, 0.0, -0.02), radius, 24, 48, [0.5; 3]);
        let field = mesh_field(
            &mesh,
            TraceSettings::default(),
            1e-3,
            ShellPlacement::Signed,
            2.0,
            0.25,
        )
        .unwrap();
        // A search box much deeper than the sphere (as a frontal-view hull is).
        let (lo, hi) = (DVec3::new(-0.1, -0.1, -0.3), DVec3::new(0.1, 0.1, 0.3));
        let (box_lo, box_hi) = occupied_box(None, lo, hi, field.as_ref(), 0.01, &Progress::hidden()).unwrap();
        let probe = (hi - lo).max_element() / f64::from(PROBE_RESOLUTION);
        let centre = DVec3::new(0.01, 0.0, -0.02);
        let r = f64::from(radius);
        for a in 0..3 {
            // Holds the sphere, within two probe voxels of it.
            assert!(
                box_lo[a] <= centre[a] - r && box_lo[a] >= centre[a] - r - 2.0 * probe,
                "{a}: {box_lo}"
            );
            assert!(
                box_hi[a] >= centre[a] + r && box_hi[a] <= centre[a] + r + 2.0 * probe,
                "{a}: {box_hi}"
            );
        }
    }
}
