//! What `nelf eval` evaluates: a capture folder, a mesh, or a built-in procedural
//! head, turned into a capture with held-aside target views and the ground truth
//! behind it.
//!
//! * `head:SEED` (the default, `head:0`): the procedural head of `nelf demo`,
//!   photographed by the path tracer (`nelf_scene::synth`);
//! * a mesh file (`.obj`, `.off`): photographed the same way;
//! * a capture folder: used as it is; its ground truth is the mesh its
//!   `synth_config.json` names (a real capture has no ground truth to score against).
//!
//! A synthesized capture is written under the output folder once and reused when
//! its `synth_config.json` matches (runs resume).

use std::path::{Path, PathBuf};

use indicatif::ProgressBar;
use nelf_bake::GroundTruth;
use nelf_scene::synth::{SynthConfig, write_synthetic_capture};
use serde::{Deserialize, Serialize};

use crate::error::{EvalError, Result};

/// How a synthesized capture is photographed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CaptureSetup {
    /// Image side, pixels (source and target views).
    pub image_size: u32,
    /// Source views.
    pub views: usize,
    /// Largest angle of a source view from the frontal one, degrees.
    pub max_angle_deg: f64,
    /// Held-aside target views (each under its own lighting).
    pub targets: usize,
    /// Height a mesh file is scaled to, metres.
    pub mesh_height_m: f32,
    /// Turn a mesh file about +y by this many degrees so that it faces +z.
    pub mesh_rotate_y_deg: f32,
    /// Path-tracer samples per light texel of the images.
    pub texel_samples: u32,
    /// Indirect directions of the images.
    pub indirect_samples: u32,
    /// Interreflection bounces.
    pub bounces: u32,
    /// Seed of the camera placement.
    pub camera_seed: u64,
}

impl CaptureSetup {
    /// Full runs: 256² images, 5 views within 30°, 4 targets, the default tracer.
    pub fn full() -> Self {
        Self {
            image_size: 256,
            views: 5,
            max_angle_deg: 30.0,
            targets: 4,
            mesh_height_m: 0.23,
            mesh_rotate_y_deg: 0.0,
            texel_samples: 4,
            indirect_samples: 32,
            bounces: 1,
            camera_seed: 2,
        }
    }

    /// Quick runs: 64² images, 2 targets, one sample per texel, no bounce.
    pub fn quick() -> Self {
        Self {
            image_size: 64,
            targets: 2,
            texel_samples: 1,
            indirect_samples: 0,
            bounces: 0,
            ..Self::full()
        }
    }
}

/// The thing evaluated.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum EvalInput {
    /// A procedural head from this seed.
    Head(u64),
    /// A mesh file to photograph.
    Mesh(PathBuf),
    /// An existing capture folder.
    Capture(PathBuf),
}

impl EvalInput {
    /// Parses `head:SEED`, a mesh file or a capture folder; `None` is `head:0`.
    pub fn parse(spec: Option<&str>) -> Result<Self> {
        let Some(spec) = spec else {
            return Ok(Self::Head(0));
        };
        if let Some(seed) = spec.strip_prefix("head:") {
            return seed
                .parse()
                .map(Self::Head)
                .map_err(|_| EvalError::Input(format!("{spec:?}: expected head:SEED with an integer seed")));
        }
        let path = PathBuf::from(spec);
        if path.is_dir() {
            if !path.join("cameras.json").is_file() {
                return Err(EvalError::Input(format!(
                    "{}: a capture folder needs a cameras.json",
                    path.display()
                )));
            }
            return Ok(Self::Capture(path));
        }
        if path.is_file() {
            return Ok(Self::Mesh(path));
        }
        Err(EvalError::Input(format!(
            "{spec}: no such capture folder or mesh file (or use head:SEED)"
        )))
    }

    /// A short name for reports.
    pub fn name(&self) -> String {
        match self {
            Self::Head(seed) => format!("procedural head {seed}"),
            Self::Mesh(p) | Self::Capture(p) => p.display().to_string(),
        }
    }
}

/// A capture ready to bake and score.
#[derive(Debug, Clone)]
pub struct Prepared {
    /// The capture folder.
    pub capture_dir: PathBuf,
    /// Its ground truth.
    pub truth: GroundTruth,
    /// The synthetic capture's settings, when it was synthesized here.
    pub synth: Option<SynthConfig>,
}

