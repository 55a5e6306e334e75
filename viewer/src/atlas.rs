//! How an asset is laid out in GPU memory (CPU side, no device needed).
//!
//! * **Atlas**: one slot of 10³ texels per brick — its 8³ voxels plus a 1-voxel apron
//!   holding the neighbouring bricks' border voxels (0 where a neighbour is missing),
//!   built by the relight pass. Hardware trilinear filtering of a point anywhere within
//!   half a voxel of a brick's box then reads only that brick's slot and equals the
//!   reference's trilinear interpolation across brick borders (`nelf_render::grid`).
//!   Slot `s` (= brick index `s`, file order) sits at slot coordinates
//!   `(s mod 2^x_bits, (s >> x_bits) mod 2^y_bits, s >> (x_bits + y_bits))`: powers of two
//!   along x and y make the shaders' slot addressing bit operations.
//! * **Halo slots**: every missing brick next to a present one gets a slot too (zeros,
//!   with the neighbours' border voxels in its apron), so a sample anywhere within one
//!   cell of a present brick is one texture fetch — the march needs no per-corner lookups.
//! * **Indirection grid** ([`Indirection`], CPU only): one `u32` per brick cell, the slot
//!   of a present brick or halo cell; it drives the apron build.
//! * **March grid** ([`MarchGrid`]): per cube of voxels, the distance to the nearest
//!   σ > 0 (empty-space skipping) and the slot of its brick cell: one fetch per step.
//! * **Fine density atlas** (format 1.4, [`fine_density_atlas`]): where an asset has a
//!   fine density of factor `F`, σ comes from a second atlas, one slot of `(8F + 2)³`
//!   texels (its `8F` fine voxels a side plus a 1-fine-voxel apron) per atlas slot at the
//!   same slot index, so the march's one slot lookup serves both; the march grid then
//!   marks a voxel dense where any of its fine voxels is ([`fine_density_per_voxel`]).
//! * **Coefficients** stay as stored (8-bit codes or f16 halves), packed into `u32`
//!   words, `⌈K/4⌉` or `⌈K/2⌉` words per voxel, word-major so SIMD lanes (neighbouring
//!   voxels) read neighbouring words; the dequantisation is folded into the projected
//!   lighting ([`fold_light`]).

use nelf_format::spec::{BRICK_SIZE, BRICK_VOXELS};
use nelf_format::{Coefficients, FineDensity};
use nelf_render::ProjectedLight;

use crate::error::ViewerError;

/// Texels along an atlas slot edge (8 voxels + 2 apron voxels).
pub const SLOT_TEXELS: u32 = 10;
/// Largest indirection grid (brick cells) the viewer builds: 2²⁴ cells = 64 MiB.
pub const MAX_INDIRECTION_CELLS: u64 = 1 << 24;

/// Placement of brick slots in the atlas.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct AtlasLayout {
    /// log2 of the slot count along x.
    pub x_bits: u32,
    /// log2 of the slot count along y.
    pub y_bits: u32,
    /// Slot count along z.
    pub slots_z: u32,
    /// Slots in use (= bricks).
    pub slot_count: u32,
}

impl AtlasLayout {
    /// A near-cubic layout for `bricks` slots whose texel extent fits `max_texels` per
    /// axis (the device's `max_texture_dimension_3d`).
    pub fn for_bricks(bricks: usize, max_texels: u32) -> Result<Self, ViewerError> {
        Self::for_slot_edge(bricks, max_texels, SLOT_TEXELS)
    }

    /// [`AtlasLayout::for_bricks`] for slots of `slot_texels` texels a side (the atlas's
    /// [`SLOT_TEXELS`], or a fine density atlas's [`fine_slot_texels`]): the same slot
    /// placement serves every atlas whose slots are at most that large.
    pub fn for_slot_edge(bricks: usize, max_texels: u32, slot_texels: u32) -> Result<Self, ViewerError> {
        let max_slots = max_texels / slot_texels.max(1);
        if max_slots == 0 {
            return Err(ViewerError::TooLarge(format!(
                "3D textures limited to {max_texels} texels, slots of {slot_texels}"
            )));
        }
        let max_pow2_bits = max_slots.ilog2();
        let n = bricks.max(1) as f64;
        let want_x = n.cbrt().ceil() as u32;
        let x_bits = want_x.max(1).next_power_of_two().ilog2().min(max_pow2_bits);
        let want_y = (n / f64::from(1u32 << x_bits)).sqrt().ceil() as u32;
        let y_bits = want_y.max(1).next_power_of_two().ilog2().min(max_pow2_bits);
        let per_layer = 1u64 << (x_bits + y_bits);
        let slots_z = (bricks.max(1) as u64).div_ceil(per_layer);
        if slots_z > u64::from(max_slots) {
            return Err(ViewerError::TooLarge(format!(
                "{bricks} bricks need {slots_z} atlas layers of {per_layer} slots, the device allows {max_slots}"
            )));
        }
        Ok(Self {
            x_bits,
            y_bits,
            slots_z: slots_z as u32,
            slot_count: bricks as u32,
        })
    }

    /// Atlas size in texels.
    pub fn texels(&self) -> [u32; 3] {
        self.texels_for_slot_edge(SLOT_TEXELS)
    }

    /// Size in texels of an atlas with this slot placement and slots of `slot_texels`
    /// texels a side (a fine density atlas: [`fine_slot_texels`]).
    pub fn texels_for_slot_edge(&self, slot_texels: u32) -> [u32; 3] {
        [
            (1 << self.x_bits) * slot_texels,
            (1 << self.y_bits) * slot_texels,
            self.slots_z * slot_texels,
        ]
    }

    /// Slot coordinates (in slots) of slot `index` (the shaders' `slot_coords`).
    pub fn slot_coords(&self, index: u32) -> [u32; 3] {
        [
            index & ((1 << self.x_bits) - 1),
            (index >> self.x_bits) & ((1 << self.y_bits) - 1),
            index >> (self.x_bits + self.y_bits),
        ]
    }

    /// Atlas texel holding local voxel `local` (each in `-1..=8`) of brick `index`.
    pub fn texel_of(&self, index: u32, local: [i32; 3]) -> [u32; 3] {
        let s = self.slot_coords(index);
        std::array::from_fn(|a| s[a] * SLOT_TEXELS + (local[a] + 1) as u32)
    }
}

/// Largest slot index + 1 an indirection entry holds (the march grid keeps it in 24 bits).
pub const SLOT_BITS: u32 = (1 << 24) - 1;

/// The indirection grid and the atlas slots it points to.
///
/// Every brick cell of the grid (x fastest) has one `u32` entry:
/// * a **present** brick: its index + 1 (its slot is its index, file order);
/// * a **halo** cell — missing, but one of its 26 neighbours is present: its slot + 1
///   (halo slots follow the bricks'). Its voxels are 0 and its apron holds the
///   neighbours' border voxels, so every trilinear sample in a halo cell's box is one
///   texture sample;
/// * any other cell: 0 (no slot; the march never samples there, [`MarchGrid`]).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Indirection {
    /// One entry per brick cell, x fastest.
    pub entries: Vec<u32>,
    /// Brick-cell coordinates of every slot: the present bricks (in file order), then the
    /// halo cells.
    pub slot_cells: Vec<[u32; 3]>,
}

