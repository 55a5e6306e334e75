//! What the bake's stages hand on to each other and to the caller: the field as
//! sampled ([`SampledField`], out of occupancy, transport and the PCA), the rank
//! chosen ([`RankChoice`]), the seconds per stage ([`StageTimings`]) and the baked
//! asset with its report ([`BakeOutput`], [`BakeReport`]).

use nelf_format::Asset;
use nelf_format::conventions::PinholeCamera;
use serde::{Deserialize, Serialize};

use crate::grid::DensityGrid;
use crate::pca::WeightedPca;
use crate::rank::CandidateLoss;
use crate::view::ViewReport;

/// Seconds spent in each stage.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct StageTimings {
    /// Visual hull (or mesh box) and the candidate bricks.
    pub hull_secs: f64,
    /// Path-tracing the ground-truth reference views (mesh bakes only).
    pub reference_secs: f64,
    /// Density of every candidate voxel, brick drop.
    pub density_secs: f64,
    /// Visibility weights of every view.
    pub weights_secs: f64,
    /// Light-transport band and its evaluation.
    pub lt_secs: f64,
    /// Weighted PCA and coefficients.
    pub pca_secs: f64,
    /// Rank choice (renders).
    pub rank_secs: f64,
    /// View dependence: sampling many directions, fitting, judging.
    #[serde(default)]
    pub view_secs: f64,
    /// The fine density (`--fine-density`): the field's density at every fine voxel.
    #[serde(default)]
    pub fine_density_secs: f64,
    /// Encoding and writing the file.
    pub write_secs: f64,
}

/// What a bake produced.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BakeReport {
    /// Voxel edge, metres.
    pub voxel_size_m: f64,
    /// Grid extent in bricks.
    pub grid_bricks: [u32; 3],
    /// Voxels inside the visual hull (all candidate voxels for a mesh bake).
    pub hull_voxels: usize,
    /// Bricks evaluated for density.
    pub candidate_bricks: usize,
    /// Bricks kept (apron bricks included).
    pub bricks: usize,
    /// Bricks kept only as an apron around dense ones.
    pub apron_bricks: usize,
    /// Voxels kept (bricks × 512).
    pub voxels: usize,
    /// Voxels whose light transport was evaluated.
    pub lt_voxels: usize,
    /// PCA rank chosen.
    pub rank: usize,
    /// Energy kept at that rank.
    pub energy_kept: f64,
    /// Rendered loss at that rank, dB.
    pub loss_db: f64,
    /// Whether the loss met the target (always true when the rank was forced).
    pub met_target: bool,
    /// `m₀`, the unquantized grid's relative squared error against ground truth.
    pub reference_relative_error: f64,
    /// Every candidate tried.
    pub candidates: Vec<CandidateLoss>,
    /// Seconds per stage.
    pub timings: StageTimings,
    /// File size in bytes (0 until written).
    pub file_size: u64,
    /// The view-dependence stage (`None` when `--view-dependence off`).
    #[serde(default)]
    pub view: Option<ViewReport>,
    /// What the capture's loader noticed and worked around (EXIF orientations
    /// not applied, …), one sentence each.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub notes: Vec<String>,
}

/// A baked asset and its report.
#[derive(Debug, Clone)]
pub struct BakeOutput {
    /// The asset (exactly what the file will hold).
    pub asset: Asset,
    /// What happened.
    pub report: BakeReport,
}

/// A field sampled on its grid: everything a bake computes before it chooses the
/// rank and the encoding (density, visibility, light transport on the band, the
/// weighted PCA, the coefficients at the largest rank allowed). Any number of
/// assets (rank × encoding) can be made from one, with no further field
/// evaluation ([`SampledField::asset`], in [`super::quantize`]): `nelf bake
/// --target-psnr` and `nelf eval pareto` try many.
#[derive(Debug, Clone)]
pub struct SampledField {
    /// Kept bricks, densities and the brick-drop figures.
    pub dense: DensityGrid,
    /// Density as the file stores it (f16).
    pub stored_density: Vec<half::f16>,
    /// The capture's views at the reduced resolution of the weights and rank renders.
    pub views: Vec<PinholeCamera>,
    /// `(reduced camera, factor)` per capture view.
    pub reduced: Vec<(PinholeCamera, u32)>,
    /// Voxels whose light transport was evaluated.
    pub lt_voxels: Vec<usize>,
    /// Their light transport, `LT_DIM` floats each.
    pub lt: Vec<f32>,
    /// Their PCA weights (visibility in the views plus the floor).
    pub lt_weights: Vec<f64>,
    /// The weighted PCA of `lt`.
    pub pca: WeightedPca,
    /// The data's numerical rank.
    pub data_rank: usize,
    /// Rank of [`Self::coefficients`]: `--rank` when forced, else `min(--max-rank, data rank)`.
    pub top_rank: usize,
    /// Coefficients at `top_rank`, `voxels × top_rank` (zero outside the band).
    pub coefficients: Vec<f32>,
    /// The 8-bit step floor for `top_rank` ([`super::quantize::quantization_step`]).
    pub min_step: f32,
    /// Rotation from the light frame to the world.
    pub world_from_light: glam::DMat3,
    /// Seconds per stage so far (rank and write still 0).
    pub timings: StageTimings,
}

/// The rank chosen by rendered-image loss ([`super::rank::choose_rank`]) and how.
#[derive(Debug, Clone)]
pub struct RankChoice {
    /// The rank chosen.
    pub rank: usize,
    /// Every candidate tried, in order.
    pub candidates: Vec<CandidateLoss>,
    /// Index of the chosen one in `candidates`.
    pub pick: usize,
    /// Whether its loss met `--max-loss-db` (always true when the rank was forced).
    pub met_target: bool,
    /// `m₀`, the unquantized grid's relative squared error against ground truth.
    pub reference_relative_error: f64,
    /// How `m₀` was known, for the metadata.
    pub reference_json: serde_json::Value,
    /// Names of the lighting the candidates were judged under.
    pub environments: Vec<String>,
    /// Seconds per stage, the rank choice's included.
    pub timings: StageTimings,
}
