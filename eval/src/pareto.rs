//! `nelf eval pareto INPUT`: sweeps grid resolution × PCA rank × coefficient
//! encoding and measures, for each setting, accuracy at held-aside views under
//! held-aside lightings ([`crate::measure`]: PSNR, SSIM, ꟻLIP, whole image and
//! foreground, beside the flat-colour baseline), file bytes, bake seconds, CPU
//! render milliseconds and GPU frame milliseconds at 512² and 1080p; marks the
//! Pareto fronts of PSNR against bytes and against frame time ([`crate::front`]);
//! writes `results.json`, `results.csv` and a self-contained `report.html`.
//!
//! The field is sampled once per resolution (`nelf_bake::sample_field`) and every
//! rank and encoding of that resolution is made from it, as `--target-psnr` does.
//! The run resumes: settings already in `results.json` (same sweep configuration)
//! are not measured again.

use std::path::{Path, PathBuf};
use std::time::Instant;

use indicatif::ProgressBar;
use nelf_bake::eval::{HeldAside, load_held_aside};
use nelf_bake::{
    BakeConfig, CaptureLoadOptions, EncodingChoice, Progress, load_capture, sample_field, with_capture_job,
};
use nelf_format::{WriteOptions, write_asset};
use serde::{Deserialize, Serialize};

use crate::error::{EvalError, Result};
use crate::input::{CaptureSetup, EvalInput, prepare};
use crate::measure::{GpuTimer, cpu_render_ms, score_held_aside, write_thumbnail_png};
use crate::rows::ParetoRow;

/// Options of `nelf eval pareto` (saved in `results.json`).
#[allow(clippy::struct_excessive_bools)] // Independent command-line switches.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, clap::Args)]
pub struct ParetoConfig {
    /// What to evaluate: a capture folder (synthetic, with its ground truth), a mesh
    /// file, or `head:SEED` (default `head:0`, the procedural head of `nelf demo`).
    pub input: Option<String>,
    /// Output folder (report.html, results.csv, results.json, assets, thumbnails).
    #[arg(short, long, default_value = "out/eval/pareto")]
    pub out: PathBuf,
    /// A minute or two: 64² images, resolutions 24 and 40, ranks 2 and 8.
    #[arg(long)]
    pub quick: bool,
    /// Grid resolutions (default 64,96,128,192; quick 24,40).
    #[arg(long, value_delimiter = ',')]
    pub resolutions: Vec<u32>,
    /// PCA ranks (default 2,4,8,16,32,64; quick 2,8).
    #[arg(long, value_delimiter = ',')]
    pub ranks: Vec<usize>,
    /// Coefficient encodings (default u8,f16).
    #[arg(long, value_delimiter = ',', value_enum)]
    pub encodings: Vec<EncodingChoice>,
    /// Image side of a synthesized capture's views and targets, pixels (default 256;
    /// quick 64).
    #[arg(long)]
    pub image_size: Option<u32>,
    /// Height a mesh input is scaled to, metres.
    #[arg(long, default_value_t = 0.23)]
    pub mesh_height_m: f32,
    /// Turn a mesh input about +y by this many degrees so that it faces +z (90 for
    /// the shared data/meshes/head.off).
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    pub mesh_rotate_y_deg: f32,
    /// No GPU frame times (they are left empty, not faked).
    #[arg(long)]
    pub no_gpu: bool,
    /// GPU frames timed per setting and size (the minimum is reported).
    #[arg(long, default_value_t = 5)]
    pub gpu_frames: usize,
    /// Measure the CPU and GPU times of the settings already in results.json again
    /// (their assets are kept under assets/), keeping their accuracy figures: for
    /// timings taken on a quiet machine after a sweep that shared it.
    #[arg(long)]
    pub retime: bool,
    /// No progress bars.
    #[arg(long)]
    pub quiet: bool,
}

impl ParetoConfig {
    fn resolutions(&self) -> Vec<u32> {
        match (&self.resolutions[..], self.quick) {
            ([], true) => vec![24, 40],
            ([], false) => vec![64, 96, 128, 192],
            (r, _) => r.to_vec(),
        }
    }

