// march_core.wgsl — the ray march of one pixel (`march_pixel`) and the full-screen
// triangle of the fragment entries, shared by the march passes: `march.wgsl` (compute and
// fragment entries, sample counters, voxel marks) and `march_nostorage.wgsl` (a fragment
// entry with no storage bindings, for devices that have none: WebGL2). Imported after
// common.wgsl.
//
// The importing pass defines `fn on_sample(u: vec3<f32>, value: vec4<f32>, weight: f32,
// voxels: vec3<i32>)`, called for every sample taken, after compositing it (u: lattice
// coordinates; value: the atlas sample; weight: its compositing weight T_i α_i, 0 where
// σ ≤ 0 or in the density view; voxels: the grid box's voxel extent): `march.wgsl` marks
// the voxels it reads there, `replay.wgsl` sums their coefficients,
// `march_nostorage.wgsl` does nothing.
//
// Mirrors nelf_render::march (the CPU reference; its module docs define every step):
// a ray per pixel centre of an OpenCV pinhole camera, clipped against the grid box,
// samples at t_i = t_entry + (i + o)·Δ with o = 0.5 (o ∈ [0, 1) per pixel and frame
// when jitter is on, against banding), trilinear σ and radiance from the relit atlas
// (hardware filtering inside a brick's slot; the 1-voxel apron makes it equal to the
// reference's trilinear across brick borders), α_i = 1 − exp(−σ_i Δ), front-to-back
// compositing (Max 1995), termination right after T < min_transmittance. Output: linear
// premultiplied rgb over black and alpha = 1 − T_end.
//
// Positions are in lattice coordinates u = (p − bbox_min)/voxel_size − 0.5 (voxel centres
// at integers); t stays in metres. Each loop iteration fetches the march grid (common.wgsl)
// at the sample:
// * where the distance to σ > 0 says every sample within s ≥ 0 voxels (Chebyshev) is 0,
//   the march jumps to the first lattice sample beyond s (empty-space skipping; on the
//   shared head scan 96 % of the lattice samples in slots are 0, so this is what pays);
// * else the sample is one texture fetch in the slot of its brick cell (box [8b − 0.5,
//   8b + 7.5]³): a present brick's or a halo cell's (a missing brick next to a present
//   one) slot holds every trilinear corner of a sample in the box, so there are no
//   per-corner lookups.
// The samples taken are the reference's, minus some whose σ is exactly 0.
//
// An asset with a fine density (format 1.4, factor F; nelf_render::render_volume_fine)
// takes σ from the fine density atlas instead of the atlas's alpha (`fine_sigma`: the
// same trilinear rule on the lattice F times finer, through a slot of the same index),
// and the radiance from the atlas at the same point; the step Δ (params) is then
// `step_voxels` fine voxels, and the march grid marks a voxel where any of its fine
// voxels has σ > 0, which keeps its skipping safe (viewer/src/atlas.rs). `on_sample`
// gets the value with that σ in alpha.

// Mirrors `MarchParams` in viewer/src/shaders.rs.
struct MarchParams {
    // Rows of the camera's world-to-camera rotation R as columns of Rᵀ (xyz).
    world_from_camera_x: vec4<f32>,
    world_from_camera_y: vec4<f32>,
    world_from_camera_z: vec4<f32>,
    // Camera centre in lattice coordinates (xyz); w: 1 / voxel size (1/m).
    origin_u: vec4<f32>,
    // fx, fy, cx, cy in pixels.
    intrinsics: vec4<f32>,
    // xyz: upper corner of the grid box in lattice coordinates (8·grid_bricks − 0.5); w: step Δ (m).
    box_max_u: vec4<f32>,
    // xyz: 1 / atlas size in texels; w: minimum transmittance.
    atlas_inv_size: vec4<f32>,
    // xyz: grid extent in bricks; w: voxels per march-grid cube edge.
    grid_bricks: vec4<i32>,
    // Image width, height; frame index (jitter seed); flags: bit 0 jitter.
    image: vec4<u32>,
    // x: view (0 shaded, 1 density maximum, 2 alpha, 3 cost: samples, loop steps and
    // lattice samples in rgb); y, z: slot packing x_bits, y_bits; w: unused.
    view: vec4<u32>,
    // x: density view scale (1 / σ shown as white); yzw: unused.
    scales: vec4<f32>,
    // A fine density (format 1.4): xyz: 1 / its atlas's size in texels; w: its factor F
    // (0: none, σ is the atlas's alpha).
    fine: vec4<f32>,
}

