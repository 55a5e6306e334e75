//! Stage 8, **fine density** (format 1.4, SPEC.md §6 `DNSF`): the field's density
//! again at every fine voxel of the kept bricks, a lattice `F` = 2 or 4 times finer
//! per axis than the voxels (`--fine-density`).
//!
//! What a finer grid buys is mostly its density: measured by swapping the parts of two
//! bakes (`detail_bench swapRES`), the density of resolution 256 under the radiance of
//! 128 carries 51–82 % of what uniform resolution 256 gains over 128, for a quarter of
//! its bytes (docs/measurements/2026-12-07-silhouettes.md). So the light transport stays
//! at the voxels and only σ is refined. A mesh's field is sampled with its ramp and lead
//! scaled to the fine voxel ([`crate::source::mesh_field`] at `Δ/F`,
//! [`FieldBake::fine_field`]); any other field gives its own density. Voxels the plan
//! keeps outside the visual hull are zero in `DENS`, and the fine voxels inside them
//! are zero too, so the fine lattice never draws what the masks rule out.

use std::collections::HashMap;
use std::time::Instant;

use glam::DVec3;
use nelf_format::asset::encode_density;
use nelf_format::spec::{BRICK_SIZE, BRICK_VOXELS};
use nelf_format::{Asset, FineDensity};
use nelf_render::BrickGrid;
use rayon::prelude::*;

use nelf_scene::field::FieldSource;
use nelf_scene::mesh::Mesh;
use nelf_scene::tracer::TraceSettings;

use crate::config::BakeConfig;
use crate::error::Result;
use crate::progress::Progress;
use crate::source::mesh_field;
use crate::stages::outputs::BakeOutput;
use crate::stages::plan::FieldBake;

/// A mesh's field for the fine density (`--fine-density F`): the same shell at voxel
/// size `Δ/F` (lead and ramp a fraction of the fine voxel), its sheets and hollows as
/// thick as the coarse field's, whose shading was baked for them. `None` for `off`,
/// and for `auto` when the mesh is not watertight ([`is_watertight`]).
pub fn fine_mesh_field(
    mesh: &Mesh,
    trace: TraceSettings,
    voxel_size_m: f64,
    config: &BakeConfig,
) -> Result<Option<Box<dyn FieldSource>>> {
    let Some(factor) = config.fine_density.factor(is_watertight(mesh)) else {
        return Ok(None);
    };
    let scale = factor as f32;
    let fine_config = BakeConfig {
        sheet_voxels: config.sheet_voxels * scale,
        hollow_voxels: config.hollow_voxels * scale,
        ..config.clone()
    };
    Ok(Some(mesh_field(
        mesh,
        trace,
        voxel_size_m / f64::from(factor),
        config.shell_placement,
        &fine_config,
    )?))
}

/// Whether every edge of `mesh` is shared by an even number of triangles (two; four
/// where a surface touches itself, as surface nets can make) once vertices at the same
/// position (to 1 µm) are welded: a closed surface, which UV seams do not open. `auto`
/// gives a fine density only to such meshes: on a one-sided sheet folded in two
/// (`tests/defects.rs`) the fine lattice opened a dark spot at the fold on the back
/// (interior 21.5 dB against ≥ 27 with the voxels alone; cause not yet found), and on
/// the head-and-shoulders figure, whose open collar is a sheet, it gains only 0.3 dB.
pub fn is_watertight(mesh: &Mesh) -> bool {
    let mut weld: HashMap<[i64; 3], u32> = HashMap::with_capacity(mesh.positions.len());
    let ids: Vec<u32> = mesh
        .positions
        .iter()
        .map(|p| {
            let next = weld.len() as u32;
            // Welded on a 1 µm lattice: a seam's copies differ in the last bits.
            let key = p.to_array().map(|c| (f64::from(c) * 1e6).round() as i64);
            *weld.entry(key).or_insert(next)
        })
        .collect();
    let mut edges: HashMap<(u32, u32), u32> = HashMap::with_capacity(3 * mesh.triangles.len() / 2);
    for t in &mesh.triangles {
        for e in 0..3 {
            let (a, b) = (ids[t[e] as usize], ids[t[(e + 1) % 3] as usize]);
            if a != b {
                *edges.entry((a.min(b), a.max(b))).or_insert(0) += 1;
            }
        }
    }
    !edges.is_empty() && edges.values().all(|&n| n % 2 == 0)
}

