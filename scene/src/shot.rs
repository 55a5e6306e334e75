//! Cameras and lightings for a shot: where a render of an asset looks from and what
//! lights it. One definition for every command that renders (`nelf render`, `nelf
//! export`, `nelf eval`): the clap option groups [`CameraArgs`] and [`LightingArgs`]
//! only hold what the user typed; the plain functions below turn them (or numbers from
//! code, without clap) into a [`PinholeCamera`] and a [`LatLong`] map.
//!
//! **Cameras** ([`resolve_camera`]) follow the project's OpenCV pinhole convention
//! (x right, y down, z forward; `x_cam = R·x_world + t`, metres) and come from one of:
//!
//! - a camera file ([`load_camera_file`]): the camera fields of a `cameras.json` view
//!   (`format/CAPTURE.md`): `width`, `height`, `intrinsics {fx, fy, cx, cy}`,
//!   `world_to_camera {rotation (row-major), translation}` ([`CameraJson`]), or a
//!   previous render's `.render.json`, whose `camera` is that object;
//! - a view or target of a capture folder (`CAPTURE_DIR:VIEW_NAME`), which brings its
//!   lighting along: the capture's environment map for a view, the target's own for a
//!   target;
//! - an orbit ([`parse_orbit`], [`orbit_camera`]) `AZ,EL[,DIST]` (degrees, degrees,
//!   metres) around the centre of a scene box (an asset's box, a field's hull box): the
//!   eye at `centre + DIST·(cos EL sin AZ, sin EL, cos EL cos AZ)` looking at the centre
//!   with +y up, so `0,0` looks from +z (the front of a head) and `90,0` from +x. DIST
//!   defaults to the distance at which the box's bounding sphere exactly fills the
//!   narrower of the two fields of view, `r / sin(fov / 2)`. The default camera is the
//!   orbit `0,0`, [`DEFAULT_ORBIT_SIZE`] pixels square, [`DEFAULT_FOV_X_DEG`] wide.
//!
//! `--width` / `--height` rescale a given camera's intrinsics ([`resized`]); one of
//! them alone keeps the aspect ratio.
//!
//! **Lightings** ([`load_lighting`]): an environment map file (`.exr` or `.hdr`,
//! lat-long, any resolution), else the lighting the camera's capture came with, else a
//! constant white map of radiance 1 in every direction (under which a voxel shows its
//! albedo-like total transport). `--rotate-deg` turns the map about +y
//! ([`world_from_env`]).

use std::path::{Path, PathBuf};

use glam::{DMat3, DVec3};
use nelf_format::capture::{Capture, CaptureError};
use nelf_format::conventions::{ConventionError, ENV_H, ENV_W, LatLong, PinholeCamera, rotation_y};
use serde::{Deserialize, Serialize};

use crate::error::SceneError;

/// Width and height in pixels of an orbit camera when none is given.
pub const DEFAULT_ORBIT_SIZE: u32 = 512;
/// Horizontal field of view of an orbit camera when none is given, degrees.
pub const DEFAULT_FOV_X_DEG: f64 = 30.0;
pub use nelf_format::orbit::MAX_ORBIT_ELEVATION_DEG;
use nelf_format::orbit::{Orbit, OrbitError};
/// Name [`load_lighting`] gives the constant white map.
pub const CONSTANT_WHITE_NAME: &str = "constant white (radiance 1)";

/// Something wrong with a camera or lighting option, file or number.
#[derive(Debug, thiserror::Error)]
pub enum ShotError {
    /// `--orbit` is not two or three numbers, or out of range.
    #[error("--{0}")]
    Orbit(#[from] OrbitError),
    /// The box an orbit circles is not finite, or empty (no default distance).
    #[error("the scene box {lo:?} .. {hi:?} must be finite with a positive diagonal")]
    SceneBox {
        /// Lowest corner, metres.
        lo: [f64; 3],
        /// Highest corner, metres.
        hi: [f64; 3],
    },
    /// `--fov-deg` out of range.
    #[error("--fov-deg {fov_x_deg} must be in (0, 179)")]
    FieldOfView {
        /// The horizontal field of view, degrees.
        fov_x_deg: f64,
    },
    /// A zero image size (`--width`, `--height`, or a camera's own).
    #[error("image size {width}×{height} must be positive")]
    ImageSize {
        /// Width in pixels.
        width: u32,
        /// Height in pixels.
        height: u32,
    },
    /// A camera file could not be read.
    #[error("cannot read {path}")]
    ReadCamera {
        /// The camera file.
        path: PathBuf,
        /// What the operating system said.
        source: std::io::Error,
    },
    /// A camera file is not JSON.
    #[error("{path} is not JSON")]
    CameraNotJson {
        /// The camera file.
        path: PathBuf,
        /// The JSON parser's error.
        source: serde_json::Error,
    },
    /// A camera file is JSON but not a camera.
    #[error(
        "{path}: expected a camera {{width, height, intrinsics {{fx, fy, cx, cy}}, world_to_camera {{rotation, translation}}}}"
    )]
    CameraLayout {
        /// The camera file.
        path: PathBuf,
        /// Which field is missing, unknown or of the wrong type.
        source: serde_json::Error,
    },
    /// A camera file holds a camera with bad numbers (size, focal lengths, rotation).
    #[error("invalid camera in {path}")]
    InvalidCameraFile {
        /// The camera file.
        path: PathBuf,
        /// What is wrong with the camera.
        source: ConventionError,
    },
    /// A resolved camera has bad numbers.
    #[error("invalid camera from {origin}")]
    InvalidCamera {
        /// The option it came from (`--camera FILE`, `--view-of …`, `--orbit …`).
        origin: String,
        /// What is wrong with the camera.
        source: ConventionError,
    },
    /// `--view-of` is not `CAPTURE_DIR:VIEW_NAME`.
    #[error("--view-of {spec:?}: expected CAPTURE_DIR:VIEW_NAME")]
    ViewOfSyntax {
        /// The option's text.
        spec: String,
    },
    /// The capture folder of `--view-of` could not be loaded.
    #[error("cannot load the capture folder {dir}")]
    Capture {
        /// The capture folder.
        dir: PathBuf,
        /// What is wrong with it.
        source: CaptureError,
    },
    /// The capture of `--view-of` has no such view or target.
    #[error("capture {dir} has no view or target named {name:?}")]
    NoSuchView {
        /// The capture folder.
        dir: PathBuf,
        /// The name asked for.
        name: String,
    },
    /// An environment map could not be loaded.
    #[error("cannot load environment map {path}")]
    Envmap {
        /// The map file.
        path: PathBuf,
        /// What went wrong.
        source: SceneError,
    },
    /// `--rank` is 0 or above the asset's PCA rank.
    #[error("--rank {rank}: the asset has PCA rank {asset_rank} (use 1..={asset_rank})")]
    Rank {
        /// The rank asked for.
        rank: usize,
        /// The asset's PCA rank.
        asset_rank: usize,
    },
}

