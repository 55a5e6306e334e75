//! Relighting only what the view reads: the marked-voxel relight.
//!
//! Radiance is relit per stored voxel (`relight.rs`), but a frame reads few of them: the
//! march takes its σ > 0 samples at the skin, and their trilinear corners are about 7 % of
//! a head's voxels (41k of 597k for the shared scan at 512²). Which voxels a march reads
//! depends on the camera, the march settings and σ, never on the lighting. So the first
//! lighting change at a camera held since the previous frame relights in full and marches
//! with `MARK_VOXELS` (`march.wgsl`), which sets one bit per stored voxel among the corners
//! of each σ > 0 sample and lists each such voxel once; the next lighting changes at that
//! camera relight the listed voxels only (`relight_marked`, an indirect dispatch sized on
//! the GPU by `relight_marked_args`), and each frame is the same as after a full relight.
//! The other voxels keep the old lighting (the atlas is *stale*) until a frame needs them:
//! the next frame whose camera differs from the marked one relights everything first.
//! Marking costs more than a march (8 scattered stores per σ > 0 sample), so it happens
//! only when the lighting is being changed at a held camera, never while orbiting; and
//! only on grids of at most [`MAX_MARKED_GRID_VOXELS`] voxels (the marks take 4 bytes a
//! voxel of the grid box).
//!
//! Jittered frames qualify when the seed stays (the app draws one jitter pattern per
//! camera); not debug views or view-dependent assets (their view or reflect pass rewrites
//! the atlas): those always relight in full.

use super::common::{compute_pipeline, shader_module, storage_entry};
use super::view::voxel_dispatch;
use super::{GpuRenderer, MarchView, RelightPipeline, ViewSettings};
use crate::atlas::RelightView;
use crate::error::ViewerError;
use crate::shaders::{MarchParams, RELIGHT_WGSL};

/// Largest grid box (voxels) whose voxels the march marks: 2²⁴ (64 MiB of marks).
pub const MAX_MARKED_GRID_VOXELS: u64 = 1 << 24;

/// How the last relight ran (tests and benchmarks).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RelightKind {
    /// Every stored voxel.
    Full,
    /// The voxels the marking march listed for the current camera.
    Marked,
    /// No voxel: the held camera's pixels from its per-pixel cache (`replay.rs`), without
    /// a march.
    Replay,
}

/// The marked relight's pipelines and the layout of its groups 1 (the list) and 2 (the
/// indirect dispatch, written by `relight_marked_args`), created once per device.
pub(super) struct MarkPipelines {
    layout: wgpu::BindGroupLayout,
    dispatch_layout: wgpu::BindGroupLayout,
    list: wgpu::ComputePipeline,
    args: wgpu::ComputePipeline,
    relight: wgpu::ComputePipeline,
}

impl MarkPipelines {
    pub(super) fn new(device: &wgpu::Device, relight: &RelightPipeline) -> Result<Self, ViewerError> {
        use wgpu::ShaderStages as S;
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("marked voxels"),
            entries: &[
                storage_entry(0, false, S::COMPUTE),
                storage_entry(1, true, S::COMPUTE),
                storage_entry(2, true, S::COMPUTE),
            ],
        });
        let dispatch_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("marked dispatch"),
            entries: &[storage_entry(0, false, S::COMPUTE)],
        });
        let module = shader_module(device, "relight.wgsl", RELIGHT_WGSL)?;
        let two = [relight.layout(), &layout];
        let list = compute_pipeline(device, &two, &module, "list_marked", &[]);
        let args = compute_pipeline(
            device,
            &[relight.layout(), &layout, &dispatch_layout],
            &module,
            "relight_marked_args",
            &[],
        );
        let relight = compute_pipeline(device, &two, &module, "relight_marked", &[]);
        Ok(Self {
            layout,
            dispatch_layout,
            list,
            args,
            relight,
        })
    }
}

/// An asset's marks: a word per voxel of the grid box (1 where a marking march read it),
/// the list of marked stored voxels (a count, then the indices) and the indirect dispatch
/// of the marked relight; its bind group also holds the asset's brick-cell buffer.
pub(super) struct GpuMarks {
    /// Whether the grid is small enough to mark ([`MAX_MARKED_GRID_VOXELS`]).
    pub(super) enabled: bool,
    pub(super) voxel_marks: wgpu::Buffer,
    list: wgpu::Buffer,
    dispatch: wgpu::Buffer,
    bind_group: wgpu::BindGroup,
    dispatch_bind_group: wgpu::BindGroup,
}

