//! The in-memory `.nelf` asset: a sparse grid of 8³ cell-centred bricks, each voxel
//! holding a density σ (1/m) and the PCA coefficients of its light-transport vector.
//!
//! Reconstruction (SPEC.md, "Reconstruction"): for voxel `v` with coefficients
//! `c_v[k]`, the light-transport vector is `T = mean + Σ_k c_v[k] · B_k` (384 numbers,
//! channel-major `c·128 + row·16 + col`, texel solid angle folded in), and the
//! radiance it sends under an 8 × 16 environment map `L` in the asset's light frame
//! is `radiance_c = Σ_k T[c·128 + k] · L[k][c]` ([`crate::conventions::shade`]).
//!
//! The asset holds exactly what the file holds (density as `f16`, coefficients
//! quantized), so writing and reading it back gives an equal asset.

use glam::{DMat3, DVec3};
use half::f16;

use crate::conventions::{LT_DIM, VIEW_HARMONICS, is_rotation, view_harmonics};
use crate::error::{FormatError, Result};
use crate::grid::{BRICK_SIZE, BRICK_VOXELS, FINE_DENSITY_FACTORS};
pub use crate::grid::{GridGeometry, brick_order_key, local_voxel_coords, local_voxel_index};

/// The PCA model of light-transport vectors: `T ≈ mean + Σ_k c_k · basis[k]`.
#[derive(Debug, Clone, PartialEq)]
pub struct PcaModel {
    /// Mean vector, [`LT_DIM`] numbers (channel-major, solid angle folded in).
    pub mean: Vec<f32>,
    /// `K` basis vectors of [`LT_DIM`] numbers each, component `k` at `k·384 .. (k+1)·384`.
    pub basis: Vec<f32>,
}

impl PcaModel {
    /// Rank `K` (number of basis vectors).
    pub fn rank(&self) -> usize {
        self.basis.len() / LT_DIM
    }

    /// Basis vector `k`.
    pub fn component(&self, k: usize) -> &[f32] {
        &self.basis[k * LT_DIM..(k + 1) * LT_DIM]
    }

    /// `out = mean + Σ_k coefficients[k] · basis[k]`, summed in `f32` in order `k = 0..K`.
    pub fn reconstruct_into(&self, coefficients: &[f32], out: &mut [f32]) {
        out[..LT_DIM].copy_from_slice(&self.mean);
        for (k, &c) in coefficients.iter().enumerate().take(self.rank()) {
            for (o, b) in out[..LT_DIM].iter_mut().zip(self.component(k)) {
                *o += c * b;
            }
        }
    }

    /// The model keeping only the first `rank` components.
    #[must_use]
    pub fn truncated(&self, rank: usize) -> Self {
        Self {
            mean: self.mean.clone(),
            basis: self.basis[..rank.min(self.rank()) * LT_DIM].to_vec(),
        }
    }

    /// Checks lengths (`mean` 384, `basis` a positive multiple of 384 up to 384²) and finiteness.
    pub fn validate(&self) -> Result<()> {
        if self.mean.len() != LT_DIM {
            return Err(FormatError::InvalidAsset(format!(
                "PCA mean has {} values, must have {LT_DIM}",
                self.mean.len()
            )));
        }
        if self.basis.len() % LT_DIM != 0 {
            return Err(FormatError::InvalidAsset(format!(
                "PCA basis has {} values, not a multiple of {LT_DIM}",
                self.basis.len()
            )));
        }
        let rank = self.rank();
        if rank == 0 || rank > LT_DIM {
            return Err(FormatError::BadRank {
                rank: rank as u64,
                max: LT_DIM,
            });
        }
        if let Some(i) = self.mean.iter().position(|v| !v.is_finite()) {
            return Err(FormatError::NonFinite {
                what: format!("PCA mean element {i}"),
            });
        }
        if let Some(i) = self.basis.iter().position(|v| !v.is_finite()) {
            return Err(FormatError::NonFinite {
                what: format!("PCA basis component {} element {}", i / LT_DIM, i % LT_DIM),
            });
        }
        Ok(())
    }
}

/// How PCA coefficients are stored.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub enum CoefficientEncoding {
    /// One byte per coefficient, affine per component: `c = offset_k + scale_k · code`.
    U8Affine,
    /// IEEE 754 binary16 per coefficient.
    F16,
}

impl CoefficientEncoding {
    /// Bytes per stored coefficient.
    pub const fn bytes_per_value(self) -> usize {
        match self {
            Self::U8Affine => 1,
            Self::F16 => 2,
        }
    }

    /// Number in the header's `coefficient_encoding` field.
    pub const fn to_u32(self) -> u32 {
        match self {
            Self::U8Affine => 1,
            Self::F16 => 2,
        }
    }

    /// Encoding with header number `v`.
    pub const fn from_u32(v: u32) -> Option<Self> {
        match v {
            1 => Some(Self::U8Affine),
            2 => Some(Self::F16),
            _ => None,
        }
    }

    /// Short name (`u8-affine`, `f16`).
    pub const fn name(self) -> &'static str {
        match self {
            Self::U8Affine => "u8-affine",
            Self::F16 => "f16",
        }
    }
}

/// Quantized PCA coefficients of every voxel, voxel-major: voxel `v`, component `k`
/// at `v·K + k`; voxels in brick order, 512 per brick, x fastest inside a brick.
#[derive(Debug, Clone, PartialEq)]
pub enum Coefficients {
    /// 8-bit affine per component: `c[v·K + k] = offset[k] + scale[k] · codes[v·K + k]` (in `f32`).
    U8Affine {
        /// Rank `K`.
        rank: usize,
        /// Per-component step, `(max_k − min_k) / 255`, ≥ 0.
        scale: Vec<f32>,
        /// Per-component value of code 0 (`min_k`).
        offset: Vec<f32>,
        /// Codes, voxel-major.
        codes: Vec<u8>,
    },
    /// binary16 values, voxel-major.
    F16 {
        /// Rank `K`.
        rank: usize,
        /// Values, voxel-major.
        values: Vec<f16>,
    },
}

