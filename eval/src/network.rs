//! `nelf eval network CAPTURE…`: the network (the shipped one, or `--weights`) against
//! the ground truth on captures it was never trained on, at each capture's
//! held-aside target views: the network rendered directly, its bake, and the
//! ground-truth bake of the same capture, in 8-bit sRGB (whole image, inside the
//! true mask, SSIM) beside the flat-colour baseline of the same views
//! (`nelf_scene::metrics::srgb8_scores`). Every capture must carry its ground truth
//! (a synthetic capture's `synth_config.json`, e.g. the held-out heads of a
//! `nelf train data` folder). `network.json` in `--out` records every score.
//! `--split` swaps parts of the network's field for the ground truth's
//! (`nelf_pipeline::{DensityAndTransport, TransportShapeFrom, TrueNormalsLambert}`)
//! to tell where its error lies (field/README.md, "Where the network's error lies").

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use glam::DMat3;
use nelf_bake::eval::load_held_aside;
use nelf_bake::{
    BakeConfig, CaptureLoadOptions, GroundTruth, Progress, ViewChoice, bake_capture, load_capture,
};
use nelf_field::render::{ImageSettings, Sampling, render_image};
use nelf_format::io_error::IoResultExt;
use nelf_format::read_asset;
use nelf_pipeline::error::{Context as _, PipelineError, Result};
use nelf_pipeline::photo::{bake_photographs, write_reconstruction};
use nelf_pipeline::{
    FromTruth, NetworkSampling, PipelineConfig, SourceFit, bake_network_field, load_network, network_field,
    network_provenance, write_bake,
};
use nelf_render::{MarchSettings, render_asset};
use nelf_scene::metrics::{Srgb8Scores, srgb8_scores};
use serde::Serialize;

