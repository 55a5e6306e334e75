//! The sparse brick grid of a bake: placement, candidate bricks, the density pass
//! that drops empty bricks, and the band of voxels whose light transport matters.
//!
//! **Placement.** The grid covers a box (the visual hull's, or a mesh's) padded by
//! one voxel on every side, rounded up to whole 8³ bricks. The voxel size is given,
//! or is the box's longest side divided by a resolution (voxels along it).
//!
//! **Candidates and density.** Candidate bricks are those with at least one voxel
//! inside the hull (every brick of the box when there is no hull). The density σ
//! (1/m) is evaluated at every voxel centre of the candidates, set to 0 outside the
//! hull (NeLF never queries there), rounded to `f16` as the file stores it, and a
//! brick is dropped when its largest density is below `σ_min = −ln(1 − α_min)/Δ`:
//! a voxel of that density is less than `α_min` opaque across one voxel (`Δ` is the
//! voxel size; `α_min` = 1 % by default). A dropped brick comes back as an
//! **apron** when it holds a voxel 26-adjacent to a voxel with `σ > 0` of a kept
//! brick: the renderer counts missing voxels as 0 in trilinear interpolation (SPEC),
//! so without it a surface at a brick face would fade to black over its last half
//! voxel. Apron bricks keep their (small or zero) density and get light transport
//! where the band below reaches them.
//!
//! **Light-transport band.** Evaluating `T` (hundreds of path-traced samples per
//! vector for the ground truth) is the expensive part, and most voxels never show:
//! deep inside an opaque head a ray has long terminated. The optical depth from
//! outside, `τ(v) = min over 26-connected voxel paths from any missing voxel of
//! Σ ½(σ⁺_a + σ⁺_b)·|a − b|` (`σ⁺ = max(σ, 0)`, as the renderer clips), is computed by forward/backward sweeps (a
//! chamfer-style shortest path; it is at most the optical depth along any straight
//! ray, so it errs toward keeping voxels). `T` is evaluated for every voxel with
//! `σ > 0` and `τ < τ_max` or on the surface (a neighbour outside or at `τ = 0`:
//! a skin opaque within one voxel keeps the layer rays stop in), and for their 26
//! neighbours (trilinear interpolation of
//! radiance reads them, even where `σ = 0`). Other voxels get `T` = the PCA mean.
//! With `τ_max = 10` a ray reaching an excluded voxel has transmittance below
//! `e⁻¹⁰ ≈ 4.5·10⁻⁵`, under the renderer's `10⁻³` cut-off.

use std::collections::{BTreeSet, HashMap};
use std::time::Instant;

use glam::{DVec3, Vec3};
use nelf_format::asset::{GridGeometry, brick_order_key, local_voxel_coords};
use nelf_format::encode_density;
use nelf_format::spec::{BRICK_SIZE, BRICK_VOXELS};
use nelf_render::BrickGrid;
use nelf_scene::field::{FieldSource, ViewPolicy};
use rayon::prelude::*;

use crate::error::{BakeError, Result};
use crate::hull::HullCarver;
use crate::progress::Progress;

/// Largest grid extent accepted, voxels per axis (keeps a dense hull pass bounded).
pub const MAX_RESOLUTION: u32 = 2048;

/// Voxel edge (metres) for a box of `extent_m`: `voxel_size_m` when given, else the
/// longest side over `resolution`.
pub fn voxel_size_for(extent_m: DVec3, resolution: u32, voxel_size_m: Option<f64>) -> Result<f64> {
    let longest = extent_m.max_element();
    if !(longest.is_finite() && longest > 0.0) {
        return Err(BakeError::Settings(format!(
            "the box to bake {extent_m} m is empty"
        )));
    }
    let size = if let Some(s) = voxel_size_m {
        s
    } else {
        if !(1..=MAX_RESOLUTION).contains(&resolution) {
            return Err(BakeError::Settings(format!(
                "--resolution {resolution} must be in 1..={MAX_RESOLUTION}"
            )));
        }
        longest / f64::from(resolution)
    };
    if !(size.is_finite() && size > 0.0) {
        return Err(BakeError::Settings(format!(
            "voxel size {size} m must be positive"
        )));
    }
    if longest / size > f64::from(MAX_RESOLUTION) {
        return Err(BakeError::Settings(format!(
            "voxel size {size} m gives {:.0} voxels along the longest side (at most {MAX_RESOLUTION})",
            longest / size
        )));
    }
    Ok(size)
}