/// Fine points per batch of field evaluations.
const FINE_BATCH_POINTS: usize = 1 << 18;

/// Adds the fine density of `config.fine_density` to `output.asset` (nothing for
/// `off`), records it in the metadata and its seconds in the report.
pub(crate) fn add_fine_density(
    job: &FieldBake<'_>,
    config: &BakeConfig,
    progress: Progress,
    output: &mut BakeOutput,
) -> Result<()> {
    let Some(factor) = config.fine_density.factor(job.fine_field.is_some()) else {
        return Ok(());
    };
    let t = Instant::now();
    let field = job.fine_field.unwrap_or(job.field);
    let values = fine_density_values(&output.asset, factor, field, job, progress)?;
    output.asset.fine_density = Some(FineDensity { factor, values });
    output.report.timings.fine_density_secs = t.elapsed().as_secs_f64();
    if let Some(meta) = output.asset.metadata.as_object_mut() {
        meta.insert(
            "fine_density".into(),
            serde_json::json!({
                "factor": factor,
                "fine_voxel_size_m": output.asset.grid.voxel_size_m / f64::from(factor),
                "field": if job.fine_field.is_some() { "the field rebuilt at the fine voxel size" } else { "the field's own density" },
            }),
        );
    }
    Ok(())
}

/// Every how many saturated fine voxels one is evaluated to confirm the value the
/// others take.
const SATURATED_SAMPLE_STRIDE: usize = 31;

