//! Measures the photographs path (`nelf_pipeline::photo`) stage by stage on a
//! synthetic capture against its ground truth: geometry (Chamfer distance, mm, and
//! normal angle error, degrees, both ways between the reconstructed and the true
//! mesh over the surface the input views see), reflectance (mean absolute error of
//! the albedo at the surface points nearest the truth's visible points), and the
//! bake (8-bit sRGB PSNR, foreground and whole image, at the held-aside targets)
//! beside the ground-truth bake and the flat colour.
//!
//! `cargo run --release -p nelf-pipeline --example photos_bench -- CAPTURE_DIR [RESOLUTION] [unnamed] [jpeg] [hull] [geometry=stereo|network] [depth] [smoothing=N] [blur=MM] [mesh=truth] [albedo=truth] [highlight=T|off] [texel_samples=N] [bounces=N] [light=uniform|truth-white] [region=STEP] [refine=N] [refine_smoothness=A] [refine_truth=N] [lead=VOXELS]`
//! (a synthetic capture with `synth_config.json` and targets, e.g. `nelf demo`'s
//! `out/demo/capture`). `unnamed` reconstructs as if the capture named no lighting
//! and scores after one exposure gain; `hull` keeps the visual hull uncarved;
//! `depth` scores the stereo depth maps against the truth's, by origin;
//! `mesh=truth` runs the reflectance stage on the true surface and `albedo=truth`
//! puts the true albedo on the reconstructed one (each stage's own error);
//! `highlight`, `texel_samples`, `bounces`, `light=uniform` rerun the reflectance
//! stage with those settings; `refine=N` refines the surface by shading for N steps and
//! `refine_truth=N` runs N steps of it from the true surface under the named
//! lighting and prints how far it leaves it.

use std::path::PathBuf;
use std::time::Instant;

