//! Brick lookup and trilinear interpolation across brick borders.
#![allow(clippy::unwrap_used)] // Test helpers outside #[test] functions unwrap too.

mod common;

use common::{Rng, all_bricks, geometry, synthetic};
use glam::DVec3;
use nelf_format::CoefficientEncoding;
use nelf_render::{BrickGrid, RenderError};

#[test]
fn voxel_indices_follow_the_file_order() {
    let asset = synthetic(3000, 4, CoefficientEncoding::F16, 3);
    let grid = BrickGrid::from_asset(&asset).unwrap();
    assert_eq!(grid.voxel_count(), asset.voxel_count());
    let size = asset.grid.voxel_size_m;
    for v in (0..asset.voxel_count()).step_by(7) {
        let p = asset.voxel_position_m(v);
        let u = (p - grid.bbox_min()) / size - 0.5;
        let ijk = [u.x.round() as i64, u.y.round() as i64, u.z.round() as i64];
        assert_eq!(grid.voxel_at(ijk), Some(v));
        assert!(grid.voxel_center(ijk).abs_diff_eq(p, 1e-12));
        // At a voxel centre trilinear interpolation picks that voxel alone (up to rounding of p).
        let mut w = [(0, 0.0); 8];
        let n = grid.trilinear(p, &mut w);
        let picked: Vec<_> = w[..n].iter().filter(|c| c.1 > 1e-6).collect();
        assert_eq!(picked.len(), 1, "voxel {v}");
        assert_eq!(picked[0].0, v);
        assert!((picked[0].1 - 1.0).abs() < 1e-6);
    }
    assert_eq!(grid.voxel_at([-1, 0, 0]), None);
    assert_eq!(grid.voxel_at([0, 0, 1 << 40]), None);
}

/// Voxel values `f(p) = a·p + b` on a grid of 3 × 2 × 2 bricks with two bricks missing.
#[test]
fn trilinear_is_exact_for_a_linear_field_across_brick_borders() {
    let geo = geometry([-0.1, 0.2, -0.05], 0.01, [3, 2, 2]);
    let bricks: Vec<[u16; 3]> = all_bricks([3, 2, 2])
        .into_iter()
        .filter(|b| *b != [2, 1, 1] && *b != [2, 0, 0])
        .collect();
    let grid = BrickGrid::new(geo, bricks).unwrap();
    let (a, b) = (DVec3::new(3.0, -2.0, 0.5), 0.25);
    let f = |p: DVec3| a.dot(p) + b;
    let values: Vec<f64> = (0..grid.voxel_count())
        .map(|v| {
            let brick = grid.bricks()[v / 512];
            let l = v % 512;
            let ijk = [
                i64::from(brick[0]) * 8 + (l % 8) as i64,
                i64::from(brick[1]) * 8 + (l / 8 % 8) as i64,
                i64::from(brick[2]) * 8 + (l / 64) as i64,
            ];
            f(grid.voxel_center(ijk))
        })
        .collect();
    let mut rng = Rng::new(9);
    let mut checked = 0;
    let mut across = 0;
    let mut w = [(0, 0.0f32); 8];
    for _ in 0..20_000 {
        let u = DVec3::new(
            f64::from(rng.next()) * 24.0,
            f64::from(rng.next()) * 16.0,
            f64::from(rng.next()) * 16.0,
        );
        let p = grid.bbox_min() + u * 0.01;
        let n = grid.trilinear(p, &mut w);
        // Only points whose 8 neighbours all exist are inside the union of bricks' centres.
        if n < 8 {
            continue;
        }
        let base = (u - 0.5).floor();
        if (0..3).any(|ax| (base[ax] as i64).rem_euclid(8) == 7) {
            across += 1;
        }
        let total: f64 = w[..n].iter().map(|c| f64::from(c.1)).sum();
        let value: f64 = w[..n].iter().map(|&(v, wt)| f64::from(wt) * values[v]).sum();
        assert!((total - 1.0).abs() < 1e-6, "weights sum to {total}");
        assert!((value - f(p)).abs() < 1e-6, "at {p}: {value} vs {}", f(p));
        checked += 1;
    }
    assert!(
        checked > 10_000 && across > 1000,
        "{checked} points, {across} across borders"
    );
}

#[test]
fn missing_neighbours_count_as_zero_without_renormalising() {
    // One brick alone: half a voxel outside its last centre the weights sum to 1/2 per axis.
    let grid = BrickGrid::new(geometry([0.0; 3], 1.0, [2, 1, 1]), vec![[0, 0, 0]]).unwrap();
    let mut w = [(0, 0.0f32); 8];
    let n = grid.trilinear(DVec3::new(8.0, 4.0, 4.0), &mut w);
    let total: f32 = w[..n].iter().map(|c| c.1).sum();
    assert_eq!(n, 4);
    assert!((total - 0.5).abs() < 1e-6);
    let n = grid.trilinear(DVec3::new(12.0, 4.0, 4.0), &mut w);
    assert_eq!(n, 0);
    assert_eq!(grid.trilinear(DVec3::new(f64::NAN, 0.0, 0.0), &mut w), 0);
}

#[test]
fn huge_sparse_grids_use_a_search_and_agree() {
    // 300³ bricks is 27 M cells: no dense table, the sorted search answers.
    let bricks = vec![[0, 0, 7], [5, 0, 0], [299, 299, 0], [1, 2, 299]];
    let big = BrickGrid::new(geometry([0.0; 3], 0.001, [300; 3]), bricks.clone());
    let Err(RenderError::InvalidBricks(_)) = big else {
        panic!("unsorted bricks must be refused");
    };
    let mut sorted = bricks;
    sorted.sort_by_key(|b| (b[2], b[1], b[0]));
    let grid = BrickGrid::new(geometry([0.0; 3], 0.001, [300; 3]), sorted.clone()).unwrap();
    for (i, b) in sorted.iter().enumerate() {
        let ijk = b.map(|v| i64::from(v) * 8 + 3);
        assert_eq!(grid.voxel_at(ijk), Some(i * 512 + 3 + 24 + 192));
        assert_eq!(grid.brick_index(b.map(i64::from)), Some(i));
    }
    assert_eq!(grid.voxel_at([8 * 6, 0, 0]), None);
}

#[test]
fn bad_grids_are_refused() {
    let geo = geometry([0.0; 3], 0.01, [2, 2, 2]);
    assert!(matches!(
        BrickGrid::new(geo, vec![[2, 0, 0]]),
        Err(RenderError::InvalidBricks(m)) if m.contains("outside")
    ));
    assert!(matches!(
        BrickGrid::new(geo, vec![[1, 0, 0], [1, 0, 0]]),
        Err(RenderError::InvalidBricks(m)) if m.contains("unsorted or repeated")
    ));
    let bad = geometry([0.0; 3], -1.0, [2, 2, 2]);
    assert!(matches!(
        BrickGrid::new(bad, vec![]),
        Err(RenderError::InvalidGrid(_))
    ));
    let bad = geometry([f64::NAN, 0.0, 0.0], 1.0, [2, 2, 2]);
    assert!(BrickGrid::new(bad, vec![]).is_err());
}
