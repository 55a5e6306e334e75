//! The settings of a bake from a capture: the network-only ones ([`PipelineConfig`]'s
//! own fields) beside every setting of `nelf-bake` ([`BakeConfig`], flattened, so
//! that the options and the saved `<asset>.bake.json` read as one set), and how a
//! bake's record gets them.

use std::path::Path;

use nelf_bake::{BakeConfig, BakeOutput, sidecar_path};
use nelf_format::io_error::FileIoError;
use serde::{Deserialize, Serialize};

use crate::error::{PipelineError, Result};

/// Default `--network-skin-mm`: measured with `nelf eval network` on held-out heads
/// (`field/README.md`, "Density of a network bake").
pub const DEFAULT_NETWORK_SKIN_MM: f32 = 1.0;

/// Default [`PipelineConfig::network_hull_margin_px`].
pub const DEFAULT_NETWORK_HULL_MARGIN_PX: f32 = 0.5;

fn default_network_skin_mm() -> f32 {
    DEFAULT_NETWORK_SKIN_MM
}

fn default_shading_prior_mm() -> f32 {
    nelf_field::prior::DEFAULT_STEP_MM
}

fn default_shading_prior_weight() -> f32 {
    nelf_field::prior::DEFAULT_WEIGHT
}

fn default_network_hull_margin_px() -> f32 {
    DEFAULT_NETWORK_HULL_MARGIN_PX
}

/// Every setting of `nelf bake capture`: the baker's ([`BakeConfig`]) and those that
/// only a network field reads. Saved beside the asset (`<asset>.bake.json`, one flat
/// object as before the two were split) and recorded in its metadata.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, clap::Args)]
pub struct PipelineConfig {
    /// The baker's settings.
    #[command(flatten)]
    #[serde(flatten)]
    pub bake: BakeConfig,
    /// Network field: its density is stored as a signed function of `ln σ`
    /// (`nelf_scene::signed_density::SignedLogDensity`) for a skin across which σ grows by `e`
    /// every this many millimetres, the surface where a ray through it reaches optical
    /// depth ln 2 (σ = ln 2 / skin); trilinear interpolation then puts the surface
    /// between voxels where the network has it, not a voxel outside. 0 stores σ itself
    /// (a baked head renders swollen by about a voxel).
    #[arg(long, default_value_t = DEFAULT_NETWORK_SKIN_MM)]
    #[serde(default = "default_network_skin_mm")]
    pub network_skin_mm: f32,
    /// Network field: leave its light transport as the network gives it. By default,
    /// when the capture names the lighting its views were taken in, the light
    /// transport is scaled by the one gain that makes the network reproduce those
    /// views under that lighting (`nelf_field::calibrate`; measured in
    /// `field/README.md`, "Source-view calibration").
    #[arg(long)]
    #[serde(default)]
    pub no_source_calibration: bool,
    /// Network field, when the capture names the lighting its views were taken in:
    /// normalise every view's light transport to that lighting point by point
    /// (`nelf_field::NelfField::normalised_to_sources`, instead of the one gain) and
    /// mix in a Lambertian shading prior about the normal of the network's density,
    /// its gradient taken over this many mm (0: the one gain, no prior). Its measured
    /// effect on bakes of held-out heads is in `models/README.md`.
    #[arg(long, default_value_t = nelf_field::prior::DEFAULT_STEP_MM)]
    #[serde(default = "default_shading_prior_mm")]
    pub shading_prior_mm: f32,
    /// Weight of that prior against the network's own transport (1: the prior alone).
    #[arg(long, default_value_t = nelf_field::prior::DEFAULT_WEIGHT)]
    #[serde(default = "default_shading_prior_weight")]
    pub shading_prior_weight: f32,
    /// Network field: leave its density uncarved. By default its signed density
    /// is carved to the visual hull of the masks (`nelf_bake::silhouette`), grown by
    /// `--network-hull-margin-px`, so that the bake keeps the photos' silhouettes
    /// instead of a halo outside them.
    #[arg(long)]
    #[serde(default)]
    pub no_network_hull_carve: bool,
    /// Network field: pixels every mask is grown by before the carve (room for mask
    /// errors; 0: the exact hull of the masks thresholded at ½).
    #[arg(long, default_value_t = DEFAULT_NETWORK_HULL_MARGIN_PX)]
    #[serde(default = "default_network_hull_margin_px")]
    pub network_hull_margin_px: f32,
}