/// σ at every fine voxel of `asset`'s bricks in the file's order (SPEC.md §6 `DNSF`),
/// from `field`, zero inside voxels the plan marks outside the hull and in apron bricks
/// the plan did not hold.
///
/// Only the band needs the field: where all eight voxels around a fine voxel hold the
/// coarse field's deepest value on one side (its cap inside, or outside), the fine voxel
/// lies farther from the surface than the fine ramp reaches (the coarse field saturates
/// 2.2 voxels from the surface, the cell's corners are within √3/2 of a voxel of the
/// fine centre, and the fine field saturates within 2.2/F), so it holds the fine
/// field's own deepest value on that side. That value is read from the field at every
/// 31st such voxel; if any of them disagrees, every fine voxel is evaluated.
fn fine_density_values(
    asset: &Asset,
    factor: u32,
    field: &dyn FieldSource,
    job: &FieldBake<'_>,
    progress: Progress,
) -> Result<Vec<half::f16>> {
    let f = factor as usize;
    let edge = BRICK_SIZE * f;
    let per_brick = BRICK_VOXELS * f * f * f;
    let fine_voxel_m = asset.grid.voxel_size_m / f64::from(factor);
    let origin = DVec3::from_array(asset.grid.bbox_min_m);
    let coarse_grid = BrickGrid::from_asset(asset)?;
    let coarse: Vec<f32> = asset.density.iter().map(|d| d.to_f32()).collect();
    let deepest = coarse.iter().fold(0.0f32, |m, &d| m.max(d));
    let shallowest = coarse.iter().fold(0.0f32, |m, &d| m.min(d));
    let candidate: HashMap<[u16; 3], usize> =
        job.plan.bricks.iter().enumerate().map(|(i, &b)| (b, i)).collect();
    let count = asset.bricks.len() * per_brick;
    let centre = |v: usize| -> DVec3 {
        let (b, l) = (asset.bricks[v / per_brick], v % per_brick);
        let ijk = [
            usize::from(b[0]) * edge + l % edge,
            usize::from(b[1]) * edge + l / edge % edge,
            usize::from(b[2]) * edge + l / (edge * edge),
        ];
        origin + (DVec3::new(ijk[0] as f64, ijk[1] as f64, ijk[2] as f64) + 0.5) * fine_voxel_m
    };
    // Which fine voxels need the field: Class::Band; the saturated ones on either side.
    let classes: Vec<Class> = (0..count)
        .into_par_iter()
        .map(|v| {
            let mut corners = [(0usize, 0.0f32); 8];
            let n = coarse_grid.trilinear(centre(v), &mut corners);
            let all = |value: f32| n == 8 && corners.iter().all(|&(c, _)| coarse[c] == value);
            if deepest > 0.0 && all(deepest) {
                Class::Inside
            } else if shallowest < 0.0 && all(shallowest) {
                Class::Outside
            } else {
                Class::Band
            }
        })
        .collect();
    let mut seen = [0usize; 2];
    let mut evaluate: Vec<usize> = Vec::new();
    for (v, class) in classes.iter().enumerate() {
        match class {
            Class::Band => evaluate.push(v),
            Class::Inside | Class::Outside => {
                let side = usize::from(*class == Class::Outside);
                if seen[side] % SATURATED_SAMPLE_STRIDE == 0 {
                    evaluate.push(v);
                }
                seen[side] += 1;
            }
        }
    }
    let mut sigma = vec![0.0f32; count];
    evaluate_at(field, &evaluate, &centre, &mut sigma, progress)?;
    // The value each saturated side takes, if every sample of it agrees.
    let mut side_value: [Option<f32>; 2] = [None, None];
    let mut consistent = true;
    for &v in &evaluate {
        let side = match classes[v] {
            Class::Band => continue,
            Class::Inside => 0,
            Class::Outside => 1,
        };
        match side_value[side] {
            None => side_value[side] = Some(sigma[v]),
            Some(value) if value == sigma[v] => {}
            Some(_) => consistent = false,
        }
    }
    if consistent {
        for (v, class) in classes.iter().enumerate() {
            match class {
                Class::Band => {}
                Class::Inside => sigma[v] = side_value[0].unwrap_or(sigma[v]),
                Class::Outside => sigma[v] = side_value[1].unwrap_or(sigma[v]),
            }
        }
    } else {
        let rest: Vec<usize> = (0..count).filter(|&v| classes[v] != Class::Band).collect();
        evaluate_at(field, &rest, &centre, &mut sigma, progress)?;
    }
    // Voxels outside the hull, and apron bricks the plan did not hold, are zero.
    for (n, b) in asset.bricks.iter().enumerate() {
        let brick_sigma = &mut sigma[n * per_brick..(n + 1) * per_brick];
        match candidate.get(b) {
            None => brick_sigma.fill(0.0),
            Some(&c) => {
                if let Some(inside) = &job.plan.inside {
                    let coarse_inside = &inside[c * BRICK_VOXELS..(c + 1) * BRICK_VOXELS];
                    for (l, s) in brick_sigma.iter_mut().enumerate() {
                        let (i, j, k) = (l % edge / f, l / edge % edge / f, l / (edge * edge) / f);
                        if !coarse_inside[i + BRICK_SIZE * (j + BRICK_SIZE * k)] {
                            *s = 0.0;
                        }
                    }
                }
            }
        }
    }
    Ok(encode_density(&sigma)?.into_iter().map(round_mantissa).collect())
}

/// Mantissa bits a fine σ keeps (of binary16's 10). Rounding to 6 moves a value by at
/// most 2⁻⁷ of itself: on the signed ramp `σ = s·(ℓ − d)` that moves the surface a
/// point describes by at most `2⁻⁷ · |ℓ − d|`, under 0.02 fine voxels where the ramp is
/// not yet at its cap; the section compresses a third smaller (0.92 → 0.62 MB on the
/// textured scan at resolution 128, factor 2).
const FINE_DENSITY_MANTISSA_BITS: u32 = 6;

