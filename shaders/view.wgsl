// view.wgsl — the view pass (compute) of a view-dependent asset (format 1.2), run
// before the march whenever the camera's eye (or the lighting) changed since the last
// frame; a view-independent asset never runs it.
//
// Mirrors nelf_render::view::radiance_seen_from: each stored voxel's radiance toward the
// eye e is
//   radiance = base + Σ_j Y_j(ω) c_j,   ω = normalize(e − voxel centre),
//   Y_j(ω) = Σ_l w_jl · y_l(ω)   (y: the 9 harmonics of common.wgsl's `view_harmonics`),
// with base (the PCA part's radiance) and the lobe colours c_j read from the lobe buffer
// the relight pass wrote once per lighting change (common.wgsl, `lobe_buffer_words`).
// The direction is taken per voxel, not per sample, so the march is unchanged: the
// result is written with σ into every atlas texel that holds the voxel (its slot and the
// neighbours' aprons, atlas_store.wgsl), as the relight pass does for a
// view-independent asset. Positions are lattice coordinates (voxel centres at
// 8·cell + local), which give world directions: the lattice is the world scaled and
// shifted.

#import "common.wgsl"
#import "atlas_store.wgsl"

// Mirrors `ViewParams` in viewer/src/shaders.rs.
struct ViewParams {
    // x_bits, y_bits of the slot packing; lobes J; stored voxels.
    atlas: vec4<u32>,
    // The eye in lattice coordinates (p − bbox_min)/voxel − 0.5 (xyz); w: unused.
    eye_u: vec4<f32>,
    // x: invocations per row of the dispatch (workgroups along x · 64); yzw: unused.
    dispatch: vec4<u32>,
    // Lobe weights w_jl: lobe j's over harmonics 0–3 in lobes[3j], 4–7 in lobes[3j + 1],
    // 8 in lobes[3j + 2].x (yzw: 0).
    lobes: array<vec4<f32>, 27>,
}

@group(0) @binding(0) var<uniform> params: ViewParams;
// The per-voxel lobe buffer (common.wgsl, `lobe_buffer_words`).
@group(0) @binding(1) var<storage, read> voxel_lobes: array<u32>;
// Brick-cell coordinates of every present brick (common.wgsl, `brick_cell`).
@group(0) @binding(2) var<storage, read> brick_cells: array<vec2<u32>>;
// Bindings 4 (neighbour blocks) and 5 (the atlas): atlas_store.wgsl.

@compute @workgroup_size(64, 1, 1)
fn view(@builtin(global_invocation_id) gid: vec3<u32>) {
    let voxels = params.atlas.w;
    let v = gid.x + gid.y * params.dispatch.x;
    if gid.x >= params.dispatch.x || v >= voxels {
        return;
    }
    let lobes = min(params.atlas.z, MAX_LOBES);
    let cell = brick_cell(brick_cells[v / 512u]);
    let local = voxel_local(v);
    let y = view_harmonics(params.eye_u.xyz - vec3<f32>(cell * BRICK + local));
    let base = lobe_buffer_radiance(voxel_lobes[v], voxel_lobes[voxels + v]);
    var rgb = base.rgb;
    for (var j = 0u; j < lobes; j++) {
        let weight = dot(params.lobes[3u * j], y[0]) + dot(params.lobes[3u * j + 1u], y[1])
            + dot(params.lobes[3u * j + 2u], y[2]);
        // Lobe j's colour: halves 4 + 3j + c, in words 2 + (3j + c) / 2.
        let h = 3u * j;
        let first = voxel_lobes[(2u + h / 2u) * voxels + v];
        let second = voxel_lobes[(3u + h / 2u) * voxels + v];
        let colour = select(
            vec3<f32>(half_of(first, 0u), half_of(first, 1u), half_of(second, 0u)),
            vec3<f32>(half_of(first, 1u), half_of(second, 0u), half_of(second, 1u)),
            (h & 1u) == 1u,
        );
        rgb += weight * colour;
    }
    store_voxel_texels(v, SlotPacking(params.atlas.x, params.atlas.y), vec4<f32>(rgb, base.a));
}
