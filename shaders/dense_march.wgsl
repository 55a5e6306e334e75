// dense_march.wgsl — benchmark baseline, not used for rendering: the bare texture march
// of docs/PLATFORM.md ("every ray taking all its steps"). One invocation per pixel; the ray
// enters a dense 3D texture (unit cube, seen head-on through a pinhole at z = −1) and
// takes exactly `image.z` trilinear samples (`textureSampleLevel`, linear sampler),
// front-to-back composited without early termination. It measures the trilinear
// sample rate the device reaches with no indirection, no skipping and no branching.

#import "common.wgsl"

// Mirrors `DenseParams` in viewer/src/shaders.rs.
struct DenseParams {
    // Image width, height, steps per ray; w unused.
    image: vec4<u32>,
}

@group(0) @binding(0) var<uniform> params: DenseParams;
@group(0) @binding(1) var volume: texture_3d<f32>;
@group(0) @binding(2) var volume_sampler: sampler;
@group(0) @binding(3) var output: texture_storage_2d<rgba32float, write>;

@compute @workgroup_size(8, 8, 1)
fn dense_march(@builtin(global_invocation_id) gid: vec3<u32>) {
    let size = params.image.xy;
    if gid.x >= size.x || gid.y >= size.y {
        return;
    }
    let uv = (vec2<f32>(gid.xy) + vec2<f32>(0.5)) / vec2<f32>(size);
    let origin = vec3<f32>(0.5, 0.5, -1.0);
    let dir = normalize(vec3<f32>(uv - vec2<f32>(0.5), 1.0) * vec3<f32>(0.9, 0.9, 1.0));
    let span = ray_box(origin, safe_inverse(dir), vec3<f32>(0.0), vec3<f32>(1.0));
    let steps = params.image.z;
    let step = max(span.y - span.x, 0.0) / f32(steps);
    var rgb = vec3<f32>(0.0);
    var transmittance = 1.0;
    for (var i = 0u; i < steps; i++) {
        let p = origin + (span.x + (f32(i) + 0.5) * step) * dir;
        let v = textureSampleLevel(volume, volume_sampler, p, 0.0);
        let survive = exp(-v.a * step);
        rgb += transmittance * (1.0 - survive) * v.rgb;
        transmittance *= survive;
    }
    textureStore(output, vec2<i32>(gid.xy), vec4<f32>(rgb, 1.0 - transmittance));
}
