//! A summary of a `.nelf` file for people and scripts (`nelf inspect`): header,
//! sections with stored and decoded sizes, counts, bounding box, the view-dependent part
//! (harmonic lobes of format 1.2, or the reflection part of 1.3), the fine density (1.4),
//! metadata, and the
//! result of checking every checksum and value ([`crate::read::AssetReader::verify`]).

use std::fmt::Write as _;
use std::path::Path;

use serde::Serialize;

use crate::asset::{Coefficients, Reflection};
use crate::error::Result;
use crate::read::AssetReader;
use crate::spec::{
    BRICK_SIZE, BRICK_VOXELS, KIND_FINE_DENSITY, KIND_REFLECTION, KIND_REFLECTION_VALUES, KIND_VIEW,
    KIND_VIEW_COEFFICIENTS, SectionEntry, SectionKind, is_known_kind,
};

/// One section as `nelf inspect` reports it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SectionSummary {
    /// Four-letter kind.
    pub kind: String,
    /// Whether a reader that does not know the kind must reject the file.
    pub required: bool,
    /// Whether this reader knows the kind.
    pub known: bool,
    /// Codec name (`raw`, `zstd`, `chunked-zstd`).
    pub codec: String,
    /// Byte-shuffle record width (0 = none).
    pub shuffle: u32,
    /// Offset in the file.
    pub offset: u64,
    /// Stored bytes.
    pub stored_bytes: u64,
    /// Decoded bytes.
    pub raw_bytes: u64,
    /// `raw_bytes / stored_bytes` (1 for empty sections).
    pub ratio: f64,
    /// xxh3-64 of the stored bytes, hex.
    pub checksum: String,
}

impl SectionSummary {
    fn new(s: &SectionEntry) -> Self {
        Self {
            kind: s.name(),
            required: s.required,
            known: is_known_kind(s.kind),
            codec: s.codec.name(),
            shuffle: s.shuffle,
            offset: s.offset,
            stored_bytes: s.stored_length,
            raw_bytes: s.raw_length,
            ratio: ratio(s.raw_length, s.stored_length),
            checksum: format!("{:016x}", s.checksum),
        }
    }
}

fn ratio(raw: u64, stored: u64) -> f64 {
    if stored == 0 {
        1.0
    } else {
        raw as f64 / stored as f64
    }
}

/// The view-dependent part (format 1.2, sections `VDEP` and `VCOF`) as `nelf inspect`
/// reports it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ViewSummary {
    /// Lobes `J`.
    pub lobes: usize,
    /// View basis rank `K_v`.
    pub rank: usize,
    /// Coefficients per voxel, `J·K_v`.
    pub coefficients_per_voxel: usize,
    /// Encoding name of the per-voxel coefficients.
    pub encoding: String,
    /// Stored bytes of `VDEP` and `VCOF` together.
    pub stored_bytes: u64,
    /// Decoded bytes of `VDEP` and `VCOF` together.
    pub raw_bytes: u64,
}

/// The reflection part (format 1.3, sections `VREF` and `VRCO`) as `nelf inspect` reports
/// it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ReflectionSummary {
    /// The lobe exponent λ.
    pub exponent: f32,
    /// The eyes (world, metres) the PCA part averages over.
    pub eyes_m: Vec<[f32; 3]>,
    /// The scales `s` the 8-bit values can hold, `[offset, offset + 255 · step]`: the
    /// dequantisation range of `VRCO`'s third value.
    pub scale_range: [f32; 2],
    /// Stored bytes of `VREF` and `VRCO` together.
    pub stored_bytes: u64,
    /// Decoded bytes of `VREF` and `VRCO` together.
    pub raw_bytes: u64,
}

impl ReflectionSummary {
    fn new(part: &Reflection, sections: &[SectionEntry]) -> Self {
        let scale_range = match &part.coefficients {
            Coefficients::U8Affine { scale, offset, .. } if scale.len() > 2 && offset.len() > 2 => {
                [offset[2], offset[2] + 255.0 * scale[2]]
            }
            _ => [0.0, 0.0],
        };
        let (stored_bytes, raw_bytes) = section_bytes(sections, &[KIND_REFLECTION, KIND_REFLECTION_VALUES]);
        Self {
            exponent: part.exponent,
            eyes_m: part.eyes_m.clone(),
            scale_range,
            stored_bytes,
            raw_bytes,
        }
    }
}

