//! `nelf-format`: the `.nelf` light-transport asset file (see `SPEC.md`), the
//! capture folder format (see `CAPTURE.md`) and the conventions every crate shares
//! (environment-map texels and their exact solid angles, light-frame rotations,
//! OpenCV pinhole cameras). No GPU, no network, no UI.

pub mod asset;
pub mod atomic;
pub mod capture;
pub mod colmap;
pub mod conventions;
pub mod envmap_file;
pub mod error;
pub mod grid;
pub mod inspect;
pub mod io_error;
pub mod orbit;
pub mod read;
pub mod spec;
pub mod synthetic;
pub mod write;

pub use asset::{
    Asset, BrickData, CoefficientEncoding, Coefficients, FineDensity, GridGeometry, PcaModel, Reflection,
    ViewDependence, encode_density, has_negative_density,
};
pub use error::FormatError;
pub use read::{AssetReader, read_asset, read_asset_bytes};
pub use write::{WriteOptions, WriteReport, encode_asset, write_asset};
