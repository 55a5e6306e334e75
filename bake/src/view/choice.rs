//! Choosing the view part: every candidate (lobes × view rank, and the reflection
//! part's exponents) built from one fit, rendered at the judging views (the capture's
//! held-aside targets, else its own views) and kept only when it gains more than
//! `--view-min-gain-db` over the view-independent asset; `auto` first probes on a
//! subsample of the band ([`ViewProbe`]).

use glam::{DVec3, Vec3};
use nelf_format::conventions::{LT_DIM, VIEW_HARMONICS};
use nelf_format::{Coefficients, Reflection, ViewDependence};
use nelf_render::BrickGrid;
use nelf_scene::field::FieldSource;
use serde::{Deserialize, Serialize};

use crate::error::{BakeError, Result};
use crate::progress::Progress;
use crate::view::harmonic::{FitScope, PROBE_SAMPLE, ViewChoice, ViewFit, fit_view};
use crate::view::reflection::{REFLECT_EXPONENTS, ReflectionTarget};

/// Rays per pixel (squared) of the judging renders: the gain is a difference of two
/// renders with the same sampling, so fewer rays than [`crate::eval::EVAL_PIXEL_GRID`]
/// do.
pub const JUDGE_PIXEL_GRID: u32 = 2;

/// One view-part candidate as judged.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ViewCandidate {
    /// `sh1`, `sh2` or the number of learned lobes.
    pub choice: ViewChoice,
    /// Lobes `J`.
    pub lobes: usize,
    /// View basis rank `K_v`.
    pub rank: usize,
    /// The lobe exponent λ of a `reflect` candidate.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub exponent: Option<f32>,
    /// Mean PSNR at the judging views, dB (`None` without judging views).
    pub psnr_db: Option<f64>,
    /// Gain over the view-independent asset, dB.
    pub gain_db: Option<f64>,
    /// Bytes of the asset with this view part: the view-independent asset's exact bytes
    /// plus the view part's, estimated at a fast zstd level ([`crate::eval::ExtraBytes`]).
    pub bytes: u64,
}

/// What the view-dependence stage decided.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ViewReport {
    /// `--view-dependence`.
    pub requested: ViewChoice,
    /// What the asset holds (`off` when no view part was kept).
    pub chosen: ViewChoice,
    /// Index of the kept candidate in [`Self::candidates`].
    pub chosen_index: Option<usize>,
    /// Relative RMS of the residual `T(ω) − T̄` over the directions each voxel is seen
    /// from, on the basis subsample; `None` when nothing was fitted (`auto` with no
    /// views to judge at: whatever it fitted would be dropped).
    pub residual_ratio: Option<f64>,
    /// Mean PSNR of the view-independent asset at the judging views, dB (with the
    /// probe's rays per pixel where only the probe ran).
    pub base_psnr_db: Option<f64>,
    /// Bytes of the view-independent asset.
    pub base_bytes: u64,
    /// Every candidate tried.
    pub candidates: Vec<ViewCandidate>,
    /// Where the judging views came from.
    pub judged_at: String,
    /// `auto`'s probe on a subsample of the band, where it ran ([`ViewProbe`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub probe: Option<ViewProbe>,
    /// Seconds spent (sampling, fitting, judging).
    pub secs: f64,
}

/// How much the probe's extrapolated gain oversells the band's fit, typically: the
/// band is fitted only where the best extrapolated gain, divided by this, reaches
/// `--view-min-gain-db`. Measured on seven fields, band gain / extrapolated gain
/// 0.28–0.95, most 0.5–0.6 (`docs/measurements/settings.md`); 2 is the middle, so the band is fitted
/// where it is expected to pay. Near the threshold either mistake is cheap in quality
/// (a part gaining about `--view-min-gain-db` kept or dropped); a band that falls short
/// skips minutes of sampling on a 600k-voxel scan.
pub const PROBE_OVERSELL: f64 = 2.0;