/// The fine density (format 1.4, section `DNSF`) as `nelf inspect` reports it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FineDensitySummary {
    /// The factor `F` (2 or 4): the fine lattice is `F` times finer per axis.
    pub factor: u32,
    /// Fine voxels along a brick's edge, `8F`.
    pub brick_edge: usize,
    /// Fine voxels per brick, `512·F³`.
    pub voxels_per_brick: u64,
    /// Fine voxels stored, `512·F³` per brick.
    pub voxel_count: u64,
    /// Fine voxel edge, metres (`voxel_size_m / F`).
    pub voxel_size_m: f64,
    /// Stored bytes of `DNSF`.
    pub stored_bytes: u64,
    /// Decoded bytes of `DNSF` (`1024·F³` per brick).
    pub raw_bytes: u64,
}

/// Stored and decoded bytes of the sections of kinds `kinds` together.
fn section_bytes(sections: &[SectionEntry], kinds: &[SectionKind]) -> (u64, u64) {
    sections
        .iter()
        .filter(|s| kinds.contains(&s.kind))
        .fold((0, 0), |(stored, raw), s| {
            (stored + s.stored_length, raw + s.raw_length)
        })
}

/// Everything `nelf inspect` prints.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Inspection {
    /// The file inspected.
    pub file: String,
    /// Its size in bytes.
    pub file_size: u64,
    /// `major.minor`.
    pub version: String,
    /// Header flags.
    pub flags: u64,
    /// Grid box minimum corner, metres.
    pub bbox_min_m: [f64; 3],
    /// Grid box maximum corner, metres.
    pub bbox_max_m: [f64; 3],
    /// Voxel edge, metres.
    pub voxel_size_m: f64,
    /// Grid extent in bricks.
    pub grid_bricks: [u32; 3],
    /// Voxels along a brick edge (8).
    pub brick_size: usize,
    /// Bricks stored.
    pub brick_count: u32,
    /// Voxels stored.
    pub voxel_count: u64,
    /// Bricks per chunk.
    pub chunk_bricks: u32,
    /// Chunks per chunked section.
    pub chunk_count: u64,
    /// `world_from_light`, rows.
    pub world_from_light: [[f64; 3]; 3],
    /// Environment-map size of the basis, `[height, width]`.
    pub env_size: [u16; 2],
    /// PCA rank `K`.
    pub pca_rank: u32,
    /// Coefficient encoding name.
    pub coefficient_encoding: String,
    /// The harmonic view-dependent part (1.2), if the file has one.
    pub view: Option<ViewSummary>,
    /// The reflection part (1.3), if the file has one (a file holds at most one of the two).
    pub reflection: Option<ReflectionSummary>,
    /// The fine density (1.4), if the file has one.
    pub fine_density: Option<FineDensitySummary>,
    /// Sections in table order.
    pub sections: Vec<SectionSummary>,
    /// Decoded bytes over all sections.
    pub raw_payload_bytes: u64,
    /// Stored bytes over all sections.
    pub stored_payload_bytes: u64,
    /// `raw_payload_bytes / stored_payload_bytes`.
    pub compression_ratio: f64,
    /// File bytes per stored voxel.
    pub bytes_per_voxel: f64,
    /// Whether every checksum and value was checked (always true when returned).
    pub verified: bool,
    /// The metadata object.
    pub metadata: serde_json::Value,
}

