//! A small writer of OpenVDB files (`.vdb`), written from OpenVDB's file layout as
//! OpenVDB 10 writes and reads it: file format version 224, library version 10.0,
//! grids of `float` (`Tree_float_5_4_3`) and `vec3s` (`Tree_vec3s_5_4_3`) values whose
//! leaves are fully active, a uniform scale + translation transform
//! (`UniformScaleTranslateMap`), string / number / vector metadata, and per-grid
//! compression "active values" (OpenVDB's `COMPRESS_ACTIVE_MASK`, no byte codec) or
//! "zip + active values" (zlib). No half floats, no tiles, no instancing, no Blosc.
//!
//! **Layout** (all little-endian):
//!
//! ```text
//! header    i64 magic 0x56444220 ("VDB "), u32 file version 224, u32 library major 10,
//!           u32 minor 0, u8 has-grid-offsets 1, 36 ASCII chars UUID
//! metadata  u32 count, then per entry (sorted by name): string name, string type name,
//!           u32 value size, value bytes            (string = u32 length + bytes)
//! u32 grid count, then per grid:
//!   string name, string tree type, string instance parent (empty),
//!   i64 grid position, i64 block position, i64 end position (absolute file offsets)
//!   grid:   u32 compression flags, metadata (as above), string map type + map,
//!           topology (i32 buffer count 1, root), then the leaf buffers
//! ```
//!
//! The tree is OpenVDB's 5-4-3 tree: a root holding upper internal nodes (32³ children,
//! 4096 voxels a side) keyed by origin, lower internal nodes (16³ children, 128 voxels),
//! leaves of 8³ voxels. Topology writes, for the root, its background value, the tile
//! count (0) and child count, then each upper node (origin first) in `(x, y, z)` origin
//! order; each internal node writes its child mask, its value mask (empty: no active
//! tiles), its values compressed (`NO_MASK_OR_INACTIVE_VALS`: every inactive value is
//! the background, so none are stored), then its children in child-index order, a leaf
//! writing just its value mask. The buffers then repeat, per leaf in the same order, its
//! value mask and its 512 values (node metadata byte 0 and, with zip, an `i64` byte count
//! — negative for data stored raw because zlib did not make it smaller — before them).
//! Inside every node the child or voxel index runs with `z` fastest:
//! `offset = (x << 2·log2dim) | (y << log2dim) | z` on the node-local coordinates.
//!
//! Output is a pure function of the grids: metadata is sorted by name, nodes by origin,
//! and the UUID (which OpenVDB draws at random) is derived from an XXH3-128 hash of the
//! bytes after it.

use std::collections::BTreeMap;

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::error::VdbError;

/// The file format version OpenVDB 10 writes (`OPENVDB_FILE_VERSION`).
pub const FILE_VERSION: u32 = 224;
/// The library version recorded in the header: OpenVDB 10.0.
pub const LIBRARY_VERSION: [u32; 2] = [10, 0];
/// `OPENVDB_MAGIC` ("VDB " as a little-endian `i64`).
const MAGIC: i64 = 0x5644_4220;
/// Where the 36-character UUID starts in the header.
const UUID_OFFSET: usize = 8 + 4 + 4 + 4 + 1;
/// Length of the UUID text (`8-4-4-4-12` hex digits).
const UUID_LEN: usize = 36;

/// Voxels along each axis of a leaf node.
pub const LEAF_DIM: i32 = 8;
/// Voxels in a leaf node.
pub const LEAF_VOXELS: usize = 512;
/// log2 of the children per axis of a lower internal node.
const LOWER_LOG2: u32 = 4;
/// log2 of the children per axis of an upper internal node.
const UPPER_LOG2: u32 = 5;
/// Voxels along each axis of a lower internal node (16 × 8).
const LOWER_SPAN: i32 = 128;
/// Voxels along each axis of an upper internal node (32 × 128).
const UPPER_SPAN: i32 = 4096;

/// `io::COMPRESS_ZIP`.
const COMPRESS_ZIP: u32 = 0x1;
/// `io::COMPRESS_ACTIVE_MASK`: only active values and at most two distinct inactive ones.
const COMPRESS_ACTIVE_MASK: u32 = 0x2;
/// Node metadata byte `NO_MASK_OR_INACTIVE_VALS`: inactive values are all the background.
const NO_MASK_OR_INACTIVE_VALS: u8 = 0;
/// zlib level of OpenVDB's `zipToStream` (`Z_DEFAULT_COMPRESSION`).
const ZIP_LEVEL: u32 = 6;

/// Per-grid compression of the node values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Compression {
    /// "active values": inactive background values are left out, the rest is stored raw.
    None,
    /// "zip + active values": each node's values are zlib-compressed (level 6, as OpenVDB).
    #[default]
    Zip,
}

