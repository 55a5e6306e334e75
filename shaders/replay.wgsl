// replay.wgsl — relighting a held camera's frame per pixel, without a march
// (viewer/src/gpu/replay.rs).
//
// A frame is linear in the lighting: the march composites C_p = Σ_i w_i L(x_i), with
// weights w_i = T_i (1 − exp(−σ_i Δ)) that depend on σ alone, and the trilinear radiance
// L(x) = Σ_c a_c L_c over the 8 corner voxels, each L_c = P_mean + Σ_k c_k P_k (zero at a
// missing brick's voxels). So
//
//   C_p = W_p P_mean + Σ_k C_pk P_k,   W_p = Σ_i w_i Σ_{c present} a_c,
//   C_pk = Σ_i w_i Σ_c a_c c_k(c),
//
// and a lighting change at a held camera needs only the K + 1 numbers per pixel, not a
// march: `replay_build` marches the pixel once (march_core.wgsl, the same samples and
// weights as the march) and stores W_p, the alpha 1 − T_end and C_pk (as halves); every
// later lighting change runs `replay_fs` (a full-screen triangle) or `replay_relight`
// (compute), a K-term dot product per pixel. For 8-bit
// codes c_k = o_k + s_k q_k, so C_pk = o_k W_p + s_k Σ_i w_i Σ_c a_c q_k: the build sums
// codes and dequantises once per pixel.
//
// Group 0 is the compute march's (march.wgsl): the uniform, atlas, march grid and output
// image; `replay_fs` reads group 1 only. `replay_build` handles components [k0, k0 + 64) per dispatch (its accumulators
// are 64 floats), so a rank-K asset takes ⌈K/64⌉ dispatches. It reads only the atlas's
// densities, which hold whatever lighting the atlas was last relit under.

#import "common.wgsl"
#import "march_core.wgsl"

// Mirrors `ReplayParams` in viewer/src/shaders.rs.
struct ReplayParams {
    // x: first component k0 of this build dispatch; y: components it sums (≤ 64);
    // z: components the relight uses (rank; the light beyond is 0); w: cached pixels P.
    components: vec4<u32>,
    // x: stored bricks (present slots); y: u32 words per voxel; z: coefficient encoding
    // (1 = 8-bit affine, 2 = f16); w: stored rank K.
    coefficients: vec4<u32>,
    // P_mean (rgb), the lighting's mean radiance, not folded.
    light_mean: vec4<f32>,
    // The cached rectangle of the image: first pixel x0, y0 and size w × h (P = w·h); no
    // ray outside it meets the grid box. Pixel (x, y) in it is p = (x − x0) + w (y − y0).
    rect: vec4<u32>,
}

// The cache index of `pixel`, or P where it lies outside the cached rectangle.
fn cached_pixel(pixel: vec2<u32>) -> u32 {
    let local = pixel - replay.rect.xy;
    if any(pixel < replay.rect.xy) || any(local >= replay.rect.zw) {
        return replay.components.w;
    }
    return local.x + local.y * replay.rect.z;
}

@group(0) @binding(4) var output: texture_storage_2d<rgba32float, write>;

@group(1) @binding(0) var<uniform> replay: ReplayParams;
// Coefficients as relight.wgsl reads them: word q of voxel v at q · voxels + v.
@group(1) @binding(1) var<storage, read> coefficients: array<u32>;
// Per component (o_k, s_k): c_k = o_k + s_k · code; (0, 1) for f16 values.
@group(1) @binding(2) var<storage, read> dequantization: array<vec2<f32>>;
// Per pixel p of P: W_p (f32 bits) at p, the alpha at P + p, then C_pk as halves, two
// components per word: word j (components 2j, 2j + 1) at (2 + j) · P + p.
@group(1) @binding(3) var<storage, read_write> cache: array<u32>;
// P_k (rgb) per component, not folded; 0 from the rank used on.
@group(1) @binding(4) var<uniform> light: array<vec4<f32>, 384>;

// Components one build dispatch sums.
const BUILD_COMPONENTS: u32 = 64u;

// The build's per-pixel state: W_p and the component sums of this dispatch.
var<private> present_weight: f32;
var<private> sums: array<vec4<f32>, 16>;

