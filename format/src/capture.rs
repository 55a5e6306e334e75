//! The capture folder (`format/CAPTURE.md`): a `cameras.json` file beside the images,
//! masks and optional lighting of one portrait capture.
//!
//! A capture is what a user brings (a few photographs, masks and camera poses) and
//! what the synthetic-capture writer produces. Cameras follow the project's OpenCV
//! pinhole convention ([`PinholeCamera`]: `x_cam = R·x_world + t`, pixel `(u, v)`
//! centred at `(u + 0.5, v + 0.5)`). The file may declare a length unit; every
//! translation is converted to metres at load, so the in-memory [`Capture`] is always
//! in metres and [`Capture::save`] always writes `"units": "m"`.
//!
//! Images are not decoded here (this crate has no image codecs): a capture holds
//! paths relative to its folder, checked to stay inside it and to exist.

use std::collections::HashSet;
use std::path::{Component, Path, PathBuf};

use glam::{DMat3, DVec3};
use serde::{Deserialize, Serialize};
use serde_json::Value;

use crate::conventions::PinholeCamera;
use crate::io_error::{FileIoError, IoResultExt};

/// Name of the capture description inside a capture folder.
pub const CAPTURE_FILE_NAME: &str = "cameras.json";
/// Value of the `"format"` field.
pub const CAPTURE_FORMAT: &str = "nelf-capture";
/// The only `"version"` this reader accepts and the one [`Capture::save`] writes.
pub const CAPTURE_VERSION: u64 = 1;
/// Largest accepted deviation of a rotation from orthonormality (`max |RᵀR − I|`,
/// `|det R − 1|`). Rotations within it are snapped to the nearest rotation at load.
pub const ROTATION_TOLERANCE: f64 = 1e-4;
/// Rotations closer than this to orthonormal are kept bit for bit (no snapping).
const ROTATION_EXACT: f64 = 1e-12;

/// File extensions accepted for view and target images.
pub const IMAGE_EXTENSIONS: &[&str] = &["exr", "png", "jpg", "jpeg"];
/// File extensions accepted for masks.
pub const MASK_EXTENSIONS: &[&str] = &["png", "exr"];
/// File extensions accepted for environment maps.
pub const ENVMAP_EXTENSIONS: &[&str] = &["exr", "hdr"];

