//! Every setting of a bake, in one place: the `nelf bake` options
//! ([`BakeConfig`], saved beside each asset), and the choices they name (view
//! policy, coefficient encoding, where the ground-truth density shell sits, path
//! tracer overrides). Nothing here runs a stage; the stages read it.

use nelf_format::CoefficientEncoding;
use nelf_format::conventions::LT_DIM;
use nelf_render::MarchSettings;
use nelf_scene::tracer::TraceSettings;
use serde::{Deserialize, Serialize};

use crate::error::{BakeError, Result};
use crate::view::ViewChoice;

/// Samples per light texel the ground-truth field takes at most by default (a
/// capture's images take 16). A baked vector needs fewer samples than a pixel: the
/// PCA keeps K of its 384 dimensions and drops most of the noise (the sweep that
/// chose it: `docs/measurements/settings.md`).
pub const FIELD_TEXEL_SAMPLES: u32 = 4;

/// Indirect directions the ground-truth field takes at most by default (a
/// capture's images take 128); see [`FIELD_TEXEL_SAMPLES`].
pub const FIELD_INDIRECT_SAMPLES: u32 = 32;

/// Default `--max-hull-radius-m`: a head and shoulders fit.
pub const DEFAULT_MAX_HULL_RADIUS_M: f64 = 0.5;

fn default_max_hull_radius_m() -> f64 {
    DEFAULT_MAX_HULL_RADIUS_M
}

/// Default `--lt-share-voxels`.
pub const DEFAULT_LT_SHARE_VOXELS: f32 = 2.0;

fn default_lt_share_voxels() -> f32 {
    DEFAULT_LT_SHARE_VOXELS
}

/// Overrides of the ground-truth path tracer's sample counts.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, clap::Args)]
pub struct TraceOverrides {
    /// Ground-truth tracer: interreflection bounces (default: the capture's
    /// `synth_config.json`, else the tracer's default, 2).
    #[arg(long)]
    pub bounces: Option<u32>,
    /// Ground-truth tracer: stratified samples per light texel (default: the capture's
    /// or the tracer's 16 for reference images; at most 4 for the baked field).
    #[arg(long)]
    pub texel_samples: Option<u32>,
    /// Ground-truth tracer: indirect directions at the first surface point (default:
    /// the capture's or the tracer's 128 for reference images; at most 32 for the
    /// baked field).
    #[arg(long)]
    pub indirect_samples: Option<u32>,
}

impl TraceOverrides {
    /// `base` with the overrides applied: the settings of reference images.
    pub fn apply(&self, base: TraceSettings) -> TraceSettings {
        TraceSettings {
            bounces: self.bounces.unwrap_or(base.bounces),
            texel_samples: self.texel_samples.unwrap_or(base.texel_samples),
            indirect_samples: self.indirect_samples.unwrap_or(base.indirect_samples),
            ..base
        }
    }

    /// The settings of the baked field: as [`Self::apply`], but sample counts not
    /// given explicitly are capped at [`FIELD_TEXEL_SAMPLES`] and
    /// [`FIELD_INDIRECT_SAMPLES`].
    pub fn apply_to_field(&self, base: TraceSettings) -> TraceSettings {
        TraceSettings {
            texel_samples: self
                .texel_samples
                .unwrap_or(base.texel_samples.min(FIELD_TEXEL_SAMPLES)),
            indirect_samples: self
                .indirect_samples
                .unwrap_or(base.indirect_samples.min(FIELD_INDIRECT_SAMPLES)),
            ..self.apply(base)
        }
    }
}

/// Where the ground-truth density's shell sits relative to the mesh surface.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum ShellPlacement {
    /// A signed linear ramp through the surface, negative outside ([`ShellProfile::Signed`]).
    #[default]
    Signed,
    /// The ramp lies inside the surface ([`ShellProfile::Inside`]).
    Inside,
    /// The ramp is centred on the surface (`MeshField`'s own profile).
    Centred,
}

/// Which outgoing direction the light transport is baked for (a baked vector has
/// one; the viewer cannot change it).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum ViewPolicyChoice {
    /// The mean of `T` over the directions toward every camera centre.
    #[default]
    AverageCameras,
    /// `T` toward the mean of the camera centres.
    MeanCamera,
}

