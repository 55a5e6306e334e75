//! The lighting the next frames use: the environment map and its rotation, projected
//! onto the asset's bases (and filtered by a reflection asset's lobe) on the CPU, the PCA
//! rank and what the relight pass writes. Each change marks the relight due; the frame
//! (`frame.rs`) runs it.

use glam::DMat3;
use nelf_format::conventions::LatLong;
use nelf_render::{project_light, project_view_light};

use super::marks::RelightKind;
use super::{GpuRenderer, Lighting};
use crate::atlas::RelightView;
use crate::error::ViewerError;

impl GpuRenderer {
    /// Sets the environment map (any resolution, lat-long, world frame) and its rotation
    /// `world_from_env`, projecting it onto the asset's basis
    /// ([`nelf_render::project_light`]), a view-dependent asset's view basis
    /// ([`nelf_render::project_view_light`]) and filtering it by a reflection asset's lobe
    /// ([`nelf_render::ReflectionLobe::filter`]). Needs an asset. The relight pass runs
    /// before the next frame.
    pub fn set_lighting(&mut self, env: &LatLong, world_from_env: DMat3) -> Result<(), ViewerError> {
        let asset = self.asset.as_ref().ok_or(ViewerError::NoAsset)?;
        let (projected, filtered) = match &asset.reflection {
            Some(reflection) => {
                let (projected, filtered) =
                    reflection.project_and_filter(&asset.pca, asset.world_from_light, env, world_from_env)?;
                (projected, Some(filtered))
            }
            None => (
                project_light(&asset.pca, asset.world_from_light, env, world_from_env)?,
                None,
            ),
        };
        let view_projected = match &asset.view {
            Some(view) => Some(project_view_light(
                &view.model,
                asset.world_from_light,
                env,
                world_from_env,
            )?),
            None => None,
        };
        self.lighting = Some(Lighting {
            env: env.clone(),
            world_from_env,
            projected,
            view_projected,
            filtered,
        });
        self.relight_dirty = true;
        Ok(())
    }

    /// Turns the current environment map to `world_from_env` (re-projects it; no need to
    /// pass the map again).
    pub fn set_light_rotation(&mut self, world_from_env: DMat3) -> Result<(), ViewerError> {
        let lighting = self.lighting.take().ok_or(ViewerError::NoLighting)?;
        let result = self.set_lighting(&lighting.env, world_from_env);
        if result.is_err() {
            self.lighting = Some(lighting);
        }
        result
    }

    /// Uses only the first `rank` PCA components (`None`: all).
    pub fn set_rank(&mut self, rank: Option<usize>) {
        if self.rank != rank {
            self.rank = rank;
            self.relight_dirty = true;
        }
    }

    /// What the relight pass writes: radiance, or one component's contribution.
    pub fn set_relight_view(&mut self, view: RelightView) {
        if self.relight_view != view {
            self.relight_view = view;
            self.relight_dirty = true;
        }
    }

    /// Makes the next frame relight even if nothing changed (benchmarks).
    pub fn invalidate_lighting(&mut self) {
        self.relight_dirty = true;
    }

    /// How the last relight ran: every voxel, or only those the current camera reads
    /// (`None` before the first).
    pub fn last_relight(&self) -> Option<RelightKind> {
        self.last_relight
    }
}
