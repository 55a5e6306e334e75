// common.wgsl — helpers shared by every pass (imported with `#import "common.wgsl"`,
// see render/src/wgsl.rs; never copied).
//
// * Brick atlas addressing: bricks (and halo cells) live in slots of 10³ texels (8³
//   voxels + a 1-voxel apron on every side), packed with power-of-two slot counts along
//   x and y, so slot coordinates are bit operations.
// * March grid: per cube of voxels, the distance to σ > 0 and the slot of its brick cell.
// * Writing a voxel into the atlas: the texels (own slot and neighbours' aprons) that
//   hold it, from its brick's neighbour block (the store itself, which names the atlas
//   binding, is atlas_store.wgsl's); shared by the relight, view and reflect passes.
// * f16 ↔ f32 by hand, the view harmonics of format 1.2 and the per-voxel lobe buffer layout
//   the relight pass writes for the view and reflect passes.
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

// The march grid (viewer/src/atlas.rs, `MarchGrid`): per cube of f³ voxels, bits 0–7 the
// Chebyshev distance in cubes to the nearest cube with σ > 0 (capped at 255), bits 8–31
// the atlas slot + 1 of the brick cell holding the cube (a present brick or a halo cell;
// 0 for none).
const MARCH_GRID_SLOT_SHIFT: u32 = 8u;

// Brick-cell coordinates of a stored brick, packed by viewer/src/atlas.rs
// (`pack_brick_cells`): (x | y << 16, z).
fn brick_cell(packed: vec2<u32>) -> vec3<i32> {
    return vec3<i32>(vec3<u32>(packed.x & 0xffffu, packed.x >> 16u, packed.y));
}

// Local coordinates (x fastest) of stored voxel `voxel` within its brick (voxel / 512).
fn voxel_local(voxel: u32) -> vec3<i32> {
    return vec3<i32>(vec3<u32>(voxel & 7u, (voxel >> 3u) & 7u, (voxel >> 6u) & 7u));
}

// Neighbour blocks (viewer/src/atlas.rs, `neighbour_blocks`, builds them): per present
// brick and octant o of its voxels (bit a set: local_a ≥ 4), the atlas slots of the 2×2×2
// cells `cell + d` a voxel of that octant can border, d_a = e_a · s_a for entry
// e = e_x + 2 e_y + 4 e_z (e_a ∈ {0, 1}, s_a = +1 in the upper half, −1 in the lower;
// entry 0 is the brick's own slot), or NO_SLOT where that cell has none; two vec4<u32>
// per octant (entries 0–3, 4–7), octant-major per brick: vec4 index (8 b + o) · 2 + h.
const NO_SLOT: u32 = 0xffffffffu;

// The octant of local voxel coordinates (its index among a brick's 8 neighbour blocks).
fn voxel_octant(local: vec3<i32>) -> u32 {
    let upper = vec3<u32>(local >= vec3<i32>(BRICK / 2));
    return upper.x | (upper.y << 1u) | (upper.z << 2u);
}

// Writing a voxel of a present brick into the atlas (the relight and view passes): the
// texels that hold voxel `local` ∈ [0, 8)³ are its own slot's and the apron texel
// (local − 8d) of the slot of each neighbouring cell `cell + d` that the voxel borders
// (d_a = −1 where l_a = 0, +1 where l_a = 7) and that has a slot (a present brick or a
// halo cell, viewer/src/atlas.rs). So a texel (slot s, local m ∈ [−1, 8]³) holds the
// voxel at global voxel coordinates 8·cell(s) + m — its own brick's inside, a
// neighbour's in the apron, and 0 where that brick is missing (never written: wgpu
// creates textures zeroed; the CPU reference counts missing voxels as 0) — so hardware
// trilinear filtering inside a slot equals the reference's trilinear across brick
// borders. A pass writes a voxel's value with atlas_store.wgsl's `store_voxel_texels`,
// which visits entries e ≤ voxel_border(local) of the voxel's neighbour block
// (`block_low`/`block_high`: entries 0–3 and 4–7).

// 1 on the axes where voxel `local` borders the neighbouring cell of its octant.
fn voxel_border(local: vec3<i32>) -> vec3<u32> {
    return vec3<u32>((local == vec3<i32>(0)) | (local == vec3<i32>(BRICK - 1)));
}

// The texel (xyz) holding voxel `local` in the slot of entry e = e_x + 2e_y + 4e_z of its
// neighbour block (e_a ≤ voxel_border(local)_a); w = 0 where that cell has no slot.
fn voxel_texel(
    block_low: vec4<u32>,
    block_high: vec4<u32>,
    packing: SlotPacking,
    local: vec3<i32>,
    e: vec3<u32>,
) -> vec4<i32> {
    let entry = e.x | (e.y << 1u) | (e.z << 2u);
    let slot = select(block_high, block_low, entry < 4u)[entry & 3u];
    let side = select(vec3<i32>(-1), vec3<i32>(1), local >= vec3<i32>(BRICK / 2));
    let d = vec3<i32>(e) * side;
    return vec4<i32>(slot_coords(slot, packing) * SLOT + local - d * BRICK + vec3<i32>(1), i32(slot != NO_SLOT));
}