impl ViewReport {
    /// The largest gain of the judged candidates, dB (−∞ when none was judged).
    pub fn best_gain_db(&self) -> f64 {
        self.candidates
            .iter()
            .filter_map(|c| c.gain_db)
            .fold(f64::NEG_INFINITY, f64::max)
    }
}

/// `auto`'s probe: the candidates fitted on [`PROBE_SAMPLE`] band voxels only, basis
/// included (the rest of the band without a view part), and judged, their gains extrapolated to the whole band
/// ([`extrapolated_gain_db`]), judged with [`PROBE_PIXEL_GRID`]² rays per pixel. Where
/// no extrapolated gain reaches `--view-min-gain-db × PROBE_OVERSELL` the band is not
/// fitted and the asset stays view-independent.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ViewProbe {
    /// Band voxels the probe fitted.
    pub voxels: usize,
    /// Band voxels.
    pub band_voxels: usize,
    /// The candidates as judged with the probe's view part.
    pub candidates: Vec<ViewCandidate>,
    /// The largest extrapolated gain, dB.
    pub best_extrapolated_gain_db: f64,
    /// Whether the band was then fitted.
    pub band_fitted: bool,
    /// The kinds the band was fitted for ([`kinds_worth_fitting`]; `sh2` stands for
    /// `sh1` too): empty when it was not fitted.
    #[serde(default)]
    pub fitted_kinds: Vec<ViewChoice>,
    /// Seconds the probe took (sampling, fitting, judging).
    #[serde(default)]
    pub secs: f64,
}

/// The gain a view part fitted on every band voxel could reach, estimated from the
/// gain `probe_gain_db` of one fitted on a fraction `fraction` of them, over a
/// view-independent asset of PSNR `base_psnr_db`: the squared error the probe removed,
/// scaled by `1/fraction`. An estimate, not a bound: with [`PROBE_SAMPLE`] strided
/// voxels it oversells the band's fit 1.05–3.6× (an isolated voxel's correction is
/// fitted to its own residual alone, while the band's neighbours share theirs through
/// interpolation; the measurements are in `docs/measurements/settings.md`): hence
/// [`PROBE_OVERSELL`]. Capped at 30 dB (99.9 % of the error removed).
pub fn extrapolated_gain_db(base_psnr_db: f64, probe_gain_db: f64, fraction: f64) -> f64 {
    let mse = |psnr: f64| 10f64.powf(-psnr / 10.0);
    let base = mse(base_psnr_db);
    // At most 99.9 % of the error (30 dB), so that the figure stays finite in JSON.
    let removed = ((base - mse(base_psnr_db + probe_gain_db)) / fraction.clamp(1e-9, 1.0)).min(0.999 * base);
    10.0 * (base / (base - removed)).log10()
}

/// Rays per pixel (squared) of the probe's judging renders: a quarter of
/// [`JUDGE_PIXEL_GRID`]'s cost; its gains are differences of renders with the same rays.
pub const PROBE_PIXEL_GRID: u32 = 1;

/// View-basis rank of an explicit `--view-dependence` without `--view-rank`, and the
/// middle rank `auto` tries (it tries half and the largest too).
pub const DEFAULT_VIEW_RANK: usize = 8;

/// `auto` takes the smallest candidate whose gain is within this of the best (dB).
pub const AUTO_GAIN_SLACK_DB: f64 = 0.1;

/// Settings of [`choose_view`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ViewSettings {
    /// `--view-dependence`.
    pub choice: ViewChoice,
    /// `--view-min-gain-db`.
    pub min_gain_db: f64,
    /// `--view-rank`.
    pub rank: Option<usize>,
    /// `--max-view-rank`.
    pub max_rank: usize,
    /// March step of the judging renders, voxels.
    pub step_voxels: f32,
}

/// One judged candidate and the part it would attach (a view part or a reflection part).
type JudgedPart = (ViewCandidate, (Option<ViewDependence>, Option<Reflection>));

