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
//!
//! **Shared light transport.** The voxels of the band around a surface (two to
//! three deep on each side) have nearly the same closest point, and path-tracing
//! each of them was most of a bake. With `--lt-share-voxels C` (default 2) points
//! whose closest points lie on the same triangle, on the same side, in the same
//! world-lattice cell of `C` voxels share one trace, made at the triangle's point
//! closest to the cell's centre and rescaled per colour channel to each point's
//! own albedo (diffuse transport is proportional to it), so texture finer than a
//! cell survives; its price in time and accuracy is measured in bake/README.md.

use std::path::{Path, PathBuf};

use glam::{DMat3, Vec3};
use nelf_format::conventions::{ENV_TEXELS, LT_DIM};
use nelf_format::io_error::IoResultExt;
use nelf_scene::bvh::{ClosestPoint, closest_point_on_triangle};
use nelf_scene::field::{
    DensityProfile, FieldError, FieldSource, MeshField, ViewPolicy, check_batch, check_density_batch,
    check_directions_batch, evaluate_directions_in_parallel, evaluate_in_parallel,
};
use nelf_scene::mesh::Mesh;
use nelf_scene::mesh_io::{LoadOptions, load_mesh};
use nelf_scene::synth::{SynthConfig, synth_mesh};
use nelf_scene::tracer::{MAX_AVERAGED_DIRECTIONS, TraceSettings};

use crate::config::{BakeConfig, ShellPlacement};
use crate::error::{BakeError, Result};

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
    /// A mesh made in memory (a surface reconstructed from photographs), traced
    /// with the default settings.
    Reconstructed {
        /// The mesh.
        mesh: Box<Mesh>,
        /// How it was made, for the asset's metadata.
        description: serde_json::Value,
    },
}

/// Name of the synthetic capture configuration inside a capture folder.
pub const SYNTH_CONFIG_FILE: &str = "synth_config.json";

