// common.wgsl — helpers shared by every pass (imported with `#import "common.wgsl"`,
// see viewer/src/shaders.rs; never copied).
//
// * Brick atlas addressing: bricks (and halo cells) live in slots of 10³ texels (8³
//   voxels + a 1-voxel apron on every side), packed with power-of-two slot counts along
//   x and y, so slot coordinates are bit operations.
// * Indirection grid: one u32 per brick cell: a present brick's or a halo cell's slot,
//   or a far cell's distance to the nearest present brick (see `FAR_FLAG`).
// * Full-screen triangle, ray–box slab test, hashing for jitter, ACES (Narkowicz 2015 fit) tone mapping,
//   and the sRGB transfer function (IEC 61966-2-1).

// Voxels along a brick edge (SPEC.md).
const BRICK: i32 = 8;
// Texels along an atlas slot edge: the brick plus a 1-voxel apron on each side.
const SLOT: i32 = 10;

// How the atlas packs slots: `x_bits`/`y_bits` are log2 of the slot counts along x and
// y; slots fill x fastest, then y, then z. Mirrors `AtlasLayout` in viewer/src/atlas.rs.
struct SlotPacking {
    x_bits: u32,
    y_bits: u32,
}

// Slot coordinates (in slots) of slot `index`.
fn slot_coords(index: u32, packing: SlotPacking) -> vec3<i32> {
    let x = index & ((1u << packing.x_bits) - 1u);
    let y = (index >> packing.x_bits) & ((1u << packing.y_bits) - 1u);
    let z = index >> (packing.x_bits + packing.y_bits);
    return vec3<i32>(vec3<u32>(x, y, z));
}

// Indirection entries (viewer/src/atlas.rs, `Indirection`, builds them), one per brick cell:
// * present brick: brick index + 1 (its slot is its index);
// * halo cell (missing, next to a present brick): HALO_FLAG | clear-face mask << 24 |
//   slot + 1 — its slot holds zeros and, in the apron, the neighbours' border voxels;
//   mask bit 2a (2a + 1): no present brick on the −a (+a) side;
// * far cell: FAR_FLAG | Chebyshev distance (≥ 2, in bricks) to the nearest present brick.
// 0 stands for outside the grid.
const FAR_FLAG: u32 = 0x80000000u;
const HALO_FLAG: u32 = 0x40000000u;
const SLOT_BITS: u32 = 0xffffffu;
const HALO_MASK_SHIFT: u32 = 24u;

// Indirection entry of brick cell `cell`; 0 outside the grid.
fn brick_entry(indirection: texture_3d<u32>, cell: vec3<i32>, grid_bricks: vec3<i32>) -> u32 {
    if any(cell < vec3<i32>(0)) || any(cell >= grid_bricks) {
        return 0u;
    }
    return textureLoad(indirection, cell, 0).x;
}

// Whether an indirection entry is a present brick (its voxels are stored).
fn is_present(entry: u32) -> bool {
    return entry != 0u && (entry & (FAR_FLAG | HALO_FLAG)) == 0u;
}

// Whether an indirection entry has an atlas slot (a present brick or a halo cell).
fn has_slot(entry: u32) -> bool {
    return entry != 0u && (entry & FAR_FLAG) == 0u;
}

// The atlas slot of an entry with one.
fn slot_of(entry: u32) -> u32 {
    return (entry & SLOT_BITS) - 1u;
}

// Full-screen triangle: vertex `index` (0, 1, 2) has uv (0, 0), (2, 0), (0, 2); uv (0, 0)
// is the top-left of the viewport and (1, 1) its bottom-right.
fn fullscreen_uv(index: u32) -> vec2<f32> {
    return vec2<f32>(f32((index << 1u) & 2u), f32(index & 2u));
}

// Clip-space position of a full-screen-triangle vertex with texture coordinates `uv`.
fn fullscreen_position(uv: vec2<f32>) -> vec4<f32> {
    return vec4<f32>(uv.x * 2.0 - 1.0, 1.0 - uv.y * 2.0, 0.0, 1.0);
}

// Reciprocal of a ray direction with zero components replaced by tiny ones of the
// same sign, so slab tests stay finite (WGSL does not promise IEEE infinities).
fn safe_inverse(d: vec3<f32>) -> vec3<f32> {
    let tiny = vec3<f32>(1e-30);
    let magnitude = max(abs(d), tiny);
    return select(vec3<f32>(1.0), vec3<f32>(-1.0), d < vec3<f32>(0.0)) / magnitude;
}

// Slab test of the line `o + t d` against the box [lo, hi]: (t_near, t_far).
fn ray_box(o: vec3<f32>, inv_d: vec3<f32>, lo: vec3<f32>, hi: vec3<f32>) -> vec2<f32> {
    let t0 = (lo - o) * inv_d;
    let t1 = (hi - o) * inv_d;
    let t_small = min(t0, t1);
    let t_large = max(t0, t1);
    return vec2<f32>(max(max(t_small.x, t_small.y), t_small.z), min(min(t_large.x, t_large.y), t_large.z));
}

// A 32-bit integer hash (Jarzynski & Olano 2020, "Hash functions for GPU rendering": PCG).
fn pcg_hash(v: u32) -> u32 {
    let state = v * 747796405u + 2891336453u;
    let word = ((state >> ((state >> 28u) + 4u)) ^ state) * 277803737u;
    return (word >> 22u) ^ word;
}

// A uniform number in [0, 1) for pixel `pixel` in frame `frame`.
fn jitter_01(pixel: vec2<u32>, frame: u32) -> f32 {
    let h = pcg_hash(pixel.x ^ pcg_hash(pixel.y ^ pcg_hash(frame)));
    return f32(h >> 8u) * (1.0 / 16777216.0);
}

// ACES filmic tone curve, Narkowicz's fit, input pre-scaled by 0.6 so 1.0 maps near 0.8.
fn tonemap_aces(x: vec3<f32>) -> vec3<f32> {
    let v = max(x, vec3<f32>(0.0)) * 0.6;
    return clamp((v * (2.51 * v + 0.03)) / (v * (2.43 * v + 0.59) + 0.14), vec3<f32>(0.0), vec3<f32>(1.0));
}

// Linear → sRGB-encoded, per channel, for values in [0, 1].
fn linear_to_srgb(x: vec3<f32>) -> vec3<f32> {
    let c = clamp(x, vec3<f32>(0.0), vec3<f32>(1.0));
    let low = c * 12.92;
    let high = 1.055 * pow(c, vec3<f32>(1.0 / 2.4)) - 0.055;
    return select(high, low, c <= vec3<f32>(0.0031308));
}
