//! COLMAP text models (`cameras.txt`, `images.txt`, `points3D.txt`) ↔ [`PinholeCamera`]s.
//!
//! COLMAP's camera convention is ours: OpenCV axes (x right, y down, z forward), a
//! world-to-camera pose `x_cam = R·x_world + t`, and pixel coordinates with the centre
//! of the top-left pixel at `(0.5, 0.5)`. Intrinsics therefore map 1:1. `R` is stored
//! as a unit quaternion `(QW, QX, QY, QZ)`, scalar first, Hamilton convention (the
//! usual `R = I + 2w[v]ₓ + 2[v]ₓ²` for `q = w + v`); glam's `DQuat` holds the same
//! quaternion as `(x, y, z, w)`.
//!
//! Supported camera models: `SIMPLE_PINHOLE` (`f cx cy`), `PINHOLE` (`fx fy cx cy`) and
//! `OPENCV` (`fx fy cx cy k1 k2 p1 p2`) when all four distortion coefficients are zero.
//! Anything else is rejected with the file, line and model: undistort first
//! (`colmap image_undistorter` writes a `PINHOLE` model).
//!
//! COLMAP reconstructions have an arbitrary scale; [`read_colmap_text`] takes the
//! metres per model unit. The 3D points are not read.

use std::collections::HashMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use glam::{DMat3, DQuat, DVec3};

use crate::conventions::PinholeCamera;
use crate::io_error::{FileIoError, IoResultExt};

/// Errors from reading or writing a COLMAP text model. Parse errors name the file and
/// the 1-based line.
#[derive(Debug, thiserror::Error)]
pub enum ColmapError {
    /// Reading or writing a file failed (a missing `cameras.txt` or `images.txt` included).
    #[error(transparent)]
    Io(#[from] FileIoError),
    /// A line does not have the expected fields.
    #[error("{path}:{line}: {message}")]
    Syntax {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// What was expected.
        message: String,
    },
    /// A camera model other than `SIMPLE_PINHOLE`, `PINHOLE`, `OPENCV`.
    #[error(
        "{path}:{line}: camera model {model} is not supported (SIMPLE_PINHOLE, PINHOLE, or OPENCV \
         with zero distortion); undistort the images first (colmap image_undistorter)"
    )]
    UnsupportedModel {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// The model name as written.
        model: String,
    },
    /// An `OPENCV` camera with non-zero distortion.
    #[error(
        "{path}:{line}: camera {camera_id} has model OPENCV with non-zero distortion \
         (k1 k2 p1 p2 = {distortion:?}); undistort the images first (colmap image_undistorter)"
    )]
    Distorted {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// The camera's id.
        camera_id: u32,
        /// `[k1, k2, p1, p2]`.
        distortion: [f64; 4],
    },
    /// A number is NaN or infinite.
    #[error("{path}:{line}: {field} = {value} is not finite")]
    NonFinite {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// Which field.
        field: &'static str,
        /// Its value.
        value: f64,
    },
    /// An image refers to a camera id that `cameras.txt` does not define.
    #[error("{path}:{line}: image {image_id} uses camera {camera_id}, which cameras.txt does not define")]
    UnknownCamera {
        /// The `images.txt` file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// The image's id.
        image_id: u32,
        /// The missing camera id.
        camera_id: u32,
    },
    /// A quaternion that is (nearly) zero.
    #[error(
        "{path}:{line}: quaternion (QW QX QY QZ) = {quaternion:?} has norm {norm:e}; it cannot be normalised"
    )]
    BadQuaternion {
        /// The `images.txt` file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// `[qw, qx, qy, qz]` as written.
        quaternion: [f64; 4],
        /// Its Euclidean norm.
        norm: f64,
    },
    /// A camera id, image id or image name appears twice.
    #[error("{path}:{line}: {what} {id} was already defined on line {first_line}")]
    Duplicate {
        /// The file.
        path: PathBuf,
        /// 1-based line number of the repeat.
        line: usize,
        /// `camera id`, `image id` or `image name`.
        what: &'static str,
        /// The repeated id or name.
        id: String,
        /// Line of the first definition.
        first_line: usize,
    },
    /// Camera parameters out of range (zero size, focal length ≤ 0).
    #[error("{path}:{line}: invalid camera: {reason}")]
    InvalidCamera {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// What is wrong.
        reason: String,
    },
    /// `metres_per_unit` is not a positive finite number.
    #[error("metres_per_unit = {0} must be positive and finite")]
    BadScale(f64),
    /// A camera or name given to [`write_colmap_text`] cannot be written.
    #[error("cannot write image {name:?} to a COLMAP model: {reason}")]
    InvalidInput {
        /// The image name.
        name: String,
        /// What is wrong.
        reason: String,
    },
}

