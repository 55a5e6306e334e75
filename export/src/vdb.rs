//! `.nelf` asset → one OpenVDB file (`nelf export vdb`): the density, the asset relit
//! under one lighting as a colour grid, and the relightable part (PCA coefficient grids,
//! with the PCA mean and basis, `world_from_light` and the env-map convention in the
//! file metadata). `export/README.md` lists every grid and metadata key.
//!
//! **Placement.** The asset's brick `(bx, by, bz)` becomes the OpenVDB leaf with origin
//! `8·(bx, by, bz)`, so voxel `(i, j, k)` of that brick has index coordinate
//! `8·(bx, by, bz) + (i, j, k)`. OpenVDB centres a voxel on its index coordinate, and
//! our voxel centre is `bbox_min + (index + ½)·voxel_size` (SPEC.md §7), so the grid
//! transform is `world = s·(bbox_min + ½·voxel_size) + s·voxel_size·index` with `s`
//! the scene units per metre (`--scale`, 1 = metres). This is the standard placement
//! (Houdini, OpenVDB's tools); Blender's Cycles samples voxel `i` at index `i + ½`, so
//! there the volume object is moved by −½ voxel on each axis (README).
//!
//! **Fine density** (format 1.4, [`FineDensity`]). When the asset has one, the
//! `density` grid holds it instead of the voxels' σ, on its own transform: fine voxel
//! `(i, j, k)` (each in `0..8F`) of brick `b` has index `8F·b + (i, j, k)` (a brick is
//! `F³` leaves), centred, as SPEC.md §6 places it, at
//! `world = s·(bbox_min + ½·Δ/F) + s·(Δ/F)·index`. Every other grid stays on the
//! voxels; OpenVDB gives each grid its own transform, so a reader combines them in
//! world space. Without a fine density the file is exactly what it was before 1.4.
//!
//! **Values.** Every voxel of every brick (every fine voxel, for a fine density) is
//! active; the background is 0.
//! - `density`: the stored signed σ in 1/m (the fine σ when present) divided by `s`
//!   (1/scene unit): a renderer uses `max(0, trilinear σ)`.
//! - colour (`color`, or e.g. `Cd`): `nelf_render::voxel_radiance` under the lighting
//!   projected by `nelf_render::project_light` (or `project_light_texels` for light
//!   already in the asset's light frame), with the exported rank: the values
//!   `nelf render` shades with, not premultiplied by σ.
//! - `pca_00` … `pca_{K−1}`: the dequantized PCA coefficients; an engine relights with
//!   `radiance_c = P_mean,c + Σ_k pca_k · P_k,c` (SPEC.md §8).

use std::path::Path;
use std::time::Instant;

use glam::DMat3;
use nelf_format::conventions::{ENV_H, ENV_TEXELS, ENV_W, LatLong, rotation_y};
use nelf_format::spec::BRICK_VOXELS;
use nelf_format::{Asset, FineDensity};
use nelf_render::{ProjectedLight, project_light, project_light_texels, voxel_radiance};
use serde::{Deserialize, Serialize};

use crate::error::ExportError;
use crate::openvdb::{
    AnyGrid, Compression, Grid, GridClass, LEAF_VOXELS, MetaValue, Transform, VdbFile, leaf_offset,
};

/// Version of this grid and metadata layout (file metadata `nelf_vdb_layout`).
pub const LAYOUT_VERSION: i32 = 1;
/// Name of the density grid.
pub const DENSITY_GRID: &str = "density";
/// Default name of the relit colour grid (Blender's; Houdini's is `Cd`).
pub const DEFAULT_COLOR_GRID: &str = "color";
/// Metadata key of a `.nelf` asset under which `nelf export` looks for the capture's
/// estimated lighting (see [`stored_light`]).
pub const STORED_LIGHT_KEY: &str = "estimated_light";

/// How the PCA coefficients are laid out in grids ([`VdbOptions::pca_grids`]).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum PcaGrids {
    /// One float grid per component, `pca_00` … `pca_{K−1}` (OpenVDB's tools, Houdini).
    #[default]
    Float,
    /// Three components per vec3s grid, `pca3_00` holding components 0, 1, 2, `pca3_01`
    /// 3, 4, 5, …, zero past the rank: a third of the texture lookups for a renderer that
    /// relights in a shader (Blender's add-on: `BLENDER.md`).
    Vec3,
}

impl PcaGrids {
    /// The grid names for `rank` components.
    pub fn names(self, rank: usize) -> Vec<String> {
        match self {
            Self::Float => (0..rank).map(pca_grid_name).collect(),
            Self::Vec3 => (0..rank.div_ceil(3)).map(|g| format!("pca3_{g:02}")).collect(),
        }
    }