/// Options of `nelf eval network`.
#[derive(Debug, clap::Args)]
#[allow(clippy::struct_excessive_bools, reason = "independent command-line switches")]
pub struct NetworkEvalConfig {
    /// Capture folders with their ground truth and held-aside targets.
    #[arg(required = true)]
    pub captures: Vec<PathBuf>,
    /// The network's weights (default: the shipped network, built in).
    #[arg(long)]
    pub weights: Option<PathBuf>,
    /// Bake resolution (voxels along the longest side of the occupied box).
    #[arg(long, default_value_t = 64)]
    pub resolution: u32,
    /// Force the PCA rank of both bakes (default: chosen per scene).
    #[arg(long)]
    pub rank: Option<usize>,
    /// Sub-points per voxel edge in the network's bake (box filter; 1 = point samples).
    #[arg(long, default_value_t = nelf_pipeline::NETWORK_VOXEL_FILTER)]
    pub voxel_filter: usize,
    /// The network's bake: its density as a signed function of `ln σ` for a skin this
    /// thick, mm (`nelf bake --network-skin-mm`; 0: σ itself).
    #[arg(long, default_value_t = nelf_pipeline::DEFAULT_NETWORK_SKIN_MM)]
    pub network_skin_mm: f32,
    /// Leave the network uncalibrated (`nelf bake --no-source-calibration`): the
    /// network's own light transport, without the gain that makes it reproduce the
    /// capture's views under their lighting.
    #[arg(long)]
    pub no_source_calibration: bool,
    /// Normalise the network to the capture's source lighting point by point and mix
    /// in the Lambertian shading prior, normals over this many mm
    /// (`nelf bake --shading-prior-mm`; 0: the one gain).
    #[arg(long, default_value_t = nelf_field::prior::DEFAULT_STEP_MM)]
    pub shading_prior_mm: f32,
    /// The prior's weight (`nelf bake --shading-prior-weight`).
    #[arg(long, default_value_t = nelf_field::prior::DEFAULT_WEIGHT)]
    pub shading_prior_weight: f32,
    /// The network's bake: leave its density uncarved by the visual hull
    /// (`nelf bake --no-network-hull-carve`).
    #[arg(long)]
    pub no_network_hull_carve: bool,
    /// The network's bake: pixels the masks are grown by before the carve
    /// (`nelf bake --network-hull-margin-px`).
    #[arg(long, default_value_t = nelf_pipeline::DEFAULT_NETWORK_HULL_MARGIN_PX)]
    pub network_hull_margin_px: f32,
    /// Also bake the network once per target with its light transport toward that
    /// target's camera (`oracle_view_bake` in the scores): what a bake without a
    /// view-dependent part could reach at best, to tell view dependence from other
    /// losses.
    #[arg(long)]
    pub oracle_view: bool,
    /// Also bake each capture with parts of the network's field taken from the
    /// ground truth, to tell its geometry error from its colour and shading errors
    /// (all of them without a value, or a comma-separated list): `density` (the truth's
    /// density, the network's light transport), `transport` (the network's density,
    /// the truth's transport), `shading` (the network's colour under the source
    /// lighting relit by the truth's transport), `colour` (the truth's colour relit by
    /// the network's transport), `normals` (the network's colour relit by a clamped
    /// cosine about the truth's normals), `shadows` (the network's colour relit by the
    /// truth's direct Lambertian transport, with its shadows). Scores
    /// `truth_<part>_bake`.
    #[arg(long, value_enum, value_delimiter = ',', num_args = 0..)]
    pub split: Option<Vec<FromTruth>>,
    /// Also bake each capture from its photographs alone (`nelf bake capture --source
    /// photos`: the masks' visual hull, its reflectance from the photographs, baked as
    /// a mesh; `nelf_pipeline::photo`), scored as `photos_bake`.
    #[arg(long)]
    pub photos: bool,
    /// With `--photos`: reconstruct as if the capture named no lighting (as real
    /// photographs: it is fitted to their shading, `nelf bake --photo-lighting`). The exposure of such an asset is then
    /// unknowable, so its renders are scored after one gain for all of a capture's
    /// targets (least squares in linear light inside the true masks), reported beside it.
    #[arg(long)]
    pub unnamed_lighting: bool,
    /// Score the bakes alone, without rendering the network directly (its renders take
    /// most of an evaluation's time at 128²; `network` is then null in the scores).
    #[arg(long)]
    pub bakes_only: bool,
    /// Output folder: the bakes and `network.json`.
    #[arg(short, long, default_value = "out/eval-network")]
    pub out: PathBuf,
}

/// The scores of one target view.
#[derive(Debug, Clone, Serialize)]
pub struct TargetScores {
    /// The capture folder.
    pub capture: PathBuf,
    /// The target's name.
    pub target: String,
    /// The network rendered directly; `None` with `--bakes-only`.
    pub network: Option<Srgb8Scores>,
    /// The network's bake.
    pub network_bake: Srgb8Scores,
    /// The ground truth's bake.
    pub truth_bake: Srgb8Scores,
    /// The network baked toward this target's camera (`--oracle-view`).
    pub oracle_view_bake: Option<Srgb8Scores>,
    /// The photographs' reconstruction baked (`--photos`).
    pub photos_bake: Option<Srgb8Scores>,
    /// The one gain its renders were scaled by (1 unless `--unnamed-lighting`).
    pub photos_gain: Option<f64>,
    /// `--split`: the scores of each part swapped for the ground truth's, by name.
    #[serde(skip_serializing_if = "BTreeMap::is_empty")]
    pub split: BTreeMap<&'static str, Srgb8Scores>,
}

impl NetworkEvalConfig {
    /// The bake settings both bakes of a capture take.
    fn bake_config(&self) -> PipelineConfig {
        PipelineConfig {
            bake: BakeConfig {
                resolution: self.resolution,
                rank: self.rank,
                view_dependence: ViewChoice::Off,
                ..BakeConfig::default()
            },
            network_skin_mm: self.network_skin_mm,
            no_source_calibration: self.no_source_calibration,
            shading_prior_mm: self.shading_prior_mm,
            shading_prior_weight: self.shading_prior_weight,
            no_network_hull_carve: self.no_network_hull_carve,
            network_hull_margin_px: self.network_hull_margin_px,
        }
    }

