//! Does a network carve the visual hull? For each given head of a dataset: the mean
//! alpha the network renders at its target views inside and outside the true mask,
//! and its density σ at the head's distillation points (near the true surface)
//! beside the true σ.
//!
//! A saturated network shows alpha ≈ 1 wherever the hull is (outside the true mask
//! too) and σ far above what a ray step can resolve, equal where the truth is empty
//! and where it is dense: `nelf train reset-density` repairs such a run.
//!
//! `cargo run --release -p nelf-train --example density_check -- WEIGHTS DATA ID...`

use std::fmt::Write as _;
use std::path::PathBuf;

use nelf_field::Stage;
use nelf_train::TrainConfig;
use nelf_train::forward::{encode, irradiance, run_points};
use nelf_train::trainer::{Jitter, prepare_heads, render_passes, target_rays};

type Failure = Box<dyn std::error::Error>;

fn main() -> Result<(), Failure> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [weights, data, ids @ ..] = args.as_slice() else {
        return Err("usage: density_check WEIGHTS DATA ID...".into());
    };
    let ids = ids
        .iter()
        .map(|s| s.parse::<u32>().map_err(|e| format!("head id {s:?}: {e}")))
        .collect::<Result<Vec<_>, _>>()?;
    let device = nelf_field::default_device();
    let samples = nelf_field::NelfConfig {
        coarse_samples: 32,
        fine_samples: 32,
        ..nelf_field::NelfConfig::for_device(&device)
    };
    let (model, name) =
        nelf_field::shipped::load_or_shipped(Some(&PathBuf::from(weights)), samples, &device)?;
    let size = model.working_image_size().unwrap_or(64);
    let config = TrainConfig {
        image_size: size,
        coarse_samples: 32,
        fine_samples: 32,
        ..TrainConfig::default()
    };
    let dataset = nelf_train::data::Dataset::open(&PathBuf::from(data))?;
    let heads = prepare_heads(&dataset, &ids, size, model.source_relative_light())?;
    println!("{name} at {size}²");
    for (id, head) in ids.iter().zip(&heads) {
        let encoded = encode(&model, &head.capture.views)?;
        for target in &head.targets {
            let irr = irradiance(&target.light_net, model.device())?;
            let pixels: Vec<usize> = (0..target.camera.width * target.camera.height).collect();
            // [inside the true mask, outside] × [alpha sum, pixels].
            let mut sums = [[0.0f64; 2]; 2];
            for chunk in pixels.chunks(512) {
                let rays = target_rays(
                    target,
                    chunk,
                    head.capture.head_centre_net(),
                    model.config().head_radius_mm,
                );
                let (coarse, fine) =
                    render_passes(&model, &encoded, head, &rays, &irr, &config, &mut Jitter::Centred)?;
                let alpha = fine.unwrap_or(coarse).alpha.to_vec1::<f32>()?;
                for (a, &p) in alpha.iter().zip(chunk) {
                    let side = usize::from(target.alpha[p] <= 0.5);
                    sums[side][0] += f64::from(*a);
                    sums[side][1] += 1.0;
                }
            }
            let mean = |s: [f64; 2]| s[0] / s[1].max(1.0);
            println!(
                "head {id}, {:?} target: mean alpha {:.3} inside the true mask, {:.3} outside",
                target.mode,
                mean(sums[0]),
                mean(sums[1])
            );
        }
        let Some(pass) = run_points(
            &model,
            &encoded,
            &head.geometry,
            &head.distill_points,
            &head.distill_dirs,
            Stage::Fine,
        )?
        else {
            println!("head {id}: no distillation point inside the hull");
            continue;
        };
        let density = pass.trace.density.flatten_all()?.to_vec1::<f32>()?;
        // σ by signed distance to the true surface: a blurred surface is dense a few
        // millimetres out; a network whose surface is the visual hull's is dense far out.
        let signed_mm: Vec<f32> = dataset
            .load(*id)?
            .distill
            .signed_distance_m
            .iter()
            .map(|d| d * 1000.0)
            .collect();
        let bands: [(f32, f32); 5] = [
            (-f32::INFINITY, -1.0),
            (-1.0, 1.0),
            (1.0, 5.0),
            (5.0, 15.0),
            (15.0, f32::INFINITY),
        ];
        let mut line = format!("head {id}: network σ (1/mm) by signed distance to the true surface:");
        for (lo, hi) in bands {
            let sigmas: Vec<f64> = pass
                .inside
                .iter()
                .zip(&density)
                .filter(|(i, _)| (lo..hi).contains(&signed_mm[**i as usize]))
                .map(|(_, s)| f64::from(*s))
                .collect();
            let mean = sigmas.iter().sum::<f64>() / sigmas.len().max(1) as f64;
            let _ = write!(line, " [{lo}, {hi}) mm {mean:.2} ({} points);", sigmas.len());
        }
        println!("{line}");
        let (mut empty, mut dense) = (Vec::new(), Vec::new());
        for (&i, &s) in pass.inside.iter().zip(&density) {
            if head.distill_sigma[i as usize] < 1e-3 {
                &mut empty
            } else {
                &mut dense
            }
            .push(f64::from(s));
        }
        let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
        // Radiance at the surface points under the novel-light target's lighting, the
        // network's against the truth, split by whether the direction the truth is for
        // faces the point's side of the head (normal ≈ away from the head's centre).
        if let Some(t) = head
            .targets
            .iter()
            .position(|t| t.mode == nelf_train::data::TargetMode::NovelLight)
        {
            let lt = nelf_train::forward::light_transport(&pass, model.device())?.to_vec2::<f32>()?;
            let light = &head.targets[t].light_net;
            let lights = head.distill_lights.len();
            let centre = head.capture.head_centre_net();
            // [facing, back-facing] × [network, truth].
            let mut sums = [[0.0f64; 2]; 2];
            for (row, &i) in lt.iter().zip(&pass.inside) {
                let i = i as usize;
                if head.distill_sigma[i] < 1e-3 {
                    continue;
                }
                let p = head.distill_points[i];
                let d = head.distill_dirs[i];
                let outward = (0..3)
                    .map(|k| (f64::from(p[k]) - f64::from(centre[k])) * f64::from(d[k]))
                    .sum::<f64>();
                let side = usize::from(outward < 0.0);
                for c in 0..3 {
                    let net: f64 = (0..128)
                        .map(|k| f64::from(row[c * 128 + k] * light[c * 128 + k]))
                        .sum();
                    sums[side][0] += net;
                    sums[side][1] += f64::from(head.distill_radiance[(i * lights + 1 + t) * 3 + c]);
                }
            }
            println!(
                "head {id}: surface radiance under the novel light, network / truth: {:.2} facing outward, {:.2} facing inward",
                sums[0][0] / sums[0][1].max(1e-12),
                sums[1][0] / sums[1][1].max(1e-12)
            );
        }
        // Can the density head's input tell empty from dense at all? Per feature, the
        // gap between the two means over their pooled spread (Fisher's ratio).
        let input = pass.trace.density_in.to_vec2::<f32>()?;
        let mut best = (0.0f64, 0usize);
        let mut magnitude = 0.0f64;
        for f in 0..input.first().map_or(0, Vec::len) {
            let (mut a, mut b) = (Vec::new(), Vec::new());
            for (&i, row) in pass.inside.iter().zip(&input) {
                magnitude += f64::from(row[f].abs());
                if head.distill_sigma[i as usize] < 1e-3 {
                    &mut a
                } else {
                    &mut b
                }
                .push(f64::from(row[f]));
            }
            let var =
                |v: &[f64], m: f64| v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / v.len().max(1) as f64;
            let (ma, mb) = (mean(&a), mean(&b));
            let ratio = (ma - mb).abs() / (0.5 * (var(&a, ma) + var(&b, mb))).sqrt().max(1e-12);
            if ratio > best.0 {
                best = (ratio, f);
            }
        }
        let cells = (input.len() * input.first().map_or(0, Vec::len)).max(1) as f64;
        println!(
            "head {id}: density input mean |x| {:.3}; best single feature {} separates empty from dense by {:.2} pooled std",
            magnitude / cells,
            best.1,
            best.0
        );
        println!(
            "head {id}: network σ {:.4}/mm where the truth is empty ({} points), {:.4}/mm where it is dense ({} points)",
            mean(&empty),
            empty.len(),
            mean(&dense),
            dense.len()
        );
    }
    Ok(())
}
