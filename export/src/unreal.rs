//! The Unreal Engine preset of the OpenVDB export (`nelf export vdb --preset unreal`).
//!
//! Unreal's Sparse Volume Texture (SVT) importer reads OpenVDB grids (half, float or
//! double, 1–4 components) into two RGBA attribute textures, A and B, so one SVT holds
//! at most 8 channels. An asset needs `1 + K` scalar channels (density and the K PCA
//! coefficients), so the preset writes `⌈(1 + K) / 8⌉` files, each a plain OpenVDB
//! file of float grids that the importer maps channel by channel:
//!
//! * file 0: `density` → A.r, `pca_00` … `pca_06` → A.g … B.a;
//! * file n ≥ 1: the next eight `pca_NN` grids → A.r … B.a.
//!
//! An asset with a fine density (format 1.4) has its `density` grid on a lattice `F`
//! times finer than the coefficients, with its own transform. One SVT has one
//! resolution, so then the density is an SVT of its own, `<stem>_density.vdb` (`density`
//! → A.r, every fine voxel), covering the same box as the others, and the coefficient
//! files hold only `pca_NN` grids, eight each (`pca_00` … `pca_07` in file 0). Without a
//! fine density every file is exactly as before.
//!
//! Beside them: `<stem>.unreal.json` (every file, grid, attribute texture and channel,
//! each channel's value range for choosing 8-bit unorm vs 16/32-bit float), and
//! `<stem>.relight.hlsl`, a function for a Custom material node that rebuilds radiance
//! from the sampled attribute textures and a projected-lighting texture
//! (`(K + 1) × 1` RGB float: texel 0 = `P_mean`, texel `k + 1` = `P_k`, SPEC.md §8 and
//! `export/README.md`), and `<stem>.projected_light.exr`, that texture for the
//! export's lighting. `export/UNREAL.md` walks through the import.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use nelf_format::Asset;
use serde::Serialize;

use crate::error::ExportError;
use crate::openvdb::{AnyGrid, VdbFile};
use crate::vdb::{DENSITY_GRID, Lighting, VdbOptions, build_vdb, pca_grid_name};

/// Channels of one Sparse Volume Texture: attribute textures A and B, RGBA each.
pub const SVT_CHANNELS: usize = 8;

/// The SVT channel names, in order.
const CHANNELS: [(&str, &str); SVT_CHANNELS] = [
    ("A", "r"),
    ("A", "g"),
    ("A", "b"),
    ("A", "a"),
    ("B", "r"),
    ("B", "g"),
    ("B", "b"),
    ("B", "a"),
];

/// Where one grid goes in Unreal.
#[derive(Debug, Clone, Serialize)]
pub struct ChannelMap {
    /// The grid's name in the file.
    pub grid: String,
    /// Attribute texture, `A` or `B`.
    pub attributes: String,
    /// Channel of that texture, `r`, `g`, `b` or `a`.
    pub channel: String,
    /// Smallest and largest active value (an 8-bit unorm channel would need this range
    /// remapped; the preset assumes 16-bit float).
    pub range: [f32; 2],
}

/// One file of the preset.
#[derive(Debug, Clone, Serialize)]
pub struct UnrealFile {
    /// File name (beside the manifest).
    pub file: String,
    /// Its grids and channels.
    pub channels: Vec<ChannelMap>,
    /// Bytes.
    pub file_size: u64,
}

/// What the preset wrote (also `<stem>.unreal.json`).
#[derive(Debug, Clone, Serialize)]
pub struct UnrealReport {
    /// The SVT files, in order.
    pub files: Vec<UnrealFile>,
    /// PCA components exported.
    pub rank: usize,
    /// The lighting of `projected_light_file`.
    pub lighting: String,
    /// This report's own file, `<stem>.unreal.json`.
    pub manifest_file: String,
    /// The HLSL file.
    pub hlsl_file: String,
    /// The projected-lighting texture for the export's lighting.
    pub projected_light_file: String,
    /// Voxel edge in scene units, and the density's unit.
    pub voxel_size: f64,
    /// Unit of the density channel.
    pub density_unit: String,
    /// Attribute texture format the HLSL and the ranges assume.
    pub attribute_format: String,
    /// With a fine density: the density's own SVT file (A.r), `F` times finer per axis
    /// than `files`; `None` (and not in the JSON) when the density is A.r of file 0.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub density_file: Option<UnrealFile>,
    /// With a fine density: its factor `F` (voxel edge `voxel_size / F`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub density_factor: Option<u32>,
}

