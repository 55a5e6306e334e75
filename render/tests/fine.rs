//! The fine density of format 1.4 (SPEC.md §6 `DNSF`, §8 "Fine density"): its values
//! land where the spec places them, and it carries a silhouette the voxels cannot.

mod common;

use glam::{DMat3, DVec3};
use half::f16;
use nelf_format::conventions::LatLong;
use nelf_format::{CoefficientEncoding, FineDensity};
use nelf_render::{FineGrid, MarchSettings, render_asset};

use common::{orbit_camera, synthetic};

/// Every fine voxel's value read back from the fine grid at the position SPEC §6 gives it.
#[test]
fn fine_voxels_sit_where_the_spec_puts_them() {
    let mut asset = synthetic(3000, 4, CoefficientEncoding::U8Affine, 7);
    for factor in [2u32, 4] {
        let per_brick = 512 * (factor as usize).pow(3);
        let values: Vec<f16> = (0..asset.bricks.len() * per_brick)
            .map(|i| f16::from_f32((i % 2039) as f32))
            .collect();
        asset.fine_density = Some(FineDensity {
            factor,
            values: values.clone(),
        });
        let fine = FineGrid::from_asset(&asset).unwrap().unwrap();
        let edge = 8 * factor as i64;
        let fine_voxel = asset.grid.voxel_size_m / f64::from(factor);
        for (b, coord) in asset.bricks.iter().enumerate().step_by(3) {
            for (i, j, k) in [
                (0, 0, 0),
                (edge - 1, 3, 5),
                (1, edge - 1, edge - 2),
                (edge / 2, edge / 3, edge - 1),
            ] {
                let ijk = [
                    i64::from(coord[0]) * edge + i,
                    i64::from(coord[1]) * edge + j,
                    i64::from(coord[2]) * edge + k,
                ];
                let stored = values[b * per_brick + (i + edge * (j + edge * k)) as usize].to_f32();
                let v = fine.grid.voxel_at(ijk).unwrap();
                assert_eq!(fine.density[v], stored);
                // The centre SPEC §6 gives: bbox_min + (8F·b + (i,j,k) + ½)·Δ/F.
                let centre = DVec3::from_array(asset.grid.bbox_min_m)
                    + (DVec3::new(ijk[0] as f64, ijk[1] as f64, ijk[2] as f64) + 0.5) * fine_voxel;
                assert!((fine.grid.voxel_center(ijk) - centre).length() < 1e-12);
            }
        }
    }
    // A count that does not match the bricks is refused, not indexed out of range.
    asset.fine_density = Some(FineDensity {
        factor: 2,
        values: vec![f16::ZERO; 10],
    });
    assert!(FineGrid::from_asset(&asset).is_err());
}

/// A sphere's signed ramp stored at the voxels and again at a lattice 2× and 4× finer
/// (each with its ramp scaled to its own voxel, as the baker stores it): the coverage
/// of the render approaches the true disc as the lattice refines, while a file without
/// the fine density renders exactly as before.
#[test]
fn a_finer_density_draws_a_truer_silhouette() {
    let mut asset = synthetic(20000, 4, CoefficientEncoding::U8Affine, 3);
    let centre = {
        let g = &asset.grid;
        DVec3::from_array(g.bbox_max_m()) * 0.5 + DVec3::from_array(g.bbox_min_m) * 0.5
    };
    let extent = DVec3::from_array(asset.grid.bbox_max_m()) - DVec3::from_array(asset.grid.bbox_min_m);
    let radius = 0.3 * extent.min_element();
    let ramp = |voxel: f64, p: DVec3| -> f16 {
        // Zero a quarter voxel outside, slope for transmittance ½ a quarter voxel inside.
        let (lead, r) = (0.25 * voxel, 0.25 * voxel);
        let slope = 2.0 * std::f64::consts::LN_2 / (r * r);
        let cap = slope * (lead + 2.0 * voxel);
        let d = (p - centre).length() - radius;
        f16::from_f64((slope * (lead - d)).clamp(-cap, cap))
    };
    let voxel = asset.grid.voxel_size_m;
    let origin = DVec3::from_array(asset.grid.bbox_min_m);
    asset.density = (0..asset.voxel_count())
        .map(|v| ramp(voxel, asset.voxel_position_m(v)))
        .collect();
    let camera = orbit_camera(20.0, 10.0, 4.0 * extent.max_element(), 96, 96);
    let env = LatLong::constant(8, 16, [1.0, 1.0, 1.0]);
    let settings = MarchSettings::default();
    // The true disc's coverage, 4 × 4 points per pixel.
    let truth: Vec<f32> = (0..96 * 96)
        .map(|i| {
            let (col, row) = (i % 96, i / 96);
            let mut hit = 0;
            for sy in 0..4 {
                for sx in 0..4 {
                    let px = glam::DVec2::new(
                        col as f64 + (sx as f64 + 0.5) / 4.0,
                        row as f64 + (sy as f64 + 0.5) / 4.0,
                    );
                    let dir = camera.ray_direction(px);
                    let oc = camera.centre() - centre;
                    let b = oc.dot(dir);
                    if b * b - (oc.length_squared() - radius * radius) > 0.0 {
                        hit += 1;
                    }
                }
            }
            hit as f32 / 16.0
        })
        .collect();
    let coverage_error = |asset: &nelf_format::Asset| -> f64 {
        let s = MarchSettings {
            pixel_grid: 4,
            ..settings
        };
        let image = render_asset(asset, &camera, &env, DMat3::IDENTITY, None, &s).unwrap();
        image
            .alpha
            .iter()
            .zip(&truth)
            .map(|(a, t)| f64::from((a - t).abs()))
            .sum::<f64>()
    };
    let coarse = coverage_error(&asset);
    let mut errors = vec![coarse];
    for factor in [2u32, 4] {
        let f = factor as usize;
        let edge = 8 * f;
        let fine_voxel = voxel / f64::from(factor);
        let mut values = Vec::with_capacity(asset.bricks.len() * 512 * f * f * f);
        for b in &asset.bricks {
            for k in 0..edge {
                for j in 0..edge {
                    for i in 0..edge {
                        let ijk = [
                            b[0] as usize * edge + i,
                            b[1] as usize * edge + j,
                            b[2] as usize * edge + k,
                        ];
                        let p = origin
                            + (DVec3::new(ijk[0] as f64, ijk[1] as f64, ijk[2] as f64) + 0.5) * fine_voxel;
                        values.push(ramp(fine_voxel, p));
                    }
                }
            }
        }
        let mut with_fine = asset.clone();
        with_fine.fine_density = Some(FineDensity { factor, values });
        errors.push(coverage_error(&with_fine));
    }
    eprintln!("coverage error: {errors:?}");
    assert!(
        errors[1] < 0.7 * errors[0] && errors[2] < 0.8 * errors[1],
        "coverage error (sum over pixels): voxels, 2×, 4× = {errors:?}"
    );
}