/// The grid covering `[lo, hi]` padded by one voxel, in whole bricks.
pub fn geometry_for_box(lo: DVec3, hi: DVec3, voxel_size_m: f64) -> Result<GridGeometry> {
    let origin = lo - DVec3::splat(voxel_size_m);
    let voxels = ((hi - lo) / voxel_size_m).ceil() + 2.0;
    let bricks = (voxels / BRICK_SIZE as f64).ceil();
    if !bricks.is_finite() || bricks.max_element() > f64::from(u16::MAX) {
        return Err(BakeError::Settings(format!(
            "grid of {bricks} bricks is too large"
        )));
    }
    let geometry = GridGeometry {
        bbox_min_m: origin.to_array(),
        voxel_size_m,
        grid_bricks: bricks.to_array().map(|b| (b as u32).max(1)),
    };
    geometry.validate().map_err(BakeError::Settings)?;
    Ok(geometry)
}

/// Candidate bricks before the density pass.
#[derive(Debug, Clone, PartialEq)]
pub struct GridPlan {
    /// Grid placement.
    pub geometry: GridGeometry,
    /// Candidate bricks, sorted by (z, y, x).
    pub bricks: Vec<[u16; 3]>,
    /// Per candidate voxel (brick order), whether it is inside the hull; `None`: all are.
    pub inside: Option<Vec<bool>>,
    /// Voxels inside the hull (all candidate voxels when there is no hull).
    pub hull_voxels: usize,
}

/// Every brick of `geometry` as a candidate (no hull).
pub fn plan_all_bricks(geometry: GridGeometry) -> GridPlan {
    let [gx, gy, gz] = geometry.grid_bricks;
    let mut bricks = Vec::with_capacity((gx * gy * gz) as usize);
    for z in 0..gz {
        for y in 0..gy {
            for x in 0..gx {
                bricks.push([x as u16, y as u16, z as u16]);
            }
        }
    }
    let hull_voxels = bricks.len() * BRICK_VOXELS;
    GridPlan {
        geometry,
        bricks,
        inside: None,
        hull_voxels,
    }
}

/// Carves every voxel of `geometry` with `carver` and keeps the bricks holding a
/// hull voxel.
pub fn plan_from_hull(carver: &HullCarver, geometry: GridGeometry) -> GridPlan {
    let dims = geometry.grid_voxels().map(|v| v as usize);
    let hull = carver.carve(
        DVec3::from_array(geometry.bbox_min_m),
        geometry.voxel_size_m,
        dims,
    );
    let [gx, gy, gz] = geometry.grid_bricks;
    let mut bricks = Vec::new();
    let mut inside = Vec::new();
    let mut hull_voxels = 0;
    let mut flags = [false; BRICK_VOXELS];
    for z in 0..gz {
        for y in 0..gy {
            for x in 0..gx {
                let base = [x, y, z].map(|b| i64::from(b) * BRICK_SIZE as i64);
                let mut any = 0;
                for (local, flag) in flags.iter_mut().enumerate() {
                    let [i, j, k] = local_voxel_coords(local);
                    *flag = hull.contains(base[0] + i as i64, base[1] + j as i64, base[2] + k as i64);
                    any += usize::from(*flag);
                }
                if any > 0 {
                    bricks.push([x as u16, y as u16, z as u16]);
                    inside.extend_from_slice(&flags);
                    hull_voxels += any;
                }
            }
        }
    }
    GridPlan {
        geometry,
        bricks,
        inside: Some(inside),
        hull_voxels,
    }
}

/// Global voxel coordinates of voxel `voxel` (brick order) of `bricks`.
pub fn voxel_coords(bricks: &[[u16; 3]], voxel: usize) -> [i64; 3] {
    let b = bricks[voxel / BRICK_VOXELS];
    let l = local_voxel_coords(voxel % BRICK_VOXELS);
    std::array::from_fn(|a| i64::from(b[a]) * BRICK_SIZE as i64 + l[a] as i64)
}

/// World position (metres) of the centre of voxel `voxel` of `bricks`.
pub fn voxel_position(geometry: &GridGeometry, bricks: &[[u16; 3]], voxel: usize) -> DVec3 {
    let ijk = voxel_coords(bricks, voxel);
    DVec3::from_array(geometry.bbox_min_m)
        + (DVec3::new(ijk[0] as f64, ijk[1] as f64, ijk[2] as f64) + 0.5) * geometry.voxel_size_m
}

