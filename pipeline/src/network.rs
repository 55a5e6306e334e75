//! The NeLF network as a capture's field source: its weights loaded, the capture's
//! views encoded ([`network_field`]), its light transport put in the capture's light
//! units and fitted to the capture's own views ([`in_capture_light_units`],
//! [`SourceFit`]), and what a bake records of it ([`network_provenance`]).

use std::path::Path;

use nelf_bake::LoadedCapture;
use nelf_field::capture::default_net_from_world;
use nelf_field::prior::ShadingPrior;
use nelf_field::{Model, NelfField, NetCapture};
use nelf_format::capture::Capture;
use nelf_format::conventions::LatLong;
use nelf_scene::field::FieldSource as _;

use crate::config::PipelineConfig;
use crate::error::{Context as _, Result, invalid};

/// How a network field is fitted to the capture's source views when the capture
/// names the lighting they were taken in.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SourceFit {
    /// Left as the network gives it (in physical units when its lighting is known).
    None,
    /// Scaled by the one gain that makes it reproduce the views
    /// (`NelfField::calibrated_to_sources`).
    Gain,
    /// Normalised to the lighting point by point, with an optional Lambertian shading
    /// prior (`NelfField::normalised_to_sources`).
    Normalised(Option<ShadingPrior>),
}

impl SourceFit {
    /// The fit a configuration asks for: none with `--no-source-calibration`,
    /// normalised with a prior for `--shading-prior-mm` > 0, else the gain.
    pub fn of_config(config: &PipelineConfig) -> Self {
        if config.no_source_calibration {
            Self::None
        } else {
            ShadingPrior::from_step_mm(config.shading_prior_mm, config.shading_prior_weight)
                .map_or(Self::Gain, |prior| Self::Normalised(Some(prior)))
        }
    }
}

/// The network's weights (`weights`, else the shipped network) on the default
/// device, with the name a bake records.
pub fn load_network(weights: Option<&Path>) -> Result<(Model, String)> {
    let device = nelf_field::default_device();
    nelf_field::shipped::load_or_shipped(weights, nelf_field::NelfConfig::for_device(&device), &device)
        .context("loading the network's weights")
}

/// The network over `capture`'s views, reduced toward its working image size: the
/// prepared views and the field they encode to, in the capture's light units and
/// fitted to its source views by `fit`.
pub fn network_field(
    capture: &LoadedCapture,
    model: Model,
    fit: SourceFit,
) -> Result<(NetCapture, NelfField)> {
    let (prepared, field) = encoded_field(capture, model)?;
    let field = in_capture_light_units(field, capture.description(), &capture.dir, fit)?;
    Ok((prepared, field))
}

/// The network over `capture`'s prepared views, its light transport in the
/// network's own units: enough for its density (the photographs' geometry).
pub fn encoded_field(capture: &LoadedCapture, model: Model) -> Result<(NetCapture, NelfField)> {
    let prepared = NetCapture::for_model(
        &model,
        &capture.cameras,
        &capture.images,
        &capture.masks,
        capture.head_centre_m,
        default_net_from_world(),
    )?;
    let field = NelfField::new(model, &prepared).context("encoding the capture's views")?;
    Ok((prepared, field))
}

/// `field` in physical units when its network takes source-relative lightings and the
/// capture (`description`, in folder `dir`) names its lighting, then fitted to the
/// capture's views under that lighting by `fit`; otherwise as it is, saying so.
pub fn in_capture_light_units(
    field: NelfField,
    description: Option<&Capture>,
    dir: &Path,
    fit: SourceFit,
) -> Result<NelfField> {
    let Some(map) = capture_source_lighting(description, dir)? else {
        if field.model().source_relative_light() {
            eprintln!(
                "note: {} records no lighting of its views, so the network's light transport stays \
                 relative to it (relit under a map of mean radiance 1 it is as bright as the capture) \
                 and is not calibrated to the views",
                dir.display()
            );
        }
        return Ok(field);
    };
    let field = field.with_source_light_power(map.mean_radiance())?;
    let light = nelf_format::conventions::project_envmap(&map, field.world_from_light())?;
    // The prior's step and weight are chosen for bakes on their own
    // (`nelf_field::prior::DEFAULT_STEP_MM`, `DEFAULT_WEIGHT`); no prior at all departs
    // from what the weights were trained with.
    let without_prior = !matches!(fit, SourceFit::Normalised(Some(_)));
    if let Some(trained) = field.model().trained_shading_prior()
        && without_prior
    {
        eprintln!(
            "note: these weights were last trained through a shading prior of weight {} with normals over {} mm; \
             this fit uses none (the weights' accuracy figures hold with the default prior)",
            trained.weight, trained.step_mm,
        );
    }
    match fit {
        SourceFit::None => Ok(field),
        SourceFit::Gain => {
            let (field, fit) = field
                .calibrated_to_sources(&light)
                .with_context(|| format!("calibrating the network to the views of {}", dir.display()))?;
            eprintln!(
                "  calibrated the network to its {} source pixels under their lighting: light transport × {:.3} \
                 (sRGB RMS error {:.4} -> {:.4}; --no-source-calibration leaves it)",
                fit.pixels, fit.gain, fit.rmse_before, fit.rmse_after
            );
            Ok(field)
        }
        SourceFit::Normalised(prior) => {
            let field = field
                .normalised_to_sources(&light, prior)
                .with_context(|| format!("normalising the network to the lighting of {}", dir.display()))?;
            eprintln!(
                "  normalised the network's light transport to the lighting of its source views{}",
                prior.map_or(String::new(), |p| format!(
                    ", with a Lambertian shading prior (weight {}, normals over {} mm)",
                    p.weight, p.step_mm
                ))
            );
            Ok(field)
        }
    }
}

/// The lighting a capture's views were taken under, when its `cameras.json`
/// (`description`, in folder `dir`) names one (synthetic captures do), checked to
/// have a positive finite mean radiance (`Σ Ω L / 4π`).
pub fn capture_source_lighting(description: Option<&Capture>, dir: &Path) -> Result<Option<LatLong>> {
    let Some(path) = description.and_then(|d| d.envmap_path(dir)) else {
        return Ok(None);
    };
    let map = nelf_scene::envmap::load_envmap(&path)
        .with_context(|| format!("reading the capture's lighting {}", path.display()))?;
    let power = map.mean_radiance();
    if !(power.is_finite() && power > 0.0) {
        return Err(invalid(format!(
            "{}: the capture's lighting has mean radiance {power}",
            path.display()
        )));
    }
    Ok(Some(map))
}

/// What a network bake records of its field: the weights it came from and how its
/// light transport was put in the capture's units (gain, normalisation, shading prior).
pub fn network_provenance(field: &NelfField, weights_name: &str) -> serde_json::Value {
    let model = field.model();
    serde_json::json!({
        "kind": "nelf-network",
        "weights": weights_name,
        "light_transport_scale": field.light_transport_scale(),
        "source_gain": field.source_gain(),
        "source_normalised": model.source_normalised(),
        "shading_prior": model.shading_prior().map(prior_json),
        "source_relative_light": model.source_relative_light(),
        "trained_shading_prior": model.trained_shading_prior().map(prior_json),
    })
}

/// A shading prior as the provenance records it.
fn prior_json(prior: ShadingPrior) -> serde_json::Value {
    serde_json::json!({"step_mm": prior.step_mm, "weight": prior.weight})
}