    fn ranks(&self) -> Vec<usize> {
        match (&self.ranks[..], self.quick) {
            ([], true) => vec![2, 8],
            ([], false) => vec![2, 4, 8, 16, 32, 64],
            (r, _) => r.to_vec(),
        }
    }

    fn encodings(&self) -> Vec<EncodingChoice> {
        if self.encodings.is_empty() {
            vec![EncodingChoice::U8, EncodingChoice::F16]
        } else {
            self.encodings.clone()
        }
    }

    fn setup(&self) -> CaptureSetup {
        let base = if self.quick {
            CaptureSetup::quick()
        } else {
            CaptureSetup::full()
        };
        CaptureSetup {
            mesh_height_m: self.mesh_height_m,
            mesh_rotate_y_deg: self.mesh_rotate_y_deg,
            image_size: self.image_size.unwrap_or(base.image_size),
            ..base
        }
    }
}

/// What `results.json` holds.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ParetoResults {
    /// The sweep's options.
    pub config: ParetoConfig,
    /// What was evaluated.
    pub input: String,
    /// Held-aside views scored.
    pub views: Vec<String>,
    /// One row per setting.
    pub rows: Vec<ParetoRow>,
    /// Seconds spent on this sweep, summed over every invocation that resumed it.
    pub run_secs: f64,
}

fn row_id(resolution: u32, rank: usize, encoding: EncodingChoice) -> String {
    format!("r{resolution}-k{rank}-{}", format!("{encoding:?}").to_lowercase())
}

fn create_dir(path: &Path) -> Result<()> {
    std::fs::create_dir_all(path).map_err(|e| EvalError::Io {
        path: path.to_path_buf(),
        message: format!("cannot create the folder: {e}"),
    })
}

/// Loads earlier rows of the same sweep from `results.json`, if any, with the
/// seconds already spent on them.
fn earlier_rows(path: &Path, config: &ParetoConfig) -> (Vec<ParetoRow>, f64) {
    std::fs::read_to_string(path)
        .ok()
        .and_then(|t| serde_json::from_str::<ParetoResults>(&t).ok())
        .filter(|r| {
            r.config.input == config.input
                && r.config.quick == config.quick
                && r.config.mesh_height_m == config.mesh_height_m
                && r.config.mesh_rotate_y_deg == config.mesh_rotate_y_deg
                && r.config.image_size == config.image_size
        })
        .map(|r| (r.rows, r.run_secs))
        .unwrap_or_default()
}

fn save(out: &Path, results: &ParetoResults) -> Result<()> {
    crate::report::write_json(&out.join("results.json"), results)?;
    Ok(())
}

