//! Photographs to an asset by reconstruction (`nelf bake capture --source photos`):
//! instead of asking a network for 384 light-transport numbers per point, recover
//! what our path tracer needs — a surface and its reflectance — from the
//! photographs, and bake that surface as any mesh is baked (path-traced transport,
//! shadows, interreflection, PCA, rank).
//!
//! Stages, one file each, each output kept for inspection:
//! 1. [`geometry`]: the masks' visual hull intersected with the NeLF network's
//!    solid (its density, `--photo-geometry network`) or carved by multi-view stereo
//!    ([`stereo`]), as a smooth closed mesh.
//! 2. [`lighting`]: the lighting the capture names, else fitted to the photographs'
//!    shading on the surface (or the network's estimate); then [`refine`]: the
//!    surface's vertices moved along their normals until `albedo × shading` under
//!    that lighting matches the photographs' brightness, and the lighting fitted
//!    again on the refined surface.
//! 3. [`reflectance`]: each vertex's colour in the views that see it divided by the
//!    shading a white copy of the surface gets under that lighting.
//! 4. The bake: the textured surface as a ground truth
//!    ([`nelf_bake::GroundTruth::Reconstructed`]) through [`nelf_bake::bake_capture`].
//!    A reconstructed surface is Lambertian, so there is no view dependence to fit.
//!
//! [`write_reconstruction`] saves the reconstruction (an OBJ with its material and
//! the albedo as a texture atlas, [`atlas`]) and a JSON report of each stage for
//! inspection.

pub mod as_photographs;
pub mod atlas;
pub mod geometry;
pub mod lighting;
mod pixels;
pub mod refine;
pub mod reflectance;
pub mod stereo;
#[cfg(test)]
mod test_support;

use std::path::Path;
use std::time::Instant;

use nelf_bake::{BakeOutput, GroundTruth, LoadedCapture, Progress, ViewChoice, bake_capture};
use nelf_scene::mesh::{Albedo, Mesh};
use serde::Serialize;

use crate::config::{PhotoGeometry, PhotoSettings, PipelineConfig};
use crate::error::{Context as _, Result};
use crate::network::{encoded_field, load_network};
use geometry::{DensitySurface, SurfaceReport, SurfaceSettings, hull_surface};
use lighting::{LightingReport, capture_lighting};
use reflectance::{ReflectanceReport, ReflectanceSettings, albedo_from_observations, observe};

/// The density at the surface of the network's solid (`--photo-geometry network`):
/// a 3.5 mm voxel of it is half opaque (`ln 2 / 3.5 mm`; measured on four heads
/// with the level of the demo's resolution-64 bake, 186–217 /m).
pub const NETWORK_SURFACE_DENSITY_PER_M: f32 = 200.0;

/// The albedo the brightest texels are scaled to when the lighting's scale is unknown.
const NORMALISED_ALBEDO: f32 = 0.9;

/// A capture's surface and reflectance, reconstructed from its photographs.
#[derive(Debug, Clone)]
pub struct Reconstruction {
    /// The surface with its per-vertex albedo, in the capture's world frame.
    pub mesh: Mesh,
    /// The lighting the albedo was recovered under (8 × 16, world frame; named, or
    /// estimated up to scale and colour).
    pub lighting: nelf_format::conventions::LatLong,
    /// What each stage did.
    pub report: ReconstructionReport,
}

/// What each stage of the reconstruction did.
#[derive(Debug, Clone, Serialize)]
pub struct ReconstructionReport {
    /// Geometry.
    pub surface: SurfaceReport,
    /// The surface's refinement by shading (`None`: not asked for).
    pub refinement: Option<refine::RefineReport>,
    /// Lighting.
    pub lighting: LightingReport,
    /// Reflectance.
    pub reflectance: ReflectanceReport,
}