impl Indirection {
    /// Halo slots (after the bricks').
    pub fn halo_count(&self, bricks: usize) -> usize {
        self.slot_cells.len() - bricks
    }
}

/// Builds the indirection grid and slot list of a brick set (see [`Indirection`]).
pub fn indirection_grid(grid_bricks: [u32; 3], bricks: &[[u16; 3]]) -> Result<Indirection, ViewerError> {
    let cells = grid_bricks.iter().map(|&n| u64::from(n)).product::<u64>();
    if cells > MAX_INDIRECTION_CELLS {
        return Err(ViewerError::TooLarge(format!(
            "grid of {grid_bricks:?} bricks has {cells} cells, the viewer's indirection grid holds at most \
             {MAX_INDIRECTION_CELLS}"
        )));
    }
    let [nx, ny, nz] = grid_bricks.map(|n| n as usize);
    let mut entries = vec![0u32; cells as usize];
    let mut slot_cells = Vec::with_capacity(2 * bricks.len());
    for (index, b) in bricks.iter().enumerate() {
        if (0..3).any(|a| u32::from(b[a]) >= grid_bricks[a]) {
            return Err(ViewerError::BadSetting(format!(
                "brick {index} at {b:?} lies outside the grid {grid_bricks:?}"
            )));
        }
        let [x, y, z] = b.map(usize::from);
        entries[x + nx * (y + ny * z)] = index as u32 + 1;
        slot_cells.push(b.map(u32::from));
    }
    // Halo cells: the missing cells of every present brick's 3³ neighbourhood, in the
    // order the bricks list them.
    for b in bricks {
        let [x, y, z] = b.map(usize::from);
        for hz in z.saturating_sub(1)..=(z + 1).min(nz - 1) {
            for hy in y.saturating_sub(1)..=(y + 1).min(ny - 1) {
                for hx in x.saturating_sub(1)..=(x + 1).min(nx - 1) {
                    let cell = hx + nx * (hy + ny * hz);
                    if entries[cell] == 0 {
                        let slot = slot_cells.len() as u32;
                        if slot >= SLOT_BITS {
                            return Err(ViewerError::TooLarge(format!(
                                "more than {SLOT_BITS} atlas slots"
                            )));
                        }
                        entries[cell] = slot + 1;
                        slot_cells.push([hx, hy, hz].map(|v| v as u32));
                    }
                }
            }
        }
    }
    Ok(Indirection { entries, slot_cells })
}

/// Marker of "no slot" in [`neighbour_blocks`].
pub const NO_SLOT: u32 = u32::MAX;

/// Where the relight and view passes write each voxel (its own slot and the aprons of the
/// neighbours it borders; `voxel_texel` in `common.wgsl`): for every present brick `b`
/// (file order) and octant `o` of its voxels (bit `a` set: local coordinate `a` ≥ 4), the
/// atlas slots of the 2×2×2 cells `b + d` a voxel of that octant can border, entry
/// `e = e_x + 2e_y + 4e_z` holding cell `d_a = e_a·s_a` (`s_a` = +1 in the upper half, −1 in
/// the lower; entry 0 is the brick's own slot), [`NO_SLOT`] for far cells and cells
/// outside the grid. `8 × bricks` blocks, brick-major.
pub fn neighbour_blocks(
    indirection: &Indirection,
    grid_bricks: [u32; 3],
    bricks: &[[u16; 3]],
) -> Vec<[u32; 8]> {
    let [nx, ny, _] = grid_bricks.map(|n| n as usize);
    let mut out = Vec::with_capacity(bricks.len() * 8);
    for b in bricks {
        for octant in 0..8usize {
            let side: [i64; 3] = std::array::from_fn(|a| if octant >> a & 1 == 1 { 1 } else { -1 });
            out.push(std::array::from_fn(|e| {
                let c: [i64; 3] = std::array::from_fn(|a| i64::from(b[a]) + (e >> a & 1) as i64 * side[a]);
                if (0..3).all(|a| c[a] >= 0 && c[a] < i64::from(grid_bricks[a])) {
                    let entry =
                        indirection.entries[c[0] as usize + nx * (c[1] as usize + ny * c[2] as usize)];
                    entry.checked_sub(1).unwrap_or(NO_SLOT)
                } else {
                    NO_SLOT
                }
            }));
        }
    }
    out
}

/// Most texels of the march grid ([`march_grid`]): 2²⁴ (64 MiB of `u32`).
pub const MAX_MARCH_GRID_TEXELS: u64 = 1 << 24;

/// What the march reads at a sample point, one `u32` fetch (`march.wgsl`): per cube of
/// `factor³` voxels (`factor` = 1, 2, 4 or 8: the smallest within
/// [`MAX_MARCH_GRID_TEXELS`] and the device's 3D texture size),
///
/// * bits 0–7: the Chebyshev distance, in cubes and capped at 255, to the nearest cube
///   holding a voxel with σ > 0 (0 in such a cube): empty-space skipping. A sample point
///   `u` (lattice coordinates, voxel centres at integers) in cube `c = ⌊(u + ½)/f⌋` with
///   distance `D` is at least `f(D − 1) + ½` voxels (per axis, Chebyshev) from every voxel
///   with σ > 0, and a trilinear sample has σ > 0 only within 1 of one, so every sample
///   within `f(D − 1) − ½` of `u` has σ = 0 and may be skipped (at `f = 1` a distance of
///   8 skips 6.5 voxels);
/// * bits 8–31: the atlas slot + 1 of the brick cell holding the cube (a present brick or
///   a halo cell; 0 for none), whose slot holds every trilinear corner of a sample there.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MarchGrid {
    /// Voxels per cube edge.
    pub factor: u32,
    /// Cubes along x, y, z (the grid's voxels / `factor`).
    pub dims: [u32; 3],
    /// One texel per cube, x fastest.
    pub texels: Vec<u32>,
}

/// Bits of a [`MarchGrid`] texel below the slot.
pub const MARCH_GRID_SLOT_SHIFT: u32 = 8;

