//! Reading a dataset back: [`Dataset`] and one head's [`TrainingSample`].

use std::path::{Path, PathBuf};

use glam::DVec3;
use nelf_format::capture::Capture;
use nelf_format::conventions::{ENV_H, ENV_W, LatLong, PinholeCamera, nearest_point_to_axes};

use super::config::DataConfig;
use super::distill::Distill;
use super::generate::HeadRecord;
use super::plan::HeadSpec;
use super::{CONFIG_FILE, DEPTH_SUFFIX, DISTILL_FILE, HEAD_FILE, TARGET_MODES, TargetMode, head_dir};
use crate::error::TrainError;

/// A dataset folder written by [`super::generate`].
#[derive(Debug, Clone)]
pub struct Dataset {
    /// The folder.
    pub dir: PathBuf,
    /// Its settings (`data_config.json`).
    pub config: DataConfig,
}

/// One target view of a head.
#[derive(Debug, Clone)]
pub struct TargetView {
    /// Self-rotation (lighting A turned) or novel light (lighting B).
    pub mode: TargetMode,
    /// The camera (metres, world frame).
    pub camera: PinholeCamera,
    /// Linear RGB radiance composited over black (multiplied by `alpha`), row-major.
    pub image: Vec<[f32; 3]>,
    /// Coverage in `[0, 1]`: the fraction of the pixel's 4 × 4 sub-pixel rays that hit
    /// the head (8-bit in the mask file).
    pub alpha: Vec<f32>,
    /// Depth along the optical axis, metres (mean over the sub-pixel rays that hit);
    /// 0 for background.
    pub depth_m: Vec<f32>,
    /// The lighting (8 × 16, world frame: the turn is already applied, i.e.
    /// `world_from_light` = identity).
    pub light: LatLong,
}

/// Everything the trainer needs of one head.
#[derive(Debug, Clone)]
pub struct TrainingSample {
    /// The head's id.
    pub id: u32,
    /// Source cameras (metres, world frame); view 0 is frontal.
    pub source_cameras: Vec<PinholeCamera>,
    /// Source images: linear RGB radiance composited over black (multiplied by the
    /// mask), row-major.
    pub source_images: Vec<Vec<[f32; 3]>>,
    /// Source masks (coverage) in `[0, 1]`.
    pub source_masks: Vec<Vec<f32>>,
    /// Centre of the head (where every camera looks), metres.
    pub head_centre_m: DVec3,
    /// Lighting A of the source views (8 × 16, world frame, turn applied).
    pub source_light: LatLong,
    /// `[self-rotation, novel-light]`.
    pub targets: Vec<TargetView>,
    /// Ground-truth density and light transport at points around the head.
    pub distill: Distill,
    /// The head's draw (identity, lightings and their turns, seeds).
    pub spec: HeadSpec,
    /// The head's folder (a capture folder `nelf bake capture` reads).
    pub dir: PathBuf,
}

fn read_json<T: serde::de::DeserializeOwned>(path: &Path) -> Result<T, TrainError> {
    let text = std::fs::read_to_string(path).map_err(|e| TrainError::io(path, e))?;
    serde_json::from_str(&text).map_err(|e| TrainError::file(path, format!("damaged: {e}")))
}

/// The image in `path`, its format guessed from its content; errors name the file.
pub(crate) fn decode(path: &Path) -> Result<image::DynamicImage, TrainError> {
    image::ImageReader::open(path)
        .map_err(|e| TrainError::io(path, e))?
        .with_guessed_format()
        .map_err(|e| TrainError::io(path, e))?
        .decode()
        .map_err(|e| TrainError::file(path, e.to_string()))
}

fn check_size(path: &Path, image: &image::DynamicImage, camera: &PinholeCamera) -> Result<(), TrainError> {
    if (image.width(), image.height()) == (camera.width, camera.height) {
        Ok(())
    } else {
        Err(TrainError::file(
            path,
            format!(
                "{}×{} image for a {}×{} camera",
                image.width(),
                image.height(),
                camera.width,
                camera.height
            ),
        ))
    }
}

fn finite_or_zero(v: f32) -> f32 {
    if v.is_finite() { v } else { 0.0 }
}

/// A linear RGB EXR of the camera's size.
fn read_rgb(path: &Path, camera: &PinholeCamera) -> Result<Vec<[f32; 3]>, TrainError> {
    let image = decode(path)?;
    check_size(path, &image, camera)?;
    Ok(image
        .into_rgb32f()
        .pixels()
        .map(|p| p.0.map(finite_or_zero))
        .collect())
}

/// A mask (grey values in `[0, 1]`) of the camera's size.
fn read_mask(path: &Path, camera: &PinholeCamera) -> Result<Vec<f32>, TrainError> {
    let image = decode(path)?;
    check_size(path, &image, camera)?;
    Ok(image
        .to_luma32f()
        .pixels()
        .map(|p| finite_or_zero(p.0[0]).clamp(0.0, 1.0))
        .collect())
}

/// An 8 × 16 lighting file.
fn read_light(path: &Path) -> Result<LatLong, TrainError> {
    let light = nelf_scene::envmap::load_envmap(path).map_err(|e| TrainError::file(path, e.to_string()))?;
    if (light.width(), light.height()) != (ENV_W, ENV_H) {
        return Err(TrainError::file(
            path,
            format!(
                "a {}×{} map, expected the {ENV_W}×{ENV_H} basis",
                light.width(),
                light.height()
            ),
        ));
    }
    Ok(light)
}