    /// The parts `--split` asks for (all of them when it names none).
    fn split_parts(&self) -> Vec<FromTruth> {
        match &self.split {
            None => Vec::new(),
            Some(parts) if parts.is_empty() => FromTruth::ALL.to_vec(),
            Some(parts) => parts.clone(),
        }
    }
}

/// Runs `nelf eval network`: every capture's bakes scored at its targets, one line
/// per target and a summary handed to `print` as they come, every score in
/// `network.json` in `config.out`; returns what `network.json` holds.
pub fn run_network(config: &NetworkEvalConfig, print: &mut dyn FnMut(&str)) -> Result<serde_json::Value> {
    let out = &config.out;
    std::fs::create_dir_all(out).with_path(out)?;
    let (model, weights_name) = load_network(config.weights.as_deref())?;
    let bake_config = config.bake_config();
    let split_parts = config.split_parts();
    let mut rows = Vec::new();
    for (index, dir) in config.captures.iter().enumerate() {
        let capture = Capture {
            index,
            dir,
            model: &model,
            weights_name: &weights_name,
            bake_config: &bake_config,
            split_parts: &split_parts,
        };
        for row in capture.evaluate(config)? {
            print(&describe_row(&row));
            rows.push(row);
        }
    }
    let summary = summarise(config, &weights_name, &split_parts, &rows);
    let mean_of = |kind: &str| summary["mean_foreground_psnr"][kind].as_f64();
    print(&format!(
        "mean over {} targets, foreground PSNR (8-bit sRGB): network {}, its bake {:.2}, ground-truth bake {:.2}, flat colour {:.2} dB",
        rows.len(),
        mean_of("network").map_or("not rendered".to_string(), |v| format!("{v:.2}")),
        mean_of("network_bake").unwrap_or(f64::NAN),
        mean_of("truth_bake").unwrap_or(f64::NAN),
        mean_of("flat_colour").unwrap_or(f64::NAN),
    ));
    let flip_of = |kind: &str| summary["mean_foreground_flip"][kind].as_f64().unwrap_or(f64::NAN);
    print(&format!(
        "  foreground ꟻLIP (lower is better): its bake {:.3}, ground-truth bake {:.3}, flat colour {:.3}",
        flip_of("network_bake"),
        flip_of("truth_bake"),
        flip_of("flat_colour"),
    ));
    if let Some(photos) = mean_of("photos_bake") {
        print(&format!(
            "  the photographs' reconstruction baked{}: {photos:.2} dB foreground, {:.2} dB whole image, foreground ꟻLIP {:.3}",
            if config.unnamed_lighting {
                " (lighting not named; one exposure gain per capture)"
            } else {
                ""
            },
            summary["mean_psnr"]["photos_bake"].as_f64().unwrap_or(f64::NAN),
            flip_of("photos_bake")
        ));
    }
    let path = out.join("network.json");
    nelf_format::atomic::write_bytes_atomically(
        &path,
        (serde_json::to_string_pretty(&summary)? + "\n").as_bytes(),
    )
    .with_path(&path)?;
    if config.oracle_view {
        print(&format!(
            "  the network baked toward each target's own camera: {:.2} dB",
            summary["mean_foreground_psnr_oracle_view_bake"]
                .as_f64()
                .unwrap_or(f64::NAN)
        ));
    }
    if !split_parts.is_empty() {
        print("  foreground (whole image) PSNR of the bake with");
        for part in &split_parts {
            let (name, what) = part.describe();
            let value = |key: &str| summary["mean_split"][name][key].as_f64().unwrap_or(f64::NAN);
            print(&format!(
                "    {what}: {:.2} ({:.2}) dB",
                value("foreground_psnr"),
                value("psnr")
            ));
        }
    }
    print(&format!("scores     {}", path.display()));
    Ok(summary)
}

