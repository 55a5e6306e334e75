//! 3D distillation points: ground-truth density and light transport at points near
//! a head's surface, from the exact mesh field (`nelf_scene::field::MeshField`, the
//! `FieldSource` whose light transport and signed distance the baker's mesh field
//! is built on).
//!
//! **`distill.bin`** (little-endian; `N` points, `D` = 384):
//!
//! | offset | bytes | what |
//! | --- | --- | --- |
//! | 0 | 8 | magic `NELFDST` and a zero byte |
//! | 8 | 4 | `u32` version, 1 |
//! | 12 | 4 | `u32` `N` |
//! | 16 | 4 | `u32` `D` = 384 |
//! | 20 | 4 | `u32` reserved, 0 |
//! | 24 | 12·N | `f32` points `[x, y, z]`, metres, world frame |
//! | … | 12·N | `f32` unit outgoing directions `ω_o` (point → viewer) the vectors are for |
//! | … | 4·N | `f32` density σ, 1/m |
//! | … | 4·N | `f32` signed distance to the surface, metres, negative inside |
//! | … | 2·D·N | `f16` light transport `T`, point-major, channel-major within a point (`T[c·128 + k]`), solid angle folded in, light frame = world frame |
//!
//! 800 bytes per point (1.6 MB for the default 2,048).

use std::path::Path;

use glam::Vec3;
use half::f16;
use nelf_format::conventions::LT_DIM;
use nelf_scene::field::{DensityProfile, FieldSource, MeshField, ViewPolicy};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;
use rayon::prelude::*;

use super::config::MAX_DISTILL_POINTS;
use crate::error::TrainError;

/// Magic bytes at the start of `distill.bin`.
pub const DISTILL_MAGIC: [u8; 8] = *b"NELFDST\0";
/// Version of `distill.bin` written.
pub const DISTILL_VERSION: u32 = 1;
const HEADER_BYTES: usize = 24;
const BYTES_PER_POINT: usize = 12 + 12 + 4 + 4 + 2 * LT_DIM;

/// Ground-truth density and light transport at a head's distillation points.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Distill {
    /// Points, metres, world frame.
    pub points_m: Vec<[f32; 3]>,
    /// Density σ at each point, 1/m (the profile of `DataConfig::distill_shell_mm`).
    pub sigma_per_m: Vec<f32>,
    /// `N × 384` light-transport floats, our layout (channel-major `T[c·128 + k]`,
    /// solid angle folded in, light frame = world frame), stored as f16.
    pub lt: Vec<f32>,
    /// Unit outgoing direction (point → viewer) each vector is for: toward one of
    /// the head's cameras (source or target), drawn per point.
    pub view_dirs: Vec<[f32; 3]>,
    /// Signed distance to the surface, metres, negative inside.
    pub signed_distance_m: Vec<f32>,
}

impl Distill {
    /// Number of points.
    pub fn len(&self) -> usize {
        self.points_m.len()
    }

    /// Whether there are no points.
    pub fn is_empty(&self) -> bool {
        self.points_m.is_empty()
    }

    /// The vector of point `i`.
    pub fn lt_of(&self, i: usize) -> &[f32] {
        &self.lt[i * LT_DIM..(i + 1) * LT_DIM]
    }

    /// The file's bytes.
    pub fn to_bytes(&self) -> Vec<u8> {
        let n = self.len();
        let mut out = Vec::with_capacity(HEADER_BYTES + n * BYTES_PER_POINT);
        out.extend_from_slice(&DISTILL_MAGIC);
        for v in [DISTILL_VERSION, n as u32, LT_DIM as u32, 0] {
            out.extend_from_slice(&v.to_le_bytes());
        }
        let floats = self
            .points_m
            .iter()
            .flatten()
            .chain(self.view_dirs.iter().flatten())
            .chain(&self.sigma_per_m)
            .chain(&self.signed_distance_m);
        for v in floats {
            out.extend_from_slice(&v.to_le_bytes());
        }
        for v in &self.lt {
            out.extend_from_slice(&f16::from_f32(*v).to_le_bytes());
        }
        out
    }