/// Builds the [`MarchGrid`] of a brick set (`density`: σ of every voxel, brick-major in
/// file order, x fastest within a brick; `indirection` from [`indirection_grid`]) for 3D
/// textures of at most `max_texture_dim` texels a side. The distance is exact (a two-pass
/// chamfer over the 26-neighbourhood with unit weights is the chessboard distance
/// transform; Rosenfeld & Pfaltz 1966).
pub fn march_grid(
    grid_bricks: [u32; 3],
    indirection: &Indirection,
    bricks: &[[u16; 3]],
    density: &[half::f16],
    max_texture_dim: u32,
) -> Result<MarchGrid, ViewerError> {
    let brick = BRICK_SIZE as u32;
    if density.len() != bricks.len() * BRICK_VOXELS {
        return Err(ViewerError::BadSetting(format!(
            "{} densities for {} bricks of {BRICK_VOXELS} voxels",
            density.len(),
            bricks.len()
        )));
    }
    let cells = grid_bricks.iter().map(|&n| n as usize).product::<usize>();
    if indirection.entries.len() != cells {
        return Err(ViewerError::BadSetting(format!(
            "indirection of {} cells for a grid of {grid_bricks:?} bricks",
            indirection.entries.len()
        )));
    }
    let factor = [1u32, 2, 4, 8]
        .into_iter()
        .find(|&f| {
            let dims = grid_bricks.map(|n| u64::from(n * brick / f));
            dims.iter().product::<u64>() <= MAX_MARCH_GRID_TEXELS
                && dims.iter().all(|&d| d <= u64::from(max_texture_dim))
        })
        .ok_or_else(|| {
            ViewerError::TooLarge(format!(
                "grid of {grid_bricks:?} bricks: no march grid fits {MAX_MARCH_GRID_TEXELS} texels and \
                 3D textures of {max_texture_dim}"
            ))
        })?;
    let dims = grid_bricks.map(|n| n * brick / factor);
    let [nx, ny, nz] = dims.map(|d| d as usize);
    let mut values = vec![u8::MAX; nx * ny * nz];
    for (b, cell) in bricks.iter().enumerate() {
        for (v, sigma) in density[b * BRICK_VOXELS..(b + 1) * BRICK_VOXELS]
            .iter()
            .enumerate()
        {
            if sigma.to_f32() > 0.0 {
                let local = [
                    v % BRICK_SIZE,
                    (v / BRICK_SIZE) % BRICK_SIZE,
                    v / (BRICK_SIZE * BRICK_SIZE),
                ];
                let [x, y, z]: [usize; 3] =
                    std::array::from_fn(|a| (usize::from(cell[a]) * BRICK_SIZE + local[a]) / factor as usize);
                if x < nx && y < ny && z < nz {
                    values[x + nx * (y + ny * z)] = 0;
                }
            }
        }
    }
    // The 13 neighbours before a cube in raster order (z, then y, then x ascending); the
    // backward pass uses their mirror images.
    let mut before = Vec::with_capacity(13);
    for dz in -1i64..=0 {
        for dy in -1i64..=1 {
            for dx in -1i64..=1 {
                if dz < 0 || dy < 0 || (dy == 0 && dx < 0) {
                    before.push([dx, dy, dz]);
                }
            }
        }
    }
    let (sx, sy, sz) = (nx as i64, ny as i64, nz as i64);
    let mut relax = |x: i64, y: i64, z: i64, sign: i64| {
        let here = (x + sx * (y + sy * z)) as usize;
        let mut best = values[here];
        for d in &before {
            let (qx, qy, qz) = (x + sign * d[0], y + sign * d[1], z + sign * d[2]);
            if qx >= 0 && qy >= 0 && qz >= 0 && qx < sx && qy < sy && qz < sz {
                best = best.min(values[(qx + sx * (qy + sy * qz)) as usize].saturating_add(1));
            }
        }
        values[here] = best;
    };
    for z in 0..sz {
        for y in 0..sy {
            for x in 0..sx {
                relax(x, y, z, 1);
            }
        }
    }
    for z in (0..sz).rev() {
        for y in (0..sy).rev() {
            for x in (0..sx).rev() {
                relax(x, y, z, -1);
            }
        }
    }
    let [gx, gy, _] = grid_bricks.map(|n| n as usize);
    let per_cell = (brick / factor) as usize;
    let mut texels = Vec::with_capacity(values.len());
    for z in 0..nz {
        for y in 0..ny {
            for x in 0..nx {
                let entry = indirection.entries[x / per_cell + gx * (y / per_cell + gy * (z / per_cell))];
                texels.push(u32::from(values[x + nx * (y + ny * z)]) | entry << MARCH_GRID_SLOT_SHIFT);
            }
        }
    }
    Ok(MarchGrid { factor, dims, texels })
}

/// Brick-cell coordinates of the present bricks (file order) as the view pass reads them
/// (`brick_cell` in `common.wgsl`): `[x | y << 16, z]`, for each voxel's centre.
pub fn pack_brick_cells(bricks: &[[u16; 3]]) -> Vec<[u32; 2]> {
    bricks
        .iter()
        .map(|b| [u32::from(b[0]) | (u32::from(b[1]) << 16), u32::from(b[2])])
        .collect()
}

/// Coefficients as the relight pass reads them: word-major (word `q` of every voxel,
/// then word `q + 1`), so neighbouring invocations read neighbouring words.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PackedCoefficients {
    /// Words: word `q` of voxel `v` at `q · voxels + v`.
    pub words: Vec<u32>,
    /// `⌈K/4⌉` (8-bit) or `⌈K/2⌉` (f16).
    pub words_per_voxel: u32,
    /// 1 = 8-bit affine codes, 2 = f16 values (the shader's encoding number).
    pub encoding: i32,
}

/// Packs stored coefficients (codes or halves, little-endian within a word).
pub fn pack_coefficients(coefficients: &Coefficients) -> PackedCoefficients {
    let rank = coefficients.rank().max(1);
    match coefficients {
        Coefficients::U8Affine { codes, .. } => {
            let per_voxel = rank.div_ceil(4);
            let voxels = codes.len() / rank;
            let mut words = vec![0u32; voxels * per_voxel];
            for (voxel, chunk) in codes.chunks_exact(rank).enumerate() {
                for (k, &code) in chunk.iter().enumerate() {
                    words[(k / 4) * voxels + voxel] |= u32::from(code) << (8 * (k % 4));
                }
            }
            PackedCoefficients {
                words,
                words_per_voxel: per_voxel as u32,
                encoding: 1,
            }
        }
        Coefficients::F16 { values, .. } => {
            let per_voxel = rank.div_ceil(2);
            let voxels = values.len() / rank;
            let mut words = vec![0u32; voxels * per_voxel];
            for (voxel, chunk) in values.chunks_exact(rank).enumerate() {
                for (k, v) in chunk.iter().enumerate() {
                    words[(k / 2) * voxels + voxel] |= u32::from(v.to_bits()) << (16 * (k % 2));
                }
            }
            PackedCoefficients {
                words,
                words_per_voxel: per_voxel as u32,
                encoding: 2,
            }
        }
    }
}

/// Densities (f16 bits) packed two per word, voxel order.
pub fn pack_density(density: &[half::f16]) -> Vec<u32> {
    density
        .chunks(2)
        .map(|pair| {
            let lo = u32::from(pair[0].to_bits());
            let hi = pair.get(1).map_or(0, |h| u32::from(h.to_bits()));
            lo | (hi << 16)
        })
        .collect()
}

/// What the relight pass shows per voxel.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum RelightView {
    /// Radiance with the first `rank` components.
    #[default]
    Shaded,
    /// `|c_k · P_k|`: what component `k` alone adds under the current lighting.
    Component(usize),
}

/// Lighting with the coefficient dequantisation folded in (see `relight.wgsl`).
#[derive(Debug, Clone, PartialEq)]
pub struct FoldedLight {
    /// Radiance of a voxel whose codes are all 0.
    pub mean_rgb: [f32; 3],
    /// Per-code radiance of each component used, `[r, g, b, 0]`.
    pub components: Vec<[f32; 4]>,
}

/// How stored coefficients turn into numbers: the part of [`Coefficients`] the
/// lighting fold needs (no per-voxel data).
#[derive(Debug, Clone, PartialEq)]
pub enum Dequantization {
    /// `c_k = offset_k + scale_k · code`.
    Affine {
        /// Per-component step.
        scale: Vec<f32>,
        /// Per-component value of code 0.
        offset: Vec<f32>,
    },
    /// f16 values are the coefficients.
    Identity {
        /// Rank `K`.
        rank: usize,
    },
}