@group(0) @binding(0) var<uniform> params: MarchParams;
@group(0) @binding(1) var atlas: texture_3d<f32>;
@group(0) @binding(2) var atlas_sampler: sampler;
// The fine density atlas (format 1.4; viewer/src/atlas.rs, `fine_density_atlas`): σ of
// the fine voxels, one slot of (8F + 2)³ texels per atlas slot, at the atlas's slot index
// (`fine_sigma`); a 1-texel placeholder where the asset has none (params.fine.w = 0).
@group(0) @binding(3) var fine_density: texture_3d<f32>;
// The march grid (common.wgsl) at cubes of f³ voxels, f = grid_bricks.w.
@group(0) @binding(6) var march_grid: texture_3d<u32>;

const VIEW_SHADED: u32 = 0u;
const VIEW_DENSITY: u32 = 1u;
const VIEW_ALPHA: u32 = 2u;
const VIEW_COST: u32 = 3u;

// Compositing state of one ray.
struct Accum {
    rgb: vec3<f32>,
    transmittance: f32,
    max_sigma: f32,
    // The last sample's compositing weight T_i α_i (for `on_sample`).
    weight: f32,
}

// Composites one sample (σ in alpha); true once the ray may stop (T < min_transmittance).
fn composite(acc: ptr<function, Accum>, value: vec4<f32>, step: f32, view: u32, min_transmittance: f32) -> bool {
    (*acc).weight = 0.0;
    let sigma = value.a;
    if sigma <= 0.0 {
        return false;
    }
    (*acc).max_sigma = max((*acc).max_sigma, sigma);
    if view == VIEW_DENSITY {
        return false;
    }
    // As the reference: s = exp(−σΔ), α = 1 − s, T ← T·s.
    let survive = exp(-sigma * step);
    let weight = (*acc).transmittance * (1.0 - survive);
    (*acc).rgb += weight * value.rgb;
    (*acc).transmittance *= survive;
    (*acc).weight = weight;
    return (*acc).transmittance < min_transmittance;
}

// σ at lattice point `u` from the fine density of factor F = params.fine.w (SPEC.md §8,
// "Fine density": the trilinear rule on the lattice of voxel size Δ/F), read in the fine
// slot at slot coordinates `slot` of the brick cell `cell` whose box [8c − ½, 8c + 7½]³
// holds `u`. Fine lattice coordinates are (u + ½)F − ½ (fine voxel centres at integers);
// texel m + 1 of the slot holds fine voxel 8F·cell + m (m ∈ [−1, 8F]: the apron), so every
// trilinear corner of a point in the box lies in the slot, as for the atlas.
fn fine_sigma(u: vec3<f32>, slot: vec3<i32>, cell: vec3<i32>) -> f32 {
    let f = params.fine.w;
    let slot_texels = i32(f) * BRICK + 2;
    let texel = vec3<f32>(slot * slot_texels) + (u + vec3<f32>(0.5) - vec3<f32>(cell * BRICK)) * f + vec3<f32>(1.0);
    return textureSampleLevel(fine_density, atlas_sampler, texel * params.fine.xyz, 0.0).r;
}

// One pixel's march: its colour and what it cost.
struct MarchResult {
    color: vec4<f32>,
    samples: u32,
    steps: u32,
}