/// What [`judge_candidates`] builds and how it renders them.
struct JudgeList<'a> {
    /// View parts: kind and view rank.
    choices: &'a [(ViewChoice, usize)],
    /// Reflection parts (with a reflection target): indices into [`REFLECT_EXPONENTS`].
    exponents: &'a [usize],
    /// Rays per pixel along each axis.
    pixel_grid: u32,
}

/// Builds and judges the view part of each of `list.choices` and, with `reflect`, the
/// reflection part of each of `list.exponents`, from `fit` (whose [`ViewFit::entries`] index
/// `lt_voxels`) on top of `asset`, the view-independent asset, judged in the same march
/// ([`crate::eval::held_aside_psnrs`]): its PSNR (`None` without judging views) and the
/// candidates.
#[allow(clippy::too_many_arguments)] // the asset, the fit and its band, what to judge and where
fn judge_candidates(
    asset: &nelf_format::Asset,
    fit: &ViewFit,
    lt_voxels: &[usize],
    list: &JudgeList,
    reflect: Option<&ReflectionTarget>,
    views: &crate::eval::HeldAside,
    bytes: &crate::eval::ExtraBytes,
    step_voxels: f32,
) -> Result<(Option<f64>, Vec<JudgedPart>)> {
    let encoding = asset.coefficients.encoding();
    let voxels = asset.voxel_count();
    let mut built: Vec<(ViewCandidate, nelf_format::Asset)> = Vec::new();
    for &(choice, rank) in list.choices {
        let lobes = fit.lobes(choice);
        let part = if fit.skipped {
            // A field without view dependence asked for one explicitly: an all-zero part.
            ViewDependence {
                lobes: lobes.iter().map(|&x| x as f32).collect(),
                basis: fit.basis[..LT_DIM].to_vec(),
                coefficients: Coefficients::quantize(
                    &vec![0.0; voxels * lobes.len() / VIEW_HARMONICS],
                    lobes.len() / VIEW_HARMONICS,
                    encoding,
                )?,
            }
        } else {
            fit.view_part(&lobes, rank, voxels, lt_voxels, encoding)?
        };
        let mut with = asset.clone();
        with.view = Some(part);
        let candidate = ViewCandidate {
            choice,
            lobes: with.view.as_ref().map_or(0, ViewDependence::lobe_count),
            rank: with.view.as_ref().map_or(0, ViewDependence::rank),
            exponent: None,
            psnr_db: None,
            gain_db: None,
            bytes: bytes.of(&with)?,
        };
        built.push((candidate, with));
    }
    // The reflection part, one candidate per exponent.
    if let Some(target) = reflect {
        let eyes_m: Vec<[f32; 3]> = target.eyes.iter().map(Vec3::to_array).collect();
        for &k in list.exponents {
            let mut normals = vec![[0.0f32, 0.0, 1.0]; voxels];
            let mut scales = vec![0.0f32; voxels];
            for ((n, s), &e) in fit.reflection.iter().zip(&fit.entries) {
                if let Some(&v) = lt_voxels.get(e) {
                    normals[v] = *n;
                    scales[v] = s[k];
                }
            }
            let part = Reflection::new(REFLECT_EXPONENTS[k], eyes_m.clone(), &normals, &scales)?;
            let mut with = asset.clone();
            with.view = None;
            with.reflection = Some(part);
            let candidate = ViewCandidate {
                choice: ViewChoice::Reflect,
                lobes: 1,
                rank: 0,
                exponent: Some(REFLECT_EXPONENTS[k]),
                psnr_db: None,
                gain_db: None,
                bytes: bytes.of(&with)?,
            };
            built.push((candidate, with));
        }
    }
    let mut base_psnr_db = None;
    if !views.is_empty() {
        let variants: Vec<&nelf_format::Asset> = std::iter::once(asset)
            .chain(built.iter().map(|(_, a)| a))
            .collect();
        let psnrs = crate::eval::held_aside_psnrs(&variants, views, step_voxels, list.pixel_grid)?;
        base_psnr_db = psnrs.first().copied();
        for ((candidate, _), &psnr) in built.iter_mut().zip(psnrs.iter().skip(1)) {
            candidate.psnr_db = Some(psnr);
            candidate.gain_db = base_psnr_db.map(|b| psnr - b);
        }
    }
    let parts = built
        .into_iter()
        .map(|(candidate, with)| (candidate, (with.view, with.reflection)))
        .collect();
    Ok((base_psnr_db, parts))
}

