//! The sparse brick grid of a `.nelf` asset (SPEC.md §7) and trilinear
//! interpolation of per-voxel values across brick borders.
//!
//! Voxel `(i, j, k)` of the whole grid (global voxel coordinates, `0 ≤ i < 8·grid_bricks_x`)
//! lives in brick `(i, j, k) / 8` at local position `(i, j, k) mod 8`; its value is
//! stored at index `brick_index · 512 + (i mod 8) + 8 (j mod 8) + 64 (k mod 8)` (the
//! file's order). Its centre is `bbox_min + (ijk + 0.5) · voxel_size`.
//!
//! **Trilinear interpolation** at a world point `p`: with continuous voxel
//! coordinates `u = (p − bbox_min) / voxel_size − 0.5` (so voxel centres sit at
//! integers), base corner `b = ⌊u⌋` and fraction `f = u − b`, the value is
//!
//! `f(p) = Σ_{d ∈ {0,1}³} w_d · v[b + d]`, `w_d = Π_a (d_a ? f_a : 1 − f_a)`,
//!
//! with `v = 0` for voxels outside every stored brick (the spec's "outside all bricks
//! σ = 0"). Weights of missing voxels are dropped, **not** renormalised, so values fall
//! off linearly to zero over the last voxel of a brick that has no neighbour. Corners are
//! visited in the order `d = (dx, dy, dz)` with `dx` fastest; each weight is computed in
//! `f32` as `(wx · wy) · wz` from `f32` fractions (a shader does the same).
//!
//! Brick lookup is a dense table of `grid_bricks` entries (`u32::MAX` = empty) when that
//! table has at most 2²⁴ entries, otherwise a binary search on the sorted brick list;
//! both give the same answers.

use glam::DVec3;
use nelf_format::Asset;
use nelf_format::asset::{GridGeometry, brick_order_key, local_voxel_index};
use nelf_format::spec::{BRICK_SIZE, BRICK_VOXELS};

use crate::error::RenderError;

/// Marker of an empty cell in the dense brick table.
const EMPTY: u32 = u32::MAX;
/// Largest dense brick table built (entries); bigger grids use binary search.
const MAX_DENSE_TABLE: u64 = 1 << 24;
/// Offsets of the 8 trilinear corners from the base voxel inside one brick, `dx` fastest.
const CORNER_OFFSETS: [usize; 8] = [0, 1, 8, 9, 64, 65, 72, 73];

/// How bricks are found from their coordinates.
#[derive(Debug, Clone)]
enum BrickLookup {
    /// `table[x + gx (y + gy z)]` = brick index or [`EMPTY`].
    Dense(Vec<u32>),
    /// Binary search on the (z, y, x)-sorted brick list.
    Sorted,
}

/// What a trilinear lookup found (internal to the marcher).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Lookup {
    /// `n` corners with their voxel indices and weights were written.
    Corners(usize),
    /// All 8 corners lie in this missing brick: the value is 0, and it stays 0 on the
    /// whole box [`BrickGrid::empty_core_box`] of that brick.
    EmptyBrick([i64; 3]),
}

/// Sparse brick grid geometry plus lookup of voxel values across brick borders.
#[derive(Debug, Clone)]
pub struct BrickGrid {
    geometry: GridGeometry,
    bricks: Vec<[u16; 3]>,
    lookup: BrickLookup,
    bbox_min: DVec3,
    bbox_max: DVec3,
    inverse_voxel_size: f64,
    grid_voxels: [i64; 3],
}

impl BrickGrid {
    /// Checks the geometry (finite origin, positive voxel size, extents in `1..=65536`) and
    /// the bricks (inside the grid, strictly increasing in (z, y, x) order) and builds the
    /// brick lookup.
    pub fn new(geometry: GridGeometry, bricks: Vec<[u16; 3]>) -> Result<Self, RenderError> {
        geometry.validate().map_err(RenderError::InvalidGrid)?;
        let n = geometry.grid_bricks;
        for (i, b) in bricks.iter().enumerate() {
            if (0..3).any(|a| u32::from(b[a]) >= n[a]) {
                return Err(RenderError::InvalidBricks(format!(
                    "brick {i} at {b:?} is outside the grid of {n:?} bricks"
                )));
            }
            if i > 0 && brick_order_key(bricks[i - 1]) >= brick_order_key(*b) {
                return Err(RenderError::InvalidBricks(format!(
                    "brick {i} at {b:?} does not follow {:?} in (z, y, x) order (unsorted or repeated)",
                    bricks[i - 1]
                )));
            }
        }
        if bricks.len() >= EMPTY as usize {
            return Err(RenderError::InvalidBricks(format!(
                "{} bricks is too many",
                bricks.len()
            )));
        }
        let cells = n.iter().map(|&v| u64::from(v)).product::<u64>();
        let lookup = if cells <= MAX_DENSE_TABLE {
            let mut table = vec![EMPTY; cells as usize];
            for (index, b) in bricks.iter().enumerate() {
                let [x, y, z] = b.map(usize::from);
                table[x + n[0] as usize * (y + n[1] as usize * z)] = index as u32;
            }
            BrickLookup::Dense(table)
        } else {
            BrickLookup::Sorted
        };
        let grid_voxels = geometry.grid_voxels().map(|v| v as i64);
        Ok(Self {
            bbox_min: DVec3::from_array(geometry.bbox_min_m),
            bbox_max: DVec3::from_array(geometry.bbox_max_m()),
            inverse_voxel_size: 1.0 / geometry.voxel_size_m,
            geometry,
            bricks,
            lookup,
            grid_voxels,
        })
    }

