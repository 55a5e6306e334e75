//! Asset upload: a validated asset becomes GPU resources (coefficients, densities,
//! neighbour blocks, the march grid and the atlas the relight pass fills; a fine
//! density's atlas (format 1.4); a
//! view-dependent asset's view part, a reflection asset's reflection part, the marks and
//! the replay's inputs), checked against the device's limits first; and what is known of
//! the loaded asset.

use nelf_format::conventions::LT_DIM;
use nelf_format::{Asset, FineDensity};
use wgpu::util::DeviceExt as _;

use super::marks::GpuMarks;
use super::reflect::{GpuReflection, REFLECT_LOBE_WORDS, ReflectPipeline};
use super::replay::ReplayInputs;
use super::view::{GpuView, LobesPipeline, ViewBindings, ViewPipeline, lobe_buffer_words};
use super::{
    AssetInfo, AtlasState, CpuRelight, GpuAsset, GpuFineDensity, GpuRenderer, ReflectionInfo, ViewInfo,
};
use crate::atlas::{
    AtlasLayout, Dequantization, GpuMemory, Indirection, atlas_sources, fine_density_atlas,
    fine_density_per_voxel, fine_slot_texels, indirection_grid, march_grid, neighbour_blocks,
    pack_brick_cells, pack_coefficients, pack_density,
};
use crate::error::ViewerError;
use crate::shaders::RelightParams;

impl GpuRenderer {
    /// The loaded asset's description.
    pub fn asset_info(&self) -> Option<AssetInfo> {
        self.asset.as_ref().map(|a| a.info)
    }

    /// Reads a `.nelf` file (fully validated by the reader) and uploads it; a missing,
    /// damaged or hostile file is an error and leaves the previous asset in place.
    pub fn load_asset_file(&mut self, path: &std::path::Path) -> Result<AssetInfo, ViewerError> {
        let asset = nelf_format::read_asset(path)?;
        self.load_asset(&asset)
    }