impl Coefficients {
    /// Quantizes `values` (voxel-major, `rank` per voxel) with `encoding`.
    ///
    /// `U8Affine` gives component `k` the step `scale_k = (max_k − min_k) / 254` and
    /// the offset `scale_k · ⌊min_k / scale_k⌋` (a multiple of the step, so a
    /// coefficient 0 — a voxel whose vector is the PCA mean — is stored exactly when
    /// `min_k ≤ 0 ≤ max_k`), and `code = round((c − offset_k) / scale_k)` in `0..=255`;
    /// the error per coefficient is at most `scale_k / 2` (plus `f32` rounding). `F16`
    /// rounds to nearest binary16: relative error ≤ 2⁻¹¹ for |c| ≥ 2⁻¹⁴, absolute ≤
    /// 2⁻²⁵ below; |c| > 65504 is an error.
    pub fn quantize(values: &[f32], rank: usize, encoding: CoefficientEncoding) -> Result<Self> {
        Self::quantize_with_min_step(values, rank, encoding, 0.0)
    }

    /// [`Self::quantize`] whose 8-bit steps are at least `min_step`:
    /// `scale_k = max((max_k − min_k) / 254, min_step)`. With an orthonormal basis
    /// the squared reconstruction error of a vector is the sum over components of
    /// the coefficient errors, so one step for every component (reverse
    /// water-filling) spends bits where the error is: a component whose spread is a
    /// few steps takes a few codes and compresses to almost nothing, where its own
    /// range over 255 codes would store noise. Ignored for `F16`.
    pub fn quantize_with_min_step(
        values: &[f32],
        rank: usize,
        encoding: CoefficientEncoding,
        min_step: f32,
    ) -> Result<Self> {
        if !(min_step.is_finite() && min_step >= 0.0) {
            return Err(FormatError::InvalidValue {
                what: "minimum quantization step".into(),
                reason: format!("{min_step} must be finite and ≥ 0"),
            });
        }
        if rank == 0 || rank > LT_DIM {
            return Err(FormatError::BadRank {
                rank: rank as u64,
                max: LT_DIM,
            });
        }
        if values.len() % rank != 0 {
            return Err(FormatError::InvalidAsset(format!(
                "{} coefficient values are not a multiple of rank {rank}",
                values.len()
            )));
        }
        if let Some(i) = values.iter().position(|v| !v.is_finite()) {
            return Err(FormatError::NonFinite {
                what: format!("coefficient of voxel {} component {}", i / rank, i % rank),
            });
        }
        match encoding {
            CoefficientEncoding::U8Affine => {
                let mut min = vec![f32::INFINITY; rank];
                let mut max = vec![f32::NEG_INFINITY; rank];
                for voxel in values.chunks_exact(rank) {
                    for k in 0..rank {
                        min[k] = min[k].min(voxel[k]);
                        max[k] = max[k].max(voxel[k]);
                    }
                }
                let lo: Vec<f32> = min.iter().map(|&m| if m.is_finite() { m } else { 0.0 }).collect();
                let scale: Vec<f32> = (0..rank)
                    .map(|k| {
                        let range = f64::from(max[k]) - f64::from(lo[k]);
                        if range.is_finite() && range > 0.0 {
                            ((range / 254.0) as f32).max(min_step)
                        } else {
                            0.0
                        }
                    })
                    .collect();
                // Offsets on the step lattice: (max − offset) / scale ≤ 254 + 1.
                let offset: Vec<f32> = (0..rank)
                    .map(|k| {
                        if scale[k] > 0.0 {
                            let s = f64::from(scale[k]);
                            ((f64::from(lo[k]) / s).floor() * s) as f32
                        } else {
                            lo[k]
                        }
                    })
                    .collect();
                if let Some(k) = scale.iter().position(|s| !s.is_finite()) {
                    return Err(FormatError::NonFinite {
                        what: format!("8-bit scale of component {k}"),
                    });
                }
                let codes = values
                    .chunks_exact(rank)
                    .flat_map(|voxel| {
                        let (scale, offset) = (&scale, &offset);
                        voxel.iter().enumerate().map(move |(k, &c)| {
                            if scale[k] > 0.0 {
                                ((f64::from(c) - f64::from(offset[k])) / f64::from(scale[k]))
                                    .round()
                                    .clamp(0.0, 255.0) as u8
                            } else {
                                0
                            }
                        })
                    })
                    .collect();
                Ok(Self::U8Affine {
                    rank,
                    scale,
                    offset,
                    codes,
                })
            }
            CoefficientEncoding::F16 => {
                if let Some(i) = values.iter().position(|v| v.abs() > f16::MAX.to_f32()) {
                    return Err(FormatError::InvalidValue {
                        what: format!("coefficient of voxel {} component {}", i / rank, i % rank),
                        reason: format!("{} exceeds the f16 range ±65504", values[i]),
                    });
                }
                Ok(Self::F16 {
                    rank,
                    values: values.iter().map(|&v| f16::from_f32(v)).collect(),
                })
            }
        }
    }

    /// Rank `K`.
    pub fn rank(&self) -> usize {
        match self {
            Self::U8Affine { rank, .. } | Self::F16 { rank, .. } => *rank,
        }
    }

    /// The encoding.
    pub fn encoding(&self) -> CoefficientEncoding {
        match self {
            Self::U8Affine { .. } => CoefficientEncoding::U8Affine,
            Self::F16 { .. } => CoefficientEncoding::F16,
        }
    }