/// Errors from loading, validating or saving a capture. Each names the
/// `cameras.json` file concerned and, where there is one, the view.
#[derive(Debug, thiserror::Error)]
pub enum CaptureError {
    /// Reading or writing a file failed.
    #[error(transparent)]
    Io(#[from] FileIoError),
    /// The file is not valid JSON or does not match the schema (the message has the line).
    #[error("{path}: {source}")]
    Json {
        /// The `cameras.json` file.
        path: PathBuf,
        /// The parser's error, with line and column.
        source: serde_json::Error,
    },
    /// The `"format"` field is missing or is not `"nelf-capture"`.
    #[error("{path}: \"format\" is {found}, expected \"{CAPTURE_FORMAT}\"")]
    WrongFormat {
        /// The `cameras.json` file.
        path: PathBuf,
        /// What the file holds (JSON text), or `missing`.
        found: String,
    },
    /// The `"version"` field is missing or not one this reader knows.
    #[error("{path}: \"version\" is {found}; this reader supports version {CAPTURE_VERSION}")]
    UnsupportedVersion {
        /// The `cameras.json` file.
        path: PathBuf,
        /// What the file holds (JSON text), or `missing`.
        found: String,
    },
    /// The `"units"` field is not `"m"`, `"cm"`, `"mm"` or `{"metres_per_unit": f}` with `f > 0`.
    #[error("{path}: \"units\" is {found}: {reason}")]
    BadUnits {
        /// The `cameras.json` file.
        path: PathBuf,
        /// The field's JSON text.
        found: String,
        /// What is wrong.
        reason: &'static str,
    },
    /// The capture has no views.
    #[error("{path}: the capture has no views (at least 1 is required)")]
    NoViews {
        /// The `cameras.json` file.
        path: PathBuf,
    },
    /// A view or target name is empty.
    #[error("{path}: {what} has an empty name")]
    EmptyName {
        /// The `cameras.json` file.
        path: PathBuf,
        /// Which entry (`view #3`, `target #0`).
        what: String,
    },
    /// Two views or targets share a name (names are unique across both lists).
    #[error("{path}: the name {name:?} is used by more than one view or target")]
    DuplicateName {
        /// The `cameras.json` file.
        path: PathBuf,
        /// The repeated name.
        name: String,
    },
    /// A file path is absolute, leaves the capture folder, or has an unsupported extension.
    #[error("{path}: {what} path {value:?} {reason}")]
    BadPath {
        /// The `cameras.json` file.
        path: PathBuf,
        /// Which field (`view "front" image`, `envmap`, …).
        what: String,
        /// The path as written.
        value: String,
        /// What is wrong.
        reason: String,
    },
    /// A referenced file does not exist.
    #[error("{path}: {what} file {file} does not exist")]
    MissingFile {
        /// The `cameras.json` file.
        path: PathBuf,
        /// Which field (`view "front" image`, `envmap`, …).
        what: String,
        /// The file looked for.
        file: PathBuf,
    },
    /// A camera number is NaN or infinite (after the unit conversion).
    #[error("{path}: {what}: {field} = {value} is not finite")]
    NonFinite {
        /// The `cameras.json` file.
        path: PathBuf,
        /// Which view or target (`view "front"`).
        what: String,
        /// Which number (`fx`, `translation[2]`, `rotation[1][0]`).
        field: String,
        /// Its value.
        value: f64,
    },
    /// A camera parameter is out of range (zero size, focal length ≤ 0).
    #[error("{path}: {what}: {reason}")]
    BadCamera {
        /// The `cameras.json` file.
        path: PathBuf,
        /// Which view or target.
        what: String,
        /// What is wrong.
        reason: String,
    },
    /// The world-to-camera rotation is not orthonormal with determinant +1 within
    /// [`ROTATION_TOLERANCE`].
    #[error(
        "{path}: {what}: world_to_camera.rotation is not a rotation: off by {deviation:.3e} \
         (max of |RᵀR − I| and |det R − 1|; tolerance {ROTATION_TOLERANCE:e})"
    )]
    NotARotation {
        /// The `cameras.json` file.
        path: PathBuf,
        /// Which view or target.
        what: String,
        /// `max(max |RᵀR − I|, |det R − 1|)`.
        deviation: f64,
    },
}

/// One input photograph: image, optional mask and camera (metres).
#[derive(Debug, Clone, PartialEq)]
pub struct CaptureView {
    /// Unique name (unique across views and targets).
    pub name: String,
    /// Image path relative to the capture folder, `/`-separated (EXR linear, or PNG/JPEG sRGB).
    pub image: String,
    /// Mask path relative to the capture folder; `None`: the image's alpha channel is the mask.
    pub mask: Option<String>,
    /// The camera, translation in metres.
    pub camera: PinholeCamera,
}

/// A held-aside evaluation view: a camera, the ground-truth image under a given lighting.
#[derive(Debug, Clone, PartialEq)]
pub struct TargetView {
    /// Unique name (unique across views and targets).
    pub name: String,
    /// Ground-truth image path relative to the capture folder.
    pub image: String,
    /// Optional mask path relative to the capture folder (else the image's alpha, if any).
    pub mask: Option<String>,
    /// Environment map the image was lit by, relative to the capture folder.
    pub envmap: String,
    /// The camera, translation in metres.
    pub camera: PinholeCamera,
}

/// A capture folder's description, in metres. See `format/CAPTURE.md`.
#[derive(Debug, Clone, PartialEq)]
pub struct Capture {
    /// The input views (at least one).
    pub views: Vec<CaptureView>,
    /// Ground-truth lighting of the input views, relative to the folder, if known.
    pub envmap: Option<String>,
    /// Held-aside evaluation views (may be empty).
    pub targets: Vec<TargetView>,
    /// Free-form JSON (provenance, generator settings); `Null` when absent.
    pub metadata: Value,
}

impl CaptureView {
    /// Absolute (or `dir`-relative) path of the image.
    pub fn image_path(&self, dir: &Path) -> PathBuf {
        dir.join(&self.image)
    }

    /// Path of the mask file, or `None` when the mask is the image's alpha.
    pub fn mask_path(&self, dir: &Path) -> Option<PathBuf> {
        self.mask.as_ref().map(|m| dir.join(m))
    }
}