/// Intrinsics of one `cameras.txt` entry.
#[derive(Debug, Clone, Copy)]
struct Intrinsics {
    width: u32,
    height: u32,
    fx: f64,
    fy: f64,
    cx: f64,
    cy: f64,
}

/// Splits off the first `n` whitespace-separated fields; the remainder is returned trimmed.
fn split_fields(line: &str, n: usize) -> (Vec<&str>, &str) {
    let mut fields = Vec::with_capacity(n);
    let mut rest = line;
    for _ in 0..n {
        rest = rest.trim_start();
        if rest.is_empty() {
            break;
        }
        let end = rest.find(char::is_whitespace).unwrap_or(rest.len());
        fields.push(&rest[..end]);
        rest = &rest[end..];
    }
    (fields, rest.trim())
}

/// Reads a text file, dropping a UTF-8 byte-order mark.
fn read_text(path: &Path) -> Result<String, ColmapError> {
    let text = std::fs::read_to_string(path).with_path(path)?;
    Ok(match text.strip_prefix('\u{feff}') {
        Some(rest) => rest.to_string(),
        None => text,
    })
}

/// A line-aware field parser for one file.
struct Fields<'a> {
    path: &'a Path,
    line: usize,
}

impl Fields<'_> {
    fn syntax(&self, message: String) -> ColmapError {
        ColmapError::Syntax {
            path: self.path.to_path_buf(),
            line: self.line,
            message,
        }
    }

    fn int(&self, token: &str, field: &'static str) -> Result<u32, ColmapError> {
        token
            .parse::<u32>()
            .map_err(|_| self.syntax(format!("{field} {token:?} is not a non-negative integer")))
    }

    fn float(&self, token: &str, field: &'static str) -> Result<f64, ColmapError> {
        let value = token
            .parse::<f64>()
            .map_err(|_| self.syntax(format!("{field} {token:?} is not a number")))?;
        if value.is_finite() {
            Ok(value)
        } else {
            Err(ColmapError::NonFinite {
                path: self.path.to_path_buf(),
                line: self.line,
                field,
                value,
            })
        }
    }
}

/// Lines that carry data: 1-based number and trimmed text, comments and blank lines dropped.
fn data_lines(text: &str) -> impl Iterator<Item = (usize, &str)> {
    text.lines()
        .enumerate()
        .map(|(i, l)| (i + 1, l.trim()))
        .filter(|(_, l)| !l.is_empty() && !l.starts_with('#'))
}