/// The densest density a dropped brick may have: `−ln(1 − α_min) / Δ`, 1/m.
pub fn brick_density_threshold(min_opacity: f64, voxel_size_m: f64) -> f64 {
    -(-min_opacity).ln_1p() / voxel_size_m
}

/// The grid after the density pass.
#[derive(Debug, Clone)]
pub struct DensityGrid {
    /// The kept bricks.
    pub grid: BrickGrid,
    /// Density σ (1/m) per kept voxel, already rounded to `f16` as the file stores it.
    pub density: Vec<f32>,
    /// Candidate bricks evaluated.
    pub candidate_bricks: usize,
    /// Bricks kept only as an apron around dense ones (module docs).
    pub apron_bricks: usize,
    /// Threshold used, 1/m.
    pub sigma_min_per_m: f64,
}

/// Bricks per density batch (32,768 points).
const DENSITY_BATCH_BRICKS: usize = 64;

/// Evaluates the density of every candidate voxel and drops bricks whose largest
/// density is below `brick_density_threshold(min_opacity, Δ)` (module docs).
pub fn evaluate_density(
    plan: &GridPlan,
    field: &dyn FieldSource,
    min_opacity: f64,
    progress: &Progress,
) -> Result<DensityGrid> {
    if !(0.0..1.0).contains(&min_opacity) {
        return Err(BakeError::Settings(format!(
            "minimum brick opacity {min_opacity} must be in [0, 1)"
        )));
    }
    let sigma_min = brick_density_threshold(min_opacity, plan.geometry.voxel_size_m);
    let bar = progress.bar("density", plan.bricks.len() as u64, "bricks");
    let mut density = vec![0.0f32; plan.bricks.len() * BRICK_VOXELS];
    let mut points = Vec::with_capacity(DENSITY_BATCH_BRICKS * BRICK_VOXELS);
    for (batch, out) in density
        .chunks_mut(DENSITY_BATCH_BRICKS * BRICK_VOXELS)
        .enumerate()
    {
        let first = batch * DENSITY_BATCH_BRICKS * BRICK_VOXELS;
        points.clear();
        points.extend(
            (first..first + out.len()).map(|v| voxel_position(&plan.geometry, &plan.bricks, v).as_vec3()),
        );
        field.evaluate_density(&points, out)?;
        if let Some(inside) = &plan.inside {
            for (d, &keep) in out.iter_mut().zip(&inside[first..]) {
                if !keep {
                    *d = 0.0;
                }
            }
        }
        bar.inc((out.len() / BRICK_VOXELS) as u64);
    }
    bar.finish_and_clear();
    let rounded: Vec<f32> = encode_density(&density)?.iter().map(|d| d.to_f32()).collect();
    let dense_bricks: Vec<usize> = (0..plan.bricks.len())
        .filter(|&b| {
            let max = rounded[b * BRICK_VOXELS..(b + 1) * BRICK_VOXELS]
                .iter()
                .fold(0.0f32, |m, &d| m.max(d));
            max > 0.0 && f64::from(max) >= sigma_min
        })
        .collect();
    if dense_bricks.is_empty() {
        return Err(BakeError::Empty(format!(
            "every one of {} candidate bricks has density below {sigma_min:.3} 1/m",
            plan.bricks.len()
        )));
    }
    let kept = with_apron(plan, &rounded, &dense_bricks);
    let candidate_index: HashMap<[u16; 3], usize> =
        plan.bricks.iter().enumerate().map(|(i, &b)| (b, i)).collect();
    let mut kept_density = Vec::with_capacity(kept.len() * BRICK_VOXELS);
    for b in &kept {
        match candidate_index.get(b) {
            Some(&i) => kept_density.extend_from_slice(&rounded[i * BRICK_VOXELS..(i + 1) * BRICK_VOXELS]),
            None => kept_density.extend_from_slice(&[0.0; BRICK_VOXELS]),
        }
    }
    Ok(DensityGrid {
        apron_bricks: kept.len() - dense_bricks.len(),
        grid: BrickGrid::new(plan.geometry, kept)?,
        density: kept_density,
        candidate_bricks: plan.bricks.len(),
        sigma_min_per_m: sigma_min,
    })
}