    /// The `nelf_pca_grid_type` metadata value.
    pub fn describe(self) -> &'static str {
        match self {
            Self::Float => "float: grid k holds component k",
            Self::Vec3 => "vec3s: grid g holds components 3g, 3g+1, 3g+2 (0 past nelf_pca_rank)",
        }
    }
}

/// Name of PCA coefficient grid `k`: `pca_00`, `pca_01`, …
pub fn pca_grid_name(k: usize) -> String {
    format!("pca_{k:02}")
}

/// Options of an OpenVDB export.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct VdbOptions {
    /// Scene units per metre: 1 writes metres, 100 centimetres. Lengths are multiplied
    /// by it, the density divided by it.
    pub scale: f64,
    /// PCA components to export, `1..=` the asset's rank (`None`: all). The colour grid
    /// is relit with the same components.
    pub rank: Option<usize>,
    /// Name of the relit colour grid (`color` for Blender, `Cd` for Houdini).
    pub color_name: String,
    /// Per-grid compression.
    pub compression: Compression,
    /// One float grid per PCA component, or three per vec3s grid.
    #[serde(default)]
    pub pca_grids: PcaGrids,
}

impl Default for VdbOptions {
    fn default() -> Self {
        Self {
            scale: 1.0,
            rank: None,
            color_name: DEFAULT_COLOR_GRID.to_string(),
            compression: Compression::Zip,
            pca_grids: PcaGrids::Float,
        }
    }
}

impl VdbOptions {
    /// Checks the options against an asset and returns the rank to export.
    pub fn validate(&self, asset: &Asset) -> Result<usize, ExportError> {
        if !(self.scale.is_finite() && self.scale > 0.0) {
            return Err(ExportError::BadOption(format!(
                "scale {} must be finite and positive",
                self.scale
            )));
        }
        let stored = asset.rank();
        let rank = match self.rank {
            None => stored,
            Some(k) if (1..=stored).contains(&k) => k,
            Some(k) => {
                return Err(ExportError::BadOption(format!(
                    "rank {k}: the asset has PCA rank {stored} (use 1..={stored})"
                )));
            }
        };
        let name = &self.color_name;
        if name.is_empty()
            || name == DENSITY_GRID
            || self.pca_grids.names(rank).contains(name)
            || name.chars().any(char::is_control)
        {
            return Err(ExportError::BadOption(format!(
                "colour grid name {name:?} must be non-empty, printable and differ from `{DENSITY_GRID}` and the pca_NN grids"
            )));
        }
        Ok(rank)
    }

    /// The unit of the density grid's values.
    pub fn density_unit(&self) -> String {
        if self.scale == 1.0 {
            "1/m".to_string()
        } else if self.scale == 100.0 {
            "1/cm".to_string()
        } else if self.scale == 1000.0 {
            "1/mm".to_string()
        } else {
            format!("1/({} m)", 1.0 / self.scale)
        }
    }
}

/// The lighting the colour grid is relit under.
#[derive(Debug, Clone)]
pub enum Lighting {
    /// A lat-long map of any resolution in the world frame, turned by `world_from_env`
    /// (a user's `--envmap`, or a built-in map).
    World {
        /// The map.
        env: LatLong,
        /// Rotation applied to the map (identity: as stored).
        world_from_env: DMat3,
        /// What it is, for metadata and reports.
        name: String,
    },
    /// 8 × 16 texels already in the asset's light frame (the capture's estimated light).
    LightFrame {
        /// The texels (mean radiance).
        texels: LatLong,
        /// What it is.
        name: String,
    },
}

impl Lighting {
    /// A world-frame map turned by `rotate_deg` about +y.
    pub fn world(env: LatLong, rotate_deg: f64, name: &str) -> Self {
        Self::World {
            env,
            world_from_env: rotation_y(rotate_deg.to_radians()),
            name: rotated_name(name, rotate_deg),
        }
    }

    /// The capture's estimated light stored in the asset ([`stored_light`]), turned by
    /// `rotate_deg` about +y; `None` when the asset stores none.
    pub fn stored(asset: &Asset, rotate_deg: f64) -> Result<Option<Self>, ExportError> {
        let Some(texels) = stored_light(asset)? else {
            return Ok(None);
        };
        let name = rotated_name("the capture's estimated light stored in the asset", rotate_deg);
        Ok(Some(if rotate_deg == 0.0 {
            Self::LightFrame { texels, name }
        } else {
            // Light-frame texels seen as a map whose frame is the light frame, turned.
            Self::World {
                env: texels,
                world_from_env: rotation_y(rotate_deg.to_radians()) * asset.world_from_light,
                name,
            }
        }))
    }