fn range(grid: &AnyGrid) -> [f32; 2] {
    let AnyGrid::Float(g) = grid else {
        return [0.0, 0.0];
    };
    g.leaves()
        .flat_map(|(_, v)| v.iter().copied())
        .fold([f32::INFINITY, f32::NEG_INFINITY], |[lo, hi], v| {
            [lo.min(v), hi.max(v)]
        })
}

/// The files of the preset, named from `out` (`head.vdb` → `head_svt0.vdb` …).
fn sibling(out: &Path, suffix: &str) -> PathBuf {
    let stem = out
        .file_stem()
        .map_or_else(|| "asset".into(), |s| s.to_string_lossy());
    out.with_file_name(format!("{stem}{suffix}"))
}

/// The HLSL function of a Custom material node for `files` SVTs and rank `rank`, the
/// density in A.r of file 0 and `pca_k` in channel `k + 1`.
pub fn relight_hlsl(files: usize, rank: usize) -> String {
    hlsl(
        files,
        rank,
        1,
        "Density is A0.r (1/scene unit, signed as stored: use max(0, A0.r)).",
    )
}

/// The HLSL function for an asset with a fine density: `files` SVTs holding only the
/// coefficients (`pca_k` in channel `k`), the density in A.r of the SVT `density_file`.
pub fn relight_hlsl_fine_density(files: usize, rank: usize, density_file: &str) -> String {
    hlsl(
        files,
        rank,
        0,
        &format!(
            "Density is A.r of the SVT {density_file} (the fine density, its own resolution, the same box:\n\
             // sample it at the same UVW; 1/scene unit, signed as stored: use max(0, A.r))."
        ),
    )
}

/// `pca_k` is read from channel `first_slot + k` of the files' channels.
fn hlsl(files: usize, rank: usize, first_slot: usize, density: &str) -> String {
    let mut inputs = Vec::new();
    for f in 0..files {
        inputs.push(format!("float4 A{f}"));
        inputs.push(format!("float4 B{f}"));
    }
    let mut body = String::new();
    body.push_str("    float3 radiance = ProjectedLight.Load(int3(0, 0, 0)).rgb; // P_mean\n");
    for k in 0..rank {
        let slot = k + first_slot;
        let (file, (attr, channel)) = (slot / SVT_CHANNELS, CHANNELS[slot % SVT_CHANNELS]);
        let _ = writeln!(
            body,
            "    radiance += {attr}{file}.{channel} * ProjectedLight.Load(int3({}, 0, 0)).rgb; // {}",
            k + 1,
            pca_grid_name(k)
        );
    }
    format!(
        "// Generated by `nelf export vdb --preset unreal` (export/UNREAL.md).\n\
         // Radiance of a voxel: P_mean + sum_k pca_k * P_k (SPEC.md section 8), from the\n\
         // attribute textures A<n>, B<n> of SVT file n sampled at the same position, and\n\
         // ProjectedLight, a ({k1} x 1) RGB float texture: texel 0 = P_mean, texel k+1 = P_k.\n\
         // {density}\n\
         // As a Custom node: inputs {inputs_list}, ProjectedLight; output float3.\n\
         float3 NelfRelight({params}, Texture2D ProjectedLight)\n{{\n{body}    return radiance;\n}}\n",
        k1 = rank + 1,
        inputs_list = inputs.join(", ").replace("float4 ", ""),
        params = inputs.join(", "),
    )
}