/// Voxels along the longest side of the box probed by [`occupied_box`].
pub const PROBE_RESOLUTION: u32 = 64;

/// The box `(min, max)`, metres, of the region where `field` is dense, within
/// `[lo, hi]` (and within the hull when `carver` is given): the density is probed on
/// a coarse grid ([`PROBE_RESOLUTION`] voxels along the longest side), voxels at or
/// above `brick_density_threshold(min_opacity, probe voxel)` count, and their box is
/// grown by one probe voxel on every side (a feature thinner than a probe voxel can
/// still end up to a voxel outside) and clipped to `[lo, hi]`. The baker sizes its
/// voxels by this box, not the hull's: a few frontal views bound depth loosely, so
/// a hull box is often half again as deep as the head.
pub fn occupied_box(
    carver: Option<&HullCarver>,
    lo: DVec3,
    hi: DVec3,
    field: &dyn FieldSource,
    min_opacity: f64,
    progress: &Progress,
) -> Result<(DVec3, DVec3)> {
    let probe = voxel_size_for(hi - lo, PROBE_RESOLUTION, None)?;
    let geometry = geometry_for_box(lo, hi, probe)?;
    let plan = match carver {
        Some(c) => plan_from_hull(c, geometry),
        None => plan_all_bricks(geometry),
    };
    let dense = evaluate_density(&plan, field, min_opacity, progress)?;
    let sigma_min = dense.sigma_min_per_m;
    let mut box_lo = DVec3::INFINITY;
    let mut box_hi = DVec3::NEG_INFINITY;
    for (v, &sigma) in dense.density.iter().enumerate() {
        if f64::from(sigma) >= sigma_min && sigma > 0.0 {
            let centre = voxel_position(&geometry, dense.grid.bricks(), v);
            box_lo = box_lo.min(centre);
            box_hi = box_hi.max(centre);
        }
    }
    // A dense brick holds at least one voxel at the threshold, so the box is not empty.
    let pad = DVec3::splat(1.5 * probe);
    Ok(((box_lo - pad).max(lo), (box_hi + pad).min(hi)))
}

/// The dense bricks plus every brick of the grid holding a voxel 26-adjacent to a
/// voxel with `σ > 0` of a dense brick, sorted by (z, y, x). A missing voxel counts
/// as 0 in trilinear interpolation, so without these a surface lying at a brick's
/// face would fade to black over its last half voxel.
fn with_apron(plan: &GridPlan, density: &[f32], dense_bricks: &[usize]) -> Vec<[u16; 3]> {
    let grid_bricks = plan.geometry.grid_bricks.map(i64::from);
    let mut kept: BTreeSet<(u16, u16, u16)> = dense_bricks
        .iter()
        .map(|&b| brick_order_key(plan.bricks[b]))
        .collect();
    let mut apron = BTreeSet::new();
    for &b in dense_bricks {
        let coord = plan.bricks[b].map(i64::from);
        for local in 0..BRICK_VOXELS {
            let l = local_voxel_coords(local);
            let on_face = l.iter().any(|&x| x == 0 || x == BRICK_SIZE - 1);
            if !on_face || density[b * BRICK_VOXELS + local] <= 0.0 {
                continue;
            }
            for (o, _) in neighbour_offsets() {
                let g: [i64; 3] = std::array::from_fn(|a| coord[a] * BRICK_SIZE as i64 + l[a] as i64 + o[a]);
                let nb = g.map(|v| v.div_euclid(BRICK_SIZE as i64));
                if nb != coord && (0..3).all(|a| (0..grid_bricks[a]).contains(&nb[a])) {
                    apron.insert((nb[2] as u16, nb[1] as u16, nb[0] as u16));
                }
            }
        }
    }
    kept.append(&mut apron);
    kept.into_iter().map(|(z, y, x)| [x, y, z]).collect()
}

/// The 26 neighbour offsets and their lengths (voxels).
fn neighbour_offsets() -> Vec<([i64; 3], f32)> {
    let mut out = Vec::with_capacity(26);
    for dz in -1i64..=1 {
        for dy in -1i64..=1 {
            for dx in -1i64..=1 {
                if (dx, dy, dz) != (0, 0, 0) {
                    let len = ((dx * dx + dy * dy + dz * dz) as f32).sqrt();
                    out.push(([dx, dy, dz], len));
                }
            }
        }
    }
    out
}

