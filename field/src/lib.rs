//! `nelf-field`: the NeLF network (Sun, Lin, Bi, Xu, Ramamoorthi, "NeLF: Neural
//! Light-transport Field for Portrait View Synthesis and Relighting", EGSR 2021) in
//! candle, parameter-compatible with the official PyTorch checkpoint (key names of
//! its `state_dict`), checked against the official implementation's numbers
//! (`data/nelf-oracle/`, from the official code; `NELF_ORACLE_FIXTURES` adds more).
//!
//! * [`model::Model`]: encoder ([`encoder`]), light estimate ([`light`]), per-point
//!   networks ([`nelfnet`]), batched evaluation with visual-hull pruning;
//! * [`render`]: coarse/fine volume rendering of the network (the reference a bake
//!   must match);
//! * [`capture`]: a capture folder (metres, our world) as network inputs
//!   (millimetres, the network's world);
//! * [`calibrate`]: one gain on the light transport that makes the network reproduce
//!   its own source views under their known lighting;
//! * [`shipped`]: the network trained by `nelf train` and shipped with the tool;
//! * [`source::NelfField`]: the baker's [`nelf_scene::field::FieldSource`].
//!
//! Runs in `f32` on the CPU; the `cuda` feature enables candle's CUDA backend.

pub mod architecture;
pub mod calibrate;
pub mod capture;
pub mod cpu;
pub mod encoder;
pub mod error;
pub mod geometry;
pub mod layers;
pub mod light;
pub mod model;
pub mod nelfnet;
pub mod prior;
pub mod render;
pub mod shipped;
pub mod source;
pub mod views;

pub use architecture::Architecture;
pub use capture::NetCapture;
pub use error::NetError;
pub use model::{Model, NelfConfig, default_device, device_name, read_safetensors_bytes};
pub use source::NelfField;
pub use views::{EncodedViews, SourceViews, Stage};