/// A kind of view part is fitted on the band only when its extrapolated gain is at least
/// this share of the best kind's: the band's candidates are then compared by gain, and
/// `auto` keeps the smallest within [`AUTO_GAIN_SLACK_DB`] of the best, which a kind
/// probed at half the best's gain does not reach. Measured in
/// `docs/measurements/settings.md` (on the CGAL head the probe extrapolates 3.85 dB for
/// the reflection part against 0.60 for 16 learned lobes; the band then gains 2.51
/// against 0.57).
pub const PROBE_KIND_SHARE: f64 = 0.5;

/// The kind a candidate stands for in the probe: `sh1` is judged as `sh2`, every learned
/// rank as the largest.
fn probe_kind(choice: ViewChoice) -> ViewChoice {
    match choice {
        ViewChoice::Sh1 => ViewChoice::Sh2,
        ViewChoice::Learned(_) => ViewChoice::Learned(3),
        c => c,
    }
}

/// The kinds (as [`probe_kind`] names them) worth fitting on the whole band, from the
/// probe's extrapolated gains: those whose gain divided by [`PROBE_OVERSELL`] reaches
/// `min_gain_db` and that reach [`PROBE_KIND_SHARE`] of the best kind's gain.
pub fn kinds_worth_fitting(extrapolated: &[(ViewChoice, f64)], min_gain_db: f64) -> Vec<ViewChoice> {
    let best = extrapolated
        .iter()
        .map(|&(_, g)| g)
        .fold(f64::NEG_INFINITY, f64::max);
    let mut kinds: Vec<ViewChoice> = Vec::new();
    for &(choice, gain) in extrapolated {
        let kind = probe_kind(choice);
        if gain / PROBE_OVERSELL >= min_gain_db && gain >= PROBE_KIND_SHARE * best && !kinds.contains(&kind) {
            kinds.push(kind);
        }
    }
    kinds
}

/// The candidates `auto`'s probe judges: the largest of each kind (its gain bounds the
/// smaller ones'), so that the probe renders three candidates, not eight.
fn probe_choices(choices: &[(ViewChoice, usize)]) -> Vec<(ViewChoice, usize)> {
    let mut out: Vec<(ViewChoice, usize)> = Vec::new();
    for &(choice, rank) in choices {
        match out.iter_mut().find(|(c, _)| probe_kind(*c) == probe_kind(choice)) {
            Some(kept) => {
                if (choice == ViewChoice::Sh2 && kept.0 == ViewChoice::Sh1)
                    || (choice == kept.0 && rank > kept.1)
                {
                    *kept = (choice, rank);
                }
            }
            None => out.push((choice, rank)),
        }
    }
    out
}