impl TargetView {
    /// Path of the ground-truth image.
    pub fn image_path(&self, dir: &Path) -> PathBuf {
        dir.join(&self.image)
    }

    /// Path of the mask file, if any.
    pub fn mask_path(&self, dir: &Path) -> Option<PathBuf> {
        self.mask.as_ref().map(|m| dir.join(m))
    }

    /// Path of the environment map lighting this target.
    pub fn envmap_path(&self, dir: &Path) -> PathBuf {
        dir.join(&self.envmap)
    }
}

// ---------------------------------------------------------------------------
// JSON schema (version 1).

#[derive(Debug, Deserialize)]
struct HeaderJson {
    format: Option<Value>,
    version: Option<Value>,
}

#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct CaptureJson {
    format: String,
    version: u64,
    units: Value,
    views: Vec<ViewJson>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    envmap: Option<String>,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    targets: Vec<TargetJson>,
    #[serde(default, skip_serializing_if = "Value::is_null")]
    metadata: Value,
}

#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct ViewJson {
    name: String,
    image: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    mask: Option<String>,
    width: u32,
    height: u32,
    intrinsics: IntrinsicsJson,
    world_to_camera: ExtrinsicsJson,
}

#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct TargetJson {
    name: String,
    image: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    mask: Option<String>,
    envmap: String,
    width: u32,
    height: u32,
    intrinsics: IntrinsicsJson,
    world_to_camera: ExtrinsicsJson,
}

#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct IntrinsicsJson {
    fx: f64,
    fy: f64,
    cx: f64,
    cy: f64,
}

#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct ExtrinsicsJson {
    /// Row-major `R`.
    rotation: [[f64; 3]; 3],
    translation: [f64; 3],
}

/// How file lengths convert to metres.
#[derive(Debug, Clone, Copy)]
enum Units {
    /// Divide by this exact integer (1, 100, 1000): correctly rounded.
    PerMetre(f64),
    /// Multiply by metres per unit.
    MetresPerUnit(f64),
}

impl Units {
    fn to_metres(self, v: f64) -> f64 {
        match self {
            Units::PerMetre(d) => v / d,
            Units::MetresPerUnit(s) => v * s,
        }
    }
}

fn parse_units(path: &Path, units: &Value) -> Result<Units, CaptureError> {
    let bad = |reason: &'static str| CaptureError::BadUnits {
        path: path.to_path_buf(),
        found: units.to_string(),
        reason,
    };
    match units {
        Value::String(s) => match s.as_str() {
            "m" => Ok(Units::PerMetre(1.0)),
            "cm" => Ok(Units::PerMetre(100.0)),
            "mm" => Ok(Units::PerMetre(1000.0)),
            _ => Err(bad(
                "expected \"m\", \"cm\", \"mm\" or {\"metres_per_unit\": number}",
            )),
        },
        Value::Object(map) => {
            if map.len() != 1 {
                return Err(bad("an object must hold exactly the key \"metres_per_unit\""));
            }
            match map.get("metres_per_unit").and_then(Value::as_f64) {
                Some(s) if s.is_finite() && s > 0.0 => Ok(Units::MetresPerUnit(s)),
                Some(_) => Err(bad("metres_per_unit must be a positive finite number")),
                None => Err(bad(
                    "an object must hold exactly the key \"metres_per_unit\" (a number)",
                )),
            }
        }
        _ => Err(bad(
            "expected \"m\", \"cm\", \"mm\" or {\"metres_per_unit\": number}",
        )),
    }
}

/// `max(max |RᵀR − I|, |det R − 1|)`; infinite for non-finite input.
pub fn rotation_deviation(r: DMat3) -> f64 {
    if !r.is_finite() {
        return f64::INFINITY;
    }
    let e = r.transpose() * r - DMat3::IDENTITY;
    let off = e.to_cols_array().iter().fold(0.0f64, |m, v| m.max(v.abs()));
    off.max((r.determinant() - 1.0).abs())
}

/// The rotation nearest to `r` (orthogonal polar factor, Newton iteration
/// `X ← (X + X⁻ᵀ)/2`), for `r` already within [`ROTATION_TOLERANCE`] of one.
fn nearest_rotation(r: DMat3) -> DMat3 {
    let mut x = r;
    for _ in 0..32 {
        let next = 0.5 * (x + x.inverse().transpose());
        let change = (next - x)
            .to_cols_array()
            .iter()
            .fold(0.0f64, |m, v| m.max(v.abs()));
        x = next;
        if change < 1e-16 {
            break;
        }
    }
    x
}