// march_core.wgsl's per-sample hook: adds the sample's compositing weight `w` (the
// march's own, from `composite`) times its 8 corners' coefficients.
fn on_sample(u: vec3<f32>, value: vec4<f32>, w: f32, voxels: vec3<i32>) {
    if w <= 0.0 {
        return;
    }
    let base = floor(u);
    let f = u - base;
    // Cube of a voxel: a shift, the factor being a power of two (integer division is
    // lane by lane on a CPU device).
    let factor_shift = vec3<u32>(countTrailingZeros(u32(params.grid_bricks.w)));
    let bricks = replay.coefficients.x;
    // The corners' stored voxels and weights (weight 0 where the brick is missing), corners
    // 0–3 (z = 0) in `*_low`, 4–7 in `*_high`, corner c at offset (c & 1, c >> 1 & 1, c >> 2):
    // vectors, not arrays, so that the loops below index nothing dynamically.
    var voxel_low = vec4<u32>(0u);
    var voxel_high = vec4<u32>(0u);
    var weight_low = vec4<f32>(0.0);
    var weight_high = vec4<f32>(0.0);
    for (var c = 0u; c < 8u; c++) {
        let bit = vec3<u32>(c & 1u, (c >> 1u) & 1u, c >> 2u);
        let g = vec3<i32>(base) + vec3<i32>(bit);
        let a = select(1.0 - f, f, bit == vec3<u32>(1u));
        var voxel = 0u;
        var weight = 0.0;
        if all(g >= vec3<i32>(0)) && all(g < voxels) {
            let slot = textureLoad(march_grid, g >> factor_shift, 0).x >> MARCH_GRID_SLOT_SHIFT;
            if slot != 0u && slot <= bricks {
                let local = vec3<u32>(g & vec3<i32>(BRICK - 1));
                voxel = (slot - 1u) * 512u + local.x + 8u * local.y + 64u * local.z;
                weight = w * a.x * a.y * a.z;
            }
        }
        let lane = vec4<bool>(c == 0u || c == 4u, c == 1u || c == 5u, c == 2u || c == 6u, c == 3u || c == 7u);
        if c < 4u {
            voxel_low = select(voxel_low, vec4<u32>(voxel), lane);
            weight_low = select(weight_low, vec4<f32>(weight), lane);
        } else {
            voxel_high = select(voxel_high, vec4<u32>(voxel), lane);
            weight_high = select(weight_high, vec4<f32>(weight), lane);
        }
    }
    present_weight += dot(weight_low + weight_high, vec4<f32>(1.0));
    let voxel_count = bricks * 512u;
    let k0 = replay.components.x;
    let n = replay.components.y;
    if replay.coefficients.z == 1u {
        // Four codes a word: word q holds components 4q .. 4q + 3.
        for (var i = 0u; i < (n + 3u) / 4u; i++) {
            let row = (k0 / 4u + i) * voxel_count;
            let lo = vec4<u32>(row) + voxel_low;
            let hi = vec4<u32>(row) + voxel_high;
            sums[i] += weight_low.x * unpack4xU8f(coefficients[lo.x]) + weight_low.y * unpack4xU8f(coefficients[lo.y])
                + weight_low.z * unpack4xU8f(coefficients[lo.z]) + weight_low.w * unpack4xU8f(coefficients[lo.w])
                + weight_high.x * unpack4xU8f(coefficients[hi.x]) + weight_high.y * unpack4xU8f(coefficients[hi.y])
                + weight_high.z * unpack4xU8f(coefficients[hi.z]) + weight_high.w * unpack4xU8f(coefficients[hi.w]);
        }
    } else {
        // Two halves a word: word j holds components 2j, 2j + 1.
        for (var i = 0u; i < (n + 1u) / 2u; i++) {
            let row = (k0 / 2u + i) * voxel_count;
            let lo = vec4<u32>(row) + voxel_low;
            let hi = vec4<u32>(row) + voxel_high;
            let s = weight_low.x * halves(coefficients[lo.x]) + weight_low.y * halves(coefficients[lo.y])
                + weight_low.z * halves(coefficients[lo.z]) + weight_low.w * halves(coefficients[lo.w])
                + weight_high.x * halves(coefficients[hi.x]) + weight_high.y * halves(coefficients[hi.y])
                + weight_high.z * halves(coefficients[hi.z]) + weight_high.w * halves(coefficients[hi.w]);
            if (i & 1u) == 0u {
                sums[i / 2u] += vec4<f32>(s, 0.0, 0.0);
            } else {
                sums[i / 2u] += vec4<f32>(0.0, 0.0, s);
            }
        }
    }
}

// The two halves of a word (low first; common.wgsl's conversion, which needs no f16
// capability).
fn halves(word: u32) -> vec2<f32> {
    return vec2<f32>(half_of(word, 0u), half_of(word, 1u));
}

// The four 8-bit codes of a word (low byte first) as floats.
fn unpack4xU8f(word: u32) -> vec4<f32> {
    return vec4<f32>(vec4<u32>(word & 0xffu, (word >> 8u) & 0xffu, (word >> 16u) & 0xffu, word >> 24u));
}