    /// What the lighting is.
    pub fn name(&self) -> &str {
        match self {
            Self::World { name, .. } | Self::LightFrame { name, .. } => name,
        }
    }

    /// The lighting projected onto the asset's PCA mean and basis (`nelf-render`).
    pub fn project(&self, asset: &Asset) -> Result<ProjectedLight, ExportError> {
        Ok(match self {
            Self::World {
                env, world_from_env, ..
            } => project_light(&asset.pca, asset.world_from_light, env, *world_from_env)?,
            Self::LightFrame { texels, .. } => project_light_texels(&asset.pca, texels)?,
        })
    }
}

fn rotated_name(name: &str, rotate_deg: f64) -> String {
    if rotate_deg == 0.0 {
        name.to_string()
    } else {
        format!("{name}, turned {rotate_deg} deg about +y")
    }
}

/// The capture's estimated lighting an asset stores in its metadata under
/// [`STORED_LIGHT_KEY`]: `{"frame": "light", "width": 16, "height": 8, "rgb": [[r, g, b],
/// … 128 texels, row-major from the zenith]}`, mean radiance per texel of the asset's
/// light frame (SPEC.md §8). `None` when the key is absent; an error when it is there
/// but malformed.
pub fn stored_light(asset: &Asset) -> Result<Option<LatLong>, ExportError> {
    let Some(value) = asset.metadata.get(STORED_LIGHT_KEY) else {
        return Ok(None);
    };
    let bad = |why: &str| ExportError::StoredLight(why.to_string());
    if value.get("frame").and_then(|f| f.as_str()) != Some("light") {
        return Err(bad("`frame` must be \"light\""));
    }
    let dims = (
        value.get("width").and_then(serde_json::Value::as_u64),
        value.get("height").and_then(serde_json::Value::as_u64),
    );
    if dims != (Some(ENV_W as u64), Some(ENV_H as u64)) {
        return Err(bad("`width` and `height` must be 16 and 8"));
    }
    let rgb: Vec<[f32; 3]> = value
        .get("rgb")
        .cloned()
        .map(serde_json::from_value)
        .transpose()
        .map_err(|e| ExportError::StoredLight(format!("`rgb`: {e}")))?
        .ok_or_else(|| bad("`rgb` is missing"))?;
    if rgb.len() != ENV_TEXELS || rgb.iter().flatten().any(|c| !c.is_finite()) {
        return Err(bad("`rgb` must hold 128 finite [r, g, b] texels"));
    }
    Ok(Some(
        LatLong::new(ENV_W, ENV_H, rgb).map_err(|e| ExportError::StoredLight(e.to_string()))?,
    ))
}

/// A grid of the export, for reports.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GridSummary {
    /// Grid name.
    pub name: String,
    /// OpenVDB tree type.
    pub tree_type: String,
    /// Active voxels.
    pub active_voxels: u64,
}

/// What an export wrote.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct VdbReport {
    /// The grids, in file order.
    pub grids: Vec<GridSummary>,
    /// PCA components exported.
    pub rank: usize,
    /// The asset's PCA rank.
    pub stored_rank: usize,
    /// The lighting of the colour grid.
    pub lighting: String,
    /// Voxel edge length in scene units.
    pub voxel_size: f64,
    /// The asset's fine-density factor `F` when the density grid holds its fine density
    /// (voxel edge `voxel_size / F`); `None` (and not in the JSON) when it holds the voxels'.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub density_factor: Option<u32>,
    /// Unit of the density grid.
    pub density_unit: String,
    /// File size in bytes.
    pub file_size: u64,
    /// Seconds projecting the lighting and relighting every voxel.
    pub relight_seconds: f64,
    /// Seconds building the grids (without relighting) and encoding the file.
    pub encode_seconds: f64,
}

