//! Measures the NeLF network on a capture (`field/README.md`, "Measurements"):
//! encoder time per view, per-point throughput of the coarse and fine networks,
//! the time to evaluate the field source on every voxel centre of a grid over the
//! hull box, and the PSNR of renders of that baked grid against direct network
//! renders of novel views, for several view policies.
//!
//! ```text
//! cargo run --release -p nelf-field --example field_bench -- \
//!     --capture CAPTURE_DIR --weights W.safetensors [--grid 128] [--render-size 64] \
//!     [--policies mean-camera,average-cameras,target] [--views 3]
//! ```
//!
//! The baked grid stores σ and the colour `T·L` under the network's own estimate of
//! the capture's lighting (storing `T` itself would be 384 floats per voxel;
//! `T·L` interpolates the same, as shading is linear). Baked renders march the grid
//! (trilinear σ and colour, half-voxel steps, the network's compositing, the same
//! near/far); direct renders are `nelf_field::render::render_rays` through pixel centres (stratified
//! coarse + fine samples). Before baking, each policy is also applied at the direct
//! render's own samples (the field source's σ and `T·L`, composited the same way):
//! that isolates the policy's error from the grid's. `target` is the oracle policy (toward the target camera
//! itself, one bake per view): it isolates the grid's error from the policy's.

use std::path::PathBuf;
use std::time::Instant;

use clap::Parser;
use glam::{DVec3, Vec3};
use nelf_field::capture::{MM_PER_M, NetCapture, default_net_from_world, load_capture_dir};
use nelf_field::light::net_light_to_latlong;
use nelf_field::render::{NetRay, RayUniforms, composite_ray, render_rays};
use nelf_field::{Model, NelfConfig, NelfField, Stage};
use nelf_format::conventions::{LT_DIM, LatLong, PinholeCamera, shade};
use nelf_scene::field::{FieldSource, ViewPolicy};
use nelf_scene::metrics::psnr;

#[derive(Debug, Parser)]
struct Args {
    /// Capture folder (cameras.json).
    #[arg(long)]
    capture: PathBuf,
    /// Weights (safetensors, official key names).
    #[arg(long)]
    weights: PathBuf,
    /// Voxels along the longest side of the hull box.
    #[arg(long, default_value_t = 128)]
    grid: usize,
    /// Side of the novel-view renders, pixels.
    #[arg(long, default_value_t = 64)]
    render_size: u32,
    /// Novel views compared (the capture's targets first, then cameras between source views).
    #[arg(long, default_value_t = 3)]
    views: usize,
    /// Policies: mean-camera, average-cameras, target (comma-separated).
    #[arg(long, default_value = "mean-camera,average-cameras,target")]
    policies: String,
    /// Points per throughput measurement.
    #[arg(long, default_value_t = 16384)]
    points: usize,
    /// Skip the bake and the renders (timings of the encoder and networks only).
    #[arg(long)]
    timings_only: bool,
}

/// A baked grid: σ (1/m) and colour per voxel centre.
struct BakedGrid {
    origin: DVec3,
    voxel_m: f64,
    dims: [usize; 3],
    sigma: Vec<f32>,
    rgb: Vec<[f32; 3]>,
}

impl BakedGrid {
    fn sample(&self, p: DVec3) -> (f32, [f32; 3]) {
        let q = (p - self.origin) / self.voxel_m - 0.5;
        let base = q.floor();
        let f = q - base;
        let mut sigma = 0.0f32;
        let mut rgb = [0.0f32; 3];
        for corner in 0..8 {
            let o = [corner & 1, (corner >> 1) & 1, (corner >> 2) & 1];
            let idx = [
                base.x as i64 + o[0] as i64,
                base.y as i64 + o[1] as i64,
                base.z as i64 + o[2] as i64,
            ];
            if (0..3).any(|k| idx[k] < 0 || idx[k] >= self.dims[k] as i64) {
                continue;
            }
            let w = (if o[0] == 1 { f.x } else { 1.0 - f.x })
                * (if o[1] == 1 { f.y } else { 1.0 - f.y })
                * (if o[2] == 1 { f.z } else { 1.0 - f.z });
            let i = (idx[2] as usize * self.dims[1] + idx[1] as usize) * self.dims[0] + idx[0] as usize;
            sigma += w as f32 * self.sigma[i];
            for (acc, v) in rgb.iter_mut().zip(self.rgb[i]) {
                *acc += w as f32 * v;
            }
        }
        (sigma, rgb)
    }