    /// Stored values (`voxels × K`).
    pub fn len(&self) -> usize {
        match self {
            Self::U8Affine { codes, .. } => codes.len(),
            Self::F16 { values, .. } => values.len(),
        }
    }

    /// Whether no voxel is stored.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Voxels stored.
    pub fn voxel_count(&self) -> usize {
        self.len() / self.rank().max(1)
    }

    /// Dequantized coefficients of voxel `voxel` into `out[..K]`.
    pub fn voxel_f32(&self, voxel: usize, out: &mut [f32]) {
        let rank = self.rank();
        let range = voxel * rank..(voxel + 1) * rank;
        match self {
            Self::U8Affine {
                scale, offset, codes, ..
            } => {
                for (k, (o, &code)) in out.iter_mut().zip(&codes[range]).enumerate() {
                    *o = offset[k] + scale[k] * f32::from(code);
                }
            }
            Self::F16 { values, .. } => {
                for (o, v) in out.iter_mut().zip(&values[range]) {
                    *o = v.to_f32();
                }
            }
        }
    }

    /// All dequantized coefficients, voxel-major.
    pub fn to_f32(&self) -> Vec<f32> {
        let rank = self.rank();
        let mut out = vec![0.0f32; self.len()];
        for (v, chunk) in out.chunks_exact_mut(rank.max(1)).enumerate() {
            self.voxel_f32(v, chunk);
        }
        out
    }

    /// Largest error of component `k` that [`Coefficients::quantize`] guarantees for
    /// in-range input: `scale_k / 2` (+ `f32` rounding) for `U8Affine`; `None` for `F16`,
    /// whose bound is relative (2⁻¹¹ |c|, or 2⁻²⁵ absolute for |c| < 2⁻¹⁴).
    pub fn abs_error_bound(&self, k: usize) -> Option<f32> {
        match self {
            Self::U8Affine { scale, offset, .. } => {
                let magnitude = offset[k].abs() + 255.0 * scale[k];
                Some(0.5 * scale[k] + 4.0 * f32::EPSILON * magnitude)
            }
            Self::F16 { .. } => None,
        }
    }

    /// Stored bytes of all coefficient values (without parameters), voxel-major.
    pub(crate) fn value_bytes(&self) -> Vec<u8> {
        match self {
            Self::U8Affine { codes, .. } => codes.clone(),
            Self::F16 { values, .. } => values.iter().flat_map(|v| v.to_bits().to_le_bytes()).collect(),
        }
    }

    /// Appends voxels from their stored bytes (`u8` codes or little-endian `f16`s, as
    /// [`Self::value_bytes`] writes them), keeping rank and parameters.
    pub(crate) fn extend_from_stored(&mut self, stored: &[u8]) {
        match self {
            Self::U8Affine { codes, .. } => codes.extend_from_slice(stored),
            Self::F16 { values, .. } => values.extend(
                stored
                    .chunks_exact(2)
                    .map(|b| f16::from_bits(u16::from_le_bytes([b[0], b[1]]))),
            ),
        }
    }

    /// Checks stored values: every `f16` finite (any 8-bit code is valid). `first_voxel`
    /// numbers the voxels and `section` names the section in the message.
    pub(crate) fn check_stored(&self, stored: &[u8], first_voxel: usize, section: &str) -> Result<()> {
        let rank = self.rank().max(1);
        if let Self::F16 { .. } = self {
            for (i, b) in stored.chunks_exact(2).enumerate() {
                if !f16::from_bits(u16::from_le_bytes([b[0], b[1]])).is_finite() {
                    return Err(FormatError::NonFinite {
                        what: format!(
                            "section {section} voxel {} component {}",
                            first_voxel + i / rank,
                            i % rank
                        ),
                    });
                }
            }
        }
        Ok(())
    }

    /// Dequantizes stored values (see [`Self::check_stored`], which this applies first)
    /// with this encoding and its 8-bit parameters: `offset_k + scale_k · code` in `f32`.
    pub(crate) fn dequantize_stored(
        &self,
        stored: &[u8],
        first_voxel: usize,
        section: &str,
    ) -> Result<Vec<f32>> {
        self.check_stored(stored, first_voxel, section)?;
        let rank = self.rank().max(1);
        Ok(match self {
            Self::U8Affine { scale, offset, .. } => stored
                .iter()
                .enumerate()
                .map(|(i, &code)| offset[i % rank] + scale[i % rank] * f32::from(code))
                .collect(),
            Self::F16 { .. } => stored
                .chunks_exact(2)
                .map(|b| f16::from_bits(u16::from_le_bytes([b[0], b[1]])).to_f32())
                .collect(),
        })
    }

    /// Checks rank, length, 8-bit parameters (named as section `params`) and finite `f16`
    /// values (named as section `values`).
    fn validate(&self, voxels: usize, params: &str, values: &str) -> Result<()> {
        let rank = self.rank();
        if rank == 0 || rank > LT_DIM {
            return Err(FormatError::BadRank {
                rank: rank as u64,
                max: LT_DIM,
            });
        }
        if self.len() != voxels * rank {
            return Err(FormatError::InvalidAsset(format!(
                "{} coefficient values for {voxels} voxels of rank {rank}",
                self.len()
            )));
        }
        match self {
            Self::U8Affine { scale, offset, .. } => {
                if scale.len() != rank || offset.len() != rank {
                    return Err(FormatError::InvalidAsset(format!(
                        "8-bit parameters have {} scales and {} offsets for rank {rank}",
                        scale.len(),
                        offset.len()
                    )));
                }
                validate_quant_params(scale, offset, params)
            }
            Self::F16 { values: stored, .. } => match stored.iter().position(|v| !v.is_finite()) {
                Some(i) => Err(FormatError::NonFinite {
                    what: format!("section {values} voxel {} component {}", i / rank, i % rank),
                }),
                None => Ok(()),
            },
        }
    }
}

