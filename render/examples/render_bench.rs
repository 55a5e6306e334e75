//! Benchmark of the CPU reference renderer: a synthetic asset of about `--voxels` voxels
//! (default 200 000, `nelf_format::synthetic`), rendered at `--size`² (default 512²) from
//! a front three-quarter orbit under an analytic sky, for PCA ranks 8 and 16 (8-bit
//! coefficients). Prints a markdown table: the time of each stage (median of `--repeats`
//! runs), lattice samples evaluated and skipped, samples per second of marching, and the
//! accuracy of the image against the same render from the exact (unquantized,
//! untruncated) light-transport vectors: PSNR = 10 log10(peak² / MSE) over all pixels and
//! channels, peak = the reference's largest value.
//!
//! `cargo run --release -p nelf-render --example render_bench [-- --voxels N --size S --repeats R
//! --write-assets DIR]`; with `--write-assets` the two assets are also written as
//! `DIR/synthetic_k8.nelf` and `DIR/synthetic_k16.nelf` (for timing `nelf render`).

use std::time::Instant;

use glam::{DMat3, DVec3};
use nelf_format::CoefficientEncoding;
use nelf_format::conventions::{
    ConventionError, LT_DIM, LatLong, PinholeCamera, direction, project_envmap, rotation_y, row_theta_bounds,
};
use nelf_format::synthetic::SyntheticField;
use nelf_render::{
    BrickGrid, Image, MarchSettings, asset_density, project_light, radiance_from_lt, render_volume,
    render_volume_stats, render_volume_unskipped, voxel_radiance,
};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut voxels = 200_000usize;
    let mut size = 512u32;
    let mut repeats = 3usize;
    let mut write_dir: Option<std::path::PathBuf> = None;
    let args: Vec<String> = std::env::args().skip(1).collect();
    for pair in args.chunks(2) {
        let value = pair.get(1).ok_or("missing value")?;
        match pair[0].as_str() {
            "--voxels" => voxels = value.parse()?,
            "--size" => size = value.parse()?,
            "--repeats" => repeats = value.parse()?,
            "--write-assets" => write_dir = Some(value.into()),
            other => return Err(format!("unknown option {other}").into()),
        }
    }
    let field = SyntheticField::new(voxels, 1);
    let env = sky(128, 64)?;
    let eye = DVec3::new(0.25, 0.08, 0.42);
    let camera = PinholeCamera::look_at(eye, DVec3::ZERO, DVec3::Y, size, size, 35f64.to_radians());
    let settings = MarchSettings::default();
    let threads = rayon::current_num_threads();
    println!(
        "synthetic asset: {} voxels in {} bricks of a {:?}-brick grid, voxel {:.2} mm; image {size}²; {threads} threads; {} repeats (median)\n",
        field.voxel_count(),
        field.bricks().len(),
        field.grid().grid_bricks,
        field.grid().voxel_size_m * 1e3,
        repeats
    );

    // Reference: exact light transport of every voxel, shaded under the projected map.
    let world_from_env = DMat3::IDENTITY;
    let world_from_light = rotation_y(nelf_format::synthetic::LIGHT_ROTATION_RAD);
    let light_texels = project_envmap(&env, world_from_env.transpose() * world_from_light)?;
    let mut lt = vec![0.0f32; field.voxel_count() * LT_DIM];
    for (v, chunk) in lt.chunks_exact_mut(LT_DIM).enumerate() {
        field.lt(v, chunk);
    }
    let exact_radiance = radiance_from_lt(&lt, &light_texels);
    drop(lt);

    println!(
        "| K | project light (ms) | voxel radiance (ms) | march (ms) | total (s) | march CPU (s, all threads) | samples evaluated | of which σ > 0 | samples skipped | samples/s (wall) | samples/s per CPU-second | march without skipping (ms) | PSNR vs exact T (dB) |"
    );
    println!("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |");
    for rank in [8usize, 16] {
        let asset = field.asset(rank, CoefficientEncoding::U8Affine)?;
        if let Some(dir) = &write_dir {
            std::fs::create_dir_all(dir)?;
            let path = dir.join(format!("synthetic_k{rank}.nelf"));
            nelf_format::write_asset(&path, &asset, &nelf_format::WriteOptions::default())?;
        }
        let grid = BrickGrid::from_asset(&asset)?;
        let density = asset_density(&asset);
        let reference = render_volume(&grid, &density, &exact_radiance, &camera, &settings)?;
        let (mut t_project, mut t_radiance, mut t_march, mut t_unskipped) = (vec![], vec![], vec![], vec![]);
        let mut cpu_march = vec![];
        let mut last = None;
        for _ in 0..repeats.max(1) {
            let start = Instant::now();
            let light = project_light(&asset.pca, asset.world_from_light, &env, world_from_env)?;
            t_project.push(start.elapsed().as_secs_f64());
            let start = Instant::now();
            let radiance = voxel_radiance(&asset, &light, None);
            t_radiance.push(start.elapsed().as_secs_f64());
            let (start, cpu_start) = (Instant::now(), cpu_seconds());
            let (image, stats) = render_volume_stats(&grid, &density, &radiance, &camera, &settings)?;
            t_march.push(start.elapsed().as_secs_f64());
            cpu_march.push(cpu_seconds() - cpu_start);
            let start = Instant::now();
            let unskipped = render_volume_unskipped(&grid, &density, &radiance, &camera, &settings)?;
            t_unskipped.push(start.elapsed().as_secs_f64());
            if unskipped != image {
                return Err("skipping changed the image".into());
            }
            last = Some((image, stats));
        }
        let Some((image, stats)) = last else {
            return Err("no run".into());
        };
        let (project, radiance, march) = (median(&t_project), median(&t_radiance), median(&t_march));
        println!(
            "| {rank} | {:.1} | {:.1} | {:.1} | {:.3} | {:.2} | {} | {} | {} | {:.1} M | {:.1} M | {:.1} | {:.2} |",
            project * 1e3,
            radiance * 1e3,
            march * 1e3,
            project + radiance + march,
            median(&cpu_march),
            stats.samples_evaluated,
            stats.samples_composited,
            stats.samples_skipped,
            stats.samples_evaluated as f64 / march / 1e6,
            stats.samples_evaluated as f64 / median(&cpu_march) / 1e6,
            median(&t_unskipped) * 1e3,
            psnr(&image, &reference),
        );
    }
    Ok(())
}

