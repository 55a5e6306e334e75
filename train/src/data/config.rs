//! [`DataConfig`]: every setting of a dataset, saved as `data_config.json` in its folder.

use std::path::PathBuf;

use serde::{Deserialize, Serialize};

use crate::error::TrainError;

/// Settings of `nelf train data`; saved as `DIR/data_config.json`. A dataset folder
/// holds one configuration: a rerun with the same settings resumes, other settings
/// are refused.
///
/// **Held-out split.** Training heads have ids `0..heads`, validation heads
/// `heads..heads + val_heads`. Validation heads draw their procedural head and
/// environment seeds from `[2^62, 2^63)`, training heads from `[0, 2^62)`; the
/// HDRIs named by `val_envmaps` (default `forest` and `interior`) light validation
/// heads only, the other maps of `envmaps_dir` training heads only; the scanned
/// head is a training identity only. `split.json` lists every head's draw.
#[derive(Debug, Clone, PartialEq, clap::Args, Serialize, Deserialize)]
pub struct DataConfig {
    /// Image width and height in pixels (source and target views).
    #[arg(long, default_value_t = 128)]
    pub size: u32,
    /// Source views per head (view 0 frontal, the others around it).
    #[arg(long, default_value_t = 5)]
    pub views: usize,
    /// Training heads (ids 0..heads).
    #[arg(long, default_value_t = 200)]
    pub heads: u32,
    /// Validation heads (ids `heads..heads + val_heads`): held-out identities and lightings.
    #[arg(long, default_value_t = 8)]
    pub val_heads: u32,
    /// Seed of every random draw (identities, lightings, cameras, tracer streams).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Largest azimuth and elevation of a source view from the frontal one, degrees.
    #[arg(long, default_value_t = 30.0)]
    pub max_angle_deg: f64,
    /// Nearest camera distance from the head centre, metres (each head draws its own
    /// range inside `[distance_min_m, distance_max_m]`).
    #[arg(long, default_value_t = 0.9)]
    pub distance_min_m: f64,
    /// Farthest camera distance from the head centre, metres.
    #[arg(long, default_value_t = 2.2)]
    pub distance_max_m: f64,
    /// Smallest share of the frame height the head's bounding sphere fills (each
    /// head draws one in `[fill_min, fill_max]`: with the distance it sets the field
    /// of view).
    #[arg(long, default_value_t = 0.7)]
    pub fill_min: f64,
    /// Largest share of the frame height the head's bounding sphere fills.
    #[arg(long, default_value_t = 0.95)]
    pub fill_max: f64,
    /// Smallest turn of lighting A for the self-rotation target, degrees: the turn is
    /// drawn uniformly with `|angle| ∈ [rotation_min_deg, 180]`, either sign.
    #[arg(long, default_value_t = 30.0)]
    pub rotation_min_deg: f32,
    /// Grid cells along a procedural head's height (triangle count ≈ 6·n²).
    #[arg(long, default_value_t = 64)]
    pub head_cells: u32,
    /// The scanned head used as some training identities (`.off` or `.obj`).
    #[arg(long, default_value = "data/meshes/head.off")]
    pub scan_mesh: PathBuf,
    /// Turn the scanned head about +y by this many degrees so that it faces +z
    /// (90 for `data/meshes/head.off`).
    #[arg(long, default_value_t = 90.0, allow_negative_numbers = true)]
    pub scan_rotate_y_deg: f32,
    /// Height the scanned head is scaled to, metres (head and neck).
    #[arg(long, default_value_t = 0.23)]
    pub scan_height_m: f32,
    /// Every `scan_every`-th training head (ids `scan_every − 1`, `2·scan_every − 1`,
    /// …) is the scanned head; 0: none.
    #[arg(long, default_value_t = 10)]
    pub scan_every: u32,
    /// Folder of real lat-long HDR environment maps (`*.exr`, `*.hdr`).
    #[arg(long, default_value = "data/envmaps")]
    pub envmaps_dir: PathBuf,
    /// Maps of `envmaps_dir` (file stems) that light validation heads only; the
    /// others light training heads only.
    #[arg(long, value_delimiter = ',', default_value = "forest,interior")]
    pub val_envmaps: Vec<String>,
    /// Probability that a lighting is a real HDRI (else a procedural environment).
    #[arg(long, default_value_t = 0.5)]
    pub hdri_share: f64,
    /// Largest sheen: each head's glossy lobe weight (`specular_weight`) is drawn
    /// uniformly in `[0, specular_max]`.
    #[arg(long, default_value_t = 0.3)]
    pub specular_max: f32,
    /// Interreflection bounces of the path tracer.
    #[arg(long, default_value_t = 2)]
    pub bounces: u32,
    /// Stratified samples per light texel for direct lighting. This sets the images'
    /// noise (against the default tracer's: `docs/measurements/settings.md`).
    #[arg(long, default_value_t = 4)]
    pub texel_samples: u32,
    /// Indirect directions at the first surface point.
    #[arg(long, default_value_t = 16)]
    pub indirect_samples: u32,
    /// Points per head with ground-truth density and light transport (`distill.bin`).
    #[arg(long, default_value_t = 2048)]
    pub distill_points: usize,
    /// Share of the distillation points drawn uniformly in the head's bounding box
    /// (grown by 2 cm); the others lie near the surface.
    #[arg(long, default_value_t = 0.15)]
    pub distill_uniform_share: f64,
    /// Standard deviation of a near-surface point's offset along the surface
    /// normal, millimetres.
    #[arg(long, default_value_t = 2.0)]
    pub distill_offset_mm: f64,
    /// Width `w` of the ground-truth density shell, millimetres: `σ(d) = σ_max ·
    /// clamp(½ − d/w, 0, 1)` with `σ_max = 100/w` (`nelf_scene::field::DensityProfile`).
    #[arg(long, default_value_t = 2.0)]
    pub distill_shell_mm: f32,
}