impl Compression {
    /// OpenVDB's compression flags.
    pub fn flags(self) -> u32 {
        match self {
            Self::None => COMPRESS_ACTIVE_MASK,
            Self::Zip => COMPRESS_ZIP | COMPRESS_ACTIVE_MASK,
        }
    }

    /// OpenVDB's description of the flags (`io::compressionToString`).
    pub fn description(self) -> &'static str {
        match self {
            Self::None => "active values",
            Self::Zip => "zip + active values",
        }
    }
}

/// A metadata value (OpenVDB's `TypedMetadata` types used here).
#[derive(Debug, Clone, PartialEq)]
pub enum MetaValue {
    /// `string`
    String(String),
    /// `bool`
    Bool(bool),
    /// `int32`
    Int32(i32),
    /// `int64`
    Int64(i64),
    /// `float`
    Float(f32),
    /// `double`
    Double(f64),
    /// `vec3i`
    Vec3i([i32; 3]),
    /// `vec3d`
    Vec3d([f64; 3]),
}

impl MetaValue {
    /// OpenVDB's type name.
    pub fn type_name(&self) -> &'static str {
        match self {
            Self::String(_) => "string",
            Self::Bool(_) => "bool",
            Self::Int32(_) => "int32",
            Self::Int64(_) => "int64",
            Self::Float(_) => "float",
            Self::Double(_) => "double",
            Self::Vec3i(_) => "vec3i",
            Self::Vec3d(_) => "vec3d",
        }
    }

    fn value_bytes(&self) -> Vec<u8> {
        match self {
            Self::String(s) => s.as_bytes().to_vec(),
            Self::Bool(b) => vec![u8::from(*b)],
            Self::Int32(v) => v.to_le_bytes().to_vec(),
            Self::Int64(v) => v.to_le_bytes().to_vec(),
            Self::Float(v) => v.to_le_bytes().to_vec(),
            Self::Double(v) => v.to_le_bytes().to_vec(),
            Self::Vec3i(v) => v.iter().flat_map(|c| c.to_le_bytes()).collect(),
            Self::Vec3d(v) => v.iter().flat_map(|c| c.to_le_bytes()).collect(),
        }
    }
}

impl From<&str> for MetaValue {
    fn from(s: &str) -> Self {
        Self::String(s.to_string())
    }
}

impl From<String> for MetaValue {
    fn from(s: String) -> Self {
        Self::String(s)
    }
}

impl From<bool> for MetaValue {
    fn from(v: bool) -> Self {
        Self::Bool(v)
    }
}

impl From<i32> for MetaValue {
    fn from(v: i32) -> Self {
        Self::Int32(v)
    }
}

impl From<i64> for MetaValue {
    fn from(v: i64) -> Self {
        Self::Int64(v)
    }
}

impl From<f64> for MetaValue {
    fn from(v: f64) -> Self {
        Self::Double(v)
    }
}

/// A value type a grid can hold.
pub trait VoxelValue: Copy + Send + Sync + 'static {
    /// OpenVDB's tree type name, e.g. `Tree_float_5_4_3`.
    const TREE_TYPE: &'static str;
    /// Bytes per value in the file.
    const SIZE: usize;
    /// The zero value (our background).
    fn zero() -> Self;
    /// Appends the value's little-endian bytes.
    fn put(&self, out: &mut Vec<u8>);
    /// Whether every component is finite.
    fn is_finite(&self) -> bool;
}

impl VoxelValue for f32 {
    const TREE_TYPE: &'static str = "Tree_float_5_4_3";
    const SIZE: usize = 4;
    fn zero() -> Self {
        0.0
    }
    fn put(&self, out: &mut Vec<u8>) {
        out.extend_from_slice(&self.to_le_bytes());
    }
    fn is_finite(&self) -> bool {
        f32::is_finite(*self)
    }
}

impl VoxelValue for [f32; 3] {
    const TREE_TYPE: &'static str = "Tree_vec3s_5_4_3";
    const SIZE: usize = 12;
    fn zero() -> Self {
        [0.0; 3]
    }
    fn put(&self, out: &mut Vec<u8>) {
        for c in self {
            out.extend_from_slice(&c.to_le_bytes());
        }
    }
    fn is_finite(&self) -> bool {
        self.iter().copied().all(f32::is_finite)
    }
}

/// Index of local voxel `(x, y, z)` (each `0..8`) in a leaf's value array, OpenVDB's
/// order: `x` slowest, `z` fastest.
pub const fn leaf_offset(x: usize, y: usize, z: usize) -> usize {
    (x << 6) | (y << 3) | z
}

