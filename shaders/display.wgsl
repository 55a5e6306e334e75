// display.wgsl — the display pass: a full-screen triangle that turns the march's linear
// premultiplied image into display colour. Per pixel:
//   c = tonemap(2^exposure · rgb + (1 − alpha) · background)
// (tonemap: identity clamped to [0, 1], or the ACES fit), then the sRGB transfer
// function unless the target format encodes sRGB itself. Debug views (density, alpha)
// skip exposure and tone mapping.

#import "common.wgsl"

// Mirrors `DisplayParams` in viewer/src/shaders.rs.
struct DisplayParams {
    // Background radiance (linear rgb); w: exposure multiplier 2^EV.
    background: vec4<f32>,
    // x: tone map (0 linear clamp, 1 ACES); y: 1 = encode sRGB in the shader;
    // z: 1 = debug view (no exposure or tone map); w: unused.
    mode: vec4<u32>,
}

@group(0) @binding(0) var<uniform> params: DisplayParams;
@group(0) @binding(1) var image: texture_2d<f32>;

struct VertexOut {
    @builtin(position) position: vec4<f32>,
    @location(0) uv: vec2<f32>,
}

// Vertices 0, 1, 2 make one triangle covering the viewport; uv (0, 0) is its top-left.
@vertex
fn vs_main(@builtin(vertex_index) index: u32) -> VertexOut {
    let uv = fullscreen_uv(index);
    var out: VertexOut;
    out.position = fullscreen_position(uv);
    out.uv = uv;
    return out;
}

@fragment
fn fs_main(in: VertexOut) -> @location(0) vec4<f32> {
    let size = vec2<f32>(textureDimensions(image));
    let pixel = vec2<i32>(clamp(in.uv * size, vec2<f32>(0.0), size - vec2<f32>(1.0)));
    let value = textureLoad(image, pixel, 0);
    var c: vec3<f32>;
    if params.mode.z == 1u {
        c = clamp(value.rgb, vec3<f32>(0.0), vec3<f32>(1.0));
    } else {
        let linear = params.background.w * value.rgb + (1.0 - value.a) * params.background.rgb;
        if params.mode.x == 1u {
            c = tonemap_aces(linear);
        } else {
            c = clamp(linear, vec3<f32>(0.0), vec3<f32>(1.0));
        }
    }
    if params.mode.y == 1u {
        c = linear_to_srgb(c);
    }
    return vec4<f32>(c, 1.0);
}