/// Writes the Unreal preset for `asset` next to `out` (see the module docs);
/// every file atomically.
pub fn write_unreal(
    out: &Path,
    asset: &Asset,
    lighting: &Lighting,
    options: &VdbOptions,
) -> Result<UnrealReport, ExportError> {
    let (full, vdb_report) = build_vdb(asset, lighting, options)?;
    let rank = vdb_report.rank;
    let mut scalar: Vec<&AnyGrid> = Vec::with_capacity(rank + 1);
    let find = |name: &str| {
        full.grids()
            .iter()
            .find(|g| g.name() == name)
            .ok_or_else(|| ExportError::Metadata(format!("grid {name} missing from the export")))
    };
    let density = find(DENSITY_GRID)?;
    // A fine density has its own resolution: an SVT of its own.
    let fine = vdb_report.density_factor;
    if fine.is_none() {
        scalar.push(density);
    }
    for k in 0..rank {
        scalar.push(find(&pca_grid_name(k))?);
    }
    let count = scalar.len().div_ceil(SVT_CHANNELS);
    let mut files = Vec::new();
    for (n, group) in scalar.chunks(SVT_CHANNELS).enumerate() {
        let mut file = svt_file(&full);
        file.insert_meta("nelf_unreal_svt", n as i32);
        file.insert_meta("nelf_unreal_svt_count", count as i32);
        let path = sibling(out, &format!("_svt{n}.vdb"));
        files.push(write_svt(file, group, &path, options)?);
    }
    let density_file = if fine.is_some() {
        let mut file = svt_file(&full);
        file.insert_meta("nelf_unreal_density_svt", true);
        file.insert_meta("nelf_unreal_svt_count", count as i32);
        let path = sibling(out, "_density.vdb");
        Some(write_svt(file, &[density], &path, options)?)
    } else {
        None
    };

    let hlsl_path = sibling(out, ".relight.hlsl");
    let hlsl = match &density_file {
        None => relight_hlsl(files.len(), rank),
        Some(d) => relight_hlsl_fine_density(files.len(), rank, &d.file),
    };
    crate::write_atomic(&hlsl_path, hlsl.as_bytes())?;
    let light = lighting.project(asset)?;
    let texels: Vec<[f32; 3]> = std::iter::once(light.mean_rgb)
        .chain(light.component_rgb.iter().take(rank).copied())
        .collect();
    let light_path = sibling(out, ".projected_light.exr");
    nelf_scene::image_io::write_exr_rgb(&light_path, texels.len() as u32, 1, &texels)
        .map_err(|e| ExportError::Metadata(format!("{}: {e}", light_path.display())))?;

    let manifest = sibling(out, ".unreal.json");
    let report = UnrealReport {
        files,
        rank,
        manifest_file: file_name(&manifest),
        lighting: lighting.name().to_string(),
        hlsl_file: file_name(&hlsl_path),
        projected_light_file: file_name(&light_path),
        voxel_size: vdb_report.voxel_size,
        density_unit: vdb_report.density_unit,
        attribute_format: "16-bit float (Unreal SVT attributes A and B)".into(),
        density_file,
        density_factor: fine,
    };
    let text =
        serde_json::to_string_pretty(&report).map_err(|e| ExportError::Metadata(e.to_string()))? + "\n";
    crate::write_atomic(&manifest, text.as_bytes())?;
    Ok(report)
}

/// An SVT file with the export's file metadata.
fn svt_file(full: &VdbFile) -> VdbFile {
    let mut file = VdbFile::new();
    for (key, value) in full.metadata() {
        file.insert_meta(key, value.clone());
    }
    file
}

/// Adds `grids` to `file` as channels A.r, A.g, … and writes it to `path` atomically.
fn write_svt(
    mut file: VdbFile,
    grids: &[&AnyGrid],
    path: &Path,
    options: &VdbOptions,
) -> Result<UnrealFile, ExportError> {
    let mut channels = Vec::new();
    for (grid, (attr, channel)) in grids.iter().zip(CHANNELS) {
        file.push_grid((*grid).clone())?;
        channels.push(ChannelMap {
            grid: grid.name().to_string(),
            attributes: attr.into(),
            channel: channel.into(),
            range: range(grid),
        });
    }
    let bytes = file.encode(options.compression)?;
    crate::write_atomic(path, &bytes)?;
    Ok(UnrealFile {
        file: file_name(path),
        channels,
        file_size: bytes.len() as u64,
    })
}

fn file_name(path: &Path) -> String {
    path.file_name()
        .map_or_else(String::new, |n| n.to_string_lossy().into_owned())
}