/// A uniform scale + translation index-to-world map (`UniformScaleTranslateMap`):
/// `world = translation + voxel_size · index`, so voxel `(i, j, k)` is centred on
/// `translation + voxel_size · (i, j, k)` (OpenVDB places voxel centres on integer
/// index coordinates).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Transform {
    /// Voxel edge length in world units.
    pub voxel_size: f64,
    /// World position of index `(0, 0, 0)`.
    pub translation: [f64; 3],
}

impl Transform {
    /// World position of an index coordinate.
    pub fn index_to_world(&self, ijk: [f64; 3]) -> [f64; 3] {
        std::array::from_fn(|a| self.translation[a] + self.voxel_size * ijk[a])
    }

    fn validate(&self) -> Result<(), VdbError> {
        let finite = self.translation.iter().copied().all(f64::is_finite);
        if !(finite && self.voxel_size.is_finite() && self.voxel_size > 0.0) {
            return Err(VdbError::BadTransform {
                voxel_size: self.voxel_size,
                translation: self.translation,
            });
        }
        Ok(())
    }

    /// `UniformScaleTranslateMap::write`: translation, then the scale map's scale,
    /// voxel size, inverse scale, inverse scale squared and half the inverse scale.
    fn write(&self, out: &mut Vec<u8>) {
        put_string(out, "UniformScaleTranslateMap");
        let s = self.voxel_size;
        let inverse = 1.0 / s;
        for v in [
            self.translation,
            [s; 3],
            [s; 3],
            [inverse; 3],
            [inverse * inverse; 3],
            [inverse / 2.0; 3],
        ] {
            for c in v {
                out.extend_from_slice(&c.to_le_bytes());
            }
        }
    }
}

/// OpenVDB's grid class metadata (`class`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum GridClass {
    /// No `class` entry (OpenVDB's `GRID_UNKNOWN`).
    #[default]
    Unknown,
    /// `"fog volume"`: a density.
    FogVolume,
}

/// One grid: a name, a transform, metadata and fully active 8³ leaves.
#[derive(Debug, Clone)]
pub struct Grid<T: VoxelValue> {
    name: String,
    class: GridClass,
    transform: Transform,
    metadata: BTreeMap<String, MetaValue>,
    leaves: BTreeMap<[i32; 3], Vec<T>>,
}

impl<T: VoxelValue> Grid<T> {
    /// An empty grid; `name` must be non-empty (OpenVDB renames unnamed grids).
    pub fn new(name: &str, class: GridClass, transform: Transform) -> Result<Self, VdbError> {
        if name.is_empty() {
            return Err(VdbError::EmptyName);
        }
        transform.validate()?;
        Ok(Self {
            name: name.to_string(),
            class,
            transform,
            metadata: BTreeMap::new(),
            leaves: BTreeMap::new(),
        })
    }

    /// The grid's name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The grid's transform.
    pub fn transform(&self) -> Transform {
        self.transform
    }

    /// Adds grid metadata (names starting `file_`, `name` and `class` are the writer's).
    pub fn insert_meta(&mut self, key: &str, value: impl Into<MetaValue>) -> Result<(), VdbError> {
        if reserved_grid_key(key) {
            return Err(VdbError::ReservedKey(key.to_string()));
        }
        self.metadata.insert(key.to_string(), value.into());
        Ok(())
    }

    /// Adds a leaf at `origin` (a multiple of 8 on each axis) with all 512 voxels active;
    /// `values` in OpenVDB's order ([`leaf_offset`]). A leaf already there is an error.
    pub fn insert_leaf(&mut self, origin: [i32; 3], values: Vec<T>) -> Result<(), VdbError> {
        if origin.iter().any(|c| c.rem_euclid(LEAF_DIM) != 0) {
            return Err(VdbError::LeafOrigin(origin));
        }
        if values.len() != LEAF_VOXELS {
            return Err(VdbError::LeafSize(values.len()));
        }
        if let Some(v) = values.iter().position(|v| !v.is_finite()) {
            return Err(VdbError::NotFinite {
                grid: self.name.clone(),
                origin,
                offset: v,
            });
        }
        if self.leaves.insert(origin, values).is_some() {
            return Err(VdbError::DuplicateLeaf(origin));
        }
        Ok(())
    }

    /// Active voxels (512 per leaf).
    pub fn active_voxel_count(&self) -> u64 {
        self.leaves.len() as u64 * LEAF_VOXELS as u64
    }

    /// The leaves, by origin.
    pub fn leaves(&self) -> impl Iterator<Item = (&[i32; 3], &[T])> {
        self.leaves.iter().map(|(o, v)| (o, v.as_slice()))
    }