/// Largest number of sweeps of the optical-depth relaxation.
const MAX_DEPTH_SWEEPS: usize = 64;

/// Optical depth from outside of every voxel (module docs), by alternating forward
/// and backward Gauss–Seidel sweeps until nothing changes.
pub fn optical_depth_from_outside(grid: &BrickGrid, density: &[f32]) -> Vec<f32> {
    let n = grid.voxel_count();
    let voxel = grid.geometry().voxel_size_m as f32;
    let offsets = neighbour_offsets();
    // Neighbour table: voxel index or usize::MAX for a missing voxel (outside: τ = 0, σ = 0).
    let neighbours: Vec<[usize; 26]> = (0..n)
        .into_par_iter()
        .map(|v| {
            let c = voxel_coords(grid.bricks(), v);
            std::array::from_fn(|i| {
                let o = offsets[i].0;
                grid.voxel_at([c[0] + o[0], c[1] + o[1], c[2] + o[2]])
                    .unwrap_or(usize::MAX)
            })
        })
        .collect();
    let mut depth = vec![f32::INFINITY; n];
    let relax = |v: usize, depth: &[f32]| -> f32 {
        let mut best = depth[v];
        for (i, &u) in neighbours[v].iter().enumerate() {
            let (du, su) = if u == usize::MAX {
                (0.0, 0.0)
            } else {
                (depth[u], density[u].max(0.0))
            };
            let candidate = du + 0.5 * (su + density[v].max(0.0)) * voxel * offsets[i].1;
            if candidate < best {
                best = candidate;
            }
        }
        best
    };
    for sweep in 0..MAX_DEPTH_SWEEPS {
        let mut changed = false;
        let mut visit = |v: usize| {
            let d = relax(v, &depth);
            if d < depth[v] {
                depth[v] = d;
                changed = true;
            }
        };
        if sweep % 2 == 0 {
            (0..n).for_each(&mut visit);
        } else {
            (0..n).rev().for_each(&mut visit);
        }
        if !changed {
            break;
        }
    }
    depth
}

/// Voxels (sorted indices) whose light transport is evaluated: `σ > 0` and an
/// optical depth from outside below `max_optical_depth`, or `σ > 0` on the surface
/// (a neighbour missing or at depth 0), plus their 26 neighbours. The surface rule
/// keeps the layer every ray stops in where one voxel alone is beyond the limit (a
/// trained network's opaque skin: σ·voxel of 20 and more).
pub fn light_transport_band(grid: &BrickGrid, density: &[f32], max_optical_depth: f64) -> Vec<usize> {
    let depth = optical_depth_from_outside(grid, density);
    let offsets = neighbour_offsets();
    let on_surface = |v: usize| -> bool {
        let c = voxel_coords(grid.bricks(), v);
        offsets.iter().any(|(o, _)| {
            grid.voxel_at([c[0] + o[0], c[1] + o[1], c[2] + o[2]])
                .is_none_or(|u| depth[u] == 0.0)
        })
    };
    let mut needed = vec![false; grid.voxel_count()];
    for v in 0..grid.voxel_count() {
        if density[v] > 0.0 && (f64::from(depth[v]) < max_optical_depth || on_surface(v)) {
            needed[v] = true;
            let c = voxel_coords(grid.bricks(), v);
            for (o, _) in &offsets {
                if let Some(u) = grid.voxel_at([c[0] + o[0], c[1] + o[1], c[2] + o[2]]) {
                    needed[u] = true;
                }
            }
        }
    }
    needed
        .iter()
        .enumerate()
        .filter_map(|(v, &b)| b.then_some(v))
        .collect()
}

/// Points per light-transport batch.
pub const LT_BATCH_POINTS: usize = 4096;

