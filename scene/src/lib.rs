//! `nelf-scene`: ground truth for every accuracy figure in the project — meshes,
//! procedural heads, environment maps, a CPU light-transport path tracer and
//! synthetic captures.
//!
//! `shot`: the cameras (camera files, capture views, orbits) and lightings (env-map
//! files, constant white) a render is made with, for every command that renders.

pub mod adapter;
pub mod bvh;
pub mod defects;
pub mod envgen;
pub mod envmap;
pub mod error;
pub mod field;
pub mod flip;
pub mod head;
pub mod image_io;
pub mod mesh;
pub mod mesh_io;
pub mod metrics;
pub mod render;
pub mod shapes;
pub mod shot;
pub mod signed_density;
pub mod srgb;
pub mod surface_nets;
pub mod synth;
pub mod tracer;
