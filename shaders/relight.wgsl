// relight.wgsl — the relight pass (compute), run once per lighting change.
//
// The lighting, projected onto the asset's PCA basis on the CPU
// (nelf_render::project_light: P_mean and P_k, K × 3 numbers), arrives with the
// coefficient dequantisation folded in: for 8-bit affine codes c_k = o_k + s_k·q_k,
//   radiance = (P_mean + Σ_k o_k P_k) + Σ_k q_k (s_k P_k) = light_mean + Σ_k q_k light[k],
// and for f16 coefficients light_mean = P_mean, light[k] = P_k, q_k = c_k. Shading is
// linear in T = mean + Σ c_k B_k, so this equals shading every sample (docs/CONVENTIONS.md).
//
// `relight`: one invocation per stored voxel (brick b, local l ∈ [0, 8)³; `relight_marked`:
// per voxel of the list a marking march made, viewer/src/gpu/marks.rs): its K-term
// dot product, with its density, is written to every atlas texel that holds it — its own
// slot and the aprons of the neighbouring slots (atlas_store.wgsl). rgb =
// radiance, a = σ (1/m). Each voxel is shaded once however many texels show it.
//
// `relight_lobes` (view-dependent assets, format 1.2; mirrors nelf_render::view): the
// same dot product, and the voxel's J lobe colours c_j = Σ_i d_ji P^v_i from the
// lighting projected onto the view basis (nelf_render::project_view_light, folded with
// the view coefficients' dequantisation the same way: c_j = lobe_mean_j + Σ_i q_ji ·
// view_light[j·K_v + i]), written as halves to the per-voxel lobe buffer (common.wgsl,
// `lobe_buffer_words`) instead of the atlas: view.wgsl adds the lobes toward the eye and
// fills the atlas whenever the camera moves. A reflection asset (format 1.3) runs it with
// no lobes (J = 0: radiance and σ only) before reflect.wgsl.

#import "common.wgsl"
#import "atlas_store.wgsl"

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
    // x: stored voxels; y: invocations per row of a dispatch over them (workgroups along
    // x · 64); z: invocations of `relight` (⌈voxels / 4⌉), w: invocations per row of its
    // dispatch.
    dispatch: vec4<u32>,
    // View part (relight_lobes only): lobes J, view rank K_v, u32 words of view
    // coefficients per voxel, their encoding (1 = 8-bit affine, 2 = f16).
    view: vec4<u32>,
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
// Bindings 4 (neighbour blocks) and 5 (the atlas): atlas_store.wgsl.

// relight_lobes only. The view lighting folded with the view dequantisation: entry
// j < MAX_LOBES is lobe j's mean colour (rgb), entry MAX_LOBES + n the per-code colour of
// view coefficient n = j·K_v + i (J·K_v ≤ 384): 9 + 384 entries.
@group(0) @binding(6) var<uniform> view_light: array<vec4<f32>, 393>;
// View coefficients, packed as the PCA ones (word-major, 4 codes or 2 halves per word).
@group(0) @binding(7) var<storage, read> view_coefficients: array<u32>;
// The per-voxel lobe buffer (common.wgsl, `lobe_buffer_words`).
@group(0) @binding(8) var<storage, read_write> voxel_lobes: array<u32>;

// Adds the lighting of one word of 8-bit codes (codes k .. k + 3, lighting l0 .. l3).
fn add_codes(rgb: vec3<f32>, word: u32, l0: vec3<f32>, l1: vec3<f32>, l2: vec3<f32>, l3: vec3<f32>) -> vec3<f32> {
    return rgb + f32(word & 0xffu) * l0 + f32((word >> 8u) & 0xffu) * l1 + f32((word >> 16u) & 0xffu) * l2
        + f32(word >> 24u) * l3;
}

// Adds the lighting of one word of f16 coefficients (k, k + 1).
fn add_halves(rgb: vec3<f32>, word: u32, l0: vec3<f32>, l1: vec3<f32>) -> vec3<f32> {
    return rgb + half_of(word, 0u) * l0 + half_of(word, 1u) * l1;
}

// Σ_k q_k · light[k] over the components used, a word (4 codes or 2 halves) at a time.
fn shade_voxel(voxel: u32) -> vec3<f32> {
    let voxels = params.dispatch.x;
    let used = params.atlas.w;
    var rgb = params.light_mean.xyz;
    if params.grid_bricks.w == 1 {
        for (var q = 0u; q < (used + 3u) / 4u; q++) {
            let k = 4u * q;
            rgb = add_codes(rgb, coefficients[q * voxels + voxel], light[k].xyz, light[k + 1u].xyz,
                light[k + 2u].xyz, light[k + 3u].xyz);
        }
    } else {
        for (var q = 0u; q < (used + 1u) / 2u; q++) {
            let k = 2u * q;
            rgb = add_halves(rgb, coefficients[q * voxels + voxel], light[k].xyz, light[k + 1u].xyz);
        }
    }
    return rgb;
}

