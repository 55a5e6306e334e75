// reflect.wgsl — the reflect pass (compute) of a reflection asset (format 1.3), the
// reflection part's counterpart of view.wgsl; a view-independent asset never runs it.
//
// Mirrors nelf_render::reflection::reflection_seen_from: each stored voxel's radiance
// toward the eye e is
//   radiance = base + s · (max(0, n·ω) E(r) − Ē),   Ē = mean_k max(0, n·ω_k) E(r_k),
// ω = normalize(e − voxel centre), r = 2 (n·ω) n − ω its mirror direction about the
// voxel's unit normal n, ω_k and r_k the same toward the capture's eyes e_k (≤ 16) the PCA
// part averages over, s ≥ 0 the voxel's scale, base the PCA part's radiance and E the
// lighting filtered by the part's lobe (nelf_render::reflection::FilteredEnvironment),
// interpolated bilinearly in a 64 × 128 lat-long table of light-frame directions
// (`filtered_environment_at`, mirroring nelf_format::conventions::lobe_table_corners).
//
// Split by when each part changes, as for view.wgsl:
// * per lighting change the CPU rebuilds the E table (ReflectionLobe::filter), the relight
//   pass (relight.wgsl, `relight_lobes` with no lobes) writes base and σ to the lobe buffer
//   (common.wgsl, `lobe_buffer_words`: two words per voxel), and `reflect_mean`, which
//   does not depend on the eye, replaces base by base − s·Ē in place;
//   A voxel whose scale is 0 (marked so in its codes word: outside the bake's band, most
//   of a baked asset's voxels) does not depend on the eye: `reflect_mean` writes its
//   base and σ into the atlas there and then;
// * per camera move `reflect_toward_eye`, over the list of voxels with a scale only, adds
//   s · max(0, n·ω) E(r) toward the eye and writes the result with σ into every atlas
//   texel that holds the voxel (atlas_store.wgsl);
// * per frame the march is unchanged.
// The normal (octahedral u, v) and the scale are 8-bit codes, dequantized as
// nelf_format::Coefficients::voxel_f32 does (offset + scale · code, f32). Positions and
// eyes are lattice coordinates (voxel centres at 8·cell + local), which give world
// directions: the lattice is the world scaled and shifted.

#import "common.wgsl"
#import "atlas_store.wgsl"

// Mirrors `ReflectParams` in viewer/src/shaders.rs.
struct ReflectParams {
    // x_bits, y_bits of the slot packing; stored voxels; eyes in `eyes_u` (1 ..= 16).
    atlas: vec4<u32>,
    // The eye in lattice coordinates (p − bbox_min)/voxel − 0.5 (xyz); w: unused.
    eye_u: vec4<f32>,
    // x: invocations per row of the dispatch over all voxels (workgroups along x · 64);
    // y: the same for the dispatch over `scaled_voxels`; z: its length; w: unused.
    dispatch: vec4<u32>,
    // Dequantization of the codes (normal u, normal v, scale s): offset + scale · code
    // (xyz); w: unused.
    code_offset: vec4<f32>,
    code_scale: vec4<f32>,
    // The columns of light_from_world, the E table's frame (xyz).
    light_from_world: array<vec4<f32>, 3>,
    // The eyes e_k in lattice coordinates (xyz).
    eyes_u: array<vec4<f32>, 16>,
}

@group(0) @binding(0) var<uniform> params: ReflectParams;
// The per-voxel lobe buffer (common.wgsl, `lobe_buffer_words`, no lobes): base radiance
// and σ from the relight pass, base − s·Ē once `reflect_mean` has run.
@group(0) @binding(1) var<storage, read_write> voxel_lobes: array<u32>;
// Brick-cell coordinates of every present brick (common.wgsl, `brick_cell`).
@group(0) @binding(2) var<storage, read> brick_cells: array<vec2<u32>>;
// Per voxel one word of 8-bit codes: normal u (bits 0–7), normal v (8–15), scale (16–23),
// and bit 24 set where the voxel has a scale (> 0; the CPU decides, so that this pass and
// the list below agree).
@group(0) @binding(3) var<storage, read> reflection_codes: array<u32>;
// Bindings 4 (neighbour blocks) and 5 (the atlas): atlas_store.wgsl.
// E(r) at the nodes of the lobe table, row-major (row · 128 + column), rgb.
@group(0) @binding(6) var<storage, read> filtered_environment: array<vec4<f32>>;
// The voxels with a scale (bit 24 of their codes word), ascending.
@group(0) @binding(7) var<storage, read> scaled_voxels: array<u32>;