    /// Inclusive index bounding box of the active voxels (`None` when empty).
    pub fn active_bbox(&self) -> Option<([i32; 3], [i32; 3])> {
        let mut it = self.leaves.keys();
        let first = *it.next()?;
        let (mut lo, mut hi) = (first, first);
        for o in it {
            for a in 0..3 {
                lo[a] = lo[a].min(o[a]);
                hi[a] = hi[a].max(o[a]);
            }
        }
        Some((lo, hi.map(|c| c + LEAF_DIM - 1)))
    }

    /// The metadata written with the grid: ours plus `name`, `class` and the statistics
    /// OpenVDB adds on writing (`file_bbox_min`/`max`, `file_compression`,
    /// `file_mem_bytes`, `file_voxel_count`).
    pub fn file_metadata(&self, compression: Compression) -> BTreeMap<String, MetaValue> {
        let mut meta = self.metadata.clone();
        meta.insert("name".into(), MetaValue::String(self.name.clone()));
        if self.class == GridClass::FogVolume {
            meta.insert("class".into(), "fog volume".into());
        }
        let (lo, hi) = self.active_bbox().unwrap_or(([0; 3], [0; 3]));
        meta.insert("file_bbox_min".into(), MetaValue::Vec3i(lo));
        meta.insert("file_bbox_max".into(), MetaValue::Vec3i(hi));
        meta.insert("file_compression".into(), compression.description().into());
        meta.insert(
            "file_mem_bytes".into(),
            MetaValue::Int64(i64::try_from(self.memory_estimate()).unwrap_or(i64::MAX)),
        );
        meta.insert(
            "file_voxel_count".into(),
            MetaValue::Int64(i64::try_from(self.active_voxel_count()).unwrap_or(i64::MAX)),
        );
        meta
    }

    /// Roughly what OpenVDB's tree occupies in memory (informational `file_mem_bytes`):
    /// per leaf its values and masks, per internal node its value/child-pointer table
    /// and masks.
    fn memory_estimate(&self) -> u64 {
        let tree = self.tree();
        let slot = T::SIZE.max(8) as u64;
        let lowers: usize = tree.values().map(BTreeMap::len).sum();
        let leaves = self.leaves.len() as u64;
        64 + tree.len() as u64 * (32768 * slot + 2 * 4096 + 16)
            + lowers as u64 * (4096 * slot + 2 * 512 + 16)
            + leaves * (LEAF_VOXELS as u64 * T::SIZE as u64 + 64 + 32)
    }

    /// The leaves grouped as OpenVDB's tree: upper node origin → lower node index →
    /// leaf index → leaf origin, each level in the order OpenVDB writes it.
    fn tree(&self) -> TreeLayout {
        let mut tree = TreeLayout::new();
        for &origin in self.leaves.keys() {
            let upper = origin.map(|c| c & !(UPPER_SPAN - 1));
            let lower = child_index(origin, UPPER_SPAN, LOWER_SPAN, UPPER_LOG2);
            let leaf = child_index(origin, LOWER_SPAN, LEAF_DIM, LOWER_LOG2);
            tree.entry(upper)
                .or_default()
                .entry(lower)
                .or_default()
                .insert(leaf, origin);
        }
        tree
    }

    /// Appends the grid (from its compression flags on) and returns the offset of its
    /// buffers relative to `out`'s start.
    fn write(&self, out: &mut Vec<u8>, compression: Compression) -> Result<usize, VdbError> {
        out.extend_from_slice(&compression.flags().to_le_bytes());
        write_metadata(out, &self.file_metadata(compression))?;
        self.transform.write(out);

        // Topology.
        let tree = self.tree();
        out.extend_from_slice(&1i32.to_le_bytes()); // buffer count
        T::zero().put(out); // background
        out.extend_from_slice(&0u32.to_le_bytes()); // tiles
        out.extend_from_slice(&len_u32(tree.len(), "root children")?.to_le_bytes());
        let mut leaf_order = Vec::with_capacity(self.leaves.len());
        for (upper_origin, lowers) in &tree {
            for c in upper_origin {
                out.extend_from_slice(&c.to_le_bytes());
            }
            write_internal_node(out, 1 << (3 * UPPER_LOG2), lowers.keys().copied(), compression);
            for leaves in lowers.values() {
                write_internal_node(out, 1 << (3 * LOWER_LOG2), leaves.keys().copied(), compression);
                for origin in leaves.values() {
                    out.extend_from_slice(&[0xFF; LEAF_VOXELS / 8]); // value mask: all on
                    leaf_order.push(*origin);
                }
            }
        }

        // Buffers: each leaf's value mask and values, encoded in parallel, in order.
        let block_pos = out.len();
        let encoded: Vec<Vec<u8>> = leaf_order
            .par_iter()
            .map(|origin| {
                let values = self.leaves.get(origin).map_or(&[][..], Vec::as_slice);
                let mut bytes = Vec::with_capacity(LEAF_VOXELS * T::SIZE + 80);
                bytes.extend_from_slice(&[0xFF; LEAF_VOXELS / 8]);
                bytes.push(NO_MASK_OR_INACTIVE_VALS);
                let mut raw = Vec::with_capacity(LEAF_VOXELS * T::SIZE);
                for v in values {
                    v.put(&mut raw);
                }
                write_data(&mut bytes, &raw, compression);
                bytes
            })
            .collect();
        for bytes in encoded {
            out.extend_from_slice(&bytes);
        }
        Ok(block_pos)
    }
}

