//! Measures the photographs path (`nelf_pipeline::photo`) stage by stage on a
//! synthetic capture against its ground truth: geometry (Chamfer distance, mm, and
//! normal angle error, degrees, both ways between the reconstructed and the true
//! mesh over the surface the input views see), reflectance (mean absolute error of
//! the albedo at the surface points nearest the truth's visible points), and the
//! bake (8-bit sRGB PSNR, foreground and whole image, at the held-aside targets)
//! beside the ground-truth bake and the flat colour.
//!
//! `cargo run --release -p nelf-pipeline --example photos_bench -- CAPTURE_DIR [RESOLUTION] [unnamed] [hull]`
//! (a synthetic capture with `synth_config.json` and targets, e.g. `nelf demo`'s
//! `out/demo/capture`). `unnamed` reconstructs as if the capture named no lighting
//! and scores after one exposure gain; `hull` keeps the visual hull uncarved.

use std::path::PathBuf;
use std::time::Instant;

use glam::{DMat3, Vec3};
use nelf_bake::eval::load_held_aside;
use nelf_bake::{
    BakeConfig, CaptureLoadOptions, GroundTruth, Progress, ViewChoice, bake_capture, load_capture,
};
use nelf_pipeline::PipelineConfig;
use nelf_pipeline::photo::{bake_photographs, write_reconstruction};
use nelf_render::{MarchSettings, render_asset};
use nelf_scene::bvh::Bvh;
use nelf_scene::mesh::Mesh;
use nelf_scene::metrics::srgb8_scores;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let dir = PathBuf::from(
        args.get(1)
            .ok_or("usage: photos_bench CAPTURE_DIR [RESOLUTION] [unnamed]")?,
    );
    let resolution: u32 = args.get(2).map_or(Ok(64), |r| r.parse())?;
    let unnamed = args.iter().any(|a| a == "unnamed");
    if !dir.exists() {
        // The demo's capture (`nelf demo`'s defaults) at 256².
        let synth = nelf_scene::synth::SynthConfig {
            views: 5,
            targets: 2,
            width: 256,
            height: 256,
            texel_samples: 4,
            indirect_samples: 32,
            bounces: 1,
            ..nelf_scene::synth::SynthConfig::default()
        };
        nelf_scene::synth::write_synthetic_capture(&synth, &dir, &indicatif::ProgressBar::hidden())?;
    }
    let capture = load_capture(&dir, &CaptureLoadOptions::default())?;
    let truth = GroundTruth::from_synth_capture(&dir)?;
    let truth_mesh = truth.mesh()?;
    let config = PipelineConfig::from(BakeConfig {
        resolution,
        view_dependence: ViewChoice::Off,
        ..BakeConfig::default()
    });
    let mut photographs = capture.clone();
    if unnamed && let nelf_bake::capture_in::CaptureSource::CamerasJson(d) = &mut photographs.source {
        d.envmap = None;
    }
    let t = Instant::now();
    let baked = bake_photographs(
        &photographs,
        None,
        &nelf_pipeline::config::PhotoSettings {
            photo_hull_only: args.iter().any(|a| a == "hull"),
            ..Default::default()
        },
        &config,
        Progress::hidden(),
    )?;
    let photo_secs = t.elapsed().as_secs_f64();
    println!(
        "reconstruction {:.1} s, bake total {photo_secs:.1} s\n{}",
        baked.reconstruct_secs,
        serde_json::to_string_pretty(&baked.reconstruction.report)?
    );
    println!(
        "bake stages: {}",
        serde_json::to_string(&baked.output.report.timings)?
    );
    let out = dir.with_file_name("photos_bench");
    write_reconstruction(&baked.reconstruction, &out.join("reconstruction"))?;
    geometry_error(&baked.reconstruction.mesh, &truth_mesh, &capture.cameras);
    // The reconstruction re-rendered at each source view under the source lighting
    // (direct light only): the reflectance stage's own check.
    if let Some(path) = capture.source_envmap_path() {
        let env = nelf_scene::envmap::load_envmap(&path)?;
        let basis = nelf_format::conventions::project_envmap(&env, DMat3::IDENTITY)?;
        let tracer = nelf_scene::tracer::LtTracer::new(
            &baked.reconstruction.mesh,
            nelf_scene::tracer::TraceSettings {
                bounces: 0,
                texel_samples: 1,
                ..Default::default()
            },
        )?;
        for v in 0..capture.len() {
            let image = nelf_scene::render::render_lt_image(&tracer, &capture.cameras[v], &basis, None)?;
            let exposure = (0.6 / nelf_bake::eval::data_range(&capture.images[v])).log2();
            nelf_pipeline::demo::side_by_side(
                &out.join(format!("source_{v}.png")),
                &capture.cameras[v],
                &capture.images[v],
                &image.rgb,
                exposure,
            )?;
        }
    }

    let t = Instant::now();
    let truth_bake = bake_capture(&capture, &truth, &config.bake, &Progress::hidden())?;
    println!("truth bake {:.1} s", t.elapsed().as_secs_f64());

    let description = capture.description().ok_or("no cameras.json")?;
    let held = load_held_aside(description, &dir)?;
    let settings = MarchSettings::default();
    let mut renders = Vec::new();
    for t in 0..held.len() {
        let photo = render_asset(
            &baked.output.asset,
            &held.cameras[t],
            &held.envs[t],
            DMat3::IDENTITY,
            None,
            &settings,
        )?;
        let truth_img = render_asset(
            &truth_bake.asset,
            &held.cameras[t],
            &held.envs[t],
            DMat3::IDENTITY,
            None,
            &settings,
        )?;
        renders.push((photo.rgb, truth_img.rgb));
    }
    let gain = if unnamed {
        let photos: Vec<Vec<[f32; 3]>> = renders.iter().map(|(photo, _)| photo.clone()).collect();
        nelf_scene::metrics::exposure_gain(&photos, &held.images, &held.masks) as f32
    } else {
        1.0
    };
    for (t, (photo, truth_img)) in renders.iter().enumerate() {
        let (w, h) = (held.cameras[t].width, held.cameras[t].height);
        let photo: Vec<[f32; 3]> = photo.iter().map(|p| p.map(|v| v * gain)).collect();
        let p = srgb8_scores(&photo, &held.images[t], &held.masks[t], w, h)?;
        let g = srgb8_scores(truth_img, &held.images[t], &held.masks[t], w, h)?;
        let closed =
            (p.foreground_psnr - p.flat_foreground_psnr) / (g.foreground_psnr - p.flat_foreground_psnr);
        println!(
            "{}: photos {:.2} fg / {:.2} whole (ssim {:.3}); truth bake {:.2} / {:.2}; flat {:.2} / {:.2}; gap closed {:.0} %; gain {gain:.3}",
            held.names[t],
            p.foreground_psnr,
            p.psnr,
            p.ssim,
            g.foreground_psnr,
            g.psnr,
            p.flat_foreground_psnr,
            p.flat_psnr,
            100.0 * closed
        );
        let exposure = (0.6 / nelf_bake::eval::data_range(&held.images[t])).log2();
        nelf_pipeline::demo::side_by_side(
            &out.join(format!("compare_{}.png", held.names[t])),
            &held.cameras[t],
            &held.images[t],
            &photo,
            exposure,
        )?;
    }
    Ok(())
}

