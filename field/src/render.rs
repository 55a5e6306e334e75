//! Volume rendering of the network (official `NelfFt.forward`; NeRF-style
//! hierarchical sampling, Mildenhall et al. 2020), in millimetres:
//!
//! * rays `[origin, unit dir, near, far]` with `near/far = |cam − head| ∓ r`;
//! * coarse depths `z_k = (k + u_k)/N_c`, `d = near·(1 − z) + far·z`, shaded by the
//!   coarse network;
//! * compositing with `δ_0 = d_1 − d_0`, `δ_i = (d_{i+1} − d_{i−1})/2`,
//!   `δ_last = d_last − d_{last−1}`, `α_i = 1 − e^{−σ_i δ_i}`, `T_i = e^{−Σ_{j<i} σ_j δ_j}`,
//!   `w_i = α_i T_i`; colour `Σ w c`, depth `Σ w d / (1 − T_end + 10⁻⁶)`, alpha
//!   `1 − T_end`, no background;
//! * fine depths by inverting the CDF of `w + 10⁻⁵` over `N_c` uniform bins of
//!   `[near, far]`: `idx = max(searchsorted_right(cdf, u) − 1, 0)`,
//!   `z = (idx + jitter)/N_c`; the `N_f` new depths join the coarse ones, sorted, and
//!   all are shaded by the fine network and composited.

use glam::DVec3;
use indicatif::ProgressBar;
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

use crate::error::NetError;
use crate::geometry::NetCamera;
use crate::model::Model;
use crate::views::{EncodedViews, Stage};

/// A ray in the network's world (millimetres).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NetRay {
    /// Origin (the target camera centre).
    pub origin: [f32; 3],
    /// Unit direction.
    pub dir: [f32; 3],
    /// Nearest depth sampled.
    pub near: f32,
    /// Farthest depth sampled.
    pub far: f32,
}

impl NetRay {
    /// The ray of `camera` through continuous pixel coordinates `(x, y)`, bounded by
    /// the sphere of radius `radius_mm` around `head_centre`: `near/far = |c − head| ∓ r`.
    /// (The official `pix_to_ray` passes integer pixel coordinates; pixel centres
    /// are at `+0.5`.)
    pub fn through_pixel(camera: &NetCamera, x: f64, y: f64, head_centre: [f32; 3], radius_mm: f32) -> Self {
        let dir = camera.ray_direction(x, y);
        let c = camera.centre();
        let dist =
            DVec3::from_array(c.map(f64::from)).distance(DVec3::from_array(head_centre.map(f64::from)));
        Self {
            origin: c,
            dir: dir.as_vec3().to_array(),
            near: (dist - f64::from(radius_mm)) as f32,
            far: (dist + f64::from(radius_mm)) as f32,
        }
    }

    /// The official 8-vector `[origin, dir, near, far]`.
    pub fn from_array(a: [f32; 8]) -> Self {
        Self {
            origin: [a[0], a[1], a[2]],
            dir: [a[3], a[4], a[5]],
            near: a[6],
            far: a[7],
        }
    }

    /// The point at `depth`.
    pub fn at(&self, depth: f32) -> [f32; 3] {
        std::array::from_fn(|k| self.origin[k] + self.dir[k] * depth)
    }

    /// `−dir`: from a point on the ray toward the camera.
    pub fn toward_camera(&self) -> [f32; 3] {
        self.dir.map(|v| -v)
    }
}

/// The uniforms of hierarchical sampling, per ray (row-major `(R, n)`).
#[derive(Debug, Clone, PartialEq)]
pub struct RayUniforms {
    /// `(R, N_c)` coarse jitter in `[0, 1)`.
    pub coarse_jitter: Vec<f32>,
    /// `(R, N_f)` CDF levels in `[0, 1)`.
    pub fine_u: Vec<f32>,
    /// `(R, N_f)` jitter inside the chosen bins.
    pub fine_jitter: Vec<f32>,
}

impl RayUniforms {
    /// Deterministic, noise-free sampling: bin mid-points and evenly spaced CDF
    /// levels `(k + ½)/N_f`.
    pub fn stratified(rays: usize, coarse: usize, fine: usize) -> Self {
        Self {
            coarse_jitter: vec![0.5; rays * coarse],
            fine_u: (0..rays * fine)
                .map(|i| ((i % fine) as f32 + 0.5) / fine as f32)
                .collect(),
            fine_jitter: vec![0.5; rays * fine],
        }
    }

