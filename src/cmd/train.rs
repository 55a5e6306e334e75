//! `nelf train …`: training the NeLF network on our own path-traced ground truth
//! (the subcommands live in `nelf_train::cli`, shared with its small GPU binary).
//! After a run, the validation curve (PSNR against hours of training, from
//! `validation.csv`) is drawn into `curve.svg` beside it with the evaluation
//! report's chart code.

use std::path::Path;

use anyhow::Context;
pub use nelf_train::cli::TrainArgs;
use nelf_train::cli::TrainCommand;

pub fn run(args: &TrainArgs) -> anyhow::Result<()> {
    let what = match &args.command {
        TrainCommand::Data(data) => format!("writing the training dataset {}", data.out.display()),
        TrainCommand::Run(config) => format!("training into {}", config.out.display()),
        TrainCommand::Eval(eval) => format!(
            "scoring a network on the held-out heads of {}",
            eval.data.display()
        ),
        TrainCommand::ResetDensity(reset) => {
            format!("resetting the density heads of {}", reset.run.display())
        }
    };
    nelf_train::cli::run(args).context(what)?;
    if let TrainCommand::Run(config) = &args.command {
        let curve = config.out.join("curve.svg");
        if write_curve(&config.out.join("validation.csv"), &curve)? {
            println!("validation curve: {}", curve.display());
        }
    }
    Ok(())
}

/// Draws whole-image and foreground validation PSNR against hours of training;
/// `false` when there is no validation yet.
fn write_curve(csv: &Path, svg: &Path) -> anyhow::Result<bool> {
    let Ok(text) = std::fs::read_to_string(csv) else {
        return Ok(false);
    };
    let mut whole = Vec::new();
    let mut foreground = Vec::new();
    let mut flat = Vec::new();
    for line in text.lines().skip(1) {
        let fields: Vec<f64> = line.split(',').filter_map(|f| f.parse().ok()).collect();
        if let [_, secs, _, _, psnr, fg, ..] = fields[..] {
            whole.push((secs / 3600.0, psnr));
            foreground.push((secs / 3600.0, fg));
        }
        // Later logs add the flat-colour baseline of the same views.
        if let [_, secs, _, _, _, _, _, flat_fg] = fields[..] {
            flat.push((secs / 3600.0, flat_fg));
        }
    }
    if whole.is_empty() {
        return Ok(false);
    }
    let series = |name: &str, points: Vec<(f64, f64)>| nelf_eval::report::Series {
        name: name.into(),
        highlight: vec![true; points.len()],
        points,
    };
    let chart = nelf_eval::report::Chart {
        title: "validation on held-out heads and lightings (novel-light views)".into(),
        x_label: "hours of training".into(),
        y_label: "PSNR, 8-bit sRGB (dB)".into(),
        log_x: false,
        series: vec![
            series("whole image", whole),
            series("foreground", foreground),
            series("flat colour in the true silhouette, foreground", flat),
        ],
        threshold_y: None,
    };
    let drawn = nelf_eval::report::chart_svg(&chart).context("drawing the validation curve")?;
    nelf_format::atomic::write_bytes_atomically(svg, drawn.as_bytes())
        .with_context(|| format!("writing {}", svg.display()))?;
    Ok(true)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::write_curve;

    #[test]
    fn the_curve_is_drawn_from_the_validation_log_and_skipped_without_one() {
        let dir = tempfile::tempdir().unwrap();
        let csv = dir.path().join("validation.csv");
        let svg = dir.path().join("curve.svg");
        assert!(!write_curve(&csv, &svg).unwrap());
        std::fs::write(
            &csv,
            "step,train_secs,loss,rgb_fine,val_psnr_db,val_foreground_psnr_db\n250,226.2,1.2,0.11,14.8,11.5\n500,480.0,1.0,0.10,16.2,13.1\n",
        )
        .unwrap();
        assert!(write_curve(&csv, &svg).unwrap());
        let text = std::fs::read_to_string(&svg).unwrap();
        assert!(
            text.starts_with("<svg") && text.contains("foreground") && text.contains("hours of training")
        );
    }
}
