//! Model no more than a scene needs: `nelf bake capture DIR --target-psnr DB`
//! (and/or `--max-bytes N`) picks the smallest asset (grid resolution, PCA rank,
//! coefficient encoding) that meets a PSNR target on the capture's own held-aside
//! views, and reports every candidate it tried.
//!
//! **The figure judged** is the one `nelf eval` and `bake_eval` report: the mean
//! over the capture's target views of whole-image PSNR (data range: each reference's
//! largest value), each target rendered under its own lighting with
//! [`EVAL_PIXEL_GRID`]² rays per pixel.
//!
//! **Cheap candidates.** The field is sampled once per resolution
//! ([`crate::sample_field`]: density, light transport, PCA at the largest
//! rank); every rank and encoding is made from that sample. A render is linear in
//! the per-voxel radiance, so each target is marched once with the features
//! `[1, c₀ … c_{K−1}]` (one ray per pixel) and the image of every rank `k` is a
//! `k`-term sum per pixel. Antialiasing is added as a correction:
//! `MSE_k ≈ MSE_top(4×4 rays) + MSE_k(1 ray) − MSE_top(1 ray)` (silhouette aliasing
//! hardly depends on the rank, the rank's error hardly on the silhouette), and the
//! asset finally chosen is rendered exactly and its PSNR reported; should it miss
//! the target, the next larger candidate is tried.
//!
//! **Resolutions** are tried in increasing order (default: ½ and 1 × `--resolution`,
//! so `--resolution` is the largest grid tried; a ½-resolution sample costs about a
//! quarter of a full one, so the choice stays within ~1.5–2× a plain bake); a larger grid is sampled only when
//! no candidate of a smaller one meets the target, since voxels grow as the square of
//! the resolution and with them the file. With `--max-bytes` alone the candidate of
//! highest PSNR within the budget wins, and resolutions grow until even rank 1 is over
//! budget. At each resolution and encoding the rank is the smallest meeting the
//! target (or the largest within the budget): file bytes are exact (the candidate
//! encoded in memory), PSNR as above. f16 coefficients are tried only where they
//! can win (`f16_worth_trying`): they cost twice the bytes of 8-bit ones at a rank.

use std::time::Instant;

use nelf_format::Asset;
use nelf_render::{BrickGrid, MarchSettings, project_light_texels, render_asset, render_features};
use nelf_scene::metrics::mse;
use serde::{Deserialize, Serialize};

use crate::capture_in::LoadedCapture;
use crate::config::{BakeConfig, EncodingChoice};
use crate::error::{BakeError, Result};
use crate::eval::{EVAL_PIXEL_GRID, HeldAside, data_range, encoded_bytes, load_held_aside};
use crate::progress::Progress;
use crate::rank::{candidate_ranks, light_texels};
use crate::source::GroundTruth;
use crate::stages;
use crate::stages::outputs::{BakeOutput, SampledField};
use crate::stages::view::add_view_dependence;

/// What to choose for (`nelf bake capture` options).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize, clap::Args)]
pub struct ChoiceArgs {
    /// Choose the smallest asset (resolution, rank, encoding) whose mean whole-image
    /// PSNR at the capture's held-aside target views reaches this many dB.
    #[arg(long, value_name = "DB")]
    pub target_psnr: Option<f64>,
    /// Choose among assets of at most this many bytes (with --target-psnr: the
    /// smallest meeting the target within the budget; alone: the best within it).
    #[arg(long, value_name = "BYTES")]
    pub max_bytes: Option<u64>,
    /// Grid resolutions to try, ascending (default: ½ and 1 × --resolution; each
    /// one more costs a field sample).
    #[arg(long, value_delimiter = ',', value_name = "R,R,…")]
    pub choice_resolutions: Vec<u32>,
}

impl ChoiceArgs {
    /// Whether a choice was asked for.
    pub fn is_active(&self) -> bool {
        self.target_psnr.is_some() || self.max_bytes.is_some()
    }

