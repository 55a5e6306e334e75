//! Measures a fine reflectance layer over coarse light transport (issue 51) before it
//! is built into the format: bakes a synthetic mesh capture at `RESOLUTION`, then
//! renders the asset at its held-aside targets (a) as it is, (b) with each voxel's
//! radiance divided by the albedo it was baked with (the texture averaged over one
//! voxel round the voxel centre's closest surface point: the mesh field's rule) and each sample multiplied by a
//! finer albedo — the mesh's own at the sample's closest surface point (`inf`, the
//! ceiling), or trilinear from a lattice `FACTOR` times finer than the voxels, each
//! lattice point the mean albedo of `SUPER³` points of its cell's closest surface
//! points. Prints whole and foreground PSNR (8-bit sRGB) against the targets and how
//! the squared error splits between the inside, the silhouette's edge and the outside.
//! `swapRES` bakes the capture at a second resolution too and swaps the two assets'
//! parts: the fine density with the coarse radiance (trilinear at each sample) and the
//! coarse density with the fine radiance, to say which of the two a finer lattice buys.
//!
//! `cargo run --release -p nelf-bake --example detail_bench -- CAPTURE RESOLUTION [FACTOR|hitFACTOR|inf|hit|swapRES ...] [super=N] [grid=N] [step=VOXELS] [errors=DIR] [coverage=truth]`

use std::collections::HashMap;
use std::path::PathBuf;
use std::time::Instant;

use glam::{DMat3, DVec3};
use nelf_bake::eval::load_held_aside;
use nelf_bake::{
    BakeConfig, CaptureLoadOptions, GroundTruth, Progress, ViewChoice, bake_capture, load_capture,
};
use nelf_format::grid::{BRICK_VOXELS, local_voxel_coords};
use nelf_format::{WriteOptions, encode_asset};
use nelf_render::march::{Image, asset_density, render_volume_factored};
use nelf_render::{BrickGrid, MarchSettings, project_light, render_asset, voxel_radiance};
use nelf_scene::bvh::Bvh;
use nelf_scene::image_io::write_png_srgb;
use nelf_scene::mesh::Mesh;
use nelf_scene::metrics::srgb8_scores;
use nelf_scene::srgb::{linear_to_srgb8, srgb_to_linear};

/// Pixels from the true silhouette counted as its edge.
const EDGE_PX: i64 = 2;
use rayon::prelude::*;

struct Surface<'a> {
    mesh: &'a Mesh,
    bvh: Bvh,
}