/// The grids of an export, ready to encode, and the report (file size 0).
pub fn build_vdb(
    asset: &Asset,
    lighting: &Lighting,
    options: &VdbOptions,
) -> Result<(VdbFile, VdbReport), ExportError> {
    asset.validate()?;
    let rank = options.validate(asset)?;
    let start = Instant::now();
    let light = lighting.project(asset)?;
    let radiance = voxel_radiance(asset, &light, Some(rank));
    let relight_seconds = start.elapsed().as_secs_f64();

    let start = Instant::now();
    let s = options.scale;
    let voxel = asset.grid.voxel_size_m;
    let transform = Transform {
        voxel_size: s * voxel,
        translation: asset.grid.bbox_min_m.map(|m| s * (m + 0.5 * voxel)),
    };
    let fine = asset.fine_density.as_ref();
    let density_transform = fine.map_or(transform, |f| fine_transform(asset, f, s));
    // Our voxel order inside a brick is x fastest; OpenVDB's leaves run z fastest.
    let slots: Vec<usize> = (0..BRICK_VOXELS)
        .map(|l| leaf_offset(l % 8, (l / 8) % 8, l / 64))
        .collect();
    let origins: Vec<[i32; 3]> = asset.bricks.iter().map(|b| b.map(|c| 8 * i32::from(c))).collect();

    let mut density = Grid::<f32>::new(DENSITY_GRID, GridClass::FogVolume, density_transform)?;
    let mut color = Grid::<[f32; 3]>::new(&options.color_name, GridClass::Unknown, transform)?;
    let pca_names = options.pca_grids.names(rank);
    let mut pca: Vec<Grid<f32>> = Vec::new();
    let mut pca3: Vec<Grid<[f32; 3]>> = Vec::new();
    for name in &pca_names {
        match options.pca_grids {
            PcaGrids::Float => pca.push(Grid::new(name, GridClass::Unknown, transform)?),
            PcaGrids::Vec3 => pca3.push(Grid::new(name, GridClass::Unknown, transform)?),
        }
    }
    let stored_rank = asset.rank();
    let mut coefficients = vec![0.0f32; stored_rank];
    for (b, &origin) in origins.iter().enumerate() {
        let mut sigma = vec![0.0f32; LEAF_VOXELS];
        let mut rgb = vec![[0.0f32; 3]; LEAF_VOXELS];
        let mut coef = vec![vec![0.0f32; LEAF_VOXELS]; rank];
        for (l, &slot) in slots.iter().enumerate() {
            let v = b * BRICK_VOXELS + l;
            if fine.is_none() {
                sigma[slot] = (f64::from(asset.density[v].to_f32()) / s) as f32;
            }
            rgb[slot] = radiance[v];
            asset.coefficients.voxel_f32(v, &mut coefficients);
            for (grid, &c) in coef.iter_mut().zip(&coefficients) {
                grid[slot] = c;
            }
        }
        match fine {
            None => density.insert_leaf(origin, sigma)?,
            Some(f) => {
                for (leaf_origin, values) in fine_density_leaves(f, b, asset.bricks[b], s) {
                    density.insert_leaf(leaf_origin, values)?;
                }
            }
        }
        color.insert_leaf(origin, rgb)?;
        if options.pca_grids == PcaGrids::Vec3 {
            for (g, grid) in pca3.iter_mut().enumerate() {
                let component = |k: usize, slot: usize| coef.get(k).map_or(0.0, |c: &Vec<f32>| c[slot]);
                let values = (0..LEAF_VOXELS)
                    .map(|slot| [0, 1, 2].map(|j| component(3 * g + j, slot)))
                    .collect();
                grid.insert_leaf(origin, values)?;
            }
        }
        for (grid, values) in pca.iter_mut().zip(coef) {
            grid.insert_leaf(origin, values)?;
        }
    }

    let unit = options.density_unit();
    density.insert_meta("nelf_unit", unit.clone())?;
    match fine {
        None => density.insert_meta(
            "nelf_quantity",
            "extinction coefficient sigma, signed as stored: render max(0, trilinear sigma)",
        )?,
        Some(f) => {
            density.insert_meta("nelf_density_factor", factor_i32(f)?)?;
            density.insert_meta(
                "nelf_quantity",
                "fine extinction coefficient sigma (the asset's fine density, nelf_density_factor times finer per axis than the other grids, on its own transform), signed as stored: render max(0, trilinear sigma)",
            )?;
        }
    }
    color.insert_meta(
        "nelf_quantity",
        "radiance relit under nelf_color_lighting (file metadata), linear RGB, not premultiplied by density",
    )?;
    color.insert_meta("nelf_lighting", lighting.name())?;
    for (k, grid) in pca.iter_mut().enumerate() {
        grid.insert_meta("nelf_pca_component", k as i32)?;
        grid.insert_meta(
            "nelf_quantity",
            "PCA coefficient of the light-transport vector (file metadata nelf_relight)",
        )?;
    }
    for (g, grid) in pca3.iter_mut().enumerate() {
        grid.insert_meta("nelf_pca_component", (3 * g) as i32)?;
        grid.insert_meta(
            "nelf_quantity",
            "PCA coefficients 3g, 3g+1, 3g+2 of the light-transport vector, 0 past the rank (file metadata nelf_relight)",
        )?;
    }

    let mut file = VdbFile::new();
    file_metadata(&mut file, asset, lighting, options, rank)?;
    file.push_grid(density)?;
    file.push_grid(color)?;
    for grid in pca {
        file.push_grid(grid)?;
    }
    for grid in pca3 {
        file.push_grid(grid)?;
    }
    let report = VdbReport {
        grids: file.grids().iter().map(summary).collect(),
        rank,
        stored_rank,
        lighting: lighting.name().to_string(),
        voxel_size: transform.voxel_size,
        density_factor: fine.map(|f| f.factor),
        density_unit: unit,
        file_size: 0,
        relight_seconds,
        encode_seconds: start.elapsed().as_secs_f64(),
    };
    Ok((file, report))
}