    /// Checks the options.
    pub fn validate(&self) -> Result<()> {
        if let Some(t) = self.target_psnr
            && !(t.is_finite() && t > 0.0)
        {
            return Err(BakeError::Settings(format!(
                "--target-psnr {t} must be a positive number of dB"
            )));
        }
        if self.max_bytes == Some(0) {
            return Err(BakeError::Settings("--max-bytes must be positive".into()));
        }
        if self.choice_resolutions.iter().any(|&r| !(8..=2048).contains(&r)) {
            return Err(BakeError::Settings(format!(
                "--choice-resolutions {:?}: each must be in 8..=2048",
                self.choice_resolutions
            )));
        }
        Ok(())
    }

    /// The resolutions tried, ascending, without repeats.
    pub fn resolutions(&self, config: &BakeConfig) -> Vec<u32> {
        let mut out = if self.choice_resolutions.is_empty() {
            let r = config.resolution;
            vec![(r / 2).max(8), r]
        } else {
            self.choice_resolutions.clone()
        };
        out.sort_unstable();
        out.dedup();
        out
    }
}

/// One candidate tried.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ChoiceCandidate {
    /// Grid resolution.
    pub resolution: u32,
    /// Voxel edge, metres.
    pub voxel_size_m: f64,
    /// Voxels.
    pub voxels: usize,
    /// PCA rank.
    pub rank: usize,
    /// Coefficient encoding.
    pub encoding: EncodingChoice,
    /// Estimated mean held-aside PSNR (module docs), dB.
    pub psnr_db: f64,
    /// Bytes of the encoded asset (metadata aside), when it was encoded.
    pub bytes: Option<u64>,
}

/// What the choice did and why.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ChoiceReport {
    /// The options.
    pub args: ChoiceArgs,
    /// Held-aside views judged.
    pub views: Vec<String>,
    /// Resolutions whose field was sampled.
    pub resolutions_sampled: Vec<u32>,
    /// Every candidate, in the order tried.
    pub candidates: Vec<ChoiceCandidate>,
    /// The candidate chosen (index into `candidates`).
    pub chosen: usize,
    /// Its held-aside PSNR rendered exactly, dB.
    pub verified_psnr_db: f64,
    /// Why it was chosen, in words.
    pub reason: String,
    /// Seconds for the whole choice (sampling, candidates, the final asset).
    pub secs: f64,
}

/// Estimated held-aside PSNR (dB, mean over views) of every rank in `ranks`
/// (ascending, each ≤ the asset's rank) of `full` (see the module docs).
pub fn rank_psnrs(full: &Asset, ranks: &[usize], held: &HeldAside, step_voxels: f32) -> Result<Vec<f64>> {
    let grid = BrickGrid::from_asset(full)?;
    let density: Vec<f32> = full.density.iter().map(|d| d.to_f32()).collect();
    let top = full.rank();
    let dim = top + 1;
    let mut features = vec![0.0f32; grid.voxel_count() * dim];
    for (v, f) in features.chunks_exact_mut(dim).enumerate() {
        f[0] = 1.0;
        full.coefficients.voxel_f32(v, &mut f[1..]);
    }
    let one_ray = MarchSettings {
        step_voxels,
        pixel_grid: 1,
        ..MarchSettings::default()
    };
    let antialiased = MarchSettings {
        pixel_grid: EVAL_PIXEL_GRID,
        ..one_ray
    };
    let mut sums = vec![0.0f64; ranks.len()];
    for (((camera, truth), env), _) in held
        .cameras
        .iter()
        .zip(&held.images)
        .zip(&held.envs)
        .zip(&held.names)
    {
        let range = f64::from(data_range(truth));
        let exact_top = render_asset(full, camera, env, glam::DMat3::IDENTITY, None, &antialiased)?;
        let mse_top_aa = mse(&exact_top.rgb, truth)?;
        let rendered = render_features(&grid, &density, &features, dim, camera, &one_ray)?;
        let light = project_light_texels(&full.pca, &light_texels(env, full.world_from_light)?)?;
        // The one-ray image, component by component; its MSE is kept at every
        // candidate rank (ranks above the top count as the top).
        let mut image: Vec<[f32; 3]> = rendered
            .chunks_exact(dim)
            .map(|f| light.mean_rgb.map(|m| f[0] * m))
            .collect();
        let mut mse_at = vec![0.0f64; top + 1];
        for (j, p) in light.component_rgb.iter().enumerate() {
            for (px, f) in image.iter_mut().zip(rendered.chunks_exact(dim)) {
                for c in 0..3 {
                    px[c] += f[j + 1] * p[c];
                }
            }
            if ranks.contains(&(j + 1)) || j + 1 == top {
                mse_at[j + 1] = mse(&image, truth)?;
            }
        }
        let mse_k: Vec<f64> = ranks.iter().map(|&k| mse_at[k.min(top)]).collect();
        let mse_top_one = mse_at[top];
        for (s, m) in sums.iter_mut().zip(&mse_k) {
            let corrected = (mse_top_aa + m - mse_top_one)
                .max(1e-3 * mse_top_aa)
                .max(f64::MIN_POSITIVE);
            *s += 10.0 * (range * range / corrected).log10();
        }
    }
    let n = held.len().max(1) as f64;
    Ok(sums.into_iter().map(|s| s / n).collect())
}

