//! The sparse grid's geometry (SPEC.md, section 7): 8³ cell-centred bricks, the grid
//! box in metres ([`GridGeometry`]), and voxel order inside a brick and along the
//! brick list. A leaf module: the asset and the byte layout (`spec`) both use it.

use glam::DVec3;

/// Voxels along each edge of a brick.
pub const BRICK_SIZE: usize = 8;
/// Voxels in one brick (`8³`).
pub const BRICK_VOXELS: usize = BRICK_SIZE * BRICK_SIZE * BRICK_SIZE;
/// Fine-density factors `F` a file may declare (format 1.4, header `fine_density_factor`,
/// section `DNSF`).
pub const FINE_DENSITY_FACTORS: [u32; 2] = [2, 4];
/// Largest grid extent, in bricks, along any axis (brick coordinates are `u16`).
pub const MAX_GRID_BRICKS: u32 = 65_536;

/// Placement of the brick grid in the world (metres).
///
/// The grid box is `[bbox_min_m, bbox_min_m + 8 · grid_bricks · voxel_size_m]`.
/// Voxel `(i, j, k)` (each `0..8`) of the brick at brick coordinates `b` has its
/// centre at `bbox_min_m + (8·b + (i, j, k) + 0.5) · voxel_size_m`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GridGeometry {
    /// Minimum corner of the grid box, metres.
    pub bbox_min_m: [f64; 3],
    /// Edge length of one voxel, metres.
    pub voxel_size_m: f64,
    /// Grid extent in bricks along x, y, z (each `1..=65536`).
    pub grid_bricks: [u32; 3],
}

impl GridGeometry {
    /// Maximum corner of the grid box: `bbox_min + 8 · grid_bricks · voxel_size`.
    pub fn bbox_max_m(&self) -> [f64; 3] {
        std::array::from_fn(|a| {
            self.bbox_min_m[a] + f64::from(self.grid_bricks[a]) * BRICK_SIZE as f64 * self.voxel_size_m
        })
    }

    /// Grid extent in voxels along x, y, z.
    pub fn grid_voxels(&self) -> [u64; 3] {
        self.grid_bricks.map(|n| u64::from(n) * BRICK_SIZE as u64)
    }

    /// World position (metres) of the centre of voxel `local` (each `0..8`) in brick `brick`.
    pub fn voxel_center_m(&self, brick: [u16; 3], local: [usize; 3]) -> DVec3 {
        let mut p = [0.0; 3];
        for a in 0..3 {
            let index = f64::from(brick[a]) * BRICK_SIZE as f64 + local[a] as f64 + 0.5;
            p[a] = self.bbox_min_m[a] + index * self.voxel_size_m;
        }
        DVec3::from_array(p)
    }

    /// Checks ranges: finite origin, positive finite voxel size, extents in `1..=65536`.
    pub fn validate(&self) -> Result<(), String> {
        if !self.bbox_min_m.iter().all(|v| v.is_finite()) {
            return Err(format!("bbox_min {:?} is not finite", self.bbox_min_m));
        }
        if !(self.voxel_size_m.is_finite() && self.voxel_size_m > 0.0) {
            return Err(format!(
                "voxel size {} must be positive and finite",
                self.voxel_size_m
            ));
        }
        if self.grid_bricks.iter().any(|&n| n == 0 || n > MAX_GRID_BRICKS) {
            return Err(format!(
                "grid extent {:?} bricks must be in 1..={MAX_GRID_BRICKS} per axis",
                self.grid_bricks
            ));
        }
        if !self.bbox_max_m().iter().all(|v| v.is_finite()) {
            return Err("grid box maximum overflows".into());
        }
        Ok(())
    }
}

/// Index of voxel `(i, j, k)` inside a brick: x fastest, `i + 8·(j + 8·k)`.
pub const fn local_voxel_index(i: usize, j: usize, k: usize) -> usize {
    i + BRICK_SIZE * (j + BRICK_SIZE * k)
}

/// `(i, j, k)` of local voxel index `index` (inverse of [`local_voxel_index`]).
pub const fn local_voxel_coords(index: usize) -> [usize; 3] {
    [
        index % BRICK_SIZE,
        (index / BRICK_SIZE) % BRICK_SIZE,
        index / (BRICK_SIZE * BRICK_SIZE),
    ]
}

/// Sort key of a brick: z, then y, then x (x varies fastest along the brick list).
pub fn brick_order_key(coord: [u16; 3]) -> (u16, u16, u16) {
    (coord[2], coord[1], coord[0])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn voxel_indexing_conventions() {
        assert_eq!(local_voxel_index(1, 2, 3), 1 + 16 + 192);
        assert_eq!(local_voxel_coords(local_voxel_index(7, 0, 5)), [7, 0, 5]);
        let g = GridGeometry {
            bbox_min_m: [-1.0, 0.0, 2.0],
            voxel_size_m: 0.5,
            grid_bricks: [2, 3, 4],
        };
        assert_eq!(g.bbox_max_m(), [7.0, 12.0, 18.0]);
        let p = g.voxel_center_m([1, 0, 2], [3, 0, 7]);
        assert_eq!(p, DVec3::new(-1.0 + 11.5 * 0.5, 0.25, 2.0 + 23.5 * 0.5));
    }
}
