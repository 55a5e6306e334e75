// march.wgsl — the ray-march pass (compute, one invocation per pixel).
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
// at integers); t stays in metres. Empty-space skipping, as in the reference: when all
// 8 trilinear corners of a sample lie in one missing brick, every sample inside that
// brick's core box [8b, 8b + 7] is 0, so the march resumes at lattice index
// max(i + 1, ⌈(t_out − t_entry)/Δ − o⌉ − 1). Corners straddling bricks use any present
// brick among those the corners touch: its slot's apron holds all 8 corners.

#import "common.wgsl"

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
    // xyz: grid extent in bricks; w: unused.
    grid_bricks: vec4<i32>,
    // Image width, height; frame index (jitter seed); flags: bit 0 jitter.
    image: vec4<u32>,
    // x: view (0 shaded, 1 density maximum, 2 alpha); y, z: slot packing x_bits, y_bits; w: unused.
    view: vec4<u32>,
    // x: density view scale (1 / σ shown as white); yzw: unused.
    scales: vec4<f32>,
}

// Counts for benchmarks: [0] trilinear atlas samples taken, [1] lattice steps visited.
struct Counters {
    samples: atomic<u32>,
    steps: atomic<u32>,
}

// Whether to count samples (a benchmark pipeline sets it; the counting costs atomics).
override COUNT_SAMPLES: bool = false;

@group(0) @binding(0) var<uniform> params: MarchParams;
@group(0) @binding(1) var atlas: texture_3d<f32>;
@group(0) @binding(2) var atlas_sampler: sampler;
@group(0) @binding(3) var indirection: texture_3d<u32>;
@group(0) @binding(4) var output: texture_storage_2d<rgba32float, write>;
@group(0) @binding(5) var<storage, read_write> counters: Counters;

const VIEW_SHADED: u32 = 0u;
const VIEW_DENSITY: u32 = 1u;
const VIEW_ALPHA: u32 = 2u;

// Trilinear (σ-in-alpha, radiance-in-rgb) value at lattice point u, or 0 where no brick is
// near; `skip_brick` receives the missing brick (w = 1) whose core box holds u.
fn sample_volume(u: vec3<f32>, packing: SlotPacking, skip_brick: ptr<function, vec4<i32>>) -> vec4<f32> {
    let base = vec3<i32>(floor(u));
    let cell = base >> vec3<u32>(3u);
    let grid = params.grid_bricks.xyz;
    var chosen = cell;
    var entry = brick_entry(indirection, cell, grid);
    if entry == 0u {
        let edge = (base & vec3<i32>(7)) == vec3<i32>(7);
        if !any(edge) {
            *skip_brick = vec4<i32>(cell, 1);
            return vec4<f32>(0.0);
        }
        // Corners reach into the next brick along the `edge` axes: find one present.
        let reach = vec3<i32>(edge);
        for (var c = 1; c < 8; c++) {
            let offset = vec3<i32>(c & 1, (c >> 1u) & 1, (c >> 2u) & 1);
            if any(offset > reach) {
                continue;
            }
            let e = brick_entry(indirection, cell + offset, grid);
            if e != 0u {
                entry = e;
                chosen = cell + offset;
                break;
            }
        }
        if entry == 0u {
            return vec4<f32>(0.0);
        }
    }
    let slot = slot_coords(entry - 1u, packing);
    // Texel centres of the slot sit at slot·10 + (local voxel + 1) + 0.5.
    let texel = vec3<f32>(slot * SLOT) + (u - vec3<f32>(chosen * BRICK)) + vec3<f32>(1.5);
    return textureSampleLevel(atlas, atlas_sampler, texel * params.atlas_inv_size.xyz, 0.0);
}

@compute @workgroup_size(8, 8, 1)
fn march(@builtin(global_invocation_id) gid: vec3<u32>) {
    let size = params.image.xy;
    if gid.x >= size.x || gid.y >= size.y {
        return;
    }
    let packing = SlotPacking(params.view.y, params.view.z);
    // Ray through the pixel centre (OpenCV pinhole), unit length in metres.
    let k = params.intrinsics;
    let d_cam = vec3<f32>((f32(gid.x) + 0.5 - k.z) / k.x, (f32(gid.y) + 0.5 - k.w) / k.y, 1.0);
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
        offset = jitter_01(gid.xy, params.image.z);
    }
    var count = 0;
    if span.x < span.y && span.y > 0.0 {
        count = i32(max(ceil((span.y - t_entry) / step - offset), 0.0));
    }
    let view = params.view.x;
    let min_transmittance = params.atlas_inv_size.w;
    var transmittance = 1.0;
    var rgb = vec3<f32>(0.0);
    var max_sigma = 0.0;
    var samples = 0u;
    var steps = 0u;
    var i = 0;
    while i < count {
        let t = t_entry + (f32(i) + offset) * step;
        var skip_brick = vec4<i32>(0);
        let value = sample_volume(o + t * du, packing, &skip_brick);
        steps += 1u;
        if skip_brick.w == 1 {
            let lo = vec3<f32>(skip_brick.xyz * BRICK);
            let t_out = ray_box(o, inv_du, lo, lo + vec3<f32>(f32(BRICK - 1))).y;
            let resume = min(ceil((t_out - t_entry) / step - offset) - 1.0, f32(count));
            i = max(i + 1, i32(resume));
            continue;
        }
        samples += 1u;
        i += 1;
        let sigma = value.a;
        if sigma > 0.0 {
            max_sigma = max(max_sigma, sigma);
            if view == VIEW_DENSITY {
                continue;
            }
            let alpha = one_minus_exp_neg(sigma * step);
            rgb += (transmittance * alpha) * value.rgb;
            transmittance *= 1.0 - alpha;
            if transmittance < min_transmittance {
                break;
            }
        }
    }
    if COUNT_SAMPLES {
        atomicAdd(&counters.samples, samples);
        atomicAdd(&counters.steps, steps);
    }
    var out = vec4<f32>(rgb, 1.0 - transmittance);
    if view == VIEW_DENSITY {
        out = vec4<f32>(vec3<f32>(max_sigma * params.scales.x), 1.0);
    } else if view == VIEW_ALPHA {
        out = vec4<f32>(vec3<f32>(1.0 - transmittance), 1.0);
    }
    textureStore(output, vec2<i32>(gid.xy), out);
}
