//! What every head of a dataset is: its identity, lightings, cameras and tracer
//! streams ([`HeadSpec`]), drawn from the dataset seed and the head's id alone, so a
//! head can be rendered (or re-rendered after a crash) in any order.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;
use serde::{Deserialize, Serialize};

use super::config::DataConfig;
use crate::error::TrainError;

/// Procedural head and environment seeds of validation heads have this bit set;
/// training heads' seeds never do: the two ranges are `[0, 2^62)` and `[2^62, 2^63)`.
pub const VAL_SEED_BIT: u64 = 1 << 62;

/// Which part of the dataset a head belongs to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Split {
    /// A training head.
    Train,
    /// A validation head: held-out identity and lightings.
    Val,
}

/// Who is photographed.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Identity {
    /// A procedural head (`nelf_scene::head::procedural_head`): shape, skin tone and
    /// hair from the seed.
    Procedural {
        /// The head's seed.
        seed: u64,
    },
    /// The shared scanned head (`DataConfig::scan_mesh`).
    Scan,
}

/// Where a lighting comes from.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LightSource {
    /// A real HDRI of `DataConfig::envmaps_dir`, by file stem.
    Hdri {
        /// The file stem (`forest` for `forest.exr`).
        name: String,
    },
    /// A procedural environment (`nelf_scene::envgen::procedural_envmap`).
    Procedural {
        /// Its seed.
        seed: u64,
    },
}

/// A lighting: a map turned about +y.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LightSpec {
    /// The map.
    pub source: LightSource,
    /// Its turn about +y, degrees (a feature at azimuth φ moves to φ − angle;
    /// `nelf_scene::envmap::envmap_to_basis`).
    pub rotate_deg: f32,
}

/// Everything drawn for one head.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct HeadSpec {
    /// The head's id (its folder is `heads/h{id:05}`).
    pub id: u32,
    /// Training or validation.
    pub split: Split,
    /// Who is photographed.
    pub identity: Identity,
    /// Share of reflected energy in the glossy lobe (sheen).
    pub specular_weight: f32,
    /// Lighting A: the source views', and turned by `self_rotation_deg` more, the
    /// self-rotation target's.
    pub light_a: LightSpec,
    /// Lighting B: the novel-light target's.
    pub light_b: LightSpec,
    /// Extra turn of lighting A for the self-rotation target, degrees.
    pub self_rotation_deg: f32,
    /// Nearest camera distance of this head, metres.
    pub min_distance_m: f64,
    /// Farthest camera distance of this head, metres.
    pub max_distance_m: f64,
    /// Share of the frame height the bounding sphere fills.
    pub fill: f64,
    /// Seed of the camera placement.
    pub camera_seed: u64,
    /// Seed of the path tracer's streams (images and distillation points).
    pub trace_seed: u64,
    /// Seed of the distillation points' positions and view directions.
    pub distill_seed: u64,
}

impl HeadSpec {
    /// The self-rotation target's lighting: A turned by `self_rotation_deg` more.
    pub fn rotated_light_a(&self) -> LightSpec {
        LightSpec {
            source: self.light_a.source.clone(),
            rotate_deg: self.light_a.rotate_deg + self.self_rotation_deg,
        }
    }
}

/// The real HDRIs of a dataset, split into training and validation maps.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct EnvCatalogue {
    /// Training maps (file stems, sorted).
    pub train: Vec<String>,
    /// Validation maps (file stems, in `DataConfig::val_envmaps` order).
    pub val: Vec<String>,
    /// Every map's file (absolute).
    #[serde(skip)]
    pub files: BTreeMap<String, PathBuf>,
}

impl EnvCatalogue {
    /// Lists `config.envmaps_dir` (`*.exr`, `*.hdr`, any case). When HDRIs can be
    /// drawn (`hdri_share > 0`) the folder must exist, every `val_envmaps` name must
    /// be one of its maps, and each split that has heads must have a map.
    pub fn scan(config: &DataConfig) -> Result<Self, TrainError> {
        let mut files = BTreeMap::new();
        let dir = &config.envmaps_dir;
        if config.hdri_share > 0.0 {
            let absolute = std::path::absolute(dir).map_err(|e| TrainError::io(dir, e))?;
            let entries = std::fs::read_dir(&absolute).map_err(|e| TrainError::io(&absolute, e))?;
            for entry in entries {
                let path = entry.map_err(|e| TrainError::io(&absolute, e))?.path();
                let ext = path
                    .extension()
                    .and_then(|e| e.to_str())
                    .map(str::to_ascii_lowercase);
                if !matches!(ext.as_deref(), Some("exr" | "hdr")) || !path.is_file() {
                    continue;
                }
                let Some(stem) = path.file_stem().and_then(|s| s.to_str()) else {
                    continue;
                };
                if let Some(other) = files.insert(stem.to_owned(), path.clone()) {
                    return Err(TrainError::file(
                        &path,
                        format!("two maps named {stem:?} (also {})", other.display()),
                    ));
                }
            }
            for name in &config.val_envmaps {
                if !files.contains_key(name) {
                    return Err(TrainError::file(
                        &absolute,
                        format!(
                            "validation map {name:?} is not here (maps: {})",
                            files.keys().cloned().collect::<Vec<_>>().join(", ")
                        ),
                    ));
                }
            }
        }
        let val: Vec<String> = if files.is_empty() {
            Vec::new()
        } else {
            config.val_envmaps.clone()
        };
        let train: Vec<String> = files.keys().filter(|k| !val.contains(k)).cloned().collect();
        if config.hdri_share > 0.0 {
            if config.heads > 0 && train.is_empty() {
                return Err(TrainError::file(
                    dir,
                    "no map is left for training heads once the validation maps are held out",
                ));
            }
            if config.val_heads > 0 && val.is_empty() {
                return Err(TrainError::Settings(
                    "--val-envmaps is empty: validation heads need held-out HDRIs (or --hdri-share 0)".into(),
                ));
            }
        }
        Ok(Self { train, val, files })
    }