/// Where a render looks from: `--camera`, `--view-of` or `--orbit` (at most one;
/// default `--orbit 0,0`), the image size and the orbit's field of view. Resolved by
/// [`resolve_camera`].
#[derive(Debug, Clone, PartialEq, clap::Args, Serialize, Deserialize)]
pub struct CameraArgs {
    /// Camera file: a cameras.json view object (metres) or a previous `.render.json`.
    #[arg(long, group = "view")]
    pub camera: Option<PathBuf>,
    /// A view or target of a capture folder, as `CAPTURE_DIR:VIEW_NAME`.
    #[arg(long, value_name = "CAPTURE_DIR:VIEW_NAME", group = "view")]
    pub view_of: Option<String>,
    /// Orbit camera `AZ,EL[,DIST]` (degrees, degrees, metres) around the box centre.
    #[arg(long, value_name = "AZ,EL[,DIST]", group = "view", allow_hyphen_values = true)]
    pub orbit: Option<String>,
    /// Image width in pixels (orbit default 512; rescales a given camera's intrinsics).
    #[arg(long)]
    pub width: Option<u32>,
    /// Image height in pixels (orbit default 512; rescales a given camera's intrinsics).
    #[arg(long)]
    pub height: Option<u32>,
    /// Horizontal field of view of the orbit camera, degrees.
    #[arg(long, default_value_t = DEFAULT_FOV_X_DEG)]
    pub fov_deg: f64,
}

impl Default for CameraArgs {
    /// The default orbit `0,0`, 512×512, 30° wide.
    fn default() -> Self {
        Self {
            camera: None,
            view_of: None,
            orbit: None,
            width: None,
            height: None,
            fov_deg: DEFAULT_FOV_X_DEG,
        }
    }
}

/// What lights a render: `--envmap` turned by `--rotate-deg` about +y. What lights it
/// without `--envmap` is the command's choice ([`load_lighting`]'s fallbacks for
/// renders).
#[derive(Debug, Clone, Default, PartialEq, clap::Args, Serialize, Deserialize)]
pub struct LightingArgs {
    /// Environment map (.exr or .hdr, lat-long, any resolution); default: constant white.
    #[arg(long)]
    pub envmap: Option<PathBuf>,
    /// Turn the lighting about +y by this many degrees.
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    pub rotate_deg: f64,
}

impl LightingArgs {
    /// `--envmap`, else `capture_envmap`, else constant white ([`load_lighting`]).
    pub fn load(&self, capture_envmap: Option<&Path>) -> Result<(LatLong, String), ShotError> {
        load_lighting(self.envmap.as_deref(), capture_envmap)
    }

    /// The rotation of `--rotate-deg` ([`world_from_env`]).
    pub fn world_from_env(&self) -> DMat3 {
        world_from_env(self.rotate_deg)
    }
}

/// A camera in the `cameras.json` view layout (`format/CAPTURE.md`), metres; what
/// `--camera` reads and what a render's record stores under `camera`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraJson {
    /// Optional label (a view's name); ignored when read.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Focal lengths and principal point, pixels.
    pub intrinsics: IntrinsicsJson,
    /// World-to-camera rotation and translation.
    pub world_to_camera: ExtrinsicsJson,
}

/// Pinhole intrinsics in pixels (continuous coordinates, pixel centres at `+0.5`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct IntrinsicsJson {
    /// Focal length along x.
    pub fx: f64,
    /// Focal length along y.
    pub fy: f64,
    /// Principal point x.
    pub cx: f64,
    /// Principal point y.
    pub cy: f64,
}

