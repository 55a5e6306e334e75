//! `nelf render --field CAPTURE_DIR`: an image straight from the NeLF network over a
//! capture, no asset (`nelf_field::render::render_image`: coarse + fine hierarchical
//! sampling inside the head sphere, visual-hull pruning): slow, and the reference a
//! bake of that capture must match. The network is put in the capture's light units
//! and normalised to its views with the default shading prior
//! ([`crate::network::in_capture_light_units`]); the lighting is projected into the
//! network's light frame; orbits circle the field's hull box.

use std::path::Path;
use std::time::Instant;

use glam::DMat3;
use nelf_field::capture::{default_net_from_world, load_capture_dir_for_model};
use nelf_field::render::{ImageSettings, NetImage, Sampling, render_image};
use nelf_format::conventions::PinholeCamera;
use nelf_scene::field::FieldSource as _;
use nelf_scene::shot::{CameraArgs, LightingArgs, resolve_camera};

use crate::error::{Context as _, Result};
use crate::network::{SourceFit, in_capture_light_units, load_network};

/// What to render from the network, and how.
#[derive(Debug, Clone, Copy)]
pub struct FieldRenderRequest<'a> {
    /// The capture folder the network encodes.
    pub capture_dir: &'a Path,
    /// The network's weights (`None`: the shipped network).
    pub weights: Option<&'a Path>,
    /// Light with the network's own estimate of the capture's lighting.
    pub estimated_light: bool,
    /// Leave the network's light transport as it gives it.
    pub no_source_calibration: bool,
    /// Random ray samples from this seed instead of stratified ones.
    pub seed: Option<u64>,
    /// Where the camera is and the image size.
    pub view: &'a CameraArgs,
    /// The environment map and its rotation (unless `estimated_light`).
    pub lighting: &'a LightingArgs,
}

/// An image rendered from the network, with what it was rendered with.
#[derive(Debug)]
pub struct FieldRender {
    /// Linear RGB, no background.
    pub image: NetImage,
    /// The camera, resolved in the world frame.
    pub camera: PinholeCamera,
    /// The lighting's name.
    pub light_name: String,
    /// The network's light frame.
    pub world_from_light: DMat3,
    /// The device the network ran on.
    pub device: &'static str,
    /// Seconds loading the weights and encoding the capture.
    pub load_seconds: f64,
    /// Seconds rendering.
    pub render_seconds: f64,
}

/// Renders every pixel of `request`'s camera straight from the NeLF network, rays
/// through pixel centres bounded by the head sphere, under the lighting projected
/// into the network's light frame.
pub fn render_field(request: &FieldRenderRequest<'_>) -> Result<FieldRender> {
    let start = Instant::now();
    let capture_dir = request.capture_dir;
    let (model, _) = load_network(request.weights)?;
    let (capture, description) = load_capture_dir_for_model(capture_dir, default_net_from_world(), &model)
        .with_context(|| format!("loading the capture {}", capture_dir.display()))?;
    let field = nelf_field::NelfField::new(model, &capture).context("encoding the capture")?;
    let field = in_capture_light_units(
        field,
        Some(&description),
        capture_dir,
        if request.no_source_calibration {
            SourceFit::None
        } else {
            SourceFit::Normalised(Some(nelf_field::prior::ShadingPrior::default()))
        },
    )?;
    let (lo, hi) = field.bounds();
    let (camera, capture_envmap) = resolve_camera(request.view, (lo.as_dvec3(), hi.as_dvec3()))?;
    let world_from_light = field.world_from_light();
    let (light, light_name) = if request.estimated_light {
        (
            field.source_light()?,
            "the network's estimate of the capture's lighting".to_string(),
        )
    } else {
        let (env, name) = request.lighting.load(capture_envmap.as_deref())?;
        (
            nelf_format::conventions::project_envmap(
                &env,
                request.lighting.world_from_env().transpose() * world_from_light,
            )?,
            name,
        )
    };
    let net_light = field.net_light(&light)?;
    let load_seconds = start.elapsed().as_secs_f64();

    let start = Instant::now();
    let settings = ImageSettings {
        head_centre: capture.head_centre_net(),
        sampling: request.seed.map_or(Sampling::Stratified, Sampling::Random),
        ..ImageSettings::default()
    };
    let progress = indicatif::ProgressBar::new(0);
    let image = render_image(
        field.model(),
        field.encoded(),
        &capture.net_camera(&camera),
        &net_light,
        &settings,
        Some(&progress),
    )?;
    progress.finish_and_clear();
    Ok(FieldRender {
        image,
        camera,
        light_name,
        world_from_light,
        device: nelf_field::device_name(&nelf_field::default_device()),
        load_seconds,
        render_seconds: start.elapsed().as_secs_f64(),
    })
}
