//! `nelf-export`: writes `.nelf` assets in formats other tools read. It implements the
//! OpenVDB export (`nelf export vdb`, [`vdb`]): one `.vdb` file with the density, the
//! asset relit under one lighting as a colour grid for DCC tools (Blender, Houdini),
//! and the PCA coefficient grids with the PCA mean and basis in the file metadata for
//! engines that relight themselves; written by our own OpenVDB 10 writer
//! ([`openvdb`]: no crate that builds here writes OpenVDB). `export/README.md`
//! lists the grids, units and metadata keys and how to import the file.
//! [`commands`] holds what each `nelf export` subcommand does, as one call taking
//! the command's settings ([`export_vdb`], [`export_web`]).
//!
//! Depends on `nelf-format` and `nelf-render` (relighting is `nelf-render`'s), never on
//! wgpu or candle.

pub mod commands;
pub mod error;
pub mod openvdb;
pub mod shaders;
pub mod unreal;
pub mod vdb;
pub mod web;

use std::path::Path;

use nelf_format::io_error::IoResultExt;

pub use commands::{
    VdbExportConfig, VdbExported, VdbPreset, WebExportConfig, export_vdb, export_web, studio_envmap,
};
pub use error::{ExportError, VdbError};
pub use openvdb::{Compression, VdbFile};
pub use vdb::{Lighting, VdbOptions, VdbReport, build_vdb, encode_vdb, stored_light, write_vdb};

/// Writes `bytes` to `path` atomically (`nelf_format::atomic`: the mode a plain
/// create gives, synced, renamed), so nothing half-written ever has the final name.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), ExportError> {
    nelf_format::atomic::write_bytes_atomically(path, bytes)
        .with_path(path)
        .map_err(ExportError::from)
}