    /// Parses a file's bytes; `path` names it in errors.
    pub fn from_bytes(bytes: &[u8], path: &Path) -> Result<Self, TrainError> {
        let bad = |m: String| TrainError::file(path, m);
        if bytes.len() < HEADER_BYTES || bytes[..8] != DISTILL_MAGIC {
            return Err(bad("not a distillation file (bad magic or too short)".into()));
        }
        let word = |i: usize| u32::from_le_bytes([bytes[i], bytes[i + 1], bytes[i + 2], bytes[i + 3]]);
        let (version, n, dim) = (word(8), word(12) as usize, word(16) as usize);
        if version != DISTILL_VERSION {
            return Err(bad(format!(
                "version {version}, this reader knows {DISTILL_VERSION}"
            )));
        }
        if dim != LT_DIM {
            return Err(bad(format!("{dim} floats per vector, expected {LT_DIM}")));
        }
        if n > MAX_DISTILL_POINTS {
            return Err(bad(format!("{n} points, more than {MAX_DISTILL_POINTS}")));
        }
        let expected = HEADER_BYTES + n * BYTES_PER_POINT;
        if bytes.len() != expected {
            return Err(bad(format!(
                "{} bytes, {expected} expected for {n} points",
                bytes.len()
            )));
        }
        let mut at = HEADER_BYTES;
        let mut f32s = |count: usize| -> Vec<f32> {
            let v = bytes[at..at + 4 * count]
                .chunks_exact(4)
                .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
                .collect();
            at += 4 * count;
            v
        };
        let triples =
            |v: Vec<f32>| -> Vec<[f32; 3]> { v.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect() };
        let points_m = triples(f32s(3 * n));
        let view_dirs = triples(f32s(3 * n));
        let sigma_per_m = f32s(n);
        let signed_distance_m = f32s(n);
        let start = HEADER_BYTES + n * 32;
        let lt: Vec<f32> = bytes[start..]
            .chunks_exact(2)
            .map(|c| f16::from_le_bytes([c[0], c[1]]).to_f32())
            .collect();
        let finite = points_m
            .iter()
            .flatten()
            .chain(view_dirs.iter().flatten())
            .all(|v| v.is_finite())
            && sigma_per_m
                .iter()
                .chain(&signed_distance_m)
                .chain(&lt)
                .all(|v| v.is_finite());
        if !finite {
            return Err(bad("holds values that are not finite".into()));
        }
        Ok(Self {
            points_m,
            sigma_per_m,
            lt,
            view_dirs,
            signed_distance_m,
        })
    }

    /// Reads `distill.bin`.
    pub fn read(path: &Path) -> Result<Self, TrainError> {
        let bytes = std::fs::read(path).map_err(|e| TrainError::io(path, e))?;
        Self::from_bytes(&bytes, path)
    }
}

/// How distillation points are drawn.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DistillSettings {
    /// Number of points.
    pub points: usize,
    /// Share drawn uniformly in the bounding box grown by [`BOX_MARGIN_M`].
    pub uniform_share: f64,
    /// Standard deviation of the near-surface points' offset along the normal, metres.
    pub offset_m: f64,
    /// Width of the density shell, metres.
    pub shell_m: f32,
    /// Seed of the positions and view directions.
    pub seed: u64,
}

/// Margin around the mesh's bounds of the uniform points, metres.
pub const BOX_MARGIN_M: f32 = 0.02;