/// Checks 8-bit dequantisation parameters: finite offsets, finite non-negative scales,
/// and a finite largest value `offset + 255·scale`; `section` (`QPRM`, `VDEP`) names them.
pub(crate) fn validate_quant_params(scale: &[f32], offset: &[f32], section: &str) -> Result<()> {
    for (k, (&s, &o)) in scale.iter().zip(offset).enumerate() {
        if !(s.is_finite() && o.is_finite() && (o + 255.0 * s).is_finite()) {
            return Err(FormatError::NonFinite {
                what: format!("section {section} component {k} (scale {s}, offset {o})"),
            });
        }
        if s < 0.0 {
            return Err(FormatError::InvalidValue {
                what: format!("section {section} component {k}"),
                reason: format!("negative scale {s}"),
            });
        }
    }
    Ok(())
}

/// Encodes densities σ (1/m) as binary16, round to nearest. Magnitudes above 65504
/// 1/m are clamped to ±65504 (already opaque at any voxel size ≥ 0.1 mm); non-finite
/// values are an error. Negative values are allowed: the density a renderer uses is
/// `max(0, trilinear(σ))` (SPEC §8), and the writer marks such files with
/// [`crate::spec::FLAG_SIGNED_DENSITY`]. Relative error ≤ 2⁻¹¹ (≈ 4.9·10⁻⁴) for
/// |σ| ≥ 6.1·10⁻⁵ 1/m, absolute ≤ 3·10⁻⁸ 1/m below.
pub fn encode_density(sigma_per_m: &[f32]) -> Result<Vec<f16>> {
    let max = f16::MAX.to_f32();
    sigma_per_m
        .iter()
        .enumerate()
        .map(|(i, &s)| {
            if s.is_finite() {
                Ok(f16::from_f32(s.clamp(-max, max)))
            } else {
                Err(FormatError::InvalidValue {
                    what: format!("density of voxel {i}"),
                    reason: format!("{s} must be finite"),
                })
            }
        })
        .collect()
}

/// Whether any stored density is negative (the file then needs
/// [`crate::spec::FLAG_SIGNED_DENSITY`]).
pub fn has_negative_density(density: &[f16]) -> bool {
    density.iter().any(|d| d.to_f32() < 0.0)
}

/// The view-dependent part of the light transport (format 1.2, optional sections
/// `VDEP` and `VCOF`, SPEC.md §6). With it, the transport a voxel sends toward a viewer
/// in world direction `ω` (unit, from the voxel toward the eye) is
///
/// `T(x, ω) = m + Σ_k c_k(x) B_k + Σ_j Y_j(ω) Σ_i d_ji(x) V_i`,
///
/// the first two terms being the asset's PCA part (the view-independent mean over the
/// directions it was seen from), `Y_j(ω) = Σ_l lobes[j·9 + l] · y_l(ω)` a lobe built from
/// the real spherical harmonics of degrees 0–2 ([`crate::conventions::view_harmonics`]),
/// `V_i` the view basis (no mean) and `d_ji(x)` per-voxel coefficients, stored at index
/// `j·K_v + i` among the voxel's `J·K_v`. A reader that ignores it renders the PCA part,
/// which is the view-averaged asset.
#[derive(Debug, Clone, PartialEq)]
pub struct ViewDependence {
    /// `J × 9` lobe weights over the degree-0–2 harmonics, lobe-major.
    pub lobes: Vec<f32>,
    /// `K_v` view basis vectors of [`LT_DIM`] numbers, vector `i` at `i·384 .. (i+1)·384`.
    pub basis: Vec<f32>,
    /// Per-voxel coefficients, `J·K_v` per voxel (the [`Coefficients`] rank), lobe-major.
    pub coefficients: Coefficients,
}

impl ViewDependence {
    /// Number of lobes `J`.
    pub fn lobe_count(&self) -> usize {
        self.lobes.len() / VIEW_HARMONICS
    }

    /// View basis rank `K_v`.
    pub fn rank(&self) -> usize {
        self.basis.len() / LT_DIM
    }

    /// Basis vector `i`.
    pub fn component(&self, i: usize) -> &[f32] {
        &self.basis[i * LT_DIM..(i + 1) * LT_DIM]
    }

    /// The `J` lobe values `Y_j(ω)` at world direction `omega` (normalised here).
    pub fn lobe_values(&self, omega: [f32; 3]) -> Vec<f32> {
        let y = view_harmonics(omega);
        self.lobes
            .chunks_exact(VIEW_HARMONICS)
            .map(|w| w.iter().zip(&y).map(|(a, b)| a * b).sum())
            .collect()
    }

    /// Adds the view-dependent transport of a voxel with dequantized coefficients
    /// `coefficients` (`J·K_v`) seen from `omega` to `out` (384 numbers):
    /// `out += Σ_j Y_j(ω) Σ_i d_ji V_i`, in `f32`, `j` then `i` ascending.
    pub fn add_to(&self, coefficients: &[f32], omega: [f32; 3], out: &mut [f32]) {
        let rank = self.rank();
        for (j, y) in self.lobe_values(omega).into_iter().enumerate() {
            for i in 0..rank {
                let w = y * coefficients[j * rank + i];
                for (o, b) in out[..LT_DIM].iter_mut().zip(self.component(i)) {
                    *o += w * b;
                }
            }
        }
    }