/// Reconstructs `capture`'s surface and reflectance; `weights` are the network's
/// for a lighting estimate (`None`: the shipped one); `max_radius_m` bounds the hull
/// where the views leave it open.
pub fn reconstruct(
    capture: &LoadedCapture,
    weights: Option<&Path>,
    settings: &PhotoSettings,
    max_radius_m: f64,
) -> Result<Reconstruction> {
    settings.validate()?;
    let spacing_m = settings.photo_spacing_mm * 1e-3;
    // The network's density, where it can be had; else (mixed image sizes, …)
    // stereo, with a note.
    let mut geometry = settings.photo_geometry;
    let mut geometry_note = None;
    let network = match geometry {
        PhotoGeometry::Network | PhotoGeometry::Fused => {
            match load_network(weights).and_then(|(model, _)| encoded_field(capture, model)) {
                Ok((_, field)) => Some(field),
                Err(e) => {
                    geometry = PhotoGeometry::Stereo;
                    geometry_note = Some(format!(
                        "the network's density could not be used ({e}); the hull was carved by stereo instead"
                    ));
                    None
                }
            }
        }
        PhotoGeometry::Stereo | PhotoGeometry::Hull => None,
    };
    let density = network.as_ref().map(|field| DensitySurface {
        field,
        level_per_m: NETWORK_SURFACE_DENSITY_PER_M,
    });
    let (mesh, surface) = hull_surface(
        capture,
        &SurfaceSettings {
            spacing_m,
            smoothing_iterations: settings.photo_smoothing,
            blur_m: settings.photo_blur_mm * 1e-3,
            max_radius_m,
            stereo: matches!(geometry, PhotoGeometry::Stereo | PhotoGeometry::Fused)
                .then(stereo::StereoSettings::default),
        },
        density.as_ref(),
    )?;
    let surface = SurfaceReport {
        note: geometry_note.or(surface.note),
        ..surface
    };
    let reflectance_settings = ReflectanceSettings {
        bounces: settings.photo_shading_bounces,
        ..ReflectanceSettings::default()
    };
    let mut observations = observe(&mesh, capture, &reflectance_settings, spacing_m as f32)?;
    let (mut light, mut lighting) =
        capture_lighting(capture, weights, settings, &observations, &mesh.triangles)?;
    let mut mesh = mesh;
    let mut refinement = None;
    if settings.photo_refine_iterations > 0 {
        let (refined, report) = refine::refine_surface(
            &mesh,
            &observations,
            &light,
            &refine::RefineSettings {
                iterations: settings.photo_refine_iterations,
                smoothness: settings.photo_refine_smoothness,
                spacing_m,
                // The lighting fit's regions; its default where it uses clusters.
                region_step: if settings.photo_light_region_step > 0.0 {
                    settings.photo_light_region_step
                } else {
                    crate::config::DEFAULT_PHOTO_LIGHT_REGION_STEP
                },
                ..refine::RefineSettings::default()
            },
        )?;
        mesh = refined;
        refinement = Some(report);
        observations = observe(&mesh, capture, &reflectance_settings, spacing_m as f32)?;
        (light, lighting) = capture_lighting(capture, weights, settings, &observations, &mesh.triangles)?;
    }
    let (albedo, reflectance) = albedo_from_observations(
        &observations,
        &mesh.triangles,
        &light,
        &ReflectanceSettings {
            normalise_to: (!lighting.named).then_some(NORMALISED_ALBEDO),
            ..reflectance_settings
        },
    )?;
    let mesh = Mesh {
        albedo: Albedo::PerVertex(albedo),
        ..mesh
    };
    mesh.validate().context("the reconstructed surface")?;
    Ok(Reconstruction {
        mesh,
        lighting: light,
        report: ReconstructionReport {
            surface,
            refinement,
            lighting,
            reflectance,
        },
    })
}

/// A bake from photographs and what its reconstruction did.
#[derive(Debug)]
pub struct PhotoBake {
    /// The asset and its report.
    pub output: BakeOutput,
    /// The reconstruction the asset was baked from.
    pub reconstruction: Reconstruction,
    /// Seconds spent reconstructing (before the bake).
    pub reconstruct_secs: f64,
}

/// The settings the reconstructed surface is baked with: `bake`'s, without view
/// dependence (a photographed capture has no views to judge it at) and with the lead
/// `--photo-lead-voxels` (the reconstructed surface lies a little inside the true
/// silhouette; [`crate::config::DEFAULT_PHOTO_LEAD_VOXELS`]).
pub fn reconstruction_bake_config(
    bake: &nelf_bake::BakeConfig,
    settings: &PhotoSettings,
) -> nelf_bake::BakeConfig {
    nelf_bake::BakeConfig {
        view_dependence: ViewChoice::Off,
        lead_voxels: settings.photo_lead_voxels,
        // `auto` would add a fine density (the reconstruction is closed), whose lead is
        // a quarter of a *fine* voxel: the silhouette of a surface that lies inside the
        // true one shrinks again (CGAL scan photographed, resolution 64: foreground
        // −0.6 to −1.2 dB per target, docs/measurements/2026-12-07-fine-density.md).
        fine_density: match bake.fine_density {
            nelf_bake::config::FineDensityChoice::Auto => nelf_bake::config::FineDensityChoice::Off,
            chosen => chosen,
        },
        ..bake.clone()
    }
}