impl Dequantization {
    /// The dequantisation of stored coefficients.
    pub fn of(coefficients: &Coefficients) -> Self {
        match coefficients {
            Coefficients::U8Affine { scale, offset, .. } => Self::Affine {
                scale: scale.clone(),
                offset: offset.clone(),
            },
            Coefficients::F16 { rank, .. } => Self::Identity { rank: *rank },
        }
    }

    /// Rank `K`.
    pub fn rank(&self) -> usize {
        match self {
            Self::Affine { scale, .. } => scale.len(),
            Self::Identity { rank } => *rank,
        }
    }

    /// Per component `[o_k, s_k]`, `c_k = o_k + s_k · stored`: `[0, 1]` for f16 values.
    pub fn offset_scale(&self) -> Vec<[f32; 2]> {
        match self {
            Self::Affine { scale, offset } => offset.iter().zip(scale).map(|(&o, &s)| [o, s]).collect(),
            Self::Identity { rank } => vec![[0.0, 1.0]; *rank],
        }
    }
}

/// Folds 8-bit affine parameters into the projected lighting: with `c_k = o_k + s_k q_k`,
/// `mean' = P_mean + Σ o_k P_k` and `light'_k = s_k P_k` (sums in `f64`); f16 coefficients
/// pass through. `rank` components are used (clamped to what exists); for
/// [`RelightView::Component`] only that one, without the mean.
pub fn fold_light(
    light: &ProjectedLight,
    dequantization: &Dequantization,
    rank: usize,
    view: RelightView,
) -> FoldedLight {
    let stored = dequantization.rank().min(light.rank());
    let (mut mean, count, only) = match view {
        RelightView::Shaded => (light.mean_rgb.map(f64::from), rank.min(stored), None),
        RelightView::Component(k) => ([0.0; 3], (k + 1).min(stored), Some(k)),
    };
    let mut components = Vec::with_capacity(count);
    for k in 0..count {
        let p = light.component_rgb[k];
        if only.is_some_and(|o| o != k) {
            components.push([0.0; 4]);
            continue;
        }
        match dequantization {
            Dequantization::Affine { scale, offset } => {
                for c in 0..3 {
                    mean[c] += f64::from(offset[k]) * f64::from(p[c]);
                }
                let s = f64::from(scale[k]);
                components.push([
                    (s * f64::from(p[0])) as f32,
                    (s * f64::from(p[1])) as f32,
                    (s * f64::from(p[2])) as f32,
                    0.0,
                ]);
            }
            Dequantization::Identity { .. } => components.push([p[0], p[1], p[2], 0.0]),
        }
    }
    FoldedLight {
        mean_rgb: mean.map(|m| m as f32),
        components,
    }
}

/// Texels along a fine density atlas slot's edge for factor `F`: the brick's `8F` fine
/// voxels plus a 1-fine-voxel apron on each side.
pub fn fine_slot_texels(factor: u32) -> u32 {
    BRICK_SIZE as u32 * factor + 2
}

/// The fine density atlas (format 1.4, [`FineDensity`]): σ of the fine voxels as f16 bits,
/// one slot of [`fine_slot_texels`]`³` texels per atlas slot, at the atlas's slot
/// placement `layout` (slot `s` at slot coordinates `layout.slot_coords(s)`, texel
/// extent `layout.texels_for_slot_edge(fine_slot_texels(F))`, x fastest). Texel
/// `m + 1` (`m ∈ [−1, 8F]³`) of the slot of brick cell `c` (a present brick or a halo
/// cell, [`Indirection`]) holds fine voxel `8F·c + m` of the whole grid: its own brick's
/// inside, the neighbours' border fine voxels in the apron, 0 where that brick is
/// missing (or outside the grid). Hardware trilinear filtering of a point in the cell's
/// box then equals the reference's trilinear over the fine lattice
/// (`nelf_render::FineGrid`), as for the atlas (module docs). Built once at load: no
/// lighting changes it.
pub fn fine_density_atlas(
    layout: &AtlasLayout,
    indirection: &Indirection,
    grid_bricks: [u32; 3],
    bricks: usize,
    fine: &FineDensity,
) -> Result<Vec<u16>, ViewerError> {
    let per_brick = fine.voxels_per_brick();
    if fine.values.len() != bricks * per_brick {
        return Err(ViewerError::BadSetting(format!(
            "{} fine density values for {bricks} bricks of {per_brick} fine voxels",
            fine.values.len()
        )));
    }
    let cells = grid_bricks.iter().map(|&n| n as usize).product::<usize>();
    if indirection.entries.len() != cells {
        return Err(ViewerError::BadSetting(format!(
            "indirection of {} cells for a grid of {grid_bricks:?} bricks",
            indirection.entries.len()
        )));
    }
    let slot_texels = fine_slot_texels(fine.factor);
    let extent = layout.texels_for_slot_edge(slot_texels);
    let total = extent.iter().map(|&n| u64::from(n)).product::<u64>();
    let total = usize::try_from(total)
        .ok()
        .filter(|&t| t <= isize::MAX as usize / 2)
        .ok_or_else(|| ViewerError::TooLarge(format!("a fine density atlas of {extent:?} texels")))?;
    let [ex, ey, _] = extent.map(|n| n as usize);
    let mut texels = vec![0u16; total];
    let edge = fine.brick_edge() as i64;
    let n = grid_bricks.map(i64::from);
    // Per fine coordinate m ∈ [−1, 8F] of a slot: the neighbouring cell's offset (−1, 0,
    // +1) and the fine voxel's coordinate inside that cell.
    let split = |m: i64| -> (usize, usize) {
        if m < 0 {
            (0, (m + edge) as usize)
        } else if m >= edge {
            (2, (m - edge) as usize)
        } else {
            (1, m as usize)
        }
    };
    let axis: Vec<(usize, usize)> = (-1..=edge).map(split).collect();
    let edge_u = edge as usize;
    for (slot, cell) in indirection.slot_cells.iter().enumerate() {
        // The present bricks among the 3³ cells around this one (index dx + 3dy + 9dz,
        // offsets shifted by 1).
        let near: [Option<usize>; 27] = std::array::from_fn(|d| {
            let c = [d % 3, (d / 3) % 3, d / 9].map(|o| o as i64 - 1);
            let g: [i64; 3] = std::array::from_fn(|a| i64::from(cell[a]) + c[a]);
            if (0..3).any(|a| g[a] < 0 || g[a] >= n[a]) {
                return None;
            }
            let entry = indirection.entries[(g[0] + n[0] * (g[1] + n[1] * g[2])) as usize];
            entry.checked_sub(1).map(|s| s as usize).filter(|&s| s < bricks)
        });
        if near.iter().all(Option::is_none) {
            continue;
        }
        let origin = layout
            .slot_coords(slot as u32)
            .map(|s| (s * slot_texels) as usize);
        for (tz, &(dz, lz)) in axis.iter().enumerate() {
            for (ty, &(dy, ly)) in axis.iter().enumerate() {
                let row = origin[0] + ex * (origin[1] + ty + ey * (origin[2] + tz));
                for (tx, &(dx, lx)) in axis.iter().enumerate() {
                    if let Some(brick) = near[dx + 3 * dy + 9 * dz] {
                        let value = fine.values[brick * per_brick + lx + edge_u * (ly + edge_u * lz)];
                        texels[row + tx] = value.to_bits();
                    }
                }
            }
        }
    }
    Ok(texels)
}

