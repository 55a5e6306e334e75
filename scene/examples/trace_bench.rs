//! Measurements of the ground-truth tracer (not a test): BVH ray throughput on a
//! ~61k-triangle mesh, the time of one light-transport image at default samples,
//! the noise of light-transport vectors across seeds, and the agreement of the two
//! independent image estimators.
//!
//! `cargo run --release -p nelf-scene --example trace_bench [-- --size 512 --head PATH --env PATH]`
//!
//! Meshes: a 61k-triangle UV sphere and a procedural head (throughput),
//! and the scanned `data/meshes/head.off` (2,918 triangles, 0.23 m,
//! facing +z) for images and noise; the lighting is an HDR lat-long map projected
//! onto the 8 × 16 basis.

use std::time::Instant;

use glam::{DVec3, Vec3};
use nelf_format::conventions::{LatLong, PinholeCamera, shade};
use nelf_scene::envmap::{envmap_to_basis, load_envmap};
use nelf_scene::head::{HeadParams, procedural_head};
use nelf_scene::mesh::Mesh;
use nelf_scene::mesh_io::{LoadOptions, load_mesh};
use nelf_scene::render::{DirectSettings, RenderedImage, render_direct_image, render_lt_image};
use nelf_scene::shapes::uv_sphere;
use nelf_scene::tracer::{LtTracer, TraceSettings, stream_rng};
use rand::Rng;
use rayon::prelude::*;

type Error = Box<dyn std::error::Error>;

fn masked_psnr(reference: &RenderedImage, test: &RenderedImage) -> f64 {
    let (mut se, mut weight, mut peak) = (0.0f64, 0.0f64, 0.0f64);
    for ((r, t), &a) in reference.rgb.iter().zip(&test.rgb).zip(&reference.alpha) {
        if a > 0.0 {
            for c in 0..3 {
                se += f64::from(a) * f64::from(r[c] - t[c]).powi(2);
                peak = peak.max(f64::from(r[c]));
            }
            weight += 3.0 * f64::from(a);
        }
    }
    10.0 * (peak * peak / (se / weight)).log10()
}

fn random_unit(rng: &mut impl Rng) -> Vec3 {
    loop {
        let v = Vec3::new(rng.random(), rng.random(), rng.random()) * 2.0 - 1.0;
        if v.length_squared() > 1e-4 && v.length_squared() <= 1.0 {
            return v.normalize();
        }
    }
}