/// Fits, judges and attaches the view part to `asset` (the bake's view-independent
/// asset) per `settings`; `judge` are the judging views (empty: none, then `auto` keeps
/// nothing and an explicit choice is kept unjudged).
///
/// `auto` first probes ([`ViewProbe`]): the candidates fitted on [`PROBE_SAMPLE`] band
/// voxels alone and judged. Only where one of them, extrapolated to the whole band, could
/// gain `--view-min-gain-db` is the band fitted (most of the stage's cost: every band
/// voxel's transport toward [`VIEW_DIRECTIONS`] directions).
#[allow(clippy::too_many_arguments)]
pub fn choose_view(
    asset: &mut nelf_format::Asset,
    field: &dyn FieldSource,
    grid: &BrickGrid,
    density: &[f32],
    lt_voxels: &[usize],
    lt: &[f32],
    weights: &[f64],
    eyes: &[DVec3],
    reflect: Option<&ReflectionTarget>,
    settings: &ViewSettings,
    judge: (&crate::eval::HeldAside, &str),
    progress: &Progress,
) -> Result<ViewReport> {
    let start = std::time::Instant::now();
    let (views, judged_at) = judge;
    if settings.choice == ViewChoice::Reflect && reflect.is_none() {
        return Err(BakeError::Settings(
            "--view-dependence reflect needs the view policy that averages toward the cameras (--view-policy average-cameras)".into(),
        ));
    }
    let reflect = match settings.choice {
        ViewChoice::Reflect | ViewChoice::Auto => reflect,
        _ => None,
    };
    let explicit = !matches!(settings.choice, ViewChoice::Auto | ViewChoice::Off);
    // `auto` with judging views probes first where the band is larger than the sample.
    let probing = settings.choice == ViewChoice::Auto && !views.is_empty() && lt_voxels.len() > PROBE_SAMPLE;
    let fit_in = |scope: FitScope, reflect: Option<&ReflectionTarget>, harmonic: bool| {
        fit_view(
            field,
            grid,
            density,
            lt_voxels,
            lt,
            weights,
            eyes,
            settings.max_rank,
            reflect,
            harmonic,
            scope,
            progress,
        )
    };
    let bytes = crate::eval::ExtraBytes::new(asset)?;
    let base_bytes = bytes.base_bytes;
    if settings.choice == ViewChoice::Off || (!explicit && views.is_empty()) {
        // `auto` keeps a candidate only when it gains at judging views: with none
        // (a photographed capture: no held-aside targets, no named lighting to compare
        // its own views under), fitting would cost the stage's time for nothing.
        return Ok(ViewReport {
            requested: settings.choice,
            chosen: ViewChoice::Off,
            chosen_index: None,
            residual_ratio: None,
            base_psnr_db: None,
            base_bytes,
            candidates: Vec::new(),
            judged_at: judged_at.to_string(),
            probe: None,
            secs: start.elapsed().as_secs_f64(),
        });
    }
    let mut fit = fit_in(
        if probing { FitScope::Sample } else { FitScope::Band },
        reflect,
        // An explicit `reflect` judges no harmonic part.
        settings.choice != ViewChoice::Reflect,
    )?;
    let mut report = ViewReport {
        requested: settings.choice,
        chosen: ViewChoice::Off,
        chosen_index: None,
        residual_ratio: Some(fit.residual_ratio),
        base_psnr_db: None,
        base_bytes,
        candidates: Vec::new(),
        judged_at: judged_at.to_string(),
        probe: None,
        secs: 0.0,
    };
    if settings.choice == ViewChoice::Off || (!explicit && (fit.skipped || views.is_empty())) {
        report.secs = start.elapsed().as_secs_f64();
        return Ok(report);
    }
    let max_rank = fit.max_rank();
    let default_rank = DEFAULT_VIEW_RANK.min(max_rank);
    let mut choices: Vec<(ViewChoice, usize)> = if settings.choice == ViewChoice::Reflect {
        Vec::new()
    } else if explicit {
        vec![(
            settings.choice,
            settings.rank.unwrap_or(default_rank).min(max_rank),
        )]
    } else if let Some(rank) = settings.rank {
        [ViewChoice::Sh1, ViewChoice::Learned(3), ViewChoice::Sh2]
            .into_iter()
            .map(|c| (c, rank.min(max_rank)))
            .collect()
    } else {
        let mut list = vec![
            (ViewChoice::Learned(3), (default_rank / 2).max(1)),
            (ViewChoice::Learned(3), default_rank),
            (ViewChoice::Learned(3), max_rank),
            (ViewChoice::Sh1, default_rank),
            (ViewChoice::Sh2, default_rank),
        ];
        list.dedup();
        list
    };
    let judge_fit = |fit: &ViewFit, list: &JudgeList| {
        judge_candidates(
            asset,
            fit,
            lt_voxels,
            list,
            reflect.filter(|_| !list.exponents.is_empty()),
            views,
            &bytes,
            settings.step_voxels,
        )
    };
    // The middle exponent alone where nothing can choose between them (no judging
    // views) and in the probe (the exponents gain within 20 % of each other).
    let middle_exponent = [REFLECT_EXPONENTS.len() / 2];
    let every_exponent: Vec<usize> = (0..REFLECT_EXPONENTS.len()).collect();
    if probing {
        let (probe_base, probed) = judge_fit(
            &fit,
            &JudgeList {
                choices: &probe_choices(&choices),
                exponents: &middle_exponent,
                pixel_grid: PROBE_PIXEL_GRID,
            },
        )?;
        let fraction = fit.entries.len() as f64 / lt_voxels.len() as f64;
        let extrapolated: Vec<(ViewChoice, f64)> = probed
            .iter()
            .filter_map(|(c, _)| {
                let (gain, base) = c.gain_db.zip(probe_base)?;
                Some((c.choice, extrapolated_gain_db(base, gain, fraction)))
            })
            .collect();
        let best = extrapolated
            .iter()
            .map(|&(_, g)| g)
            .fold(f64::NEG_INFINITY, f64::max);
        let fitted_kinds = kinds_worth_fitting(&extrapolated, settings.min_gain_db);
        let band_fitted = !fitted_kinds.is_empty();
        report.base_psnr_db = probe_base;
        report.probe = Some(ViewProbe {
            voxels: fit.entries.len(),
            band_voxels: lt_voxels.len(),
            candidates: probed.into_iter().map(|(c, _)| c).collect(),
            best_extrapolated_gain_db: best,
            band_fitted,
            fitted_kinds: fitted_kinds.clone(),
            secs: start.elapsed().as_secs_f64(),
        });
        if !band_fitted {
            report.secs = start.elapsed().as_secs_f64();
            return Ok(report);
        }
        choices.retain(|&(c, _)| fitted_kinds.contains(&probe_kind(c)));
        let reflect = reflect.filter(|_| fitted_kinds.contains(&ViewChoice::Reflect));
        fit = fit_in(FitScope::Band, reflect, !choices.is_empty())?;
    }
    let reflection_fitted = !fit.reflection.is_empty() || fit.skipped;
    let (base_psnr_db, judged) = judge_fit(
        &fit,
        &JudgeList {
            choices: &choices,
            exponents: if !reflection_fitted {
                &[]
            } else if views.is_empty() {
                &middle_exponent
            } else {
                &every_exponent
            },
            pixel_grid: JUDGE_PIXEL_GRID,
        },
    )?;
    report.base_psnr_db = base_psnr_db;
    let (candidates, mut parts): (Vec<ViewCandidate>, Vec<_>) = judged.into_iter().unzip();
    report.candidates = candidates;
    let best_psnr = |list: &[ViewCandidate]| {
        (0..list.len()).max_by(|&a, &b| {
            let psnr = |i: usize| list[i].psnr_db.unwrap_or(f64::NEG_INFINITY);
            psnr(a).total_cmp(&psnr(b))
        })
    };
    let pick = if settings.choice == ViewChoice::Reflect {
        best_psnr(&report.candidates)
    } else if explicit {
        Some(0)
    } else {
        // The best gain; a candidate within AUTO_GAIN_SLACK_DB of it with fewer bytes wins.
        let best = report.best_gain_db();
        if best > settings.min_gain_db {
            report
                .candidates
                .iter()
                .enumerate()
                .filter(|(_, c)| c.gain_db.is_some_and(|g| g >= best - AUTO_GAIN_SLACK_DB))
                .min_by_key(|(_, c)| c.bytes)
                .map(|(i, _)| i)
        } else {
            None
        }
    };
    if let Some(i) = pick {
        report.chosen = report.candidates[i].choice;
        report.chosen_index = Some(i);
        (asset.view, asset.reflection) = parts.swap_remove(i);
    }
    report.secs = start.elapsed().as_secs_f64();
    Ok(report)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_probe_judges_the_largest_candidate_of_each_kind() {
        let auto = [
            (ViewChoice::Learned(3), 4),
            (ViewChoice::Learned(3), 8),
            (ViewChoice::Learned(3), 16),
            (ViewChoice::Sh1, 8),
            (ViewChoice::Sh2, 8),
        ];
        assert_eq!(
            probe_choices(&auto),
            vec![(ViewChoice::Learned(3), 16), (ViewChoice::Sh2, 8)]
        );
        // With `--view-rank`: one of each, sh1 folded into sh2.
        let ranked = [
            (ViewChoice::Sh1, 4),
            (ViewChoice::Learned(3), 4),
            (ViewChoice::Sh2, 4),
        ];
        assert_eq!(
            probe_choices(&ranked),
            vec![(ViewChoice::Sh2, 4), (ViewChoice::Learned(3), 4)]
        );
    }

    #[test]
    fn the_band_is_fitted_only_for_kinds_that_can_pay_and_come_near_the_best() {
        let learned = ViewChoice::Learned(3);
        // The CGAL head's probe: the reflection part far ahead, the harmonic kinds not
        // fitted although 16 learned lobes would pass the threshold on their own.
        let cgal = [
            (ViewChoice::Learned(16), 0.60),
            (ViewChoice::Sh2, 0.56),
            (ViewChoice::Reflect, 3.85),
        ];
        assert_eq!(kinds_worth_fitting(&cgal, 0.25), vec![ViewChoice::Reflect]);
        // Two kinds close together: both, in the probe's order, learned ranks as one.
        let close = [(learned, 1.2), (ViewChoice::Sh2, 0.7), (ViewChoice::Reflect, 1.0)];
        assert_eq!(
            kinds_worth_fitting(&close, 0.25),
            vec![learned, ViewChoice::Sh2, ViewChoice::Reflect]
        );
        // Nothing reaches --view-min-gain-db × PROBE_OVERSELL: the band is not fitted.
        let small = [(learned, 0.45), (ViewChoice::Reflect, 0.49)];
        assert!(kinds_worth_fitting(&small, 0.25).is_empty());
        // sh1 is judged as sh2.
        assert_eq!(probe_kind(ViewChoice::Sh1), ViewChoice::Sh2);
        assert_eq!(probe_kind(ViewChoice::Learned(9)), learned);
    }

    #[test]
    fn the_extrapolated_gain_scales_the_removed_error() {
        // The whole band probed: the gain itself.
        assert!((extrapolated_gain_db(30.0, 0.4, 1.0) - 0.4).abs() < 1e-12);
        // No gain, or a loss, stays so.
        assert!(extrapolated_gain_db(30.0, 0.0, 0.05).abs() < 1e-12);
        assert!(extrapolated_gain_db(30.0, -0.01, 0.05) < 0.0);
        // A tenth of the band removing 1 % of the error: the band removes 10 %.
        let base = 10f64.powf(-3.0);
        let probe = 10.0 * (base / (0.99 * base)).log10();
        let full = extrapolated_gain_db(30.0, probe, 0.1);
        assert!((full - 10.0 * (1.0 / 0.9f64).log10()).abs() < 1e-9, "{full}");
        // All the error or more: capped at 30 dB, finite, so the band is fitted.
        let capped = extrapolated_gain_db(30.0, probe, 0.005);
        assert!((capped - 30.0).abs() < 1e-9, "{capped}");
        // Monotonic in the probe's gain.
        assert!(extrapolated_gain_db(25.0, 0.02, 0.04) < extrapolated_gain_db(25.0, 0.03, 0.04));
    }
}