/// CPU seconds (user + system, all threads) this process has used, from `/proc/self/stat`
/// (clock ticks of 1/100 s, Linux's `USER_HZ`); 0 where that file is unavailable.
fn cpu_seconds() -> f64 {
    let Ok(stat) = std::fs::read_to_string("/proc/self/stat") else {
        return 0.0;
    };
    // Fields after the parenthesised command name; utime and stime are fields 14 and 15.
    let Some((_, rest)) = stat.rsplit_once(')') else {
        return 0.0;
    };
    let fields: Vec<&str> = rest.split_whitespace().collect();
    let ticks = |i: usize| fields.get(i).and_then(|v| v.parse::<f64>().ok()).unwrap_or(0.0);
    (ticks(11) + ticks(12)) / 100.0
}

fn median(values: &[f64]) -> f64 {
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// PSNR of `image` against `reference` over all pixels and channels; peak = reference max.
fn psnr(image: &Image, reference: &Image) -> f64 {
    let peak = reference
        .rgb
        .iter()
        .flatten()
        .fold(0.0f64, |m, &v| m.max(f64::from(v)));
    let n = (reference.rgb.len() * 3) as f64;
    let mse = image
        .rgb
        .iter()
        .flatten()
        .zip(reference.rgb.iter().flatten())
        .map(|(&a, &b)| (f64::from(a) - f64::from(b)).powi(2))
        .sum::<f64>()
        / n;
    10.0 * (peak * peak / mse).log10()
}

/// An analytic sky: blue gradient above, brown ground below, a warm sun at 40° elevation.
fn sky(width: usize, height: usize) -> Result<LatLong, ConventionError> {
    let sun = direction(50f64.to_radians(), 0.8);
    let mut texels = Vec::with_capacity(width * height);
    for row in 0..height {
        let (t0, t1) = row_theta_bounds(row, height);
        for col in 0..width {
            let phi = (col as f64 + 0.5) / width as f64 * 2.0 * std::f64::consts::PI - std::f64::consts::PI;
            let d = direction(0.5 * (t0 + t1), phi);
            let base = if d.y > 0.0 {
                [0.4 + 0.3 * (1.0 - d.y), 0.6 + 0.2 * (1.0 - d.y), 1.0]
            } else {
                [0.25, 0.18, 0.12]
            };
            let glow = 40.0 * d.dot(sun).max(0.0).powi(64);
            texels.push(base.map(|b| (b + glow) as f32));
        }
    }
    LatLong::new(width, height, texels)
}
