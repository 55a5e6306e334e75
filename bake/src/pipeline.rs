//! The names this module held before the bake was laid out as stages
//! ([`crate::stages`]), re-exported from where they now live so that old paths keep
//! working.

pub use crate::jobs::{bake_field, finish_bake, sample_field};
pub use crate::stages::outputs::{BakeOutput, BakeReport, SampledField, StageTimings};
pub use crate::stages::plan::{FieldBake, Reference, view_policy_for};
pub use crate::stages::quantize::quantization_step;
pub use crate::stages::view::{add_view_dependence, reflection_target};
pub use crate::stages::write::{sidecar_path, write_bake};