/// Checks a camera's numbers and turns near-rotations into exact ones.
fn checked_camera(path: &Path, what: &str, mut camera: PinholeCamera) -> Result<PinholeCamera, CaptureError> {
    let non_finite = |field: String, value: f64| CaptureError::NonFinite {
        path: path.to_path_buf(),
        what: what.to_string(),
        field,
        value,
    };
    let bad = |reason: String| CaptureError::BadCamera {
        path: path.to_path_buf(),
        what: what.to_string(),
        reason,
    };
    for (field, v) in [
        ("fx", camera.fx),
        ("fy", camera.fy),
        ("cx", camera.cx),
        ("cy", camera.cy),
    ] {
        if !v.is_finite() {
            return Err(non_finite(field.to_string(), v));
        }
    }
    for (i, v) in camera.translation.to_array().into_iter().enumerate() {
        if !v.is_finite() {
            return Err(non_finite(format!("translation[{i}]"), v));
        }
    }
    let rows = camera.rotation.transpose().to_cols_array_2d();
    for (i, row) in rows.iter().enumerate() {
        for (j, &v) in row.iter().enumerate() {
            if !v.is_finite() {
                return Err(non_finite(format!("rotation[{i}][{j}]"), v));
            }
        }
    }
    if camera.width == 0 || camera.height == 0 {
        return Err(bad(format!(
            "image size {}×{} must be positive",
            camera.width, camera.height
        )));
    }
    for (field, v) in [("fx", camera.fx), ("fy", camera.fy)] {
        if v <= 0.0 {
            return Err(bad(format!("{field} = {v} must be positive")));
        }
    }
    let deviation = rotation_deviation(camera.rotation);
    if deviation > ROTATION_TOLERANCE {
        return Err(CaptureError::NotARotation {
            path: path.to_path_buf(),
            what: what.to_string(),
            deviation,
        });
    }
    if deviation > ROTATION_EXACT {
        camera.rotation = nearest_rotation(camera.rotation);
    }
    camera.validate().map_err(|e| bad(e.to_string()))?;
    Ok(camera)
}

/// Checks that `value` is a relative path that stays inside the folder and has one of
/// `extensions` (case-insensitive).
fn check_relative_path(
    path: &Path,
    what: &str,
    value: &str,
    extensions: &[&str],
) -> Result<(), CaptureError> {
    let bad = |reason: String| CaptureError::BadPath {
        path: path.to_path_buf(),
        what: what.to_string(),
        value: value.to_string(),
        reason,
    };
    if value.is_empty() {
        return Err(bad("is empty".into()));
    }
    if value.contains('\\') {
        return Err(bad("contains '\\': use '/' as the separator".into()));
    }
    let bytes = value.as_bytes();
    if value.starts_with('/') || (bytes.len() >= 2 && bytes[1] == b':' && bytes[0].is_ascii_alphabetic()) {
        return Err(bad("is absolute: paths are relative to the capture folder".into()));
    }
    for component in Path::new(value).components() {
        match component {
            Component::Normal(_) | Component::CurDir => {}
            Component::ParentDir => {
                return Err(bad("leaves the capture folder ('..' is not allowed)".into()));
            }
            Component::RootDir | Component::Prefix(_) => {
                return Err(bad("is absolute: paths are relative to the capture folder".into()));
            }
        }
    }
    let extension = Path::new(value)
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    match extension {
        Some(e) if extensions.contains(&e.as_str()) => Ok(()),
        _ => Err(bad(format!(
            "has an unsupported extension (expected one of {extensions:?})"
        ))),
    }
}

fn camera_from_json(
    width: u32,
    height: u32,
    intrinsics: &IntrinsicsJson,
    extrinsics: &ExtrinsicsJson,
    units: Units,
) -> PinholeCamera {
    let [tx, ty, tz] = extrinsics.translation;
    PinholeCamera {
        width,
        height,
        fx: intrinsics.fx,
        fy: intrinsics.fy,
        cx: intrinsics.cx,
        cy: intrinsics.cy,
        // JSON rows → columns of the transpose.
        rotation: DMat3::from_cols_array_2d(&extrinsics.rotation).transpose(),
        translation: DVec3::new(units.to_metres(tx), units.to_metres(ty), units.to_metres(tz)),
    }
}