/// The density grid's transform for a fine density: voxel edge `s·Δ/F`, fine voxel
/// `(i, j, k)` of brick `b` at index `8F·b + (i, j, k)` centred on
/// `s·(bbox_min + (index + ½)·Δ/F)` (SPEC.md §6), OpenVDB centring voxels on their index.
fn fine_transform(asset: &Asset, fine: &FineDensity, s: f64) -> Transform {
    let fine_voxel = asset.grid.voxel_size_m / f64::from(fine.factor);
    Transform {
        voxel_size: s * fine_voxel,
        translation: asset.grid.bbox_min_m.map(|m| s * (m + 0.5 * fine_voxel)),
    }
}

/// The `F³` OpenVDB leaves of brick `b` (at `brick`) of a fine density, σ divided by `s`:
/// leaf `(lx, ly, lz)` (each in `0..F`) has origin `8F·brick + 8·(lx, ly, lz)` and holds
/// fine voxels `8·(lx, ly, lz) + (x, y, z)` of the brick at OpenVDB's offsets.
fn fine_density_leaves(fine: &FineDensity, b: usize, brick: [u16; 3], s: f64) -> Vec<([i32; 3], Vec<f32>)> {
    let f = fine.factor as usize;
    let edge = fine.brick_edge();
    let per_brick = fine.voxels_per_brick();
    let values = &fine.values[b * per_brick..(b + 1) * per_brick];
    let base = brick.map(|c| edge as i32 * i32::from(c));
    let mut leaves = Vec::with_capacity(f * f * f);
    for lx in 0..f {
        for ly in 0..f {
            for lz in 0..f {
                let mut leaf = vec![0.0f32; LEAF_VOXELS];
                for x in 0..8 {
                    for y in 0..8 {
                        for z in 0..8 {
                            let (i, j, k) = (8 * lx + x, 8 * ly + y, 8 * lz + z);
                            let sigma = values[i + edge * (j + edge * k)].to_f32();
                            leaf[leaf_offset(x, y, z)] = (f64::from(sigma) / s) as f32;
                        }
                    }
                }
                let origin = [lx, ly, lz].map(|l| 8 * l as i32);
                leaves.push((std::array::from_fn(|a| base[a] + origin[a]), leaf));
            }
        }
    }
    leaves
}

/// The fine-density factor as the `int32` OpenVDB metadata holds.
fn factor_i32(fine: &FineDensity) -> Result<i32, ExportError> {
    i32::try_from(fine.factor)
        .map_err(|_| ExportError::Metadata(format!("fine density factor {} out of range", fine.factor)))
}

fn summary(grid: &AnyGrid) -> GridSummary {
    GridSummary {
        name: grid.name().to_string(),
        tree_type: grid.tree_type().to_string(),
        active_voxels: grid.active_voxel_count(),
    }
}