// `shade_voxel` of four voxels at once: each load of the folded lighting serves four dot
// products (a CPU device loads a loop-indexed uniform lane by lane, which was 40–50 % of
// the pass when shading one voxel per invocation).
fn shade_four(v: vec4<u32>) -> array<vec3<f32>, 4> {
    let voxels = params.dispatch.x;
    let used = params.atlas.w;
    var a = params.light_mean.xyz;
    var b = a;
    var c = a;
    var d = a;
    if params.grid_bricks.w == 1 {
        for (var q = 0u; q < (used + 3u) / 4u; q++) {
            let k = 4u * q;
            let l0 = light[k].xyz;
            let l1 = light[k + 1u].xyz;
            let l2 = light[k + 2u].xyz;
            let l3 = light[k + 3u].xyz;
            let row = q * voxels;
            a = add_codes(a, coefficients[row + v.x], l0, l1, l2, l3);
            b = add_codes(b, coefficients[row + v.y], l0, l1, l2, l3);
            c = add_codes(c, coefficients[row + v.z], l0, l1, l2, l3);
            d = add_codes(d, coefficients[row + v.w], l0, l1, l2, l3);
        }
    } else {
        for (var q = 0u; q < (used + 1u) / 2u; q++) {
            let k = 2u * q;
            let l0 = light[k].xyz;
            let l1 = light[k + 1u].xyz;
            let row = q * voxels;
            a = add_halves(a, coefficients[row + v.x], l0, l1);
            b = add_halves(b, coefficients[row + v.y], l0, l1);
            c = add_halves(c, coefficients[row + v.z], l0, l1);
            d = add_halves(d, coefficients[row + v.w], l0, l1);
        }
    }
    return array<vec3<f32>, 4>(a, b, c, d);
}

fn voxel_density(voxel: u32) -> f32 {
    return half_of(density[voxel >> 1u], voxel);
}

// The voxel of invocation `gid`, or voxels (out of range).
fn invocation_voxel(gid: vec3<u32>) -> u32 {
    let v = gid.x + gid.y * params.dispatch.y;
    return select(v, params.dispatch.x, gid.x >= params.dispatch.y || v >= params.dispatch.x);
}

// Writes stored voxel `v`'s radiance `rgb`, with its density, to every atlas texel that
// holds it.
fn store_voxel(v: u32, radiance: vec3<f32>) {
    var rgb = radiance;
    if params.words.z == 1u {
        rgb = abs(rgb);
    }
    store_voxel_texels(v, SlotPacking(params.atlas.x, params.atlas.y), vec4<f32>(rgb, voxel_density(v)));
}

// Shades the voxels `v` (`count` ≤ 4 of them valid; the others repeat a valid one) and
// stores the valid ones.
fn relight_four(v: vec4<u32>, count: u32) {
    let rgb = shade_four(v);
    for (var j = 0u; j < 4u; j++) {
        if j < count {
            store_voxel(v[j], rgb[j]);
        }
    }
}

// One invocation per four stored voxels, i + n·S for n < 4 (S = dispatch.z invocations,
// so neighbouring invocations read neighbouring words).
@compute @workgroup_size(64, 1, 1)
fn relight(@builtin(global_invocation_id) gid: vec3<u32>) {
    let quarter = params.dispatch.z;
    let i = gid.x + gid.y * params.dispatch.w;
    if gid.x >= params.dispatch.w || i >= quarter {
        return;
    }
    let voxels = params.dispatch.x;
    let n = vec4<u32>(0u, 1u, 2u, 3u);
    let v = vec4<u32>(i) + n * quarter;
    let count = min((voxels - i + quarter - 1u) / quarter, 4u);
    relight_four(select(vec4<u32>(i), v, v < vec4<u32>(voxels)), count);
}

// The marked relight (viewer/src/gpu/marks.rs). Group 1: the list of marked stored voxels,
// the marks a marking march left in the voxel grid (one word per voxel of the grid box),
// and each brick's cell (`brick_cell`). `list_marked` (one invocation per stored voxel)
// lists the marked ones; `relight_marked_args` writes the indirect dispatch size from
// the count (group 2: the indirect buffer cannot be bound to the dispatch that it sizes);
// `relight_marked` relights the listed voxels.
// The marked stored voxels (brick · 512 + local), each once, and how many.
struct VoxelList {
    count: atomic<u32>,
    voxels: array<u32>,
}

