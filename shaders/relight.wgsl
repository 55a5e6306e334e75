// relight.wgsl — the relight pass (compute), run once per lighting change.
//
// The lighting, projected onto the asset's PCA basis on the CPU
// (nelf_render::project_light: P_mean and P_k, K × 3 numbers), arrives with the
// coefficient dequantisation folded in: for 8-bit affine codes c_k = o_k + s_k·q_k,
//   radiance = (P_mean + Σ_k o_k P_k) + Σ_k q_k (s_k P_k) = light_mean + Σ_k q_k light[k],
// and for f16 coefficients light_mean = P_mean, light[k] = P_k, q_k = c_k. Shading is
// linear in T = mean + Σ c_k B_k, so this equals shading every sample (DESIGN.md).
//
// One invocation per stored voxel (brick b, local l ∈ [0, 8)³): its K-term dot product,
// with its density, is written to every atlas texel that holds it — its own slot at
// local l, and the apron (local l − 8d) of the slot of each neighbouring cell b + d,
// d ∈ {−1, 0, 1}³, that the voxel borders (a present brick or a halo cell; see
// viewer/src/atlas.rs). So a texel (slot s, local m ∈ [−1, 8]³) holds the voxel at global
// voxel coordinates 8·cell(s) + m — its own brick's inside, a neighbour's in the apron,
// and 0 where that brick is missing (never written: wgpu creates textures zeroed; the
// CPU reference counts missing voxels as 0) — so hardware trilinear filtering inside a
// slot equals the reference's trilinear across brick borders. rgb = radiance, a = σ
// (1/m). Each voxel is shaded once however many texels show it.

#import "common.wgsl"

// Mirrors `RelightParams` in viewer/src/shaders.rs.
struct RelightParams {
    // x_bits, y_bits of the slot packing; slot count (bricks + halos); components used (rank).
    atlas: vec4<u32>,
    // Grid extent in bricks (xyz); w: coefficient encoding, 1 = 8-bit affine, 2 = f16.
    grid_bricks: vec4<i32>,
    // x: stored rank K (coefficients per voxel); y: u32 words per voxel; z: 1 = show |rgb|.
    words: vec4<u32>,
    // Folded mean radiance (rgb).
    light_mean: vec4<f32>,
    // x: stored voxels; y: invocations per row of the dispatch (workgroups along x · 64).
    dispatch: vec4<u32>,
}

@group(0) @binding(0) var<uniform> params: RelightParams;
// Largest rank (LT_DIM = 384 lighting numbers per channel bound the PCA rank).
const MAX_RANK: u32 = 384u;

// Folded per-component radiance (rgb in xyz); entries from the rank used up to the next
// multiple of 4 are 0, so whole words of codes can be applied.
@group(0) @binding(1) var<uniform> light: array<vec4<f32>, MAX_RANK>;
// Coefficients, word-major: word q of voxel v at q · voxels + v; 4 codes (u8) or 2
// halves (f16) per word (neighbouring invocations read neighbouring words).
@group(0) @binding(2) var<storage, read> coefficients: array<u32>;
// Density σ (1/m) as f16, two voxels per word.
@group(0) @binding(3) var<storage, read> density: array<u32>;
// Per present brick, 27 slots: that of cell b + d for d = (dx, dy, dz) ∈ {−1, 0, 1}³ at
// index (dx + 1) + 3 (dy + 1) + 9 (dz + 1) (13: its own), or NO_SLOT.
@group(0) @binding(4) var<storage, read> neighbour_slots: array<u32>;
@group(0) @binding(5) var atlas: texture_storage_3d<rgba16float, write>;

const NO_SLOT: u32 = 0xffffffffu;

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

// Σ_k q_k · light[k] over the components used, a word (4 codes or 2 halves) at a time.
fn shade_voxel(voxel: u32) -> vec3<f32> {
    let voxels = params.dispatch.x;
    let used = params.atlas.w;
    var rgb = params.light_mean.xyz;
    if params.grid_bricks.w == 1 {
        for (var q = 0u; q < (used + 3u) / 4u; q++) {
            let word = coefficients[q * voxels + voxel];
            let k = 4u * q;
            rgb += f32(word & 0xffu) * light[k].xyz + f32((word >> 8u) & 0xffu) * light[k + 1u].xyz
                + f32((word >> 16u) & 0xffu) * light[k + 2u].xyz + f32(word >> 24u) * light[k + 3u].xyz;
        }
    } else {
        for (var q = 0u; q < (used + 1u) / 2u; q++) {
            let word = coefficients[q * voxels + voxel];
            let k = 2u * q;
            rgb += half_of(word, 0u) * light[k].xyz + half_of(word, 1u) * light[k + 1u].xyz;
        }
    }
    return rgb;
}

fn voxel_density(voxel: u32) -> f32 {
    return half_of(density[voxel >> 1u], voxel);
}

@compute @workgroup_size(64, 1, 1)
fn relight(@builtin(global_invocation_id) gid: vec3<u32>) {
    let v = gid.x + gid.y * params.dispatch.y;
    if gid.x >= params.dispatch.y || v >= params.dispatch.x {
        return;
    }
    var rgb = shade_voxel(v);
    if params.words.z == 1u {
        rgb = abs(rgb);
    }
    let value = vec4<f32>(rgb, voxel_density(v));
    let brick = v / 512u;
    let local = vec3<i32>(vec3<u32>(v & 7u, (v >> 3u) & 7u, (v >> 6u) & 7u));
    // Neighbours whose apron holds this voxel: d_a = −1 where l_a = 0, +1 where l_a = 7.
    let low = select(vec3<i32>(0), vec3<i32>(-1), local == vec3<i32>(0));
    let high = select(vec3<i32>(0), vec3<i32>(1), local == vec3<i32>(BRICK - 1));
    let packing = SlotPacking(params.atlas.x, params.atlas.y);
    for (var dz = low.z; dz <= high.z; dz++) {
        for (var dy = low.y; dy <= high.y; dy++) {
            for (var dx = low.x; dx <= high.x; dx++) {
                let slot = neighbour_slots[brick * 27u + u32((dx + 1) + 3 * (dy + 1) + 9 * (dz + 1))];
                if slot != NO_SLOT {
                    let d = vec3<i32>(dx, dy, dz);
                    textureStore(atlas, slot_coords(slot, packing) * SLOT + local - d * BRICK + vec3<i32>(1), value);
                }
            }
        }
    }
}