use glam::{DMat3, Vec3};
use nelf_bake::eval::load_held_aside;
use nelf_bake::{
    BakeConfig, CaptureLoadOptions, GroundTruth, Progress, ViewChoice, bake_capture, load_capture,
};
use nelf_pipeline::PipelineConfig;
use nelf_pipeline::photo::{reconstruct, write_reconstruction};
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
    // `jpeg`: the capture written as JPEG + masks + COLMAP (no lighting named) first.
    let jpeg = args.iter().any(|a| a == "jpeg");
    let unnamed = jpeg || args.iter().any(|a| a == "unnamed");
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
    // `lead=VOXELS`: the signed shell's lead of every bake here (`--lead-voxels` and
    // `--photo-lead-voxels`; without it each bake takes its own default).
    let lead_voxels = args
        .iter()
        .find_map(|a| a.strip_prefix("lead="))
        .map_or(Ok(BakeConfig::default().lead_voxels), str::parse)?;
    let config = PipelineConfig::from(BakeConfig {
        resolution,
        view_dependence: ViewChoice::Off,
        lead_voxels,
        ..BakeConfig::default()
    });
    let mut photographs = capture.clone();
    if unnamed && let nelf_bake::capture_in::CaptureSource::CamerasJson(d) = &mut photographs.source {
        d.envmap = None;
    }
    if jpeg {
        // As a camera and COLMAP give it: JPEG, PNG masks, a COLMAP text model, no lighting.
        let photographed = dir.with_file_name("photographed");
        let written =
            nelf_pipeline::photo::as_photographs::write_as_photographs(&capture, &photographed, 90)?;
        println!(
            "photographed as JPEG + COLMAP in {} (exposure gain {:.3})",
            photographed.display(),
            written.exposure_gain
        );
        photographs = load_capture(
            &photographed,
            &CaptureLoadOptions {
                format: nelf_bake::CaptureFormat::Colmap,
                ..CaptureLoadOptions::default()
            },
        )?;
    }
    let option = |key: &str| args.iter().find_map(|a| a.strip_prefix(key)?.strip_prefix('='));
    let settings = nelf_pipeline::config::PhotoSettings {
        photo_geometry: match option("geometry") {
            Some("stereo") => nelf_pipeline::config::PhotoGeometry::Stereo,
            Some("network") => nelf_pipeline::config::PhotoGeometry::Network,
            Some("fused") => nelf_pipeline::config::PhotoGeometry::Fused,
            _ if args.iter().any(|a| a == "hull") => nelf_pipeline::config::PhotoGeometry::Hull,
            _ => nelf_pipeline::config::PhotoGeometry::default(),
        },
        photo_smoothing: option("smoothing").map_or(Ok(30), str::parse)?,
        photo_lighting: match option("lighting") {
            Some("network") => nelf_pipeline::config::UnnamedLighting::Network,
            _ => nelf_pipeline::config::UnnamedLighting::Fit,
        },
        photo_blur_mm: option("blur").map_or(Ok(nelf_pipeline::config::DEFAULT_PHOTO_BLUR_MM), str::parse)?,
        photo_light_region_step: option("region").map_or(
            Ok(nelf_pipeline::config::DEFAULT_PHOTO_LIGHT_REGION_STEP),
            str::parse,
        )?,
        photo_refine_iterations: option("refine").map_or(Ok(0), str::parse)?,
        photo_refine_smoothness: option("refine_smoothness")
            .map_or(Ok(nelf_pipeline::photo::refine::DEFAULT_SMOOTHNESS), str::parse)?,
        photo_lead_voxels: option("lead")
            .map_or(Ok(nelf_pipeline::config::DEFAULT_PHOTO_LEAD_VOXELS), str::parse)?,
        ..Default::default()
    };
    if args.iter().any(|a| a == "depth") {
        depth_error(&photographs, &truth_mesh, config.bake.max_hull_radius_m)?;
    }
    if let Some(it) = option("refine_truth") {
        // The refinement started from the true surface: how far it leaves it.
        let light = nelf_format::conventions::project_envmap(
            &nelf_scene::envmap::load_envmap(&capture.source_envmap_path().ok_or("needs a named lighting")?)?,
            DMat3::IDENTITY,
        )?;
        let observations = nelf_pipeline::photo::reflectance::observe(
            &truth_mesh,
            &photographs,
            &nelf_pipeline::photo::reflectance::ReflectanceSettings::default(),
            1.5e-3,
        )?;
        let (moved, report) = nelf_pipeline::photo::refine::refine_surface(
            &truth_mesh,
            &observations,
            &light,
            &nelf_pipeline::photo::refine::RefineSettings {
                iterations: it.parse()?,
                smoothness: settings.photo_refine_smoothness,
                ..Default::default()
            },
        )?;
        println!("refine on the truth: {}", serde_json::to_string(&report)?);
        geometry_error(&moved, &truth_mesh, &capture.cameras);
        return Ok(());
    }
    let t = Instant::now();
    // `albedo=truth`: the true albedo on the reconstructed surface (geometry's own error).
    // The reflectance stage again, on the true surface (`mesh=truth`: its own error)
    // or with other settings or lighting (`light=uniform`: a white ambient light).
    let mut reconstruction = reconstruct(&photographs, None, &settings, config.bake.max_hull_radius_m)?;
    let rerun = ["mesh", "light", "texel_samples", "bounces", "highlight"]
        .iter()
        .any(|k| option(k).is_some());
    if rerun {
        let geometry = match option("mesh") {
            Some("truth") => truth_mesh.clone(),
            _ => reconstruction.mesh.clone(),
        };
        let reflectance = nelf_pipeline::photo::reflectance::ReflectanceSettings {
            texel_samples: option("texel_samples").map_or(Ok(1), str::parse)?,
            bounces: option("bounces").map_or(Ok(0), str::parse)?,
            highlight_tolerance: match option("highlight") {
                Some("off") => None,
                Some(t) => Some(t.parse()?),
                None => Some(0.1),
            },
            ..Default::default()
        };
        let observations =
            nelf_pipeline::photo::reflectance::observe(&geometry, &photographs, &reflectance, 1.5e-3)?;
        let (light, named) = if option("light") == Some("uniform") {
            (
                nelf_format::conventions::LatLong::constant(16, 8, [1.0; 3]),
                false,
            )
        } else if option("light") == Some("truth-white") {
            // The source lighting's shape with its colour taken out (equal power per
            // channel) and its scale forgotten: what a perfect fit could give.
            let path = capture
                .source_envmap_path()
                .ok_or("light=truth-white needs a named lighting")?;
            let mut map = nelf_format::conventions::project_envmap(
                &nelf_scene::envmap::load_envmap(&path)?,
                DMat3::IDENTITY,
            )?;
            let integral = map.integral();
            for t in map.texels_mut() {
                for ch in 0..3 {
                    t[ch] = (f64::from(t[ch]) / integral[ch]) as f32;
                }
            }
            if option("mesh") == Some("truth")
                && let nelf_scene::mesh::Albedo::PerVertex(truth_albedo) = &truth_mesh.albedo
            {
                // How well `albedo × white shading` explains the photographs under the
                // true light's shape, vertex by vertex.
                let lum = |c: [f32; 3]| f64::from(c[0] + c[1] + c[2]);
                // Each seen vertex's ratio, with its true albedo (in hundredths) as key.
                let keyed: Vec<([i32; 3], f64)> = (0..observations.colour.len())
                    .filter_map(|i| {
                        let c = observations.colour[i]?;
                        let s = lum(observations.shading(i, &map));
                        (s > 0.0).then(|| {
                            (
                                truth_albedo[i].map(|a| (a * 100.0).round() as i32),
                                lum(c) / s / lum(truth_albedo[i]).max(1e-6),
                            )
                        })
                    })
                    .collect();
                let quantile = |sorted: &[f64], p: f64| sorted[((sorted.len() - 1) as f64 * p) as usize];
                let mut by_albedo = std::collections::BTreeMap::<[i32; 3], Vec<f64>>::new();
                for &(key, ratio) in &keyed {
                    by_albedo.entry(key).or_default().push(ratio);
                }
                let mut ratios: Vec<f64> = keyed.into_iter().map(|(_, ratio)| ratio).collect();
                let mut groups: Vec<_> = by_albedo.into_iter().filter(|(_, v)| v.len() > 200).collect();
                groups.sort_by_key(|(_, v)| std::cmp::Reverse(v.len()));
                for (key, mut v) in groups {
                    v.sort_by(f64::total_cmp);
                    let q = |p: f64| quantile(&v, p);
                    println!(
                        "  albedo {key:?}: {} vertices, ratio percentiles 5 25 50 75 95: {:.3} {:.3} {:.3} {:.3} {:.3}",
                        v.len(),
                        q(0.05),
                        q(0.25),
                        q(0.5),
                        q(0.75),
                        q(0.95)
                    );
                }
                ratios.sort_by(f64::total_cmp);
                let q = |p: f64| quantile(&ratios, p);
                let median = q(0.5);
                println!(
                    "photo / (albedo x shading), relative to the median, percentiles 5 25 50 75 95: {:.2} {:.2} 1 {:.2} {:.2} ({} vertices)",
                    q(0.05) / median,
                    q(0.25) / median,
                    q(0.75) / median,
                    q(0.95) / median,
                    ratios.len()
                );
            }
            (map, false)
        } else {
            let (light, report) = nelf_pipeline::photo::lighting::capture_lighting(
                &photographs,
                None,
                &settings,
                &observations,
                &geometry.triangles,
            )?;
            if let Some(fit) = &report.fit {
                println!("rerun fit: {}", serde_json::to_string(fit)?);
            }
            (light, report.named)
        };
        let (albedo, report) = nelf_pipeline::photo::reflectance::albedo_from_observations(
            &observations,
            &geometry.triangles,
            &light,
            &nelf_pipeline::photo::reflectance::ReflectanceSettings {
                normalise_to: (!named).then_some(0.9),
                ..reflectance
            },
        )?;
        reconstruction.lighting = light;
        if option("mesh") == Some("truth") {
            albedo_error(&albedo, &truth_mesh, &capture.cameras);
        }
        reconstruction.report.reflectance = report;
        reconstruction.mesh = Mesh {
            albedo: nelf_scene::mesh::Albedo::PerVertex(albedo),
            ..geometry
        };
    }
    if option("albedo") == Some("truth") {
        let bvh_t = Bvh::new(&truth_mesh.positions, &truth_mesh.triangles);
        let albedo = reconstruction
            .mesh
            .positions
            .iter()
            .map(|p| {
                bvh_t.closest_point(*p, f32::INFINITY).map_or([0.5; 3], |c| {
                    truth_mesh.albedo_at(c.triangle as usize, c.b1, c.b2)
                })
            })
            .collect();
        reconstruction.mesh.albedo = nelf_scene::mesh::Albedo::PerVertex(albedo);
    }
    let reconstruct_secs = t.elapsed().as_secs_f64();
    let description = serde_json::to_value(&reconstruction.report)?;
    let output = bake_capture(
        &photographs,
        &GroundTruth::Reconstructed {
            mesh: Box::new(reconstruction.mesh.clone()),
            description,
        },
        &nelf_pipeline::photo::reconstruction_bake_config(&config.bake, &settings),
        &Progress::hidden(),
    )?;
    let photo_secs = t.elapsed().as_secs_f64();
    println!(
        "reconstruction {reconstruct_secs:.1} s, bake total {photo_secs:.1} s (truth mesh {} vertices)\n{}",
        truth_mesh.positions.len(),
        serde_json::to_string_pretty(&reconstruction.report)?
    );
    println!("bake stages: {}", serde_json::to_string(&output.report.timings)?);
    let (bytes, _) = nelf_format::encode_asset(&output.asset, &nelf_format::WriteOptions::default())?;
    println!("asset: {} bytes", bytes.len());
    let baked = (output, reconstruction);
    let out = dir.with_file_name("photos_bench");
    write_reconstruction(&baked.1, &out.join("reconstruction"))?;
    geometry_error(&baked.1.mesh, &truth_mesh, &capture.cameras);
    reflectance_error(&baked.1.mesh, &truth_mesh);
    if let Some(path) = capture.source_envmap_path() {
        let truth_light = nelf_format::conventions::project_envmap(
            &nelf_scene::envmap::load_envmap(&path)?,
            DMat3::IDENTITY,
        )?;
        lighting_error(&baked.1.lighting, &truth_light);
    }
    // The reconstruction re-rendered at each source view under the source lighting
    // (direct light only): the reflectance stage's own check.
    if let Some(path) = capture.source_envmap_path() {
        let env = nelf_scene::envmap::load_envmap(&path)?;
        let basis = nelf_format::conventions::project_envmap(&env, DMat3::IDENTITY)?;
        let tracer = nelf_scene::tracer::LtTracer::new(
            &baked.1.mesh,
            nelf_scene::tracer::TraceSettings {
                bounces: 0,
                texel_samples: 1,
                ..Default::default()
            },
        )?;
        // Albedo × ambient occlusion (uniform white light): truth beside reconstruction.
        let white = nelf_format::conventions::LatLong::constant(16, 8, [1.0; 3]);
        let truth_tracer = nelf_scene::tracer::LtTracer::new(&truth_mesh, truth.trace_settings())?;
        for v in [0, capture.len() - 1] {
            let a = nelf_scene::render::render_lt_image(&truth_tracer, &capture.cameras[v], &white, None)?;
            let b = nelf_scene::render::render_lt_image(&tracer, &capture.cameras[v], &white, None)?;
            nelf_pipeline::demo::side_by_side(
                &out.join(format!("albedo_{v}.png")),
                &capture.cameras[v],
                &a.rgb,
                &b.rgb,
                0.0,
            )?;
        }
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
            &baked.0.asset,
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
            "{}: photos {:.2} fg / {:.2} whole (ssim {:.3}, ꟻLIP {:.3} fg / {:.3}); truth bake {:.2} / {:.2} (ꟻLIP {:.3} / {:.3}); flat {:.2} / {:.2} (ꟻLIP {:.3} / {:.3}); gap closed {:.0} %; gain {gain:.3}",
            held.names[t],
            p.foreground_psnr,
            p.psnr,
            p.ssim,
            p.foreground_flip,
            p.flip,
            g.foreground_psnr,
            g.psnr,
            g.foreground_flip,
            g.flip,
            p.flat_foreground_psnr,
            p.flat_psnr,
            p.flat_foreground_flip,
            p.flat_flip,
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
        nelf_pipeline::demo::side_by_side(
            &out.join(format!("vs_truth_bake_{}.png", held.names[t])),
            &held.cameras[t],
            truth_img,
            &photo,
            exposure,
        )?;
    }
    Ok(())
}