/// Leaf origins of one lower internal node, by child index.
type LowerNode = BTreeMap<u32, [i32; 3]>;
/// Upper internal nodes by origin, each with its lower nodes by child index.
type TreeLayout = BTreeMap<[i32; 3], BTreeMap<u32, LowerNode>>;

/// Index of the child of a node of `span` voxels (`log2` children per axis) that holds
/// `origin`, `z` fastest.
fn child_index(origin: [i32; 3], span: i32, child_span: i32, log2: u32) -> u32 {
    let local = origin.map(|c| ((c & (span - 1)) / child_span) as u32);
    (local[0] << (2 * log2)) | (local[1] << log2) | local[2]
}

/// An internal node's topology: child mask, value mask (empty) and its values, all
/// inactive and equal to the background, so stored as none (`NO_MASK_OR_INACTIVE_VALS`).
fn write_internal_node(
    out: &mut Vec<u8>,
    slots: usize,
    children: impl Iterator<Item = u32>,
    compression: Compression,
) {
    let mut mask = vec![0u64; slots / 64];
    for c in children {
        mask[c as usize / 64] |= 1 << (c % 64);
    }
    for word in &mask {
        out.extend_from_slice(&word.to_le_bytes());
    }
    out.resize(out.len() + slots / 8, 0); // value mask
    out.push(NO_MASK_OR_INACTIVE_VALS);
    write_data(out, &[], compression);
}

/// `io::writeData`: raw bytes, or with zip an `i64` size and the zlib stream (a negative
/// size and the raw bytes when zlib does not make them smaller).
fn write_data(out: &mut Vec<u8>, raw: &[u8], compression: Compression) {
    match compression {
        Compression::None => out.extend_from_slice(raw),
        Compression::Zip => {
            let zipped = if raw.is_empty() { None } else { zlib(raw) };
            match zipped {
                Some(z) if z.len() < raw.len() => {
                    out.extend_from_slice(&(z.len() as i64).to_le_bytes());
                    out.extend_from_slice(&z);
                }
                _ => {
                    out.extend_from_slice(&(-(raw.len() as i64)).to_le_bytes());
                    out.extend_from_slice(raw);
                }
            }
        }
    }
}

/// zlib (RFC 1950) stream of `raw` at OpenVDB's level; `None` if the encoder fails.
fn zlib(raw: &[u8]) -> Option<Vec<u8>> {
    use std::io::Write as _;
    let mut encoder =
        flate2::write::ZlibEncoder::new(Vec::with_capacity(raw.len()), flate2::Compression::new(ZIP_LEVEL));
    encoder.write_all(raw).ok()?;
    encoder.finish().ok()
}

fn reserved_grid_key(key: &str) -> bool {
    key == "name" || key == "class" || key.starts_with("file_")
}

fn len_u32(n: usize, what: &'static str) -> Result<u32, VdbError> {
    u32::try_from(n).map_err(|_| VdbError::TooLarge(what))
}

/// `writeString`: `u32` length and the bytes.
fn put_string(out: &mut Vec<u8>, s: &str) {
    // Names and type names are short; metadata strings are length-checked by the caller.
    out.extend_from_slice(&(s.len() as u32).to_le_bytes());
    out.extend_from_slice(s.as_bytes());
}

/// `MetaMap::writeMeta`: count, then name, type name, size and value per entry, sorted.
fn write_metadata(out: &mut Vec<u8>, meta: &BTreeMap<String, MetaValue>) -> Result<(), VdbError> {
    out.extend_from_slice(&len_u32(meta.len(), "metadata entries")?.to_le_bytes());
    for (name, value) in meta {
        len_u32(name.len(), "metadata name")?;
        put_string(out, name);
        put_string(out, value.type_name());
        let bytes = value.value_bytes();
        out.extend_from_slice(&len_u32(bytes.len(), "metadata value")?.to_le_bytes());
        out.extend_from_slice(&bytes);
    }
    Ok(())
}

/// A grid of either value type.
#[derive(Debug, Clone)]
pub enum AnyGrid {
    /// `float` values.
    Float(Grid<f32>),
    /// `vec3s` values.
    Vec3s(Grid<[f32; 3]>),
}