impl Surface<'_> {
    fn albedo(&self, p: DVec3) -> Option<[f32; 3]> {
        let c = self.bvh.closest_point(p.as_vec3(), f32::INFINITY)?;
        Some(self.mesh.albedo_at(c.triangle as usize, c.b1, c.b2))
    }

    /// The albedo the mesh field bakes a point with: the texture averaged over a
    /// voxel-sized footprint round its closest surface point (`Mesh::albedo_footprint`).
    fn baked_albedo(&self, p: DVec3, voxel_m: f32) -> Option<[f32; 3]> {
        let c = self.bvh.closest_point(p.as_vec3(), f32::INFINITY)?;
        Some(
            self.mesh
                .albedo_footprint(c.triangle as usize, c.b1, c.b2, voxel_m),
        )
    }
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let dir = PathBuf::from(
        args.get(1)
            .ok_or("usage: detail_bench CAPTURE RESOLUTION [FACTOR|hitFACTOR|inf|hit ...]")?,
    );
    let resolution: u32 = args.get(2).map_or(Ok(128), |r| r.parse())?;
    let supersample: usize = args
        .iter()
        .find_map(|a| a.strip_prefix("super="))
        .map_or(Ok(2), str::parse)?;
    let modes: Vec<String> = args[3.min(args.len())..]
        .iter()
        .filter(|a| !a.contains('='))
        .cloned()
        .collect();
    // `errors=DIR`: truth | render | error strips per target and variant.
    let true_coverage = args.iter().any(|a| a == "coverage=truth");
    let error_dir = args
        .iter()
        .find_map(|a| a.strip_prefix("errors="))
        .map(PathBuf::from);
    let capture = load_capture(&dir, &CaptureLoadOptions::default())?;
    let truth = GroundTruth::from_synth_capture(&dir)?;
    let mesh = truth.mesh()?;
    let config = BakeConfig {
        resolution,
        view_dependence: ViewChoice::Off,
        ..BakeConfig::default()
    };
    let t = Instant::now();
    let output = bake_capture(&capture, &truth, &config, &Progress::hidden())?;
    let bake_secs = t.elapsed().as_secs_f64();
    let asset = &output.asset;
    let (bytes, _) = encode_asset(asset, &WriteOptions::default())?;
    println!(
        "resolution {resolution}: bake {bake_secs:.1} s, {} bytes, {} bricks, voxel {:.2} mm",
        bytes.len(),
        asset.bricks.len(),
        asset.grid.voxel_size_m * 1e3
    );
    let grid = BrickGrid::from_asset(asset)?;
    let density = asset_density(asset);
    let surface = Surface {
        mesh: &mesh,
        bvh: Bvh::new(&mesh.positions, &mesh.triangles),
    };
    let voxel_m = asset.grid.voxel_size_m;
    let centre = |v: usize| {
        asset.grid.voxel_center_m(
            asset.bricks[v / BRICK_VOXELS],
            local_voxel_coords(v % BRICK_VOXELS),
        )
    };
    // The albedo each voxel was baked with.
    let t = Instant::now();
    let coarse: Vec<[f32; 3]> = (0..density.len())
        .into_par_iter()
        .map(|v| {
            surface
                .baked_albedo(centre(v), voxel_m as f32)
                .unwrap_or([1.0; 3])
        })
        .collect();
    println!("coarse albedo {:.1} s", t.elapsed().as_secs_f64());
    let description = capture.description().ok_or("no cameras.json")?;
    let held = load_held_aside(description, &dir)?;
    // Rays per pixel along each axis (`grid=N`; the targets are antialiased with 4).
    let settings = MarchSettings {
        pixel_grid: args
            .iter()
            .find_map(|a| a.strip_prefix("grid="))
            .map_or(Ok(nelf_bake::eval::EVAL_PIXEL_GRID), str::parse)?,
        step_voxels: args
            .iter()
            .find_map(|a| a.strip_prefix("step="))
            .map_or(Ok(MarchSettings::default().step_voxels), str::parse)?,
        ..MarchSettings::default()
    };
    let score_all = |name: &str, render: &dyn Fn(usize) -> Result<Image, Box<dyn std::error::Error>>| {
        let (mut whole, mut fg) = (0.0, 0.0);
        let mut line = Vec::new();
        // Squared 8-bit error inside the true mask (farther than EDGE_PX from its
        // silhouette), within EDGE_PX of the silhouette, and outside.
        let mut parts = [0.0f64; 3];
        for t in 0..held.len() {
            let rendered = render(t)?;
            // `coverage=truth`: the render's colour over the true coverage
            // (silhouettes exact; what is left is colour).
            let image: Vec<[f32; 3]> = if true_coverage {
                rendered
                    .rgb
                    .iter()
                    .zip(&rendered.alpha)
                    .zip(&held.masks[t])
                    .map(|((c, &a), &m)| if a > 1e-3 { c.map(|v| v / a * m) } else { [0.0; 3] })
                    .collect()
            } else {
                rendered.rgb
            };
            let (w, h) = (held.cameras[t].width, held.cameras[t].height);
            let s = srgb8_scores(&image, &held.images[t], &held.masks[t], w, h)?;
            if let Some(dir) = &error_dir {
                // Truth | render | |error| × 4, in sRGB.
                let (wu, hu) = (w as usize, h as usize);
                let mut strip = vec![[0.0f32; 3]; 3 * wu * hu];
                for (i, (a, b)) in image.iter().zip(&held.images[t]).enumerate() {
                    let (x, y) = (i % wu, i / wu);
                    let row = y * 3 * wu;
                    strip[row + x] = *b;
                    strip[row + wu + x] = *a;
                    strip[row + 2 * wu + x] = std::array::from_fn(|ch| {
                        let d = f32::from(linear_to_srgb8(a[ch])) - f32::from(linear_to_srgb8(b[ch]));
                        srgb_to_linear((d.abs() * 4.0 / 255.0).min(1.0))
                    });
                }
                std::fs::create_dir_all(dir)?;
                let tag: String = name
                    .chars()
                    .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
                    .collect();
                write_png_srgb(dir.join(format!("{tag}_{t}.png")), 3 * w, h, &strip, 0.0)?;
            }
            whole += s.psnr / held.len() as f64;
            fg += s.foreground_psnr / held.len() as f64;
            line.push(format!("{:.2}", s.psnr));
            let inside = |x: i64, y: i64| {
                x >= 0
                    && y >= 0
                    && x < i64::from(w)
                    && y < i64::from(h)
                    && held.masks[t][(y * i64::from(w) + x) as usize] > 0.5
            };
            for (i, (a, b)) in image.iter().zip(&held.images[t]).enumerate() {
                let (x, y) = ((i % w as usize) as i64, (i / w as usize) as i64);
                let here = inside(x, y);
                let near_edge = (-EDGE_PX..=EDGE_PX)
                    .any(|dy| (-EDGE_PX..=EDGE_PX).any(|dx| inside(x + dx, y + dy) != here));
                let part = if near_edge {
                    1
                } else if here {
                    0
                } else {
                    2
                };
                for ch in 0..3 {
                    let d = f64::from(linear_to_srgb8(a[ch])) - f64::from(linear_to_srgb8(b[ch]));
                    parts[part] += d * d;
                }
            }
        }
        let total: f64 = parts.iter().sum::<f64>().max(1e-30);
        println!(
            "{name}: mean {whole:.2} whole / {fg:.2} fg; per target whole {}; squared error inside / within {EDGE_PX} px of the silhouette / outside: {:.0} / {:.0} / {:.0} %",
            line.join(" "),
            100.0 * parts[0] / total,
            100.0 * parts[1] / total,
            100.0 * parts[2] / total
        );
        Ok::<(), Box<dyn std::error::Error>>(())
    };
    score_all("as baked", &|t| {
        Ok(render_asset(
            asset,
            &held.cameras[t],
            &held.envs[t],
            DMat3::IDENTITY,
            None,
            &settings,
        )?)
    })?;
    // Per-voxel values trilinear at `p`, normalised over the corners the grid has (zero
    // off its bricks).
    let radiance_at = |grid: &BrickGrid, values: &[[f32; 3]], p: DVec3| {
        let mut corners = [(0usize, 0.0f32); 8];
        let n = grid.trilinear(p, &mut corners);
        let (mut sum, mut wsum) = ([0.0f32; 3], 0.0f32);
        for &(v, w) in &corners[..n] {
            for ch in 0..3 {
                sum[ch] += w * values[v][ch];
            }
            wsum += w;
        }
        sum.map(|x| x / wsum.max(1e-6))
    };
    // An asset's voxel radiance under target `t`'s lighting.
    let radiance_of =
        |asset: &nelf_format::Asset, t: usize| -> Result<Vec<[f32; 3]>, Box<dyn std::error::Error>> {
            let light = project_light(&asset.pca, asset.world_from_light, &held.envs[t], DMat3::IDENTITY)?;
            Ok(voxel_radiance(asset, &light, None))
        };
    let white = |t: usize| -> Result<Vec<[f32; 3]>, Box<dyn std::error::Error>> {
        Ok(radiance_of(asset, t)?
            .iter()
            .zip(&coarse)
            .map(|(r, a)| std::array::from_fn(|ch| r[ch] / a[ch].max(1e-3)))
            .collect())
    };
    // The white radiance × `factor` at every sample, at target `t`.
    let factored = |t: usize,
                    factor: &(dyn Fn(DVec3) -> [f32; 3] + Sync)|
     -> Result<Image, Box<dyn std::error::Error>> {
        Ok(render_volume_factored(
            &grid,
            &density,
            &white(t)?,
            factor,
            &held.cameras[t],
            &settings,
        )?)
    };
    for mode in &modes {
        let t0 = Instant::now();
        if let Some(fine_res) = mode.strip_prefix("swap") {
            let fine_config = BakeConfig {
                resolution: fine_res.parse()?,
                ..config.clone()
            };
            let fine_output = bake_capture(&capture, &truth, &fine_config, &Progress::hidden())?;
            let fine = &fine_output.asset;
            let fine_grid = BrickGrid::from_asset(fine)?;
            let fine_density = asset_density(fine);
            let (fine_bytes, _) = encode_asset(fine, &WriteOptions::default())?;
            println!(
                "resolution {fine_res}: bake {:.1} s, {} bytes, {} bricks, {} density values",
                t0.elapsed().as_secs_f64(),
                fine_bytes.len(),
                fine.bricks.len(),
                fine_density.len()
            );
            score_all(&format!("resolution {fine_res} as baked"), &|t| {
                Ok(render_asset(
                    fine,
                    &held.cameras[t],
                    &held.envs[t],
                    DMat3::IDENTITY,
                    None,
                    &settings,
                )?)
            })?;
            // One asset's density (its grid) with the other's radiance at every sample.
            let swapped = |(density_grid, density_values): (&BrickGrid, &[f32]),
                           (radiance_asset, radiance_grid): (&nelf_format::Asset, &BrickGrid),
                           t: usize|
             -> Result<Image, Box<dyn std::error::Error>> {
                let values = radiance_of(radiance_asset, t)?;
                let factor = |p: DVec3| radiance_at(radiance_grid, &values, p);
                Ok(render_volume_factored(
                    density_grid,
                    density_values,
                    &vec![[1.0f32; 3]; density_values.len()],
                    &factor,
                    &held.cameras[t],
                    &settings,
                )?)
            };
            score_all(
                &format!("density of {fine_res}, radiance of {resolution}"),
                &|t| swapped((&fine_grid, &fine_density), (asset, &grid), t),
            )?;
            score_all(
                &format!("density of {resolution}, radiance of {fine_res}"),
                &|t| swapped((&grid, &density), (fine, &fine_grid), t),
            )?;
            continue;
        }
        if mode == "hit" {
            // The albedo where the camera's ray through the sample first meets the
            // mesh: the fine layer on a perfectly sharp surface.
            score_all("fine = the mesh's albedo at the ray's hit", &|t| {
                let eye = held.cameras[t].centre();
                let factor = |p: DVec3| {
                    let dir = (p - eye).as_vec3();
                    surface.bvh.closest_hit(eye.as_vec3(), dir, 0.0, 2.0).map_or_else(
                        || surface.albedo(p).unwrap_or([1.0; 3]),
                        |h| mesh.albedo_at(h.triangle as usize, h.b1, h.b2),
                    )
                };
                factored(t, &factor)
            })?;
            continue;
        }
        if mode == "inf" {
            let factor = |p: DVec3| surface.albedo(p).unwrap_or([1.0; 3]);
            score_all("fine = the mesh's albedo", &|t| factored(t, &factor))?;
            continue;
        }
        // `hitN`: the lattice read where the camera's ray meets the mesh.
        let (at_hit, k) = match mode.strip_prefix("hit") {
            Some(k) => (true, k.parse::<usize>()?),
            None => (false, mode.parse::<usize>()?),
        };
        let fine_m = voxel_m / k as f64;
        let origin = DVec3::from_array(asset.grid.bbox_min_m);
        // Fine lattice points (fine-cell centres) inside voxels that have density.
        let mut keys = Vec::new();
        for (v, &sigma) in density.iter().enumerate() {
            if sigma <= 0.0 {
                continue;
            }
            let base = ((centre(v) - origin) / voxel_m - 0.5).round();
            for l in 0..k * k * k {
                let (a, b, c) = (l % k, (l / k) % k, l / (k * k));
                keys.push([
                    base.x as i64 * k as i64 + a as i64,
                    base.y as i64 * k as i64 + b as i64,
                    base.z as i64 * k as i64 + c as i64,
                ]);
            }
        }
        let s = supersample.max(1);
        let values: Vec<[f32; 3]> = keys
            .par_iter()
            .map(|key| {
                let mut sum = [0.0f32; 3];
                for q in 0..s * s * s {
                    let o = DVec3::new((q % s) as f64, ((q / s) % s) as f64, (q / (s * s)) as f64);
                    let p = origin
                        + (DVec3::new(key[0] as f64, key[1] as f64, key[2] as f64) + (o + 0.5) / s as f64)
                            * fine_m;
                    let a = surface.albedo(p).unwrap_or([1.0; 3]);
                    for ch in 0..3 {
                        sum[ch] += a[ch] / (s * s * s) as f32;
                    }
                }
                sum
            })
            .collect();
        let lattice: HashMap<[i64; 3], [f32; 3]> = keys.into_iter().zip(values).collect();
        println!(
            "factor {k}: {} fine points ({:.1} MB at 3 bytes), {:.1} s",
            lattice.len(),
            lattice.len() as f64 * 3.0 / 1e6,
            t0.elapsed().as_secs_f64()
        );
        let coarse_at = |p: DVec3| radiance_at(&grid, &coarse, p);
        let factor = |p: DVec3| {
            let u = (p - origin) / fine_m - 0.5;
            let base = u.floor();
            let f = (u - base).as_vec3();
            let (mut sum, mut wsum) = ([0.0f32; 3], 0.0f32);
            for corner in 0..8 {
                let d = [corner & 1, (corner >> 1) & 1, corner >> 2];
                let key = [
                    base.x as i64 + d[0] as i64,
                    base.y as i64 + d[1] as i64,
                    base.z as i64 + d[2] as i64,
                ];
                let w = (0..3)
                    .map(|a| if d[a] == 1 { f[a] } else { 1.0 - f[a] })
                    .product::<f32>();
                if let Some(v) = lattice.get(&key) {
                    for ch in 0..3 {
                        sum[ch] += w * v[ch];
                    }
                    wsum += w;
                }
            }
            if wsum > 1e-6 {
                sum.map(|x| x / wsum)
            } else {
                coarse_at(p)
            }
        };
        let at = if at_hit {
            "at the ray's hit"
        } else {
            "at each sample"
        };
        score_all(
            &format!("fine lattice ×{k}, {s}³ samples per point, read {at}"),
            &|t| {
                let eye = held.cameras[t].centre();
                let read = |p: DVec3| {
                    if !at_hit {
                        return factor(p);
                    }
                    surface
                        .bvh
                        .closest_hit(eye.as_vec3(), (p - eye).as_vec3(), 0.0, 2.0)
                        .map_or_else(|| factor(p), |h| factor(eye + (p - eye) * f64::from(h.t)))
                };
                factored(t, &read)
            },
        )?;
        println!("  ({:.1} s)", t0.elapsed().as_secs_f64());
    }
    Ok(())
}
