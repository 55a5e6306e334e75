//! Meshes with the defects real scans have (`nelf_scene::defects`) bake right: a
//! one-sided sheet seen from both sides, a sphere torn open by holes of three sizes,
//! a closed mesh with a piece not connected to it, a textured quad, and a sphere
//! with flipped triangles and a non-manifold fin. Each is baked directly
//! (`bake_mesh`), rendered by the reference renderer at views around it (front,
//! back, sides, above) under a sharp real HDRI (`data/envmaps/sunset.exr`, a low
//! sun), and compared with the two-sided path tracer's images of the mesh under the
//! same light: coverage (mean |alpha − path-traced alpha| per pixel) and PSNR.
//!
//! Floors are set from measured values (stated per case) with a margin of about
//! 1.5 dB. The grid is coarse (40 voxels along the mesh, about one voxel per pixel),
//! so silhouettes dominate the whole-image figures of sheets; the interior figures
//! say whether each side is shaded as the path tracer shades it.

#![allow(clippy::unwrap_used)] // Test helpers outside #[test] functions unwrap too.

use std::path::Path;

use glam::DVec3;
use nelf_bake::eval::{data_range, error_breakdown, score_view};
use nelf_bake::{BakeConfig, Progress, TraceOverrides, bake_mesh};
use nelf_format::conventions::PinholeCamera;
use nelf_scene::defects::test_cases;
use nelf_scene::envmap::{envmap_to_basis, load_envmap};
use nelf_scene::mesh::Mesh;
use nelf_scene::render::render_lt_image;
use nelf_scene::tracer::{LtTracer, TraceSettings};

/// Pixels along each side of the views scored.
const SIZE: u32 = 48;

/// A cheap but exact-enough tracer: direct light only, 4 samples per texel. The
/// bake and the reference use the same settings, so the comparison measures the
/// grid, not the tracer's noise.
fn trace() -> TraceSettings {
    TraceSettings {
        bounces: 0,
        texel_samples: 4,
        indirect_samples: 0,
        ..TraceSettings::default()
    }
}

/// Cameras on a sphere around the mesh's bounding sphere: front, back, both sides, above.
fn cameras(mesh: &Mesh) -> Vec<(String, PinholeCamera)> {
    let (centre, radius) = mesh.bounding_sphere();
    let distance = 4.0 * radius;
    let fov = 2.0 * (1.25 * radius / distance).asin();
    [
        ("front", DVec3::new(0.15, 0.1, 1.0)),
        ("back", DVec3::new(-0.2, 0.15, -1.0)),
        ("left", DVec3::new(-1.0, 0.2, 0.1)),
        ("right", DVec3::new(1.0, -0.1, 0.3)),
        ("above", DVec3::new(0.2, 1.0, 0.4)),
    ]
    .into_iter()
    .map(|(name, dir)| {
        let eye = centre + dir.normalize() * distance;
        (
            name.to_string(),
            PinholeCamera::look_at(eye, centre, DVec3::Y, SIZE, SIZE, fov),
        )
    })
    .collect()
}

/// Worst whole-image PSNR (dB), worst interior PSNR (dB, views with an interior)
/// and worst coverage error over the views. With `DEFECTS_OUT=DIR` in the
/// environment, truth | bake previews (4× nearest) are written there.
fn bake_and_score(mesh: &Mesh, name: &str, hollow_voxels: f32) -> (f64, f64, f64) {
    let config = BakeConfig {
        resolution: 40,
        render_size: SIZE,
        hollow_voxels,
        trace: TraceOverrides {
            bounces: Some(0),
            texel_samples: Some(4),
            indirect_samples: Some(0),
        },
        ..BakeConfig::default()
    };
    let output = bake_mesh(mesh, &serde_json::json!(name), &config, &Progress::hidden()).unwrap();
    let env_path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../data/envmaps/sunset.exr");
    let light = envmap_to_basis(&load_envmap(&env_path).unwrap(), 0.0);
    let tracer = LtTracer::new(mesh, trace()).unwrap();
    let (mut worst_psnr, mut worst_interior, mut worst_coverage) = (f64::INFINITY, f64::INFINITY, 0.0f64);
    for (view, camera) in cameras(mesh) {
        let truth = render_lt_image(&tracer, &camera, &light, None).unwrap();
        let reference = truth.over([0.0; 3]);
        let (score, image) = score_view(&output.asset, &camera, &light, &reference, &view).unwrap();
        let range = f64::from(data_range(&reference));
        let breakdown = error_breakdown(&image, &reference, &truth.alpha, range).unwrap();
        eprintln!(
            "{name} {view}: PSNR {:.2} dB, coverage error {:.4}, interior PSNR {:.2} dB",
            score.psnr_db, breakdown.coverage_error, breakdown.interior_psnr_db
        );
        if let Some(dir) = std::env::var_os("DEFECTS_OUT") {
            let stops = (0.5 / data_range(&reference)).log2();
            let n = SIZE as usize;
            let both: Vec<[f32; 3]> = (0..4 * n)
                .flat_map(|y| {
                    let (r, i) = (&reference, &image.rgb);
                    (0..8 * n).map(move |x| {
                        let (x, y) = (x / 4, y / 4);
                        if x < n { r[y * n + x] } else { i[y * n + x - n] }
                    })
                })
                .collect();
            nelf_scene::image_io::write_png_srgb(
                Path::new(&dir).join(format!("{}_{view}.png", name.replace(' ', "_"))),
                8 * SIZE,
                4 * SIZE,
                &both,
                stops,
            )
            .unwrap();
        }
        worst_psnr = worst_psnr.min(score.psnr_db);
        worst_interior = worst_interior.min(breakdown.interior_psnr_db);
        worst_coverage = worst_coverage.max(breakdown.coverage_error);
    }
    (worst_psnr, worst_interior, worst_coverage)
}