// IEEE binary16 bits (low 16 bits of `bits`) to f32, exactly, for finite values (the
// reader has rejected non-finite ones); written out so no f16 capability is needed.
fn half_to_f32(bits: u32) -> f32 {
    let sign = (bits & 0x8000u) << 16u;
    let exponent = (bits >> 10u) & 0x1fu;
    let mantissa = bits & 0x3ffu;
    if exponent == 0u {
        // Zero or subnormal: mantissa · 2⁻²⁴.
        let magnitude = f32(mantissa) * 5.9604645e-8;
        return select(magnitude, -magnitude, sign != 0u);
    }
    return bitcast<f32>(sign | ((exponent + 112u) << 23u) | (mantissa << 13u));
}

// Half `index & 1` of the pair packed in `word` (low half first).
fn half_of(word: u32, index: u32) -> f32 {
    return half_to_f32((word >> (16u * (index & 1u))) & 0xffffu);
}

// f32 to IEEE binary16 bits, rounded to nearest (ties to even), as `half::f16::from_f32`:
// subnormal results kept, magnitudes past the f16 range (and NaN) give ±infinity. Written
// out, as `half_to_f32`, so no f16 capability is needed (`pack2x16float` needs one).
fn f32_to_half(x: f32) -> u32 {
    let bits = bitcast<u32>(x);
    let sign = (bits >> 16u) & 0x8000u;
    let exponent = i32((bits >> 23u) & 0xffu) - 112;
    let mantissa = bits & 0x7fffffu;
    if exponent >= 31 {
        return sign | 0x7c00u;
    }
    if exponent <= 0 {
        // Subnormal: the 24-bit significand shifted to units of 2⁻²⁴.
        if exponent < -10 {
            return sign;
        }
        let significand = mantissa | 0x800000u;
        let shift = u32(14 - exponent);
        let half = significand >> shift;
        let rest = significand & ((1u << shift) - 1u);
        let halfway = 1u << (shift - 1u);
        return sign | (half + u32(rest > halfway || (rest == halfway && (half & 1u) == 1u)));
    }
    let half = (u32(exponent) << 10u) | (mantissa >> 13u);
    let rest = mantissa & 0x1fffu;
    // A carry out of the mantissa rounds up into the exponent (to infinity at the top).
    return sign | (half + u32(rest > 0x1000u || (rest == 0x1000u && (half & 1u) == 1u)));
}

// Two f32 as binary16 halves in one word (`a` in the low half).
fn pack_halves(a: f32, b: f32) -> u32 {
    return f32_to_half(a) | (f32_to_half(b) << 16u);
}

// The real spherical harmonics of degrees 0, 1 and 2 at direction `omega` (normalised
// here; a zero vector gives zeros), in the order of nelf_format::conventions::view_harmonics
// (degree by degree, m = −l … l): [0] = (c₀, a·y, a·z, a·x), [1] = (b·xy, b·yz,
// c·(3z² − 1), b·xz), [2] = (b/2·(x² − y²), 0, 0, 0); c₀ = 1/(2√π), a = √(3/4π),
// b = √(15/4π), c = √(5/16π). (A convention without degree 0 gives y_0 weight 0:
// viewer/src/gpu/view.rs places lobe weights.)
fn view_harmonics(omega: vec3<f32>) -> array<vec4<f32>, 3> {
    let len = length(omega);
    if !(len > 0.0) {
        return array<vec4<f32>, 3>(vec4<f32>(0.0), vec4<f32>(0.0), vec4<f32>(0.0));
    }
    let w = omega / len;
    let c0 = 0.2820948;
    let a = 0.4886025;
    let b = 1.0925484;
    let c = 0.31539157;
    return array<vec4<f32>, 3>(
        vec4<f32>(c0, a * w.y, a * w.z, a * w.x),
        vec4<f32>(b * w.x * w.y, b * w.y * w.z, c * (3.0 * w.z * w.z - 1.0), b * w.x * w.z),
        vec4<f32>(0.5 * b * (w.x * w.x - w.y * w.y), 0.0, 0.0, 0.0),
    );
}

// The per-voxel lobe buffer of a view-dependent asset (written by relight.wgsl's
// `relight_lobes` once per lighting change, read by view.wgsl or reflect.wgsl per camera
// move; a reflection asset's has no lobes, J = 0: the radiance and σ only): per
// voxel, halves (f16) h = 0, 1, 2: the view-independent radiance (rgb), h = 3: σ (the
// stored f16 bits), h = 4 + 3j + c: lobe j's colour in channel c; two halves per u32
// word, low half first, word-major like the coefficients (word q of voxel v at
// q · voxels + v). Words per voxel for `lobes` lobes:
fn lobe_buffer_words(lobes: u32) -> u32 {
    return 2u + (3u * lobes + 1u) / 2u;
}

// The view-independent radiance (rgb) and σ (a) of a voxel from its first two lobe-buffer
// words (word 0 of the voxel: halves 0, 1; word 1: halves 2, 3).
fn lobe_buffer_radiance(word0: u32, word1: u32) -> vec4<f32> {
    return vec4<f32>(half_of(word0, 0u), half_of(word0, 1u), half_of(word1, 0u), half_of(word1, 1u));
}

// Largest lobe count (nelf_format::conventions::VIEW_HARMONICS, 9).
const MAX_LOBES: u32 = 9u;

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
