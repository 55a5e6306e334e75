// march_nostorage.wgsl — the ray-march pass for devices without storage buffers or
// compute shaders (WebGL2): the fragment entry of march.wgsl (`march_vs`/`march_fs` over
// a full-screen triangle, `march_pixel` of march_core.wgsl) with only the uniform and
// texture bindings: the same image, with no counters and no voxel marks.

#import "common.wgsl"
#import "march_core.wgsl"

// march_core.wgsl's per-sample hook: nothing to record here.
fn on_sample(u: vec3<f32>, value: vec4<f32>, weight: f32, voxels: vec3<i32>) {}

@fragment
fn march_fs(@builtin(position) position: vec4<f32>) -> @location(0) vec4<f32> {
    return march_pixel(vec2<u32>(position.xy)).color;
}