impl AnyGrid {
    /// The grid's name.
    pub fn name(&self) -> &str {
        match self {
            Self::Float(g) => g.name(),
            Self::Vec3s(g) => g.name(),
        }
    }

    /// OpenVDB's tree type name.
    pub fn tree_type(&self) -> &'static str {
        match self {
            Self::Float(_) => f32::TREE_TYPE,
            Self::Vec3s(_) => <[f32; 3]>::TREE_TYPE,
        }
    }

    /// Active voxels.
    pub fn active_voxel_count(&self) -> u64 {
        match self {
            Self::Float(g) => g.active_voxel_count(),
            Self::Vec3s(g) => g.active_voxel_count(),
        }
    }

    fn write(&self, out: &mut Vec<u8>, compression: Compression) -> Result<usize, VdbError> {
        match self {
            Self::Float(g) => g.write(out, compression),
            Self::Vec3s(g) => g.write(out, compression),
        }
    }
}

impl From<Grid<f32>> for AnyGrid {
    fn from(g: Grid<f32>) -> Self {
        Self::Float(g)
    }
}

impl From<Grid<[f32; 3]>> for AnyGrid {
    fn from(g: Grid<[f32; 3]>) -> Self {
        Self::Vec3s(g)
    }
}

/// A whole file: file-level metadata and grids (written in the order added).
#[derive(Debug, Clone, Default)]
pub struct VdbFile {
    metadata: BTreeMap<String, MetaValue>,
    grids: Vec<AnyGrid>,
}

impl VdbFile {
    /// An empty file.
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds file-level metadata.
    pub fn insert_meta(&mut self, key: &str, value: impl Into<MetaValue>) {
        self.metadata.insert(key.to_string(), value.into());
    }

    /// File-level metadata.
    pub fn metadata(&self) -> &BTreeMap<String, MetaValue> {
        &self.metadata
    }

    /// Adds a grid; names must be unique (OpenVDB would rename a repeated one).
    pub fn push_grid(&mut self, grid: impl Into<AnyGrid>) -> Result<(), VdbError> {
        let grid = grid.into();
        if self.grids.iter().any(|g| g.name() == grid.name()) {
            return Err(VdbError::DuplicateGrid(grid.name().to_string()));
        }
        self.grids.push(grid);
        Ok(())
    }

    /// The grids, in file order.
    pub fn grids(&self) -> &[AnyGrid] {
        &self.grids
    }

    /// The file's bytes.
    pub fn encode(&self, compression: Compression) -> Result<Vec<u8>, VdbError> {
        let mut out = Vec::new();
        out.extend_from_slice(&MAGIC.to_le_bytes());
        out.extend_from_slice(&FILE_VERSION.to_le_bytes());
        out.extend_from_slice(&LIBRARY_VERSION[0].to_le_bytes());
        out.extend_from_slice(&LIBRARY_VERSION[1].to_le_bytes());
        out.push(1); // has grid offsets
        debug_assert_eq!(out.len(), UUID_OFFSET);
        out.resize(UUID_OFFSET + UUID_LEN, b'0'); // filled in below
        write_metadata(&mut out, &self.metadata)?;
        out.extend_from_slice(&len_u32(self.grids.len(), "grids")?.to_le_bytes());
        for grid in &self.grids {
            len_u32(grid.name().len(), "grid name")?;
            put_string(&mut out, grid.name());
            put_string(&mut out, grid.tree_type());
            put_string(&mut out, ""); // instance parent
            let offsets_at = out.len();
            out.resize(offsets_at + 24, 0);
            let grid_pos = out.len();
            let block_pos = grid.write(&mut out, compression)?;
            let end_pos = out.len();
            for (i, pos) in [grid_pos, block_pos, end_pos].into_iter().enumerate() {
                let at = offsets_at + 8 * i;
                out[at..at + 8].copy_from_slice(&(pos as i64).to_le_bytes());
            }
        }
        let uuid = content_uuid(&out[UUID_OFFSET + UUID_LEN..]);
        out[UUID_OFFSET..UUID_OFFSET + UUID_LEN].copy_from_slice(uuid.as_bytes());
        Ok(out)
    }
}