/// Default `--photo-spacing-mm`.
pub const DEFAULT_PHOTO_SPACING_MM: f64 = 1.5;
/// Default `--photo-smoothing`.
pub const DEFAULT_PHOTO_SMOOTHING: usize = 30;

/// Default `--photo-blur-mm`.
pub const DEFAULT_PHOTO_BLUR_MM: f64 = 3.0;

fn default_photo_blur_mm() -> f64 {
    DEFAULT_PHOTO_BLUR_MM
}

/// Default `--photo-light-region-step`.
pub const DEFAULT_PHOTO_LIGHT_REGION_STEP: f64 = 0.05;

fn default_photo_light_region_step() -> f64 {
    DEFAULT_PHOTO_LIGHT_REGION_STEP
}

/// Default `--photo-refine-smoothness` (chosen on heads 1 and 6 of the 21-head
/// protocol: 0.3–3 bend the normals to explain albedo texture, 100–300 move too
/// little).
pub const DEFAULT_PHOTO_REFINE_SMOOTHNESS: f64 = 30.0;

/// `--photo-lead-voxels`: the signed shell's lead of the bake of a reconstructed surface
/// (`--lead-voxels` is 0.05 for a mesh). A surface reconstructed from the masks lies a
/// little inside the true silhouette; the old lead of a quarter voxel makes up for it:
/// over the 21-head protocol at resolution 32 (lighting not named) the photographs' bake
/// scores 24.38 / 27.81 dB foreground / whole with it and 22.38 / 26.88 with 0.05
/// (docs/measurements/2026-12-07-silhouettes.md).
pub const DEFAULT_PHOTO_LEAD_VOXELS: f32 = 0.25;

fn default_photo_lead_voxels() -> f32 {
    DEFAULT_PHOTO_LEAD_VOXELS
}

fn default_photo_refine_smoothness() -> f64 {
    DEFAULT_PHOTO_REFINE_SMOOTHNESS
}

fn default_photo_spacing_mm() -> f64 {
    DEFAULT_PHOTO_SPACING_MM
}

fn default_photo_smoothing() -> usize {
    DEFAULT_PHOTO_SMOOTHING
}

/// How the lighting of a capture that names none is estimated.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum UnnamedLighting {
    /// Fitted to the photographs' shading on the reconstructed surface (`nelf_pipeline::photo::lighting::fit_lighting`).
    #[default]
    Fit,
    /// The NeLF network's estimate from the photographs.
    Network,
}

/// How the surface of a photographed head is made from the masks' visual hull.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum PhotoGeometry {
    /// Intersected with the solid where the NeLF network's density (the shipped
    /// network, or `--weights`) exceeds half a voxel's opacity: the network's learned
    /// shape where the photographs have too little texture for stereo.
    #[default]
    Network,
    /// Carved by multi-view stereo (plane-sweep depth maps fused into a truncated
    /// signed distance, `nelf_pipeline::photo::stereo`): needs texture.
    Stereo,
    /// Both: stereo where a second view confirms a depth, the network's density
    /// elsewhere.
    Fused,
    /// The hull as it is.
    Hull,
}