/// World-to-camera `[R|t]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ExtrinsicsJson {
    /// Row-major `R`.
    pub rotation: [[f64; 3]; 3],
    /// `t`, metres.
    pub translation: [f64; 3],
}

impl CameraJson {
    /// The camera these numbers describe (not validated; see [`PinholeCamera::validate`]).
    pub fn to_camera(&self) -> PinholeCamera {
        let rows = self.world_to_camera.rotation.map(DVec3::from_array);
        PinholeCamera {
            width: self.width,
            height: self.height,
            fx: self.intrinsics.fx,
            fy: self.intrinsics.fy,
            cx: self.intrinsics.cx,
            cy: self.intrinsics.cy,
            rotation: DMat3::from_cols(rows[0], rows[1], rows[2]).transpose(),
            translation: DVec3::from_array(self.world_to_camera.translation),
        }
    }
}

/// `camera` in the `cameras.json` view layout, without a name; [`CameraJson::to_camera`]
/// gives it back bit for bit.
pub fn camera_to_json(camera: &PinholeCamera) -> CameraJson {
    let r = camera.rotation;
    CameraJson {
        name: None,
        width: camera.width,
        height: camera.height,
        intrinsics: IntrinsicsJson {
            fx: camera.fx,
            fy: camera.fy,
            cx: camera.cx,
            cy: camera.cy,
        },
        world_to_camera: ExtrinsicsJson {
            rotation: [0, 1, 2].map(|i| r.row(i).to_array()),
            translation: camera.translation.to_array(),
        },
    }
}

/// The camera from `--camera`, `--view-of` or `--orbit` (default `--orbit 0,0`) at
/// `--width`/`--height`, validated; with the lighting a capture view or target comes
/// with, if any. `scene_box` (lowest and highest corner, metres) is what an orbit
/// circles.
pub fn resolve_camera(
    args: &CameraArgs,
    scene_box: (DVec3, DVec3),
) -> Result<(PinholeCamera, Option<PathBuf>), ShotError> {
    let (camera, capture_envmap, origin) = if let Some(path) = &args.camera {
        (
            resized(load_camera_file(path)?, args.width, args.height)?,
            None,
            format!("--camera {}", path.display()),
        )
    } else if let Some(spec) = &args.view_of {
        let (camera, envmap) = capture_camera(spec)?;
        (
            resized(camera, args.width, args.height)?,
            envmap,
            format!("--view-of {spec}"),
        )
    } else {
        let spec = args.orbit.as_deref().unwrap_or("0,0");
        let (azimuth_deg, elevation_deg, distance_m) = parse_orbit(spec)?;
        let camera = orbit_camera(
            azimuth_deg,
            elevation_deg,
            distance_m,
            args.width.unwrap_or(DEFAULT_ORBIT_SIZE),
            args.height.unwrap_or(DEFAULT_ORBIT_SIZE),
            args.fov_deg,
            scene_box,
        )?;
        (camera, None, format!("--orbit {spec}"))
    };
    camera
        .validate()
        .map_err(|source| ShotError::InvalidCamera { origin, source })?;
    Ok((camera, capture_envmap))
}

/// The camera of view or target `VIEW_NAME` of the capture folder `CAPTURE_DIR`
/// (`spec` is `CAPTURE_DIR:VIEW_NAME`), and its lighting: the capture's env map for a
/// view (if it has one), the target's for a target.
fn capture_camera(spec: &str) -> Result<(PinholeCamera, Option<PathBuf>), ShotError> {
    let (dir, name) = spec.rsplit_once(':').ok_or_else(|| ShotError::ViewOfSyntax {
        spec: spec.to_string(),
    })?;
    let dir = Path::new(dir);
    let capture = Capture::load(dir).map_err(|source| ShotError::Capture {
        dir: dir.to_path_buf(),
        source,
    })?;
    if let Some(view) = capture.view(name) {
        Ok((view.camera, capture.envmap_path(dir)))
    } else if let Some(target) = capture.target(name) {
        Ok((target.camera, Some(target.envmap_path(dir))))
    } else {
        Err(ShotError::NoSuchView {
            dir: dir.to_path_buf(),
            name: name.to_string(),
        })
    }
}

/// Reads a camera object ([`CameraJson`]), or the `camera` of a previous
/// `.render.json`, and validates it.
pub fn load_camera_file(path: &Path) -> Result<PinholeCamera, ShotError> {
    let text = std::fs::read_to_string(path).map_err(|source| ShotError::ReadCamera {
        path: path.to_path_buf(),
        source,
    })?;
    let value: serde_json::Value =
        serde_json::from_str(&text).map_err(|source| ShotError::CameraNotJson {
            path: path.to_path_buf(),
            source,
        })?;
    let object = value.get("camera").cloned().unwrap_or(value);
    let camera: CameraJson = serde_json::from_value(object).map_err(|source| ShotError::CameraLayout {
        path: path.to_path_buf(),
        source,
    })?;
    let camera = camera.to_camera();
    camera.validate().map_err(|source| ShotError::InvalidCameraFile {
        path: path.to_path_buf(),
        source,
    })?;
    Ok(camera)
}