fn camera_to_json(camera: &PinholeCamera) -> (IntrinsicsJson, ExtrinsicsJson) {
    (
        IntrinsicsJson {
            fx: camera.fx,
            fy: camera.fy,
            cx: camera.cx,
            cy: camera.cy,
        },
        ExtrinsicsJson {
            rotation: camera.rotation.transpose().to_cols_array_2d(),
            translation: camera.translation.to_array(),
        },
    )
}

impl Capture {
    /// A capture of these views with no lighting, targets or metadata.
    pub fn new(views: Vec<CaptureView>) -> Self {
        Self {
            views,
            envmap: None,
            targets: Vec::new(),
            metadata: Value::Null,
        }
    }

    /// The input views' cameras, in view order, translations in metres.
    pub fn cameras(&self) -> Vec<PinholeCamera> {
        self.views.iter().map(|v| v.camera).collect()
    }

    /// The input view named `name`.
    pub fn view(&self, name: &str) -> Option<&CaptureView> {
        self.views.iter().find(|v| v.name == name)
    }

    /// The target named `name`.
    pub fn target(&self, name: &str) -> Option<&TargetView> {
        self.targets.iter().find(|t| t.name == name)
    }

    /// Path of the capture's ground-truth lighting, if it has one.
    pub fn envmap_path(&self, dir: &Path) -> Option<PathBuf> {
        self.envmap.as_ref().map(|e| dir.join(e))
    }

    /// Reads and validates `dir/cameras.json`: format and version, units (lengths are
    /// converted to metres), at least one view, finite numbers, positive sizes and
    /// focal lengths, rotations (within [`ROTATION_TOLERANCE`]; snapped to the nearest
    /// rotation unless already within 1e-12), unique names, relative paths that stay
    /// in the folder, and that every referenced file exists.
    pub fn load(dir: impl AsRef<Path>) -> Result<Self, CaptureError> {
        let dir = dir.as_ref();
        let path = dir.join(CAPTURE_FILE_NAME);
        let text = std::fs::read_to_string(&path).with_path(&path)?;
        let capture = Self::from_json_str(&text, &path)?;
        capture.check_files(dir, &path)?;
        Ok(capture)
    }

    /// Parses and validates the text of a `cameras.json` (no file checks); `path` names it in errors.
    fn from_json_str(text: &str, path: &Path) -> Result<Self, CaptureError> {
        let json_err = |source| CaptureError::Json {
            path: path.to_path_buf(),
            source,
        };
        let header: HeaderJson = serde_json::from_str(text).map_err(json_err)?;
        let shown = |v: &Option<Value>| v.as_ref().map_or_else(|| "missing".to_string(), Value::to_string);
        if header.format.as_ref().and_then(Value::as_str) != Some(CAPTURE_FORMAT) {
            return Err(CaptureError::WrongFormat {
                path: path.to_path_buf(),
                found: shown(&header.format),
            });
        }
        if header.version.as_ref().and_then(Value::as_u64) != Some(CAPTURE_VERSION) {
            return Err(CaptureError::UnsupportedVersion {
                path: path.to_path_buf(),
                found: shown(&header.version),
            });
        }
        let file: CaptureJson = serde_json::from_str(text).map_err(json_err)?;
        let units = parse_units(path, &file.units)?;
        let views = file
            .views
            .into_iter()
            .map(|v| {
                let camera = camera_from_json(v.width, v.height, &v.intrinsics, &v.world_to_camera, units);
                let camera = checked_camera(path, &format!("view {:?}", v.name), camera)?;
                Ok(CaptureView {
                    name: v.name,
                    image: v.image,
                    mask: v.mask,
                    camera,
                })
            })
            .collect::<Result<Vec<_>, CaptureError>>()?;
        let targets = file
            .targets
            .into_iter()
            .map(|t| {
                let camera = camera_from_json(t.width, t.height, &t.intrinsics, &t.world_to_camera, units);
                let camera = checked_camera(path, &format!("target {:?}", t.name), camera)?;
                Ok(TargetView {
                    name: t.name,
                    image: t.image,
                    mask: t.mask,
                    envmap: t.envmap,
                    camera,
                })
            })
            .collect::<Result<Vec<_>, CaptureError>>()?;
        let capture = Self {
            views,
            envmap: file.envmap,
            targets,
            metadata: file.metadata,
        };
        capture.check_structure(path)?;
        Ok(capture)
    }

