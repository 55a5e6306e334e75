//! View-dependent light transport (format 1.2): fitting
//! `T(x, ω) ≈ T̄(x) + Σ_j Y_j(ω) Σ_i d_ji(x) V_i` to a field's transport toward many
//! outgoing directions, and choosing the lobes `Y_j` per scene.
//!
//! `T̄` is the bake's view-independent vector (the view policy's mean over the directions
//! toward the capture's cameras), stored as today by the PCA part, so a reader that
//! ignores the view part still renders the asset a view-independent bake would have.
//! The view part models the **residual** `R(x, ω) = T(x, ω) − T̄(x)`:
//!
//! 1. **Samples.** Every band voxel's transport toward `D` fixed world directions (a
//!    Fibonacci sphere, [`VIEW_DIRECTIONS`]), from
//!    [`nelf_scene::field::FieldSource::evaluate_directions`]. A direction counts with
//!    weight `max(0, n·ω)`, `n` the outward normal of the density (`−∇σ`, central
//!    differences of the trilinear grid): the directions the voxel can be seen from.
//! 2. **Harmonics fit.** Per voxel, weighted least squares of `R` on the nine real
//!    spherical harmonics of degrees 0–2 (`view_harmonics`; the constant corrects `T̄`
//!    for the directions the voxel is seen from, which need not be the cameras'), with a
//!    small ridge (`λ = 10⁻³ · tr G / J`) so that directions never seen stay near zero.
//! 3. **View basis.** On an evenly strided subsample of the band ([`BASIS_SAMPLE`]
//!    voxels) the fitted harmonic vectors are pooled, weighted by how much the voxel
//!    shows in the capture's views, and their uncentred principal directions become the
//!    basis `V` (rank ≤ `--max-view-rank`). Then every voxel's residual is projected on
//!    `V` first and fitted second (the fit is linear, so the order does not matter), and
//!    only the per-voxel normal equations (`G`, 9 × 9, and `h`, 9 × `K_v`) are kept: any
//!    choice of lobes is then an exact weighted least-squares fit without new samples.
//! 4. **Lobes** (`--view-dependence`): `sh1` (the four harmonics of degrees 0–1), `sh2`
//!    (all nine), or `N` lobes learned per asset: the top `N` eigenvectors of the
//!    visibility-weighted second moment of the fitted harmonic coefficients (a small
//!    per-asset decoder as in Hedman et al. 2021, "Baking neural radiance fields", kept linear so relighting
//!    stays a dot product).
//!    `auto` fits the candidates, renders each at the judging views (the capture's
//!    held-aside targets, else its own views) and keeps the best only when it gains more
//!    than `--view-min-gain-db` over the view-independent asset.
//!
//! Files by job: [`directions`] (the outgoing directions sampled and how much each
//! counts at a voxel), [`harmonic`] (steps 2–4: the lobes, the view basis, the
//! per-voxel fit), [`reflection`] (the reflection part: one lobe about the mirror
//! direction per voxel), [`choice`] (judging the candidates, `auto`'s probe, attaching
//! the part kept).

pub mod choice;
pub mod directions;
pub mod harmonic;
pub mod reflection;

pub use choice::{
    AUTO_GAIN_SLACK_DB, DEFAULT_VIEW_RANK, JUDGE_PIXEL_GRID, PROBE_OVERSELL, PROBE_PIXEL_GRID, ViewCandidate,
    ViewProbe, ViewReport, ViewSettings, choose_view, extrapolated_gain_db,
};
pub use directions::{VIEW_DIRECTIONS, sample_directions, seen_weights};
pub use harmonic::{
    BASIS_SAMPLE, FitScope, NO_VIEW_DEPENDENCE, PROBE_SAMPLE, REFLECT_LATTICE_MIN_BAND,
    REFLECT_LATTICE_STRIDE, ViewChoice, ViewFit, fit_view,
};
pub use reflection::{
    REFLECT_EXPONENTS, REFLECT_NORMAL_SEARCH_DEG, ReflectionFit, ReflectionTarget, fit_reflection,
    normal_candidates,
};