/// The synthetic-capture settings of `input` under `setup` (`None` for a capture folder).
pub fn synth_config(input: &EvalInput, setup: &CaptureSetup) -> Option<SynthConfig> {
    let base = SynthConfig {
        width: setup.image_size,
        height: setup.image_size,
        views: setup.views,
        max_angle_deg: setup.max_angle_deg,
        targets: setup.targets,
        texel_samples: setup.texel_samples,
        indirect_samples: setup.indirect_samples,
        bounces: setup.bounces,
        camera_seed: setup.camera_seed,
        ..SynthConfig::default()
    };
    match input {
        EvalInput::Head(seed) => Some(SynthConfig {
            head_seed: *seed,
            head_cells: if setup.image_size <= 96 { 48 } else { 96 },
            ..base
        }),
        EvalInput::Mesh(path) => Some(SynthConfig {
            mesh: Some(path.clone()),
            mesh_height_m: setup.mesh_height_m,
            mesh_rotate_y_deg: setup.mesh_rotate_y_deg,
            ..base
        }),
        EvalInput::Capture(_) => None,
    }
}

/// Writes (or reuses) the synthetic capture `config` in `dir`.
pub fn synthesize(config: &SynthConfig, dir: &Path, progress: &ProgressBar) -> Result<()> {
    let existing = std::fs::read_to_string(dir.join("synth_config.json"))
        .ok()
        .and_then(|text| serde_json::from_str::<SynthConfig>(&text).ok());
    if existing.as_ref() == Some(config) && dir.join("cameras.json").is_file() {
        return Ok(());
    }
    // Written beside, then moved into place: a failure leaves an earlier capture intact.
    let mut partial = dir.as_os_str().to_owned();
    partial.push(".partial");
    let partial = PathBuf::from(partial);
    let io = |path: &Path, e: std::io::Error| EvalError::Io {
        path: path.to_path_buf(),
        message: e.to_string(),
    };
    if partial.exists() {
        std::fs::remove_dir_all(&partial).map_err(|e| io(&partial, e))?;
    }
    write_synthetic_capture(config, &partial, progress)?;
    if dir.exists() {
        std::fs::remove_dir_all(dir).map_err(|e| io(dir, e))?;
    }
    std::fs::rename(&partial, dir).map_err(|e| io(dir, e))?;
    Ok(())
}

/// Copies the files under `from` into `to` (made as needed), recursively, keeping
/// any file `to` already holds: a stability point's copy of the base capture, and
/// the parts of a sweep merged into one folder (`merge`).
pub fn copy_tree(from: &Path, to: &Path) -> Result<()> {
    let io = |path: &Path, e: std::io::Error| EvalError::Io {
        path: path.to_path_buf(),
        message: e.to_string(),
    };
    std::fs::create_dir_all(to).map_err(|e| io(to, e))?;
    for entry in std::fs::read_dir(from).map_err(|e| io(from, e))? {
        let path = entry.map_err(|e| io(from, e))?.path();
        let Some(name) = path.file_name() else { continue };
        let target = to.join(name);
        if path.is_dir() {
            copy_tree(&path, &target)?;
        } else if !target.exists() {
            std::fs::copy(&path, &target).map_err(|e| io(&target, e))?;
        }
    }
    Ok(())
}

/// Turns `input` into a capture with ground truth; synthesized captures go to
/// `work_dir/capture`.
pub fn prepare(
    input: &EvalInput,
    setup: &CaptureSetup,
    work_dir: &Path,
    progress: &ProgressBar,
) -> Result<Prepared> {
    let (capture_dir, synth) = if let EvalInput::Capture(dir) = input {
        (dir.clone(), None)
    } else {
        let dir = work_dir.join("capture");
        let config = synth_config(input, setup)
            .ok_or_else(|| EvalError::Input("no synthetic capture for a capture folder".into()))?;
        synthesize(&config, &dir, progress)?;
        (dir, Some(config))
    };
    let truth = GroundTruth::from_synth_capture(&capture_dir).map_err(|e| {
        EvalError::Input(format!(
            "{}: no ground truth to score against ({e}); nelf eval needs a synthetic capture (synth_config.json), a mesh or head:SEED",
            capture_dir.display()
        ))
    })?;
    Ok(Prepared {
        capture_dir,
        truth,
        synth,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn inputs_parse_or_say_why_not() {
        assert_eq!(EvalInput::parse(None).ok(), Some(EvalInput::Head(0)));
        assert_eq!(EvalInput::parse(Some("head:7")).ok(), Some(EvalInput::Head(7)));
        let bad = EvalInput::parse(Some("head:x")).err().map(|e| e.to_string());
        assert!(bad.is_some_and(|m| m.contains("head:SEED")));
        let missing = EvalInput::parse(Some("/no/such/thing"))
            .err()
            .map(|e| e.to_string());
        assert!(missing.is_some_and(|m| m.contains("/no/such/thing")));
    }
}