/// A raw little-endian f32 depth map of the camera's size.
fn read_depth(path: &Path, camera: &PinholeCamera) -> Result<Vec<f32>, TrainError> {
    let bytes = std::fs::read(path).map_err(|e| TrainError::io(path, e))?;
    let pixels = camera.width as usize * camera.height as usize;
    if bytes.len() != 4 * pixels {
        return Err(TrainError::file(
            path,
            format!(
                "{} bytes, expected {} for a {}×{} f32 depth map",
                bytes.len(),
                4 * pixels,
                camera.width,
                camera.height
            ),
        ));
    }
    let depth: Vec<f32> = bytes
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect();
    if depth.iter().any(|d| !d.is_finite() || *d < 0.0) {
        return Err(TrainError::file(path, "depths must be finite and ≥ 0"));
    }
    Ok(depth)
}

impl Dataset {
    /// Opens a dataset folder: reads and checks `data_config.json`.
    pub fn open(dir: &Path) -> Result<Self, TrainError> {
        let path = dir.join(CONFIG_FILE);
        let config: DataConfig = read_json(&path)?;
        config
            .validate()
            .map_err(|e| TrainError::file(&path, format!("damaged: {e}")))?;
        Ok(Self {
            dir: dir.to_path_buf(),
            config,
        })
    }

    /// The folder of head `id`.
    pub fn head_dir(&self, id: u32) -> PathBuf {
        head_dir(&self.dir, id)
    }

    fn finished(&self, ids: std::ops::Range<u32>) -> Vec<u32> {
        ids.filter(|&id| self.head_dir(id).is_dir()).collect()
    }

    /// Finished training heads, ascending.
    pub fn train_ids(&self) -> Vec<u32> {
        self.finished(0..self.config.heads)
    }

    /// Finished validation heads, ascending.
    pub fn val_ids(&self) -> Vec<u32> {
        self.finished(self.config.heads..self.config.total_heads())
    }

    /// Loads head `id`: images, masks, lightings, depth maps and distillation points.
    pub fn load(&self, id: u32) -> Result<TrainingSample, TrainError> {
        let dir = self.head_dir(id);
        if id >= self.config.total_heads() || !dir.is_dir() {
            return Err(TrainError::MissingHead { dir, id });
        }
        let record: HeadRecord = read_json(&dir.join(HEAD_FILE))?;
        if record.spec.id != id {
            return Err(TrainError::file(
                dir.join(HEAD_FILE),
                format!("describes head {}, not {id}", record.spec.id),
            ));
        }
        let capture = Capture::load(&dir)?;
        let mut source_images = Vec::with_capacity(capture.views.len());
        let mut source_masks = Vec::with_capacity(capture.views.len());
        for view in &capture.views {
            source_images.push(read_rgb(&view.image_path(&dir), &view.camera)?);
            let mask = view.mask_path(&dir).ok_or_else(|| {
                TrainError::file(
                    dir.join("cameras.json"),
                    format!("view {} has no mask", view.name),
                )
            })?;
            source_masks.push(read_mask(&mask, &view.camera)?);
        }
        let source_light = read_light(
            &capture
                .envmap_path(&dir)
                .ok_or_else(|| TrainError::file(dir.join("cameras.json"), "no source lighting"))?,
        )?;
        if capture.targets.len() != TARGET_MODES.len() {
            return Err(TrainError::file(
                dir.join("cameras.json"),
                format!(
                    "{} targets, expected {}",
                    capture.targets.len(),
                    TARGET_MODES.len()
                ),
            ));
        }
        let mut targets = Vec::with_capacity(capture.targets.len());
        for (target, mode) in capture.targets.iter().zip(TARGET_MODES) {
            let mask = target.mask_path(&dir).ok_or_else(|| {
                TrainError::file(
                    dir.join("cameras.json"),
                    format!("target {} has no mask", target.name),
                )
            })?;
            targets.push(TargetView {
                mode,
                camera: target.camera,
                image: read_rgb(&target.image_path(&dir), &target.camera)?,
                alpha: read_mask(&mask, &target.camera)?,
                depth_m: read_depth(
                    &dir.join(format!("targets/{}{DEPTH_SUFFIX}", target.name)),
                    &target.camera,
                )?,
                light: read_light(&target.envmap_path(&dir))?,
            });
        }
        let source_cameras = capture.cameras();
        let head_centre_m = capture
            .metadata
            .get("head_centre_m")
            .and_then(|v| serde_json::from_value::<[f64; 3]>(v.clone()).ok())
            .map(DVec3::from_array)
            .filter(|c| c.is_finite())
            .or_else(|| nearest_point_to_axes(&source_cameras))
            .ok_or_else(|| TrainError::file(dir.join("cameras.json"), "no head centre"))?;
        let distill = Distill::read(&dir.join(DISTILL_FILE))?;
        Ok(TrainingSample {
            id,
            source_cameras,
            source_images,
            source_masks,
            head_centre_m,
            source_light,
            targets,
            distill,
            spec: record.spec,
            dir,
        })
    }
}
