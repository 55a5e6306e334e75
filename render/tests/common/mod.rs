//! Fixtures shared by the renderer's tests: hand-built grids, a tiny synthetic asset,
//! seeded random numbers and env maps.
#![allow(dead_code, clippy::unwrap_used)] // Each test file uses some helpers; helpers unwrap.

use glam::DVec3;
use nelf_format::asset::GridGeometry;
use nelf_format::conventions::{LatLong, PinholeCamera};
use nelf_format::synthetic::SyntheticField;
use nelf_format::{Asset, CoefficientEncoding, Coefficients};

/// xorshift32 in `[0, 1)`, deterministic.
pub struct Rng(u32);

impl Rng {
    pub fn new(seed: u32) -> Self {
        Self(seed.wrapping_mul(2_654_435_761).max(1))
    }

    pub fn next(&mut self) -> f32 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 17;
        self.0 ^= self.0 << 5;
        (self.0 >> 8) as f32 / (1u32 << 24) as f32
    }
}

/// A random lat-long map of any size with radiance in `[0, scale)`.
pub fn random_map(width: usize, height: usize, seed: u32, scale: f32) -> LatLong {
    let mut rng = Rng::new(seed);
    let texels = (0..width * height)
        .map(|_| [rng.next() * scale, rng.next() * scale, rng.next() * scale])
        .collect();
    LatLong::new(width, height, texels).unwrap()
}

/// Every brick of a `n[0] × n[1] × n[2]`-brick grid, in (z, y, x) order.
pub fn all_bricks(n: [u16; 3]) -> Vec<[u16; 3]> {
    let mut out = Vec::new();
    for z in 0..n[2] {
        for y in 0..n[1] {
            for x in 0..n[0] {
                out.push([x, y, z]);
            }
        }
    }
    out
}

/// A grid geometry with the given origin, voxel size and extent in bricks.
pub fn geometry(bbox_min_m: [f64; 3], voxel_size_m: f64, grid_bricks: [u32; 3]) -> GridGeometry {
    GridGeometry {
        bbox_min_m,
        voxel_size_m,
        grid_bricks,
    }
}

/// A small synthetic asset (about `voxels` voxels), PCA fitted on few samples to stay fast.
pub fn synthetic(voxels: usize, rank: usize, encoding: CoefficientEncoding, seed: u64) -> Asset {
    let field = SyntheticField::new(voxels, seed);
    let pca = field.fit_pca(rank, 400);
    let coefficients = Coefficients::quantize(&field.project(&pca), pca.rank(), encoding).unwrap();
    field.asset_with(pca, coefficients).unwrap()
}

/// A camera on a circle around the origin (azimuth from +z towards +x, elevation up).
pub fn orbit_camera(
    azimuth_deg: f64,
    elevation_deg: f64,
    distance_m: f64,
    width: u32,
    height: u32,
) -> PinholeCamera {
    let (az, el) = (azimuth_deg.to_radians(), elevation_deg.to_radians());
    let eye = distance_m * DVec3::new(el.cos() * az.sin(), el.sin(), el.cos() * az.cos());
    PinholeCamera::look_at(eye, DVec3::ZERO, DVec3::Y, width, height, 40f64.to_radians())
}
