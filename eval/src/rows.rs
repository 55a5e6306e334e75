//! The rows `nelf eval` measures and reports: one per setting of a Pareto sweep
//! ([`ParetoRow`]) and one per point of a stability axis ([`StabilityPoint`]), with
//! the image scores they share ([`Scores`]).

use serde::{Deserialize, Serialize};

/// Image scores of an asset at held-aside views under held-aside lightings, means
/// over the views. PSNR and SSIM use a data range equal to each reference image's
/// largest value (as `nelf_bake::eval`); ꟻLIP is NVIDIA's, on 8-bit sRGB at an
/// exposure that puts the reference's largest value at 0.5 (lower is better).
/// "Foreground" figures count only pixels inside the true silhouette (mask > 0.5).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Scores {
    /// Whole-image PSNR, dB.
    pub psnr_db: f64,
    /// Foreground-only PSNR, dB.
    pub psnr_fg_db: f64,
    /// Whole-image SSIM.
    pub ssim: f64,
    /// Foreground-only SSIM.
    pub ssim_fg: f64,
    /// Whole-image mean ꟻLIP.
    pub flip: f64,
    /// Foreground-only mean ꟻLIP.
    pub flip_fg: f64,
    /// The trivial baseline on the same views: each view's mean foreground colour,
    /// flat inside the true silhouette, black outside; whole-image PSNR, dB.
    pub baseline_psnr_db: f64,
    /// The same baseline, foreground-only PSNR, dB.
    pub baseline_psnr_fg_db: f64,
    /// Number of views averaged.
    pub views: usize,
}

/// One setting of a Pareto sweep and what it measured.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ParetoRow {
    /// Short unique name of the setting, e.g. `r128-k16-u8`.
    pub id: String,
    /// Voxels along the longest side of the baked region.
    pub resolution: u32,
    /// PCA rank K.
    pub rank: usize,
    /// Coefficient encoding (`u8` or `f16`).
    pub encoding: String,
    /// Voxels in the asset.
    pub voxels: usize,
    /// Bytes of the `.nelf` file.
    pub file_bytes: u64,
    /// Seconds to bake this setting: the stages it shares with the other settings of
    /// its resolution (field evaluation, PCA) plus its own (truncation, quantization,
    /// writing).
    pub bake_secs: f64,
    /// Image scores at the held-aside views.
    pub scores: Scores,
    /// CPU reference renderer, one ray per pixel, milliseconds per held-aside view.
    pub cpu_render_ms: f64,
    /// GPU frame (relit once, then marched) at 512², milliseconds; `None` if no GPU
    /// adapter was available.
    pub gpu_frame_ms_512: Option<f64>,
    /// GPU frame at 1920 × 1080, milliseconds; `None` if not measured.
    pub gpu_frame_ms_1080p: Option<f64>,
    /// The GPU adapter the frame times come from.
    pub gpu_adapter: Option<String>,
    /// A thumbnail of the first held-aside view, relative to the report folder.
    pub thumbnail: Option<String>,
    /// On the Pareto front of quality (PSNR) against file bytes.
    pub front_bytes: bool,
    /// On the Pareto front of quality (PSNR) against GPU frame time at 512².
    pub front_frame: bool,
}

/// One point of a stability axis.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StabilityPoint {
    /// The axis (`views`, `spread_deg`, `target_angle_deg`, `sun_radius_deg`,
    /// `hdri`, `rank`, `pose_noise_deg`, `pose_noise_mm`, `mask_px`, `mask_soft_px`,
    /// `mesh_defect`).
    pub axis: String,
    /// The value on the axis (numeric axes), as plotted.
    pub value: f64,
    /// A label for the value (`2 views`, `torn sphere`, `sunset.exr`, …).
    pub label: String,
    /// Image scores at the held-aside views.
    pub scores: Scores,
    /// The worst view's whole-image PSNR, dB.
    pub worst_psnr_db: f64,
    /// Gallery image (truth | ours | ꟻLIP map) of the worst view, relative to the
    /// report folder.
    pub gallery: Option<String>,
    /// Why no asset could be made at this point (the bake's error), if it failed;
    /// its scores are then zero.
    #[serde(default)]
    pub failure: Option<String>,
}