    /// Ray-marches `camera` between the network's near and far (head sphere).
    fn render(&self, camera: &PinholeCamera, head_m: DVec3, radius_m: f64) -> Vec<[f32; 3]> {
        let step = 0.5 * self.voxel_m;
        let mut out = Vec::with_capacity((camera.width * camera.height) as usize);
        for v in 0..camera.height {
            for u in 0..camera.width {
                let (o, d) = camera.pixel_ray(u, v);
                let dist = (o - head_m).length();
                let (near, far) = (dist - radius_m, dist + radius_m);
                let steps = ((far - near) / step).ceil() as usize;
                let mut transmittance = 1.0f32;
                let mut rgb = [0.0f32; 3];
                for k in 0..steps {
                    let (s, c) = self.sample(o + d * (near + (k as f64 + 0.5) * step));
                    if s <= 0.0 {
                        continue;
                    }
                    let alpha = 1.0 - (-s * step as f32).exp();
                    for ch in 0..3 {
                        rgb[ch] += transmittance * alpha * c[ch];
                    }
                    transmittance *= 1.0 - alpha;
                    if transmittance < 1e-4 {
                        break;
                    }
                }
                out.push(rgb);
            }
        }
        out
    }
}

fn bake(
    field: &NelfField,
    policy: &ViewPolicy,
    grid: usize,
    light: &LatLong,
) -> anyhow::Result<(BakedGrid, f64, usize)> {
    let (lo, hi) = field.bounds();
    let extent = (hi - lo).as_dvec3();
    let voxel_m = extent.max_element() / grid as f64;
    let dims = [0, 1, 2].map(|k| ((extent[k] / voxel_m).ceil() as usize).max(1));
    let origin = lo.as_dvec3();
    let total = dims[0] * dims[1] * dims[2];
    let mut sigma = vec![0.0f32; total];
    let mut rgb = vec![[0.0f32; 3]; total];
    let start = Instant::now();
    let chunk = 65_536;
    let mut density = vec![0.0f32; chunk];
    let mut lt = vec![0.0f32; chunk * LT_DIM];
    let mut inside = 0usize;
    for first in (0..total).step_by(chunk) {
        let n = chunk.min(total - first);
        let points: Vec<Vec3> = (first..first + n)
            .map(|i| {
                let (x, y, z) = (i % dims[0], (i / dims[0]) % dims[1], i / (dims[0] * dims[1]));
                (origin + (DVec3::new(x as f64, y as f64, z as f64) + 0.5) * voxel_m).as_vec3()
            })
            .collect();
        field.evaluate(&points, policy, &mut density[..n], &mut lt[..n * LT_DIM])?;
        for k in 0..n {
            sigma[first + k] = density[k];
            rgb[first + k] = shade(&lt[k * LT_DIM..(k + 1) * LT_DIM], light);
            inside += usize::from(density[k] > 0.0);
        }
    }
    let secs = start.elapsed().as_secs_f64();
    Ok((
        BakedGrid {
            origin,
            voxel_m,
            dims,
            sigma,
            rgb,
        },
        secs,
        inside,
    ))
}

/// Re-renders rays at given fine depths with the field source (policy `view`):
/// σ and `T·L` per sample, composited as the network's renderer does.
fn shade_samples(
    field: &NelfField,
    capture: &NetCapture,
    per_ray: &[(NetRay, Vec<f32>)],
    view: &ViewPolicy,
    light: &LatLong,
) -> anyhow::Result<Vec<[f32; 3]>> {
    let world_from_net = capture.net_from_world.transpose();
    let mut image = Vec::with_capacity(per_ray.len());
    for chunk in per_ray.chunks(256) {
        let points: Vec<Vec3> = chunk
            .iter()
            .flat_map(|(ray, depths)| depths.iter().map(move |&d| ray.at(d)))
            .map(|x| (world_from_net * DVec3::from_array(x.map(f64::from)) / MM_PER_M).as_vec3())
            .collect();
        let mut density = vec![0.0f32; points.len()];
        let mut lt = vec![0.0f32; points.len() * LT_DIM];
        field.evaluate(&points, view, &mut density, &mut lt)?;
        let mut offset = 0;
        for (_, depths) in chunk {
            let n = depths.len();
            let sigma_mm: Vec<f32> = density[offset..offset + n]
                .iter()
                .map(|s| s / MM_PER_M as f32)
                .collect();
            let rgb: Vec<f32> = (offset..offset + n)
                .flat_map(|k| shade(&lt[k * LT_DIM..(k + 1) * LT_DIM], light))
                .collect();
            image.push(composite_ray(depths, &sigma_mm, &rgb).1);
            offset += n;
        }
    }
    Ok(image)
}