/// Mean held-aside PSNR of `asset` rendered exactly ([`EVAL_PIXEL_GRID`]² rays per pixel).
pub fn held_aside_psnr(asset: &Asset, held: &HeldAside, step_voxels: f32) -> Result<f64> {
    crate::eval::held_aside_psnr(asset, held, step_voxels, EVAL_PIXEL_GRID)
}

/// The candidates of one sampled resolution: per encoding, the smallest rank
/// meeting the target (bytes measured), or with a budget only, the largest rank
/// within it. Also lists every rank's estimated PSNR (bytes unmeasured).
fn resolution_candidates(
    sampled: &SampledField,
    resolution: u32,
    args: &ChoiceArgs,
    held: &HeldAside,
    step_voxels: f32,
    progress: Progress,
) -> Result<Vec<ChoiceCandidate>> {
    let ranks = candidate_ranks(sampled.top_rank, sampled.data_rank);
    let voxel_size_m = sampled.dense.grid.geometry().voxel_size_m;
    let voxels = sampled.dense.grid.voxel_count();
    let mut out: Vec<ChoiceCandidate> = Vec::new();
    let bar = progress.bar("candidates", 2, "encodings");
    for encoding in [EncodingChoice::U8, EncodingChoice::F16] {
        if encoding == EncodingChoice::F16 && !f16_worth_trying(&out, args) {
            continue;
        }
        let full = sampled.asset(sampled.top_rank, encoding.encoding())?;
        let psnrs = rank_psnrs(&full, &ranks, held, step_voxels)?;
        let mut rows: Vec<ChoiceCandidate> = ranks
            .iter()
            .zip(&psnrs)
            .map(|(&rank, &psnr_db)| ChoiceCandidate {
                resolution,
                voxel_size_m,
                voxels,
                rank,
                encoding,
                psnr_db,
                bytes: None,
            })
            .collect();
        if let Some(target) = args.target_psnr {
            if let Some(i) = rows.iter().position(|r| r.psnr_db >= target) {
                measure_bytes(sampled, &mut rows[i])?;
            }
        } else if let Some(budget) = args.max_bytes {
            // Bytes grow with the rank: binary search the largest rank within budget.
            let (mut lo, mut hi) = (0usize, rows.len());
            while lo < hi {
                let mid = usize::midpoint(lo, hi);
                if measure_bytes(sampled, &mut rows[mid])? <= budget {
                    lo = mid + 1;
                } else {
                    hi = mid;
                }
            }
        }
        out.extend(rows);
        bar.inc(1);
    }
    bar.finish_and_clear();
    Ok(out)
}