/// How a capture without ground truth is reconstructed before its bake
/// (`--source photos`): the masks' visual hull as a mesh, its reflectance from the
/// photographs, then a mesh bake.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, clap::Args)]
pub struct PhotoSettings {
    /// Photographs: grid spacing of the reconstructed surface, millimetres.
    #[arg(long, default_value_t = DEFAULT_PHOTO_SPACING_MM)]
    #[serde(default = "default_photo_spacing_mm")]
    pub photo_spacing_mm: f64,
    /// Photographs: Taubin smoothing iterations of the reconstructed surface.
    #[arg(long, default_value_t = DEFAULT_PHOTO_SMOOTHING)]
    #[serde(default = "default_photo_smoothing")]
    pub photo_smoothing: usize,
    /// Photographs: standard deviation of the Gaussian the fused signed distance is
    /// blurred with before meshing, millimetres (0: none). Removes the stereo's
    /// narrow grooves and spikes, which no vertex smoothing reaches.
    #[arg(long, default_value_t = DEFAULT_PHOTO_BLUR_MM)]
    #[serde(default = "default_photo_blur_mm")]
    pub photo_blur_mm: f64,
    /// Photographs: interreflections in the shading the photographs are divided by
    /// to recover reflectance (0: direct light with shadows only).
    #[arg(long, default_value_t = 0)]
    #[serde(default)]
    pub photo_shading_bounces: u32,
    /// Photographs: how the lighting is estimated when the capture names none.
    #[arg(long, value_enum, default_value_t)]
    #[serde(default)]
    pub photo_lighting: UnnamedLighting,
    /// Photographs: how the masks' visual hull is refined into the surface.
    #[arg(long, value_enum, default_value_t)]
    #[serde(default)]
    pub photo_geometry: PhotoGeometry,
    /// Photographs: the lighting fit's materials as regions of the surface whose
    /// neighbouring colours differ by less than this in log luminance (an albedo
    /// edge is a step, shading changes smoothly; 0: chromaticity clusters).
    #[arg(long, default_value_t = DEFAULT_PHOTO_LIGHT_REGION_STEP)]
    #[serde(default = "default_photo_light_region_step")]
    pub photo_light_region_step: f64,
    /// Photographs: descent steps of the surface's refinement by shading (0: none):
    /// vertices move along their normals until `albedo × shading` under the
    /// lighting matches the photographs' brightness.
    /// Off by default: over the 21-head protocol it closes 61 % of the gap instead
    /// of 58 %, but it loses 0.2 dB on the head-and-shoulders scan and costs half
    /// a minute there (docs/measurements/2026-12-07-photographs-refine.md).
    #[arg(long, default_value_t = 0)]
    #[serde(default)]
    pub photo_refine_iterations: usize,
    /// Photographs: weight of the refinement's displacement roughness.
    #[arg(long, default_value_t = DEFAULT_PHOTO_REFINE_SMOOTHNESS)]
    #[serde(default = "default_photo_refine_smoothness")]
    pub photo_refine_smoothness: f64,
    /// Photographs: the signed shell's lead of the reconstructed surface's bake,
    /// voxels (the mesh bake's `--lead-voxels` is smaller: a reconstructed surface lies
    /// a little inside the true silhouette).
    #[arg(long, default_value_t = DEFAULT_PHOTO_LEAD_VOXELS)]
    #[serde(default = "default_photo_lead_voxels")]
    pub photo_lead_voxels: f32,
}

impl PhotoSettings {
    /// Checks the ranges of every setting.
    pub fn validate(&self) -> Result<()> {
        if !(self.photo_spacing_mm.is_finite() && self.photo_spacing_mm > 0.0) {
            return Err(PipelineError::Invalid(format!(
                "invalid reconstruction settings: --photo-spacing-mm {} must be positive",
                self.photo_spacing_mm
            )));
        }
        if !(self.photo_light_region_step.is_finite() && self.photo_light_region_step >= 0.0) {
            return Err(PipelineError::Invalid(format!(
                "invalid reconstruction settings: --photo-light-region-step {} must be zero or positive",
                self.photo_light_region_step
            )));
        }
        if !(self.photo_refine_smoothness.is_finite() && self.photo_refine_smoothness >= 0.0) {
            return Err(PipelineError::Invalid(format!(
                "invalid reconstruction settings: --photo-refine-smoothness {} must be zero or positive",
                self.photo_refine_smoothness
            )));
        }
        if !(self.photo_lead_voxels.is_finite() && (0.0..=2.0).contains(&self.photo_lead_voxels)) {
            return Err(PipelineError::Invalid(format!(
                "invalid reconstruction settings: --photo-lead-voxels {} must be in [0, 2]",
                self.photo_lead_voxels
            )));
        }
        if !(self.photo_blur_mm.is_finite() && self.photo_blur_mm >= 0.0) {
            return Err(PipelineError::Invalid(format!(
                "invalid reconstruction settings: --photo-blur-mm {} must be zero or positive",
                self.photo_blur_mm
            )));
        }
        Ok(())
    }
}