impl Default for DataConfig {
    fn default() -> Self {
        Self {
            size: 128,
            views: 5,
            heads: 200,
            val_heads: 8,
            seed: 0,
            max_angle_deg: 30.0,
            distance_min_m: 0.9,
            distance_max_m: 2.2,
            fill_min: 0.7,
            fill_max: 0.95,
            rotation_min_deg: 30.0,
            head_cells: 64,
            scan_mesh: PathBuf::from("data/meshes/head.off"),
            scan_rotate_y_deg: 90.0,
            scan_height_m: 0.23,
            scan_every: 10,
            envmaps_dir: PathBuf::from("data/envmaps"),
            val_envmaps: vec!["forest".into(), "interior".into()],
            hdri_share: 0.5,
            specular_max: 0.3,
            bounces: 2,
            texel_samples: 4,
            indirect_samples: 16,
            distill_points: 2048,
            distill_uniform_share: 0.15,
            distill_offset_mm: 2.0,
            distill_shell_mm: 2.0,
        }
    }
}

/// Most distillation points a head may have (a damaged file is refused beyond it).
pub const MAX_DISTILL_POINTS: usize = 1 << 22;

impl DataConfig {
    /// Total number of heads, training and validation.
    pub fn total_heads(&self) -> u32 {
        self.heads.saturating_add(self.val_heads)
    }

    /// Whether head `id` is a validation head.
    pub fn is_val(&self, id: u32) -> bool {
        id >= self.heads
    }

    /// Checks ranges before any work is done (files are checked when they are read).
    pub fn validate(&self) -> Result<(), TrainError> {
        let bad = |m: String| Err(TrainError::Settings(m));
        let finite_in = |v: f64, lo: f64, hi: f64| v.is_finite() && v >= lo && v <= hi;
        if !(16..=4096).contains(&self.size) {
            return bad(format!("--size {} must be within 16..=4096", self.size));
        }
        if self.views < 2 {
            return bad(format!("--views {} (a head needs at least 2)", self.views));
        }
        if u64::from(self.heads) + u64::from(self.val_heads) == 0 {
            return bad("--heads and --val-heads are both 0: nothing to make".into());
        }
        if u64::from(self.heads) + u64::from(self.val_heads) > 99_999 {
            return bad(format!(
                "{} heads: at most 99,999 fit the folder names h00000…h99998",
                u64::from(self.heads) + u64::from(self.val_heads)
            ));
        }
        if !(finite_in(self.max_angle_deg, 0.0, 80.0) && self.max_angle_deg > 0.0) {
            return bad(format!(
                "--max-angle-deg {} must be in (0, 80]",
                self.max_angle_deg
            ));
        }
        if !(self.distance_min_m.is_finite()
            && self.distance_min_m > 0.0
            && finite_in(self.distance_max_m, self.distance_min_m, 1e3))
        {
            return bad(format!(
                "distances {}..{} m must be positive and ordered",
                self.distance_min_m, self.distance_max_m
            ));
        }
        if !(self.fill_min > 0.05 && finite_in(self.fill_max, self.fill_min, 1.0)) {
            return bad(format!(
                "fills {}..{} must be ordered within (0.05, 1]",
                self.fill_min, self.fill_max
            ));
        }
        if !finite_in(f64::from(self.rotation_min_deg), 0.0, 180.0) {
            return bad(format!(
                "--rotation-min-deg {} must be in [0, 180]",
                self.rotation_min_deg
            ));
        }
        if !(self.scan_height_m.is_finite() && self.scan_height_m > 0.0 && self.scan_rotate_y_deg.is_finite())
        {
            return bad(format!(
                "--scan-height-m {} must be positive and --scan-rotate-y-deg {} finite",
                self.scan_height_m, self.scan_rotate_y_deg
            ));
        }
        if !finite_in(self.hdri_share, 0.0, 1.0) {
            return bad(format!("--hdri-share {} must be in [0, 1]", self.hdri_share));
        }
        if !finite_in(f64::from(self.specular_max), 0.0, 1.0) {
            return bad(format!("--specular-max {} must be in [0, 1]", self.specular_max));
        }
        if self.texel_samples == 0 {
            return bad("--texel-samples must be at least 1".into());
        }
        if self.distill_points > MAX_DISTILL_POINTS {
            return bad(format!(
                "--distill-points {} exceeds {MAX_DISTILL_POINTS}",
                self.distill_points
            ));
        }
        if !finite_in(self.distill_uniform_share, 0.0, 1.0) {
            return bad(format!(
                "--distill-uniform-share {} must be in [0, 1]",
                self.distill_uniform_share
            ));
        }
        if !(self.distill_offset_mm.is_finite() && self.distill_offset_mm >= 0.0) {
            return bad(format!(
                "--distill-offset-mm {} must be finite and ≥ 0",
                self.distill_offset_mm
            ));
        }
        if !(self.distill_shell_mm.is_finite() && self.distill_shell_mm > 0.0) {
            return bad(format!(
                "--distill-shell-mm {} must be positive",
                self.distill_shell_mm
            ));
        }
        let mut names = self.val_envmaps.clone();
        names.sort();
        names.dedup();
        if names.len() != self.val_envmaps.len() || names.iter().any(|n| n.trim().is_empty()) {
            return bad(format!(
                "--val-envmaps {:?} must be distinct, non-empty names",
                self.val_envmaps
            ));
        }
        Ok(())
    }
}
