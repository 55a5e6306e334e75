//! Merging sweeps that ran in parts (one `nelf batch` item per grid resolution of a
//! Pareto sweep, or per axis of a stability sweep, on any number of machines) into
//! the report one machine's run writes. The parts' measured rows and points, their
//! thumbnails, gallery images and assets are gathered into one folder; then the
//! sweep itself runs there over every part's settings, finds each one measured
//! (both sweeps resume from their results file) and writes the CSV, JSON, charts
//! and `report.html` exactly as a single run does — nothing is measured again.

use std::path::{Path, PathBuf};

use crate::error::{EvalError, Result};
use crate::input::copy_tree;
use crate::pareto::{ParetoResults, run_pareto};
use crate::stability::{StabilityResults, run_stability};

fn io(path: &Path, e: &std::io::Error) -> EvalError {
    EvalError::Io {
        path: path.to_path_buf(),
        message: e.to_string(),
    }
}

fn read_json<T: serde::de::DeserializeOwned>(path: &Path) -> Result<T> {
    let text = std::fs::read_to_string(path).map_err(|e| io(path, &e))?;
    serde_json::from_str(&text).map_err(|e| EvalError::Io {
        path: path.to_path_buf(),
        message: format!("not a results file of this nelf: {e}"),
    })
}

/// [`copy_tree`] of a part's folder that may be absent (a part without thumbnails).
fn copy_if_there(from: &Path, to: &Path) -> Result<()> {
    if from.is_dir() {
        copy_tree(from, to)
    } else {
        Ok(())
    }
}

/// Merges Pareto sweeps run in parts (`parts`: their output folders) into `out`.
pub fn merge_pareto(parts: &[PathBuf], out: &Path) -> Result<ParetoResults> {
    let Some(first_part) = parts.first() else {
        return Err(EvalError::Input("no Pareto parts to merge".into()));
    };
    let first: ParetoResults = read_json(&first_part.join("results.json"))?;
    let mut config = first.config.clone();
    config.resolutions.clear();
    config.out = out.to_path_buf();
    let mut merged = ParetoResults {
        config: config.clone(),
        input: first.input.clone(),
        views: first.views.clone(),
        rows: Vec::new(),
        run_secs: 0.0,
    };
    for part in parts {
        let results: ParetoResults = read_json(&part.join("results.json"))?;
        let c = &results.config;
        if c.input != config.input
            || c.quick != config.quick
            || c.image_size != config.image_size
            || c.mesh_height_m != config.mesh_height_m
            || c.mesh_rotate_y_deg != config.mesh_rotate_y_deg
            || c.ranks != config.ranks
            || c.encodings != config.encodings
        {
            return Err(EvalError::Input(format!(
                "{}: a part of another sweep (input, size or settings differ from {})",
                part.display(),
                first_part.display()
            )));
        }
        for resolution in &c.resolutions {
            if !config.resolutions.contains(resolution) {
                config.resolutions.push(*resolution);
            }
        }
        for dir in ["assets", "thumbnails", "capture"] {
            copy_if_there(&part.join(dir), &out.join(dir))?;
        }
        merged.rows.extend(results.rows);
        merged.run_secs += results.run_secs;
    }
    merged.config = config.clone();
    crate::report::write_json(&out.join("results.json"), &merged)?;
    let config = crate::pareto::ParetoConfig {
        no_gpu: true,
        retime: false,
        quiet: true,
        ..config
    };
    run_pareto(&config)
}

/// Merges stability sweeps run in parts (one axis each) into `out`.
pub fn merge_stability(parts: &[PathBuf], out: &Path) -> Result<StabilityResults> {
    let Some(first_part) = parts.first() else {
        return Err(EvalError::Input("no stability parts to merge".into()));
    };
    let first: StabilityResults = read_json(&first_part.join("stability.json"))?;
    let mut config = first.config.clone();
    config.axes.clear();
    config.out = out.to_path_buf();
    config.quiet = true;
    let mut merged = StabilityResults {
        config: config.clone(),
        input: first.input.clone(),
        points: Vec::new(),
        breaks: Vec::new(),
        run_secs: 0.0,
    };
    for part in parts {
        let results: StabilityResults = read_json(&part.join("stability.json"))?;
        let c = &results.config;
        if c.input != config.input
            || c.quick != config.quick
            || c.resolution != config.resolution
            || c.image_size != config.image_size
            || c.mesh_height_m != config.mesh_height_m
            || c.mesh_rotate_y_deg != config.mesh_rotate_y_deg
        {
            return Err(EvalError::Input(format!(
                "{}: a part of another sweep (input, size or settings differ from {})",
                part.display(),
                first_part.display()
            )));
        }
        for axis in &c.axes {
            if !config.axes.contains(axis) {
                config.axes.push(axis.clone());
            }
        }
        for dir in ["gallery", "captures/base"] {
            copy_if_there(&part.join(dir), &out.join(dir))?;
        }
        merged.points.extend(results.points);
        merged.run_secs += results.run_secs;
    }
    merged.config = config.clone();
    crate::report::write_json(&out.join("stability.json"), &merged)?;
    run_stability(&config)
}