impl Default for PhotoSettings {
    fn default() -> Self {
        Self {
            photo_spacing_mm: DEFAULT_PHOTO_SPACING_MM,
            photo_smoothing: DEFAULT_PHOTO_SMOOTHING,
            photo_blur_mm: DEFAULT_PHOTO_BLUR_MM,
            photo_shading_bounces: 0,
            photo_lighting: UnnamedLighting::default(),
            photo_geometry: PhotoGeometry::default(),
            photo_light_region_step: DEFAULT_PHOTO_LIGHT_REGION_STEP,
            photo_refine_iterations: 0,
            photo_refine_smoothness: DEFAULT_PHOTO_REFINE_SMOOTHNESS,
            photo_lead_voxels: DEFAULT_PHOTO_LEAD_VOXELS,
        }
    }
}

impl Default for PipelineConfig {
    fn default() -> Self {
        Self::from(BakeConfig::default())
    }
}

impl From<BakeConfig> for PipelineConfig {
    /// `bake` with the network settings at their defaults.
    fn from(bake: BakeConfig) -> Self {
        Self {
            bake,
            network_skin_mm: DEFAULT_NETWORK_SKIN_MM,
            no_source_calibration: false,
            shading_prior_mm: nelf_field::prior::DEFAULT_STEP_MM,
            shading_prior_weight: nelf_field::prior::DEFAULT_WEIGHT,
            no_network_hull_carve: false,
            network_hull_margin_px: DEFAULT_NETWORK_HULL_MARGIN_PX,
        }
    }
}

impl PipelineConfig {
    /// Checks the ranges of every setting before any work.
    pub fn validate(&self) -> Result<()> {
        let bad = |m: String| Err(PipelineError::Invalid(format!("invalid bake settings: {m}")));
        if !(self.network_skin_mm.is_finite() && self.network_skin_mm >= 0.0) {
            return bad(format!(
                "--network-skin-mm {} must be ≥ 0 (0: store σ itself)",
                self.network_skin_mm
            ));
        }
        if !(self.network_hull_margin_px.is_finite() && self.network_hull_margin_px >= 0.0) {
            return bad(format!(
                "--network-hull-margin-px {} must be ≥ 0",
                self.network_hull_margin_px
            ));
        }
        if !(self.shading_prior_mm.is_finite() && self.shading_prior_mm >= 0.0) {
            return bad(format!(
                "--shading-prior-mm {} must be ≥ 0 (0: no prior)",
                self.shading_prior_mm
            ));
        }
        if !(0.0..=1.0).contains(&self.shading_prior_weight) {
            return bad(format!(
                "--shading-prior-weight {} must be in [0, 1]",
                self.shading_prior_weight
            ));
        }
        Ok(self.bake.validate()?)
    }

    /// Adds the settings `record` lacks (the network's, where the baker recorded its
    /// own) to `record`, when it is a JSON object; the baker's values stay.
    fn fill_in(&self, record: &mut serde_json::Value) -> Result<()> {
        let serde_json::Value::Object(all) = serde_json::to_value(self)? else {
            return Ok(());
        };
        if let serde_json::Value::Object(record) = record {
            for (key, value) in all {
                record.entry(key).or_insert(value);
            }
        }
        Ok(())
    }
}