    /// The grid of an asset (its geometry and bricks, checked as in [`BrickGrid::new`]).
    pub fn from_asset(asset: &Asset) -> Result<Self, RenderError> {
        Self::new(asset.grid, asset.bricks.clone())
    }

    /// Grid placement.
    pub fn geometry(&self) -> &GridGeometry {
        &self.geometry
    }

    /// Brick coordinates, sorted by (z, y, x).
    pub fn bricks(&self) -> &[[u16; 3]] {
        &self.bricks
    }

    /// Voxels stored: bricks × 512; voxel `v = brick · 512 + x + 8y + 64z` (the file's order).
    pub fn voxel_count(&self) -> usize {
        self.bricks.len() * BRICK_VOXELS
    }

    /// Minimum corner of the grid box, metres.
    pub fn bbox_min(&self) -> DVec3 {
        self.bbox_min
    }

    /// Maximum corner of the grid box, metres.
    pub fn bbox_max(&self) -> DVec3 {
        self.bbox_max
    }

    /// Index in [`BrickGrid::bricks`] of the brick at brick coordinates `b`, if stored.
    #[inline]
    pub fn brick_index(&self, b: [i64; 3]) -> Option<usize> {
        let n = self.geometry.grid_bricks;
        if (0..3).any(|a| b[a] < 0 || b[a] >= i64::from(n[a])) {
            return None;
        }
        match &self.lookup {
            BrickLookup::Dense(table) => {
                let cell = b[0] as usize + n[0] as usize * (b[1] as usize + n[1] as usize * b[2] as usize);
                let index = table[cell];
                (index != EMPTY).then_some(index as usize)
            }
            BrickLookup::Sorted => {
                let key = (b[2] as u16, b[1] as u16, b[0] as u16);
                self.bricks
                    .binary_search_by_key(&key, |&c| brick_order_key(c))
                    .ok()
            }
        }
    }

    /// [`BrickGrid::brick_index`] for coordinates already known to be inside the grid.
    #[inline]
    fn brick_index_in_grid(&self, b: [i64; 3]) -> Option<usize> {
        debug_assert!((0..3).all(|a| b[a] >= 0 && b[a] < i64::from(self.geometry.grid_bricks[a])));
        match &self.lookup {
            BrickLookup::Dense(table) => {
                let n = self.geometry.grid_bricks;
                let cell = b[0] as usize + n[0] as usize * (b[1] as usize + n[1] as usize * b[2] as usize);
                let index = table[cell];
                (index != EMPTY).then_some(index as usize)
            }
            BrickLookup::Sorted => self.brick_index(b),
        }
    }

    /// Global voxel coordinates → voxel index (`None` outside the grid or in a missing brick).
    pub fn voxel_at(&self, ijk: [i64; 3]) -> Option<usize> {
        if (0..3).any(|a| ijk[a] < 0 || ijk[a] >= self.grid_voxels[a]) {
            return None;
        }
        let b = ijk.map(|v| v.div_euclid(BRICK_SIZE as i64));
        let l = ijk.map(|v| v.rem_euclid(BRICK_SIZE as i64) as usize);
        self.brick_index(b)
            .map(|index| index * BRICK_VOXELS + local_voxel_index(l[0], l[1], l[2]))
    }

    /// World position (metres) of the centre of global voxel `ijk`.
    pub fn voxel_center(&self, ijk: [i64; 3]) -> DVec3 {
        self.bbox_min
            + (DVec3::new(ijk[0] as f64, ijk[1] as f64, ijk[2] as f64) + 0.5) * self.geometry.voxel_size_m
    }