/// Bytes of a candidate's asset (encoded in memory once, then remembered).
fn measure_bytes(sampled: &SampledField, c: &mut ChoiceCandidate) -> Result<u64> {
    if let Some(b) = c.bytes {
        return Ok(b);
    }
    let b = encoded_bytes(&sampled.asset(c.rank, c.encoding.encoding())?)?;
    c.bytes = Some(b);
    Ok(b)
}

/// Whether f16 coefficients can win over the 8-bit ones of the same resolution
/// (`u8` rows, already measured). They take twice the bytes at a rank and differ in
/// PSNR only by the 8-bit rounding, so: with a target, only when no 8-bit rank meets
/// it but the best comes within [`F16_MARGIN_DB`]; with a budget alone, only when
/// the 8-bit asset at the top rank fits it (more PSNR might then be bought).
fn f16_worth_trying(u8_rows: &[ChoiceCandidate], args: &ChoiceArgs) -> bool {
    let best = u8_rows
        .iter()
        .map(|c| c.psnr_db)
        .fold(f64::NEG_INFINITY, f64::max);
    if let Some(target) = args.target_psnr {
        return best < target && best >= target - F16_MARGIN_DB;
    }
    match (args.max_bytes, u8_rows.last().and_then(|c| c.bytes)) {
        (Some(budget), Some(top_bytes)) => top_bytes <= budget,
        _ => false,
    }
}

/// How far below a target the best 8-bit candidate may be for f16 to be tried, dB.
pub const F16_MARGIN_DB: f64 = 0.5;

/// Whether `c` is acceptable: meets the target (if any) and the budget (if any,
/// with bytes measured).
fn acceptable(c: &ChoiceCandidate, args: &ChoiceArgs) -> bool {
    let meets = args.target_psnr.is_none_or(|t| c.psnr_db >= t);
    // Only candidates whose bytes were measured are acceptable.
    let within = c
        .bytes
        .is_some_and(|b| args.max_bytes.is_none_or(|budget| b <= budget));
    meets && within
}

/// Ranks acceptable candidates: with a target, fewest bytes first; budget only,
/// highest PSNR first.
fn order(a: &ChoiceCandidate, b: &ChoiceCandidate, args: &ChoiceArgs) -> std::cmp::Ordering {
    if args.target_psnr.is_some() {
        a.bytes.cmp(&b.bytes).then(b.psnr_db.total_cmp(&a.psnr_db))
    } else {
        b.psnr_db.total_cmp(&a.psnr_db).then(a.bytes.cmp(&b.bytes))
    }
}