/// One capture of an evaluation, with what every capture shares.
struct Capture<'a> {
    index: usize,
    dir: &'a Path,
    model: &'a nelf_field::Model,
    weights_name: &'a str,
    bake_config: &'a PipelineConfig,
    split_parts: &'a [FromTruth],
}

impl Capture<'_> {
    /// The capture's bakes (the network's, its splits, the ground truth's) scored at
    /// each of its targets.
    fn evaluate(&self, config: &NetworkEvalConfig) -> Result<Vec<TargetScores>> {
        let (dir, index, bake_config) = (self.dir, self.index, self.bake_config);
        let progress = Progress::hidden();
        let capture = load_capture(dir, &CaptureLoadOptions::default())
            .with_context(|| format!("loading the capture {}", dir.display()))?;
        let description = capture
            .description()
            .with_context(|| format!("{}: no cameras.json with held-aside targets", dir.display()))?;
        let held =
            load_held_aside(description, dir).with_context(|| format!("{}: the targets", dir.display()))?;
        if held.is_empty() {
            return Err(PipelineError::Invalid(format!(
                "{}: no held-aside targets to score",
                dir.display()
            )));
        }
        let truth = GroundTruth::from_synth_capture(dir)
            .with_context(|| format!("{}: no ground truth (synth_config.json)", dir.display()))?;

        // The network, over the capture's views reduced to its working size.
        let (prepared, field) =
            network_field(&capture, self.model.clone(), SourceFit::of_config(bake_config))?;
        let provenance = network_provenance(&field, self.weights_name);
        // The network's bake with a view policy (`None`: its recommended one), written to
        // `name` and read back as a viewer would.
        let network_bake = |view_policy, from_truth, name: String| -> Result<nelf_format::Asset> {
            let mut output = bake_network_field(
                &capture,
                &field,
                &provenance,
                bake_config,
                progress,
                &NetworkSampling {
                    voxel_filter: config.voxel_filter,
                    view_policy,
                    from_truth,
                },
            )
            .with_context(|| format!("baking {} with the network", dir.display()))?;
            let path = config.out.join(name);
            write_bake(&mut output, bake_config, &path)?;
            Ok(read_asset(&path)?)
        };
        let network_asset = network_bake(None, None, format!("capture{index}_network.nelf"))?;
        let split_assets = self
            .split_parts
            .iter()
            .map(|part| {
                let (name, _) = part.describe();
                let asset = network_bake(None, Some((&truth, *part)), format!("capture{index}_{name}.nelf"))?;
                Ok((name, asset))
            })
            .collect::<Result<Vec<_>>>()?;
        let mut truth_bake = bake_capture(&capture, &truth, &bake_config.bake, &progress)
            .with_context(|| format!("baking {} from its ground truth", dir.display()))?;
        let truth_path = config.out.join(format!("capture{index}_truth.nelf"));
        write_bake(&mut truth_bake, bake_config, &truth_path)?;
        let truth_asset = read_asset(&truth_path)?;
        let photos_asset = if config.photos {
            let mut photographs = capture.clone();
            if config.unnamed_lighting
                && let nelf_bake::capture_in::CaptureSource::CamerasJson(description) =
                    &mut photographs.source
            {
                description.envmap = None;
            }
            let mut baked = bake_photographs(
                &photographs,
                config.weights.as_deref(),
                &nelf_pipeline::config::PhotoSettings::default(),
                bake_config,
                progress,
            )?;
            let path = config.out.join(format!("capture{index}_photos.nelf"));
            write_bake(&mut baked.output, bake_config, &path)?;
            write_reconstruction(&baked.reconstruction, &path.with_extension("reconstruction"))?;
            let asset = read_asset(&path)?;
            let renders = (0..held.len())
                .map(|t| {
                    render_asset(
                        &asset,
                        &held.cameras[t],
                        &held.envs[t],
                        DMat3::IDENTITY,
                        None,
                        &MarchSettings::default(),
                    )
                    .map(|image| image.rgb)
                })
                .collect::<std::result::Result<Vec<_>, _>>()?;
            let gain = if config.unnamed_lighting {
                nelf_scene::metrics::exposure_gain(&renders, &held.images, &held.masks)
            } else {
                1.0
            };
            Some((renders, gain))
        } else {
            None
        };

        let mut rows = Vec::new();
        for t in 0..held.len() {
            let camera = &held.cameras[t];
            let (w, h) = (camera.width, camera.height);
            let score = |image: &[[f32; 3]]| srgb8_scores(image, &held.images[t], &held.masks[t], w, h);
            let light = nelf_format::conventions::project_envmap(&held.envs[t], prepared.world_from_light())?;
            let direct = if config.bakes_only {
                None
            } else {
                Some(render_image(
                    field.model(),
                    field.encoded(),
                    &prepared.net_camera(camera),
                    &field.net_light(&light)?,
                    &ImageSettings {
                        head_centre: prepared.head_centre_net(),
                        sampling: Sampling::Stratified,
                        ..ImageSettings::default()
                    },
                    None,
                )?)
            };
            let settings = MarchSettings::default();
            let baked = |asset: &nelf_format::Asset| {
                render_asset(asset, camera, &held.envs[t], DMat3::IDENTITY, None, &settings)
            };
            let oracle_view_bake = if config.oracle_view {
                let policy = nelf_scene::field::ViewPolicy::TowardPoint(camera.centre().as_vec3());
                let asset = network_bake(
                    Some(policy),
                    None,
                    format!("capture{index}_network_{}.nelf", held.names[t]),
                )?;
                Some(score(&baked(&asset)?.rgb)?)
            } else {
                None
            };
            rows.push(TargetScores {
                capture: dir.to_path_buf(),
                target: held.names[t].clone(),
                network: direct.map(|d| score(&d.rgb)).transpose()?,
                network_bake: score(&baked(&network_asset)?.rgb)?,
                truth_bake: score(&baked(&truth_asset)?.rgb)?,
                oracle_view_bake,
                photos_bake: photos_asset
                    .as_ref()
                    .map(|(renders, gain)| {
                        let scaled: Vec<[f32; 3]> =
                            renders[t].iter().map(|p| p.map(|v| v * *gain as f32)).collect();
                        score(&scaled)
                    })
                    .transpose()?,
                photos_gain: photos_asset.as_ref().map(|(_, gain)| *gain),
                split: split_assets
                    .iter()
                    .map(|(name, asset)| Ok((*name, score(&baked(asset)?.rgb)?)))
                    .collect::<Result<_>>()?,
            });
        }
        Ok(rows)
    }
}