/// Per stored voxel (brick-major, file order), the largest σ of its `F³` fine voxels:
/// what [`march_grid`] reads of a fine density. A trilinear sample of the fine lattice
/// has σ > 0 only within one fine voxel (`1/F` voxel) of a fine voxel with σ > 0, which
/// lies within `½ − 1/(2F)` of its voxel's centre: within 1 voxel of a voxel marked
/// here, so the march grid's distances stay safe for it.
pub fn fine_density_per_voxel(fine: &FineDensity, bricks: usize) -> Result<Vec<half::f16>, ViewerError> {
    let per_brick = fine.voxels_per_brick();
    if fine.values.len() != bricks * per_brick {
        return Err(ViewerError::BadSetting(format!(
            "{} fine density values for {bricks} bricks of {per_brick} fine voxels",
            fine.values.len()
        )));
    }
    let f = fine.factor as usize;
    let edge = fine.brick_edge();
    let mut out = vec![half::f16::NEG_INFINITY; bricks * BRICK_VOXELS];
    for (b, values) in fine.values.chunks_exact(per_brick.max(1)).enumerate() {
        for (i, value) in values.iter().enumerate() {
            let (x, y, z) = (i % edge, (i / edge) % edge, i / (edge * edge));
            let voxel = b * BRICK_VOXELS + x / f + BRICK_SIZE * (y / f + BRICK_SIZE * (z / f));
            if value.to_f32() > out[voxel].to_f32() {
                out[voxel] = *value;
            }
        }
    }
    Ok(out)
}

/// Marker of an atlas texel that mirrors no stored voxel in [`atlas_sources`].
pub const NO_SOURCE: u32 = u32::MAX;

/// The stored voxel every atlas texel mirrors, for the CPU relight
/// ([`relight_atlas_cpu`]); fixed per asset, so computed once at load. Every texel of every
/// slot (present brick or halo cell: its 8³ voxels and the 1-voxel apron) mirrors the
/// grid voxel at its place, [`NO_SOURCE`] where no brick stores that voxel. Texels x
/// fastest, in the atlas's `layout.texels()` extent; `bricks` is the stored brick count.
pub fn atlas_sources(
    layout: &AtlasLayout,
    indirection: &Indirection,
    grid_bricks: [u32; 3],
    bricks: usize,
) -> Vec<u32> {
    let texels = layout.texels().map(|n| n as usize);
    let mut sources = vec![NO_SOURCE; texels[0] * texels[1] * texels[2]];
    let n = grid_bricks.map(i64::from);
    let brick = BRICK_SIZE as i64;
    for (slot, cell) in indirection.slot_cells.iter().enumerate() {
        for lz in -1..=brick as i32 {
            for ly in -1..=brick as i32 {
                for lx in -1..=brick as i32 {
                    let local = [lx, ly, lz];
                    let g: [i64; 3] =
                        std::array::from_fn(|a| i64::from(cell[a]) * brick + i64::from(local[a]));
                    let c = g.map(|x| x.div_euclid(brick));
                    if (0..3).any(|a| c[a] < 0 || c[a] >= n[a]) {
                        continue;
                    }
                    let entry = indirection.entries[(c[0] + n[0] * (c[1] + n[1] * c[2])) as usize];
                    let Some(source) = entry.checked_sub(1).map(|s| s as usize).filter(|&s| s < bricks)
                    else {
                        continue;
                    };
                    let l = g.map(|x| x.rem_euclid(brick) as usize);
                    let t = layout.texel_of(slot as u32, local).map(|x| x as usize);
                    sources[t[0] + texels[0] * (t[1] + texels[1] * t[2])] =
                        (source * BRICK_VOXELS + l[0] + 8 * l[1] + 64 * l[2]) as u32;
                }
            }
        }
    }
    sources
}

/// The relit atlas computed on the CPU, texel for texel what the relight pass
/// (`relight.wgsl`, `relight`) writes, for devices that cannot run it (no compute
/// shaders: WebGL2). Every stored voxel is shaded as `shade_voxel` does (`folded`'s mean
/// plus its codes or halves times `folded`'s per-code radiance, `|rgb|` with
/// `magnitude`, the component view), with its density in alpha; then every texel takes
/// the value of the voxel `sources` ([`atlas_sources`]) names, 0 for [`NO_SOURCE`].
pub fn relight_atlas_cpu(
    sources: &[u32],
    coefficients: &PackedCoefficients,
    density: &[half::f16],
    folded: &FoldedLight,
    magnitude: bool,
) -> Vec<[half::f16; 4]> {
    let voxels = density.len();
    let used = folded.components.len();
    let light = |k: usize| folded.components.get(k).copied().unwrap_or([0.0; 4]);
    let words_used = if coefficients.encoding == 1 {
        used.div_ceil(4)
    } else {
        used.div_ceil(2)
    };
    let mut values = vec![[half::f16::ZERO; 4]; voxels];
    for (v, value) in values.iter_mut().enumerate() {
        let mut rgb = folded.mean_rgb;
        for q in 0..words_used {
            let word = coefficients.words.get(q * voxels + v).copied().unwrap_or(0);
            if coefficients.encoding == 1 {
                for j in 0..4 {
                    let code = ((word >> (8 * j)) & 0xff) as f32;
                    let l = light(4 * q + j);
                    rgb = std::array::from_fn(|c| rgb[c] + code * l[c]);
                }
            } else {
                for j in 0..2 {
                    let x = half::f16::from_bits((word >> (16 * j)) as u16).to_f32();
                    let l = light(2 * q + j);
                    rgb = std::array::from_fn(|c| rgb[c] + x * l[c]);
                }
            }
        }
        if magnitude {
            rgb = rgb.map(f32::abs);
        }
        *value = [rgb[0], rgb[1], rgb[2], density[v].to_f32()].map(half::f16::from_f32);
    }
    sources
        .iter()
        .map(|&v| values.get(v as usize).copied().unwrap_or([half::f16::ZERO; 4]))
        .collect()
}

/// Lobe count the view lighting buffer and the shaders have room for: the 9 real
/// spherical harmonics of degrees 0–2, the most [`nelf_format::conventions::VIEW_HARMONICS`]
/// allows.
pub const MAX_LOBES: usize = 9;
const _: () = assert!(nelf_format::conventions::VIEW_HARMONICS <= MAX_LOBES);