/// How PCA coefficients are stored.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum EncodingChoice {
    /// One byte per coefficient, affine per component.
    #[default]
    U8,
    /// IEEE binary16 per coefficient.
    F16,
}

impl EncodingChoice {
    /// The file's encoding.
    pub fn encoding(self) -> CoefficientEncoding {
        match self {
            Self::U8 => CoefficientEncoding::U8Affine,
            Self::F16 => CoefficientEncoding::F16,
        }
    }
}

/// `--ramp-voxels`' default (and the value of bakes saved before it existed, whose
/// ramp was their lead).
fn default_ramp_voxels() -> f32 {
    0.25
}

/// Every setting of a bake (the `nelf bake` options); saved beside the asset in
/// `<asset>.bake.json` and recorded in its metadata.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, clap::Args)]
pub struct BakeConfig {
    /// Voxels along the longest side of the region baked (hull or mesh box); ignored
    /// when --voxel-size-m is given.
    #[arg(long, default_value_t = 128)]
    pub resolution: u32,
    /// Voxel edge in metres (overrides --resolution).
    #[arg(long)]
    pub voxel_size_m: Option<f64>,
    /// Visual hull: grow every mask by this many pixels (a (2r+1)² square) before carving.
    #[arg(long, default_value_t = 2)]
    pub dilate_px: u32,
    /// Visual hull: clip it to a cube of this half-size (metres) around the head
    /// centre when the views leave it unbounded (two views, or views close
    /// together), as NeLF bounds its rays by a sphere around the head.
    #[arg(long, default_value_t = DEFAULT_MAX_HULL_RADIUS_M)]
    #[serde(default = "default_max_hull_radius_m")]
    pub max_hull_radius_m: f64,
    /// Drop a brick whose densest voxel is less opaque than this across one voxel
    /// (`σ_min = −ln(1 − α)/voxel_size`).
    #[arg(long, default_value_t = 0.01)]
    pub min_brick_opacity: f64,
    /// Evaluate light transport only where the optical depth from outside is below
    /// this (plus one voxel around), elsewhere the PCA mean.
    #[arg(long, default_value_t = 10.0)]
    pub max_optical_depth: f64,
    /// Ground-truth field: how density follows the signed distance to the mesh (a
    /// signed linear ramp through the surface, a ramp inside it, or one centred on it).
    #[arg(long, value_enum, default_value_t)]
    pub shell_placement: ShellPlacement,
    /// Ground-truth field, `inside`/`centred` shells: ramp width, voxels.
    #[arg(long, default_value_t = 2.0)]
    pub shell_voxels: f32,
    /// Ground-truth field, `signed` shell: how far outside the surface the density
    /// crosses zero, voxels; its slope is set by `--ramp-voxels`. 0.05 against the
    /// ramp's 0.25 keeps rays that graze the surface from seeing a silhouette grown by
    /// ~¼ voxel (+0.8 to +3.5 dB on three scans, bake/README.md "Where the shell sits").
    #[arg(long, default_value_t = 0.05)]
    pub lead_voxels: f32,
    /// Signed density (the ground-truth field's `signed` shell, a network field's
    /// `--network-skin-mm`): the density's ramp, voxels: transmittance along the
    /// normal reaches ½ this far past the zero crossing (the slope is `2 ln 2 /
    /// ramp²`; a steeper ramp than the march step resolves renders a staircase). A
    /// network field's zero crossing is this far outside its surface, so that
    /// transmittance ½ falls on it.
    #[arg(long, default_value_t = 0.25)]
    #[serde(default = "default_ramp_voxels")]
    pub ramp_voxels: f32,
    /// Ground-truth field: thickness, voxels, given to open sheets and parts thinner
    /// than it (a collar, a flap of cloth, an ear's rim), so that they come out
    /// opaque and each side keeps its own shading.
    #[arg(long, default_value_t = 2.0)]
    pub sheet_voxels: f32,
    /// Ground-truth field, `signed` shell: closed parts are hollow shells this many
    /// voxels thick (0, the default: solid). Unchanged from outside; through a hole
    /// that loading left open (wider than `close_holes` closes) the inside of the
    /// mesh shows, as in the path tracer's images. Costs light transport wherever a
    /// hollow is reachable from outside: on the head-and-shoulders scan 3 voxels
    /// took 140 s of light transport against 35 s solid, at the same PSNR.
    #[arg(long, default_value_t = 0.0)]
    pub hollow_voxels: f32,
    /// Ground-truth field: surface points closer than this (voxels, a cubic cell of
    /// the world lattice) on the same triangle and side share one path-traced light
    /// transport, traced at the point of the triangle closest to the cell's centre.
    /// The voxels of the band around a surface have nearly the same closest point;
    /// sharing traces each once. 0 traces every voxel's own closest point.
    #[arg(long, default_value_t = DEFAULT_LT_SHARE_VOXELS)]
    #[serde(default = "default_lt_share_voxels")]
    pub lt_share_voxels: f32,
    /// Outgoing direction the light transport is baked for.
    #[arg(long, value_enum, default_value_t)]
    pub view_policy: ViewPolicyChoice,
    /// Longest side, pixels, of the renders that weight the PCA and choose the rank.
    #[arg(long, default_value_t = 128)]
    pub render_size: u32,
    /// Ray-march step of those renders, voxels.
    #[arg(long, default_value_t = 0.5)]
    pub step_voxels: f32,
    /// PCA weight floor, relative to the mean visibility weight, so unseen voxels
    /// still count a little.
    #[arg(long, default_value_t = 0.01)]
    pub weight_floor: f64,
    /// Force the PCA rank K (skip the choice; its loss is still measured).
    #[arg(long)]
    pub rank: Option<usize>,
    /// Largest rank the choice may take.
    #[arg(long, default_value_t = 64)]
    pub max_rank: usize,
    /// Rank choice: largest rendered-image loss accepted, dB.
    #[arg(long, default_value_t = 0.1)]
    pub max_loss_db: f64,
    /// Rank choice: the signal-to-noise ratio (dB) assumed for the unquantized grid
    /// against ground truth when the capture's lighting is unknown (no envmap in
    /// cameras.json); the default asks for more accuracy than the default synthetic
    /// capture's grid has (`docs/measurements/settings.md`).
    #[arg(long, default_value_t = 20.0)]
    pub reference_snr_db: f64,
    /// Coefficient storage.
    #[arg(long, value_enum, default_value_t)]
    pub encoding: EncodingChoice,
    /// 8-bit coefficients: one quantization step for every component, sized so that
    /// rounding adds this share of the PCA truncation error (0: each component's
    /// own range over 254 steps).
    #[arg(long, default_value_t = 0.1)]
    pub quantization_share: f64,
    /// View-dependent light transport (sheen, highlights): `auto` fits the candidates
    /// (a reflection lobe at exponents 10, 20, 40; 3 learned lobes at view ranks 4, 8,
    /// 16; sh1 and sh2 at 8) and keeps the best (the smallest within 0.1 dB of it) only
    /// when it gains more than --view-min-gain-db at the judging views (the capture's
    /// held-aside targets, else its own views); `off`; `reflect` (one glossy lobe about
    /// each voxel's mirror direction, format 1.3, the exponent chosen at the judging
    /// views); `sh1`/`sh2` (spherical harmonics of the outgoing direction up to degree
    /// 1 / 2); or N (1..=9) lobes learned per asset.
    #[arg(long, default_value_t = ViewChoice::Auto)]
    #[serde(default)]
    pub view_dependence: ViewChoice,
    /// `auto`: smallest PSNR gain (dB, mean over the judging views) that keeps a view part.
    #[arg(long, default_value_t = DEFAULT_VIEW_MIN_GAIN_DB)]
    #[serde(default = "default_view_min_gain_db")]
    pub view_min_gain_db: f64,
    /// Rank of the view basis (default: `auto` tries 4, 8 and --max-view-rank for three
    /// learned lobes and 8 for sh1 and sh2; an explicit choice takes 8).
    #[arg(long)]
    #[serde(default)]
    pub view_rank: Option<usize>,
    /// Largest view-basis rank fitted.
    #[arg(long, default_value_t = DEFAULT_MAX_VIEW_RANK)]
    #[serde(default = "default_max_view_rank")]
    pub max_view_rank: usize,
    /// The density again on a lattice 2 or 4 times finer per axis (format 1.4, section
    /// `DNSF`), sampled from the field with its ramp and lead scaled to the fine voxel:
    /// sharper silhouettes and thin parts while the light transport stays at the voxels.
    /// `auto`: 2 for a watertight mesh's field (a closed scan, a capture's ground truth,
    /// a surface reconstructed from photographs; +1.0 to +1.3 dB at +0.6 MB on three),
    /// off for a mesh with open sheets and for a network's field (8× its density
    /// evaluations); `off`, `2`, `4` force it. Readers
    /// before 1.4 render the coarse density.
    #[arg(long, value_enum, default_value_t)]
    #[serde(default)]
    pub fine_density: FineDensityChoice,
    /// Ground-truth path-tracer overrides.
    #[command(flatten)]
    pub trace: TraceOverrides,
}

