//! `nelf-scene`: ground truth for every accuracy figure in the project — meshes,
//! procedural heads, environment maps, a CPU light-transport path tracer and
//! synthetic captures.

pub mod mesh;
pub mod metrics;
