//! How much view dependence could gain at most (a measurement, not a test): bakes a
//! ground-truth capture once per held-aside target with the light transport taken
//! exactly toward that target's eye (`ViewPolicy::TowardPoint`, no view part), scores
//! that target, and prints it beside the usual bake (transport averaged over the
//! source cameras). The difference bounds what any view-dependent representation of
//! the same grid, rank and encoding can recover at those views.
//!
//! `cargo run --release -p nelf-bake --example view_oracle -- CAPTURE_DIR [--resolution N]`

use std::path::PathBuf;

use nelf_bake::eval::{TruthCapture, load_truth_capture, score_view};
use nelf_bake::{BakeConfig, FieldBake, Progress, ViewChoice, bake_field, with_capture_job};
use nelf_scene::field::ViewPolicy;

type Error = Box<dyn std::error::Error>;

fn main() -> Result<(), Error> {
    let mut args = std::env::args().skip(1);
    let dir = PathBuf::from(
        args.next()
            .ok_or("usage: view_oracle CAPTURE_DIR [--resolution N]")?,
    );
    let mut resolution = 128;
    while let Some(a) = args.next() {
        if a == "--resolution" {
            resolution = args.next().ok_or("--resolution needs a value")?.parse()?;
        }
    }
    let TruthCapture { capture, truth, held } = load_truth_capture(&dir)?;
    let config = BakeConfig {
        resolution,
        view_dependence: ViewChoice::Off,
        ..BakeConfig::default()
    };
    let progress = Progress::hidden();
    with_capture_job(&capture, &truth, &config, &progress, |job, prior| {
        let averaged = bake_field(job, &config, &progress, prior)?;
        let (mut sum_avg, mut sum_oracle) = (0.0, 0.0);
        for (i, camera) in held.cameras.iter().enumerate() {
            let toward = FieldBake {
                field: job.field,
                plan: job.plan.clone(),
                cameras: job.cameras.clone(),
                view_policy: ViewPolicy::TowardPoint(camera.centre().as_vec3()),
                reference: job.reference.clone(),
                provenance: job.provenance.clone(),
                held: nelf_bake::eval::HeldAside::default(),
                fine_field: None,
            };
            let exact = bake_field(&toward, &config, &progress, prior)?;
            let (a, _) = score_view(
                &averaged.asset,
                camera,
                &held.envs[i],
                &held.images[i],
                "averaged",
            )?;
            let (o, _) = score_view(&exact.asset, camera, &held.envs[i], &held.images[i], "toward")?;
            println!(
                "{}: averaged over the cameras {:.2} dB, exact toward the target {:.2} dB ({:+.2})",
                held.names[i],
                a.psnr_db,
                o.psnr_db,
                o.psnr_db - a.psnr_db
            );
            sum_avg += a.psnr_db;
            sum_oracle += o.psnr_db;
        }
        let n = held.len().max(1) as f64;
        println!(
            "mean: averaged {:.2} dB, exact {:.2} dB ({:+.2})",
            sum_avg / n,
            sum_oracle / n,
            (sum_oracle - sum_avg) / n
        );
        Ok(())
    })?;
    Ok(())
}