/// The reconstructed albedo against the truth's texture at the closest true surface
/// point, over reconstructed vertices within 2 mm of the true surface (where the
/// surfaces agree), after one least-squares gain (a capture that names no lighting
/// has no albedo scale): mean absolute error per channel, and the same for the flat
/// colour (the mean true albedo) as a baseline.
fn reflectance_error(reconstructed: &Mesh, truth: &Mesh) {
    let nelf_scene::mesh::Albedo::PerVertex(albedo) = &reconstructed.albedo else {
        return;
    };
    let bvh = Bvh::new(&truth.positions, &truth.triangles);
    let pairs: Vec<([f32; 3], [f32; 3])> = reconstructed
        .positions
        .iter()
        .zip(albedo)
        .filter_map(|(p, a)| {
            let c = bvh.closest_point(*p, 2e-3)?;
            Some((*a, truth.albedo_at(c.triangle as usize, c.b1, c.b2)))
        })
        .collect();
    if pairs.is_empty() {
        println!("reflectance: no reconstructed vertex within 2 mm of the true surface");
        return;
    }
    let (mut ab, mut aa) = (0.0f64, 0.0f64);
    let mut mean = [0.0f64; 3];
    for (a, b) in &pairs {
        for ch in 0..3 {
            ab += f64::from(a[ch]) * f64::from(b[ch]);
            aa += f64::from(a[ch]).powi(2);
            mean[ch] += f64::from(b[ch]) / pairs.len() as f64;
        }
    }
    let gain = ab / aa.max(1e-30);
    let (mut error, mut flat) = (0.0f64, 0.0f64);
    for (a, b) in &pairs {
        for ch in 0..3 {
            error += (gain * f64::from(a[ch]) - f64::from(b[ch])).abs();
            flat += (mean[ch] - f64::from(b[ch])).abs();
        }
    }
    let count = 3.0 * pairs.len() as f64;
    println!(
        "reflectance: mean absolute albedo error {:.3} after a gain of {gain:.3} (flat colour {:.3}) over {} vertices within 2 mm of the true surface ({:.0} % of them)",
        error / count,
        flat / count,
        pairs.len(),
        100.0 * pairs.len() as f64 / reconstructed.positions.len() as f64
    );
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

/// Mean absolute error (linear, per channel) and mean ratio of an estimated
/// per-vertex albedo of `truth`'s own vertices against its albedo there.
fn albedo_error(albedo: &[[f32; 3]], truth: &Mesh, cameras: &[nelf_format::conventions::PinholeCamera]) {
    let mut corner_albedo = vec![None; truth.positions.len()];
    for (t, tri) in truth.triangles.iter().enumerate() {
        for (k, &v) in tri.iter().enumerate() {
            let (b1, b2) = [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0)][k];
            corner_albedo[v as usize].get_or_insert_with(|| truth.albedo_at(t, b1, b2));
        }
    }
    let normals = truth.vertex_normals();
    let (mut abs, mut est, mut tru, mut count) = ([0.0f64; 3], [0.0f64; 3], [0.0f64; 3], 0.0f64);
    for ((a, t), (p, n)) in albedo
        .iter()
        .zip(&corner_albedo)
        .zip(truth.positions.iter().zip(&normals))
    {
        let Some(t) = t else { continue };
        // Vertices facing every camera (the front of the head).
        if !cameras
            .iter()
            .all(|c| n.dot((c.centre().as_vec3() - *p).normalize()) > 0.3)
        {
            continue;
        }
        for ch in 0..3 {
            abs[ch] += f64::from((a[ch] - t[ch]).abs());
            est[ch] += f64::from(a[ch]);
            tru[ch] += f64::from(t[ch]);
        }
        count += 1.0;
    }
    let r = |v: [f64; 3]| v.map(|v| (v / count * 1e3).round() / 1e3);
    println!(
        "albedo on the true surface (front): mean |error| {:?}, mean estimate {:?}, mean truth {:?} over {count} vertices",
        r(abs),
        r(est),
        r(tru)
    );
}