/// Opens, fully verifies and summarises the `.nelf` file at `path`.
pub fn inspect(path: &Path) -> Result<Inspection> {
    let mut reader = AssetReader::open(path)?;
    reader.verify()?;
    let h = reader.header().clone();
    let sections: Vec<SectionSummary> = reader.sections().iter().map(SectionSummary::new).collect();
    let raw: u64 = sections.iter().map(|s| s.raw_bytes).sum();
    let stored: u64 = sections.iter().map(|s| s.stored_bytes).sum();
    let rows = h.world_from_light.transpose().to_cols_array_2d();
    let voxel_count = h.voxel_count();
    let view = reader.view_params().map(|v| {
        let (stored_bytes, raw_bytes) =
            section_bytes(reader.sections(), &[KIND_VIEW, KIND_VIEW_COEFFICIENTS]);
        ViewSummary {
            lobes: v.lobe_count(),
            rank: v.rank(),
            coefficients_per_voxel: v.coefficients.rank(),
            encoding: v.coefficients.encoding().name().to_string(),
            stored_bytes,
            raw_bytes,
        }
    });
    let reflection = reader
        .reflection_params()
        .map(|part| ReflectionSummary::new(part, reader.sections()));
    let fine_density = (h.fine_density_factor != 0).then(|| {
        let factor = h.fine_density_factor;
        let (stored_bytes, raw_bytes) = section_bytes(reader.sections(), &[KIND_FINE_DENSITY]);
        let voxels_per_brick = BRICK_VOXELS as u64 * u64::from(factor).pow(3);
        FineDensitySummary {
            factor,
            brick_edge: BRICK_SIZE * factor as usize,
            voxels_per_brick,
            voxel_count: u64::from(h.brick_count) * voxels_per_brick,
            voxel_size_m: h.grid.voxel_size_m / f64::from(factor),
            stored_bytes,
            raw_bytes,
        }
    });
    Ok(Inspection {
        file: path.display().to_string(),
        file_size: h.file_size,
        version: format!("{}.{}", h.version_major, h.version_minor),
        flags: h.flags,
        bbox_min_m: h.grid.bbox_min_m,
        bbox_max_m: h.grid.bbox_max_m(),
        voxel_size_m: h.grid.voxel_size_m,
        grid_bricks: h.grid.grid_bricks,
        brick_size: BRICK_SIZE,
        brick_count: h.brick_count,
        voxel_count,
        chunk_bricks: h.chunk_bricks,
        chunk_count: h.chunk_count(),
        world_from_light: rows,
        env_size: [h.env_height, h.env_width],
        pca_rank: h.pca_rank,
        coefficient_encoding: h.coefficient_encoding.name().to_string(),
        view,
        reflection,
        fine_density,
        sections,
        raw_payload_bytes: raw,
        stored_payload_bytes: stored,
        compression_ratio: ratio(raw, stored),
        bytes_per_voxel: if voxel_count == 0 {
            0.0
        } else {
            h.file_size as f64 / voxel_count as f64
        },
        verified: true,
        metadata: reader.metadata().clone(),
    })
}