/// The view part's lighting with its coefficient dequantisation folded in, as
/// `relight.wgsl`'s `relight_lobes` reads it: entry `j <` [`MAX_LOBES`] is lobe `j`'s mean
/// colour, entry `MAX_LOBES + n` the per-code colour of view coefficient `n = j·K_v + i`.
///
/// Lobe `j`'s colour is `c_j = Σ_i d_ji P^v_i` (`P^v` from
/// [`nelf_render::project_view_light`]); with 8-bit codes `d_n = o_n + s_n q_n`, so
/// `mean_j = Σ_i o_n P^v_i` and `light_n = s_n P^v_i` (sums in `f64`); f16 values pass
/// through (`mean_j = 0`, `light_n = P^v_i`). `dequantization` is the view coefficients'
/// (rank `J·K_v`); `lobes` is `J`.
pub fn fold_view_light(
    view_light: &[[f32; 3]],
    dequantization: &Dequantization,
    lobes: usize,
) -> Vec<[f32; 4]> {
    let rank = view_light.len();
    let codes = dequantization
        .rank()
        .min(lobes.min(MAX_LOBES) * rank)
        .min(nelf_format::conventions::LT_DIM);
    let mut out = vec![[0.0f32; 4]; MAX_LOBES + nelf_format::conventions::LT_DIM];
    let mut means = [[0.0f64; 3]; MAX_LOBES];
    for n in 0..codes {
        let (j, p) = (n / rank, view_light[n % rank]);
        match dequantization {
            Dequantization::Affine { scale, offset } => {
                let (o, s) = (f64::from(offset[n]), f64::from(scale[n]));
                for c in 0..3 {
                    means[j][c] += o * f64::from(p[c]);
                    out[MAX_LOBES + n][c] = (s * f64::from(p[c])) as f32;
                }
            }
            Dequantization::Identity { .. } => out[MAX_LOBES + n] = [p[0], p[1], p[2], 0.0],
        }
    }
    for (o, m) in out.iter_mut().zip(means) {
        *o = [m[0] as f32, m[1] as f32, m[2] as f32, 0.0];
    }
    out
}

/// Bytes of GPU memory an asset occupies.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct GpuMemory {
    /// The relit RGBA16F atlas (with aprons and unused slots).
    pub atlas_bytes: u64,
    /// Packed coefficients.
    pub coefficient_bytes: u64,
    /// Packed densities.
    pub density_bytes: u64,
    /// March grid (empty-space skipping and slots; [`MarchGrid`]).
    pub march_grid_bytes: u64,
    /// Where the relight and view passes write each brick's voxels (8 blocks of 8 slots
    /// per brick).
    pub neighbour_bytes: u64,
    /// A view-dependent asset's view part (its packed coefficients, the per-voxel lobe
    /// buffer and uniforms) or a reflection asset's reflection part (its codes, the lobe
    /// buffer, the filtered environment's table and uniforms); 0 for a view-independent
    /// asset.
    pub view_bytes: u64,
    /// Uniforms and the lighting buffer.
    pub other_bytes: u64,
    /// The fine density atlas (format 1.4; R16F, with aprons and unused slots); 0 for an
    /// asset without one.
    pub fine_density_bytes: u64,
}

impl GpuMemory {
    /// Sum of all parts.
    pub fn total(&self) -> u64 {
        self.atlas_bytes
            + self.fine_density_bytes
            + self.coefficient_bytes
            + self.density_bytes
            + self.march_grid_bytes
            + self.neighbour_bytes
            + self.view_bytes
            + self.other_bytes
    }
}

/// Voxels of `bricks` bricks.
pub fn voxel_count(bricks: usize) -> usize {
    bricks * BRICK_VOXELS
}

#[cfg(test)]
mod tests {
    use half::f16;
    use nelf_format::CoefficientEncoding;

    use super::*;

    #[test]
    fn march_grid_holds_chessboard_distances_and_slots() {
        // Three bricks in a 3×2×2 grid, a few dense voxels, the rest empty; brute force
        // over every pair of cubes at factor 1, and at factor 2 when textures are small.
        let grid = [3, 2, 2];
        let bricks = [[0u16, 0, 0], [2, 1, 0], [1, 1, 1]];
        let indirection = indirection_grid(grid, &bricks).unwrap();
        let mut density = vec![f16::ZERO; bricks.len() * BRICK_VOXELS];
        for (b, v) in [
            (0usize, 0usize),
            (0, 7 + 8 * 3),
            (1, 511),
            (2, 4 + 8 * 4 + 64 * 4),
        ] {
            density[b * BRICK_VOXELS + v] = f16::from_f32(2.5);
        }
        // A brick with σ = 0 everywhere counts as empty.
        for (max_dim, factor) in [(2048, 1u32), (16, 2)] {
            let field = march_grid(grid, &indirection, &bricks, &density, max_dim).unwrap();
            assert_eq!(field.factor, factor);
            let dims = field.dims.map(|d| d as i64);
            assert_eq!(field.dims, grid.map(|n| n * 8 / factor));
            let mut dense = Vec::new();
            for (b, cell) in bricks.iter().enumerate() {
                for v in 0..BRICK_VOXELS {
                    if density[b * BRICK_VOXELS + v].to_f32() > 0.0 {
                        let local = [v % 8, (v / 8) % 8, v / 64];
                        dense.push(std::array::from_fn::<i64, 3, _>(|a| {
                            ((usize::from(cell[a]) * 8 + local[a]) / factor as usize) as i64
                        }));
                    }
                }
            }
            for z in 0..dims[2] {
                for y in 0..dims[1] {
                    for x in 0..dims[0] {
                        let want = dense
                            .iter()
                            .map(|d| (d[0] - x).abs().max((d[1] - y).abs()).max((d[2] - z).abs()))
                            .min()
                            .unwrap()
                            .min(255);
                        let texel = field.texels[(x + dims[0] * (y + dims[1] * z)) as usize];
                        assert_eq!(
                            i64::from(texel & 0xff),
                            want,
                            "cube {x},{y},{z} at factor {factor}"
                        );
                        let c = [x, y, z].map(|v| (v * i64::from(factor) / 8) as usize);
                        let entry = indirection.entries[c[0] + 3 * (c[1] + 2 * c[2])];
                        assert_eq!(texel >> MARCH_GRID_SLOT_SHIFT, entry);
                        // Where the march samples (nothing to skip), there is a slot.
                        if want == 0 || (factor == 1 && want == 1) {
                            assert_ne!(entry, 0, "cube {x},{y},{z} at factor {factor}");
                        }
                    }
                }
            }
        }
        // No dense voxel at all: every cube at the cap; a density per voxel is required.
        let empty = vec![f16::ZERO; bricks.len() * BRICK_VOXELS];
        let field = march_grid(grid, &indirection, &bricks, &empty, 2048).unwrap();
        assert!(field.texels.iter().all(|&t| t & 0xff == 255));
        assert!(march_grid(grid, &indirection, &bricks, &empty[1..], 2048).is_err());
    }