    /// The maps a split may draw.
    pub fn maps(&self, split: Split) -> &[String] {
        match split {
            Split::Train => &self.train,
            Split::Val => &self.val,
        }
    }
}

/// The generator of head `id`: a stream of its own, from the dataset seed.
fn head_rng(seed: u64, id: u32) -> Pcg64 {
    let key = nelf_scene::tracer::mix64(seed ^ nelf_scene::tracer::mix64(u64::from(id) + 0x7e57_da7a));
    Pcg64::seed_from_u64(key)
}

/// A seed in the split's range.
fn split_seed(rng: &mut Pcg64, split: Split) -> u64 {
    let low = rng.random::<u64>() >> 2;
    match split {
        Split::Train => low,
        Split::Val => VAL_SEED_BIT | low,
    }
}

fn draw_light(
    rng: &mut Pcg64,
    config: &DataConfig,
    envs: &EnvCatalogue,
    split: Split,
    not: Option<&LightSource>,
) -> LightSpec {
    let maps: Vec<&String> = envs
        .maps(split)
        .iter()
        .filter(|name| !matches!(not, Some(LightSource::Hdri { name: n }) if n == *name))
        .collect();
    let hdri = rng.random_bool(config.hdri_share);
    let proc_seed = split_seed(rng, split);
    let index = rng.random_range(0..maps.len().max(1));
    let rotate_deg = rng.random_range(0.0f32..360.0);
    let source = match maps.get(index) {
        Some(name) if hdri => LightSource::Hdri {
            name: (*name).clone(),
        },
        _ => LightSource::Procedural { seed: proc_seed },
    };
    LightSpec { source, rotate_deg }
}

/// Head `id`'s draw. Pure: the same configuration, catalogue and id give the same
/// head.
pub fn plan_head(config: &DataConfig, envs: &EnvCatalogue, id: u32) -> HeadSpec {
    let mut rng = head_rng(config.seed, id);
    let split = if config.is_val(id) {
        Split::Val
    } else {
        Split::Train
    };
    let head_seed = split_seed(&mut rng, split);
    let scan = split == Split::Train && config.scan_every > 0 && (id + 1) % config.scan_every == 0;
    let identity = if scan {
        Identity::Scan
    } else {
        Identity::Procedural { seed: head_seed }
    };
    let specular_weight = rng.random::<f32>() * config.specular_max;
    let light_a = draw_light(&mut rng, config, envs, split, None);
    let light_b = draw_light(&mut rng, config, envs, split, Some(&light_a.source));
    let lo = f64::from(config.rotation_min_deg.clamp(0.0, 180.0));
    let magnitude = lo + (180.0 - lo) * rng.random::<f64>();
    let self_rotation_deg = if rng.random_bool(0.5) {
        magnitude
    } else {
        -magnitude
    } as f32;
    let (dmin, dmax) = (config.distance_min_m, config.distance_max_m);
    let d0 = dmin + (dmax - dmin) * rng.random::<f64>();
    let d1 = dmin + (dmax - dmin) * rng.random::<f64>();
    let fill = config.fill_min + (config.fill_max - config.fill_min) * rng.random::<f64>();
    HeadSpec {
        id,
        split,
        identity,
        specular_weight,
        light_a,
        light_b,
        self_rotation_deg,
        min_distance_m: d0.min(d1),
        max_distance_m: d0.max(d1),
        fill,
        camera_seed: rng.random(),
        trace_seed: rng.random(),
        distill_seed: rng.random(),
    }
}

/// `split.json`: which heads are which, and every head's draw.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SplitRecord {
    /// Training head ids.
    pub train_ids: std::ops::Range<u32>,
    /// Validation head ids.
    pub val_ids: std::ops::Range<u32>,
    /// HDRIs lighting training heads.
    pub train_envmaps: Vec<String>,
    /// HDRIs lighting validation heads only.
    pub val_envmaps: Vec<String>,
    /// Range of training heads' procedural head and environment seeds.
    pub train_seed_range: [u64; 2],
    /// Range of validation heads' procedural head and environment seeds.
    pub val_seed_range: [u64; 2],
    /// Every head's draw, by id.
    pub heads: Vec<HeadSpec>,
}

impl SplitRecord {
    /// The record of a dataset.
    pub fn new(config: &DataConfig, envs: &EnvCatalogue) -> Self {
        Self {
            train_ids: 0..config.heads,
            val_ids: config.heads..config.total_heads(),
            train_envmaps: envs.train.clone(),
            val_envmaps: envs.val.clone(),
            train_seed_range: [0, VAL_SEED_BIT],
            val_seed_range: [VAL_SEED_BIT, 2 * VAL_SEED_BIT],
            heads: (0..config.total_heads())
                .map(|id| plan_head(config, envs, id))
                .collect(),
        }
    }
}

/// File of a procedural environment map inside a dataset folder.
pub fn procedural_env_file(dir: &Path, seed: u64) -> PathBuf {
    dir.join("envs").join(format!("procedural_{seed:016x}.exr"))
}
