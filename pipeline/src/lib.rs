//! `nelf-pipeline`: from a capture's photos to a `.nelf` asset, the part that knows
//! about more than one field.
//!
//! 1. **Which field** ([`capture_bake`]): a capture is baked from its ground truth
//!    (a mesh, or a synthetic capture's `synth_config.json`) or from the NeLF
//!    network evaluated on its own images ([`SourceChoice`], `nelf bake capture`).
//! 2. **The network's field** ([`network`]): weights loaded, views encoded, light
//!    transport put in the capture's light units and fitted to its views
//!    ([`SourceFit`]), and what a bake records of it.
//! 3. **Between a field and the baker** (the adapters [`voxel_filter`] and
//!    [`split`], on `nelf-scene`'s one delegation mechanism [`Adapter`] /
//!    [`Adapted`]): the network bake's box filter, and parts of one field swapped
//!    for another's.
//! 4. **The network's bake** ([`network_bake`]): filtered, its density signed and
//!    carved to the masks' hull, optionally with a part from the ground truth
//!    ([`truth_split`], `nelf eval network --split`), baked by `nelf-bake`.
//! 5. **Settings** ([`config`]): the network-only options beside `nelf-bake`'s
//!    [`nelf_bake::BakeConfig`], saved with the asset as one flat object.
//! 6. **Photographs by reconstruction** ([`photo`], `--source photos`): the masks'
//!    visual hull as a mesh, its reflectance from the photographs, baked as a mesh.
//! 7. **Showing it** ([`demo`], `nelf demo`; [`field_render`], `nelf render
//!    --field`; [`summary`], what `nelf bake` prints; [`light`], the network's
//!    estimate of a capture's lighting, `nelf light`).
//!
//! Dependencies run one way: `error` ← `config` ← `network` ←
//! `voxel_filter`, `split` ← `truth_split` ← `network_bake` ← `capture_bake`, `demo`;
//! `light`, `network` ← `photo` ← `capture_bake`.

pub mod capture_bake;
pub mod config;
pub mod demo;
pub mod error;
pub mod field_render;
pub mod light;
pub mod network;
pub mod network_bake;
pub mod photo;
pub mod split;
pub mod summary;
pub mod truth_split;
pub mod voxel_filter;

pub use capture_bake::{CaptureBake, CaptureBakeOptions, SourceChoice, bake_capture_dir};
pub use config::{DEFAULT_NETWORK_HULL_MARGIN_PX, DEFAULT_NETWORK_SKIN_MM, PipelineConfig, write_bake};
pub use demo::{DemoConfig, DemoReport, DemoRun, DemoSteps, ImagesBakeDemo, run_demo};
pub use error::{PipelineError, Result};
pub use field_render::{FieldRender, FieldRenderRequest, render_field};
pub use light::{LightEstimate, LightRequest, estimate_light};
pub use network::{
    SourceFit, capture_source_lighting, in_capture_light_units, load_network, network_field,
    network_provenance,
};
pub use network_bake::{NETWORK_VOXEL_FILTER, NetworkSampling, bake_network, bake_network_field};
pub use split::{DensityAndTransport, TransportShapeFrom, TrueNormalsLambert};
pub use truth_split::{FromTruth, with_truth_part};
pub use voxel_filter::VoxelFiltered;

// The delegation mechanism the adapters rest on, now `nelf-scene`'s, where callers
// of the pipeline have named it.
pub use nelf_scene::adapter::{Adapted, Adapter};