impl GpuMarks {
    /// The marks of an asset of `voxels` stored voxels on a grid of `grid_bricks`, with its
    /// brick-cell buffer (`crate::atlas::pack_brick_cells`).
    pub(super) fn new(
        device: &wgpu::Device,
        pipelines: &MarkPipelines,
        grid_bricks: [u32; 3],
        voxels: usize,
        brick_cells: &wgpu::Buffer,
    ) -> Self {
        let grid_voxels = grid_bricks.iter().map(|&n| u64::from(n) * 8).product::<u64>();
        let enabled = grid_voxels <= MAX_MARKED_GRID_VOXELS;
        let buffer = |label: &str, size: u64, usage: wgpu::BufferUsages| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: size.max(16),
                usage: wgpu::BufferUsages::STORAGE | usage,
                mapped_at_creation: false,
            })
        };
        let marked_words = if enabled { grid_voxels } else { 0 };
        let voxel_marks = buffer("voxel marks", marked_words * 4, wgpu::BufferUsages::COPY_DST);
        let stored = if enabled { voxels as u64 } else { 0 };
        let list = buffer("marked voxels", (stored + 1) * 4, wgpu::BufferUsages::COPY_DST);
        let dispatch = buffer("marked dispatch", 12, wgpu::BufferUsages::INDIRECT);
        let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("marked voxels"),
            layout: &pipelines.layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: list.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: voxel_marks.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 2,
                    resource: brick_cells.as_entire_binding(),
                },
            ],
        });
        let dispatch_bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("marked dispatch"),
            layout: &pipelines.dispatch_layout,
            entries: &[wgpu::BindGroupEntry {
                binding: 0,
                resource: dispatch.as_entire_binding(),
            }],
        });
        Self {
            enabled,
            voxel_marks,
            list,
            dispatch,
            bind_group,
            dispatch_bind_group,
        }
    }

    /// GPU memory of the marks.
    pub(super) fn bytes(&self) -> u64 {
        self.voxel_marks.size() + self.list.size() + self.dispatch.size()
    }

    /// Clears the marks before a marking march.
    pub(super) fn encode_clear(&self, encoder: &mut wgpu::CommandEncoder) {
        encoder.clear_buffer(&self.voxel_marks, 0, None);
    }
}

impl GpuRenderer {
    /// The key of the voxels a march of `params` reads, when the marked relight may serve
    /// it: a view-independent asset, shaded; `None` otherwise. The key holds the camera,
    /// the march settings and the jitter seed (a jittered frame with another seed reads
    /// other voxels).
    pub(super) fn mark_key(&self, params: &MarchParams, settings: &ViewSettings) -> Option<MarchParams> {
        let asset = self.asset.as_ref()?;
        let eligible = asset.marks.as_ref().is_some_and(|m| m.enabled)
            && asset.view.is_none()
            && asset.reflection.is_none()
            && settings.view == MarchView::Shaded
            && self.relight_view == RelightView::Shaded;
        eligible.then_some(*params)
    }

    /// Encodes the marked relight (the relight uniform and lighting already written):
    /// after a marking march the list of marked stored voxels and the dispatch size from
    /// its count (once per marking), then four listed voxels per invocation; separate
    /// passes, each reading what the one before wrote.
    pub(super) fn encode_marked_relight(
        &mut self,
        encoder: &mut wgpu::CommandEncoder,
    ) -> Result<(), ViewerError> {
        let asset = self.asset.as_ref().ok_or(ViewerError::NoAsset)?;
        let none = || ViewerError::NoCompute("the marked relight");
        let pipelines = self.pipelines.marks.as_ref().ok_or_else(none)?;
        let marks = asset.marks.as_ref().ok_or_else(none)?;
        let relight_bind_group = asset.relight_bind_group.as_ref().ok_or_else(none)?;
        let begin = |encoder: &mut wgpu::CommandEncoder, label: &str| {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some(label),
                timestamp_writes: None,
            });
            pass.set_bind_group(0, relight_bind_group, &[]);
            pass.set_bind_group(1, &marks.bind_group, &[]);
            pass.forget_lifetime()
        };
        // The list and its dispatch size change only with the marks.
        if !self.marks_listed {
            encoder.clear_buffer(&marks.list, 0, Some(4));
            let (groups, _) = voxel_dispatch(asset.voxel_count);
            {
                let mut pass = begin(encoder, "list marked voxels");
                pass.set_pipeline(&pipelines.list);
                pass.dispatch_workgroups(groups[0], groups[1], 1);
            }
            let mut pass = begin(encoder, "marked relight size");
            pass.set_bind_group(2, &marks.dispatch_bind_group, &[]);
            pass.set_pipeline(&pipelines.args);
            pass.dispatch_workgroups(1, 1, 1);
        }
        let mut pass = begin(encoder, "relight (marked voxels)");
        pass.set_pipeline(&pipelines.relight);
        pass.dispatch_workgroups_indirect(&marks.dispatch, 0);
        drop(pass);
        self.marks_listed = true;
        Ok(())
    }
}