    /// Uniform random numbers from a seeded generator (as the official sampler).
    pub fn random(rays: usize, coarse: usize, fine: usize, seed: u64) -> Self {
        let mut rng = Pcg64::seed_from_u64(seed);
        let mut draw = |n: usize| (0..n).map(|_| rng.random::<f32>()).collect::<Vec<f32>>();
        Self {
            coarse_jitter: draw(rays * coarse),
            fine_u: draw(rays * fine),
            fine_jitter: draw(rays * fine),
        }
    }
}

/// One composited pass over `R` rays of `S` samples.
#[derive(Debug, Clone, PartialEq)]
pub struct Composite {
    /// Samples per ray.
    pub samples: usize,
    /// `(R, S)` depths (mm).
    pub depth_samples: Vec<f32>,
    /// `(R, S)` σ (1/mm).
    pub sigma: Vec<f32>,
    /// `(R, S, 3)` colours.
    pub rgb_samples: Vec<f32>,
    /// `(R, S)` compositing weights.
    pub weights: Vec<f32>,
    /// `(R, 3)` rendered colour.
    pub rgb: Vec<f32>,
    /// `(R)` rendered depth (mm).
    pub depth: Vec<f32>,
    /// `(R)` accumulated opacity.
    pub alpha: Vec<f32>,
}

/// Both passes of a render.
#[derive(Debug, Clone, PartialEq)]
pub struct RenderOutput {
    /// The coarse pass.
    pub coarse: Composite,
    /// `(R, N_f)` the importance-sampled depths, in drawing order.
    pub fine_new_depth_samples: Vec<f32>,
    /// The fine pass over the sorted union of coarse and new depths.
    pub fine: Composite,
}

/// The length `δ_i` each sample of a ray stands for (module docs): `d_1 − d_0` for
/// the first, `d_last − d_{last−1}` for the last, `(d_{i+1} − d_{i−1})/2` between;
/// 0 for a ray of fewer than two samples.
pub fn sample_delta(depths: &[f32], i: usize) -> f32 {
    let n = depths.len();
    if n < 2 {
        0.0
    } else if i == 0 {
        depths[1] - depths[0]
    } else if i == n - 1 {
        depths[n - 1] - depths[n - 2]
    } else {
        (depths[i + 1] - depths[i - 1]) / 2.0
    }
}

/// Composites one ray: returns the weights and `(rgb, depth, alpha)`.
pub fn composite_ray(depths: &[f32], sigma: &[f32], rgb: &[f32]) -> (Vec<f32>, [f32; 3], f32, f32) {
    let n = depths.len();
    let delta = |i: usize| sample_delta(depths, i);
    let mut weights = Vec::with_capacity(n);
    let mut optical = 0.0f32;
    let (mut c, mut d) = ([0.0f64; 3], 0.0f64);
    for i in 0..n {
        let a = delta(i) * sigma[i];
        let alpha = 1.0 - (-a).exp();
        let w = alpha * (-optical).exp();
        optical += a;
        weights.push(w);
        for k in 0..3 {
            c[k] += f64::from(w) * f64::from(rgb[3 * i + k]);
        }
        d += f64::from(w) * f64::from(depths[i]);
    }
    let alpha = 1.0 - (-optical).exp();
    let depth = (d / (f64::from(1.0 - (-optical).exp()) + 1e-6)) as f32;
    (weights, c.map(|v| v as f32), depth, alpha)
}

/// The importance-sampled depths of one ray from its coarse `weights` (`N_c` bins of
/// `[near, far]`), levels `u` and `jitter` (module docs).
pub fn importance_depths(weights: &[f32], near: f32, far: f32, u: &[f32], jitter: &[f32]) -> Vec<f32> {
    let bins = weights.len();
    let total: f32 = weights.iter().map(|w| w + 1e-5).sum();
    let mut cdf = Vec::with_capacity(bins + 1);
    cdf.push(0.0f32);
    let mut acc = 0.0f32;
    for w in weights {
        acc += (w + 1e-5) / total;
        cdf.push(acc);
    }
    u.iter()
        .zip(jitter)
        .map(|(&level, &j)| {
            let count = cdf.partition_point(|&c| c <= level);
            let idx = count.saturating_sub(1);
            let z = (idx as f32 + j) / bins as f32;
            near * (1.0 - z) + far * z
        })
        .collect()
}

