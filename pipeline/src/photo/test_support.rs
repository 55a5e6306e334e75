//! Test helpers shared by the photographs stages' tests: a convex surface's
//! observations under a sun and sky, computed in closed form.

use glam::DVec3;
use nelf_format::conventions::{
    ENV_H, ENV_TEXELS, ENV_W, LatLong, texel_center_direction, texel_solid_angle,
};

use crate::photo::reflectance::Observations;

/// The direction through the centre of texel `k` (row-major).
pub(crate) fn texel_direction(k: usize) -> DVec3 {
    texel_center_direction(k / ENV_W, k % ENV_W, ENV_H, ENV_W)
}

/// A white Lambertian surface's transport per texel at normal `n` without
/// shadows: `Ω_k max(0, n·d_k) / π`.
pub(crate) fn convex_transport(n: DVec3) -> Vec<f32> {
    (0..ENV_TEXELS)
        .map(|k| {
            let omega = texel_solid_angle(k / ENV_W, ENV_H, ENV_W);
            (omega * n.dot(texel_direction(k)).max(0.0) / std::f64::consts::PI) as f32
        })
        .collect()
}

/// A sun in texel `sun` (radiance 20) over a dim uniform sky (0.05), grey.
pub(crate) fn sun_and_sky(sun: usize) -> LatLong {
    let mut texels = vec![[0.05f32; 3]; ENV_TEXELS];
    texels[sun] = [20.0; 3];
    LatLong::new(ENV_W, ENV_H, texels).expect("8 x 16")
}

/// What the views see of a convex surface (no shadows) with these normals and
/// albedos under the grey `light`: each point's colour and white transport.
pub(crate) fn convex_observations(
    points: impl IntoIterator<Item = (DVec3, [f32; 3])>,
    light: &LatLong,
) -> Observations {
    let (colour, transport) = points
        .into_iter()
        .map(|(n, albedo)| {
            let t = convex_transport(n);
            let shading: f32 = t.iter().zip(light.texels()).map(|(t, l)| t * l[0]).sum();
            (Some(albedo.map(|a| a * shading)), t)
        })
        .unzip();
    Observations {
        colour,
        transport,
        seconds: 0.0,
    }
}