    /// Checks shapes (1..=9 lobes, rank ≥ 1, `J·K_v ≤ 384` coefficients per voxel,
    /// `voxels × J·K_v` values), finiteness and the coefficient parameters.
    pub fn validate(&self, voxels: usize) -> Result<()> {
        let lobes = self.lobe_count();
        if self.lobes.len() % VIEW_HARMONICS != 0 || !(1..=VIEW_HARMONICS).contains(&lobes) {
            return Err(FormatError::InvalidAsset(format!(
                "view dependence has {} lobe weights: must be {VIEW_HARMONICS} per lobe, 1 to {VIEW_HARMONICS} lobes",
                self.lobes.len()
            )));
        }
        if self.basis.len() % LT_DIM != 0 || self.basis.is_empty() {
            return Err(FormatError::InvalidAsset(format!(
                "view basis has {} values, not a positive multiple of {LT_DIM}",
                self.basis.len()
            )));
        }
        let per_voxel = lobes * self.rank();
        if per_voxel > LT_DIM || self.coefficients.rank() != per_voxel {
            return Err(FormatError::InvalidAsset(format!(
                "view coefficients have {} values per voxel; {lobes} lobes × rank {} = {per_voxel} (at most {LT_DIM})",
                self.coefficients.rank(),
                self.rank()
            )));
        }
        if let Some(i) = self.lobes.iter().position(|v| !v.is_finite()) {
            return Err(FormatError::NonFinite {
                what: format!(
                    "section VDEP lobe {} weight {}",
                    i / VIEW_HARMONICS,
                    i % VIEW_HARMONICS
                ),
            });
        }
        if let Some(i) = self.basis.iter().position(|v| !v.is_finite()) {
            return Err(FormatError::NonFinite {
                what: format!("section VDEP basis vector {} element {}", i / LT_DIM, i % LT_DIM),
            });
        }
        self.coefficients.validate(voxels, "VDEP", "VCOF")
    }
}

/// Most eyes a reflection part may average over (format 1.3, `VREF`).
pub const MAX_REFLECTION_EYES: usize = 16;

/// Largest lobe exponent λ a reflection part may have (a narrower lobe is finer than the
/// lobe table's nodes, 2.8° apart).
pub const MAX_REFLECTION_EXPONENT: f32 = 200.0;

/// The reflection-aligned view-dependent part (format 1.3, optional sections `VREF` and
/// `VRCO`, SPEC.md §6): one glossy lobe about the mirror direction per voxel. Seen from
/// world direction `ω` (unit, voxel toward the eye), with the voxel's unit normal `n`
/// and the mirror direction `r = 2 (n·ω) n − ω`, the transport is
///
/// `T(x, ω)[c·128 + i] = T̄(x)[c·128 + i] + s(x) · (max(0, n·ω) g_i(r) − h̄_i(x))`,
///
/// `T̄` the PCA part, `g_i(r)` the lobe `max(0, r·ω')^λ` integrated over light texel `i`
/// (interpolated from a table of directions, [`crate::conventions::lobe_table_corners`];
/// `nelf_render::reflection` builds it) and `h̄_i(x) = mean_e max(0, n·ω_e) g_i(r_e)` the
/// same toward the eyes the PCA part averages over, so a reader that ignores the part
/// renders the view-averaged asset. One scale `s ≥ 0` for the three channels (measured
/// as good as three, `docs/measurements/2026-11-27-reflection-lobe.md`).
#[derive(Debug, Clone, PartialEq)]
pub struct Reflection {
    /// The lobe's exponent λ (`1 ..= 200`).
    pub exponent: f32,
    /// The eyes (world, metres) `T̄` averages over, `1 ..= 16`.
    pub eyes_m: Vec<[f32; 3]>,
    /// Per voxel, 8-bit: the octahedral normal `(u, v)`
    /// ([`crate::conventions::octahedral_decode`]) and the scale `s`, rank 3.
    pub coefficients: Coefficients,
}

impl Reflection {
    /// Values per voxel in `VRCO`: normal `u`, normal `v`, scale.
    pub const VALUES_PER_VOXEL: usize = 3;

    /// Quantizes per-voxel unit normals and scales (`s ≥ 0`) into a reflection part.
    pub fn new(exponent: f32, eyes_m: Vec<[f32; 3]>, normals: &[[f32; 3]], scales: &[f32]) -> Result<Self> {
        if normals.len() != scales.len() {
            return Err(FormatError::InvalidAsset(format!(
                "reflection part: {} normals for {} scales",
                normals.len(),
                scales.len()
            )));
        }
        let values: Vec<f32> = normals
            .iter()
            .zip(scales)
            .flat_map(|(n, &s)| {
                let (u, v) = crate::conventions::octahedral_encode(*n);
                [u, v, s.max(0.0)]
            })
            .collect();
        let coefficients =
            Coefficients::quantize(&values, Self::VALUES_PER_VOXEL, CoefficientEncoding::U8Affine)?;
        let part = Self {
            exponent,
            eyes_m,
            coefficients,
        };
        part.validate(normals.len())?;
        Ok(part)
    }

    /// Unit normal and scale of voxel `voxel`.
    pub fn voxel(&self, voxel: usize) -> ([f32; 3], f32) {
        let mut v = [0.0f32; Self::VALUES_PER_VOXEL];
        self.coefficients.voxel_f32(voxel, &mut v);
        (crate::conventions::octahedral_decode(v[0], v[1]), v[2].max(0.0))
    }

