// march.wgsl — the ray-march pass, one invocation per pixel: a compute entry (`march`,
// which can also count samples) and a fragment entry over a full-screen triangle
// (`march_vs`/`march_fs`); both run `march_pixel` (march_core.wgsl, which documents the
// march), and either can mark the voxels its samples read.

#import "common.wgsl"
#import "march_core.wgsl"

// Counts for benchmarks: trilinear atlas samples taken, and loop iterations (samples
// plus jumps).
struct Counters {
    samples: atomic<u32>,
    steps: atomic<u32>,
}

// Whether this march also marks the stored voxels its samples read (viewer/src/gpu/marks.rs:
// a camera that has not moved then relights only those).
override MARK_VOXELS: bool = false;

// Whether to count samples (a benchmark pipeline sets it; the counting costs atomics).
override COUNT_SAMPLES: bool = false;

@group(0) @binding(4) var output: texture_storage_2d<rgba32float, write>;
@group(0) @binding(5) var<storage, read_write> counters: Counters;
// MARK_VOXELS only: one word per voxel of the grid box (x fastest), 1 where a sample read it.
@group(0) @binding(7) var<storage, read_write> voxel_marks: array<u32>;

// Marks the 8 trilinear corners of the sample at `u` in the voxel grid (a plain store of
// 1 per corner: no atomics; `relight.wgsl`'s `list_marked` lists the stored ones).
fn mark_corners(u: vec3<f32>, voxels: vec3<i32>) {
    let base = vec3<i32>(floor(u));
    for (var c = 0u; c < 8u; c++) {
        let g = base + vec3<i32>(vec3<u32>(c & 1u, (c >> 1u) & 1u, c >> 2u));
        if all(g >= vec3<i32>(0)) && all(g < voxels) {
            voxel_marks[u32(g.x + voxels.x * (g.y + voxels.y * g.z))] = 1u;
        }
    }
}

// march_core.wgsl's per-sample hook: with MARK_VOXELS, marks the voxels a sample with
// σ > 0 reads.
fn on_sample(u: vec3<f32>, value: vec4<f32>, weight: f32, voxels: vec3<i32>) {
    if MARK_VOXELS && value.a > 0.0 {
        mark_corners(u, voxels);
    }
}

// The compute march: one invocation per pixel, into the `output` storage texture.
@compute @workgroup_size(8, 8, 1)
fn march(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= params.image.x || gid.y >= params.image.y {
        return;
    }
    let result = march_pixel(gid.xy);
    if COUNT_SAMPLES {
        atomicAdd(&counters.samples, result.samples);
        atomicAdd(&counters.steps, result.steps);
    }
    textureStore(output, vec2<i32>(gid.xy), result.color);
}

@fragment
fn march_fs(@builtin(position) position: vec4<f32>) -> @location(0) vec4<f32> {
    return march_pixel(vec2<u32>(position.xy)).color;
}
