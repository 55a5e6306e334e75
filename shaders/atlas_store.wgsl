// atlas_store.wgsl — writing a stored voxel's [rgb, σ] into the atlas, shared by the
// passes that fill it: relight.wgsl (a view-independent asset, per lighting change),
// view.wgsl and reflect.wgsl (a view-dependent asset, per camera move). Imported after
// common.wgsl, whose addressing it uses (`voxel_local`, `voxel_octant`, `voxel_border`,
// `voxel_texel`).
//
// It declares the two bindings the write needs, at the same numbers in every pass that
// imports it: 4, the neighbour blocks, and 5, the atlas (a write-only storage texture).
// The store lives here rather than in common.wgsl because it names the atlas binding (a
// storage texture cannot be a function argument in the GLSL the exporter writes, and
// gathering the texels in an array for the caller made the relight pass ≈ 10 % slower
// on lavapipe), and common.wgsl is imported by passes that have no such binding.

// Per present brick and octant, the atlas slots its voxels can be written to
// (common.wgsl, `voxel_texel`).
@group(0) @binding(4) var<storage, read> neighbour_blocks: array<vec4<u32>>;
@group(0) @binding(5) var atlas: texture_storage_3d<rgba16float, write>;

// Writes `value` to every atlas texel that holds stored voxel `v` (brick v / 512): its
// own slot's and the apron texel of each neighbouring cell's slot it borders
// (common.wgsl, `voxel_texel`); `packing`: the atlas's slot packing.
fn store_voxel_texels(v: u32, packing: SlotPacking, value: vec4<f32>) {
    let local = voxel_local(v);
    let block = (v / 512u * 8u + voxel_octant(local)) * 2u;
    let block_low = neighbour_blocks[block];
    let block_high = neighbour_blocks[block + 1u];
    let border = voxel_border(local);
    for (var ez = 0u; ez <= border.z; ez++) {
        for (var ey = 0u; ey <= border.y; ey++) {
            for (var ex = 0u; ex <= border.x; ex++) {
                let texel = voxel_texel(block_low, block_high, packing, local, vec3<u32>(ex, ey, ez));
                if texel.w != 0 {
                    textureStore(atlas, texel.xyz, value);
                }
            }
        }
    }
}