/// `camera` at `width` × `height` pixels, intrinsics scaled; only one of them given
/// keeps the aspect ratio (the other rounded, at least 1); neither returns it as is.
pub fn resized(
    camera: PinholeCamera,
    width: Option<u32>,
    height: Option<u32>,
) -> Result<PinholeCamera, ShotError> {
    if width.is_none() && height.is_none() {
        return Ok(camera);
    }
    if camera.width == 0 || camera.height == 0 {
        return Err(ShotError::ImageSize {
            width: camera.width,
            height: camera.height,
        });
    }
    let (w0, h0) = (f64::from(camera.width), f64::from(camera.height));
    let (width, height) = match (width, height) {
        (Some(w), Some(h)) => (w, h),
        (Some(w), None) => (w, (f64::from(w) * h0 / w0).round().max(1.0) as u32),
        (None, Some(h)) => ((f64::from(h) * w0 / h0).round().max(1.0) as u32, h),
        (None, None) => (camera.width, camera.height),
    };
    if width == 0 || height == 0 {
        return Err(ShotError::ImageSize { width, height });
    }
    let (sx, sy) = (f64::from(width) / w0, f64::from(height) / h0);
    Ok(PinholeCamera {
        width,
        height,
        fx: camera.fx * sx,
        fy: camera.fy * sy,
        cx: camera.cx * sx,
        cy: camera.cy * sy,
        ..camera
    })
}

/// Parses `AZ,EL[,DIST]` (degrees, degrees, metres; spaces allowed around the numbers)
/// and checks the ranges [`orbit_camera`] accepts ([`nelf_format::orbit::Orbit::parse`]).
pub fn parse_orbit(spec: &str) -> Result<(f64, f64, Option<f64>), ShotError> {
    let orbit = Orbit::parse(spec)?;
    Ok((orbit.azimuth_deg, orbit.elevation_deg, orbit.distance_m))
}

/// A `width` × `height` camera with a horizontal field of view of `fov_x_deg` at
/// `centre + DIST·(cos EL sin AZ, sin EL, cos EL cos AZ)`, looking at the centre of
/// `scene_box` (lowest and highest corner, metres) with +y up. `distance_m` `None`: the
/// distance at which the box's bounding sphere exactly fills the narrower field of view.
pub fn orbit_camera(
    azimuth_deg: f64,
    elevation_deg: f64,
    distance_m: Option<f64>,
    width: u32,
    height: u32,
    fov_x_deg: f64,
    scene_box: (DVec3, DVec3),
) -> Result<PinholeCamera, ShotError> {
    Orbit::new(azimuth_deg, elevation_deg, distance_m)?;
    if width == 0 || height == 0 {
        return Err(ShotError::ImageSize { width, height });
    }
    if !(fov_x_deg.is_finite() && fov_x_deg > 0.0 && fov_x_deg < 179.0) {
        return Err(ShotError::FieldOfView { fov_x_deg });
    }
    let (lo, hi) = scene_box;
    let diagonal = (hi - lo).length();
    let bad_box = || ShotError::SceneBox {
        lo: lo.to_array(),
        hi: hi.to_array(),
    };
    if !(lo.is_finite() && hi.is_finite()) {
        return Err(bad_box());
    }
    let fov_x = fov_x_deg.to_radians();
    let centre = 0.5 * (lo + hi);
    let distance = if let Some(d) = distance_m {
        d
    } else {
        // The narrower of the two fields of view must hold the box's bounding sphere.
        let fov_y = 2.0 * ((0.5 * fov_x).tan() * f64::from(height) / f64::from(width)).atan();
        let d = 0.5 * diagonal / (0.5 * fov_x.min(fov_y)).sin();
        if !(d.is_finite() && d > 0.0) {
            return Err(bad_box());
        }
        d
    };
    let (az, el) = (azimuth_deg.to_radians(), elevation_deg.to_radians());
    let eye = centre + distance * DVec3::new(el.cos() * az.sin(), el.sin(), el.cos() * az.cos());
    Ok(PinholeCamera::look_at(
        eye,
        centre,
        DVec3::Y,
        width,
        height,
        fov_x,
    ))
}

/// The lighting to render under, with a name for people: the map `envmap`, else
/// `fallback_capture_envmap` (the lighting a capture view came with), else a constant
/// white map of radiance 1 ([`CONSTANT_WHITE_NAME`], [`ENV_W`] × [`ENV_H`] texels).
/// A file's name is its path.
pub fn load_lighting(
    envmap: Option<&Path>,
    fallback_capture_envmap: Option<&Path>,
) -> Result<(LatLong, String), ShotError> {
    match envmap.or(fallback_capture_envmap) {
        Some(path) => {
            let env = crate::envmap::load_envmap(path).map_err(|source| ShotError::Envmap {
                path: path.to_path_buf(),
                source,
            })?;
            Ok((env, path.display().to_string()))
        }
        None => Ok((
            LatLong::constant(ENV_W, ENV_H, [1.0; 3]),
            CONSTANT_WHITE_NAME.to_string(),
        )),
    }
}

