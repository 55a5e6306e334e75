//! `nelf-render`: the CPU reference renderer of `.nelf` assets — the numerical
//! definition that the GPU shaders mirror, and the renderer the baker uses to choose a
//! PCA rank and to weight its fit by visibility. Depends only on `nelf-format`.
//!
//! **Model.** A `.nelf` asset is a density σ (1/m) and a light-transport vector `T`
//! (SPEC.md §8) on a sparse grid of 8³-voxel bricks. Under a distant environment map
//! `L` (8 × 16 texels in the asset's light frame, solid angles folded into `T`) a point
//! emits `radiance_c = Σ_j T[c·128 + j] · L[j][c]` (`docs/CONVENTIONS.md`). The image is the
//! emission–absorption volume rendering integral (Max 1995)
//!
//! `C = ∫ T(t) σ(t) c(t) dt`, `T(t) = exp(−∫₀ᵗ σ)`,
//!
//! discretised as `C = Σ_i T_i (1 − e^{−σ_i Δ}) c_i`, `T_i = Π_{j<i} e^{−σ_j Δ}`, with σ and
//! `c` interpolated trilinearly between voxel centres ([`grid`], [`march`]).
//!
//! **Relighting** is linear in `T` and `T = m + Σ_k c_k B_k`, so the lighting is projected
//! once onto the PCA mean and basis ([`project_light`]) and each voxel's radiance costs
//! `K` multiply-adds per channel ([`voxel_radiance`]) — exactly equal to shading the
//! reconstructed `T` ([`radiance_from_lt`] is that unquantized reference).
//!
//! Typical use: [`render_asset`]; or [`BrickGrid::from_asset`] + [`project_light`] +
//! [`voxel_radiance`] + [`render_volume`] to reuse pieces across frames, and
//! [`visibility_weights`] to know how much each voxel shows in a view.

pub mod error;
pub mod fine;
pub mod grid;
pub mod light;
pub mod march;
pub mod reflection;
pub mod view;
pub mod wgsl;

pub use error::RenderError;
pub use fine::FineGrid;
pub use grid::BrickGrid;
pub use light::{ProjectedLight, project_light, project_light_texels, radiance_from_lt, voxel_radiance};
pub use march::{
    Image, MAX_PIXEL_GRID, MarchSettings, MarchStats, asset_density, asset_radiance, asset_radiance_with,
    filtered_environment, filtered_environment_with, render_asset, render_asset_radiances, render_features,
    render_volume, render_volume_fine, render_volume_stats, render_volume_unskipped, visibility_weights,
};
pub use reflection::{FilteredEnvironment, ReflectionLobe, mirror, reflection_seen_from};
pub use view::{project_view_light, project_view_light_texels, radiance_seen_from, voxel_lobe_radiance};