/// `--fine-density`: the factor of the fine density lattice, or none.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, clap::ValueEnum)]
pub enum FineDensityChoice {
    /// Factor 2 for a watertight mesh's field, none for any other.
    #[default]
    #[value(name = "auto")]
    #[serde(rename = "auto")]
    Auto,
    /// No fine density: the file holds the voxels' density only.
    #[value(name = "off")]
    #[serde(rename = "off")]
    Off,
    /// Twice as fine per axis (8 fine voxels per voxel, 8 KiB per brick before zstd).
    #[value(name = "2")]
    #[serde(rename = "2")]
    X2,
    /// Four times as fine per axis (64 fine voxels per voxel, 64 KiB per brick before zstd).
    #[value(name = "4")]
    #[serde(rename = "4")]
    X4,
}

impl FineDensityChoice {
    /// The factor `F` for a field that is a mesh's (`mesh`) or not; `None` for none.
    pub fn factor(self, mesh: bool) -> Option<u32> {
        match self {
            Self::Auto => mesh.then_some(2),
            Self::Off => None,
            Self::X2 => Some(2),
            Self::X4 => Some(4),
        }
    }
}

/// Default `--view-min-gain-db`.
pub const DEFAULT_VIEW_MIN_GAIN_DB: f64 = 0.25;