/// `world_from_env` of a map turned by `rotate_deg` degrees about +y.
pub fn world_from_env(rotate_deg: f64) -> DMat3 {
    rotation_y(rotate_deg.to_radians())
}

/// One image of an asset as `nelf render` frames it: the camera, the lighting and the
/// rank, resolved from the options against the asset.
#[derive(Debug, Clone)]
pub struct AssetShot {
    /// The camera ([`resolve_camera`] about the asset's box).
    pub camera: PinholeCamera,
    /// The environment map ([`LightingArgs::load`]).
    pub env: LatLong,
    /// Where the map came from, for records and messages.
    pub envmap_name: String,
    /// The map's rotation into the world ([`LightingArgs::world_from_env`]).
    pub world_from_env: DMat3,
    /// The PCA rank used ([`checked_rank`]; `None`: all).
    pub rank: Option<usize>,
}

/// Resolves `view`, `lighting` and `rank` for one image of `asset`: the rank checked
/// against the asset's, the camera about the asset's box (or from a camera file or a
/// capture's view), the lighting from `--envmap` or the capture view's own map.
pub fn asset_shot(
    asset: &nelf_format::Asset,
    view: &CameraArgs,
    lighting: &LightingArgs,
    rank: Option<usize>,
) -> Result<AssetShot, ShotError> {
    let rank = checked_rank(rank, asset.rank())?;
    let asset_box = (
        DVec3::from_array(asset.grid.bbox_min_m),
        DVec3::from_array(asset.grid.bbox_max_m()),
    );
    let (camera, capture_envmap) = resolve_camera(view, asset_box)?;
    let (env, envmap_name) = lighting.load(capture_envmap.as_deref())?;
    Ok(AssetShot {
        camera,
        env,
        envmap_name,
        world_from_env: lighting.world_from_env(),
        rank,
    })
}

/// `rank` (`--rank K`: the first K PCA components) checked against an asset's PCA
/// rank: `None` (all) passes, `Some(k)` needs `1 ≤ k ≤ asset_rank`.
pub fn checked_rank(rank: Option<usize>, asset_rank: usize) -> Result<Option<usize>, ShotError> {
    match rank {
        Some(k) if k == 0 || k > asset_rank => Err(ShotError::Rank { rank: k, asset_rank }),
        other => Ok(other),
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::expect_used)]
mod tests {
    use std::error::Error as _;

    use clap::Parser;
    use nelf_format::capture::{CaptureView, TargetView};

    use super::*;

    const BOX: (DVec3, DVec3) = (DVec3::new(-0.1, -0.15, -0.12), DVec3::new(0.12, 0.2, 0.1));

    /// A camera with numbers that do not round-trip by accident.
    fn odd_camera() -> PinholeCamera {
        let mut camera = PinholeCamera::look_at(
            DVec3::new(0.1 / 3.0, 0.05_f64.sqrt(), 0.45 + 1e-17),
            DVec3::new(1e-3, -2.0 / 7.0, 0.0),
            DVec3::Y,
            37,
            23,
            0.7,
        );
        camera.cx += 1.0 / 3.0;
        camera.fy *= 1.000_000_1;
        camera
    }

    fn bits(camera: &PinholeCamera) -> Vec<u64> {
        [camera.fx, camera.fy, camera.cx, camera.cy]
            .into_iter()
            .chain(camera.rotation.to_cols_array())
            .chain(camera.translation.to_array())
            .map(f64::to_bits)
            .collect()
    }

    #[test]
    fn orbit_looks_at_the_box_centre_and_its_bounding_sphere_fits() {
        let (lo, hi) = BOX;
        let centre = 0.5 * (lo + hi);
        let radius = 0.5 * (hi - lo).length();
        for (width, height) in [(64, 48), (40, 80), (50, 50)] {
            for (az, el) in [(0.0, 0.0), (30.0, -10.0), (-120.0, 45.0), (200.0, 89.0)] {
                let camera = orbit_camera(az, el, None, width, height, 30.0, BOX).unwrap();
                camera.validate().unwrap();
                assert_eq!((camera.width, camera.height), (width, height));
                // Looks at the centre: it projects to the image centre.
                let at = camera.project(centre).unwrap();
                assert!((at.x - 0.5 * f64::from(width)).abs() < 1e-9, "{at}");
                assert!((at.y - 0.5 * f64::from(height)).abs() < 1e-9, "{at}");
                // The eye is on the orbit's direction.
                let (a, e) = (f64::to_radians(az), f64::to_radians(el));
                let direction = DVec3::new(e.cos() * a.sin(), e.sin(), e.cos() * a.cos());
                let offset = camera.centre() - centre;
                assert!((offset.normalize() - direction).length() < 1e-9);
                // +y is up in the image (image y points down).
                assert!(camera.project(centre + 0.01 * DVec3::Y).unwrap().y < at.y);
                // The bounding sphere fits and touches the narrower side.
                let half_narrower = 0.5 * f64::from(width.min(height));
                let mut farthest = 0.0_f64;
                for i in 0..4000 {
                    // Fibonacci sphere.
                    let z = 1.0 - 2.0 * (f64::from(i) + 0.5) / 4000.0;
                    let phi = f64::from(i) * 2.399_963_229_728_653;
                    let r = (1.0 - z * z).sqrt();
                    let p = centre + radius * DVec3::new(r * phi.cos(), r * phi.sin(), z);
                    let pixel = camera.project(p).unwrap();
                    assert!(pixel.x >= -1e-9 && pixel.x <= f64::from(width) + 1e-9, "{pixel}");
                    assert!(pixel.y >= -1e-9 && pixel.y <= f64::from(height) + 1e-9, "{pixel}");
                    farthest = farthest.max((pixel - at).length());
                }
                assert!(farthest <= half_narrower + 1e-9, "{farthest} > {half_narrower}");
                assert!(farthest > 0.99 * half_narrower, "{farthest} ≪ {half_narrower}");
            }
        }
        // An explicit distance puts the eye there.
        let camera = orbit_camera(90.0, 0.0, Some(2.5), 32, 32, 30.0, BOX).unwrap();
        assert!((camera.centre() - (centre + DVec3::new(2.5, 0.0, 0.0))).length() < 1e-12);
        // The default camera.
        let (camera, envmap) = resolve_camera(&CameraArgs::default(), BOX).unwrap();
        assert_eq!(envmap, None);
        assert_eq!(
            (camera.width, camera.height),
            (DEFAULT_ORBIT_SIZE, DEFAULT_ORBIT_SIZE)
        );
        assert!(camera.centre().z > centre.z && (camera.centre().x - centre.x).abs() < 1e-12);
    }

