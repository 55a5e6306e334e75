// relight.wgsl — the relight pass (compute), run once per lighting change.
//
// The lighting, projected onto the asset's PCA basis on the CPU
// (nelf_render::project_light: P_mean and P_k, K × 3 numbers), arrives with the
// coefficient dequantisation folded in: for 8-bit affine codes c_k = o_k + s_k·q_k,
//   radiance = (P_mean + Σ_k o_k P_k) + Σ_k q_k (s_k P_k) = light_mean + Σ_k q_k light[k],
// and for f16 coefficients light_mean = P_mean, light[k] = P_k, q_k = c_k. Shading is
// linear in T = mean + Σ c_k B_k, so this equals shading every sample (DESIGN.md).
//
// One invocation per atlas texel: texel (slot s, local l ∈ [−1, 8]³) holds the voxel at
// global voxel coordinates 8·brick(s) + l — its own brick's voxel inside, a neighbour's
// in the apron, 0 where that neighbour brick is missing (the CPU reference counts
// missing voxels as 0), so hardware trilinear filtering inside a slot equals the
// reference's trilinear across brick borders. rgb = radiance, a = density σ (1/m).

#import "common.wgsl"

// Mirrors `RelightParams` in viewer/src/shaders.rs.
struct RelightParams {
    // x_bits, y_bits of the slot packing; slot (= brick) count; components used (rank).
    atlas: vec4<u32>,
    // Grid extent in bricks (xyz); w: coefficient encoding, 1 = 8-bit affine, 2 = f16.
    grid_bricks: vec4<i32>,
    // x: stored rank K (coefficients per voxel); y: u32 words per voxel; z: 1 = show |rgb|.
    words: vec4<u32>,
    // Folded mean radiance (rgb).
    light_mean: vec4<f32>,
}

@group(0) @binding(0) var<uniform> params: RelightParams;
// Folded per-component radiance (rgb in xyz), one entry per component used.
@group(0) @binding(1) var<storage, read> light: array<vec4<f32>>;
// Coefficients, voxel-major, `words.y` words per voxel: 4 codes (u8) or 2 halves (f16) per word.
@group(0) @binding(2) var<storage, read> coefficients: array<u32>;
// Density σ (1/m) as f16, two voxels per word.
@group(0) @binding(3) var<storage, read> density: array<u32>;
// Brick coordinates per brick: (x | y << 16, z).
@group(0) @binding(4) var<storage, read> bricks: array<vec2<u32>>;
@group(0) @binding(5) var indirection: texture_3d<u32>;
@group(0) @binding(6) var atlas: texture_storage_3d<rgba16float, write>;

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

fn coefficient(voxel: u32, k: u32) -> f32 {
    let base = voxel * params.words.y;
    if params.grid_bricks.w == 1 {
        let word = coefficients[base + (k >> 2u)];
        return f32((word >> (8u * (k & 3u))) & 0xffu);
    }
    return half_of(coefficients[base + (k >> 1u)], k);
}

fn voxel_density(voxel: u32) -> f32 {
    return half_of(density[voxel >> 1u], voxel);
}

@compute @workgroup_size(4, 4, 4)
fn relight(@builtin(global_invocation_id) gid: vec3<u32>) {
    let texel = vec3<i32>(gid);
    let slot = texel / SLOT;
    let packing = SlotPacking(params.atlas.x, params.atlas.y);
    let slot_index = u32(slot.x) | (u32(slot.y) << packing.x_bits) | (u32(slot.z) << (packing.x_bits + packing.y_bits));
    if slot.x >= (1 << packing.x_bits) || slot.y >= (1 << packing.y_bits) || slot_index >= params.atlas.z {
        return;
    }
    let packed = bricks[slot_index];
    let brick = vec3<i32>(vec3<u32>(packed.x & 0xffffu, packed.x >> 16u, packed.y));
    // Global voxel coordinates of this texel, then the brick that holds it.
    let voxel = brick * BRICK + (texel - slot * SLOT) - vec3<i32>(1);
    let cell = voxel >> vec3<u32>(3u);
    let entry = brick_entry(indirection, cell, params.grid_bricks.xyz);
    var value = vec4<f32>(0.0);
    if entry != 0u {
        let local = voxel - cell * BRICK;
        let v = (entry - 1u) * 512u + u32(local.x + BRICK * (local.y + BRICK * local.z));
        var rgb = params.light_mean.xyz;
        for (var k = 0u; k < params.atlas.w; k++) {
            rgb += coefficient(v, k) * light[k].xyz;
        }
        if params.words.z == 1u {
            rgb = abs(rgb);
        }
        value = vec4<f32>(rgb, voxel_density(v));
    }
    textureStore(atlas, texel, value);
}