/// The file-level metadata (README lists the keys).
fn file_metadata(
    file: &mut VdbFile,
    asset: &Asset,
    lighting: &Lighting,
    options: &VdbOptions,
    rank: usize,
) -> Result<(), ExportError> {
    let m = asset.world_from_light;
    let rows: [[f64; 3]; 3] = [0, 1, 2].map(|r| m.row(r).to_array());
    let basis: Vec<&[f32]> = (0..rank).map(|k| asset.pca.component(k)).collect();
    let pca_names = options.pca_grids.names(rank);
    file.insert_meta("nelf_vdb_layout", LAYOUT_VERSION);
    file.insert_meta(
        "nelf_generator",
        format!("nelf-export {}", env!("CARGO_PKG_VERSION")),
    );
    file.insert_meta("nelf_scale", options.scale);
    file.insert_meta("nelf_scene_unit_m", 1.0 / options.scale);
    file.insert_meta("nelf_voxel_size_m", asset.grid.voxel_size_m);
    file.insert_meta("nelf_bbox_min_m", MetaValue::Vec3d(asset.grid.bbox_min_m));
    file.insert_meta(
        "nelf_index_placement",
        "brick (bx,by,bz) voxel (i,j,k) has index 8*(bx,by,bz)+(i,j,k); OpenVDB standard: the voxel is centred on its index coordinate, world = scale*(bbox_min_m + (index + 0.5)*voxel_size_m); Cycles samples at index + 0.5, so move the Blender object by -0.5 voxel per axis",
    );
    file.insert_meta("nelf_density_grid", DENSITY_GRID);
    file.insert_meta("nelf_density_unit", options.density_unit());
    if let Some(fine) = &asset.fine_density {
        file.insert_meta("nelf_density_factor", factor_i32(fine)?);
        file.insert_meta(
            "nelf_density_voxel_size_m",
            asset.grid.voxel_size_m / f64::from(fine.factor),
        );
        file.insert_meta(
            "nelf_density_index_placement",
            "the density grid holds the asset's fine density (format 1.4) on its own transform: fine voxel (i,j,k) of brick (bx,by,bz), each of i,j,k in 0..8F with F = nelf_density_factor, has index 8F*(bx,by,bz)+(i,j,k); world = scale*(bbox_min_m + (index + 0.5)*voxel_size_m/F); the other grids follow nelf_index_placement; Cycles samples each grid at index + 0.5 of its own voxels",
        );
    }
    file.insert_meta("nelf_color_grid", options.color_name.as_str());
    file.insert_meta("nelf_color_lighting", lighting.name());
    file.insert_meta("nelf_pca_grids", json(&pca_names)?);
    file.insert_meta("nelf_pca_grid_type", options.pca_grids.describe());
    file.insert_meta("nelf_pca_rank", rank as i32);
    file.insert_meta("nelf_pca_stored_rank", asset.rank() as i32);
    file.insert_meta("nelf_pca_mean", json(&asset.pca.mean)?);
    file.insert_meta("nelf_pca_basis", json(&basis)?);
    file.insert_meta(
        "nelf_coefficients",
        format!(
            "dequantized to f32 from the asset's {} coefficients",
            asset.coefficients.encoding().name()
        ),
    );
    file.insert_meta(
        "nelf_lt_layout",
        "light-transport vector T of 384 = 3 channels x 128 texels, index j = c*128 + row*16 + col, c in (R, G, B); T = nelf_pca_mean + sum_k pca_k * nelf_pca_basis[k]",
    );
    file.insert_meta("nelf_world_from_light", json(&rows)?);
    file.insert_meta("nelf_env_height", ENV_H as i32);
    file.insert_meta("nelf_env_width", ENV_W as i32);
    file.insert_meta(
        "nelf_envmap_convention",
        "lat-long 8x16 in the light frame; row r covers polar angle theta in [r*pi/8, (r+1)*pi/8] from +y; column c covers azimuth phi in [c*2pi/16 - pi, (c+1)*2pi/16 - pi]; direction (sin theta sin phi, cos theta, -sin theta cos phi); world direction = nelf_world_from_light (row-major 3x3) * light direction; texel value L = mean radiance over the texel, its solid angle is folded into T; world frame right-handed, +y up",
    );
    file.insert_meta(
        "nelf_relight",
        "radiance_c = P_mean_c + sum_k pca_k * P_k_c with P_mean_c = sum_t mean[c*128+t] * L[t][c] and P_k_c = sum_t basis[k][c*128+t] * L[t][c]; volume: emission-absorption with density max(0, trilinear density) and emitted radiance trilinear radiance",
    );
    Ok(())
}

/// JSON text of a metadata array (f32 as the shortest text that reads back exactly).
fn json<T: Serialize + ?Sized>(value: &T) -> Result<String, ExportError> {
    serde_json::to_string(value).map_err(|e| ExportError::Metadata(e.to_string()))
}

/// The bytes of the OpenVDB file and the report (with the file size).
pub fn encode_vdb(
    asset: &Asset,
    lighting: &Lighting,
    options: &VdbOptions,
) -> Result<(Vec<u8>, VdbReport), ExportError> {
    let (file, mut report) = build_vdb(asset, lighting, options)?;
    let start = Instant::now();
    let bytes = file.encode(options.compression)?;
    report.encode_seconds += start.elapsed().as_secs_f64();
    report.file_size = bytes.len() as u64;
    Ok((bytes, report))
}