    #[test]
    fn bad_orbits_sizes_and_boxes_are_refused() {
        // The parser is nelf_format::orbit's (tested there); here it speaks as the option.
        assert_eq!(parse_orbit(" 1, 2 ,3").unwrap(), (1.0, 2.0, Some(3.0)));
        for (spec, says) in [("a,b", "AZ,EL"), ("0,90", "elevation"), ("0,0,-1", "distance")] {
            let error = parse_orbit(spec).unwrap_err();
            assert!(matches!(error, ShotError::Orbit(_)), "{spec}: {error}");
            let text = error.to_string();
            assert!(text.starts_with("--orbit") && text.contains(says), "{text}");
        }
        assert!(matches!(
            orbit_camera(0.0, 89.9, None, 8, 8, 30.0, BOX),
            Err(ShotError::Orbit(OrbitError::Angles { .. }))
        ));
        assert!(matches!(
            orbit_camera(0.0, 0.0, Some(0.0), 8, 8, 30.0, BOX),
            Err(ShotError::Orbit(OrbitError::Distance { .. }))
        ));
        for (width, height) in [(0, 8), (8, 0)] {
            let error = orbit_camera(0.0, 0.0, None, width, height, 30.0, BOX).unwrap_err();
            assert!(matches!(error, ShotError::ImageSize { .. }), "{error}");
            assert!(error.to_string().contains("must be positive"), "{error}");
        }
        for fov in [0.0, -5.0, 179.0, f64::NAN] {
            let error = orbit_camera(0.0, 0.0, None, 8, 8, fov, BOX).unwrap_err();
            assert!(error.to_string().contains("--fov-deg"), "{error}");
        }
        let point = (DVec3::ONE, DVec3::ONE);
        assert!(matches!(
            orbit_camera(0.0, 0.0, None, 8, 8, 30.0, point),
            Err(ShotError::SceneBox { .. })
        ));
        assert!(orbit_camera(0.0, 0.0, Some(1.0), 8, 8, 30.0, point).is_ok());
        let infinite = (DVec3::ZERO, DVec3::new(f64::INFINITY, 1.0, 1.0));
        assert!(matches!(
            orbit_camera(0.0, 0.0, Some(1.0), 8, 8, 30.0, infinite),
            Err(ShotError::SceneBox { .. })
        ));
        let args = CameraArgs {
            orbit: Some("0,0".into()),
            width: Some(0),
            ..CameraArgs::default()
        };
        assert!(matches!(
            resolve_camera(&args, BOX),
            Err(ShotError::ImageSize { .. })
        ));
    }