    #[test]
    fn fine_density_atlas_mirrors_every_fine_voxel_at_its_place() {
        // Three bricks in a 3×2×2 grid (with halo cells around them), distinct values per
        // fine voxel; brute force over every texel of every slot, at both factors.
        let grid = [3u32, 2, 2];
        let bricks = [[0u16, 0, 0], [2, 1, 0], [1, 1, 1]];
        let indirection = indirection_grid(grid, &bricks).unwrap();
        for factor in [2u32, 4] {
            let edge = 8 * i64::from(factor);
            let per_brick = (edge * edge * edge) as usize;
            let values: Vec<f16> = (0..bricks.len() * per_brick)
                .map(|i| f16::from_f32(1.0 + (i % 1999) as f32))
                .collect();
            let fine = FineDensity { factor, values };
            let slot_texels = fine_slot_texels(factor);
            assert_eq!(i64::from(slot_texels), edge + 2);
            let layout = AtlasLayout::for_slot_edge(indirection.slot_cells.len(), 2048, slot_texels).unwrap();
            let texels = fine_density_atlas(&layout, &indirection, grid, bricks.len(), &fine).unwrap();
            let extent = layout.texels_for_slot_edge(slot_texels).map(|n| n as usize);
            assert_eq!(texels.len(), extent.iter().product::<usize>());
            let mut nonzero = 0;
            for (slot, cell) in indirection.slot_cells.iter().enumerate() {
                let origin = layout.slot_coords(slot as u32);
                for mz in -1..=edge {
                    for my in -1..=edge {
                        for mx in -1..=edge {
                            let g = [mx, my, mz]
                                .iter()
                                .zip(cell)
                                .map(|(&m, &c)| i64::from(c) * edge + m)
                                .collect::<Vec<_>>();
                            let brick = bricks
                                .iter()
                                .position(|b| (0..3).all(|a| i64::from(b[a]) == g[a].div_euclid(edge)));
                            let want = brick.map_or(0, |b| {
                                let l = g.iter().map(|v| v.rem_euclid(edge)).collect::<Vec<_>>();
                                fine.values[b * per_brick + (l[0] + edge * (l[1] + edge * l[2])) as usize]
                                    .to_bits()
                            });
                            let t: Vec<usize> = [mx, my, mz]
                                .iter()
                                .enumerate()
                                .map(|(a, &m)| (i64::from(origin[a] * slot_texels) + m + 1) as usize)
                                .collect();
                            let got = texels[t[0] + extent[0] * (t[1] + extent[1] * t[2])];
                            assert_eq!(got, want, "F {factor} slot {slot} at {mx},{my},{mz}");
                            nonzero += usize::from(got != 0);
                        }
                    }
                }
            }
            // Every fine voxel is in its own slot, and the aprons repeat some.
            assert!(nonzero > fine.values.len(), "{nonzero}");
            // Per voxel, the largest of its fine voxels.
            let per_voxel = fine_density_per_voxel(&fine, bricks.len()).unwrap();
            assert_eq!(per_voxel.len(), bricks.len() * BRICK_VOXELS);
            let f = factor as usize;
            for (v, got) in per_voxel.iter().enumerate() {
                let (b, x, y, z) = (v / 512, v % 8, (v / 8) % 8, (v / 64) % 8);
                let mut want = f32::NEG_INFINITY;
                for (i, value) in fine.values[b * per_brick..(b + 1) * per_brick].iter().enumerate() {
                    let e = 8 * f;
                    if (i % e) / f == x && ((i / e) % e) / f == y && (i / (e * e)) / f == z {
                        want = want.max(value.to_f32());
                    }
                }
                assert_eq!(got.to_f32(), want, "voxel {v}");
            }
            // A count that does not match the bricks is an error.
            let short = FineDensity {
                factor,
                values: fine.values[1..].to_vec(),
            };
            assert!(fine_density_atlas(&layout, &indirection, grid, bricks.len(), &short).is_err());
            assert!(fine_density_per_voxel(&short, bricks.len()).is_err());
        }
        // Larger slots fit fewer per axis: the same slot count fails where the atlas's fit.
        assert!(AtlasLayout::for_bricks(400, 256).is_ok());
        assert!(AtlasLayout::for_slot_edge(400, 256, fine_slot_texels(4)).is_err());
        let layout = AtlasLayout::for_slot_edge(100, 256, fine_slot_texels(4)).unwrap();
        assert!(
            layout
                .texels_for_slot_edge(fine_slot_texels(4))
                .iter()
                .all(|&t| t <= 256)
        );
        assert_eq!(layout.texels(), layout.texels_for_slot_edge(SLOT_TEXELS));
    }

    #[test]
    fn layout_holds_every_brick_once_within_limits() {
        for bricks in [1usize, 5, 64, 600, 4097, 100_000] {
            let layout = AtlasLayout::for_bricks(bricks, 2048).unwrap();
            let t = layout.texels();
            assert!(
                t.iter().all(|&v| v <= 2048 && v % SLOT_TEXELS == 0),
                "{bricks}: {t:?}"
            );
            let capacity = (t[0] / 10) as usize * (t[1] / 10) as usize * (t[2] / 10) as usize;
            assert!(
                capacity >= bricks && capacity < 4 * bricks + 8,
                "{bricks}: capacity {capacity}"
            );
            let mut seen = std::collections::HashSet::new();
            for s in 0..bricks as u32 {
                let c = layout.slot_coords(s);
                assert!((0..3).all(|a| c[a] < t[a] / 10));
                assert!(seen.insert(c));
            }
            assert_eq!(layout.texel_of(0, [-1, -1, -1]), [0, 0, 0]);
        }
        assert!(AtlasLayout::for_bricks(10_000_000, 2048).is_err());
        assert!(AtlasLayout::for_bricks(10, 9).is_err());
    }

    #[test]
    fn indirection_marks_bricks_and_halos() {
        let grid = [7u32, 5, 6];
        let bricks = [[1u16, 1, 1], [5, 3, 4]];
        let ind = indirection_grid(grid, &bricks).unwrap();
        assert_eq!(ind.entries.len(), 7 * 5 * 6);
        assert_eq!(&ind.slot_cells[..2], &[[1, 1, 1], [5, 3, 4]]);
        let mut halos = 0;
        for z in 0..6i32 {
            for y in 0..5i32 {
                for x in 0..7i32 {
                    let entry = ind.entries[(x + 7 * (y + 5 * z)) as usize];
                    let chebyshev = |b: &[u16; 3]| {
                        (x - i32::from(b[0]))
                            .abs()
                            .max((y - i32::from(b[1])).abs())
                            .max((z - i32::from(b[2])).abs())
                    };
                    match bricks.iter().map(chebyshev).min().unwrap() {
                        0 => assert!(entry == 1 || entry == 2, "({x}, {y}, {z}): {entry:#x}"),
                        1 => {
                            halos += 1;
                            assert!(entry > 2);
                            let slot = entry - 1;
                            assert_eq!(ind.slot_cells[slot as usize], [x as u32, y as u32, z as u32]);
                        }
                        _ => assert_eq!(entry, 0, "({x}, {y}, {z})"),
                    }
                }
            }
        }
        assert_eq!(ind.halo_count(2), halos);
        assert_eq!(halos, 26 + 26);
        let none = indirection_grid([2, 2, 2], &[]).unwrap();
        assert!(none.entries.iter().all(|&e| e == 0));
        assert!(indirection_grid([65536, 65536, 2], &[]).is_err());
        assert!(indirection_grid([2, 2, 2], &[[5, 0, 0]]).is_err());
        // Neighbour blocks point at the cells around each brick, octant by octant.
        let blocks = neighbour_blocks(&ind, grid, &bricks);
        assert_eq!(blocks.len(), 2 * 8);
        for (b, brick) in bricks.iter().enumerate() {
            for octant in 0..8 {
                let block = blocks[b * 8 + octant];
                assert_eq!(block[0], b as u32);
                for (e, &slot) in block.iter().enumerate() {
                    let cell: [i32; 3] = std::array::from_fn(|a| {
                        let side = if octant >> a & 1 == 1 { 1 } else { -1 };
                        i32::from(brick[a]) + (e >> a & 1) as i32 * side
                    });
                    assert_ne!(slot, NO_SLOT, "every neighbour of an inner brick is a halo cell");
                    assert_eq!(ind.slot_cells[slot as usize], cell.map(|c| c as u32));
                }
            }
        }
        let edge = indirection_grid([2, 1, 1], &[[0, 0, 0]]).unwrap();
        let blocks = neighbour_blocks(&edge, [2, 1, 1], &[[0, 0, 0]]);
        // Upper-x octants (1, 3, 5, 7) reach the halo cell at x = 1 (entry 1); every other
        // cell but the brick's own (entry 0) is outside the grid.
        assert_eq!(blocks[1][..2], [0, 1]);
        assert!(blocks[1][2..].iter().all(|&s| s == NO_SLOT));
        assert_eq!(blocks.iter().flatten().filter(|&&s| s != NO_SLOT).count(), 8 + 4);
        let cells = pack_brick_cells(&[[1, 2, 3], [65535, 40000, 7]]);
        assert_eq!(cells, [[1 | 2 << 16, 3], [65535 | 40000 << 16, 7]]);
    }