/// Exports `asset` to the OpenVDB file `path`, atomically ([`crate::write_atomic`]).
pub fn write_vdb(
    path: &Path,
    asset: &Asset,
    lighting: &Lighting,
    options: &VdbOptions,
) -> Result<VdbReport, ExportError> {
    let (bytes, report) = encode_vdb(asset, lighting, options)?;
    crate::write_atomic(path, &bytes)?;
    Ok(report)
}

#[cfg(test)]
mod tests {
    use nelf_format::CoefficientEncoding;
    use nelf_format::synthetic::synthetic_asset;

    use super::*;

    fn asset() -> Asset {
        synthetic_asset(3000, 4, CoefficientEncoding::U8Affine, 5).unwrap()
    }

    fn white() -> Lighting {
        Lighting::world(LatLong::constant(ENV_W, ENV_H, [1.0; 3]), 0.0, "white")
    }

    #[test]
    fn options_are_checked() {
        let asset = asset();
        let ok = VdbOptions::default();
        assert_eq!(ok.validate(&asset).unwrap(), 4);
        for bad in [
            VdbOptions {
                scale: 0.0,
                ..ok.clone()
            },
            VdbOptions {
                scale: f64::NAN,
                ..ok.clone()
            },
            VdbOptions {
                rank: Some(0),
                ..ok.clone()
            },
            VdbOptions {
                rank: Some(5),
                ..ok.clone()
            },
            VdbOptions {
                color_name: String::new(),
                ..ok.clone()
            },
            VdbOptions {
                color_name: "density".into(),
                ..ok.clone()
            },
            VdbOptions {
                color_name: "pca_03".into(),
                ..ok.clone()
            },
        ] {
            assert!(
                matches!(build_vdb(&asset, &white(), &bad), Err(ExportError::BadOption(_))),
                "{bad:?}"
            );
        }
        // `pca_03` is free when only three components are exported.
        let cut = VdbOptions {
            rank: Some(3),
            color_name: "pca_03".into(),
            ..ok
        };
        assert_eq!(cut.validate(&asset).unwrap(), 3);
        assert_eq!(
            VdbOptions {
                scale: 100.0,
                ..VdbOptions::default()
            }
            .density_unit(),
            "1/cm"
        );
        assert_eq!(
            VdbOptions {
                scale: 2.0,
                ..VdbOptions::default()
            }
            .density_unit(),
            "1/(0.5 m)"
        );
    }

    /// Leaves hold each brick's voxels at OpenVDB's offsets, and the colour grid the
    /// values of `nelf_render::voxel_radiance`.
    #[test]
    fn grids_hold_the_asset_voxels() {
        let asset = asset();
        let lighting = white();
        let options = VdbOptions {
            rank: Some(3),
            ..VdbOptions::default()
        };
        let (file, report) = build_vdb(&asset, &lighting, &options).unwrap();
        let names: Vec<&str> = file.grids().iter().map(AnyGrid::name).collect();
        assert_eq!(names, ["density", "color", "pca_00", "pca_01", "pca_02"]);
        assert_eq!(report.rank, 3);
        let radiance = voxel_radiance(&asset, &lighting.project(&asset).unwrap(), Some(3));
        let AnyGrid::Vec3s(color) = &file.grids()[1] else {
            panic!("colour is vec3s")
        };
        let AnyGrid::Float(density) = &file.grids()[0] else {
            panic!("density is float")
        };
        let AnyGrid::Float(pca2) = &file.grids()[4] else {
            panic!("pca is float")
        };
        let mut coefficients = vec![0.0; 4];
        for (b, brick) in asset.bricks.iter().enumerate() {
            let origin = brick.map(|c| 8 * i32::from(c));
            let (_, rgb) = color.leaves().find(|(o, _)| **o == origin).unwrap();
            let (_, sigma) = density.leaves().find(|(o, _)| **o == origin).unwrap();
            let (_, c2) = pca2.leaves().find(|(o, _)| **o == origin).unwrap();
            for (i, j, k) in [(0, 0, 0), (1, 0, 0), (0, 2, 0), (3, 5, 7), (7, 7, 7)] {
                let v = b * 512 + i + 8 * j + 64 * k;
                let slot = leaf_offset(i, j, k);
                assert_eq!(rgb[slot], radiance[v]);
                assert_eq!(sigma[slot], asset.density[v].to_f32());
                asset.coefficients.voxel_f32(v, &mut coefficients);
                assert_eq!(c2[slot], coefficients[2]);
            }
        }
        let t = color.transform();
        let centre = asset.voxel_position_m(0);
        let index = asset.bricks[0].map(|c| 8.0 * f64::from(c));
        let world = t.index_to_world(index);
        for a in 0..3 {
            assert!((world[a] - centre[a]).abs() < 1e-12, "{world:?} vs {centre:?}");
        }
    }