fn parse_cameras(path: &Path, text: &str) -> Result<HashMap<u32, (usize, Intrinsics)>, ColmapError> {
    let mut cameras: HashMap<u32, (usize, Intrinsics)> = HashMap::new();
    for (line, content) in data_lines(text) {
        let f = Fields { path, line };
        let tokens: Vec<&str> = content.split_whitespace().collect();
        if tokens.len() < 4 {
            return Err(f.syntax(format!(
                "expected CAMERA_ID MODEL WIDTH HEIGHT PARAMS..., found {} fields",
                tokens.len()
            )));
        }
        let camera_id = f.int(tokens[0], "CAMERA_ID")?;
        let model = tokens[1];
        let n_params = match model {
            "SIMPLE_PINHOLE" => 3,
            "PINHOLE" => 4,
            "OPENCV" => 8,
            _ => {
                return Err(ColmapError::UnsupportedModel {
                    path: path.to_path_buf(),
                    line,
                    model: model.to_string(),
                });
            }
        };
        let width = f.int(tokens[2], "WIDTH")?;
        let height = f.int(tokens[3], "HEIGHT")?;
        let params = &tokens[4..];
        if params.len() != n_params {
            return Err(f.syntax(format!(
                "model {model} takes {n_params} parameters, found {}",
                params.len()
            )));
        }
        let p = params
            .iter()
            .map(|t| f.float(t, "camera parameter"))
            .collect::<Result<Vec<f64>, _>>()?;
        let (fx, fy, cx, cy) = match model {
            "SIMPLE_PINHOLE" => (p[0], p[0], p[1], p[2]),
            _ => (p[0], p[1], p[2], p[3]),
        };
        if model == "OPENCV" && p[4..].iter().any(|&k| k != 0.0) {
            return Err(ColmapError::Distorted {
                path: path.to_path_buf(),
                line,
                camera_id,
                distortion: [p[4], p[5], p[6], p[7]],
            });
        }
        if width == 0 || height == 0 {
            return Err(ColmapError::InvalidCamera {
                path: path.to_path_buf(),
                line,
                reason: format!("image size {width}×{height} must be positive"),
            });
        }
        if fx <= 0.0 || fy <= 0.0 {
            return Err(ColmapError::InvalidCamera {
                path: path.to_path_buf(),
                line,
                reason: format!("focal lengths fx = {fx}, fy = {fy} must be positive"),
            });
        }
        let intrinsics = Intrinsics {
            width,
            height,
            fx,
            fy,
            cx,
            cy,
        };
        if let Some(&(first_line, _)) = cameras.get(&camera_id) {
            return Err(ColmapError::Duplicate {
                path: path.to_path_buf(),
                line,
                what: "camera id",
                id: camera_id.to_string(),
                first_line,
            });
        }
        cameras.insert(camera_id, (line, intrinsics));
    }
    Ok(cameras)
}

/// Checks a 2D-points line: empty, or `X Y POINT3D_ID` triples.
fn check_points_line(f: &Fields<'_>, content: &str, image_id: u32) -> Result<(), ColmapError> {
    let tokens: Vec<&str> = content.split_whitespace().collect();
    let expected = || {
        f.syntax(format!(
            "expected the 2D-points line of image {image_id} (empty, or X Y POINT3D_ID triples) \
             right after its image line"
        ))
    };
    if tokens.len() % 3 != 0 {
        return Err(expected());
    }
    for triple in tokens.chunks_exact(3) {
        let numbers_ok = triple[0].parse::<f64>().is_ok()
            && triple[1].parse::<f64>().is_ok()
            && triple[2].parse::<i64>().is_ok();
        if !numbers_ok {
            return Err(expected());
        }
    }
    Ok(())
}