// The lobe table's rows (polar angle) and columns (azimuth), as
// nelf_format::conventions::LOBE_TABLE_H / LOBE_TABLE_W.
const LOBE_TABLE_H: u32 = 64u;
const LOBE_TABLE_W: u32 = 128u;
const PI: f32 = 3.14159265358979323846;
const TAU: f32 = 6.28318530717958647692;

// 1 for a ≥ 0, −1 below (the octahedral code's sign, which is never 0).
fn sign_not_zero(a: f32) -> f32 {
    return select(-1.0, 1.0, a >= 0.0);
}

// The unit normal of octahedral coordinates (u, v) ∈ [−1, 1]² (clamped), as
// nelf_format::conventions::octahedral_decode.
fn octahedral_decode(uv: vec2<f32>) -> vec3<f32> {
    let u = clamp(uv.x, -1.0, 1.0);
    let v = clamp(uv.y, -1.0, 1.0);
    let z = 1.0 - abs(u) - abs(v);
    var xy = vec2<f32>(u, v);
    if z < 0.0 {
        xy = vec2<f32>((1.0 - abs(v)) * sign_not_zero(u), (1.0 - abs(u)) * sign_not_zero(v));
    }
    let n = vec3<f32>(xy, z);
    return n / sqrt(n.x * n.x + n.y * n.y + n.z * n.z);
}

// `d` scaled to unit length, or 0 where its length is 0 or not finite (glam's
// `normalize_or_zero`).
fn normalize_or_zero(d: vec3<f32>) -> vec3<f32> {
    let inverse = 1.0 / length(d);
    if inverse > 0.0 && inverse <= 3.4028235e38 {
        return d * inverse;
    }
    return vec3<f32>(0.0);
}

// E at world direction `r`, interpolated bilinearly between the four nodes around its
// light-frame direction d = light_from_world · r, as lobe_table_corners: (θ, φ) of d
// normalised (+y where d is 0 or not finite), t = θH/π − ½ clamped to [0, H − 1],
// s = (φ + π)W/2π − ½ wrapping in φ.
fn filtered_environment_at(r: vec3<f32>) -> vec3<f32> {
    let m = params.light_from_world;
    let d = m[0].xyz * r.x + m[1].xyz * r.y + m[2].xyz * r.z;
    let len = sqrt(d.x * d.x + d.y * d.y + d.z * d.z);
    var w = vec3<f32>(0.0, 1.0, 0.0);
    if len > 0.0 && len <= 3.4028235e38 {
        w = d / len;
    }
    let h = f32(LOBE_TABLE_H);
    let theta = acos(clamp(w.y, -1.0, 1.0));
    let phi = atan2(w.x, -w.z);
    let t = clamp(theta * h / PI - 0.5, 0.0, h - 1.0);
    let s = (phi + PI) * f32(LOBE_TABLE_W) / TAU - 0.5;
    let t0 = floor(t);
    let s0 = floor(s);
    let ft = t - t0;
    let fs = s - s0;
    let row0 = u32(t0) * LOBE_TABLE_W;
    let row1 = min(u32(t0) + 1u, LOBE_TABLE_H - 1u) * LOBE_TABLE_W;
    let width = i32(LOBE_TABLE_W);
    let col0 = u32((i32(s0) % width + width) % width);
    let col1 = (col0 + 1u) % LOBE_TABLE_W;
    return (1.0 - ft) * (1.0 - fs) * filtered_environment[row0 + col0].xyz
        + (1.0 - ft) * fs * filtered_environment[row0 + col1].xyz
        + ft * (1.0 - fs) * filtered_environment[row1 + col0].xyz
        + ft * fs * filtered_environment[row1 + col1].xyz;
}