/// One target's scores, one line.
fn describe_row(row: &TargetScores) -> String {
    let network = |f: fn(&Srgb8Scores) -> String| row.network.as_ref().map_or("-".to_string(), f);
    let photos = row.photos_bake.as_ref().map_or(String::new(), |s| {
        format!(
            "; photographs' bake {:.2} ({:.2}, SSIM {:.3}, ꟻLIP {:.3}) dB",
            s.foreground_psnr, s.psnr, s.ssim, s.foreground_flip
        )
    });
    format!(
        "{} {}: foreground PSNR network {}, its bake {:.2}, ground-truth bake {:.2}, flat colour {:.2} dB \
         (whole image {}, {:.2}, {:.2}, {:.2}; SSIM {}, {:.3}, {:.3}, {:.3}; foreground ꟻLIP {}, {:.3}, {:.3}, {:.3}){photos}",
        row.capture.display(),
        row.target,
        network(|s| format!("{:.2}", s.foreground_psnr)),
        row.network_bake.foreground_psnr,
        row.truth_bake.foreground_psnr,
        row.network_bake.flat_foreground_psnr,
        network(|s| format!("{:.2}", s.psnr)),
        row.network_bake.psnr,
        row.truth_bake.psnr,
        row.network_bake.flat_psnr,
        network(|s| format!("{:.3}", s.ssim)),
        row.network_bake.ssim,
        row.truth_bake.ssim,
        row.network_bake.flat_ssim,
        network(|s| format!("{:.3}", s.foreground_flip)),
        row.network_bake.foreground_flip,
        row.truth_bake.foreground_flip,
        row.network_bake.flat_foreground_flip
    )
}