// Marches the ray through the centre of pixel `pixel`.
fn march_pixel(pixel: vec2<u32>) -> MarchResult {
    let packing = SlotPacking(params.view.y, params.view.z);
    // Ray through the pixel centre (OpenCV pinhole), unit length in metres.
    let k = params.intrinsics;
    let d_cam = vec3<f32>((f32(pixel.x) + 0.5 - k.z) / k.x, (f32(pixel.y) + 0.5 - k.w) / k.y, 1.0);
    let dir = normalize(
        d_cam.x * params.world_from_camera_x.xyz + d_cam.y * params.world_from_camera_y.xyz
            + d_cam.z * params.world_from_camera_z.xyz,
    );
    let o = params.origin_u.xyz;
    let du = dir * params.origin_u.w;
    let inv_du = safe_inverse(du);
    let span = ray_box(o, inv_du, vec3<f32>(-0.5), params.box_max_u.xyz);
    let step = params.box_max_u.w;
    let t_entry = max(span.x, 0.0);
    var offset = 0.5;
    if (params.image.w & 1u) != 0u {
        offset = jitter_01(pixel, params.image.z);
    }
    var count = 0;
    if span.x < span.y && span.y > 0.0 {
        count = i32(max(ceil((span.y - t_entry) / step - offset), 0.0));
    }
    let view = params.view.x;
    let fine = params.fine.w > 0.0;
    let min_transmittance = params.atlas_inv_size.w;
    let inv_atlas = params.atlas_inv_size.xyz;
    var acc = Accum(vec3<f32>(0.0), 1.0, 0.0, 0.0);
    var samples = 0u;
    var steps = 0u;
    // The march grid (viewer/src/atlas.rs, `MarchGrid`): per cube of f³ voxels, the
    // distance D to σ > 0 (σ = 0 within f(D − 1) − ½ voxels, Chebyshev, of a sample in the
    // cube, so the samples that near are skipped) and the slot of its brick cell. A ray
    // moves at most `per_sample` lattice units per sample along any axis.
    let factor_i = params.grid_bricks.w;
    let factor = f32(factor_i);
    let inv_factor = 1.0 / factor;
    let cube_max = vec3<i32>(textureDimensions(march_grid)) - vec3<i32>(1);
    let per_sample = max(max(abs(du.x), abs(du.y)), abs(du.z)) * step;
    let samples_per_unit = 1.0 / per_sample;
    // One flat loop, each iteration one fetch and then one sample or one jump: a CPU
    // device runs SIMD lanes through every branch masked, so the body is short and the
    // same for all lanes.
    var i = 0;
    while i < count {
        let t = t_entry + (f32(i) + offset) * step;
        let u = o + t * du;
        steps += 1u;
        let cube = clamp(vec3<i32>(floor((u + vec3<f32>(0.5)) * inv_factor)), vec3<i32>(0), cube_max);
        let texel = textureLoad(march_grid, cube, 0).x;
        let safe = factor * (f32(texel & 0xffu) - 1.0) - 0.5;
        if safe >= 0.0 {
            // Sample i and every later one within `safe` are 0: jump past them.
            i += 1 + i32(min(floor((safe - 1e-3) * samples_per_unit), f32(count)));
            continue;
        }
        i += 1;
        // Near σ > 0, so in a slot: that of the brick cell holding the cube, whose box
        // [8b − 0.5, 8b + 7.5]³ holds the sample (up to rounding at the grid box's faces,
        // which the apron covers) and whose slot holds every trilinear corner of it.
        let cell = (cube * factor_i) >> vec3<u32>(3u);
        let slot = slot_coords((texel >> MARCH_GRID_SLOT_SHIFT) - 1u, packing);
        let shift = vec3<f32>(slot * SLOT - cell * BRICK) + vec3<f32>(1.5);
        var value = textureSampleLevel(atlas, atlas_sampler, (u + shift) * inv_atlas, 0.0);
        if fine {
            // σ from the fine lattice, the radiance from the atlas at the same point.
            value.a = fine_sigma(u, slot, cell);
        }
        samples += 1u;
        let stop = composite(&acc, value, step, view, min_transmittance);
        on_sample(u, value, acc.weight, (cube_max + vec3<i32>(1)) * factor_i);
        if stop {
            break;
        }
    }
    var out = vec4<f32>(acc.rgb, 1.0 - acc.transmittance);
    if view == VIEW_DENSITY {
        out = vec4<f32>(vec3<f32>(acc.max_sigma * params.scales.x), 1.0);
    } else if view == VIEW_ALPHA {
        out = vec4<f32>(vec3<f32>(1.0 - acc.transmittance), 1.0);
    } else if view == VIEW_COST {
        out = vec4<f32>(f32(samples), f32(steps), f32(count), 1.0);
    }
    return MarchResult(out, samples, steps);
}

// The fragment march: a full-screen triangle over a colour target of the image's size
// (llvmpipe's rasteriser writes its tiles faster than per-invocation storage stores).
@vertex
fn march_vs(@builtin(vertex_index) index: u32) -> @builtin(position) vec4<f32> {
    return fullscreen_position(fullscreen_uv(index));
}