fn default_view_min_gain_db() -> f64 {
    DEFAULT_VIEW_MIN_GAIN_DB
}

/// Default `--max-view-rank`.
pub const DEFAULT_MAX_VIEW_RANK: usize = 16;

fn default_max_view_rank() -> usize {
    DEFAULT_MAX_VIEW_RANK
}

impl Default for BakeConfig {
    fn default() -> Self {
        Self {
            resolution: 128,
            voxel_size_m: None,
            dilate_px: 2,
            max_hull_radius_m: DEFAULT_MAX_HULL_RADIUS_M,
            min_brick_opacity: 0.01,
            max_optical_depth: 10.0,
            shell_placement: ShellPlacement::Signed,
            shell_voxels: 2.0,
            lead_voxels: 0.05,
            ramp_voxels: 0.25,
            sheet_voxels: 2.0,
            hollow_voxels: 0.0,
            lt_share_voxels: DEFAULT_LT_SHARE_VOXELS,
            view_policy: ViewPolicyChoice::AverageCameras,
            render_size: 128,
            step_voxels: 0.5,
            weight_floor: 0.01,
            rank: None,
            max_rank: 64,
            max_loss_db: 0.1,
            reference_snr_db: 20.0,
            encoding: EncodingChoice::U8,
            quantization_share: 0.1,
            view_dependence: ViewChoice::Auto,
            view_min_gain_db: DEFAULT_VIEW_MIN_GAIN_DB,
            view_rank: None,
            max_view_rank: DEFAULT_MAX_VIEW_RANK,
            fine_density: FineDensityChoice::default(),
            trace: TraceOverrides::default(),
        }
    }
}