    /// `PcaGrids::Vec3`: components 3g, 3g+1, 3g+2 in grid g, zero past the rank.
    #[test]
    fn vec3_grids_hold_three_components_each() {
        let asset = asset();
        let options = VdbOptions {
            pca_grids: PcaGrids::Vec3,
            ..VdbOptions::default()
        };
        let (file, report) = build_vdb(&asset, &white(), &options).unwrap();
        let names: Vec<&str> = file.grids().iter().map(AnyGrid::name).collect();
        assert_eq!(names, ["density", "color", "pca3_00", "pca3_01"]);
        assert_eq!(report.rank, 4);
        assert!(file.metadata()["nelf_pca_grids"] == MetaValue::String(r#"["pca3_00","pca3_01"]"#.into()));
        let mut coefficients = vec![0.0; 4];
        for (g, grid) in file.grids()[2..].iter().enumerate() {
            let AnyGrid::Vec3s(grid) = grid else {
                panic!("coefficient groups are vec3s")
            };
            for (b, brick) in asset.bricks.iter().enumerate() {
                let origin = brick.map(|c| 8 * i32::from(c));
                let (_, values) = grid.leaves().find(|(o, _)| **o == origin).unwrap();
                for (i, j, k) in [(0, 0, 0), (3, 5, 7), (7, 7, 7)] {
                    let v = b * 512 + i + 8 * j + 64 * k;
                    asset.coefficients.voxel_f32(v, &mut coefficients);
                    let want = [0, 1, 2].map(|c| coefficients.get(3 * g + c).copied().unwrap_or(0.0));
                    assert_eq!(values[leaf_offset(i, j, k)], want);
                }
            }
        }
        // Its names are taken too.
        let clash = VdbOptions {
            color_name: "pca3_01".into(),
            ..options
        };
        assert!(matches!(clash.validate(&asset), Err(ExportError::BadOption(_))));
    }

    #[test]
    fn stored_light_is_read_or_refused() {
        let mut asset = asset();
        assert!(stored_light(&asset).unwrap().is_none());
        assert!(Lighting::stored(&asset, 0.0).unwrap().is_none());
        let rgb: Vec<[f32; 3]> = (0..128).map(|t| [t as f32, 1.0, 0.5]).collect();
        asset.metadata[STORED_LIGHT_KEY] =
            serde_json::json!({"frame": "light", "width": 16, "height": 8, "rgb": rgb});
        let light = stored_light(&asset).unwrap().unwrap();
        assert_eq!(light.texels()[5], [5.0, 1.0, 0.5]);
        // Unturned, it projects exactly like nelf-render's light-frame projection.
        let lighting = Lighting::stored(&asset, 0.0).unwrap().unwrap();
        assert_eq!(
            lighting.project(&asset).unwrap(),
            project_light_texels(&asset.pca, &light).unwrap()
        );
        assert!(matches!(
            Lighting::stored(&asset, 30.0).unwrap(),
            Some(Lighting::World { .. })
        ));
        asset.metadata[STORED_LIGHT_KEY]["rgb"] = serde_json::json!([[1.0, 2.0, 3.0]]);
        assert!(matches!(stored_light(&asset), Err(ExportError::StoredLight(_))));
        asset.metadata[STORED_LIGHT_KEY] = serde_json::json!({"frame": "world"});
        assert!(matches!(stored_light(&asset), Err(ExportError::StoredLight(_))));
    }

    #[test]
    fn scale_converts_lengths_and_density() {
        let asset = asset();
        let options = VdbOptions {
            scale: 100.0,
            ..VdbOptions::default()
        };
        let (file, report) = build_vdb(&asset, &white(), &options).unwrap();
        assert_eq!(report.density_unit, "1/cm");
        assert!((report.voxel_size - 100.0 * asset.grid.voxel_size_m).abs() < 1e-12);
        let AnyGrid::Float(density) = &file.grids()[0] else {
            panic!("density is float")
        };
        let (origin, sigma) = density.leaves().next().unwrap();
        let b = asset
            .find_brick([origin[0], origin[1], origin[2]].map(|c| (c / 8) as u16))
            .unwrap();
        let v = b * 512 + 1;
        assert_eq!(
            sigma[leaf_offset(1, 0, 0)],
            (f64::from(asset.density[v].to_f32()) / 100.0) as f32
        );
    }
}