    #[test]
    fn camera_json_round_trips_bit_for_bit_and_render_records_are_read() {
        let dir = tempfile::tempdir().unwrap();
        let camera = odd_camera();
        let json = camera_to_json(&camera);
        assert_eq!(bits(&json.to_camera()), bits(&camera));
        let path = dir.path().join("cam.json");
        std::fs::write(&path, serde_json::to_string_pretty(&json).unwrap()).unwrap();
        let read = load_camera_file(&path).unwrap();
        assert_eq!((read.width, read.height), (camera.width, camera.height));
        assert_eq!(bits(&read), bits(&camera));

        // A render's record: the camera under `camera`, beside other settings.
        let record = serde_json::json!({
            "config": {"camera": null, "orbit": "30,-10", "rank": 4},
            "camera": json,
            "envmap": CONSTANT_WHITE_NAME,
        });
        let record_path = dir.path().join("x.png.render.json");
        std::fs::write(&record_path, record.to_string()).unwrap();
        assert_eq!(bits(&load_camera_file(&record_path).unwrap()), bits(&camera));
        // Through CameraArgs, resized to half the width (the aspect ratio is kept).
        let args = CameraArgs {
            camera: Some(record_path),
            width: Some(74),
            ..CameraArgs::default()
        };
        let (resolved, envmap) = resolve_camera(&args, BOX).unwrap();
        assert_eq!((resolved.width, resolved.height, envmap), (74, 46, None));

        // A name is allowed; anything else is refused, naming the file.
        let mut named = json.clone();
        named.name = Some("front".into());
        std::fs::write(&path, serde_json::to_string(&named).unwrap()).unwrap();
        assert_eq!(bits(&load_camera_file(&path).unwrap()), bits(&camera));
        std::fs::write(&path, "{\"width\": 4").unwrap();
        let error = load_camera_file(&path).unwrap_err();
        assert!(matches!(error, ShotError::CameraNotJson { .. }), "{error}");
        assert!(error.to_string().contains("cam.json"), "{error}");
        std::fs::write(&path, "{\"width\": 4, \"height\": 4}").unwrap();
        let error = load_camera_file(&path).unwrap_err();
        assert!(matches!(error, ShotError::CameraLayout { .. }), "{error}");
        let chain = crate::error::error_chain(&error);
        assert!(chain.contains("intrinsics"), "{chain}");
        let mut mirrored = json;
        mirrored.world_to_camera.rotation[2] =
            (-DVec3::from_array(mirrored.world_to_camera.rotation[2])).to_array();
        std::fs::write(&path, serde_json::to_string(&mirrored).unwrap()).unwrap();
        let error = load_camera_file(&path).unwrap_err();
        assert!(matches!(error, ShotError::InvalidCameraFile { .. }), "{error}");
        let chain = crate::error::error_chain(&error);
        assert!(chain.contains("not a rotation"), "{chain}");
        let missing = dir.path().join("missing.json");
        let error = load_camera_file(&missing).unwrap_err();
        assert!(matches!(error, ShotError::ReadCamera { .. }), "{error}");
        assert!(error.source().is_some() && error.to_string().contains("missing.json"));
    }

    #[test]
    fn resize_scales_intrinsics_and_keeps_the_aspect_with_one_side() {
        let camera = PinholeCamera::look_at(DVec3::new(0.0, 0.0, 1.0), DVec3::ZERO, DVec3::Y, 40, 30, 0.8);
        assert_eq!(resized(camera, None, None).unwrap(), camera);
        let half = resized(camera, Some(20), None).unwrap();
        assert_eq!((half.width, half.height), (20, 15));
        assert_eq!(
            (half.fx, half.fy, half.cx, half.cy),
            (camera.fx * 0.5, camera.fy * 0.5, 10.0, 7.5)
        );
        assert_eq!(
            (half.rotation, half.translation),
            (camera.rotation, camera.translation)
        );
        let tall = resized(camera, None, Some(60)).unwrap();
        assert_eq!((tall.width, tall.height), (80, 60));
        let squashed = resized(camera, Some(40), Some(10)).unwrap();
        assert_eq!((squashed.fx, squashed.fy), (camera.fx, camera.fy * (10.0 / 30.0)));
        assert_eq!((tall.fx, tall.cx, tall.cy), (camera.fx * 2.0, 40.0, 30.0));
        assert_eq!((resized(camera, Some(1), None).unwrap().height), 1);
        for (width, height) in [(Some(0), None), (None, Some(0)), (Some(3), Some(0))] {
            assert!(matches!(
                resized(camera, width, height),
                Err(ShotError::ImageSize { .. })
            ));
        }
    }

    #[test]
    fn lighting_defaults_to_constant_white_and_prefers_the_given_map() {
        let (white, name) = load_lighting(None, None).unwrap();
        assert_eq!((white.width(), white.height()), (ENV_W, ENV_H));
        assert!(white.texels().iter().all(|&t| t == [1.0; 3]));
        assert_eq!(name, CONSTANT_WHITE_NAME);
        assert_eq!(LightingArgs::default().load(None).unwrap(), (white, name));

        let dir = tempfile::tempdir().unwrap();
        let given = dir.path().join("given.exr");
        let capture = dir.path().join("capture.exr");
        crate::image_io::write_exr_rgb(&given, 4, 2, &[[2.0, 1.0, 0.5]; 8]).unwrap();
        crate::image_io::write_exr_rgb(&capture, 4, 2, &[[0.25; 3]; 8]).unwrap();
        let (env, name) = load_lighting(Some(&given), Some(&capture)).unwrap();
        assert_eq!(
            (env.get(0, 0), name),
            ([2.0, 1.0, 0.5], given.display().to_string())
        );
        let (env, name) = load_lighting(None, Some(&capture)).unwrap();
        assert_eq!((env.get(1, 3), name), ([0.25; 3], capture.display().to_string()));
        let missing = dir.path().join("missing.hdr");
        let error = load_lighting(Some(&missing), Some(&capture)).unwrap_err();
        assert!(matches!(error, ShotError::Envmap { .. }), "{error}");
        assert!(
            error.to_string().contains("cannot load environment map")
                && error.to_string().contains("missing.hdr")
        );

        let args = LightingArgs {
            envmap: None,
            rotate_deg: 90.0,
        };
        assert_eq!(args.world_from_env(), rotation_y(std::f64::consts::FRAC_PI_2));
        assert_eq!(world_from_env(0.0), DMat3::IDENTITY);
    }