fn composite_all(
    rays: usize,
    samples: usize,
    depth_samples: Vec<f32>,
    sigma: Vec<f32>,
    rgb_samples: Vec<f32>,
) -> Composite {
    let mut out = Composite {
        samples,
        weights: Vec::with_capacity(rays * samples),
        rgb: Vec::with_capacity(rays * 3),
        depth: Vec::with_capacity(rays),
        alpha: Vec::with_capacity(rays),
        depth_samples,
        sigma,
        rgb_samples,
    };
    for r in 0..rays {
        let s = r * samples..(r + 1) * samples;
        let (w, c, d, a) = composite_ray(
            &out.depth_samples[s.clone()],
            &out.sigma[s],
            &out.rgb_samples[3 * r * samples..3 * (r + 1) * samples],
        );
        out.weights.extend(w);
        out.rgb.extend(c);
        out.depth.push(d);
        out.alpha.push(a);
    }
    out
}

/// Renders `rays` through the coarse and fine networks under the network-layout
/// light `light` (`(3, 8, 16)` radiance) with the given sampling uniforms.
pub fn render_rays(
    model: &Model,
    encoded: &EncodedViews,
    rays: &[NetRay],
    uniforms: &RayUniforms,
    light: &[f32],
) -> Result<RenderOutput, NetError> {
    let (nc, nf) = (model.config().coarse_samples, model.config().fine_samples);
    let r = rays.len();
    if uniforms.coarse_jitter.len() != r * nc
        || uniforms.fine_u.len() != r * nf
        || uniforms.fine_jitter.len() != r * nf
    {
        return Err(NetError::input(format!(
            "uniforms for {r} rays of {nc}+{nf} samples have the wrong lengths"
        )));
    }
    let mut coarse_depths = Vec::with_capacity(r * nc);
    for (i, ray) in rays.iter().enumerate() {
        for k in 0..nc {
            let z = k as f32 / nc as f32 + uniforms.coarse_jitter[i * nc + k] / nc as f32;
            coarse_depths.push(ray.near * (1.0 - z) + ray.far * z);
        }
    }
    let shade = |depths: &[f32], per_ray: usize, stage: Stage| {
        let points: Vec<[f32; 3]> = depths
            .iter()
            .enumerate()
            .map(|(i, &d)| rays[i / per_ray].at(d))
            .collect();
        let dirs: Vec<[f32; 3]> = (0..depths.len())
            .map(|i| rays[i / per_ray].toward_camera())
            .collect();
        model.shade_points(encoded, &points, &dirs, stage, light)
    };
    let coarse_values = shade(&coarse_depths, nc, Stage::Coarse)?;
    let coarse = composite_all(r, nc, coarse_depths, coarse_values.sigma, coarse_values.values);
    let mut fine_new = Vec::with_capacity(r * nf);
    let mut fine_depths = Vec::with_capacity(r * (nc + nf));
    for (i, ray) in rays.iter().enumerate() {
        let new = importance_depths(
            &coarse.weights[i * nc..(i + 1) * nc],
            ray.near,
            ray.far,
            &uniforms.fine_u[i * nf..(i + 1) * nf],
            &uniforms.fine_jitter[i * nf..(i + 1) * nf],
        );
        let mut all: Vec<f32> = coarse.depth_samples[i * nc..(i + 1) * nc].to_vec();
        all.extend_from_slice(&new);
        all.sort_by(f32::total_cmp);
        fine_new.extend(new);
        fine_depths.extend(all);
    }
    let fine_values = shade(&fine_depths, nc + nf, Stage::Fine)?;
    let fine = composite_all(r, nc + nf, fine_depths, fine_values.sigma, fine_values.values);
    Ok(RenderOutput {
        coarse,
        fine_new_depth_samples: fine_new,
        fine,
    })
}

/// How a full image's rays are sampled.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Sampling {
    /// [`RayUniforms::stratified`].
    Stratified,
    /// [`RayUniforms::random`] with this seed.
    Random(u64),
}