@group(1) @binding(0) var<storage, read_write> marked: VoxelList;
@group(1) @binding(1) var<storage, read> voxel_marks: array<u32>;
@group(1) @binding(2) var<storage, read> brick_cells: array<vec2<u32>>;
@group(2) @binding(0) var<storage, read_write> marked_dispatch: array<u32, 3>;

@compute @workgroup_size(64, 1, 1)
fn list_marked(@builtin(global_invocation_id) gid: vec3<u32>) {
    let v = invocation_voxel(gid);
    if v >= params.dispatch.x {
        return;
    }
    let voxels = vec3<i32>(params.grid_bricks.xyz * BRICK);
    let g = brick_cell(brick_cells[v / 512u]) * BRICK + voxel_local(v);
    if voxel_marks[u32(g.x + voxels.x * (g.y + voxels.y * g.z))] != 0u {
        marked.voxels[atomicAdd(&marked.count, 1u)] = v;
    }
}

// Largest workgroup count along x of one dispatch (WebGPU's default limit).
const MAX_GROUPS_X: u32 = 65535u;

// Listed voxels per invocation of `relight_marked`.
const MARKED_PER_INVOCATION: u32 = 4u;

@compute @workgroup_size(1, 1, 1)
fn relight_marked_args() {
    let groups = (atomicLoad(&marked.count) + 64u * MARKED_PER_INVOCATION - 1u) / (64u * MARKED_PER_INVOCATION);
    marked_dispatch[0] = min(groups, MAX_GROUPS_X);
    marked_dispatch[1] = (groups + MAX_GROUPS_X - 1u) / MAX_GROUPS_X;
    marked_dispatch[2] = 1u;
}

@compute @workgroup_size(64, 1, 1)
fn relight_marked(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let first = (gid.x + gid.y * groups.x * 64u) * MARKED_PER_INVOCATION;
    let listed = atomicLoad(&marked.count);
    if first >= listed {
        return;
    }
    let last = listed - 1u;
    let v = vec4<u32>(
        marked.voxels[first],
        marked.voxels[min(first + 1u, last)],
        marked.voxels[min(first + 2u, last)],
        marked.voxels[min(first + 3u, last)],
    );
    relight_four(v, min(listed - first, MARKED_PER_INVOCATION));
}

@compute @workgroup_size(64, 1, 1)
fn relight_lobes(@builtin(global_invocation_id) gid: vec3<u32>) {
    let v = invocation_voxel(gid);
    if v >= params.dispatch.x {
        return;
    }
    let voxels = params.dispatch.x;
    let lobes = min(params.view.x, MAX_LOBES);
    let rank = params.view.y;
    let bytes = params.view.w == 1u;
    let per_word = select(2u, 4u, bytes);
    let rgb = shade_voxel(v);
    let sigma_bits = (density[v >> 1u] >> (16u * (v & 1u))) & 0xffffu;
    voxel_lobes[v] = pack_halves(rgb.x, rgb.y);
    voxel_lobes[voxels + v] = f32_to_half(rgb.z) | (sigma_bits << 16u);
    // Lobe colours c_j = lobe_mean_j + Σ_i q_ji · view_light[MAX_LOBES + j·K_v + i], i
    // ascending; their halves 3j + c go out a word (two halves) at a time.
    var half_index = 0u;
    var pending = 0u;
    for (var j = 0u; j < lobes; j++) {
        var c = view_light[j].xyz;
        var word = 0u;
        for (var i = 0u; i < rank; i++) {
            let n = j * rank + i;
            if i == 0u || n % per_word == 0u {
                word = view_coefficients[(n / per_word) * voxels + v];
            }
            let code = select(half_of(word, n), f32((word >> (8u * (n & 3u))) & 0xffu), bytes);
            c += code * view_light[MAX_LOBES + n].xyz;
        }
        for (var ch = 0u; ch < 3u; ch++) {
            let half = f32_to_half(c[ch]);
            if (half_index & 1u) == 0u {
                pending = half;
            } else {
                voxel_lobes[(2u + half_index / 2u) * voxels + v] = pending | (half << 16u);
            }
            half_index++;
        }
    }
    if (half_index & 1u) == 1u {
        voxel_lobes[(2u + half_index / 2u) * voxels + v] = pending;
    }
}