impl BakeConfig {
    /// Checks ranges before any work.
    pub fn validate(&self) -> Result<()> {
        let bad = |m: String| Err(BakeError::Settings(m));
        if let Some(k) = self.rank
            && !(1..=LT_DIM).contains(&k)
        {
            return bad(format!("--rank {k} must be in 1..={LT_DIM}"));
        }
        if !(1..=LT_DIM).contains(&self.max_rank) {
            return bad(format!("--max-rank {} must be in 1..={LT_DIM}", self.max_rank));
        }
        if !(self.max_hull_radius_m.is_finite() && self.max_hull_radius_m > 0.0) {
            return bad(format!(
                "--max-hull-radius-m {} must be positive",
                self.max_hull_radius_m
            ));
        }
        if !(self.max_loss_db.is_finite() && self.max_loss_db >= 0.0) {
            return bad(format!("--max-loss-db {} must be ≥ 0", self.max_loss_db));
        }
        if !self.reference_snr_db.is_finite() {
            return bad(format!(
                "--reference-snr-db {} must be finite",
                self.reference_snr_db
            ));
        }
        if !(self.quantization_share.is_finite() && self.quantization_share >= 0.0) {
            return bad(format!(
                "--quantization-share {} must be ≥ 0",
                self.quantization_share
            ));
        }
        if !(self.weight_floor.is_finite() && self.weight_floor >= 0.0) {
            return bad(format!("--weight-floor {} must be ≥ 0", self.weight_floor));
        }
        if !(self.max_optical_depth.is_finite() && self.max_optical_depth > 0.0) {
            return bad(format!(
                "--max-optical-depth {} must be positive",
                self.max_optical_depth
            ));
        }
        if !(8..=4096).contains(&self.render_size) {
            return bad(format!("--render-size {} must be in 8..=4096", self.render_size));
        }
        if !(self.shell_voxels.is_finite() && self.shell_voxels > 0.0) {
            return bad(format!("--shell-voxels {} must be positive", self.shell_voxels));
        }
        if !(self.sheet_voxels.is_finite() && self.sheet_voxels > 0.0) {
            return bad(format!("--sheet-voxels {} must be positive", self.sheet_voxels));
        }
        if !(self.hollow_voxels.is_finite() && (self.hollow_voxels == 0.0 || self.hollow_voxels >= 2.0)) {
            return bad(format!(
                "--hollow-voxels {} must be 0 (solid) or at least 2",
                self.hollow_voxels
            ));
        }
        if !(self.lt_share_voxels.is_finite() && (0.0..=4.0).contains(&self.lt_share_voxels)) {
            return bad(format!(
                "--lt-share-voxels {} must be in 0..=4 (0: no sharing)",
                self.lt_share_voxels
            ));
        }
        if !(self.lead_voxels.is_finite() && self.lead_voxels > 0.0 && self.lead_voxels <= 2.0) {
            return bad(format!("--lead-voxels {} must be in (0, 2]", self.lead_voxels));
        }
        if !(self.ramp_voxels.is_finite() && self.ramp_voxels > 0.0 && self.ramp_voxels <= 2.0) {
            return bad(format!("--ramp-voxels {} must be in (0, 2]", self.ramp_voxels));
        }
        if !(1..=LT_DIM).contains(&self.max_view_rank) {
            return bad(format!(
                "--max-view-rank {} must be in 1..={LT_DIM}",
                self.max_view_rank
            ));
        }
        if let Some(k) = self.view_rank
            && !(1..=self.max_view_rank).contains(&k)
        {
            return bad(format!(
                "--view-rank {k} must be in 1..=--max-view-rank ({})",
                self.max_view_rank
            ));
        }
        if !self.view_min_gain_db.is_finite() {
            return bad(format!(
                "--view-min-gain-db {} must be finite",
                self.view_min_gain_db
            ));
        }
        self.march().validate()?;
        Ok(())
    }

    /// Ray-marching settings of the bake's renders.
    pub fn march(&self) -> MarchSettings {
        MarchSettings {
            step_voxels: self.step_voxels,
            ..MarchSettings::default()
        }
    }
}