/// A rendered image (row-major, `width × height`).
#[derive(Debug, Clone, PartialEq)]
pub struct NetImage {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Linear RGB per pixel (fine pass, no background).
    pub rgb: Vec<[f32; 3]>,
    /// Accumulated opacity per pixel.
    pub alpha: Vec<f32>,
    /// Depth per pixel, millimetres.
    pub depth_mm: Vec<f32>,
}

/// How [`render_image`] samples and batches.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ImageSettings {
    /// Centre of the sphere bounding the rays (the head), millimetres.
    pub head_centre: [f32; 3],
    /// Sampling uniforms.
    pub sampling: Sampling,
    /// Rays rendered together (bounds memory with the model's batch size).
    pub rays_per_chunk: usize,
}

impl Default for ImageSettings {
    fn default() -> Self {
        Self {
            head_centre: [0.0; 3],
            sampling: Sampling::Stratified,
            rays_per_chunk: 512,
        }
    }
}

/// Renders every pixel of `camera` (rays through pixel centres) under the
/// network-layout light `light`, ticking `progress` by rays.
pub fn render_image(
    model: &Model,
    encoded: &EncodedViews,
    camera: &NetCamera,
    light: &[f32],
    settings: &ImageSettings,
    progress: Option<&ProgressBar>,
) -> Result<NetImage, NetError> {
    camera.validate()?;
    let (w, h) = (camera.width, camera.height);
    let (nc, nf) = (model.config().coarse_samples, model.config().fine_samples);
    let radius = model.config().head_radius_mm;
    let head_centre = settings.head_centre;
    let rays: Vec<NetRay> = (0..w * h)
        .map(|p| {
            NetRay::through_pixel(
                camera,
                (p % w) as f64 + 0.5,
                (p / w) as f64 + 0.5,
                head_centre,
                radius,
            )
        })
        .collect();
    if let Some(pb) = progress {
        pb.set_length(rays.len() as u64);
    }
    let mut image = NetImage {
        width: w,
        height: h,
        rgb: Vec::with_capacity(w * h),
        alpha: Vec::with_capacity(w * h),
        depth_mm: Vec::with_capacity(w * h),
    };
    for (c, chunk) in rays.chunks(settings.rays_per_chunk.max(1)).enumerate() {
        let uniforms = match settings.sampling {
            Sampling::Stratified => RayUniforms::stratified(chunk.len(), nc, nf),
            Sampling::Random(seed) => RayUniforms::random(
                chunk.len(),
                nc,
                nf,
                seed ^ (c as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15),
            ),
        };
        let out = render_rays(model, encoded, chunk, &uniforms, light)?;
        image
            .rgb
            .extend(out.fine.rgb.chunks(3).map(|v| [v[0], v[1], v[2]]));
        image.alpha.extend(out.fine.alpha);
        image.depth_mm.extend(out.fine.depth);
        if let Some(pb) = progress {
            pb.inc(chunk.len() as u64);
        }
    }
    Ok(image)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn opaque_wall_composites_to_its_colour_and_depth() {
        let depths: Vec<f32> = (0..64).map(|k| 900.0 + k as f32 * 3.0).collect();
        let sigma: Vec<f32> = depths
            .iter()
            .map(|&d| if d >= 1000.0 { 50.0 } else { 0.0 })
            .collect();
        let rgb: Vec<f32> = (0..64).flat_map(|_| [0.2f32, 0.4, 0.6]).collect();
        let (w, c, d, a) = composite_ray(&depths, &sigma, &rgb);
        assert!((a - 1.0).abs() < 1e-6);
        assert!((c[1] - 0.4).abs() < 1e-5);
        let first = depths.iter().position(|&x| x >= 1000.0).unwrap();
        assert!((d - depths[first]).abs() < 1e-3, "{d}");
        assert!(w[..first].iter().all(|&x| x == 0.0));
    }

    #[test]
    fn importance_samples_follow_the_weights() {
        let mut weights = vec![0.0f32; 64];
        weights[40] = 1.0;
        let u: Vec<f32> = (0..128).map(|k| (k as f32 + 0.5) / 128.0).collect();
        let j = vec![0.5f32; 128];
        let d = importance_depths(&weights, 0.0, 64.0, &u, &j);
        let in_bin = d.iter().filter(|&&x| (40.0..41.0).contains(&x)).count();
        // All but the 1e-5 floor's share (64e-5/(1+64e-5) of the mass) land in bin 40.
        assert!(in_bin >= 127, "{in_bin}");
    }
}