    #[test]
    fn capture_views_and_targets_bring_their_lighting() {
        let dir = tempfile::tempdir().unwrap();
        let capture_dir = dir.path().join("cap:ture");
        std::fs::create_dir_all(capture_dir.join("images")).unwrap();
        for file in ["images/front.png", "images/side.png", "light.exr", "target.exr"] {
            std::fs::write(capture_dir.join(file), b"").unwrap();
        }
        let front = PinholeCamera::look_at(DVec3::new(0.0, 0.0, 0.5), DVec3::ZERO, DVec3::Y, 30, 20, 0.8);
        let side = PinholeCamera::look_at(DVec3::new(0.5, 0.0, 0.0), DVec3::ZERO, DVec3::Y, 16, 16, 0.8);
        let mut capture = Capture::new(vec![CaptureView {
            name: "front".into(),
            image: "images/front.png".into(),
            mask: None,
            camera: front,
        }]);
        capture.envmap = Some("light.exr".into());
        capture.targets.push(TargetView {
            name: "side".into(),
            image: "images/side.png".into(),
            mask: None,
            envmap: "target.exr".into(),
            camera: side,
        });
        capture.save(&capture_dir).unwrap();
        let view_of = |name: &str| CameraArgs {
            view_of: Some(format!("{}:{name}", capture_dir.display())),
            ..CameraArgs::default()
        };

        let (camera, envmap) = resolve_camera(&view_of("front"), BOX).unwrap();
        assert_eq!((camera, envmap), (front, Some(capture_dir.join("light.exr"))));
        let (camera, envmap) = resolve_camera(
            &CameraArgs {
                height: Some(10),
                ..view_of("front")
            },
            BOX,
        )
        .unwrap();
        assert_eq!((camera.width, camera.height), (15, 10));
        assert!(envmap.is_some());
        let (camera, envmap) = resolve_camera(&view_of("side"), BOX).unwrap();
        assert_eq!((camera, envmap), (side, Some(capture_dir.join("target.exr"))));
        let error = resolve_camera(&view_of("nope"), BOX).unwrap_err();
        assert!(
            error.to_string().contains("no view or target named \"nope\""),
            "{error}"
        );

        let no_colon = CameraArgs {
            view_of: Some("folder".into()),
            ..CameraArgs::default()
        };
        let error = resolve_camera(&no_colon, BOX).unwrap_err();
        assert!(matches!(error, ShotError::ViewOfSyntax { .. }), "{error}");
        let no_capture = CameraArgs {
            view_of: Some(format!("{}:front", dir.path().display())),
            ..CameraArgs::default()
        };
        let error = resolve_camera(&no_capture, BOX).unwrap_err();
        assert!(matches!(error, ShotError::Capture { .. }), "{error}");
        assert!(
            error.to_string().contains("cannot load the capture folder"),
            "{error}"
        );
    }

    #[test]
    fn checked_rank_accepts_one_to_the_asset_rank() {
        assert_eq!(checked_rank(None, 6).unwrap(), None);
        assert_eq!(checked_rank(Some(6), 6).unwrap(), Some(6));
        for k in [0, 7] {
            let error = checked_rank(Some(k), 6).unwrap_err();
            assert!(
                error.to_string().contains("the asset has PCA rank 6 (use 1..=6)"),
                "{error}"
            );
        }
    }

    #[derive(Debug, Parser)]
    struct Cli {
        #[command(flatten)]
        camera: CameraArgs,
        #[command(flatten)]
        lighting: LightingArgs,
    }

    #[test]
    fn the_options_parse_as_nelf_render_declares_them() {
        let cli = Cli::try_parse_from(["t"]).unwrap();
        assert_eq!(
            (cli.camera, cli.lighting),
            (CameraArgs::default(), LightingArgs::default())
        );
        let cli = Cli::try_parse_from([
            "t",
            "--orbit",
            "-30,10,0.8",
            "--width",
            "40",
            "--fov-deg",
            "20",
            "--envmap",
            "sky.exr",
            "--rotate-deg",
            "-40",
        ])
        .unwrap();
        assert_eq!(cli.camera.orbit.as_deref(), Some("-30,10,0.8"));
        assert_eq!(
            (cli.camera.width, cli.camera.height, cli.camera.fov_deg),
            (Some(40), None, 20.0)
        );
        assert_eq!(cli.lighting.envmap, Some(PathBuf::from("sky.exr")));
        assert_eq!(cli.lighting.rotate_deg, -40.0);
        let cli = Cli::try_parse_from(["t", "--view-of", "cap:front", "--height", "9"]).unwrap();
        assert_eq!(cli.camera.view_of.as_deref(), Some("cap:front"));
        // At most one of --camera, --view-of, --orbit.
        assert!(Cli::try_parse_from(["t", "--camera", "c.json", "--orbit", "0,0"]).is_err());
        assert!(Cli::try_parse_from(["t", "--view-of", "a:b", "--camera", "c.json"]).is_err());
        // The serde layout is flat field names, as in the render records.
        let json = serde_json::to_value(CameraArgs::default()).unwrap();
        assert_eq!(json["fov_deg"], 30.0);
        assert!(json["orbit"].is_null());
    }
}