    /// Trilinear weights at world point `p`: up to 8 `(voxel index, weight)` pairs written to
    /// `out`, returning how many. Voxel centres are at `bbox_min + (ijk + 0.5)·voxel_size`;
    /// missing voxels (outside bricks or the grid) are left out and weights are **not**
    /// renormalised (see the module docs). A non-finite `p` gives 0 pairs.
    pub fn trilinear(&self, p: DVec3, out: &mut [(usize, f32); 8]) -> usize {
        match self.lookup_trilinear(p, out) {
            Lookup::Corners(n) => n,
            Lookup::EmptyBrick(_) => 0,
        }
    }

    /// Continuous voxel coordinates `u = (p − bbox_min)/voxel_size − 0.5`, base corner and
    /// `f32` fractions; `None` when not finite or absurdly far away.
    #[inline]
    fn base_and_fraction(&self, p: DVec3) -> Option<([i64; 3], [f32; 3])> {
        /// Beyond ±2⁵³ voxels nothing can be found; the comparisons also reject NaN and ±∞.
        const LIMIT: f64 = 9.0e15;
        let ux = (p.x - self.bbox_min.x) * self.inverse_voxel_size - 0.5;
        let uy = (p.y - self.bbox_min.y) * self.inverse_voxel_size - 0.5;
        let uz = (p.z - self.bbox_min.z) * self.inverse_voxel_size - 0.5;
        if ux.abs() < LIMIT && uy.abs() < LIMIT && uz.abs() < LIMIT {
            let (bx, by, bz) = (floor_i64(ux), floor_i64(uy), floor_i64(uz));
            let f = [
                (ux - bx as f64) as f32,
                (uy - by as f64) as f32,
                (uz - bz as f64) as f32,
            ];
            Some(([bx, by, bz], f))
        } else {
            None
        }
    }

    /// Trilinear lookup with the fast path used by the marcher: when all 8 corners are in
    /// one brick it is found once (and reported as [`Lookup::EmptyBrick`] when missing);
    /// otherwise each distinct brick among the corners is looked up once. Same corners,
    /// order and weights as [`BrickGrid::trilinear_general`].
    #[inline]
    pub(crate) fn lookup_trilinear(&self, p: DVec3, out: &mut [(usize, f32); 8]) -> Lookup {
        let Some((b, f)) = self.base_and_fraction(p) else {
            return Lookup::Corners(0);
        };
        // b ≥ 0 is checked first, so the shifts and masks below act on non-negative values.
        let last = BRICK_SIZE as i64 - 1;
        let one_brick = (0..3).all(|a| b[a] >= 0 && b[a] + 1 < self.grid_voxels[a] && b[a] & last != last);
        if !one_brick {
            return Lookup::Corners(self.straddling_corners(b, f, out));
        }
        let brick = b.map(|v| v >> 3);
        let Some(index) = self.brick_index_in_grid(brick) else {
            return Lookup::EmptyBrick(brick);
        };
        let l = b.map(|v| (v & last) as usize);
        let first = index * BRICK_VOXELS + local_voxel_index(l[0], l[1], l[2]);
        let w = corner_weights(f);
        for (slot, (offset, weight)) in out.iter_mut().zip(CORNER_OFFSETS.iter().zip(w)) {
            *slot = (first + offset, weight);
        }
        Lookup::Corners(8)
    }

    /// Corners of a cell that crosses a brick border or the grid's edge: each distinct
    /// brick among the corners is looked up once.
    fn straddling_corners(&self, b: [i64; 3], f: [f32; 3], out: &mut [(usize, f32); 8]) -> usize {
        let w = corner_weights(f);
        let g = self.grid_voxels;
        // Per axis and side d ∈ {0, 1}: inside the grid, brick coordinate, local coordinate
        // (shift and mask are floor division and remainder by 8, negatives included).
        let side = |a: usize, d: i64| {
            let c = b[a] + d;
            (c >= 0 && c < g[a], c >> 3, (c & 7) as usize)
        };
        let axes = [
            [side(0, 0), side(0, 1)],
            [side(1, 0), side(1, 1)],
            [side(2, 0), side(2, 1)],
        ];
        // Bit a of `shared` is set when both sides of axis a are in the same brick.
        let shared = (0..3).fold(0usize, |m, a| {
            m | (usize::from(axes[a][0].1 == axes[a][1].1) << a)
        });
        let mut brick_of = [None; 8];
        let mut n = 0;
        for (corner, &weight) in w.iter().enumerate() {
            let (x, y, z) = (
                axes[0][corner & 1],
                axes[1][(corner >> 1) & 1],
                axes[2][corner >> 2],
            );
            if !(x.0 && y.0 && z.0) {
                continue;
            }
            // The corner with the shared axes' bits cleared lies in the same brick and was seen
            // first (clearing bits only lowers the number); look up only new bricks.
            let canonical = corner & !shared;
            let index = if canonical == corner {
                self.brick_index_in_grid([x.1, y.1, z.1])
            } else {
                brick_of[canonical]
            };
            brick_of[corner] = index;
            if let Some(index) = index {
                out[n] = (index * BRICK_VOXELS + local_voxel_index(x.2, y.2, z.2), weight);
                n += 1;
            }
        }
        n
    }