    /// Every file path with the field it comes from and its allowed extensions.
    fn file_fields(&self) -> Vec<(String, &str, &'static [&'static str])> {
        let mut out = Vec::new();
        for v in &self.views {
            out.push((
                format!("view {:?} image", v.name),
                v.image.as_str(),
                IMAGE_EXTENSIONS,
            ));
            if let Some(m) = &v.mask {
                out.push((format!("view {:?} mask", v.name), m.as_str(), MASK_EXTENSIONS));
            }
        }
        if let Some(e) = &self.envmap {
            out.push(("envmap".to_string(), e.as_str(), ENVMAP_EXTENSIONS));
        }
        for t in &self.targets {
            out.push((
                format!("target {:?} image", t.name),
                t.image.as_str(),
                IMAGE_EXTENSIONS,
            ));
            if let Some(m) = &t.mask {
                out.push((format!("target {:?} mask", t.name), m.as_str(), MASK_EXTENSIONS));
            }
            out.push((
                format!("target {:?} envmap", t.name),
                t.envmap.as_str(),
                ENVMAP_EXTENSIONS,
            ));
        }
        out
    }

    /// Everything but file existence: views present, names, paths, cameras.
    fn check_structure(&self, path: &Path) -> Result<(), CaptureError> {
        if self.views.is_empty() {
            return Err(CaptureError::NoViews {
                path: path.to_path_buf(),
            });
        }
        let mut names = HashSet::new();
        let entries = self
            .views
            .iter()
            .enumerate()
            .map(|(i, v)| ("view", i, v.name.as_str(), v.camera))
            .chain(
                self.targets
                    .iter()
                    .enumerate()
                    .map(|(i, t)| ("target", i, t.name.as_str(), t.camera)),
            );
        for (kind, i, name, camera) in entries {
            if name.is_empty() {
                return Err(CaptureError::EmptyName {
                    path: path.to_path_buf(),
                    what: format!("{kind} #{i}"),
                });
            }
            if !names.insert(name) {
                return Err(CaptureError::DuplicateName {
                    path: path.to_path_buf(),
                    name: name.to_string(),
                });
            }
            checked_camera(path, &format!("{kind} {name:?}"), camera)?;
        }
        for (what, value, extensions) in self.file_fields() {
            check_relative_path(path, &what, value, extensions)?;
        }
        Ok(())
    }

    /// Checks that every referenced file exists under `dir`.
    fn check_files(&self, dir: &Path, path: &Path) -> Result<(), CaptureError> {
        for (what, value, _) in self.file_fields() {
            let file = dir.join(value);
            if !file.is_file() {
                return Err(CaptureError::MissingFile {
                    path: path.to_path_buf(),
                    what,
                    file,
                });
            }
        }
        Ok(())
    }

    /// The `cameras.json` text [`Capture::save`] writes: pretty-printed, fields in schema
    /// order, `"units": "m"`, a trailing newline. Validates like [`Capture::load`] except
    /// that referenced files need not exist yet.
    pub fn to_json_string(&self) -> Result<String, CaptureError> {
        let path = Path::new(CAPTURE_FILE_NAME);
        self.check_structure(path)?;
        let file = CaptureJson {
            format: CAPTURE_FORMAT.to_string(),
            version: CAPTURE_VERSION,
            units: Value::String("m".into()),
            views: self
                .views
                .iter()
                .map(|v| {
                    let (intrinsics, world_to_camera) = camera_to_json(&v.camera);
                    ViewJson {
                        name: v.name.clone(),
                        image: v.image.clone(),
                        mask: v.mask.clone(),
                        width: v.camera.width,
                        height: v.camera.height,
                        intrinsics,
                        world_to_camera,
                    }
                })
                .collect(),
            envmap: self.envmap.clone(),
            targets: self
                .targets
                .iter()
                .map(|t| {
                    let (intrinsics, world_to_camera) = camera_to_json(&t.camera);
                    TargetJson {
                        name: t.name.clone(),
                        image: t.image.clone(),
                        mask: t.mask.clone(),
                        envmap: t.envmap.clone(),
                        width: t.camera.width,
                        height: t.camera.height,
                        intrinsics,
                        world_to_camera,
                    }
                })
                .collect(),
            metadata: self.metadata.clone(),
        };
        let mut text = serde_json::to_string_pretty(&file).map_err(|source| CaptureError::Json {
            path: path.to_path_buf(),
            source,
        })?;
        text.push('\n');
        Ok(text)
    }

    /// Writes `dir/cameras.json` (creating `dir` if needed) atomically: a temporary
    /// file in `dir`, then a rename. The output is deterministic (see
    /// [`Capture::to_json_string`]). Referenced files are not checked, so a writer may
    /// save before or after writing its images; [`Capture::load`] checks them.
    pub fn save(&self, dir: impl AsRef<Path>) -> Result<(), CaptureError> {
        let dir = dir.as_ref();
        let path = dir.join(CAPTURE_FILE_NAME);
        let text = self.to_json_string().map_err(|e| rename_file(e, &path))?;
        let io = |source| CaptureError::Io(FileIoError::new(path.clone(), source));
        std::fs::create_dir_all(dir).map_err(io)?;
        crate::atomic::write_bytes_atomically(&path, text.as_bytes()).map_err(io)
    }
}