/// Runs the sweep (module docs) and writes its outputs; returns the results.
pub fn run_pareto(config: &ParetoConfig) -> Result<ParetoResults> {
    let start = Instant::now();
    let input = EvalInput::parse(config.input.as_deref())?;
    let out = &config.out;
    for dir in [out.clone(), out.join("assets"), out.join("thumbnails")] {
        create_dir(&dir)?;
    }
    let progress = if config.quiet {
        Progress::hidden()
    } else {
        Progress::stderr()
    };
    let synth_bar = if config.quiet {
        ProgressBar::hidden()
    } else {
        ProgressBar::new(0)
    };
    let prepared = prepare(&input, &config.setup(), out, &synth_bar)?;
    synth_bar.finish_and_clear();
    let capture = load_capture(&prepared.capture_dir, &CaptureLoadOptions::default())?;
    let description = capture.description().ok_or_else(|| {
        EvalError::Input(format!(
            "{}: a cameras.json capture is needed (its held-aside targets are scored)",
            prepared.capture_dir.display()
        ))
    })?;
    let held = load_held_aside(description, &prepared.capture_dir)?;
    if held.is_empty() {
        return Err(EvalError::Input(format!(
            "{}: the capture has no held-aside target views to score at",
            prepared.capture_dir.display()
        )));
    }
    let results_path = out.join("results.json");
    let (mut rows, earlier_secs) = earlier_rows(&results_path, config);
    let mut gpu = if config.no_gpu {
        None
    } else {
        match GpuTimer::new() {
            Ok(g) => Some(g),
            Err(why) => {
                eprintln!("no GPU frame times: {why}");
                None
            }
        }
    };
    let settings: Vec<(u32, usize, EncodingChoice)> = config
        .resolutions()
        .into_iter()
        .flat_map(|r| {
            config
                .ranks()
                .into_iter()
                .flat_map(move |k| config.encodings().into_iter().map(move |e| (r, k, e)))
        })
        .collect();
    let total = settings.len() as u64;
    let bar = progress.bar("settings", total, "settings");
    bar.inc(
        settings
            .iter()
            .filter(|(r, k, e)| rows.iter().any(|row| row.id == row_id(*r, *k, *e)))
            .count() as u64,
    );
    let mut results = ParetoResults {
        config: config.clone(),
        input: input.name(),
        views: held.names.clone(),
        rows: Vec::new(),
        run_secs: 0.0,
    };
    if config.retime {
        let bar = progress.bar("retime", rows.len() as u64, "settings");
        for row in &mut rows {
            retime(row, &held, out, gpu.as_mut(), config)?;
            bar.inc(1);
        }
        bar.finish_and_clear();
    }
    for resolution in config.resolutions() {
        let todo: Vec<(usize, EncodingChoice)> = settings
            .iter()
            .filter(|(r, k, e)| *r == resolution && !rows.iter().any(|row| row.id == row_id(*r, *k, *e)))
            .map(|(_, k, e)| (*k, *e))
            .collect();
        if todo.is_empty() {
            continue;
        }
        let bake_config = BakeConfig {
            resolution,
            max_rank: todo.iter().map(|(k, _)| *k).max().unwrap_or(1).clamp(1, 384),
            render_size: config.setup().image_size.clamp(8, 128),
            ..BakeConfig::default()
        };
        let t = Instant::now();
        let new_rows = with_capture_job(
            &capture,
            &prepared.truth,
            &bake_config,
            &Progress::hidden(),
            |job, prior| {
                let sampled = sample_field(job, &bake_config, &Progress::hidden(), prior)?;
                let sample_secs = t.elapsed().as_secs_f64();
                let mut made = Vec::new();
                for &(rank, encoding) in &todo {
                    let row = measure_setting(
                        &sampled,
                        resolution,
                        rank,
                        encoding,
                        sample_secs,
                        &held,
                        out,
                        gpu.as_mut(),
                        config,
                    )
                    .map_err(|e| nelf_bake::BakeError::Settings(e.to_string()))?;
                    made.push(row);
                    bar.inc(1);
                }
                Ok(made)
            },
        )?;
        rows.extend(new_rows);
        results.rows.clone_from(&rows);
        results.run_secs = earlier_secs + start.elapsed().as_secs_f64();
        save(out, &results)?;
    }
    bar.finish_and_clear();
    // Keep the sweep's order, drop rows of settings no longer asked for.
    let mut ordered: Vec<ParetoRow> = settings
        .iter()
        .filter_map(|(r, k, e)| rows.iter().find(|row| row.id == row_id(*r, *k, *e)).cloned())
        .collect();
    crate::front::mark_fronts(&mut ordered);
    results.rows = ordered;
    results.run_secs = earlier_secs + start.elapsed().as_secs_f64();
    save(out, &results)?;
    crate::report::write_csv(&out.join("results.csv"), &results.rows)?;
    let mut sections = crate::report::pareto_sections(&results.rows, &results.input, out);
    sections.insert(0, about_section(&results, &held));
    crate::report::write_chart_files(&out.join("charts"), &sections)?;
    crate::report::write_html_report(
        &out.join("report.html"),
        &format!("nelf eval pareto: {}", results.input),
        &sections,
    )?;
    Ok(results)
}

fn about_section(results: &ParetoResults, held: &HeldAside) -> crate::report::Section {
    crate::report::Section {
        heading: "What was measured".into(),
        text: format!(
            "{} settings of {}; accuracy at {} held-aside views ({}), each under its own lighting, against path-traced ground truth; the flat-colour baseline is the truth's mean foreground colour inside the true silhouette. Run time {:.1} s.",
            results.rows.len(),
            results.input,
            held.len(),
            held.names.join(", "),
            results.run_secs
        ),
        charts: Vec::new(),
        table: None,
        images: Vec::new(),
    }
}

