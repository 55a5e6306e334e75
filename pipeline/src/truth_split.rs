//! The ground truth standing in for part of a network bake (`nelf eval network
//! --split`, [`FromTruth`]), to tell the network's geometry error from its shading
//! error: [`with_truth_part`] builds the swapped field.

use nelf_bake::{GroundTruth, LoadedCapture, truth_field, truth_field_traced};
use nelf_format::conventions::LatLong;
use nelf_scene::field::{DensityProfile, FieldSource, MeshField};
use nelf_scene::tracer::TraceSettings;

use crate::config::PipelineConfig;
use crate::error::{Context as _, Result};
use crate::network::capture_source_lighting;
use crate::split::{DensityAndTransport, TransportShapeFrom, TrueNormalsLambert};

/// The part of a network bake the ground truth stands in for (`nelf eval network
/// --split`), to tell the network's geometry error from its shading error.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum FromTruth {
    /// The ground truth's density with the network's light transport.
    Density,
    /// The network's density (signed and carved as in its bake) with the ground
    /// truth's light transport.
    Transport,
    /// The network's density and its colour under the capture's source lighting, with
    /// the ground truth's transport scaled to that colour: how the colour changes
    /// with the lighting is the truth's ([`TransportShapeFrom`]).
    Shading,
    /// The network's density and its transport scaled to the ground truth's colour
    /// under the capture's source lighting: how the colour changes with the lighting
    /// is the network's.
    Colour,
    /// The network's density and colour, relit by the clamped cosine about the
    /// truth's normals (the shading prior with true normals, alone).
    Normals,
    /// The network's density and colour, relit by the truth's direct Lambertian
    /// transport: its normals and shadows, without interreflection or gloss.
    Shadows,
}

impl FromTruth {
    /// Every split, in the order `nelf eval network --split` bakes and reports them.
    pub const ALL: [Self; 6] = [
        Self::Density,
        Self::Transport,
        Self::Shading,
        Self::Colour,
        Self::Normals,
        Self::Shadows,
    ];

    /// The name of its scores (`truth_density_bake`, …) and `what` its bake swaps.
    pub fn describe(self) -> (&'static str, &'static str) {
        match self {
            Self::Density => (
                "truth_density_bake",
                "the ground truth's density, the network's transport",
            ),
            Self::Transport => (
                "truth_transport_bake",
                "the network's density, the ground truth's transport",
            ),
            Self::Shading => (
                "truth_shading_bake",
                "the network's colour under the source lighting, the ground truth's shading",
            ),
            Self::Colour => (
                "truth_colour_bake",
                "the ground truth's colour under the source lighting, the network's shading",
            ),
            Self::Normals => (
                "truth_normals_bake",
                "the network's colour, a Lambertian shading about the ground truth's normals",
            ),
            Self::Shadows => (
                "truth_shadows_bake",
                "the network's colour, the ground truth's direct Lambertian shading with its shadows",
            ),
        }
    }
}

/// Runs `then` on the network's field `source` with `part` taken from
/// `ground_truth` (the truth's field at voxels of `voxel_size_m`, its mesh, or its
/// direct transport; the capture's source lighting where the part is a shading).
pub fn with_truth_part<R>(
    capture: &LoadedCapture,
    ground_truth: &GroundTruth,
    part: FromTruth,
    config: &PipelineConfig,
    voxel_size_m: f64,
    source: &dyn FieldSource,
    then: impl FnOnce(&dyn FieldSource) -> Result<R>,
) -> Result<R> {
    let of_truth = |what: &str| format!("the ground truth's {what} of {}", capture.dir.display());
    let full_truth =
        || truth_field(ground_truth, &config.bake, voxel_size_m).with_context(|| of_truth("field"));
    let source_lighting = || -> Result<LatLong> {
        capture_source_lighting(capture.description(), &capture.dir)?
            .with_context(|| format!("{} names no source lighting", capture.dir.display()))
    };
    match part {
        FromTruth::Density => {
            let truth = full_truth()?;
            then(&DensityAndTransport::new(truth.as_ref(), source))
        }
        FromTruth::Transport => {
            let truth = full_truth()?;
            then(&DensityAndTransport::new(source, truth.as_ref()))
        }
        FromTruth::Shading => {
            let truth = full_truth()?;
            then(&TransportShapeFrom::new(
                truth.as_ref(),
                source,
                &source_lighting()?,
            )?)
        }
        FromTruth::Colour => {
            let truth = full_truth()?;
            // The network's transport at the truth's colour, the network's density kept.
            let recoloured = TransportShapeFrom::new(source, truth.as_ref(), &source_lighting()?)?;
            then(&DensityAndTransport::new(source, &recoloured))
        }
        FromTruth::Normals => {
            let surface = ground_truth.mesh().with_context(|| of_truth("mesh"))?;
            let mesh = MeshField::new(&surface, TraceSettings::default(), DensityProfile::default())
                .with_context(|| of_truth("mesh"))?;
            let lambert = TrueNormalsLambert::new(&mesh);
            then(&TransportShapeFrom::new(&lambert, source, &source_lighting()?)?)
        }
        FromTruth::Shadows => {
            let truth = truth_field_traced(ground_truth, &config.bake, voxel_size_m, |trace| {
                trace.bounces = 0;
                trace.specular = None;
            })
            .with_context(|| of_truth("direct field"))?;
            then(&TransportShapeFrom::new(
                truth.as_ref(),
                source,
                &source_lighting()?,
            )?)
        }
    }
}