// One invocation per pixel: marches it, storing W_p and the alpha (first dispatch) and the
// dequantised sums C_pk of this dispatch's components.
@compute @workgroup_size(8, 8, 1)
fn replay_build(@builtin(global_invocation_id) gid: vec3<u32>) {
    if any(gid.xy >= replay.rect.zw) {
        return;
    }
    present_weight = 0.0;
    for (var i = 0u; i < BUILD_COMPONENTS / 4u; i++) {
        sums[i] = vec4<f32>(0.0);
    }
    let result = march_pixel(gid.xy + replay.rect.xy);
    let pixels = replay.components.w;
    let p = gid.x + gid.y * replay.rect.z;
    let k0 = replay.components.x;
    if k0 == 0u {
        cache[p] = bitcast<u32>(present_weight);
        cache[pixels + p] = bitcast<u32>(result.color.a);
    }
    // The relight reads no C_pk where W_p = 0.
    var n = replay.components.y;
    if present_weight <= 0.0 {
        n = 0u;
    }
    for (var i = 0u; i < (n + 1u) / 2u; i++) {
        let k = k0 + 2u * i;
        let pair = select(sums[i / 2u].xy, sums[i / 2u].zw, (i & 1u) == 1u);
        let d0 = dequantization[k];
        let d1 = dequantization[min(k + 1u, replay.coefficients.w - 1u)];
        let c = vec2<f32>(d0.x, d1.x) * present_weight + vec2<f32>(d0.y, d1.y) * pair;
        cache[(2u + k / 2u) * pixels + p] = pack_halves(c.x, c.y);
    }
}

// The cache again, read-only, for the relight's fragment entry (its own binding: the
// build's is writable).
@group(1) @binding(5) var<storage, read> cache_read: array<u32>;

// A full-screen triangle over the frame's image (vertex entry `march_vs`, march_core.wgsl;
// llvmpipe's rasteriser writes its tiles faster than per-invocation storage stores): per
// pixel C_p = W_p P_mean + Σ_k C_pk P_k, with the stored alpha; 0 outside the rectangle.
@fragment
fn replay_fs(@builtin(position) position: vec4<f32>) -> @location(0) vec4<f32> {
    let pixels = replay.components.w;
    let p = cached_pixel(vec2<u32>(position.xy));
    if p >= pixels {
        return vec4<f32>(0.0);
    }
    let weight = bitcast<f32>(cache_read[p]);
    var rgb = vec3<f32>(0.0);
    if weight > 0.0 {
        rgb = weight * replay.light_mean.xyz;
        for (var j = 0u; j < (replay.components.z + 1u) / 2u; j++) {
            let c = halves(cache_read[(2u + j) * pixels + p]);
            rgb += c.x * light[2u * j].xyz + c.y * light[2u * j + 1u].xyz;
        }
    }
    return vec4<f32>(rgb, bitcast<f32>(cache_read[pixels + p]));
}

// The same as a compute entry (faster on GPUs, whose fragment march is slower than their
// compute march; viewer/src/gpu/march.rs, `MarchPass::for_device`) over the whole image:
// one invocation per four pixels in a row, so each load of the lighting serves four (a
// CPU device loads a loop-indexed uniform lane by lane).
@compute @workgroup_size(8, 8, 1)
fn replay_relight(@builtin(global_invocation_id) gid: vec3<u32>) {
    let width = params.image.x;
    let x0 = 4u * gid.x;
    if x0 >= width || gid.y >= params.image.y {
        return;
    }
    let pixels = replay.components.w;
    // Outside the rectangle (or past the row's end) a pixel reads cache entry 0 with
    // weight 0 and is stored as 0 (or not at all).
    var p = vec4<u32>(0u);
    var inside = vec4<bool>(false);
    for (var i = 0u; i < 4u; i++) {
        let q = cached_pixel(vec2<u32>(x0 + i, gid.y));
        inside[i] = q < pixels;
        p[i] = select(0u, q, q < pixels);
    }
    let weight = select(vec4<f32>(0.0), vec4<f32>(bitcast<f32>(cache[p.x]), bitcast<f32>(cache[p.y]),
        bitcast<f32>(cache[p.z]), bitcast<f32>(cache[p.w])), inside);
    let mean = replay.light_mean.xyz;
    var r = array<vec3<f32>, 4>(weight.x * mean, weight.y * mean, weight.z * mean, weight.w * mean);
    if any(weight > vec4<f32>(0.0)) {
        for (var j = 0u; j < (replay.components.z + 1u) / 2u; j++) {
            let l0 = light[2u * j].xyz;
            let l1 = light[2u * j + 1u].xyz;
            let base = (2u + j) * pixels;
            let a = halves(cache[base + p.x]);
            let b = halves(cache[base + p.y]);
            let c = halves(cache[base + p.z]);
            let d = halves(cache[base + p.w]);
            r[0] += a.x * l0 + a.y * l1;
            r[1] += b.x * l0 + b.y * l1;
            r[2] += c.x * l0 + c.y * l1;
            r[3] += d.x * l0 + d.y * l1;
        }
    }
    for (var i = 0u; i < 4u; i++) {
        if x0 + i < width {
            let alpha = select(0.0, bitcast<f32>(cache[pixels + p[i]]), inside[i]);
            textureStore(output, vec2<i32>(vec2<u32>(x0 + i, gid.y)), vec4<f32>(select(vec3<f32>(0.0), r[i], inside[i]), alpha));
        }
    }
}
