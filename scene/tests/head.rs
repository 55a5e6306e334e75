//! Procedural heads: determinism, size, topology, orientation, variety.

#![allow(clippy::unwrap_used)] // Test helpers outside #[test] functions unwrap too.

use glam::Vec3;
use nelf_scene::head::{HairColour, HeadParams, head_traits, procedural_head, skin_albedo};
use nelf_scene::mesh::{Albedo, Mesh};

fn luminance(c: [f32; 3]) -> f32 {
    0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]
}

fn per_vertex(mesh: &Mesh) -> &[[f32; 3]] {
    match &mesh.albedo {
        Albedo::PerVertex(c) => c,
        other => panic!("expected per-vertex albedo, got {other:?}"),
    }
}

#[test]
fn heads_are_deterministic_sized_closed_and_outward() {
    let params = HeadParams::default();
    for seed in [0u64, 1, 7, 42] {
        let mesh = procedural_head(seed, &params);
        mesh.validate().unwrap();
        assert_eq!(
            mesh,
            procedural_head(seed, &params),
            "seed {seed} is deterministic"
        );
        let n = mesh.triangles.len();
        assert!((10_000..=60_000).contains(&n), "seed {seed}: {n} triangles");

        let (lo, hi) = mesh.bounds();
        let height = hi.y - lo.y;
        assert!((0.18..=0.25).contains(&height), "seed {seed}: {height} m tall");
        assert!((height - head_traits(seed, &params).height_m).abs() < 1e-5);
        assert!((0.5 * (lo + hi)).length() < 1e-5, "seed {seed}: centred");
        let size = hi - lo;
        assert!(
            size.x < size.y && size.z < size.y,
            "seed {seed}: taller than wide or deep: {size:?}"
        );

        assert_eq!(
            mesh.edge_defects(),
            0,
            "seed {seed}: watertight, consistently wound"
        );
        assert!(mesh.signed_volume() > 0.0, "seed {seed}: outward");
        // Nearly all faces point away from the centre (ears and nostrils are the exceptions).
        let centre = 0.5 * (lo + hi);
        let outward = (0..n)
            .filter(|&t| {
                let [a, b, c] = mesh.corners(t);
                mesh.face_normal(t).dot((a + b + c) / 3.0 - centre) > 0.0
            })
            .count();
        assert!(
            outward as f64 > 0.9 * n as f64,
            "seed {seed}: {outward}/{n} face outward"
        );
    }
}

#[test]
fn head_faces_plus_z_with_eyes_and_hair() {
    let seed = 5;
    let params = HeadParams::default();
    let mesh = procedural_head(seed, &params);
    let traits = head_traits(seed, &params);
    let colours = per_vertex(&mesh);
    // The frontmost point is the nose tip: on the midline, in skin.
    let (tip, tip_colour) = mesh
        .positions
        .iter()
        .zip(colours)
        .max_by(|a, b| a.0.z.total_cmp(&b.0.z))
        .unwrap();
    assert!(tip.x.abs() < 0.003, "nose tip on the midline: {tip:?}");
    assert!(tip.y > -0.03 && tip.y < 0.08, "nose tip at face height: {tip:?}");
    let skin_or_lip = |c: &[f32; 3]| (0..3).all(|k| (c[k] - traits.skin_albedo[k]).abs() < 0.2);
    assert!(
        skin_or_lip(tip_colour),
        "{tip_colour:?} vs skin {:?}",
        traits.skin_albedo
    );
    // The top is hair; the back of the head is hair; the eyes have whites.
    let top = mesh
        .positions
        .iter()
        .zip(colours)
        .max_by(|a, b| a.0.y.total_cmp(&b.0.y))
        .unwrap();
    assert_eq!(*top.1, traits.hair_albedo);
    let back = mesh
        .positions
        .iter()
        .zip(colours)
        .min_by(|a, b| a.0.z.total_cmp(&b.0.z))
        .unwrap();
    assert_eq!(*back.1, traits.hair_albedo, "back of the skull at {:?}", back.0);
    let sclera = colours
        .iter()
        .filter(|c| c[0] > 0.55 && c[1] > 0.5 && c[2] > 0.45)
        .count();
    assert!(sclera > 10, "{sclera} sclera vertices");
    // The eyes are on the front, the bottom is the neck cut.
    let (lo, _) = mesh.bounds();
    let bottom: Vec<Vec3> = mesh
        .positions
        .iter()
        .copied()
        .filter(|p| p.y < lo.y + 1e-3)
        .collect();
    assert!(bottom.len() > 50, "a flat neck cut");
}

#[test]
fn seeds_vary_shape_and_albedo() {
    let params = HeadParams::default();
    let a = procedural_head(11, &params);
    let b = procedural_head(12, &params);
    assert_ne!(a.bounds(), b.bounds(), "shapes differ");
    let ta = head_traits(11, &params);
    let tb = head_traits(12, &params);
    assert_ne!(ta.skin_albedo, tb.skin_albedo, "skin differs");
    assert!(per_vertex(&a).contains(&ta.skin_albedo));
    assert!(per_vertex(&b).contains(&tb.skin_albedo));

    // Across seeds: skin tones from pale to dark, several hair colours, heights spread.
    let traits: Vec<_> = (0..60).map(|s| head_traits(s, &params)).collect();
    let tones: Vec<f32> = traits.iter().map(|t| t.skin_tone).collect();
    let palest = tones.iter().copied().fold(f32::INFINITY, f32::min);
    let darkest = tones.iter().copied().fold(f32::NEG_INFINITY, f32::max);
    assert!(palest < 0.15 && darkest > 0.85, "tones {palest}…{darkest}");
    assert!(luminance(skin_albedo(palest)) > 4.0 * luminance(skin_albedo(darkest)));
    let hair: std::collections::HashSet<_> = traits.iter().map(|t| format!("{:?}", t.hair)).collect();
    assert!(hair.len() >= 5, "{hair:?}");
    let heights: Vec<f32> = traits.iter().map(|t| t.height_m).collect();
    assert!(heights.iter().all(|h| (0.19..=0.24).contains(h)));
    assert!(heights.iter().copied().fold(0.0, f32::max) - heights.iter().copied().fold(1.0, f32::min) > 0.03);
}

#[test]
fn params_fix_appearance_and_resolution() {
    let params = HeadParams {
        cells_per_height: 48,
        height_m: Some(0.2),
        skin_tone: Some(1.0),
        hair: Some(HairColour::Grey),
    };
    let mesh = procedural_head(3, &params);
    let coarse = mesh.triangles.len();
    let fine = procedural_head(3, &HeadParams::default()).triangles.len();
    assert!(coarse * 3 < fine, "{coarse} vs {fine} triangles");
    assert_eq!(mesh.edge_defects(), 0);
    let (lo, hi) = mesh.bounds();
    assert!((hi.y - lo.y - 0.2).abs() < 1e-5);
    let colours = per_vertex(&mesh);
    assert!(colours.contains(&skin_albedo(1.0)));
    assert!(colours.contains(&HairColour::Grey.albedo()));
    for c in colours {
        assert!(c.iter().all(|v| (0.0..=1.0).contains(v)), "{c:?}");
    }
}