/// A UUID (text form, lowercase, version 8 "custom") from the XXH3-128 hash of `bytes`.
fn content_uuid(bytes: &[u8]) -> String {
    use std::fmt::Write as _;
    let mut b = xxhash_rust::xxh3::xxh3_128(bytes).to_be_bytes();
    b[6] = (b[6] & 0x0F) | 0x80; // version 8
    b[8] = (b[8] & 0x3F) | 0x80; // RFC 4122 variant
    let hex: String = b.iter().fold(String::with_capacity(32), |mut s, x| {
        // Writing to a String cannot fail.
        let _ = write!(s, "{x:02x}");
        s
    });
    format!(
        "{}-{}-{}-{}-{}",
        &hex[0..8],
        &hex[8..12],
        &hex[12..16],
        &hex[16..20],
        &hex[20..32]
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn transform() -> Transform {
        Transform {
            voxel_size: 0.25,
            translation: [1.0, 2.0, 3.0],
        }
    }

    #[test]
    fn child_indices_run_z_fastest() {
        assert_eq!(leaf_offset(1, 0, 0), 64);
        assert_eq!(leaf_offset(0, 1, 0), 8);
        assert_eq!(leaf_offset(0, 0, 1), 1);
        // Leaf at (8, 16, 24) inside the lower node at the origin: local (1, 2, 3).
        assert_eq!(
            child_index([8, 16, 24], LOWER_SPAN, LEAF_DIM, LOWER_LOG2),
            (1 << 8) | (2 << 4) | 3
        );
        // Negative origins belong to the node below zero.
        assert_eq!(child_index([-8, 0, 0], LOWER_SPAN, LEAF_DIM, LOWER_LOG2), 15 << 8);
        assert_eq!(
            child_index([128, 0, -128], UPPER_SPAN, LOWER_SPAN, UPPER_LOG2),
            (1 << 10) | 31
        );
    }

    #[test]
    fn leaves_are_checked() {
        let mut g = Grid::<f32>::new("d", GridClass::Unknown, transform()).unwrap();
        assert!(matches!(
            g.insert_leaf([1, 0, 0], vec![0.0; 512]),
            Err(VdbError::LeafOrigin(_))
        ));
        assert!(matches!(
            g.insert_leaf([0, 0, 0], vec![0.0; 5]),
            Err(VdbError::LeafSize(5))
        ));
        let mut bad = vec![0.0; 512];
        bad[7] = f32::NAN;
        assert!(matches!(
            g.insert_leaf([0, 0, 0], bad),
            Err(VdbError::NotFinite { offset: 7, .. })
        ));
        g.insert_leaf([0, 0, -8], vec![1.0; 512]).unwrap();
        assert!(matches!(
            g.insert_leaf([0, 0, -8], vec![1.0; 512]),
            Err(VdbError::DuplicateLeaf(_))
        ));
        assert_eq!(g.active_bbox(), Some(([0, 0, -8], [7, 7, -1])));
        assert!(matches!(
            g.insert_meta("file_x", 1),
            Err(VdbError::ReservedKey(_))
        ));
        assert!(Grid::<f32>::new("", GridClass::Unknown, transform()).is_err());
        let bad_transform = Transform {
            voxel_size: 0.0,
            ..transform()
        };
        assert!(Grid::<f32>::new("d", GridClass::Unknown, bad_transform).is_err());
        let mut file = VdbFile::new();
        file.push_grid(g.clone()).unwrap();
        assert!(matches!(file.push_grid(g), Err(VdbError::DuplicateGrid(_))));
    }

    /// The bytes of a one-leaf float grid, field by field.
    #[test]
    fn one_leaf_layout() {
        let mut g = Grid::<f32>::new("density", GridClass::FogVolume, transform()).unwrap();
        let values: Vec<f32> = (0..512).map(|v| v as f32).collect();
        g.insert_leaf([8, 0, 0], values.clone()).unwrap();
        let mut file = VdbFile::new();
        file.insert_meta("k", "v");
        file.push_grid(g).unwrap();
        let bytes = file.encode(Compression::None).unwrap();
        let mut r = Reader { bytes: &bytes, at: 0 };
        assert_eq!(r.i64(), 0x5644_4220);
        assert_eq!((r.u32(), r.u32(), r.u32(), r.u8()), (224, 10, 0, 1));
        let uuid = r.take(36);
        assert_eq!(uuid[8], b'-');
        assert_eq!(r.u32(), 1); // file metadata
        assert_eq!(
            (r.string(), r.string(), r.u32(), r.take(1)),
            ("k".into(), "string".into(), 1, &b"v"[..])
        );
        assert_eq!(r.u32(), 1); // grids
        assert_eq!(
            (r.string(), r.string(), r.string()),
            ("density".into(), "Tree_float_5_4_3".into(), String::new())
        );
        let (grid_pos, block_pos, end_pos) = (r.i64(), r.i64(), r.i64());
        assert_eq!(grid_pos as usize, r.at);
        assert_eq!(end_pos as usize, bytes.len());
        assert_eq!(r.u32(), 2); // active values
        let entries = r.u32();
        let mut names = Vec::new();
        for _ in 0..entries {
            names.push(r.string());
            let _type = r.string();
            let n = r.u32() as usize;
            r.take(n);
        }
        assert_eq!(
            names,
            [
                "class",
                "file_bbox_max",
                "file_bbox_min",
                "file_compression",
                "file_mem_bytes",
                "file_voxel_count",
                "name"
            ]
        );
        assert_eq!(r.string(), "UniformScaleTranslateMap");
        let map: Vec<f64> = (0..18).map(|_| r.f64()).collect();
        assert_eq!(&map[..6], &[1.0, 2.0, 3.0, 0.25, 0.25, 0.25]);
        assert_eq!(&map[9..], &[4.0, 4.0, 4.0, 16.0, 16.0, 16.0, 2.0, 2.0, 2.0]);
        // Topology: 1 buffer, background 0, no tiles, one upper node at the origin.
        assert_eq!((r.i32(), r.f32(), r.u32(), r.u32()), (1, 0.0, 0, 1));
        assert_eq!([r.i32(), r.i32(), r.i32()], [0, 0, 0]);
        let upper_children = r.take(4096);
        assert_eq!(upper_children[0], 1); // lower node 0
        assert!(upper_children[1..].iter().all(|&b| b == 0));
        assert!(r.take(4096).iter().all(|&b| b == 0));
        assert_eq!(r.u8(), 0); // NO_MASK_OR_INACTIVE_VALS, no values
        let lower_children = r.take(512);
        // Leaf (1, 0, 0) in its lower node: child index 1 << 8 = 256 → word 4, bit 0.
        assert_eq!(lower_children[32], 1);
        assert_eq!(lower_children.iter().map(|b| b.count_ones()).sum::<u32>(), 1);
        assert!(r.take(512).iter().all(|&b| b == 0));
        assert_eq!(r.u8(), 0);
        assert!(r.take(64).iter().all(|&b| b == 0xFF)); // leaf topology: value mask
        assert_eq!(r.at, block_pos as usize);
        assert!(r.take(64).iter().all(|&b| b == 0xFF));
        assert_eq!(r.u8(), 0);
        let read: Vec<f32> = (0..512).map(|_| r.f32()).collect();
        assert_eq!(read, values);
        assert_eq!(r.at, bytes.len());
        // Deterministic, and the UUID follows the content.
        assert_eq!(file.encode(Compression::None).unwrap(), bytes);
        file.insert_meta("k", "w");
        let other = file.encode(Compression::None).unwrap();
        assert_ne!(
            other[UUID_OFFSET..UUID_OFFSET + UUID_LEN],
            bytes[UUID_OFFSET..UUID_OFFSET + UUID_LEN]
        );
    }

    #[test]
    fn zip_stores_a_size_then_zlib_or_raw() {
        let mut out = Vec::new();
        write_data(&mut out, &[], Compression::Zip);
        assert_eq!(out, 0i64.to_le_bytes());
        let raw = vec![7u8; 2048];
        out.clear();
        write_data(&mut out, &raw, Compression::Zip);
        let n = i64::from_le_bytes(out[..8].try_into().unwrap());
        assert!(n > 0 && (n as usize) < raw.len());
        assert_eq!(out.len(), 8 + n as usize);
        let mut decoded = Vec::new();
        std::io::Read::read_to_end(&mut flate2::read::ZlibDecoder::new(&out[8..]), &mut decoded).unwrap();
        assert_eq!(decoded, raw);
        // Incompressible bytes are stored raw behind a negative size.
        let noise: Vec<u8> = (0..64u32)
            .map(|i| (i.wrapping_mul(2_654_435_761) >> 13) as u8)
            .collect();
        out.clear();
        write_data(&mut out, &noise, Compression::Zip);
        assert_eq!(i64::from_le_bytes(out[..8].try_into().unwrap()), -64);
        assert_eq!(&out[8..], &noise[..]);
    }

    struct Reader<'a> {
        bytes: &'a [u8],
        at: usize,
    }

    impl Reader<'_> {
        fn take(&mut self, n: usize) -> &[u8] {
            self.at += n;
            &self.bytes[self.at - n..self.at]
        }
        fn u8(&mut self) -> u8 {
            self.take(1)[0]
        }
        fn u32(&mut self) -> u32 {
            u32::from_le_bytes(self.take(4).try_into().unwrap())
        }
        fn i32(&mut self) -> i32 {
            i32::from_le_bytes(self.take(4).try_into().unwrap())
        }
        fn i64(&mut self) -> i64 {
            i64::from_le_bytes(self.take(8).try_into().unwrap())
        }
        fn f32(&mut self) -> f32 {
            f32::from_le_bytes(self.take(4).try_into().unwrap())
        }
        fn f64(&mut self) -> f64 {
            f64::from_le_bytes(self.take(8).try_into().unwrap())
        }
        fn string(&mut self) -> String {
            let n = self.u32() as usize;
            String::from_utf8(self.take(n).to_vec()).unwrap()
        }
    }
}