/// Reads `dir/cameras.txt` and `dir/images.txt` (a COLMAP text model) into one
/// `(image name, camera)` per image, ordered by `IMAGE_ID`. Translations are multiplied
/// by `metres_per_unit`; quaternions are normalised. `points3D.txt` is not read.
pub fn read_colmap_text(
    dir: impl AsRef<Path>,
    metres_per_unit: f64,
) -> Result<Vec<(String, PinholeCamera)>, ColmapError> {
    if !(metres_per_unit.is_finite() && metres_per_unit > 0.0) {
        return Err(ColmapError::BadScale(metres_per_unit));
    }
    let dir = dir.as_ref();
    let cameras_path = dir.join("cameras.txt");
    let cameras = parse_cameras(&cameras_path, &read_text(&cameras_path)?)?;
    let images_path = dir.join("images.txt");
    let text = read_text(&images_path)?;
    let path = images_path.as_path();

    let mut seen_ids: HashMap<u32, usize> = HashMap::new();
    let mut seen_names: HashMap<String, usize> = HashMap::new();
    let mut images: Vec<(u32, String, PinholeCamera)> = Vec::new();
    let lines: Vec<&str> = text.lines().collect();
    let mut index = 0;
    while index < lines.len() {
        let line = index + 1;
        let content = lines[index].trim();
        index += 1;
        if content.is_empty() || content.starts_with('#') {
            continue;
        }
        let f = Fields { path, line };
        let (fields, name) = split_fields(content, 9);
        if fields.len() < 9 || name.is_empty() {
            return Err(f.syntax(
                "expected IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME (then a 2D-points line)".into(),
            ));
        }
        let image_id = f.int(fields[0], "IMAGE_ID")?;
        let qw = f.float(fields[1], "QW")?;
        let qx = f.float(fields[2], "QX")?;
        let qy = f.float(fields[3], "QY")?;
        let qz = f.float(fields[4], "QZ")?;
        let tx = f.float(fields[5], "TX")?;
        let ty = f.float(fields[6], "TY")?;
        let tz = f.float(fields[7], "TZ")?;
        let camera_id = f.int(fields[8], "CAMERA_ID")?;

        // The next line, whatever it holds, is this image's 2D points (it may be empty or absent at EOF).
        if index < lines.len() {
            let points = Fields {
                path,
                line: index + 1,
            };
            check_points_line(&points, lines[index].trim(), image_id)?;
            index += 1;
        }

        let norm = (qw * qw + qx * qx + qy * qy + qz * qz).sqrt();
        if !(norm > 1e-8 && norm.is_finite()) {
            return Err(ColmapError::BadQuaternion {
                path: path.to_path_buf(),
                line,
                quaternion: [qw, qx, qy, qz],
                norm,
            });
        }
        let rotation = DMat3::from_quat(DQuat::from_xyzw(qx / norm, qy / norm, qz / norm, qw / norm));
        let Some(&(_, intrinsics)) = cameras.get(&camera_id) else {
            return Err(ColmapError::UnknownCamera {
                path: path.to_path_buf(),
                line,
                image_id,
                camera_id,
            });
        };
        if let Some(&first_line) = seen_ids.get(&image_id) {
            return Err(ColmapError::Duplicate {
                path: path.to_path_buf(),
                line,
                what: "image id",
                id: image_id.to_string(),
                first_line,
            });
        }
        if let Some(&first_line) = seen_names.get(name) {
            return Err(ColmapError::Duplicate {
                path: path.to_path_buf(),
                line,
                what: "image name",
                id: name.to_string(),
                first_line,
            });
        }
        seen_ids.insert(image_id, line);
        seen_names.insert(name.to_string(), line);
        let camera = PinholeCamera {
            width: intrinsics.width,
            height: intrinsics.height,
            fx: intrinsics.fx,
            fy: intrinsics.fy,
            cx: intrinsics.cx,
            cy: intrinsics.cy,
            rotation,
            translation: DVec3::new(tx, ty, tz) * metres_per_unit,
        };
        camera.validate().map_err(|e| ColmapError::InvalidCamera {
            path: path.to_path_buf(),
            line,
            reason: e.to_string(),
        })?;
        images.push((image_id, name.to_string(), camera));
    }
    images.sort_by_key(|(id, _, _)| *id);
    Ok(images
        .into_iter()
        .map(|(_, name, camera)| (name, camera))
        .collect())
}

/// Writes `text` to `path` atomically ([`crate::atomic`]).
fn write_atomically(path: &Path, text: &str) -> Result<(), ColmapError> {
    crate::atomic::write_bytes_atomically(path, text.as_bytes())
        .map_err(|source| ColmapError::Io(FileIoError::new(path.to_path_buf(), source)))
}