/// Asserts the worst view's whole-image PSNR, interior PSNR and coverage error.
fn check(mesh: &Mesh, name: &str, psnr_floor_db: f64, interior_floor_db: f64, coverage_tolerance: f64) {
    check_hollow(
        mesh,
        name,
        0.0,
        psnr_floor_db,
        interior_floor_db,
        coverage_tolerance,
    );
}

/// [`check`] with closed parts baked as hollow shells `hollow_voxels` thick.
fn check_hollow(
    mesh: &Mesh,
    name: &str,
    hollow_voxels: f32,
    psnr_floor_db: f64,
    interior_floor_db: f64,
    coverage_tolerance: f64,
) {
    let (psnr, interior, coverage) = bake_and_score(mesh, name, hollow_voxels);
    assert!(
        coverage <= coverage_tolerance,
        "{name}: coverage error {coverage:.4} > {coverage_tolerance}"
    );
    assert!(
        psnr >= psnr_floor_db,
        "{name}: worst view {psnr:.2} dB < {psnr_floor_db} dB"
    );
    assert!(
        interior >= interior_floor_db,
        "{name}: worst interior {interior:.2} dB < {interior_floor_db} dB"
    );
}

/// The named case of `nelf_scene::defects::test_cases`.
fn case(name: &str) -> Mesh {
    test_cases()
        .into_iter()
        .find(|(n, _)| *n == name)
        .map_or_else(|| panic!("no defect case {name}"), |(_, mesh)| mesh)
}

#[test]
fn one_sided_sheet_is_opaque_and_lit_on_the_side_seen() {
    // Measured: worst whole image 14.26 dB (the view from above, along the sheet:
    // silhouette), worst interior 29.22 dB (back; before the sheet handling 9.4 dB),
    // coverage 0.037 (a sheet baked two voxels thick at 4 mm voxels ≈ 1 px/voxel).
    check(&case("sheet"), "sheet", 13.0, 27.0, 0.045);
}

#[test]
fn torn_sphere_with_holes_of_three_sizes() {
    // Holes this wide stay open at load; hollow shells let the inside show through
    // them. Measured: worst 20.12 dB whole / 16.76 dB interior with 3 voxels of
    // shell (solid: 15.4 / 11.9 dB; before: 15.42 / 11.89 dB), coverage 0.014.
    check_hollow(&case("torn_sphere"), "torn sphere", 3.0, 18.5, 15.0, 0.02);
}

#[test]
fn closed_mesh_with_a_disconnected_piece() {
    // Measured: worst 36.30 dB whole / 35.70 dB interior, coverage 0.0064.
    check(&case("loose_piece"), "disconnected piece", 34.5, 34.0, 0.01);
}

#[test]
fn textured_quad_keeps_its_texture() {
    // Measured: worst 14.05 dB whole (grazing views: silhouette), 12.81 dB interior,
    // coverage 0.033.
    check(&case("textured_quad"), "textured quad", 12.5, 11.5, 0.04);
}

#[test]
fn flipped_triangles_and_a_non_manifold_fin() {
    // Measured: worst 34.57 dB whole / 30.92 dB interior, coverage 0.0011 (the view
    // from above, the fin edge-on: its root a darker streak than the truth's); with
    // the lead equal to the ramp (before 2026-12-07) 31.06 / 34.77, coverage 0.0107:
    // the sphere's silhouette sat ~¼ voxel out; before the closed/open test from both
    // sides of the surface: 23.2 dB, 20.0 dB.
    check(&case("flipped_fin"), "flipped + fin", 33.0, 29.5, 0.004);
}