/// The stereo stage's depth maps against the true surface's depths, per view:
/// median and 90th-percentile error (mm) and the share off by more than 5 mm.
fn depth_error(
    capture: &nelf_bake::LoadedCapture,
    truth: &Mesh,
    max_radius_m: f64,
) -> Result<(), Box<dyn std::error::Error>> {
    use nelf_pipeline::photo::geometry::{SurfaceSettings, hull_surface};
    use nelf_pipeline::photo::stereo::{DepthOrigin, StereoSettings, depth_maps};
    let (hull, _) = hull_surface(
        capture,
        &SurfaceSettings {
            spacing_m: 1.5e-3,
            smoothing_iterations: 0,
            blur_m: 0.0,
            max_radius_m,
            stereo: None,
        },
        None,
    )?;
    let (maps, report) = depth_maps(capture, &hull, &StereoSettings::default());
    println!("stereo: {}", serde_json::to_string(&report)?);
    let bvh = Bvh::new(&truth.positions, &truth.triangles);
    for (v, camera) in capture.cameras.iter().enumerate() {
        let w = camera.width as usize;
        for kind in [DepthOrigin::Stereo, DepthOrigin::Filled] {
            let mut errors = Vec::new();
            for (i, d) in maps[v].depth_m.iter().enumerate() {
                if !d.is_finite() || maps[v].origin[i] != kind {
                    continue;
                }
                let dir = camera.ray_direction(glam::DVec2::new((i % w) as f64 + 0.5, (i / w) as f64 + 0.5));
                if let Some(hit) =
                    bvh.closest_hit(camera.centre().as_vec3(), dir.as_vec3(), 0.0, f32::INFINITY)
                {
                    errors.push(1e3 * f64::from(d - hit.t));
                }
            }
            if errors.is_empty() {
                continue;
            }
            let mut abs: Vec<f64> = errors.iter().map(|e| e.abs()).collect();
            abs.sort_by(f64::total_cmp);
            let mean = errors.iter().sum::<f64>() / errors.len() as f64;
            println!(
                "view {v} {kind:?}: depth error median {:.2} mm, p90 {:.2} mm, > 5 mm {:.1} %, mean signed {mean:+.2} mm over {} pixels",
                abs[abs.len() / 2],
                abs[abs.len() * 9 / 10],
                100.0 * abs.iter().filter(|&&e| e > 5.0).count() as f64 / abs.len() as f64,
                abs.len()
            );
        }
    }
    Ok(())
}