/// Writes a COLMAP text model of `views` into `dir` (created if needed): one `PINHOLE`
/// camera per image (`CAMERA_ID` = `IMAGE_ID` = position + 1), translations in metres
/// (model unit = 1 m), empty 2D-points lines and an empty `points3D.txt`, so COLMAP
/// itself can open the model. Names must be non-empty, unique and free of whitespace
/// (COLMAP splits on it). Numbers are written in Rust's shortest round-trip form, so
/// intrinsics and translations read back exactly; rotations go through a quaternion
/// (scalar written non-negative) and read back within ~1e-15.
pub fn write_colmap_text(
    dir: impl AsRef<Path>,
    views: &[(String, PinholeCamera)],
) -> Result<(), ColmapError> {
    let dir = dir.as_ref();
    let mut names = std::collections::HashSet::new();
    for (name, camera) in views {
        let invalid = |reason: String| ColmapError::InvalidInput {
            name: name.clone(),
            reason,
        };
        if name.is_empty() || name.chars().any(char::is_whitespace) {
            return Err(invalid(
                "names must be non-empty and contain no whitespace".into(),
            ));
        }
        if !names.insert(name.as_str()) {
            return Err(invalid("the name is used twice".into()));
        }
        camera.validate().map_err(|e| invalid(e.to_string()))?;
    }

    let n = views.len();
    let mut cameras = String::new();
    let mut images = String::new();
    // `fmt::Write` for `String` cannot fail.
    let _ = writeln!(cameras, "# Camera list with one line of data per camera:");
    let _ = writeln!(cameras, "#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]");
    let _ = writeln!(cameras, "# Number of cameras: {n}");
    let _ = writeln!(images, "# Image list with two lines of data per image:");
    let _ = writeln!(
        images,
        "#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME"
    );
    let _ = writeln!(images, "#   POINTS2D[] as (X, Y, POINT3D_ID)");
    let _ = writeln!(images, "# Number of images: {n}, mean observations per image: 0");
    for (i, (name, camera)) in views.iter().enumerate() {
        let id = i + 1;
        let _ = writeln!(
            cameras,
            "{id} PINHOLE {} {} {} {} {} {}",
            camera.width, camera.height, camera.fx, camera.fy, camera.cx, camera.cy
        );
        let mut q = DQuat::from_mat3(&camera.rotation).normalize();
        if q.w < 0.0 {
            q = -q;
        }
        let t = camera.translation;
        let _ = writeln!(
            images,
            "{id} {} {} {} {} {} {} {} {id} {name}",
            q.w, q.x, q.y, q.z, t.x, t.y, t.z
        );
        let _ = writeln!(images);
    }
    let points = "# 3D point list with one line of data per point:\n\
                  #   POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)\n\
                  # Number of points: 0, mean track length: 0\n";

    std::fs::create_dir_all(dir).with_path(dir)?;
    write_atomically(&dir.join("cameras.txt"), &cameras)?;
    write_atomically(&dir.join("images.txt"), &images)?;
    write_atomically(&dir.join("points3D.txt"), points)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn split_fields_keeps_name_with_spaces() {
        let (f, rest) = split_fields("1 2  3\tfour five six", 3);
        assert_eq!(f, ["1", "2", "3"]);
        assert_eq!(rest, "four five six");
        let (f, rest) = split_fields("1 2", 3);
        assert_eq!(f.len(), 2);
        assert_eq!(rest, "");
    }

    #[test]
    fn quaternion_order_matches_colmap() {
        // A 90° turn about +z: q = (cos 45°, 0, 0, sin 45°) maps x to y.
        let h = std::f64::consts::FRAC_1_SQRT_2;
        let r = DMat3::from_quat(DQuat::from_xyzw(0.0, 0.0, h, h));
        assert!((r * DVec3::X).abs_diff_eq(DVec3::Y, 1e-15));
    }
}
