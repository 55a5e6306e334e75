//! `nelf-format`: the `.nelf` light-transport asset file (see `SPEC.md`), the
//! capture folder format (see `CAPTURE.md`) and the conventions every crate shares
//! (environment-map texels and their exact solid angles, light-frame rotations,
//! OpenCV pinhole cameras). No GPU, no network, no UI.

pub mod capture;
pub mod colmap;
pub mod conventions;