    /// Checks the exponent, the eyes (finite, `1..=16`), that the values are 8-bit with
    /// three per voxel, a scale that cannot be negative, and `voxels` voxels.
    pub fn validate(&self, voxels: usize) -> Result<()> {
        let bad = |reason: String| FormatError::InvalidView(format!("section VREF: {reason}"));
        if !(1.0..=MAX_REFLECTION_EXPONENT).contains(&self.exponent) {
            return Err(bad(format!(
                "lobe exponent {} is not in 1..={MAX_REFLECTION_EXPONENT}",
                self.exponent
            )));
        }
        if !(1..=MAX_REFLECTION_EYES).contains(&self.eyes_m.len()) {
            return Err(bad(format!(
                "{} eyes, must be 1..={MAX_REFLECTION_EYES}",
                self.eyes_m.len()
            )));
        }
        if let Some(i) = self.eyes_m.iter().position(|e| e.iter().any(|v| !v.is_finite())) {
            return Err(FormatError::NonFinite {
                what: format!("section VREF eye {i}"),
            });
        }
        match &self.coefficients {
            Coefficients::U8Affine { rank: 3, offset, .. } => {
                if offset[2] < 0.0 {
                    return Err(bad(format!("the scale's offset {} is negative", offset[2])));
                }
            }
            other => {
                return Err(bad(format!(
                    "values must be 8-bit, three per voxel (found {:?}, {} per voxel)",
                    other.encoding(),
                    other.rank()
                )));
            }
        }
        self.coefficients.validate(voxels, "VREF", "VRCO")
    }
}

/// A whole `.nelf` asset in memory.
#[derive(Debug, Clone, PartialEq)]
pub struct Asset {
    /// Grid placement (metres).
    pub grid: GridGeometry,
    /// Rotation taking light-frame directions (the texels of `T`) to world directions.
    pub world_from_light: DMat3,
    /// Brick coordinates (in bricks), sorted by (z, y, x), no repeats, inside the grid.
    pub bricks: Vec<[u16; 3]>,
    /// Density σ (1/m) per voxel, `bricks.len() × 512`, brick order then x-fastest.
    pub density: Vec<f16>,
    /// PCA mean and basis.
    pub pca: PcaModel,
    /// Quantized coefficients, `bricks.len() × 512 × K`.
    pub coefficients: Coefficients,
    /// The view-dependent part (format 1.2), `None` for a view-independent asset.
    pub view: Option<ViewDependence>,
    /// The reflection-aligned view-dependent part (format 1.3); at most one of `view`
    /// and `reflection` is present.
    pub reflection: Option<Reflection>,
    /// The density on a finer lattice (format 1.4); `None` renders `density`.
    pub fine_density: Option<FineDensity>,
    /// Metadata, a JSON object (provenance, bake settings, measured error).
    pub metadata: serde_json::Value,
}

/// One brick read by random access (see [`crate::read::AssetReader::read_brick`]).
#[derive(Debug, Clone, PartialEq)]
pub struct BrickData {
    /// Brick coordinates.
    pub coord: [u16; 3],
    /// Density σ (1/m) of its 512 voxels, x fastest.
    pub density: Vec<f32>,
    /// Dequantized coefficients, `512 × K`, voxel-major.
    pub coefficients: Vec<f32>,
    /// Dequantized view-dependent coefficients (format 1.2), `512 × J·K_v`, voxel-major
    /// (`d_ji` of a voxel at `j·K_v + i`); empty when the file has no view-dependent part.
    pub view_coefficients: Vec<f32>,
    /// Dequantized reflection values (format 1.3), `512 × 3`, voxel-major (octahedral
    /// `u`, `v`, scale); empty when the file has no reflection part.
    pub reflection: Vec<f32>,
    /// Fine density σ (1/m, format 1.4), `512·F³` values in the brick's fine-voxel order
    /// ([`FineDensity`]); empty when the file has none.
    pub fine_density: Vec<f32>,
}

/// The density on a lattice `F` times finer per axis than the voxels (format 1.4,
/// optional section `DNSF`, SPEC.md §6 and §8). Each brick holds `8F × 8F × 8F` fine
/// voxels; fine voxel `(i, j, k)` of brick `(bx, by, bz)` (each of `i, j, k` in `0..8F`)
/// is centred at `bbox_min + (8F·(bx, by, bz) + (i, j, k) + ½) · Δ/F` and stored at
/// `brick_index · 512F³ + i + 8F·(j + 8F·k)`. A renderer that reads it takes the density
/// at a point as `max(0, trilinear)` over this lattice, exactly the rule of `DENS` on a
/// grid of voxel size `Δ/F` (fine voxels outside every brick are 0), and the radiance
/// from the voxels as before; one that does not renders `DENS`, the coarse asset.
#[derive(Debug, Clone, PartialEq)]
pub struct FineDensity {
    /// `F`, one of [`FINE_DENSITY_FACTORS`] (2 or 4).
    pub factor: u32,
    /// σ (1/m) per fine voxel, `bricks × 512·F³`, brick order, x fastest inside a brick.
    pub values: Vec<f16>,
}

impl FineDensity {
    /// Fine voxels per brick, `512·F³`.
    pub fn voxels_per_brick(&self) -> usize {
        BRICK_VOXELS * (self.factor as usize).pow(3)
    }

    /// Fine voxels along a brick's edge, `8F`.
    pub fn brick_edge(&self) -> usize {
        BRICK_SIZE * self.factor as usize
    }

    /// Checks the factor, the count for `bricks` bricks and the values (finite).
    pub fn validate(&self, bricks: usize) -> Result<()> {
        if !FINE_DENSITY_FACTORS.contains(&self.factor) {
            return Err(FormatError::InvalidAsset(format!(
                "fine density factor {} must be 2 or 4",
                self.factor
            )));
        }
        let expected = bricks * self.voxels_per_brick();
        if self.values.len() != expected {
            return Err(FormatError::InvalidAsset(format!(
                "{} fine density values for {bricks} bricks at factor {} ({expected} expected)",
                self.values.len(),
                self.factor
            )));
        }
        validate_density_values(&self.values, 0, true, "DNSF")
    }
}

impl Asset {
    /// Voxels stored (`bricks × 512`).
    pub fn voxel_count(&self) -> usize {
        self.bricks.len() * BRICK_VOXELS
    }

    /// PCA rank `K`.
    pub fn rank(&self) -> usize {
        self.pca.rank()
    }