/// Evaluates the light transport (`voxels.len() × 384`, channel-major) of the given
/// voxels under `view`, in batches; returns it with the seconds taken.
pub fn evaluate_light_transport(
    grid: &BrickGrid,
    voxels: &[usize],
    field: &dyn FieldSource,
    view: &ViewPolicy,
    progress: &Progress,
) -> Result<(Vec<f32>, f64)> {
    use nelf_format::conventions::LT_DIM;
    let start = Instant::now();
    let geometry = *grid.geometry();
    let bar = progress.bar("light", voxels.len() as u64, "voxels");
    let mut lt = vec![0.0f32; voxels.len() * LT_DIM];
    let mut density = vec![0.0f32; LT_BATCH_POINTS];
    let mut points: Vec<Vec3> = Vec::with_capacity(LT_BATCH_POINTS);
    for (batch, out) in voxels
        .chunks(LT_BATCH_POINTS)
        .zip(lt.chunks_mut(LT_BATCH_POINTS * LT_DIM))
    {
        points.clear();
        points.extend(
            batch
                .iter()
                .map(|&v| voxel_position(&geometry, grid.bricks(), v).as_vec3()),
        );
        field.evaluate(&points, view, &mut density[..batch.len()], out)?;
        if let Some(i) = out.iter().position(|x| !x.is_finite()) {
            return Err(BakeError::Pca(format!(
                "the field returned a non-finite light-transport value at {} (element {})",
                points[i / LT_DIM],
                i % LT_DIM
            )));
        }
        bar.inc(batch.len() as u64);
    }
    bar.finish_and_clear();
    Ok((lt, start.elapsed().as_secs_f64()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn geometry_pads_and_rounds_to_bricks() {
        let g = geometry_for_box(DVec3::ZERO, DVec3::new(1.0, 0.5, 0.25), 0.1).unwrap();
        assert_eq!(g.bbox_min_m, [-0.1, -0.1, -0.1]);
        // 10 + 2 = 12 voxels → 2 bricks; 5 + 2 = 7 → 1; 3 + 2 = 5 → 1 (ceil of 2.5 = 3).
        assert_eq!(g.grid_bricks, [2, 1, 1]);
        assert!((brick_density_threshold(0.01, 0.002) - 0.01005 / 0.002).abs() < 0.01);
        assert!(voxel_size_for(DVec3::new(0.2, 0.1, 0.1), 100, None).unwrap() - 0.002 < 1e-12);
        assert!(voxel_size_for(DVec3::new(0.2, 0.1, 0.1), 0, None).is_err());
        assert!(voxel_size_for(DVec3::new(0.2, 0.1, 0.1), 10, Some(1e-6)).is_err());
    }

    #[test]
    fn optical_depth_grows_inward() {
        // One brick, a solid 6³ block of σΔ = 1 per voxel in its middle.
        let geometry = GridGeometry {
            bbox_min_m: [0.0; 3],
            voxel_size_m: 0.5,
            grid_bricks: [1, 1, 1],
        };
        let grid = BrickGrid::new(geometry, vec![[0, 0, 0]]).unwrap();
        let mut density = vec![0.0f32; 512];
        for (v, d) in density.iter_mut().enumerate() {
            let c = voxel_coords(grid.bricks(), v);
            if c.iter().all(|&x| (1..7).contains(&x)) {
                *d = 2.0;
            }
        }
        let depth = optical_depth_from_outside(&grid, &density);
        let at = |c: [i64; 3]| depth[grid.voxel_at(c).unwrap()];
        assert_eq!(at([0, 0, 0]), 0.0);
        // From empty (1,1,0) into (1,1,1): ½(0 + 2)·0.5 = 0.5; each step inward adds 1.
        assert!((at([1, 1, 1]) - 0.5).abs() < 1e-6);
        assert!((at([2, 2, 2]) - 1.5).abs() < 1e-6);
        assert!((at([3, 3, 3]) - 2.5).abs() < 1e-6);
        let band = light_transport_band(&grid, &density, 1.0);
        // The block's shell, its neighbours inside and out are in; the core is not.
        let has = |band: &[usize], c: [i64; 3]| band.contains(&grid.voxel_at(c).unwrap());
        assert!(has(&band, [1, 1, 1]) && has(&band, [0, 0, 0]) && has(&band, [2, 2, 2]));
        assert!(!has(&band, [3, 3, 3]));
        let band_all = light_transport_band(&grid, &density, 100.0);
        assert!(has(&band_all, [3, 3, 3]));
        assert!(band.len() < band_all.len());

        // A skin opaque within one voxel (σΔ = 50 ≫ the limit): its outer layer, the
        // one rays stop in, and the layer under it are still evaluated.
        let skin: Vec<f32> = density.iter().map(|d| d * 50.0).collect();
        let band_skin = light_transport_band(&grid, &skin, 10.0);
        assert!(has(&band_skin, [1, 1, 1]) && has(&band_skin, [1, 3, 3]) && has(&band_skin, [2, 2, 2]));
        assert!(!has(&band_skin, [3, 3, 3]));
    }
}