    /// Trilinear weights looking up every corner on its own (the slow, obviously correct path).
    pub(crate) fn trilinear_general(&self, p: DVec3, out: &mut [(usize, f32); 8]) -> usize {
        match self.base_and_fraction(p) {
            Some((b, f)) => self.general_corners(b, f, out),
            None => 0,
        }
    }

    fn general_corners(&self, b: [i64; 3], f: [f32; 3], out: &mut [(usize, f32); 8]) -> usize {
        let w = corner_weights(f);
        let mut n = 0;
        for (corner, weight) in w.iter().enumerate() {
            let d = [corner & 1, (corner >> 1) & 1, corner >> 2].map(|v| v as i64);
            if let Some(v) = self.voxel_at([b[0] + d[0], b[1] + d[1], b[2] + d[2]]) {
                out[n] = (v, *weight);
                n += 1;
            }
        }
        n
    }

    /// The box (world, metres) on which every trilinear lookup finds only voxels of brick
    /// `brick`: its voxel centres' hull, the brick box shrunk by half a voxel on every side.
    /// If that brick is missing, every value inside this closed box is exactly 0.
    pub fn empty_core_box(&self, brick: [i64; 3]) -> (DVec3, DVec3) {
        let size = self.geometry.voxel_size_m;
        let lo = DVec3::new(brick[0] as f64, brick[1] as f64, brick[2] as f64) * (BRICK_SIZE as f64);
        (
            self.bbox_min + (lo + 0.5) * size,
            self.bbox_min + (lo + (BRICK_SIZE as f64 - 0.5)) * size,
        )
    }
}

/// `⌊x⌋` for finite `|x| < 2⁶³` without a libm call.
#[inline]
fn floor_i64(x: f64) -> i64 {
    let truncated = x as i64;
    truncated - i64::from((truncated as f64) > x)
}

/// The 8 trilinear weights, `dx` fastest, each `(wx · wy) · wz` in `f32`.
fn corner_weights(f: [f32; 3]) -> [f32; 8] {
    let wx = [1.0 - f[0], f[0]];
    let wy = [1.0 - f[1], f[1]];
    let wz = [1.0 - f[2], f[2]];
    std::array::from_fn(|c| (wx[c & 1] * wy[(c >> 1) & 1]) * wz[c >> 2])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fast_lookup_equals_per_corner_lookup() {
        let geometry = GridGeometry {
            bbox_min_m: [-0.3, 0.1, 0.0],
            voxel_size_m: 0.02,
            grid_bricks: [3, 2, 2],
        };
        let bricks = vec![[0, 0, 0], [1, 0, 0], [0, 1, 0], [2, 1, 0], [1, 1, 1]];
        let grid = BrickGrid::new(geometry, bricks).unwrap();
        let mut state = 12345u32;
        let (mut fast, mut slow) = ([(0, 0.0); 8], [(0, 0.0); 8]);
        let mut empty = 0;
        for _ in 0..20_000 {
            let mut next = || {
                state ^= state << 13;
                state ^= state >> 17;
                state ^= state << 5;
                f64::from(state) / f64::from(u32::MAX)
            };
            let u = DVec3::new(next() * 26.0 - 1.0, next() * 18.0 - 1.0, next() * 18.0 - 1.0);
            let p = grid.bbox_min() + u * 0.02;
            let n_slow = grid.trilinear_general(p, &mut slow);
            match grid.lookup_trilinear(p, &mut fast) {
                Lookup::Corners(n) => assert_eq!(fast[..n], slow[..n_slow]),
                Lookup::EmptyBrick(brick) => {
                    empty += 1;
                    assert_eq!(n_slow, 0);
                    let (lo, hi) = grid.empty_core_box(brick);
                    assert!(p.cmpge(lo).all() && p.cmple(hi).all());
                }
            }
        }
        assert!(empty > 1000);
    }
}