    /// Brick coordinates and local `(i, j, k)` of global voxel `voxel`.
    pub fn voxel_location(&self, voxel: usize) -> ([u16; 3], [usize; 3]) {
        (
            self.bricks[voxel / BRICK_VOXELS],
            local_voxel_coords(voxel % BRICK_VOXELS),
        )
    }

    /// World position (metres) of the centre of global voxel `voxel` (`brick·512 + local`).
    pub fn voxel_position_m(&self, voxel: usize) -> DVec3 {
        let (brick, local) = self.voxel_location(voxel);
        self.grid.voxel_center_m(brick, local)
    }

    /// Density σ (1/m) of voxel `voxel`.
    pub fn density_at(&self, voxel: usize) -> f32 {
        self.density[voxel].to_f32()
    }

    /// Dequantized coefficients of voxel `voxel` into `out[..K]`.
    pub fn coefficients_f32(&self, voxel: usize, out: &mut [f32]) {
        self.coefficients.voxel_f32(voxel, out);
    }

    /// Light-transport vector of voxel `voxel`: `mean + Σ_k c_k · B_k`.
    pub fn reconstruct_lt(&self, voxel: usize) -> [f32; LT_DIM] {
        let mut coefficients = vec![0.0f32; self.rank()];
        self.coefficients_f32(voxel, &mut coefficients);
        let mut out = [0.0f32; LT_DIM];
        self.pca.reconstruct_into(&coefficients, &mut out);
        out
    }

    /// Light-transport vector of voxel `voxel` seen from world direction `omega` (from the
    /// voxel toward the eye; normalised here): [`Self::reconstruct_lt`], plus
    /// `Σ_j Y_j(ω) Σ_i d_ji V_i` ([`ViewDependence::add_to`]) when the asset has a
    /// view-dependent part.
    pub fn reconstruct_lt_toward(&self, voxel: usize, omega: [f32; 3]) -> [f32; LT_DIM] {
        let mut out = self.reconstruct_lt(voxel);
        if let Some(view) = &self.view {
            let mut d = vec![0.0f32; view.coefficients.rank()];
            view.coefficients.voxel_f32(voxel, &mut d);
            view.add_to(&d, omega, &mut out);
        }
        out
    }

    /// Index of the brick at `coord`, by binary search on the (z, y, x) order.
    pub fn find_brick(&self, coord: [u16; 3]) -> Option<usize> {
        self.bricks
            .binary_search_by_key(&brick_order_key(coord), |&c| brick_order_key(c))
            .ok()
    }

    /// Checks everything the file format requires: grid ranges, rotation, sorted
    /// in-grid bricks, array lengths, ranks, finite and non-negative values, and
    /// that the metadata is a JSON object.
    pub fn validate(&self) -> Result<()> {
        self.grid.validate().map_err(FormatError::InvalidAsset)?;
        if !is_rotation(self.world_from_light, 1e-5) {
            return Err(FormatError::InvalidAsset(format!(
                "world_from_light {:?} is not a rotation",
                self.world_from_light.to_cols_array()
            )));
        }
        validate_bricks(&self.bricks, self.grid.grid_bricks)?;
        if self.bricks.len() > u32::MAX as usize {
            return Err(FormatError::CountTooLarge {
                what: "brick count".into(),
                count: self.bricks.len() as u64,
                limit: u64::from(u32::MAX),
            });
        }
        let voxels = self.voxel_count();
        if self.density.len() != voxels {
            return Err(FormatError::InvalidAsset(format!(
                "{} density values for {voxels} voxels",
                self.density.len()
            )));
        }
        validate_density(&self.density, 0, true)?;
        self.pca.validate()?;
        if self.coefficients.rank() != self.pca.rank() {
            return Err(FormatError::InvalidAsset(format!(
                "coefficients have rank {} but the PCA basis has {}",
                self.coefficients.rank(),
                self.pca.rank()
            )));
        }
        self.coefficients.validate(voxels, "QPRM", "COEF")?;
        if let Some(view) = &self.view {
            view.validate(voxels)?;
        }
        if let Some(reflection) = &self.reflection {
            if self.view.is_some() {
                return Err(FormatError::InvalidView(
                    "an asset holds at most one view-dependent part: VDEP or VREF, not both".into(),
                ));
            }
            reflection.validate(voxels)?;
        }
        if let Some(fine) = &self.fine_density {
            fine.validate(self.bricks.len())?;
        }
        if !self.metadata.is_object() {
            return Err(FormatError::MetadataNotObject {
                found: json_type_name(&self.metadata),
            });
        }
        Ok(())
    }
}

/// Checks brick coordinates: inside the grid, strictly increasing in (z, y, x) order.
pub(crate) fn validate_bricks(bricks: &[[u16; 3]], grid_bricks: [u32; 3]) -> Result<()> {
    for (i, b) in bricks.iter().enumerate() {
        if (0..3).any(|a| u32::from(b[a]) >= grid_bricks[a]) {
            return Err(FormatError::InvalidBricks(format!(
                "brick {i} at {b:?} is outside the grid of {grid_bricks:?} bricks"
            )));
        }
        if i > 0 && brick_order_key(bricks[i - 1]) >= brick_order_key(*b) {
            return Err(FormatError::InvalidBricks(format!(
                "brick {i} at {b:?} does not follow {:?} in (z, y, x) order (unsorted or repeated)",
                bricks[i - 1]
            )));
        }
    }
    Ok(())
}

/// Checks densities are finite, and not negative unless `signed` (the file's
/// [`crate::spec::FLAG_SIGNED_DENSITY`]); `first_voxel` numbers them in messages.
pub(crate) fn validate_density(density: &[f16], first_voxel: usize, signed: bool) -> Result<()> {
    validate_density_values(density, first_voxel, signed, "DENS")
}