fn ray_throughput(mesh: &Mesh, label: &str) -> Result<(), Error> {
    let tracer = LtTracer::new(mesh, TraceSettings::default())?;
    let bvh = tracer.bvh();
    let (lo, hi) = mesh.bounds();
    let (centre, extent) = (0.5 * (lo + hi), (hi - lo).length());
    let n = 2_000_000usize;
    let mut rng = stream_rng(1, 1);
    // Camera-like rays: from a sphere around the mesh toward random points in its box.
    let camera_rays: Vec<(Vec3, Vec3)> = (0..n)
        .map(|_| {
            let o = centre + random_unit(&mut rng) * extent * 1.5;
            let target = lo + (hi - lo) * Vec3::new(rng.random(), rng.random(), rng.random());
            (o, (target - o).normalize())
        })
        .collect();
    // Shadow rays: from surface points (offset by ε) into their upper hemisphere.
    let shadow_rays: Vec<(Vec3, Vec3)> = camera_rays
        .iter()
        .filter_map(|&(o, d)| tracer.intersect(o, d).map(|h| (h, d)))
        .map(|(h, d)| {
            let sp = tracer.surface_at_hit(&h, d);
            let mut w = random_unit(&mut rng);
            if w.dot(sp.geometric_normal) < 0.0 {
                w = -w;
            }
            (sp.position + tracer.ray_epsilon() * sp.geometric_normal, w)
        })
        .collect();
    let time = |f: &dyn Fn() -> usize| {
        let t = Instant::now();
        let hits = f();
        (t.elapsed().as_secs_f64(), hits)
    };
    let inf = f32::INFINITY;
    let (t1, h1) = time(&|| {
        camera_rays
            .iter()
            .filter(|(o, d)| bvh.closest_hit(*o, *d, 0.0, inf).is_some())
            .count()
    });
    let (tp, _) = time(&|| {
        camera_rays
            .par_iter()
            .filter(|(o, d)| bvh.closest_hit(*o, *d, 0.0, inf).is_some())
            .count()
    });
    let m = shadow_rays.len() as f64;
    let (t2, h2) = time(&|| {
        shadow_rays
            .iter()
            .filter(|(o, d)| bvh.any_hit(*o, *d, 0.0, inf))
            .count()
    });
    let (t2p, _) = time(&|| {
        shadow_rays
            .par_iter()
            .filter(|(o, d)| bvh.any_hit(*o, *d, 0.0, inf))
            .count()
    });
    // The tracer's pattern: many shadow rays from one surface point at a time.
    let per_point = 1024usize;
    let coherent: Vec<(Vec3, Vec3)> = shadow_rays
        .iter()
        .take(2000)
        .flat_map(|&(o, _)| {
            let normal = tracer
                .bvh()
                .closest_point(o, f32::INFINITY)
                .map_or(Vec3::Y, |cp| {
                    tracer.surface_point(cp.triangle, cp.b1, cp.b2).geometric_normal
                });
            let mut local = stream_rng(2, o.x.to_bits().into());
            (0..per_point)
                .map(|_| {
                    let mut w = random_unit(&mut local);
                    if w.dot(normal) < 0.0 {
                        w = -w;
                    }
                    (o, w)
                })
                .collect::<Vec<_>>()
        })
        .collect();
    let k = coherent.len() as f64;
    let (t3, h3) = time(&|| {
        coherent
            .iter()
            .filter(|(o, d)| bvh.any_hit(*o, *d, 0.0, inf))
            .count()
    });
    println!(
        "{label}: {} triangles, {} BVH nodes",
        mesh.triangles.len(),
        bvh.node_count()
    );
    println!(
        "  closest hit, camera rays ({:.0}% hit): {:.2} M rays/s on 1 thread, {:.2} M rays/s on {} threads",
        100.0 * h1 as f64 / n as f64,
        n as f64 / t1 / 1e6,
        n as f64 / tp / 1e6,
        rayon::current_num_threads()
    );
    println!(
        "  any hit, shadow rays from the surface ({:.0}% occluded): {:.2} M rays/s on 1 thread, {:.2} M rays/s on {} threads",
        100.0 * h2 as f64 / m,
        m / t2 / 1e6,
        m / t2p / 1e6,
        rayon::current_num_threads()
    );
    println!(
        "  any hit, {per_point} shadow rays per surface point in a row ({:.0}% occluded): {:.2} M rays/s on 1 thread",
        100.0 * h3 as f64 / k,
        k / t3 / 1e6
    );
    Ok(())
}

fn head_camera(size: u32) -> PinholeCamera {
    PinholeCamera::look_at(
        DVec3::new(0.12, 0.04, 0.55),
        DVec3::new(0.0, 0.0, 0.0),
        DVec3::Y,
        size,
        size,
        0.5,
    )
}