// max(0, n·ω) E(r), r = normalize(2 (n·ω) n − ω): the lobe's radiance per unit scale
// toward `toward_eye` (unit) at a surface of unit normal `n`
// (nelf_render::reflection::FilteredEnvironment::toward).
fn lobe_radiance(toward_eye: vec3<f32>, n: vec3<f32>) -> vec3<f32> {
    let c = dot(n, toward_eye);
    if c <= 0.0 {
        return vec3<f32>(0.0);
    }
    return c * filtered_environment_at(normalize_or_zero(2.0 * c * n - toward_eye));
}

// Stored voxel `v`'s unit normal (xyz) and scale s ≥ 0 (w), dequantized from its codes; a
// voxel without the bit of a scale has scale 0.
fn voxel_normal_scale(v: u32) -> vec4<f32> {
    let word = reflection_codes[v];
    let codes = vec3<f32>(vec3<u32>(word & 0xffu, (word >> 8u) & 0xffu, (word >> 16u) & 0xffu));
    let values = params.code_offset.xyz + params.code_scale.xyz * codes;
    let scaled = (word & 0x1000000u) != 0u;
    return vec4<f32>(octahedral_decode(values.xy), select(0.0, max(values.z, 0.0), scaled));
}

// Stored voxel `v`'s centre in lattice coordinates.
fn voxel_centre_u(v: u32) -> vec3<f32> {
    return vec3<f32>(brick_cell(brick_cells[v / 512u]) * BRICK + voxel_local(v));
}

// The item of invocation `gid` in a dispatch of `per_row` invocations per row over
// `count` items (voxels, or entries of `scaled_voxels`), or `count` (out of range).
fn invocation_item(gid: vec3<u32>, per_row: u32, count: u32) -> u32 {
    let i = gid.x + gid.y * per_row;
    return select(i, count, gid.x >= per_row || i >= count);
}

// Per lighting change, after the relight pass: base → base − s·Ē in the lobe buffer; a
// voxel without a scale goes into the atlas as it is.
@compute @workgroup_size(64, 1, 1)
fn reflect_mean(@builtin(global_invocation_id) gid: vec3<u32>) {
    let voxels = params.atlas.z;
    let v = invocation_item(gid, params.dispatch.x, voxels);
    if v >= voxels {
        return;
    }
    let normal_scale = voxel_normal_scale(v);
    if !(normal_scale.w > 0.0) {
        let base = lobe_buffer_radiance(voxel_lobes[v], voxel_lobes[voxels + v]);
        store_voxel_texels(v, SlotPacking(params.atlas.x, params.atlas.y), base);
        return;
    }
    let n = normal_scale.xyz;
    let p = voxel_centre_u(v);
    let eyes = clamp(params.atlas.w, 1u, 16u);
    let share = 1.0 / f32(eyes);
    var mean = vec3<f32>(0.0);
    for (var k = 0u; k < eyes; k++) {
        mean += share * lobe_radiance(normalize_or_zero(params.eyes_u[k].xyz - p), n);
    }
    let second = voxel_lobes[voxels + v];
    let rgb = lobe_buffer_radiance(voxel_lobes[v], second).rgb - normal_scale.w * mean;
    voxel_lobes[v] = pack_halves(rgb.x, rgb.y);
    voxel_lobes[voxels + v] = f32_to_half(rgb.z) | (second & 0xffff0000u);
}

// Per camera move, over the voxels with a scale: the radiance toward the eye, written
// with σ into the atlas.
@compute @workgroup_size(64, 1, 1)
fn reflect_toward_eye(@builtin(global_invocation_id) gid: vec3<u32>) {
    let voxels = params.atlas.z;
    let i = invocation_item(gid, params.dispatch.y, params.dispatch.z);
    if i >= params.dispatch.z {
        return;
    }
    let v = scaled_voxels[i];
    if v >= voxels {
        return;
    }
    let base = lobe_buffer_radiance(voxel_lobes[v], voxel_lobes[voxels + v]);
    let normal_scale = voxel_normal_scale(v);
    let toward_eye = normalize_or_zero(params.eye_u.xyz - voxel_centre_u(v));
    let rgb = base.rgb + normal_scale.w * lobe_radiance(toward_eye, normal_scale.xyz);
    store_voxel_texels(v, SlotPacking(params.atlas.x, params.atlas.y), vec4<f32>(rgb, base.a));
}