/// Bakes the capture's ground truth to the smallest asset meeting `args` (module
/// docs). `config` gives every other setting; its `--resolution` is the largest
/// grid tried unless `--choice-resolutions` says otherwise, and its `--rank` and
/// `--encoding` are ignored (they are what is chosen).
pub fn bake_capture_to_target(
    capture: &LoadedCapture,
    truth: &GroundTruth,
    config: &BakeConfig,
    args: &ChoiceArgs,
    progress: &Progress,
) -> Result<(BakeOutput, ChoiceReport)> {
    let start = Instant::now();
    args.validate()?;
    config.validate()?;
    if !args.is_active() {
        return Err(BakeError::Settings(
            "a choice needs --target-psnr or --max-bytes".into(),
        ));
    }
    let description = capture.description().ok_or_else(|| {
        BakeError::Settings(format!(
            "{}: --target-psnr/--max-bytes judge candidates at held-aside target views, which only a cameras.json capture can list (COLMAP models have none)",
            capture.dir.display()
        ))
    })?;
    let held = load_held_aside(description, &capture.dir)?;
    if held.is_empty() {
        return Err(BakeError::Settings(format!(
            "{}: the capture has no held-aside target views (`targets` in cameras.json); --target-psnr/--max-bytes judge candidates there",
            capture.dir.display()
        )));
    }
    let mut candidates: Vec<ChoiceCandidate> = Vec::new();
    let mut sampled_resolutions = Vec::new();
    let mut best: Option<(BakeOutput, usize, f64)> = None;
    for resolution in args.resolutions(config) {
        let config_r = BakeConfig {
            resolution,
            voxel_size_m: None,
            rank: None,
            ..config.clone()
        };
        let finished = stages::with_truth_job(capture, truth, &config_r, *progress, |job, prior| {
            let sampled = stages::sample(job, &config_r, *progress, prior)?;
            let first = candidates.len();
            candidates.extend(resolution_candidates(
                &sampled,
                resolution,
                args,
                &held,
                config.step_voxels,
                *progress,
            )?);
            // This resolution's acceptable candidates, best first.
            let mut local: Vec<usize> = (first..candidates.len())
                .filter(|&i| acceptable(&candidates[i], args))
                .collect();
            local.sort_by(|&a, &b| order(&candidates[a], &candidates[b], args));
            if let Some((_, best_i, _)) = &best
                && let Some(&i) = local.first()
                && order(&candidates[*best_i], &candidates[i], args).is_le()
            {
                return Ok(None);
            }
            // The best first; should its exact render miss the target (the
            // estimate was optimistic), the next rank up of the same encoding.
            let mut queue = local;
            for _ in 0..3 {
                if queue.is_empty() {
                    break;
                }
                let i = queue.remove(0);
                let c = &candidates[i];
                let config_c = BakeConfig {
                    rank: Some(c.rank),
                    encoding: c.encoding,
                    ..config_r.clone()
                };
                let mut output = stages::finish(job, &config_c, *progress, &sampled)?;
                // The view part (`--view-dependence`), judged at the same held-aside views;
                // dropped again when it breaks the byte budget.
                add_view_dependence(job, &config_c, progress, &sampled, &mut output)?;
                if let Some(max) = args.max_bytes
                    && (output.asset.view.is_some() || output.asset.reflection.is_some())
                    && encoded_bytes(&output.asset)? > max
                {
                    output.asset.view = None;
                    output.asset.reflection = None;
                    if let Some(v) = output.report.view.as_mut() {
                        v.chosen = crate::view::ViewChoice::Off;
                        v.chosen_index = None;
                    }
                    if let Some(meta) = output.asset.metadata.as_object_mut() {
                        meta.insert(
                            "view_dependence".into(),
                            serde_json::json!({ "dropped": "over --max-bytes" }),
                        );
                    }
                }
                let verified = held_aside_psnr(&output.asset, &held, config.step_voxels)?;
                if args.target_psnr.is_none_or(|t| verified >= t) {
                    return Ok(Some((output, i, verified)));
                }
                let j = i + 1;
                if j < candidates.len()
                    && candidates[j].resolution == resolution
                    && candidates[j].encoding == candidates[i].encoding
                    && args.target_psnr.is_none_or(|t| candidates[j].psnr_db >= t)
                {
                    measure_bytes(&sampled, &mut candidates[j])?;
                    queue.push(j);
                    queue.sort_by(|&a, &b| order(&candidates[a], &candidates[b], args));
                }
            }
            Ok(None)
        })?;
        sampled_resolutions.push(resolution);
        let met_here = finished.is_some();
        if let Some(found) = finished {
            best = Some(found);
        }
        let stop = if args.target_psnr.is_some() {
            met_here
        } else {
            // Budget only: stop once even rank 1 of this resolution is over budget.
            candidates
                .iter()
                .filter(|c| c.resolution == resolution && c.rank == 1)
                .all(|c| c.bytes.is_some_and(|b| Some(b) > args.max_bytes))
        };
        if stop {
            break;
        }
    }
    let Some((mut output, chosen, verified_psnr_db)) = best else {
        let top = candidates
            .iter()
            .max_by(|a, b| a.psnr_db.total_cmp(&b.psnr_db))
            .map_or_else(String::new, |c| {
                format!(
                    "; the best reached is {:.2} dB (resolution {}, rank {}, {:?})",
                    c.psnr_db, c.resolution, c.rank, c.encoding
                )
            });
        let smallest = candidates
            .iter()
            .filter_map(|c| c.bytes.map(|b| (b, c)))
            .min_by_key(|(b, _)| *b)
            .map_or_else(String::new, |(b, c)| {
                format!("; the smallest measured is {b} bytes at {:.2} dB", c.psnr_db)
            });
        return Err(BakeError::Settings(format!(
            "no asset meets {}{}{top}{smallest}; raise --resolution (the largest grid tried) or lower the target",
            args.target_psnr
                .map_or_else(String::new, |t| format!("--target-psnr {t} dB")),
            args.max_bytes
                .map_or_else(String::new, |b| format!(" within --max-bytes {b}")),
        )));
    };
    let c = &candidates[chosen];
    let reason = match (args.target_psnr, args.max_bytes) {
        (Some(t), budget) => format!(
            "the smallest candidate estimated at ≥ {t} dB{}: resolution {} ({} voxels), rank {}, {:?}, {} bytes before metadata, {verified_psnr_db:.2} dB rendered exactly",
            budget.map_or_else(String::new, |b| format!(" within {b} bytes")),
            c.resolution,
            c.voxels,
            c.rank,
            c.encoding,
            c.bytes.unwrap_or(0)
        ),
        (None, budget) => format!(
            "the best candidate within {} bytes: resolution {}, rank {}, {:?}, {} bytes before metadata, {verified_psnr_db:.2} dB rendered exactly",
            budget.unwrap_or(0),
            c.resolution,
            c.rank,
            c.encoding,
            c.bytes.unwrap_or(0)
        ),
    };
    let report = ChoiceReport {
        args: args.clone(),
        views: held.names.clone(),
        resolutions_sampled: sampled_resolutions,
        candidates: candidates.clone(),
        chosen,
        verified_psnr_db,
        reason,
        secs: start.elapsed().as_secs_f64(),
    };
    if let Some(m) = output.asset.metadata.as_object_mut() {
        m.insert(
            "choice".into(),
            serde_json::to_value(&report).map_err(|e| BakeError::Settings(format!("choice report: {e}")))?,
        );
    }
    Ok((output, report))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cand(rank: usize, psnr_db: f64, bytes: Option<u64>) -> ChoiceCandidate {
        ChoiceCandidate {
            resolution: 64,
            voxel_size_m: 0.004,
            voxels: 1000,
            rank,
            encoding: EncodingChoice::U8,
            psnr_db,
            bytes,
        }
    }

    #[test]
    fn acceptance_and_order_follow_the_mode() {
        let target = ChoiceArgs {
            target_psnr: Some(30.0),
            ..ChoiceArgs::default()
        };
        assert!(acceptable(&cand(4, 31.0, Some(100)), &target));
        assert!(!acceptable(&cand(4, 29.0, Some(100)), &target));
        assert!(!acceptable(&cand(4, 31.0, None), &target), "bytes unmeasured");
        let (small, big) = (cand(2, 30.5, Some(90)), cand(8, 35.0, Some(200)));
        assert!(order(&small, &big, &target).is_lt(), "fewest bytes first");
        let budget = ChoiceArgs {
            max_bytes: Some(150),
            ..ChoiceArgs::default()
        };
        assert!(acceptable(&small, &budget));
        assert!(!acceptable(&big, &budget));
        let (worse, better) = (cand(2, 30.5, Some(90)), cand(3, 31.0, Some(120)));
        assert!(order(&better, &worse, &budget).is_lt(), "best PSNR first");
    }

    #[test]
    fn default_resolutions_end_at_the_configured_one() {
        let config = BakeConfig::default();
        assert_eq!(ChoiceArgs::default().resolutions(&config), vec![64, 128]);
        let given = ChoiceArgs {
            choice_resolutions: vec![96, 48, 96],
            ..ChoiceArgs::default()
        };
        assert_eq!(given.resolutions(&config), vec![48, 96]);
        assert!(
            ChoiceArgs {
                target_psnr: Some(f64::NAN),
                ..ChoiceArgs::default()
            }
            .validate()
            .is_err()
        );
    }
}