    /// Uploads `asset` (validated first; an invalid one is an error and leaves the
    /// previous asset in place): coefficients, densities, brick list, indirection grid,
    /// and an atlas the relight pass fills; for a view-dependent asset also its view
    /// coefficients and a per-voxel lobe buffer (`gpu/view.rs`), for a reflection asset its
    /// tabulated lobe, codes and lobe buffer (`gpu/reflect.rs`), for an asset with a fine
    /// density (format 1.4) its atlas, from which the march takes σ
    /// ([`AssetInfo::fine_density_ignored`] says where it did not fit). Lighting, if set, is
    /// re-projected onto the new basis. A device without compute shaders (WebGL2) leaves
    /// the view-dependent part out and shows the view-averaged asset
    /// ([`AssetInfo::view_part_ignored`] names what it left out).
    pub fn load_asset(&mut self, asset: &Asset) -> Result<AssetInfo, ViewerError> {
        asset.validate()?;
        // Without compute (WebGL2) the view-dependent parts cannot be shaded; the PCA part
        // alone is the view-averaged asset every reader can show (SPEC.md §6), so the
        // renderer shows that and says what it left out.
        let compute = self.storage();
        let view_part = asset.view.as_ref().filter(|_| compute);
        let reflection_part = asset.reflection.as_ref().filter(|_| compute);
        let view_part_ignored = match (&asset.view, &asset.reflection) {
            _ if compute => None,
            (Some(_), _) => Some("view-dependent part (format 1.2)"),
            (None, Some(_)) => Some("reflection part (format 1.3)"),
            (None, None) => None,
        };
        let limits = self.device.limits();
        let grid_bricks = asset.grid.grid_bricks;
        if grid_bricks.iter().any(|&n| n > limits.max_texture_dimension_3d) {
            return Err(ViewerError::TooLarge(format!(
                "grid of {grid_bricks:?} bricks exceeds 3D textures of {} texels",
                limits.max_texture_dimension_3d
            )));
        }
        let indirection = indirection_grid(grid_bricks, &asset.bricks)?;
        // A fine density (format 1.4) gets an atlas of its own at the same slot placement,
        // its slots larger: where that does not fit the device's 3D textures, the renderer
        // shows the voxels' density (what a reader without the section shows) and says so.
        let slots = indirection.slot_cells.len();
        let max_3d = limits.max_texture_dimension_3d;
        let (layout, fine_part, fine_density_ignored) = match &asset.fine_density {
            Some(fine) => match AtlasLayout::for_slot_edge(slots, max_3d, fine_slot_texels(fine.factor)) {
                Ok(layout) => (layout, Some(fine), None),
                Err(_) => (AtlasLayout::for_bricks(slots, max_3d)?, None, Some(fine.factor)),
            },
            None => (AtlasLayout::for_bricks(slots, max_3d)?, None, None),
        };
        // With a fine density the march grid skips what is empty of it.
        let fine_per_voxel = fine_part
            .map(|fine| fine_density_per_voxel(fine, asset.bricks.len()))
            .transpose()?;
        let march_grid = march_grid(
            grid_bricks,
            &indirection,
            &asset.bricks,
            fine_per_voxel.as_deref().unwrap_or(&asset.density),
            max_3d,
        )?;
        let fine =
            self.upload_fine_density(&layout, &indirection, grid_bricks, asset.bricks.len(), fine_part)?;
        let coefficients = pack_coefficients(&asset.coefficients);
        let density = pack_density(&asset.density);
        let neighbours = neighbour_blocks(&indirection, grid_bricks, &asset.bricks);
        let view_coefficients = view_part.map(|v| pack_coefficients(&v.coefficients));
        let max_binding = limits.max_storage_buffer_binding_size.min(limits.max_buffer_size);
        let voxel_count = asset.voxel_count();
        let lobe_words = match (view_part, reflection_part) {
            (Some(v), _) => lobe_buffer_words(v.lobe_count()),
            (None, Some(_)) => REFLECT_LOBE_WORDS,
            (None, None) => 0,
        };
        let lobe_bytes = (voxel_count * lobe_words) as u64 * 4;
        for (what, bytes) in [
            ("coefficients", coefficients.words.len() as u64 * 4),
            ("densities", density.len() as u64 * 4),
            ("neighbour blocks", neighbours.len() as u64 * 32),
            (
                "view coefficients",
                view_coefficients.as_ref().map_or(0, |p| p.words.len() as u64 * 4),
            ),
            ("per-voxel view lobes", lobe_bytes),
            (
                "reflection codes",
                reflection_part.map_or(0, |_| voxel_count as u64 * 4),
            ),
        ] {
            // Without storage bindings these stay on the CPU.
            if self.storage() && bytes > max_binding {
                return Err(ViewerError::TooLarge(format!(
                    "{what} take {bytes} bytes, the device binds at most {max_binding}"
                )));
            }
        }
        let storage = |label: &str, data: &[u8]| {
            // Storage bindings must not be empty.
            let padded;
            let contents = if data.is_empty() {
                padded = [0u8; 16];
                &padded[..]
            } else {
                data
            };
            self.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents,
                usage: wgpu::BufferUsages::STORAGE,
            })
        };
        // Without storage bindings (WebGL2) the relight reads these on the CPU.
        let has_storage = self.storage();
        let storage = |label: &str, data: &[u8]| {
            if has_storage {
                storage(label, data)
            } else {
                self.device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some(label),
                    size: 16,
                    usage: wgpu::BufferUsages::COPY_DST,
                    mapped_at_creation: false,
                })
            }
        };
        let coefficient_buffer = storage("coefficients", bytemuck::cast_slice(&coefficients.words));
        let density_buffer = storage("density", bytemuck::cast_slice(&density));
        let neighbour_buffer = storage("neighbour blocks", bytemuck::cast_slice(&neighbours));
        let rank = asset.rank();
        let light = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("light"),
            size: (LT_DIM * 16) as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let relight_params = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("relight params"),
            size: size_of::<RelightParams>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let march_grid_texture = self.device.create_texture_with_data(
            &self.queue,
            &wgpu::TextureDescriptor {
                label: Some("march grid"),
                size: wgpu::Extent3d {
                    width: march_grid.dims[0],
                    height: march_grid.dims[1],
                    depth_or_array_layers: march_grid.dims[2],
                },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D3,
                format: wgpu::TextureFormat::R32Uint,
                usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
                view_formats: &[],
            },
            wgpu::util::TextureDataOrder::LayerMajor,
            bytemuck::cast_slice(&march_grid.texels),
        );
        let texels = layout.texels();
        let atlas = self.device.create_texture(&wgpu::TextureDescriptor {
            label: Some("atlas"),
            size: wgpu::Extent3d {
                width: texels[0],
                height: texels[1],
                depth_or_array_layers: texels[2],
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D3,
            format: wgpu::TextureFormat::Rgba16Float,
            // Written by the relight pass, or by an upload of the CPU relight.
            usage: self.storage_texture_usage()
                | wgpu::TextureUsages::COPY_DST
                | wgpu::TextureUsages::TEXTURE_BINDING
                | wgpu::TextureUsages::COPY_SRC,
            view_formats: &[],
        });
        let atlas_view = atlas.create_view(&wgpu::TextureViewDescriptor::default());
        let march_grid_view = march_grid_texture.create_view(&wgpu::TextureViewDescriptor::default());
        let relight_bind_group = self.pipelines.relight.as_ref().map(|relight| {
            relight.bind_group(
                &self.device,
                [
                    &relight_params,
                    &light,
                    &coefficient_buffer,
                    &density_buffer,
                    &neighbour_buffer,
                ],
                &atlas_view,
            )
        });
        // Read by the view pass and the marked relight's listing.
        let brick_cells = storage(
            "brick cells",
            bytemuck::cast_slice(&pack_brick_cells(&asset.bricks)),
        );
        let view_bindings = ViewBindings {
            relight: [&relight_params, &light, &coefficient_buffer, &density_buffer],
            neighbour_blocks: &neighbour_buffer,
            atlas: &atlas_view,
        };
        if (view_part.is_some() || reflection_part.is_some()) && self.pipelines.lobes.is_none() {
            self.pipelines.lobes = Some(LobesPipeline::new(&self.device)?);
        }
        let view = match (view_part, &view_coefficients) {
            (Some(v), Some(packed)) => {
                if self.pipelines.view.is_none() {
                    self.pipelines.view = Some(ViewPipeline::new(&self.device)?);
                }
                let lobes = self.pipelines.lobes.as_ref().ok_or(ViewerError::NoAsset)?;
                let pipeline = self.pipelines.view.as_ref().ok_or(ViewerError::NoAsset)?;
                let mut view =
                    GpuView::upload(&self.device, v, packed, brick_cells.clone(), voxel_count, storage);
                view.bind(&self.device, lobes, pipeline, &view_bindings);
                Some(view)
            }
            _ => None,
        };
        let reflection = match reflection_part {
            Some(r) => {
                if self.pipelines.reflect.is_none() {
                    self.pipelines.reflect = Some(ReflectPipeline::new(&self.device)?);
                }
                let lobes = self.pipelines.lobes.as_ref().ok_or(ViewerError::NoAsset)?;
                let pipeline = self.pipelines.reflect.as_ref().ok_or(ViewerError::NoAsset)?;
                let mut reflection =
                    GpuReflection::upload(&self.device, asset, r, &layout, brick_cells.clone(), storage)?;
                reflection.bind(&self.device, lobes, pipeline, &view_bindings);
                Some(reflection)
            }
            None => None,
        };
        let marks =
            self.pipelines.marks.as_ref().map(|pipelines| {
                GpuMarks::new(&self.device, pipelines, grid_bricks, voxel_count, &brick_cells)
            });
        let memory = GpuMemory {
            atlas_bytes: u64::from(texels[0]) * u64::from(texels[1]) * u64::from(texels[2]) * 8,
            fine_density_bytes: if fine.factor > 0 {
                fine.texels.iter().map(|&n| u64::from(n)).product::<u64>() * 2
            } else {
                0
            },
            coefficient_bytes: coefficient_buffer.size(),
            density_bytes: density_buffer.size(),
            march_grid_bytes: march_grid.texels.len() as u64 * 4,
            neighbour_bytes: neighbour_buffer.size(),
            view_bytes: view.as_ref().map_or(0, GpuView::bytes)
                + reflection.as_ref().map_or(0, GpuReflection::bytes),
            other_bytes: light.size()
                + relight_params.size()
                + brick_cells.size()
                + marks.as_ref().map_or(0, GpuMarks::bytes),
        };
        let max_density_per_m = fine_part
            .map_or(&asset.density, |f| &f.values)
            .iter()
            .map(|d| d.to_f32())
            .fold(0.0f32, f32::max);
        let info = AssetInfo {
            bricks: asset.bricks.len(),
            halo_slots: indirection.halo_count(asset.bricks.len()),
            rank,
            atlas_texels: texels,
            memory,
            max_density_per_m,
            view: view_part.map(|v| ViewInfo {
                lobes: v.lobe_count(),
                rank: v.rank(),
                encoding: v.coefficients.encoding(),
            }),
            reflection: reflection_part.map(|r| ReflectionInfo {
                exponent: r.exponent,
                eyes: r.eyes_m.len(),
            }),
            view_part_ignored,
            fine_density: fine_part.map(|f| f.factor),
            fine_density_ignored,
        };
        let dequantization = Dequantization::of(&asset.coefficients);
        let replay = self.pipelines.replay.is_some().then(|| ReplayInputs {
            coefficients: coefficient_buffer.clone(),
            dequantization: storage(
                "replay dequantization",
                bytemuck::cast_slice(&dequantization.offset_scale()),
            ),
        });
        self.asset = Some(GpuAsset {
            layout,
            grid: asset.grid,
            pca: asset.pca.clone(),
            world_from_light: asset.world_from_light,
            dequantization,
            coefficient_words_per_voxel: coefficients.words_per_voxel,
            coefficient_encoding: coefficients.encoding,
            atlas,
            atlas_view,
            fine,
            march_grid_view,
            march_grid_factor: march_grid.factor,
            relight_params,
            light,
            relight_bind_group,
            marks,
            replay,
            cpu_relight: (!self.storage()).then(|| CpuRelight {
                sources: atlas_sources(&layout, &indirection, grid_bricks, asset.bricks.len()),
                coefficients,
                density: asset.density.clone(),
            }),
            view,
            reflection,
            voxel_count,
            info,
        });
        // Bind groups of the old atlas are stale.
        self.target = None;
        self.relight_dirty = true;
        self.marks_key = None;
        self.last_mark_key = None;
        self.replay = None;
        self.atlas_state = AtlasState::Unlit;
        self.view_eye = None;
        self.last_eye = None;
        if let Some(lighting) = self.lighting.take() {
            self.set_lighting(&lighting.env, lighting.world_from_env)?;
        }
        Ok(info)
    }

    /// The fine density atlas of `fine` (`atlas::fine_density_atlas`, at the slot placement
    /// `layout`) as an R16F 3D texture, or a 1-texel placeholder where there is none.
    fn upload_fine_density(
        &self,
        layout: &AtlasLayout,
        indirection: &Indirection,
        grid_bricks: [u32; 3],
        bricks: usize,
        fine: Option<&FineDensity>,
    ) -> Result<GpuFineDensity, ViewerError> {
        let (factor, texels, data) = match fine {
            Some(fine) => (
                fine.factor,
                layout.texels_for_slot_edge(fine_slot_texels(fine.factor)),
                fine_density_atlas(layout, indirection, grid_bricks, bricks, fine)?,
            ),
            None => (0, [1, 1, 1], vec![0u16]),
        };
        let texture = self.device.create_texture_with_data(
            &self.queue,
            &wgpu::TextureDescriptor {
                label: Some("fine density"),
                size: wgpu::Extent3d {
                    width: texels[0],
                    height: texels[1],
                    depth_or_array_layers: texels[2],
                },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D3,
                format: wgpu::TextureFormat::R16Float,
                usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
                view_formats: &[],
            },
            wgpu::util::TextureDataOrder::LayerMajor,
            bytemuck::cast_slice(&data),
        );
        Ok(GpuFineDensity {
            factor,
            texels,
            view: texture.create_view(&wgpu::TextureViewDescriptor::default()),
        })
    }

    /// Edge length of one voxel of the loaded asset, metres.
    pub fn voxel_size_m(&self) -> Option<f64> {
        self.asset.as_ref().map(|a| a.grid.voxel_size_m)
    }

    /// The loaded asset's grid box `(min, max)` in metres.
    pub fn bounds_m(&self) -> Option<([f64; 3], [f64; 3])> {
        self.asset
            .as_ref()
            .map(|a| (a.grid.bbox_min_m, a.grid.bbox_max_m()))
    }
}