/// The lighting used against the truth's, both 8 × 16: relative RMS error after the
/// best single gain (scale is unknowable without a named lighting), and after the
/// best gain per channel (colour too).
fn lighting_error(used: &nelf_format::conventions::LatLong, truth: &nelf_format::conventions::LatLong) {
    let pairs: Vec<([f32; 3], [f32; 3])> = used
        .texels()
        .iter()
        .copied()
        .zip(truth.texels().iter().copied())
        .collect();
    let error = |gain: [f64; 3]| {
        let (mut num, mut den) = (0.0f64, 0.0f64);
        for (u, t) in &pairs {
            for ch in 0..3 {
                num += (gain[ch] * f64::from(u[ch]) - f64::from(t[ch])).powi(2);
                den += f64::from(t[ch]).powi(2);
            }
        }
        (num / den).sqrt()
    };
    let dot = |ch: Option<usize>| {
        let (mut ut, mut uu) = (0.0f64, 0.0f64);
        for (u, t) in &pairs {
            for c in 0..3 {
                if ch.is_none_or(|k| k == c) {
                    ut += f64::from(u[c]) * f64::from(t[c]);
                    uu += f64::from(u[c]).powi(2);
                }
            }
        }
        ut / uu.max(1e-30)
    };
    let one = dot(None);
    for (name, map, gain) in [("used (x gain)", used, one), ("truth", truth, 1.0)] {
        println!("{name}, luminance per texel (rows from +y down):");
        for row in 0..8 {
            let line: Vec<String> = (0..16)
                .map(|col| {
                    let t = map.get(row, col);
                    format!("{:6.2}", gain * f64::from(t[0] + t[1] + t[2]) / 3.0)
                })
                .collect();
            println!("  {}", line.join(""));
        }
    }
    println!(
        "lighting: relative error {:.3} after one gain, {:.3} after a gain per channel (8 x 16 texels)",
        error([one; 3]),
        error([dot(Some(0)), dot(Some(1)), dot(Some(2))])
    );
}