/// Writes the asset and `<asset>.bake.json` as [`nelf_bake::write_bake`] does, with
/// every setting of `config` recorded (the asset's `settings` and the sidecar's
/// `config` get the network's beside the baker's).
pub fn write_bake(
    output: &mut BakeOutput,
    config: &PipelineConfig,
    path: &Path,
) -> Result<nelf_format::WriteReport> {
    if let Some(settings) = output.asset.metadata.get_mut("settings") {
        config.fill_in(settings)?;
    }
    let written = nelf_bake::write_bake(output, &config.bake, path)?;
    let sidecar = sidecar_path(path);
    let io = |source| PipelineError::Io(FileIoError::new(sidecar.clone(), source));
    let mut json: serde_json::Value = serde_json::from_slice(&std::fs::read(&sidecar).map_err(io)?)?;
    if let Some(recorded) = json.get_mut("config") {
        config.fill_in(recorded)?;
    }
    let text = serde_json::to_string_pretty(&json)? + "\n";
    nelf_format::atomic::write_bytes_atomically(&sidecar, text.as_bytes()).map_err(io)?;
    Ok(written)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn network_skin_is_validated_and_defaults_for_older_configs() {
        assert!(PipelineConfig::default().validate().is_ok());
        for bad in [-1.0f32, f32::NAN, f32::INFINITY] {
            let config = PipelineConfig {
                network_skin_mm: bad,
                ..PipelineConfig::default()
            };
            let message = config.validate().err().map(|e| e.to_string()).unwrap_or_default();
            assert!(message.contains("--network-skin-mm"), "{bad}: {message}");
        }
        let off = PipelineConfig {
            network_skin_mm: 0.0,
            ..PipelineConfig::default()
        };
        assert!(off.validate().is_ok());
        // A config saved before the option existed reads back with the default.
        let mut json = serde_json::to_value(PipelineConfig::default()).unwrap_or_default();
        if let Some(map) = json.as_object_mut() {
            map.remove("network_skin_mm");
        }
        let read: PipelineConfig = serde_json::from_value(json).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(read.network_skin_mm, DEFAULT_NETWORK_SKIN_MM);
    }

    #[test]
    fn hull_carve_is_validated_and_defaults_on_for_older_configs() {
        for bad in [-0.5f32, f32::NAN, f32::INFINITY] {
            let config = PipelineConfig {
                network_hull_margin_px: bad,
                ..PipelineConfig::default()
            };
            let message = config.validate().err().map(|e| e.to_string()).unwrap_or_default();
            assert!(message.contains("--network-hull-margin-px"), "{bad}: {message}");
        }
        let mut json = serde_json::to_value(PipelineConfig::default()).unwrap_or_default();
        if let Some(map) = json.as_object_mut() {
            map.remove("network_hull_margin_px");
            map.remove("no_network_hull_carve");
        }
        let read: PipelineConfig = serde_json::from_value(json).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(read.network_hull_margin_px, DEFAULT_NETWORK_HULL_MARGIN_PX);
        assert!(!read.no_network_hull_carve);
    }

    /// The saved settings are one flat object, the baker's keys beside the network's,
    /// and a flat object written before the split reads back whole.
    #[test]
    fn the_saved_settings_stay_one_flat_object() {
        let config = PipelineConfig {
            shading_prior_mm: 5.0,
            ..PipelineConfig::default()
        };
        let json = serde_json::to_value(&config).unwrap_or_default();
        assert_eq!(json["resolution"], 128, "{json}");
        assert_eq!(json["shading_prior_mm"], 5.0, "{json}");
        let read: PipelineConfig = serde_json::from_value(json).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(read, config);
        // The baker reads its own settings out of the same object.
        let bake: BakeConfig = serde_json::from_value(serde_json::to_value(&config).unwrap_or_default())
            .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(bake, config.bake);
    }
}
