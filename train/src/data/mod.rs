//! Training data: NeLF triplets rendered by our path tracer, written once into a
//! dataset folder, resumable, with held-out identities and lightings.
//!
//! For every head (an identity under lighting A): the source views (view 0
//! frontal, the others within `±max_angle_deg`, distance range and field of view
//! drawn per head), a novel view under lighting A turned about +y by a random angle
//! (the paper's *self-rotation* mode, target 0), and a novel view under another
//! lighting B (*novel light*, target 1); masks, target depth and alpha; and points
//! around the head with ground-truth density and light transport for 3D
//! distillation.
//!
//! **Layout** (`nelf train data -o DIR`):
//!
//! * `DIR/data_config.json`: the [`DataConfig`]; `DIR/split.json`: training and
//!   validation ids, the HDRIs of each split, the seed ranges and every head's draw
//!   ([`HeadSpec`]).
//! * `DIR/envs/procedural_<seed>.exr`: the procedural environments drawn (128 × 64),
//!   which the heads' `synth_config.json` name as their lighting files.
//! * `DIR/heads/hNNNNN/`: a synthetic capture folder (`nelf_scene::synth`:
//!   `cameras.json`, `images/`, `masks/`, `colmap/`, `lighting/source.exr`,
//!   `lighting/target_00i.exr`, `targets/target_00i.exr` + `_mask.png`,
//!   `synth_config.json`), readable by `nelf_field::capture::load_capture_dir` and
//!   `nelf bake capture`; target 0 is self-rotation, target 1 novel light. Added:
//!   `targets/target_00i_depth.f32` (raw little-endian f32, row-major, the target
//!   camera's width × height: depth along the optical axis in metres, the mean over
//!   the pixel's covered sub-pixel rays, 0 for background), `distill.bin`
//!   ([`distill`]'s format) and `head.json` (the draw, target modes, timings).
//!   Alpha is the target's mask: the fraction of the pixel's 4 × 4 sub-pixel rays
//!   that hit the head, stored in 8 bits.
//!
//! **Frames and units.** Metres, our world frame (+y up, the head facing +z).
//! Every lighting file is the 8 × 16 radiance map in the world frame with its turn
//! about +y already applied (the tracer's light frame is the world frame), so the
//! `light` fields of [`TrainingSample`] and [`TargetView`] are world-frame maps.
//! Images are linear RGB composited over black.
//!
//! **Held-out split.** See [`DataConfig`]: validation heads (ids after the training
//! heads) use head and environment seeds from `[2^62, 2^63)` (training:
//! `[0, 2^62)`) and only the HDRIs of `val_envmaps`, which training heads never
//! use; the scanned head is a training identity only.
//!
//! **Writing.** Each head is rendered into `heads/.tmp-hNNNNN` and renamed when
//! complete; a rerun skips finished heads and refuses other settings.

pub mod config;
pub mod distill;
pub mod generate;
pub mod plan;
pub mod read;

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

pub use config::DataConfig;
pub use distill::Distill;
pub use generate::{GenerateReport, HeadRecord, HeadTimings, generate, generate_heads};
pub use plan::{EnvCatalogue, HeadSpec, Identity, LightSource, LightSpec, Split, SplitRecord, plan_head};
pub use read::{Dataset, TargetView, TrainingSample};

/// The dataset's settings file.
pub const CONFIG_FILE: &str = "data_config.json";
/// The split and every head's draw.
pub const SPLIT_FILE: &str = "split.json";
/// Folder of the heads.
pub const HEADS_DIR: &str = "heads";
/// A head's record inside its folder.
pub const HEAD_FILE: &str = "head.json";
/// A head's distillation points inside its folder.
pub const DISTILL_FILE: &str = "distill.bin";
/// Suffix of a target's depth map after the target's name, in `targets/`.
pub const DEPTH_SUFFIX: &str = "_depth.f32";

/// What a target view tests.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TargetMode {
    /// A novel view under the source lighting turned about +y.
    SelfRotation,
    /// A novel view under another lighting.
    NovelLight,
}

/// The modes of a head's targets, in target order.
pub const TARGET_MODES: [TargetMode; 2] = [TargetMode::SelfRotation, TargetMode::NovelLight];

/// Folder of head `id` in dataset `dir`.
pub fn head_dir(dir: &Path, id: u32) -> PathBuf {
    dir.join(HEADS_DIR).join(format!("h{id:05}"))
}
