//! `nelf-scene`: ground truth for every accuracy figure in the project — meshes,
//! procedural heads, environment maps, a CPU light-transport path tracer and
//! synthetic captures.

pub mod bvh;
pub mod field;
pub mod mesh;
pub mod metrics;
pub mod render;
pub mod shapes;
pub mod tracer;