    #[test]
    fn packing_round_trips_codes_and_halves() {
        let values: Vec<f32> = (0..5 * 7).map(|i| (i as f32 * 0.73).sin() * 3.0).collect();
        let q = Coefficients::quantize(&values, 5, CoefficientEncoding::U8Affine).unwrap();
        let p = pack_coefficients(&q);
        assert_eq!((p.words_per_voxel, p.encoding, p.words.len()), (2, 1, 14));
        let Coefficients::U8Affine { codes, .. } = &q else {
            panic!()
        };
        for (i, &code) in codes.iter().enumerate() {
            let (v, k) = (i / 5, i % 5);
            let word = p.words[(k / 4) * 7 + v];
            assert_eq!((word >> (8 * (k % 4))) & 0xff, u32::from(code));
        }
        let h = Coefficients::quantize(&values, 5, CoefficientEncoding::F16).unwrap();
        let p = pack_coefficients(&h);
        assert_eq!((p.words_per_voxel, p.encoding), (3, 2));
        let back = h.to_f32();
        for (i, want) in back.iter().enumerate() {
            let (v, k) = (i / 5, i % 5);
            let bits = (p.words[(k / 2) * 7 + v] >> (16 * (k % 2))) & 0xffff;
            assert_eq!(f16::from_bits(bits as u16).to_f32(), *want);
        }
        let d = pack_density(&[f16::from_f32(1.0), f16::from_f32(2.0), f16::from_f32(3.0)]);
        assert_eq!(d.len(), 2);
        assert_eq!(f16::from_bits((d[0] >> 16) as u16).to_f32(), 2.0);
        assert_eq!(f16::from_bits(d[1] as u16).to_f32(), 3.0);
    }

    #[test]
    fn folded_view_light_reproduces_reference_lobe_colours() {
        use nelf_format::ViewDependence;
        use nelf_format::conventions::{LT_DIM, VIEW_HARMONICS};
        let (lobes, rank, voxels) = (3usize, 4usize, 7usize);
        let values: Vec<f32> = (0..voxels * lobes * rank)
            .map(|i| (i as f32 * 0.91).sin() * 1.5 - 0.2)
            .collect();
        let view_light: Vec<[f32; 3]> = (0..rank)
            .map(|i| [0.5 - i as f32, 0.25 * i as f32, (i as f32).cos()])
            .collect();
        for encoding in [CoefficientEncoding::U8Affine, CoefficientEncoding::F16] {
            let coefficients = Coefficients::quantize(&values, lobes * rank, encoding).unwrap();
            let packed = pack_coefficients(&coefficients);
            let view = ViewDependence {
                lobes: vec![1.0; lobes * VIEW_HARMONICS],
                basis: vec![0.0; rank * LT_DIM],
                coefficients,
            };
            let want = nelf_render::voxel_lobe_radiance(&view, &view_light, voxels);
            let folded = fold_view_light(&view_light, &Dequantization::of(&view.coefficients), lobes);
            assert_eq!(folded.len(), MAX_LOBES + LT_DIM);
            for v in 0..voxels {
                for j in 0..lobes {
                    let mut got = folded[j];
                    for i in 0..rank {
                        let n = j * rank + i;
                        let code = if packed.encoding == 1 {
                            ((packed.words[(n / 4) * voxels + v] >> (8 * (n % 4))) & 0xff) as f32
                        } else {
                            let w = packed.words[(n / 2) * voxels + v] >> (16 * (n % 2));
                            f16::from_bits((w & 0xffff) as u16).to_f32()
                        };
                        for c in 0..3 {
                            got[c] += code * folded[MAX_LOBES + n][c];
                        }
                    }
                    for c in 0..3 {
                        let w = want[v * lobes + j][c];
                        assert!(
                            (got[c] - w).abs() < 1e-5 * (1.0 + w.abs()),
                            "{encoding:?} voxel {v} lobe {j}: {got:?} vs {:?}",
                            want[v * lobes + j]
                        );
                    }
                }
            }
            // Entries past the codes are zero.
            assert!(folded[lobes..MAX_LOBES].iter().all(|m| *m == [0.0; 4]));
            assert!(folded[MAX_LOBES + lobes * rank..].iter().all(|m| *m == [0.0; 4]));
        }
    }

    #[test]
    fn folded_light_reproduces_reference_radiance() {
        let values: Vec<f32> = (0..4 * 9).map(|i| (i as f32 * 1.37).cos() * 2.0 + 0.5).collect();
        let light = ProjectedLight {
            mean_rgb: [0.3, 0.2, 0.1],
            component_rgb: vec![
                [1.0, -0.5, 0.25],
                [0.1, 0.2, 0.3],
                [-1.0, 0.0, 2.0],
                [0.5, 0.5, 0.5],
            ],
        };
        for encoding in [CoefficientEncoding::U8Affine, CoefficientEncoding::F16] {
            let q = Coefficients::quantize(&values, 4, encoding).unwrap();
            let packed = pack_coefficients(&q);
            for rank in [0usize, 2, 4] {
                let folded = fold_light(&light, &Dequantization::of(&q), rank, RelightView::Shaded);
                assert_eq!(folded.components.len(), rank);
                let mut c = vec![0.0f32; 4];
                for v in 0..9 {
                    q.voxel_f32(v, &mut c);
                    let want = light.radiance(&c[..rank]);
                    let mut got = folded.mean_rgb;
                    for (k, comp) in folded.components.iter().enumerate() {
                        let code = if packed.encoding == 1 {
                            ((packed.words[v] >> (8 * k)) & 0xff) as f32
                        } else {
                            let w = packed.words[(k / 2) * 9 + v] >> (16 * (k % 2));
                            f16::from_bits((w & 0xffff) as u16).to_f32()
                        };
                        for ch in 0..3 {
                            got[ch] += code * comp[ch];
                        }
                    }
                    for ch in 0..3 {
                        assert!(
                            (got[ch] - want[ch]).abs() < 1e-5,
                            "{encoding:?} rank {rank}: {got:?} vs {want:?}"
                        );
                    }
                }
            }
            // A single component's view: c_k · P_k only.
            let only = fold_light(&light, &Dequantization::of(&q), 4, RelightView::Component(2));
            assert_eq!(only.components.len(), 3);
            assert_eq!(only.components[0], [0.0; 4]);
            let mut c = vec![0.0f32; 4];
            q.voxel_f32(0, &mut c);
            let code0 = match &q {
                Coefficients::U8Affine { codes, .. } => f32::from(codes[2]),
                Coefficients::F16 { values, .. } => values[2].to_f32(),
            };
            let got = only.mean_rgb[2] + code0 * only.components[2][2];
            assert!((got - c[2] * 2.0).abs() < 1e-5);
        }
    }
}