/// Checks density values of section `section` (`DENS`, or `DNSF` counted in fine
/// voxels): finite, and not negative unless `signed`.
pub(crate) fn validate_density_values(
    density: &[f16],
    first_voxel: usize,
    signed: bool,
    section: &str,
) -> Result<()> {
    for (i, d) in density.iter().enumerate() {
        if !d.is_finite() {
            return Err(FormatError::NonFinite {
                what: format!("section {section} voxel {}", first_voxel + i),
            });
        }
        if !signed && d.to_f32() < 0.0 {
            return Err(FormatError::InvalidValue {
                what: format!("section {section} voxel {}", first_voxel + i),
                reason: format!("negative density {d} in a file without the signed-density flag"),
            });
        }
    }
    Ok(())
}

/// JSON type of a value, for messages.
pub(crate) fn json_type_name(v: &serde_json::Value) -> &'static str {
    match v {
        serde_json::Value::Null => "null",
        serde_json::Value::Bool(_) => "a boolean",
        serde_json::Value::Number(_) => "a number",
        serde_json::Value::String(_) => "a string",
        serde_json::Value::Array(_) => "an array",
        serde_json::Value::Object(_) => "an object",
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn u8_quantization_error_within_half_step() {
        let values: Vec<f32> = (0..600)
            .map(|i| ((i as f32) * 0.37).sin() * (1.0 + (i % 3) as f32))
            .collect();
        let q = Coefficients::quantize(&values, 3, CoefficientEncoding::U8Affine).unwrap();
        let back = q.to_f32();
        for (i, (a, b)) in values.iter().zip(&back).enumerate() {
            let bound = q.abs_error_bound(i % 3).unwrap();
            assert!((a - b).abs() <= bound, "{i}: {a} vs {b}, bound {bound}");
        }
        // The range spans (nearly) every code.
        let Coefficients::U8Affine { codes, .. } = &q else {
            panic!()
        };
        assert!(codes.contains(&0) && codes.iter().any(|&c| c >= 254));
    }

    #[test]
    fn u8_step_floor_keeps_zero_exact_and_uses_fewer_codes() {
        // Component 0 spans ±1, component 1 only ±0.01.
        let values: Vec<f32> = (0..1000)
            .flat_map(|i| {
                let x = ((i as f32) * 0.61).sin();
                [x, 0.01 * ((i as f32) * 1.3).cos()]
            })
            .chain([0.0, 0.0])
            .collect();
        let plain = Coefficients::quantize(&values, 2, CoefficientEncoding::U8Affine).unwrap();
        let step = 0.004;
        let floored =
            Coefficients::quantize_with_min_step(&values, 2, CoefficientEncoding::U8Affine, step).unwrap();
        for q in [&plain, &floored] {
            let back = q.to_f32();
            assert_eq!(
                &back[back.len() - 2..],
                [0.0, 0.0],
                "a zero coefficient decodes to 0"
            );
            for (i, (a, b)) in values.iter().zip(&back).enumerate() {
                assert!((a - b).abs() <= q.abs_error_bound(i % 2).unwrap(), "{i}");
            }
        }
        let distinct = |q: &Coefficients, k: usize| {
            let Coefficients::U8Affine { codes, scale, .. } = q else {
                panic!()
            };
            let set: std::collections::BTreeSet<u8> = codes.iter().skip(k).step_by(2).copied().collect();
            (set.len(), scale[k])
        };
        let (plain_codes, plain_scale) = distinct(&plain, 1);
        let (floored_codes, floored_scale) = distinct(&floored, 1);
        assert!(
            plain_codes > 50 && plain_scale < step,
            "{plain_codes} codes, step {plain_scale}"
        );
        assert_eq!(floored_scale, step);
        assert!(
            floored_codes <= 7,
            "±0.01 in steps of 0.004: {floored_codes} codes"
        );
        assert!(
            distinct(&floored, 0).1 > step,
            "a wider component keeps its own step"
        );
        assert!(
            Coefficients::quantize_with_min_step(&values, 2, CoefficientEncoding::U8Affine, -1.0).is_err()
        );
    }

    #[test]
    fn f16_quantization_is_relative() {
        let values = [1.0f32, -3.25, 1e-3, 60000.0];
        let q = Coefficients::quantize(&values, 2, CoefficientEncoding::F16).unwrap();
        for (a, b) in values.iter().zip(q.to_f32()) {
            assert!((a - b).abs() <= a.abs() * 2f32.powi(-11));
        }
        assert!(Coefficients::quantize(&[7e4, 0.0], 2, CoefficientEncoding::F16).is_err());
        assert!(Coefficients::quantize(&[f32::NAN, 0.0], 2, CoefficientEncoding::U8Affine).is_err());
        assert!(Coefficients::quantize(&[0.0; 3], 2, CoefficientEncoding::F16).is_err());
        assert!(Coefficients::quantize(&[0.0; 385], 385, CoefficientEncoding::F16).is_err());
    }

    #[test]
    fn constant_component_quantizes_exactly() {
        let q = Coefficients::quantize(&[2.5, 2.5, 2.5], 1, CoefficientEncoding::U8Affine).unwrap();
        assert_eq!(q.to_f32(), vec![2.5; 3]);
    }

    #[test]
    fn density_encoding_clamps_and_rejects() {
        let d = encode_density(&[0.0, 1.0, 1e6, -1.0]).unwrap();
        assert_eq!(d[2], f16::MAX);
        assert_eq!(d[3].to_f32(), -1.0, "signed densities are kept");
        assert!(has_negative_density(&d) && !has_negative_density(&d[..3]));
        assert!(encode_density(&[f32::NAN]).is_err());
        assert!(encode_density(&[f32::NEG_INFINITY]).is_err());
    }
}