/// What `network.json` holds: the settings, the means over every target, the rows.
fn summarise(
    config: &NetworkEvalConfig,
    weights_name: &str,
    split_parts: &[FromTruth],
    rows: &[TargetScores],
) -> serde_json::Value {
    let mean = |f: &dyn Fn(&TargetScores) -> f64| rows.iter().map(f).sum::<f64>() / rows.len().max(1) as f64;
    // The network's own renders (null with --bakes-only).
    let mean_network = |key: fn(&Srgb8Scores) -> f64| {
        (!config.bakes_only).then(|| mean(&|r| r.network.as_ref().map_or(f64::NAN, key)))
    };
    // One score's means for every source, beside the flat colour's.
    let by_source = |value: fn(&Srgb8Scores) -> f64, flat: fn(&Srgb8Scores) -> f64| {
        serde_json::json!({
            "network": mean_network(value),
            "network_bake": mean(&|r| value(&r.network_bake)),
            "truth_bake": mean(&|r| value(&r.truth_bake)),
            "flat_colour": mean(&|r| flat(&r.network_bake)),
            "photos_bake": config.photos.then(|| mean(&|r| r.photos_bake.as_ref().map_or(f64::NAN, value))),
        })
    };
    serde_json::json!({
        "weights": weights_name,
        "resolution": config.resolution,
        "voxel_filter": config.voxel_filter,
        "network_skin_mm": config.network_skin_mm,
        "no_source_calibration": config.no_source_calibration,
        "shading_prior_mm": config.shading_prior_mm,
        "shading_prior_weight": config.shading_prior_weight,
        "network_hull_carve": !config.no_network_hull_carve,
        "network_hull_margin_px": config.network_hull_margin_px,
        "rank": config.rank,
        "bakes_only": config.bakes_only,
        "targets": rows.len(),
        "mean_foreground_psnr": by_source(|s| s.foreground_psnr, |s| s.flat_foreground_psnr),
        "photos_unnamed_lighting": config.photos.then_some(config.unnamed_lighting),
        "mean_foreground_psnr_oracle_view_bake": config.oracle_view.then(|| mean(&|r| r.oracle_view_bake.map_or(f64::NAN, |s| s.foreground_psnr))),
        "mean_split": (!split_parts.is_empty()).then(|| split_parts.iter().map(|part| {
            let (name, _) = part.describe();
            let of = |key: fn(&Srgb8Scores) -> f64| mean(&|r| r.split.get(name).map_or(f64::NAN, key));
            (name.to_string(), serde_json::json!({
                "foreground_psnr": of(|s| s.foreground_psnr),
                "psnr": of(|s| s.psnr),
            }))
        }).collect::<serde_json::Map<_, _>>()),
        "mean_psnr": by_source(|s| s.psnr, |s| s.flat_psnr),
        "mean_ssim": by_source(|s| s.ssim, |s| s.flat_ssim),
        "mean_flip": by_source(|s| s.flip, |s| s.flat_flip),
        "mean_foreground_flip": by_source(|s| s.foreground_flip, |s| s.flat_foreground_flip),
        "rows": rows,
    })
}