/// Relative noise of T across seeds at a few surface points.
fn lt_noise(tracer: &LtTracer, light: &LatLong) {
    let seeds = 32u64;
    let cam = head_camera(64);
    println!("LT noise at default samples ({seeds} seeds per point):");
    for (u, v) in [(32u32, 24u32), (28, 36), (38, 44), (24, 50)] {
        let (o, d) = cam.pixel_ray(u, v);
        let Some(hit) = tracer.intersect(o.as_vec3(), d.as_vec3()) else {
            println!("  pixel ({u}, {v}) misses the head");
            continue;
        };
        let sp = tracer.surface_at_hit(&hit, d.as_vec3());
        let t = Instant::now();
        let vectors: Vec<[f32; 384]> = (0..seeds)
            .into_par_iter()
            .map(|s| tracer.light_transport(&sp, -d.as_vec3(), &mut tracer.rng(1000 + s)))
            .collect();
        let per_vector = t.elapsed().as_secs_f64() / seeds as f64 * rayon::current_num_threads() as f64;
        let mean: Vec<f64> = (0..384)
            .map(|i| vectors.iter().map(|x| f64::from(x[i])).sum::<f64>() / seeds as f64)
            .collect();
        let var: f64 = (0..384)
            .map(|i| {
                vectors
                    .iter()
                    .map(|x| (f64::from(x[i]) - mean[i]).powi(2))
                    .sum::<f64>()
                    / (seeds - 1) as f64
            })
            .sum();
        let norm2: f64 = mean.iter().map(|m| m * m).sum();
        // Per-texel relative noise among texels carrying ≥ 1% of the vector's largest entry.
        let max = mean.iter().copied().fold(0.0, f64::max);
        let rel: Vec<f64> = (0..384)
            .filter(|&i| mean[i] > 0.01 * max)
            .map(|i| {
                let sd = (vectors
                    .iter()
                    .map(|x| (f64::from(x[i]) - mean[i]).powi(2))
                    .sum::<f64>()
                    / (seeds - 1) as f64)
                    .sqrt();
                sd / mean[i]
            })
            .collect();
        let median_rel = {
            let mut r = rel.clone();
            r.sort_by(f64::total_cmp);
            r.get(r.len() / 2).copied().unwrap_or(0.0)
        };
        let shaded: Vec<f64> = vectors.iter().map(|x| f64::from(shade(x, light)[1])).collect();
        let sm = shaded.iter().sum::<f64>() / seeds as f64;
        let ssd = (shaded.iter().map(|s| (s - sm).powi(2)).sum::<f64>() / (seeds - 1) as f64).sqrt();
        println!(
            "  pixel ({u}, {v}): ‖σ‖/‖mean‖ = {:.2}%, median per-texel σ/mean = {:.1}% ({} texels), \
             shaded (green) σ/mean = {:.2}%, {:.1} ms per vector per thread",
            100.0 * (var / norm2).sqrt(),
            100.0 * median_rel,
            rel.len(),
            100.0 * ssd / sm,
            1e3 * per_vector
        );
    }
}

fn main() -> Result<(), Error> {
    let args: Vec<String> = std::env::args().collect();
    let arg = |name: &str| {
        args.iter()
            .position(|a| a == name)
            .and_then(|i| args.get(i + 1))
            .cloned()
    };
    let size: u32 = arg("--size").map(|s| s.parse()).transpose()?.unwrap_or(512);
    let data = concat!(env!("CARGO_MANIFEST_DIR"), "/../data");
    let head_path = arg("--head").unwrap_or_else(|| format!("{data}/meshes/head.off"));
    let env_path = arg("--env").unwrap_or_else(|| format!("{data}/envmaps/courtyard.exr"));

    let sphere = uv_sphere(Vec3::ZERO, 0.12, 128, 240, [0.6; 3]);
    ray_throughput(&sphere, "UV sphere")?;
    let params = HeadParams {
        cells_per_height: 106,
        height_m: Some(0.23),
        ..HeadParams::default()
    };
    let procedural = procedural_head(3, &params);
    ray_throughput(&procedural, "procedural head (seed 3, 106 cells)")?;
    let head = load_mesh(&head_path, &LoadOptions::head_off())?;
    ray_throughput(&head, "head.off")?;

    let light = envmap_to_basis(&load_envmap(&env_path)?, 0.0);
    let tracer = LtTracer::new(&head, TraceSettings::default())?;
    lt_noise(&tracer, &light);

    let cam = head_camera(64);
    let t = Instant::now();
    let lt_image = render_lt_image(&tracer, &cam, &light, None)?;
    let t_lt = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let direct = render_direct_image(&tracer, &cam, &light, &DirectSettings::default(), None)?;
    let t_direct = t.elapsed().as_secs_f64();
    println!(
        "estimator agreement, head 64², {env_path}: {:.2} dB (T·L {t_lt:.1} s, direct {} paths/pixel {t_direct:.1} s)",
        masked_psnr(&direct, &lt_image),
        DirectSettings::default().paths_per_pixel
    );

    let cam = head_camera(size);
    let bar = indicatif::ProgressBar::new(u64::from(size));
    let t = Instant::now();
    let image = render_lt_image(&tracer, &cam, &light, Some(&bar))?;
    bar.finish_and_clear();
    let covered = image.alpha.iter().filter(|&&a| a > 0.0).count();
    println!(
        "LT image {size}² of the head at default samples: {:.1} s on {} threads ({covered} covered pixels, {:.2} ms per covered pixel per thread)",
        t.elapsed().as_secs_f64(),
        rayon::current_num_threads(),
        1e3 * t.elapsed().as_secs_f64() * rayon::current_num_threads() as f64 / covered.max(1) as f64
    );
    Ok(())
}