/// Draws the points and their eyes: near-surface points at area-uniform surface
/// points moved along the face normal by a normal offset, the rest uniform in the
/// grown box; each point's eye is one of `eyes`, uniformly.
fn sample_points(field: &MeshField, eyes: &[Vec3], settings: &DistillSettings) -> Vec<(Vec3, usize)> {
    let mesh = field.tracer().mesh();
    let mut rng = Pcg64::seed_from_u64(settings.seed);
    let mut cumulative = Vec::with_capacity(mesh.triangles.len());
    let mut total = 0.0f64;
    for t in 0..mesh.triangles.len() {
        let [a, b, c] = mesh.corners(t);
        total += f64::from(0.5 * (b - a).cross(c - a).length());
        cumulative.push(total);
    }
    let (lo, hi) = mesh.bounds();
    let (lo, hi) = (lo - Vec3::splat(BOX_MARGIN_M), hi + Vec3::splat(BOX_MARGIN_M));
    let uniform = ((settings.points as f64) * settings.uniform_share).round() as usize;
    let mut out = Vec::with_capacity(settings.points);
    for i in 0..settings.points {
        let eye = rng.random_range(0..eyes.len().max(1));
        let near = i >= uniform && total > 0.0;
        let x = if near {
            let pick = rng.random::<f64>() * total;
            let t = cumulative
                .partition_point(|&c| c < pick)
                .min(cumulative.len() - 1);
            let (mut u, mut v) = (rng.random::<f32>(), rng.random::<f32>());
            if u + v > 1.0 {
                (u, v) = (1.0 - u, 1.0 - v);
            }
            let [a, b, c] = mesh.corners(t);
            let p = a + u * (b - a) + v * (c - a);
            // Box–Muller normal offset.
            let r1 = rng.random::<f64>().max(f64::MIN_POSITIVE);
            let r2 = rng.random::<f64>();
            let g = (-2.0 * r1.ln()).sqrt() * (std::f64::consts::TAU * r2).cos();
            p + mesh.face_normal(t) * (g * settings.offset_m) as f32
        } else {
            Vec3::new(
                rng.random_range(lo.x..=hi.x),
                rng.random_range(lo.y..=hi.y),
                rng.random_range(lo.z..=hi.z),
            )
        };
        out.push((x, eye));
    }
    out
}

/// Ground truth at a head's distillation points: density of the profile of width
/// `settings.shell_m`, light transport toward each point's eye (one of `eyes`,
/// the head's camera centres) from the mesh field of `field`'s tracer.
pub fn distill_points(
    field: &MeshField,
    eyes: &[Vec3],
    settings: &DistillSettings,
) -> Result<Distill, String> {
    if eyes.is_empty() {
        return Err("no cameras to look from".into());
    }
    let drawn = sample_points(field, eyes, settings);
    let n = drawn.len();
    let mut out = Distill {
        points_m: drawn.iter().map(|(x, _)| x.to_array()).collect(),
        sigma_per_m: vec![0.0; n],
        lt: vec![0.0; n * LT_DIM],
        view_dirs: drawn
            .iter()
            .map(|(x, e)| (eyes[*e] - *x).normalize_or(Vec3::Z).to_array())
            .collect(),
        signed_distance_m: vec![0.0; n],
    };
    // One batch per eye (the view policy is per batch), results put back in order.
    for (e, eye) in eyes.iter().enumerate() {
        let index: Vec<usize> = (0..n).filter(|&i| drawn[i].1 == e).collect();
        if index.is_empty() {
            continue;
        }
        let points: Vec<Vec3> = index.iter().map(|&i| drawn[i].0).collect();
        let mut sigma = vec![0.0f32; points.len()];
        let mut lt = vec![0.0f32; points.len() * LT_DIM];
        field
            .evaluate(&points, &ViewPolicy::TowardPoint(*eye), &mut sigma, &mut lt)
            .map_err(|e| e.to_string())?;
        for (k, &i) in index.iter().enumerate() {
            out.sigma_per_m[i] = sigma[k];
            out.lt[i * LT_DIM..(i + 1) * LT_DIM].copy_from_slice(&lt[k * LT_DIM..(k + 1) * LT_DIM]);
        }
    }
    out.signed_distance_m = drawn
        .par_iter()
        .map(|(x, _)| field.signed_distance(*x).map_or(f32::MAX, |(d, _)| d))
        .collect();
    Ok(out)
}

/// The field a head's distillation points are evaluated on.
pub fn distill_field(tracer: nelf_scene::tracer::LtTracer, shell_m: f32) -> Result<MeshField, String> {
    MeshField::from_tracer(tracer, DensityProfile::with_shell_width(shell_m)).map_err(|e| e.to_string())
}