/// Chamfer distance and normal error between the meshes, over points of each that
/// some input camera sees (the back of a head no view sees is not reconstructed).
fn geometry_error(reconstructed: &Mesh, truth: &Mesh, cameras: &[nelf_format::conventions::PinholeCamera]) {
    let bvh_r = Bvh::new(&reconstructed.positions, &reconstructed.triangles);
    let bvh_t = Bvh::new(&truth.positions, &truth.triangles);
    let normals_r = reconstructed.vertex_normals();
    let normals_t = truth.vertex_normals();
    let seen = |p: Vec3, n: Vec3, bvh: &Bvh| {
        cameras.iter().any(|c| {
            let eye = c.centre().as_vec3();
            let d = (eye - p).normalize();
            n.dot(d) > 0.1
                && c.project(p.as_dvec3()).is_some_and(|px| {
                    px.x >= 0.0 && px.y >= 0.0 && px.x < f64::from(c.width) && px.y < f64::from(c.height)
                })
                && bvh
                    .closest_hit(p + d * 1e-3, d, 0.0, (eye - p).length())
                    .is_none()
        })
    };
    let one_way = |from: &Mesh, nf: &[Vec3], bvh_from: &Bvh, to: &Mesh, bvh_to: &Bvh| {
        let (mut dist, mut angle, mut count) = (0.0f64, 0.0f64, 0usize);
        let mut worst = Vec::new();
        for (i, p) in from.positions.iter().enumerate().step_by(7) {
            if !seen(*p, nf[i], bvh_from) {
                continue;
            }
            if let Some(cp) = bvh_to.closest_point(*p, 0.2) {
                let d = f64::from(cp.distance);
                let n = to.face_normal(cp.triangle as usize);
                dist += d;
                worst.push(d);
                angle += f64::from(nf[i].dot(n).clamp(-1.0, 1.0).acos().to_degrees());
                count += 1;
            }
        }
        worst.sort_by(f64::total_cmp);
        let p90 = worst.get(worst.len() * 9 / 10).copied().unwrap_or(f64::NAN);
        (1e3 * dist / count as f64, angle / count as f64, 1e3 * p90, count)
    };
    let (d_rt, a_rt, p_rt, n_rt) = one_way(reconstructed, &normals_r, &bvh_r, truth, &bvh_t);
    let (d_tr, a_tr, p_tr, n_tr) = one_way(truth, &normals_t, &bvh_t, reconstructed, &bvh_r);
    println!(
        "geometry: reconstructed→truth mean {d_rt:.2} mm (p90 {p_rt:.2}), normals {a_rt:.1}° over {n_rt} points; truth→reconstructed {d_tr:.2} mm (p90 {p_tr:.2}), {a_tr:.1}° over {n_tr}; Chamfer {:.2} mm",
        0.5 * (d_rt + d_tr)
    );
}