/// The times of one setting.
struct Times {
    cpu_ms: f64,
    gpu_512: Option<f64>,
    gpu_1080: Option<f64>,
    adapter: Option<String>,
}

/// The CPU and GPU times of one setting.
fn times(
    asset: &nelf_format::Asset,
    id: &str,
    held: &HeldAside,
    gpu: Option<&mut GpuTimer>,
    config: &ParetoConfig,
) -> Result<Times> {
    let step = BakeConfig::default().step_voxels;
    let cpu_ms = cpu_render_ms(asset, &held.cameras[0], &held.envs[0], step)?;
    // A GPU that cannot hold the asset (a binding limit) leaves its times empty.
    let (gpu_512, gpu_1080, adapter) = match gpu {
        Some(g) => {
            let mut time = |w: u32, h: u32| match g.frame_ms(asset, &held.envs[0], w, h, config.gpu_frames) {
                Ok(ms) => Some(ms),
                Err(e) => {
                    eprintln!("{id}: no GPU frame time at {w}×{h}: {e}");
                    None
                }
            };
            let (a, b) = (time(512, 512), time(1920, 1080));
            (a, b, Some(g.adapter().to_string()))
        }
        None => (None, None, None),
    };
    Ok(Times {
        cpu_ms,
        gpu_512,
        gpu_1080,
        adapter,
    })
}

/// Re-measures `row`'s times from `assets/<id>.nelf`.
fn retime(
    row: &mut ParetoRow,
    held: &HeldAside,
    out: &Path,
    gpu: Option<&mut GpuTimer>,
    config: &ParetoConfig,
) -> Result<()> {
    let path = out.join("assets").join(format!("{}.nelf", row.id));
    let asset = nelf_format::read_asset(&path)?;
    let t = times(&asset, &row.id, held, gpu, config)?;
    row.cpu_render_ms = t.cpu_ms;
    row.gpu_frame_ms_512 = t.gpu_512;
    row.gpu_frame_ms_1080p = t.gpu_1080;
    row.gpu_adapter = t.adapter;
    Ok(())
}

#[allow(clippy::too_many_arguments)] // One setting's every input; a struct would only rename them.
fn measure_setting(
    sampled: &nelf_bake::SampledField,
    resolution: u32,
    rank: usize,
    encoding: EncodingChoice,
    sample_secs: f64,
    held: &HeldAside,
    out: &Path,
    gpu: Option<&mut GpuTimer>,
    config: &ParetoConfig,
) -> Result<ParetoRow> {
    let id = row_id(resolution, rank, encoding);
    let t = Instant::now();
    let rank_used = rank.min(sampled.top_rank);
    let mut asset = sampled.asset(rank_used, encoding.encoding())?;
    asset.metadata = serde_json::json!({
        "generator": "nelf eval pareto",
        "setting": { "resolution": resolution, "rank": rank_used, "encoding": encoding },
    });
    let path = out.join("assets").join(format!("{id}.nelf"));
    let written = write_asset(&path, &asset, &WriteOptions::default())?;
    let own_secs = t.elapsed().as_secs_f64();
    let step = BakeConfig::default().step_voxels;
    let (scores, views) = score_held_aside(&asset, held, step)?;
    let thumbnail = format!("thumbnails/{id}.png");
    write_thumbnail_png(&out.join(&thumbnail), &held.images[0], &views[0])?;
    let t = times(&asset, &id, held, gpu, config)?;
    Ok(ParetoRow {
        id,
        resolution,
        rank: rank_used,
        encoding: format!("{encoding:?}").to_lowercase(),
        voxels: asset.voxel_count(),
        file_bytes: written.file_size,
        bake_secs: sample_secs + own_secs,
        scores,
        cpu_render_ms: t.cpu_ms,
        gpu_frame_ms_512: t.gpu_512,
        gpu_frame_ms_1080p: t.gpu_1080,
        gpu_adapter: t.adapter,
        thumbnail: Some(thumbnail),
        front_bytes: false,
        front_frame: false,
    })
}
