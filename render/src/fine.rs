//! The fine density of a format-1.4 asset (SPEC.md §6 `DNSF`, §8 "Fine density") as a
//! brick grid of its own.
//!
//! A fine density of factor `F` stores, per brick of the asset, the `8F × 8F × 8F` fine
//! voxels of voxel size `Δ/F`. Read with exactly the interpolation rule of `DENS`
//! (trilinear between fine-voxel centres, missing fine voxels 0, weights not
//! renormalised), that is the rule of a grid of voxel size `Δ/F`, `F` times as many
//! bricks per axis, in which each asset brick `b` becomes the `F³` bricks `F·b + o`,
//! `o ∈ {0..F}³`. [`FineGrid`] builds that grid (the same [`BrickGrid`] the marcher
//! walks, with its empty-space skipping) and reorders the values into its bricks; the
//! renderer then takes σ from it and everything else from the asset's own grid.

use nelf_format::Asset;
use nelf_format::asset::{GridGeometry, brick_order_key, local_voxel_index};
use nelf_format::spec::{BRICK_SIZE, BRICK_VOXELS};

use crate::error::RenderError;
use crate::grid::BrickGrid;

/// An asset's fine density as a grid of fine voxels and their σ (1/m) in its order.
#[derive(Debug, Clone)]
pub struct FineGrid {
    /// The grid of fine voxels (voxel size `Δ/F`).
    pub grid: BrickGrid,
    /// σ per fine voxel in `grid`'s voxel order.
    pub density: Vec<f32>,
    /// The factor `F`.
    pub factor: u32,
}

impl FineGrid {
    /// The fine grid of `asset`, `None` when it has no fine density. Checks what the
    /// asset's own validation checks about it (factor and count).
    pub fn from_asset(asset: &Asset) -> Result<Option<Self>, RenderError> {
        let Some(fine) = &asset.fine_density else {
            return Ok(None);
        };
        fine.validate(asset.bricks.len())?;
        let f = fine.factor as usize;
        let geometry = GridGeometry {
            bbox_min_m: asset.grid.bbox_min_m,
            voxel_size_m: asset.grid.voxel_size_m / f64::from(fine.factor),
            grid_bricks: asset.grid.grid_bricks.map(|n| n * fine.factor),
        };
        // Fine bricks with the index of their asset brick and their offset inside it.
        let mut fine_bricks: Vec<([u16; 3], usize, [usize; 3])> =
            Vec::with_capacity(asset.bricks.len() * f * f * f);
        for (index, b) in asset.bricks.iter().enumerate() {
            for oz in 0..f {
                for oy in 0..f {
                    for ox in 0..f {
                        let o = [ox, oy, oz];
                        let coord: [u16; 3] = std::array::from_fn(|a| {
                            u16::try_from(usize::from(b[a]) * f + o[a]).unwrap_or(u16::MAX)
                        });
                        fine_bricks.push((coord, index, o));
                    }
                }
            }
        }
        fine_bricks.sort_by_key(|(c, _, _)| brick_order_key(*c));
        let edge = fine.brick_edge();
        let per_brick = fine.voxels_per_brick();
        let mut density = Vec::with_capacity(fine_bricks.len() * BRICK_VOXELS);
        for (_, index, o) in &fine_bricks {
            let base = index * per_brick;
            for k in 0..BRICK_SIZE {
                for j in 0..BRICK_SIZE {
                    for i in 0..BRICK_SIZE {
                        let (fi, fj, fk) = (
                            o[0] * BRICK_SIZE + i,
                            o[1] * BRICK_SIZE + j,
                            o[2] * BRICK_SIZE + k,
                        );
                        density.push(fine.values[base + fi + edge * (fj + edge * fk)].to_f32());
                    }
                }
            }
            debug_assert_eq!(density.len() % BRICK_VOXELS, 0);
        }
        debug_assert!(density.len() == fine_bricks.len() * BRICK_VOXELS && local_voxel_index(1, 0, 0) == 1);
        let grid = BrickGrid::new(geometry, fine_bricks.into_iter().map(|(c, _, _)| c).collect())?;
        Ok(Some(Self {
            grid,
            density,
            factor: fine.factor,
        }))
    }
}