/// Novel cameras: the capture's targets, then cameras half-way between neighbouring source views.
fn novel_cameras(
    capture: &NetCapture,
    targets: &[PinholeCamera],
    count: usize,
    size: u32,
) -> Vec<PinholeCamera> {
    let mut cams: Vec<PinholeCamera> = targets.to_vec();
    let src = &capture.cameras;
    let mut i = 0;
    while cams.len() < count && i + 1 < src.len() {
        let eye = 0.5 * (src[i].centre() + src[i + 1].centre());
        let up = -(0.5 * (src[i].rotation.row(1) + src[i + 1].rotation.row(1)));
        let mut cam =
            PinholeCamera::look_at(eye, capture.head_centre_m, up, src[0].width, src[0].height, 0.5);
        cam.fx = src[0].fx;
        cam.fy = src[0].fy;
        cams.push(cam);
        i += 1;
    }
    cams.truncate(count);
    cams.iter()
        .map(|c| {
            let (sx, sy) = (
                f64::from(size) / f64::from(c.width),
                f64::from(size) / f64::from(c.height),
            );
            PinholeCamera {
                width: size,
                height: size,
                fx: c.fx * sx,
                fy: c.fy * sy,
                cx: c.cx * sx,
                cy: c.cy * sy,
                ..*c
            }
        })
        .collect()
}