/// Replaces the placeholder file name in a validation error with the real destination.
fn rename_file(error: CaptureError, real: &Path) -> CaptureError {
    let mut error = error;
    match &mut error {
        CaptureError::Io(FileIoError { path, .. })
        | CaptureError::Json { path, .. }
        | CaptureError::WrongFormat { path, .. }
        | CaptureError::UnsupportedVersion { path, .. }
        | CaptureError::BadUnits { path, .. }
        | CaptureError::NoViews { path }
        | CaptureError::EmptyName { path, .. }
        | CaptureError::DuplicateName { path, .. }
        | CaptureError::BadPath { path, .. }
        | CaptureError::MissingFile { path, .. }
        | CaptureError::NonFinite { path, .. }
        | CaptureError::BadCamera { path, .. }
        | CaptureError::NotARotation { path, .. } => *path = real.to_path_buf(),
    }
    error
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nearest_rotation_snaps_small_errors() {
        let r = DMat3::from_rotation_x(0.3) * DMat3::from_rotation_y(-1.2);
        let perturbed = r + DMat3::from_cols_array(&[3e-5, -2e-5, 1e-5, 0.0, 4e-5, -3e-5, 2e-5, 1e-5, -4e-5]);
        assert!(rotation_deviation(perturbed) > 1e-5);
        let snapped = nearest_rotation(perturbed);
        assert!(rotation_deviation(snapped) < 1e-14);
        assert!(snapped.abs_diff_eq(r, 1e-4));
    }

    #[test]
    fn units_parse() {
        let p = Path::new("x");
        let mm = parse_units(p, &serde_json::json!("mm")).unwrap();
        assert_eq!(mm.to_metres(1500.0), 1.5);
        let s = parse_units(p, &serde_json::json!({"metres_per_unit": 0.5})).unwrap();
        assert_eq!(s.to_metres(3.0), 1.5);
        for bad in [
            serde_json::json!("inch"),
            serde_json::json!({"metres_per_unit": -1.0}),
            serde_json::json!({"metres_per_unit": 1.0, "x": 1}),
            serde_json::json!(3),
        ] {
            assert!(
                matches!(parse_units(p, &bad), Err(CaptureError::BadUnits { .. })),
                "{bad}"
            );
        }
    }

    #[test]
    fn path_rules() {
        let p = Path::new("cameras.json");
        for ok in ["images/a.png", "./a.EXR", "a b/c.jpg"] {
            check_relative_path(p, "x", ok, IMAGE_EXTENSIONS).unwrap();
        }
        for bad in [
            "",
            "/abs/a.png",
            "../a.png",
            "images/../../a.png",
            "C:/a.png",
            "a\\b.png",
            "a.tiff",
        ] {
            assert!(
                check_relative_path(p, "x", bad, IMAGE_EXTENSIONS).is_err(),
                "{bad}"
            );
        }
    }
}