impl Inspection {
    /// The human-readable report.
    pub fn to_text(&self) -> String {
        let mut s = String::new();
        let v3 = |v: [f64; 3]| format!("({:.6}, {:.6}, {:.6})", v[0], v[1], v[2]);
        // Writing to a String cannot fail.
        let _ = writeln!(s, "file:              {}", self.file);
        let _ = writeln!(
            s,
            "format:            .nelf v{}, {} bytes, flags {:#x}",
            self.version, self.file_size, self.flags
        );
        let _ = writeln!(s, "checksums:         all verified");
        let _ = writeln!(
            s,
            "bounding box (m):  min {} max {}",
            v3(self.bbox_min_m),
            v3(self.bbox_max_m)
        );
        let _ = writeln!(
            s,
            "voxel size:        {:.6} m ({:.3} mm)",
            self.voxel_size_m,
            1e3 * self.voxel_size_m
        );
        let g = self.grid_bricks;
        let _ = writeln!(
            s,
            "grid:              {}×{}×{} bricks of {}³ = {}×{}×{} voxels",
            g[0],
            g[1],
            g[2],
            self.brick_size,
            u64::from(g[0]) * self.brick_size as u64,
            u64::from(g[1]) * self.brick_size as u64,
            u64::from(g[2]) * self.brick_size as u64
        );
        let _ = writeln!(s, "bricks:            {}", self.brick_count);
        let _ = writeln!(s, "voxels:            {}", self.voxel_count);
        let _ = writeln!(
            s,
            "chunks:            {} of {} bricks",
            self.chunk_count, self.chunk_bricks
        );
        let _ = writeln!(
            s,
            "environment basis: {}×{} texels",
            self.env_size[0], self.env_size[1]
        );
        let _ = writeln!(s, "PCA rank:          {}", self.pca_rank);
        let _ = writeln!(s, "coefficients:      {}", self.coefficient_encoding);
        match &self.view {
            Some(v) => {
                let _ = writeln!(
                    s,
                    "view dependence:   {} lobes × rank {} = {} coefficients per voxel, {}, {} bytes stored, {} decoded",
                    v.lobes, v.rank, v.coefficients_per_voxel, v.encoding, v.stored_bytes, v.raw_bytes
                );
            }
            None => {
                let _ = writeln!(s, "view dependence:   none");
            }
        }
        match &self.reflection {
            Some(r) => {
                let _ = writeln!(
                    s,
                    "reflection:        lobe exponent {}, {} eyes, scale {} … {} (8-bit), {} bytes stored, {} decoded",
                    r.exponent,
                    r.eyes_m.len(),
                    r.scale_range[0],
                    r.scale_range[1],
                    r.stored_bytes,
                    r.raw_bytes
                );
                let eyes: Vec<String> = r
                    .eyes_m
                    .iter()
                    .map(|e| format!("({:.3}, {:.3}, {:.3})", e[0], e[1], e[2]))
                    .collect();
                let _ = writeln!(s, "reflection eyes:   {} m", eyes.join(" "));
            }
            None => {
                let _ = writeln!(s, "reflection:        none");
            }
        }
        match &self.fine_density {
            Some(f) => {
                let _ = writeln!(
                    s,
                    "fine density:      F = {}, {}³ fine voxels a brick ({} in all) of {:.6} m ({:.3} mm), {} bytes stored, {} decoded",
                    f.factor,
                    f.brick_edge,
                    f.voxel_count,
                    f.voxel_size_m,
                    1e3 * f.voxel_size_m,
                    f.stored_bytes,
                    f.raw_bytes
                );
            }
            None => {
                let _ = writeln!(s, "fine density:      none");
            }
        }
        for (i, r) in self.world_from_light.iter().enumerate() {
            let label = if i == 0 { "world_from_light:" } else { "" };
            let _ = writeln!(s, "{label:<19}[{:>9.6} {:>9.6} {:>9.6}]", r[0], r[1], r[2]);
        }
        let _ = writeln!(
            s,
            "payload:           {} bytes stored, {} decoded (ratio {:.2}), {:.2} bytes/voxel",
            self.stored_payload_bytes, self.raw_payload_bytes, self.compression_ratio, self.bytes_per_voxel
        );
        let _ = writeln!(s, "sections:");
        let h = [
            "kind", "req", "codec", "shuffle", "offset", "stored", "decoded", "ratio", "xxh3",
        ];
        let _ = writeln!(
            s,
            "  {:<4} {:<4} {:<12} {:>7} {:>10} {:>12} {:>12} {:>7}  {}",
            h[0], h[1], h[2], h[3], h[4], h[5], h[6], h[7], h[8]
        );
        for sec in &self.sections {
            let kind = if sec.known {
                sec.kind.clone()
            } else {
                format!("{}?", sec.kind)
            };
            let _ = writeln!(
                s,
                "  {:<4} {:<4} {:<12} {:>7} {:>10} {:>12} {:>12} {:>7.2}  {}",
                kind,
                if sec.required { "yes" } else { "no" },
                sec.codec,
                sec.shuffle,
                sec.offset,
                sec.stored_bytes,
                sec.raw_bytes,
                sec.ratio,
                sec.checksum
            );
        }
        let metadata = serde_json::to_string_pretty(&self.metadata).unwrap_or_else(|e| format!("<{e}>"));
        let _ = writeln!(s, "metadata:");
        for line in metadata.lines() {
            let _ = writeln!(s, "  {line}");
        }
        s
    }
}