fn main() -> anyhow::Result<()> {
    let args = Args::parse();
    let (capture, description) = load_capture_dir(&args.capture, default_net_from_world())?;
    let device = candle_core::Device::Cpu;
    let model = Model::load(&args.weights, NelfConfig::default(), &device)?;
    let v = capture.cameras.len();
    println!(
        "capture: {v} views of {}×{}, threads {}",
        capture.views.width,
        capture.views.height,
        rayon::current_num_threads()
    );

    // Encoder (second run, warm).
    let _ = model.encode(&capture.views)?;
    let start = Instant::now();
    let encoded = model.encode(&capture.views)?;
    let enc_ms = start.elapsed().as_secs_f64() * 1e3;
    println!(
        "encoder: {enc_ms:.0} ms for {v} views = {:.0} ms per view",
        enc_ms / v as f64
    );

    let field = NelfField::from_encoded(model.clone(), encoded, &capture)?;
    let (lo, hi) = field.bounds();
    println!("hull box: {lo} .. {hi} m");

    // Per-point throughput on in-hull points.
    let mut points_net = Vec::new();
    let mut k = 0u64;
    while points_net.len() < args.points && k < 50_000_000 {
        let h = |s: u64| ((s.wrapping_mul(0x9E37_79B9_7F4A_7C15) >> 11) as f64) / (1u64 << 53) as f64;
        let p = lo.as_dvec3() + (hi - lo).as_dvec3() * DVec3::new(h(3 * k), h(3 * k + 1), h(3 * k + 2));
        let net = capture.to_net_point(p);
        if field.encoded().in_hull(net) {
            points_net.push(net);
        }
        k += 1;
    }
    let eye = capture.to_net_point(capture.cameras[0].centre());
    let dirs: Vec<[f32; 3]> = points_net
        .iter()
        .map(|p| {
            let d = DVec3::new(
                f64::from(eye[0] - p[0]),
                f64::from(eye[1] - p[1]),
                f64::from(eye[2] - p[2]),
            )
            .normalize();
            d.as_vec3().to_array()
        })
        .collect();
    let n = points_net.len();
    let start = Instant::now();
    let _ = field.encoded().gather(&points_net, &dirs, Stage::Fine)?;
    let gather_s = start.elapsed().as_secs_f64();
    println!("gather ({v} views): {:.0} points/s", n as f64 / gather_s);
    let light_net = field.encoded().light().source_light.clone();
    for stage in [Stage::Coarse, Stage::Fine] {
        let _ = model.shade_points(
            field.encoded(),
            &points_net[..n.min(2048)],
            &dirs[..n.min(2048)],
            stage,
            &light_net,
        )?;
        let start = Instant::now();
        let _ = model.shade_points(field.encoded(), &points_net, &dirs, stage, &light_net)?;
        let s = start.elapsed().as_secs_f64();
        let start = Instant::now();
        let _ = model.light_transport_points(field.encoded(), &points_net, &dirs, stage)?;
        let t = start.elapsed().as_secs_f64();
        println!(
            "{} network ({v} views, {n} points): shading {:.0} points/s, light transport {:.0} points/s",
            stage.name(),
            n as f64 / s,
            n as f64 / t
        );
    }
    if args.timings_only {
        return Ok(());
    }

    // Novel views: direct network renders under the capture's estimated light.
    let light = net_light_to_latlong(&light_net)?;
    let targets: Vec<PinholeCamera> = description.targets.iter().map(|t| t.camera).collect();
    let cams = novel_cameras(&capture, &targets, args.views, args.render_size);
    let head_net = capture.head_centre_net();
    let radius_m = f64::from(model.config().head_radius_mm) / MM_PER_M;
    let mut direct = Vec::new();
    let mut samples: Vec<Vec<(NetRay, Vec<f32>)>> = Vec::new();
    let radius_mm = model.config().head_radius_mm;
    let (nc, nf) = (model.config().coarse_samples, model.config().fine_samples);
    for (i, cam) in cams.iter().enumerate() {
        let start = Instant::now();
        let net_cam = capture.net_camera(cam);
        let rays: Vec<NetRay> = (0..cam.width * cam.height)
            .map(|p| {
                let (u, w) = (f64::from(p % cam.width) + 0.5, f64::from(p / cam.width) + 0.5);
                NetRay::through_pixel(&net_cam, u, w, head_net, radius_mm)
            })
            .collect();
        let mut rgb = Vec::with_capacity(rays.len());
        let mut per_ray = Vec::with_capacity(rays.len());
        for chunk in rays.chunks(512) {
            let uniforms = RayUniforms::stratified(chunk.len(), nc, nf);
            let out = render_rays(&model, field.encoded(), chunk, &uniforms, &light_net)?;
            rgb.extend(out.fine.rgb.chunks(3).map(|c| [c[0], c[1], c[2]]));
            let s = out.fine.samples;
            for (r, ray) in chunk.iter().enumerate() {
                per_ray.push((*ray, out.fine.depth_samples[r * s..(r + 1) * s].to_vec()));
            }
        }
        let max = rgb.iter().flatten().fold(0.0f32, |a, b| a.max(*b));
        println!(
            "direct render {i} ({}², eye {}): {:.1} s, max {max:.4}",
            cam.width,
            cam.centre(),
            start.elapsed().as_secs_f64()
        );
        direct.push(rgb);
        samples.push(per_ray);
    }

    let range_of =
        |img: &[[f32; 3]]| f64::from(img.iter().flatten().fold(0.0f32, |a, b| a.max(*b))).max(1e-6);
    for policy_name in args.policies.split(',') {
        let mean = capture.cameras.iter().map(PinholeCamera::centre).sum::<DVec3>() / v as f64;
        // One bake for every view, or (oracle) one per view.
        let per_view: Vec<ViewPolicy> = match policy_name {
            "mean-camera" => vec![ViewPolicy::TowardPoint(mean.as_vec3())],
            "average-cameras" => vec![field.average_cameras_view_policy()],
            "target" => cams
                .iter()
                .map(|c| ViewPolicy::TowardPoint(c.centre().as_vec3()))
                .collect(),
            other => anyhow::bail!("unknown policy {other}"),
        };
        // Policy alone: the field source at the direct render's own samples.
        let mut policy_scores = Vec::new();
        for (i, per_ray) in samples.iter().enumerate() {
            let policy = &per_view[i.min(per_view.len() - 1)];
            let image = shade_samples(&field, &capture, per_ray, policy, &light)?;
            policy_scores.push(psnr(&image, &direct[i], range_of(&direct[i]))?);
        }
        println!(
            "policy {policy_name}: field-source-at-direct-samples vs direct PSNR {policy_scores:.2?} dB"
        );
        let mut scores = Vec::new();
        let mut secs_total = 0.0;
        for (b, policy) in per_view.iter().enumerate() {
            let (grid, secs, inside) = bake(&field, policy, args.grid, &light)?;
            secs_total += secs;
            println!(
                "bake {policy_name} #{b}: grid {:?} ({:.2} mm voxels), {inside} voxels in the hull, {secs:.1} s",
                grid.dims,
                grid.voxel_m * 1e3
            );
            let views: Vec<usize> = if per_view.len() == 1 {
                (0..cams.len()).collect()
            } else {
                vec![b]
            };
            for i in views {
                let baked = grid.render(&cams[i], capture.head_centre_m, radius_m);
                scores.push(psnr(&baked, &direct[i], range_of(&direct[i]))?);
            }
        }
        let mean_db = scores.iter().sum::<f64>() / scores.len() as f64;
        println!(
            "policy {policy_name}: baked-vs-direct PSNR {scores:.2?} dB (mean {mean_db:.2} dB), bake time {secs_total:.1} s"
        );
    }
    Ok(())
}