/// Reconstructs `capture` and bakes the result (see the module documentation).
pub fn bake_photographs(
    capture: &LoadedCapture,
    weights: Option<&Path>,
    settings: &PhotoSettings,
    config: &PipelineConfig,
    progress: Progress,
) -> Result<PhotoBake> {
    config.validate()?;
    let start = Instant::now();
    let reconstruction = reconstruct(capture, weights, settings, config.bake.max_hull_radius_m)
        .with_context(|| format!("reconstructing {} from its photographs", capture.dir.display()))?;
    let reconstruct_secs = start.elapsed().as_secs_f64();
    let description = serde_json::to_value(&reconstruction.report)?;
    let truth = GroundTruth::Reconstructed {
        mesh: Box::new(reconstruction.mesh.clone()),
        description,
    };
    let bake_config = reconstruction_bake_config(&config.bake, settings);
    let output = bake_capture(capture, &truth, &bake_config, &progress)
        .with_context(|| format!("baking the surface reconstructed from {}", capture.dir.display()))?;
    Ok(PhotoBake {
        output,
        reconstruction,
        reconstruct_secs,
    })
}

/// Writes `dir/reconstruction.obj` with `reconstruction.mtl` and the albedo as a
/// texture atlas, `reconstruction_albedo.jpg` (what any DCC tool opens;
/// [`atlas::texture_atlas`]), and `dir/reconstruction.json`.
pub fn write_reconstruction(reconstruction: &Reconstruction, dir: &Path) -> Result<()> {
    std::fs::create_dir_all(dir)
        .map_err(|e| nelf_format::io_error::FileIoError::new(dir.to_path_buf(), e))?;
    let textured = atlas::texture_atlas(&reconstruction.mesh, atlas::DEFAULT_CELL_TEXELS);
    nelf_scene::mesh_io::write_obj(&textured, &dir.join("reconstruction.obj"))?;
    let path = dir.join("reconstruction.json");
    let json = serde_json::to_string_pretty(&reconstruction.report)? + "\n";
    nelf_format::atomic::write_bytes_atomically(&path, json.as_bytes())
        .map_err(|e| nelf_format::io_error::FileIoError::new(path, e))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::photo::geometry::tests::sphere_views;
    use glam::{DMat3, DVec3};

    /// Five views in a 35° cone of a textured sphere of radius 0.1 m, at `size`².
    fn textured_sphere(size: u32) -> LoadedCapture {
        let eyes: Vec<DVec3> = [(0.0, 0.0), (0.6, 0.2), (-0.6, 0.2), (0.2, 0.6), (-0.2, -0.6)]
            .iter()
            .map(|&(x, y)| DVec3::new(x, y, 1.0).normalize())
            .collect();
        sphere_views(0.1, &eyes, size, 0.3, |p| {
            let v = 0.5 + 0.4 * ((p.x * 150.0).sin() * (p.y * 130.0).cos()) as f32;
            [v, 0.6 * v + 0.2, 1.0 - v]
        })
    }

    /// Every mask pixel replaced by the minimum (`erode`) or maximum over the
    /// `(2r+1)²` square around it.
    fn morph(mask: &[f32], size: usize, r: i64, erode: bool) -> Vec<f32> {
        (0..size * size)
            .map(|i| {
                let (x, y) = ((i % size) as i64, (i / size) as i64);
                let mut out = if erode { 1.0f32 } else { 0.0 };
                for dy in -r..=r {
                    for dx in -r..=r {
                        let (u, v) = (x + dx, y + dy);
                        let m = if u < 0 || v < 0 || u >= size as i64 || v >= size as i64 {
                            0.0
                        } else {
                            mask[v as usize * size + u as usize]
                        };
                        out = if erode { out.min(m) } else { out.max(m) };
                    }
                }
                out
            })
            .collect()
    }

    fn settings(geometry: PhotoGeometry) -> PhotoSettings {
        PhotoSettings {
            photo_spacing_mm: 4.0,
            photo_geometry: geometry,
            ..PhotoSettings::default()
        }
    }

    /// The reconstruction is a valid surface whose front (the views' side; the back
    /// is left open by a 35° cone of views) lies near the sphere's, with a finite
    /// albedo in [0, 1] that is not black. The network's solid is a head's, not a
    /// sphere's: with it the front may lie deeper.
    fn assert_sane(what: &str, reconstruction: &Reconstruction, geometry: PhotoGeometry) {
        let mesh = &reconstruction.mesh;
        assert!(mesh.validate().is_ok(), "{what}");
        let front = mesh
            .positions
            .iter()
            .map(|p| p.z)
            .fold(f32::NEG_INFINITY, f32::max);
        let widest = mesh
            .positions
            .iter()
            .map(|p| p.x.hypot(p.y))
            .fold(0.0f32, f32::max);
        let nearest = if geometry == PhotoGeometry::Network {
            0.06
        } else {
            0.085
        };
        assert!(
            (nearest..0.125).contains(&front) && (0.08..0.13).contains(&widest),
            "{what}: front at z = {front} m, widest {widest} m from the axis (sphere: 0.1)"
        );
        let Albedo::PerVertex(albedo) = &mesh.albedo else {
            panic!("{what}: no per-vertex albedo");
        };
        assert!(
            albedo
                .iter()
                .flatten()
                .all(|a| a.is_finite() && (0.0..=1.0).contains(a)),
            "{what}: albedo out of range"
        );
        let mean = albedo.iter().map(|a| a.iter().sum::<f32>() / 3.0).sum::<f32>() / albedo.len() as f32;
        assert!(mean > 0.1, "{what}: mean albedo {mean}");
        assert!(reconstruction.report.reflectance.seen_vertices > 0, "{what}");
    }

    #[test]
    fn the_defects_of_real_photographs_give_a_sane_surface_or_a_clear_error() {
        let size = 64;
        let clean = textured_sphere(size);
        for geometry in [PhotoGeometry::Stereo, PhotoGeometry::Network] {
            let reconstruct_it =
                |capture: &LoadedCapture| reconstruct(capture, None, &settings(geometry), 0.5);
            let fitted = reconstruct_it(&clean).expect("clean");
            assert_sane("clean", &fitted, geometry);
            // The lighting is not named: it was fitted.
            assert!(!fitted.report.lighting.named && fitted.report.lighting.fit.is_some());
            // Refined by shading: still sane, and the refinement lowered its residual.
            let refining = PhotoSettings {
                photo_refine_iterations: refine::DEFAULT_ITERATIONS,
                ..settings(geometry)
            };
            let refined = reconstruct(&clean, None, &refining, 0.5).expect("refined");
            assert_sane("refined", &refined, geometry);
            let report = refined.report.refinement.expect("a refinement report");
            assert!(
                report.steps > 0 && report.rms_log_residual[1] < report.rms_log_residual[0],
                "{report:?}"
            );

            // Masks eroded and dilated by 4 pixels (a matting tool's soft edge
            // thresholded differently).
            for erode in [true, false] {
                let mut capture = clean.clone();
                for m in &mut capture.masks {
                    *m = morph(m, size as usize, 4, erode);
                }
                let what = if erode { "eroded masks" } else { "dilated masks" };
                assert_sane(what, &reconstruct_it(&capture).expect(what), geometry);
            }

            // One camera's pose off by 1° (a poor registration): the views disagree.
            let mut capture = clean.clone();
            let turn = DMat3::from_axis_angle(DVec3::new(1.0, 1.0, 0.0).normalize(), 1f64.to_radians());
            capture.cameras[2].rotation = turn * capture.cameras[2].rotation;
            capture.cameras[2].translation = turn * capture.cameras[2].translation;
            assert_sane(
                "1° pose error",
                &reconstruct_it(&capture).expect("1° pose error"),
                geometry,
            );

            // Views of different sizes (one photographed at 48² with the same field).
            let small = textured_sphere(48);
            let mut capture = clean.clone();
            capture.cameras[3] = small.cameras[3];
            capture.images[3] = small.images[3].clone();
            capture.masks[3] = small.masks[3].clone();
            // The network's views are brought to one size first
            // (`nelf_field::capture::to_one_size`): the geometry asked for, no note.
            let mixed = reconstruct_it(&capture).expect("mixed sizes");
            assert_sane("mixed sizes", &mixed, geometry);
            assert_eq!(mixed.report.surface.geometry, geometry);
            assert!(
                mixed.report.surface.note.is_none(),
                "{:?}",
                mixed.report.surface.note
            );
        }
        let reconstruct_it =
            |capture: &LoadedCapture| reconstruct(capture, None, &settings(PhotoGeometry::Network), 0.5);

        // A view that sees nothing of the head: its empty mask empties the hull,
        // which is an error that says so (the loader refuses such a mask first).
        let mut capture = clean;
        capture.masks[1].fill(0.0);
        let err = reconstruct_it(&capture).expect_err("an empty view");
        let chain = nelf_scene::error::error_chain(&err);
        assert!(
            chain.contains("visual hull") && chain.contains("check poses and masks"),
            "{chain}"
        );
    }
}