impl GroundTruth {
    /// Reads `dir/synth_config.json`.
    pub fn from_synth_capture(dir: &Path) -> Result<Self> {
        let path = dir.join(SYNTH_CONFIG_FILE);
        let text = std::fs::read_to_string(&path).with_path(&path)?;
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
            Self::Reconstructed { mesh, .. } => Ok(mesh.as_ref().clone()),
        }
    }

    /// Path-tracer settings: the synthetic capture's, else the defaults.
    pub fn trace_settings(&self) -> TraceSettings {
        match self {
            Self::Synth { config, .. } => config.trace_settings(),
            Self::MeshFile { .. } | Self::Reconstructed { .. } => TraceSettings::default(),
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
            Self::Reconstructed { description, .. } => serde_json::json!({
                "kind": "reconstructed-mesh",
                "reconstruction": description,
            }),
        }
    }
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
    /// surface, slope `s = 2 ln 2 / r²` for a *ramp* `r`, so that a ray arriving along
    /// the normal reaches optical depth `ln 2` (transmittance ½) a distance `r` past the
    /// zero, and linear over `max(ℓ, r)` plus two voxels on either side of the zero
    /// (`σ_cap = s · (max(ℓ, r) + 2Δ)`).
    ///
    /// With `ℓ = r` the surface has transmittance ½ along its normal; but a ray that
    /// grazes a convex surface of radius `R` crosses the positive layer outside it along
    /// a chord, and reaches transmittance ½ at a distance `δ` outside where
    /// `(ℓ − δ)^{3/2} = 3 r² / (8 √(2R))` (voxels): about 0.23 voxels for `ℓ = r = ¼`
    /// and `R` = 40 voxels, so the silhouette of a head grows by ~0.45 mm at 1.9 mm
    /// voxels. A smaller lead at the same ramp keeps the ramp the march can resolve
    /// and puts the grazing silhouette on the surface; the visible surface along the
    /// normal then lies `r − ℓ` inside, where the transport is the same closest
    /// point's (measured in bake/README.md, "Where the shell sits").
    /// Trilinear interpolation reproduces an affine function exactly, and the
    /// renderer takes `max(0, ·)` of the interpolated value (SPEC §8), so a plane
    /// renders at its true position whatever its offset from the voxel lattice: no
    /// voxel staircase.
    Signed {
        /// Lead `ℓ`, metres.
        lead_m: f32,
        /// Ramp `r`, metres.
        ramp_m: f32,
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
            Self::Signed {
                lead_m,
                ramp_m,
                voxel_m,
            } => {
                let slope = 2.0 * std::f32::consts::LN_2 / (ramp_m * ramp_m);
                let cap = slope * (lead_m.max(ramp_m) + 2.0 * voxel_m);
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

    /// How much thicker a sheet's positive layer is made on each side than the lead
    /// alone would make it, metres: `r − ℓ` (at least 0) for [`Self::Signed`], so that
    /// a sheet's visible faces stay where a lead equal to the ramp puts them, `t/2`
    /// from its middle. A sheet is seen face-on, not along its chord, and with the
    /// closed surfaces' smaller lead its faces came 0.2 voxels nearer the middle,
    /// where the interpolation mixes in the other side's shading (measured:
    /// `bake/tests/defects.rs`, a one-sided sheet's interior 21.8 dB instead of ≥ 27).
    pub fn sheet_extra_m(&self) -> f32 {
        match *self {
            Self::Inside { .. } => 0.0,
            Self::Signed { lead_m, ramp_m, .. } => (ramp_m - lead_m).max(0.0),
        }
    }

    /// Distance from the surface beyond which the density is constant, metres.
    pub fn reach_m(&self) -> f32 {
        match *self {
            Self::Inside { width_m } => width_m,
            Self::Signed {
                lead_m,
                ramp_m,
                voxel_m,
            } => 2.0 * lead_m.max(ramp_m) + 2.0 * voxel_m,
        }
    }

    fn validate(&self) -> Result<()> {
        let ok = |v: f32| v.is_finite() && v > 0.0;
        let good = match *self {
            Self::Inside { width_m } => ok(width_m),
            Self::Signed {
                lead_m,
                ramp_m,
                voxel_m,
            } => ok(lead_m) && ok(ramp_m) && ok(voxel_m),
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
/// light transport as [`MeshField`]'s, shaded on the side each point sees.
///
/// **Open and thin surfaces.** Inside and outside come from the generalised winding
/// number, which puts both sides of an open sheet (a collar, a flap of cloth, a
/// zero-volume cap over a flap) near ±½: a shell built on `w ≥ ½` would leave such
/// a sheet transparent or fill the hollow behind a bent one. Where the surface
/// closest to a point is open or thinner than `sheet_thickness_m` (told apart by
/// the winding number on both sides of it, [`Self::locate`]), the density is the
/// profile's for a sheet of that thickness centred on the surface (signed distance
/// `|d| − t/2`). Closed surfaces thicker than `t` are unchanged.
///
/// **Hollow shells.** With `hollow_depth_m = Some(D)` the inside of a closed surface
/// is a shell `D` thick, empty beyond (its inner wall is a signed ramp like the
/// outer one). From outside nothing changes (the outer ramp and everything within
/// `D/2` of it are as before); through a hole in the surface (a torn shell whose
/// winding number still says "inside") a camera sees the inner wall, shaded facing
/// the hollow, as the two-sided path tracer shows the inside of the mesh.
///
/// **Sides.** A point behind an open sheet, a point outside a closed surface whose
/// closest triangle is wound inward (flipped), and a point in the inner half of a
/// hollow shell are shaded with the normal turned toward them; a point within a hair
/// of an open sheet takes the side the view policy's directions face (with
/// [`FieldSource::evaluate_directions`], the side each direction faces).
#[derive(Debug, Clone)]
pub struct ShellMeshField {
    inner: MeshField,
    profile: ShellProfile,
    sheet_thickness_m: f32,
    hollow_depth_m: Option<f32>,
    share_cell_m: Option<f32>,
    albedo_footprint_m: Option<f32>,
}

/// Below this traced albedo a shared vector is not rescaled to a point's own albedo.
const ALBEDO_RATIO_FLOOR: f32 = 1e-3;

/// The light transport a located point shares with others: its closest triangle,
/// the side it sees, and the world-lattice cell its closest point lies in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
struct ShareKey {
    triangle: u32,
    back: bool,
    cell: [i32; 3],
}

/// What [`ShellMeshField`] decides at a point.
#[derive(Debug, Clone, Copy)]
struct Located {
    density: f32,
    /// The closest surface point, when one is within the search distance.
    closest: Option<ClosestPoint>,
    /// Whether the point sees the closest triangle's back (normals to be turned).
    back: bool,
    /// Whether the side is a tie (the point lies on an open sheet).
    tie: bool,
}

impl ShellMeshField {
    /// The field of `inner`'s mesh with density `profile`, thin parts thickened to
    /// `sheet_thickness_m`, closed parts hollow beyond `hollow_depth_m` (if given).
    pub fn new(
        inner: MeshField,
        profile: ShellProfile,
        sheet_thickness_m: f32,
        hollow_depth_m: Option<f32>,
    ) -> Result<Self> {
        profile.validate()?;
        let positive = |v: f32| v.is_finite() && v > 0.0;
        if !positive(sheet_thickness_m) || !hollow_depth_m.is_none_or(positive) {
            return Err(BakeError::Settings(format!(
                "sheet thickness {sheet_thickness_m} m and hollow depth {hollow_depth_m:?} m must be positive"
            )));
        }
        Ok(Self {
            inner,
            profile,
            sheet_thickness_m,
            hollow_depth_m,
            share_cell_m: None,
            albedo_footprint_m: None,
        })
    }

    /// Each point's own albedo (what a shared vector is rescaled to) averaged over a
    /// square of this side around its closest surface point (`Mesh::albedo_footprint`),
    /// instead of read at that point: a voxel then carries the texture it covers, not
    /// a pore that happens to lie under its centre (`None`: read at the point).
    #[must_use]
    pub fn with_albedo_footprint(mut self, footprint_m: Option<f32>) -> Self {
        self.albedo_footprint_m = footprint_m.filter(|f| f.is_finite() && *f > 0.0);
        self
    }

    /// A located point's own albedo (see [`Self::with_albedo_footprint`]).
    fn own_albedo(&self, mesh: &Mesh, cp: &ClosestPoint) -> [f32; 3] {
        let t = cp.triangle as usize;
        match self.albedo_footprint_m {
            Some(footprint) => mesh.albedo_footprint(t, cp.b1, cp.b2, footprint),
            None => mesh.albedo_at(t, cp.b1, cp.b2),
        }
    }

    /// Shares light transport among points whose closest points lie on the same
    /// triangle, seen from the same side, in the same cubic cell of edge `cell_m`
    /// (`None` or 0: every point traces its own). Each shared value is traced at the
    /// point of the triangle closest to the cell's centre, so it is a function of
    /// the cell alone, whatever the batch.
    #[must_use]
    pub fn with_shared_transport(mut self, cell_m: Option<f32>) -> Self {
        self.share_cell_m = cell_m.filter(|c| c.is_finite() && *c > 0.0);
        self
    }

    /// Distance from the surface within which the density varies.
    fn reach_m(&self) -> f32 {
        let sheet = 0.5 * self.sheet_thickness_m + self.profile.reach_m();
        let hollow = self.hollow_depth_m.map_or(0.0, |d| d + self.profile.reach_m());
        sheet.max(hollow).max(self.profile.reach_m())
    }

    /// Density at `x`, 1/m.
    pub fn density(&self, x: Vec3) -> f32 {
        self.locate(x, self.reach_m()).density
    }

    /// The winding numbers half as deep, in front of and behind `cp`, where the probe
    /// from `cp` into the surface along `-probe_dir` left a closed solid only because it
    /// ran out under a crease: it exits within `probe` through a
    /// face across its path (the face's normal within 60° of square to it), and half way
    /// to that exit the winding number says closed. A part thinner than `probe` exits
    /// through a face that looks back along the probe and stays a sheet, as does an
    /// open sheet (±½ on its two sides). Points beside a scan's flat-cut neck, whose
    /// closest point lies on the side wall a hair above the cut, would otherwise take
    /// the wall's rim for a sheet's and grow a tube below it.
    fn beside_a_crease(&self, cp: &ClosestPoint, probe_dir: Vec3, probe: f32) -> Option<(f32, f32)> {
        let bvh = self.inner.tracer().bvh();
        let inward = -probe_dir;
        let lift = 1e-4 * probe;
        let hit = bvh.closest_hit(cp.point + inward * lift, inward, 0.0, probe)?;
        let exit_normal = self.inner.tracer().mesh().face_normal(hit.triangle as usize);
        if exit_normal.dot(inward).abs() >= 0.5 {
            return None;
        }
        let half = 0.5 * (hit.t + lift);
        let readings = (
            bvh.winding_number(cp.point + probe_dir * half),
            bvh.winding_number(cp.point + inward * half),
        );
        (0.5 * (readings.0 + readings.1) >= 0.25).then_some(readings)
    }

    /// Density, closest point (searched up to `max_distance_m`) and side at `x`.
    ///
    /// Near a surface (within [`Self::reach_m`]) the winding number is read on both
    /// sides of the closest point, `sheet_thickness_m` away along its normal: across
    /// any surface it jumps by 1, from about 0 to 1 for a closed one (inside where
    /// it is 1, whichever way the triangle is wound) and from about −½ to ½ for an
    /// open sheet. So the mean of the two readings says which it is (≥ ¼: closed),
    /// robustly on both sides of a bent sheet, inside a torn shell, and next to
    /// flipped triangles. Far from every surface, `x`'s own winding number decides.
    fn locate(&self, x: Vec3, max_distance_m: f32) -> Located {
        let bvh = self.inner.tracer().bvh();
        let closest = bvh.closest_point(x, max_distance_m);
        let mut out = Located {
            density: 0.0,
            closest,
            back: false,
            tie: false,
        };
        let Some(cp) = closest.filter(|c| c.distance <= self.reach_m()) else {
            // Far from every surface: solid inside (unless hollow), empty outside.
            let inside = bvh.winding_number(x) >= 0.5;
            out.density = self
                .profile
                .density(None, inside && self.hollow_depth_m.is_none());
            out.back = inside && self.hollow_depth_m.is_some();
            return out;
        };
        let normal = self.inner.tracer().mesh().face_normal(cp.triangle as usize);
        let side = (x - cp.point).dot(normal);
        let probe = self.sheet_thickness_m;
        // The winding number is read along the direction from the closest point to `x`
        // (turned into the face normal's hemisphere), which is the face normal where
        // the closest point lies inside a triangle. Where it lies on an edge — a crease
        // such as the rim of a cut neck — the face normal would probe along the other
        // face's plane, read ~½ there and take the crease for an open sheet, thickening
        // it into a tube a voxel round (a dark band below a scan's neck).
        let offset = x - cp.point;
        let probe_dir = if cp.distance > 1e-3 * probe {
            let dir = offset / cp.distance;
            if dir.dot(normal) < 0.0 { -dir } else { dir }
        } else {
            normal
        };
        let mut front = bvh.winding_number(cp.point + probe_dir * probe);
        let mut behind = bvh.winding_number(cp.point - probe_dir * probe);
        if 0.5 * (front + behind) < 0.25
            && let Some((f, b)) = self.beside_a_crease(&cp, probe_dir, probe)
        {
            (front, behind) = (f, b);
        }
        if 0.5 * (front + behind) < 0.25 {
            // An open sheet, or a part thinner than the sheet thickness.
            let d = cp.distance - 0.5 * self.sheet_thickness_m - self.profile.sheet_extra_m();
            out.density = self.profile.density(Some(d.abs()), d < 0.0);
            out.back = side < 0.0;
            out.tie = side.abs() < 0.05 * self.sheet_thickness_m;
            return out;
        }
        // A closed surface; its outside is where the winding number is low.
        let outward = if front <= behind { 1.0 } else { -1.0 };
        let inside = side * outward < 0.0;
        if !inside {
            out.density = self.profile.density(Some(cp.distance), false);
            out.back = outward < 0.0;
            return out;
        }
        match self.hollow_depth_m {
            Some(depth) if cp.distance > 0.5 * depth => {
                // The inner half of a hollow shell: signed distance to its inner wall,
                // shaded facing the hollow.
                let d = depth - cp.distance;
                out.density = self.profile.density(Some(d.abs()), d > 0.0);
                out.back = outward > 0.0;
            }
            _ => {
                out.density = self.profile.density(Some(cp.distance), true);
                out.back = outward < 0.0;
            }
        }
        out
    }

    /// Density at `x`, and the closest surface point with the side `x` sees (turn
    /// the normals when `true`), if any.
    fn side_at(&self, x: Vec3, view: &ViewPolicy) -> (f32, Option<(ClosestPoint, bool)>) {
        let located = self.locate(x, f32::INFINITY);
        let Some(cp) = located.closest else {
            return (located.density, None);
        };
        let back = if located.tie {
            // On the sheet itself: the side the view policy's directions face.
            let normal = self.face_normal(&cp);
            let mut omegas = [Vec3::ZERO; MAX_AVERAGED_DIRECTIONS];
            let n = view.directions_at(x, normal, &mut omegas);
            omegas[..n].iter().sum::<Vec3>().dot(normal) < 0.0
        } else {
            located.back
        };
        (located.density, Some((cp, back)))
    }

    /// The true normal of the closest point's triangle.
    fn face_normal(&self, cp: &ClosestPoint) -> Vec3 {
        self.inner.tracer().mesh().face_normal(cp.triangle as usize)
    }

    /// The side a located point sees toward each fixed direction: [`Located::back`],
    /// except on an open sheet (a tie), where each direction decides as
    /// [`Self::side_at`] decides for `ViewPolicy::Direction(direction)`.
    fn sides_toward(&self, located: &Located, cp: &ClosestPoint, directions: &[Vec3]) -> Vec<bool> {
        if located.tie {
            let normal = self.face_normal(cp);
            directions
                .iter()
                .map(|d| d.normalize_or(normal).dot(normal) < 0.0)
                .collect()
        } else {
            vec![located.back; directions.len()]
        }
    }

    /// Writes to `out` (`directions.len() × 384` floats) the light transport of
    /// surface point `cp` toward each direction `d`, on the side `back[d]` says: one
    /// trace per side ([`MeshField::light_transport_directions_at`]).
    fn light_transport_directions(
        &self,
        cp: &ClosestPoint,
        back: &[bool],
        directions: &[Vec3],
        out: &mut [f32],
    ) {
        let surface = |back: bool| {
            let sp = self.inner.surface_at(cp);
            if back { sp.turned() } else { sp }
        };
        if back.iter().all(|&b| b == back[0]) {
            self.inner
                .light_transport_directions_at(&surface(back[0]), cp, directions, out);
            return;
        }
        for side in [false, true] {
            let chosen: Vec<usize> = (0..directions.len()).filter(|&d| back[d] == side).collect();
            let toward: Vec<Vec3> = chosen.iter().map(|&d| directions[d]).collect();
            let mut vectors = vec![0.0f32; chosen.len() * LT_DIM];
            self.inner
                .light_transport_directions_at(&surface(side), cp, &toward, &mut vectors);
            for (&d, v) in chosen.iter().zip(vectors.chunks_exact(LT_DIM)) {
                out[d * LT_DIM..(d + 1) * LT_DIM].copy_from_slice(v);
            }
        }
    }

    /// Adds to `out` the light transport of surface point `cp` seen from `x` on the
    /// side `back` says.
    fn light_transport(&self, x: Vec3, cp: &ClosestPoint, back: bool, view: &ViewPolicy, out: &mut [f32]) {
        let sp = self.inner.surface_at(cp);
        let sp = if back { sp.turned() } else { sp };
        self.inner.light_transport_at(x, &sp, cp, view, out);
    }

    /// Density and light transport of one point (`out` zeroed by the caller).
    fn evaluate_point(&self, x: Vec3, view: &ViewPolicy, out: &mut [f32]) -> f32 {
        let (density, side) = self.side_at(x, view);
        if let Some((cp, back)) = side {
            self.light_transport(x, &cp, back, view, out);
        }
        density
    }

    /// [`FieldSource::evaluate`] with shared light transport (see
    /// [`Self::with_shared_transport`]): locate every point, trace each distinct
    /// [`ShareKey`] once, copy.
    fn evaluate_shared(
        &self,
        cell_m: f32,
        points: &[Vec3],
        view: &ViewPolicy,
        density: &mut [f32],
        lt: &mut [f32],
    ) -> Result<(), FieldError> {
        use rayon::prelude::*;
        check_batch(points, density, lt)?;
        view.validate()?;
        let mesh = self.inner.tracer().mesh();
        // Each point's key and its own closest point's albedo.
        let located: Vec<Option<(ShareKey, [f32; 3])>> = points
            .par_iter()
            .zip(density.par_iter_mut())
            .map(|(x, d)| {
                let (sigma, side) = self.side_at(*x, view);
                *d = sigma;
                side.map(|(cp, back)| {
                    let key = ShareKey {
                        triangle: cp.triangle,
                        back,
                        cell: (cp.point / cell_m).floor().as_ivec3().to_array(),
                    };
                    (key, self.own_albedo(mesh, &cp))
                })
            })
            .collect();
        let mut distinct: Vec<ShareKey> = located.iter().flatten().map(|(k, _)| *k).collect();
        distinct.par_sort_unstable();
        distinct.dedup();
        // One trace per key, with the albedo it was traced with.
        let mut shared = vec![0.0f32; distinct.len() * LT_DIM];
        let traced_albedo: Vec<[f32; 3]> = shared
            .par_chunks_mut(LT_DIM)
            .zip(distinct.par_iter())
            .map(|(out, key)| {
                let centre = (glam::IVec3::from_array(key.cell).as_vec3() + 0.5) * cell_m;
                let (point, b1, b2) = closest_point_on_triangle(mesh.corners(key.triangle as usize), centre);
                let cp = ClosestPoint {
                    point,
                    triangle: key.triangle,
                    b1,
                    b2,
                    distance: 0.0,
                };
                self.light_transport(point, &cp, key.back, view, out);
                mesh.albedo_at(key.triangle as usize, b1, b2)
            })
            .collect();
        // Diffuse light transport is proportional to the albedo at the point, so each
        // point rescales the shared vector to its own albedo (texture detail finer
        // than a cell survives); the specular part, a few per cent, is shared as is.
        lt.par_chunks_mut(LT_DIM)
            .zip(located.par_iter())
            .for_each(|(out, entry)| {
                let Some((i, albedo)) =
                    entry.and_then(|(k, a)| distinct.binary_search(&k).ok().map(|i| (i, a)))
                else {
                    out.fill(0.0);
                    return;
                };
                rescale_shared(
                    &shared[i * LT_DIM..(i + 1) * LT_DIM],
                    traced_albedo[i],
                    albedo,
                    out,
                );
            });
        Ok(())
    }

    /// [`FieldSource::evaluate_directions`] with shared light transport: as
    /// [`Self::evaluate_shared`], with every point's key per direction (the side of
    /// a point on an open sheet depends on the direction) and one trace per distinct
    /// key for all the directions. The shared vectors take as much memory as the
    /// output for that many points.
    fn evaluate_shared_directions(
        &self,
        cell_m: f32,
        points: &[Vec3],
        directions: &[Vec3],
        density: &mut [f32],
        lt: &mut [f32],
    ) -> Result<(), FieldError> {
        use rayon::prelude::*;
        check_directions_batch(points, directions, density, lt)?;
        let count = directions.len();
        let mesh = self.inner.tracer().mesh();
        // Each point's key per direction and its own closest point's albedo.
        let located: Vec<Option<(Vec<ShareKey>, [f32; 3])>> = points
            .par_iter()
            .zip(density.par_iter_mut())
            .map(|(x, d)| {
                let located = self.locate(*x, f32::INFINITY);
                *d = located.density;
                located.closest.map(|cp| {
                    let cell = (cp.point / cell_m).floor().as_ivec3().to_array();
                    let keys = self
                        .sides_toward(&located, &cp, directions)
                        .into_iter()
                        .map(|back| ShareKey {
                            triangle: cp.triangle,
                            back,
                            cell,
                        })
                        .collect();
                    (keys, self.own_albedo(mesh, &cp))
                })
            })
            .collect();
        let mut distinct: Vec<ShareKey> = located
            .iter()
            .flatten()
            .flat_map(|(keys, _)| keys.iter().copied())
            .collect();
        distinct.par_sort_unstable();
        distinct.dedup();
        // One trace per key toward every direction, with the albedo it was traced with.
        let mut shared = vec![0.0f32; distinct.len() * count * LT_DIM];
        let traced_albedo: Vec<[f32; 3]> = shared
            .par_chunks_mut(count * LT_DIM)
            .zip(distinct.par_iter())
            .map(|(out, key)| {
                let centre = (glam::IVec3::from_array(key.cell).as_vec3() + 0.5) * cell_m;
                let (point, b1, b2) = closest_point_on_triangle(mesh.corners(key.triangle as usize), centre);
                let cp = ClosestPoint {
                    point,
                    triangle: key.triangle,
                    b1,
                    b2,
                    distance: 0.0,
                };
                self.light_transport_directions(&cp, &vec![key.back; count], directions, out);
                mesh.albedo_at(key.triangle as usize, b1, b2)
            })
            .collect();
        lt.par_chunks_mut(count * LT_DIM)
            .zip(located.par_iter())
            .for_each(|(out, entry)| {
                let Some((keys, albedo)) = entry else {
                    out.fill(0.0);
                    return;
                };
                for (d, (out, key)) in out.chunks_exact_mut(LT_DIM).zip(keys).enumerate() {
                    match distinct.binary_search(key) {
                        Ok(i) => {
                            let at = (i * count + d) * LT_DIM;
                            rescale_shared(&shared[at..at + LT_DIM], traced_albedo[i], *albedo, out);
                        }
                        Err(_) => out.fill(0.0),
                    }
                }
            });
        Ok(())
    }
}

/// Writes to `out` a shared vector `source`, traced with albedo `traced`, rescaled
/// per colour channel to a point's own `albedo` (diffuse light transport is
/// proportional to it; the specular part, a few per cent, is shared as is). Below
/// [`ALBEDO_RATIO_FLOOR`] a channel is copied unscaled.
fn rescale_shared(source: &[f32], traced: [f32; 3], albedo: [f32; 3], out: &mut [f32]) {
    for (c, (o, s)) in out
        .chunks_mut(ENV_TEXELS)
        .zip(source.chunks(ENV_TEXELS))
        .enumerate()
    {
        let ratio = if traced[c] > ALBEDO_RATIO_FLOOR {
            albedo[c] / traced[c]
        } else {
            1.0
        };
        for (o, s) in o.iter_mut().zip(s) {
            *o = s * ratio;
        }
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
        if let Some(cell_m) = self.share_cell_m {
            return self.evaluate_shared(cell_m, points, view, density, lt);
        }
        evaluate_in_parallel(points, view, density, lt, None, |x, out| {
            self.evaluate_point(x, view, out)
        })
    }

    /// One trace per point (or shared key) and side for all directions, equal to
    /// per-direction [`Self::evaluate`] calls bit for bit; a point on an open sheet
    /// takes, per direction, the side that direction faces.
    fn evaluate_directions(
        &self,
        points: &[Vec3],
        directions: &[Vec3],
        density: &mut [f32],
        lt: &mut [f32],
    ) -> Result<(), FieldError> {
        if let Some(cell_m) = self.share_cell_m {
            return self.evaluate_shared_directions(cell_m, points, directions, density, lt);
        }
        evaluate_directions_in_parallel(points, directions, density, lt, |x, out| {
            let located = self.locate(x, f32::INFINITY);
            match located.closest {
                Some(cp) => {
                    let back = self.sides_toward(&located, &cp, directions);
                    self.light_transport_directions(&cp, &back, directions, out);
                }
                None => out.fill(0.0),
            }
            located.density
        })
    }

    fn bounds(&self) -> (Vec3, Vec3) {
        let (lo, hi) = self.inner.bounds();
        let pad = Vec3::splat(self.reach_m());
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
/// placed by `placement` (`config.shell_voxels` wide for `Inside`/`Centred`, a lead
/// of `config.lead_voxels` for `Signed`), open sheets `config.sheet_voxels` thick,
/// closed parts hollow beyond `config.hollow_voxels` (`Signed` only; 0 keeps them
/// solid), light transport by `trace`.
pub fn mesh_field(
    mesh: &Mesh,
    trace: TraceSettings,
    voxel_size_m: f64,
    placement: ShellPlacement,
    config: &BakeConfig,
) -> Result<Box<dyn FieldSource>> {
    let voxel = voxel_size_m as f32;
    let width = config.shell_voxels * voxel;
    if !(width.is_finite() && width > 0.0) {
        return Err(BakeError::Settings(format!(
            "--shell-voxels {} must be positive",
            config.shell_voxels
        )));
    }
    let sheet = config.sheet_voxels * voxel;
    let share = Some(config.lt_share_voxels * voxel);
    let field = MeshField::new(mesh, trace, DensityProfile::with_shell_width(width))?;
    Ok(match placement {
        ShellPlacement::Centred => Box::new(field),
        ShellPlacement::Inside => Box::new(
            ShellMeshField::new(field, ShellProfile::Inside { width_m: width }, sheet, None)?
                .with_shared_transport(share)
                .with_albedo_footprint(Some(voxel)),
        ),
        ShellPlacement::Signed => Box::new(
            ShellMeshField::new(
                field,
                ShellProfile::Signed {
                    lead_m: config.lead_voxels * voxel,
                    ramp_m: config.ramp_voxels * voxel,
                    voxel_m: voxel,
                },
                sheet,
                (config.hollow_voxels > 0.0).then_some(config.hollow_voxels * voxel),
            )?
            .with_shared_transport(share)
            .with_albedo_footprint(Some(voxel)),
        ),
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
        "ramp_voxels": config.ramp_voxels,
        "sheet_voxels": config.sheet_voxels,
        "lt_share_voxels": config.lt_share_voxels,
        "hollow_voxels": config.hollow_voxels,
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
            ramp_m: lead,
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
            &BakeConfig::default(),
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

    /// A closed solid's sharp edges are creases, not open sheets: just outside an
    /// edge the density is the signed profile's (zero a lead away from the surface),
    /// not a sheet's tube a voxel round. Before the winding number was read along the
    /// direction to the point, the probe from a 60° edge along a face's inward normal
    /// left the solid through the other face, both readings said "outside", and the
    /// edge grew a tube (the dark band below a scan's cut neck).
    #[test]
    fn a_sharp_edge_of_a_closed_solid_stays_sharp() {
        let voxel = 2e-3f32;
        // A prism along z, its cross-section an equilateral triangle (60° edges).
        let (r, h) = (0.05f32, 0.05f32);
        let corner = |k: u32, z: f32| {
            let a = std::f32::consts::FRAC_PI_2 + k as f32 * std::f32::consts::TAU / 3.0;
            Vec3::new(r * a.cos(), r * a.sin(), z)
        };
        let positions: Vec<Vec3> = (0..3)
            .map(|k| corner(k, -h))
            .chain((0..3).map(|k| corner(k, h)))
            .collect();
        let mut triangles = vec![[0u32, 2, 1], [3, 4, 5]];
        for k in 0..3u32 {
            let j = (k + 1) % 3;
            triangles.push([k, j, j + 3]);
            triangles.push([k, j + 3, k + 3]);
        }
        let mesh = Mesh {
            positions,
            triangles,
            albedo: nelf_scene::mesh::Albedo::Uniform([0.5; 3]),
        };
        mesh.validate().unwrap();
        let (shell, profile) = one_sample_shell(&mesh, voxel, 0.05);
        let apex = corner(0, 0.0);
        for along in [-0.03f32, 0.0, 0.02] {
            for d in [0.2f32, 0.5, 1.0, 1.5].map(|k| k * voxel) {
                // Straight out of the apex edge, along its bisector.
                let x = apex + Vec3::new(0.0, d, along);
                let sigma = shell.density(x);
                let expected = profile.density(Some(d), false);
                assert!(
                    (sigma - expected).abs() <= 1e-3 * expected.abs().max(1.0),
                    "{d} m off the edge at z = {along}: σ = {sigma}, the signed profile's {expected}"
                );
                assert!(sigma <= 0.0, "{d} m off the edge is outside: σ = {sigma}");
            }
        }
        // Inside, near the edge: dense.
        assert!(shell.density(apex - Vec3::new(0.0, 0.5 * voxel, 0.0)) > 0.0);

        // Beside a face a hair below a crease: a box whose top is dented into a
        // shallow pyramid (a scan's flat-cut neck, closed by a fan). The probe along the
        // side's normal runs out under the dented top within a sheet thickness.
        let (h, dent) = (0.05f32, 0.005f32);
        let mut positions = Vec::new();
        for y in [-h, h] {
            for (x, z) in [(-h, -h), (h, -h), (h, h), (-h, h)] {
                positions.push(Vec3::new(x, y, z));
            }
        }
        positions.push(Vec3::new(0.0, h - dent, 0.0));
        let mut triangles: Vec<[u32; 3]> = vec![[0, 1, 2], [0, 2, 3]];
        for k in 0..4u32 {
            let j = (k + 1) % 4;
            triangles.extend([[k, j, j + 4], [k, j + 4, k + 4], [k + 4, j + 4, 8]]);
        }
        // Wound outward (the box is star-shaped about its centre).
        for t in &mut triangles {
            let [a, b, c] = t.map(|i| positions[i as usize]);
            if (b - a).cross(c - a).dot(a + b + c) < 0.0 {
                t.swap(1, 2);
            }
        }
        let mesh = Mesh {
            positions,
            triangles,
            albedo: nelf_scene::mesh::Albedo::Uniform([0.5; 3]),
        };
        mesh.validate().unwrap();
        let (shell, profile) = one_sample_shell(&mesh, voxel, 0.05);
        for d in [0.5f32, 1.0, 1.5].map(|k| k * voxel) {
            let x = Vec3::new(h + d, h - 0.15 * voxel, 0.01);
            let sigma = shell.density(x);
            let expected = profile.density(Some(d), false);
            assert!(
                (sigma - expected).abs() <= 1e-3 * expected.abs().max(1.0),
                "{d} m beside the face below the crease: σ = {sigma}, the signed profile's {expected}"
            );
        }
    }

    /// `mesh`'s field with a one-sample tracer (tracing every point) as a signed shell of
    /// `voxel` voxels with lead `lead_voxels` and a quarter-voxel ramp, sheets 2 voxels thick.
    fn one_sample_shell(mesh: &Mesh, voxel: f32, lead_voxels: f32) -> (ShellMeshField, ShellProfile) {
        let trace = TraceSettings {
            texel_samples: 1,
            indirect_samples: 1,
            bounces: 0,
            ..TraceSettings::default()
        };
        let field = MeshField::new(mesh, trace, DensityProfile::with_shell_width(2.0 * voxel)).unwrap();
        let profile = ShellProfile::Signed {
            lead_m: lead_voxels * voxel,
            ramp_m: 0.25 * voxel,
            voxel_m: voxel,
        };
        (
            ShellMeshField::new(field, profile, 2.0 * voxel, None).unwrap(),
            profile,
        )
    }

    /// Voxel edge of the textured-sheet tests, metres.
    const SHEET_VOXEL: f32 = 2e-3;

    /// A 10 cm square sheet in `z = 0` with `texture`, a one-sample tracer, as a signed
    /// shell field of [`SHEET_VOXEL`] voxels (tracing every point).
    fn textured_sheet_field(texture: nelf_scene::mesh::Texture) -> ShellMeshField {
        let mesh = nelf_scene::defects::textured_quad(
            Vec3::new(-0.05, -0.05, 0.0),
            Vec3::new(0.1, 0.0, 0.0),
            Vec3::new(0.0, 0.1, 0.0),
            4,
            texture,
        );
        one_sample_shell(&mesh, SHEET_VOXEL, 0.25).0
    }

    /// Sharing light transport among the band's voxels: the result is a function of
    /// each point alone (any batch split gives the same bits), a textured sheet keeps
    /// its texture (each point rescales to its own albedo), and the shared field
    /// stays within a few per cent of tracing every point.
    #[test]
    fn shared_transport_is_per_point_and_close_to_tracing_each_point() {
        use nelf_scene::defects::striped_texture;
        let texture = striped_texture(32, 32, 4, [[0.8, 0.2, 0.1], [0.1, 0.6, 0.9], [0.5, 0.5, 0.5]]);
        let voxel = SHEET_VOXEL;
        let config = BakeConfig::default();
        let own = textured_sheet_field(texture.clone());
        let shared =
            textured_sheet_field(texture).with_shared_transport(Some(config.lt_share_voxels * voxel));
        // A lattice of points in the band on both sides of the sheet.
        let points: Vec<Vec3> = (0..40)
            .flat_map(|i| (0..40).flat_map(move |j| (-1..=1).map(move |k| (i, j, k))))
            .map(|(i, j, k)| {
                Vec3::new(
                    -0.039 + 0.002 * i as f32,
                    -0.039 + 0.002 * j as f32,
                    0.0007 * k as f32 + 0.0003,
                )
            })
            .collect();
        let view = ViewPolicy::AverageDirections(vec![Vec3::Z, -Vec3::Z + 0.3 * Vec3::X]);
        let run = |f: &ShellMeshField, pts: &[Vec3]| {
            let mut d = vec![0.0; pts.len()];
            let mut t = vec![0.0; pts.len() * LT_DIM];
            f.evaluate(pts, &view, &mut d, &mut t).unwrap();
            (d, t)
        };
        let (d_all, t_all) = run(&shared, &points);
        // Any batch split, any order within it: the same bits.
        let (d_half, t_half) = run(&shared, &points[points.len() / 3..]);
        assert_eq!(d_half, d_all[points.len() / 3..]);
        assert_eq!(t_half, t_all[points.len() / 3 * LT_DIM..]);
        let (d_own, t_own) = run(&own, &points);
        assert_eq!(d_own, d_all, "sharing changes light transport only");
        // Radiance under uniform white light, per point and channel.
        let radiance = |t: &[f32]| -> Vec<f32> { t.chunks(ENV_TEXELS).map(|c| c.iter().sum()).collect() };
        let (a, b) = (radiance(&t_all), radiance(&t_own));
        let scale = b.iter().map(|v| v.abs()).sum::<f32>() / b.len() as f32;
        let mean_abs = a.iter().zip(&b).map(|(x, y)| (x - y).abs()).sum::<f32>() / b.len() as f32;
        assert!(scale > 0.05, "the sheet is lit: {scale}");
        assert!(
            mean_abs < 0.03 * scale,
            "shared differs from own by {mean_abs} (scale {scale})"
        );
        // Texture survives: shared and own radiance correlate point by point across stripes.
        let corr = {
            let (ma, mb) = (a.iter().sum::<f32>() / a.len() as f32, scale);
            let cov: f32 = a.iter().zip(&b).map(|(x, y)| (x - ma) * (y - mb)).sum();
            let va: f32 = a.iter().map(|x| (x - ma).powi(2)).sum();
            let vb: f32 = b.iter().map(|y| (y - mb).powi(2)).sum();
            cov / (va * vb).sqrt()
        };
        assert!(corr > 0.99, "correlation {corr}");
        // Sharing traced fewer points than it answered.
        let mut keys = Vec::new();
        for x in &points {
            if let (_, Some((cp, back))) = shared.side_at(*x, &view) {
                keys.push((
                    cp.triangle,
                    back,
                    (cp.point / (config.lt_share_voxels * voxel))
                        .floor()
                        .as_ivec3()
                        .to_array(),
                ));
            }
        }
        let answered = keys.len();
        keys.sort_unstable();
        keys.dedup();
        assert!(
            keys.len() * 3 <= answered * 2,
            "{} traces for {answered} points",
            keys.len()
        );
    }

    /// A texture finer than a voxel (a checkerboard of 0.4 mm black and white texels
    /// under 2 mm voxels): read at each point's closest surface point, neighbouring
    /// voxels flip between black and white (the specks of docs/measurements/
    /// 2026-12-07-specks.md); averaged over the voxel's footprint they carry its grey.
    #[test]
    fn albedo_footprint_removes_texture_finer_than_a_voxel() {
        use nelf_scene::mesh::Texture;
        let side = 256;
        let texels = (0..side * side)
            .map(|i| {
                if (i / side + i % side) % 2 == 0 {
                    [0.9; 3]
                } else {
                    [0.05; 3]
                }
            })
            .collect();
        let texture = Texture {
            width: side,
            height: side,
            texels,
        };
        let voxel = SHEET_VOXEL;
        let share = Some(BakeConfig::default().lt_share_voxels * voxel);
        let point = textured_sheet_field(texture.clone()).with_shared_transport(share);
        let footprint = textured_sheet_field(texture)
            .with_shared_transport(share)
            .with_albedo_footprint(Some(voxel));
        // Voxel centres in the band in front of the quad, away from its edges.
        let points: Vec<Vec3> = (0..30)
            .flat_map(|i| {
                (0..30).map(move |j| Vec3::new(-0.03 + 0.002 * i as f32, -0.03 + 0.002 * j as f32, 0.0003))
            })
            .collect();
        let view = ViewPolicy::AverageDirections(vec![Vec3::Z]);
        let spread = |f: &ShellMeshField| {
            let mut d = vec![0.0; points.len()];
            let mut t = vec![0.0; points.len() * LT_DIM];
            f.evaluate(&points, &view, &mut d, &mut t).unwrap();
            // Radiance under uniform white light (red channel), per point.
            let r: Vec<f32> = t.chunks(LT_DIM).map(|c| c[..ENV_TEXELS].iter().sum()).collect();
            let mean = r.iter().sum::<f32>() / r.len() as f32;
            let sd = (r.iter().map(|v| (v - mean).powi(2)).sum::<f32>() / r.len() as f32).sqrt();
            (mean, sd / mean)
        };
        let (point_mean, point_spread) = spread(&point);
        let (footprint_mean, footprint_spread) = spread(&footprint);
        assert!(
            point_spread > 0.5,
            "point-sampled albedo flips between texels: spread {point_spread}"
        );
        assert!(
            footprint_spread < 0.1,
            "footprint albedo is the voxel's grey: spread {footprint_spread}"
        );
        // The same mean light (the average albedo is kept).
        assert!(
            (footprint_mean - point_mean).abs() < 0.15 * point_mean,
            "{footprint_mean} vs {point_mean}"
        );
    }

    /// `evaluate_directions` equals one `evaluate` per direction (`==` on every
    /// float) with a glossy lobe, tracing every point or sharing per cell, on both
    /// sides of an open sheet and on the sheet itself (where the side follows each
    /// direction), and near a closed sphere; the shared one is independent of the batch.
    #[test]
    fn evaluate_directions_equals_per_direction_evaluate() {
        use nelf_scene::defects::{striped_texture, textured_quad};
        use nelf_scene::tracer::Specular;
        let texture = striped_texture(16, 16, 4, [[0.8, 0.2, 0.1], [0.1, 0.6, 0.9], [0.5, 0.5, 0.5]]);
        let sheet = textured_quad(
            Vec3::new(-0.05, -0.05, 0.0),
            Vec3::new(0.1, 0.0, 0.0),
            Vec3::new(0.0, 0.1, 0.0),
            3,
            texture,
        );
        let ball = uv_sphere(Vec3::new(0.0, 0.0, 0.04), 0.02, 8, 16, [0.6, 0.5, 0.4]);
        let mesh = nelf_scene::defects::merge_textured(&[sheet, ball]);
        let voxel = 2e-3f32;
        let trace = TraceSettings {
            texel_samples: 1,
            indirect_samples: 4,
            bounces: 1,
            specular: Some(Specular {
                weight: 0.3,
                exponent: 8.0,
            }),
            ..TraceSettings::default()
        };
        let field = || MeshField::new(&mesh, trace, DensityProfile::with_shell_width(2.0 * voxel)).unwrap();
        let profile = ShellProfile::Signed {
            lead_m: 0.25 * voxel,
            ramp_m: 0.25 * voxel,
            voxel_m: voxel,
        };
        let own = ShellMeshField::new(field(), profile, 2.0 * voxel, None).unwrap();
        let shared = ShellMeshField::new(field(), profile, 2.0 * voxel, None)
            .unwrap()
            .with_shared_transport(Some(2.0 * voxel));
        // Points on both sides of the sheet, on it (ties), and around the ball.
        let mut points: Vec<Vec3> = (0..8)
            .flat_map(|i| {
                (0..8).flat_map(move |j| [-0.0015f32, 0.0, 0.00005, 0.0015].map(move |z| (i, j, z)))
            })
            .map(|(i, j, z)| Vec3::new(-0.035 + 0.01 * i as f32, -0.035 + 0.01 * j as f32, z))
            .collect();
        points.extend((0..24).map(|i| {
            let a = i as f32 * 0.7;
            Vec3::new(0.0, 0.0, 0.04) + Vec3::new(a.cos(), (0.3 * a).sin(), a.sin()).normalize() * 0.0205
        }));
        let directions = [
            Vec3::Z,
            -Vec3::Z,
            Vec3::new(0.3, 0.2, 0.9).normalize(),
            Vec3::new(-0.5, 0.1, -0.6).normalize(),
            Vec3::new(0.8, -0.6, 0.05).normalize(),
            Vec3::new(-0.1, 0.7, 0.3),
        ];
        let per_direction = |f: &ShellMeshField, pts: &[Vec3]| {
            let mut density = vec![0.0f32; pts.len()];
            let mut lt = vec![0.0f32; pts.len() * directions.len() * LT_DIM];
            let mut one = vec![0.0f32; pts.len() * LT_DIM];
            for (d, dir) in directions.iter().enumerate() {
                f.evaluate(pts, &ViewPolicy::Direction(*dir), &mut density, &mut one)
                    .unwrap();
                for (i, t) in one.chunks_exact(LT_DIM).enumerate() {
                    let at = (i * directions.len() + d) * LT_DIM;
                    lt[at..at + LT_DIM].copy_from_slice(t);
                }
            }
            (density, lt)
        };
        let joint = |f: &ShellMeshField, pts: &[Vec3]| {
            let mut density = vec![f32::NAN; pts.len()];
            let mut lt = vec![f32::NAN; pts.len() * directions.len() * LT_DIM];
            f.evaluate_directions(pts, &directions, &mut density, &mut lt)
                .unwrap();
            (density, lt)
        };
        for (name, f) in [("own", &own), ("shared", &shared)] {
            let (want_d, want_lt) = per_direction(f, &points);
            let (d, lt) = joint(f, &points);
            assert_eq!(d, want_d, "{name}");
            assert!(lt == want_lt, "{name}: evaluate_directions differs");
            assert!(lt.iter().any(|&v| v > 0.0));
        }
        // Points on the sheet see its front toward some directions, its back toward others.
        let ties = points
            .iter()
            .filter(|x| {
                let located = own.locate(**x, f32::INFINITY);
                let sides = own.sides_toward(&located, &located.closest.unwrap(), &directions);
                located.tie && sides.contains(&true) && sides.contains(&false)
            })
            .count();
        assert!(ties >= 32, "{ties} points on the sheet");
        // Sharing: any batch gives the same bits.
        let (d_all, lt_all) = joint(&shared, &points);
        let (d_tail, lt_tail) = joint(&shared, &points[100..]);
        assert_eq!(d_tail, d_all[100..]);
        assert!(lt_tail == lt_all[100 * directions.len() * LT_DIM..]);
    }
}