/// `value` rounded to nearest with [`FINE_DENSITY_MANTISSA_BITS`] mantissa bits (ties
/// away from zero in magnitude); truncated where rounding up would reach infinity.
fn round_mantissa(value: half::f16) -> half::f16 {
    let drop = 10 - FINE_DENSITY_MANTISSA_BITS;
    let bits = value.to_bits();
    let rounded = half::f16::from_bits((bits + (1 << (drop - 1))) & !((1u16 << drop) - 1));
    if rounded.is_finite() {
        rounded
    } else {
        half::f16::from_bits(bits & !((1u16 << drop) - 1))
    }
}

/// Where a fine voxel lies relative to the coarse field's saturation.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Class {
    /// Near the surface: the field is evaluated.
    Band,
    /// All eight voxels around it hold the deepest value inside.
    Inside,
    /// All eight hold the deepest value outside.
    Outside,
}

/// `sigma[v] = field's density at centre(v)` for every `v` of `voxels`, in batches.
fn evaluate_at(
    field: &dyn FieldSource,
    voxels: &[usize],
    centre: &(dyn Fn(usize) -> DVec3 + Sync),
    sigma: &mut [f32],
    progress: Progress,
) -> Result<()> {
    let bar = progress.bar("fine density", voxels.len() as u64, "points");
    let mut out = vec![0.0f32; FINE_BATCH_POINTS];
    for batch in voxels.chunks(FINE_BATCH_POINTS) {
        let points: Vec<glam::Vec3> = batch.iter().map(|&v| centre(v).as_vec3()).collect();
        let out = &mut out[..batch.len()];
        field.evaluate_density(&points, out)?;
        for (&v, &s) in batch.iter().zip(out.iter()) {
            sigma[v] = s;
        }
        bar.inc(batch.len() as u64);
    }
    bar.finish_and_clear();
    Ok(())
}

#[cfg(test)]
mod tests {
    use half::f16;

    use super::*;

    #[test]
    fn a_closed_surface_is_watertight_and_a_sheet_or_a_holed_one_is_not() {
        use glam::Vec3;
        let sphere = nelf_scene::shapes::uv_sphere(Vec3::ZERO, 0.1, 8, 12, [0.5; 3]);
        assert!(is_watertight(&sphere));
        let quad = nelf_scene::shapes::quad(Vec3::ZERO, Vec3::X, Vec3::Y, 2, [0.5; 3]);
        assert!(!is_watertight(&quad));
        let mut holed = sphere.clone();
        holed.triangles.remove(7);
        assert!(!is_watertight(&holed));
        // Duplicated vertices (a UV seam) do not open a closed surface.
        let mut seamed = sphere;
        let copy = seamed.positions[5];
        seamed.positions.push(copy);
        let new = (seamed.positions.len() - 1) as u32;
        for t in seamed.triangles.iter_mut().filter(|t| t.contains(&5)).take(2) {
            for v in t.iter_mut().filter(|v| **v == 5) {
                *v = new;
            }
        }
        assert!(is_watertight(&seamed));
        // The procedural heads (surface nets) are closed.
        let head = nelf_scene::head::procedural_head(11, &nelf_scene::head::HeadParams::default());
        assert!(is_watertight(&head));
    }

    #[test]
    fn rounding_keeps_six_mantissa_bits_and_the_sign() {
        for v in [
            0.0f32, -0.0, 1.0, -1.0, 3.0e-5, 1234.5, -987.25, 65504.0, -65504.0,
        ] {
            let x = f16::from_f32(v);
            let r = round_mantissa(x);
            assert!(r.is_finite());
            assert_eq!(r.to_bits() & 0xF, 0, "{v}");
            assert!(
                // Relative 2⁻⁷ for normal values; subnormals (below 6.1e-5) lose up to
                // half of the 16 smallest steps (2⁻²⁴ each).
                (r.to_f32() - x.to_f32()).abs() <= x.to_f32().abs() / 128.0 + 8.0 * 2f32.powi(-24),
                "{v} → {r}"
            );
            assert_eq!(r.to_f32().is_sign_negative(), x.to_f32().is_sign_negative());
        }
    }
}
