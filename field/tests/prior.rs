//! The Lambertian shading prior (`nelf_field::prior`): normals from a density's
//! gradient, the clamped-cosine transport about them, and its quotient under the
//! source lighting.

use candle_core::{Device, Tensor};
use nelf_field::light::net_texel_direction;
use nelf_field::nelfnet::normalise_to_source;
use nelf_field::prior::{ShadingPrior, density_normals, lambert_transport};
use nelf_format::conventions::{ENV_TEXELS, ENV_W, LT_DIM};

const IDENTITY: [[f32; 3]; 3] = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];

/// A soft ball of radius 80 mm about `centre`: σ falls off outward.
fn ball(centre: [f32; 3]) -> impl Fn(&[[f32; 3]]) -> Result<Vec<f32>, nelf_field::NetError> {
    move |points| {
        Ok(points
            .iter()
            .map(|p| {
                let r =
                    ((p[0] - centre[0]).powi(2) + (p[1] - centre[1]).powi(2) + (p[2] - centre[2]).powi(2))
                        .sqrt();
                1.0 / (1.0 + ((r - 80.0) / 3.0).exp())
            })
            .collect())
    }
}

#[test]
fn normals_of_a_ball_point_outward_and_vanish_where_density_is_flat() {
    let centre = [10.0, -20.0, 400.0];
    let points = [
        [90.0, -20.0, 400.0],
        [10.0, 58.0, 400.0],
        [10.0 + 80.0 * 0.6, -20.0, 400.0 - 80.0 * 0.8],
        centre,
        [1000.0, 0.0, 0.0],
    ];
    let normals = density_normals(&points, 2.0, ball(centre)).unwrap();
    let expected = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.6, 0.0, -0.8]];
    for (n, e) in normals.iter().zip(expected) {
        let n = n.expect("a normal on the ball's surface");
        let dot: f32 = n.iter().zip(e).map(|(a, b)| a * b).sum();
        assert!(dot > 0.999, "normal {n:?}, expected {e:?}");
    }
    assert!(
        normals[3].is_none(),
        "the centre has no gradient: {:?}",
        normals[3]
    );
    assert!(
        normals[4].is_none(),
        "far away there is no gradient: {:?}",
        normals[4]
    );
}

/// A density of the signed distance `d` (mm, positive outside) to a solid: a
/// logistic step 3 mm soft, as the network's density is soft.
fn soft(d: f32) -> f32 {
    1.0 / (1.0 + (d / 3.0).exp())
}

/// Asserts each normal is within 2.6° of its expected direction.
fn assert_normals(normals: &[Option<[f32; 3]>], expected: &[[f32; 3]], what: &str) {
    for (n, e) in normals.iter().zip(expected) {
        let n = n.unwrap_or_else(|| panic!("{what}: no normal where {e:?} is expected"));
        let dot: f32 = n.iter().zip(e).map(|(a, b)| a * b).sum();
        assert!(dot > 0.999, "{what}: normal {n:?}, expected {e:?}");
    }
}

#[test]
fn normals_of_open_holed_and_thin_surfaces_point_out_of_the_material() {
    // The defects of real scans, at the default step (5 mm). A 20 mm slab (|z| < 10
    // mm) holed by a cylinder of radius 30 mm about z and open at x = 100 mm: its
    // faces, the wall of its hole and its open edge.
    let step = nelf_field::prior::DEFAULT_STEP_MM;
    let holed = |points: &[[f32; 3]]| -> Result<Vec<f32>, nelf_field::NetError> {
        Ok(points
            .iter()
            .map(|p| {
                let faces = p[2].abs() - 10.0;
                let hole = 30.0 - p[0].hypot(p[1]);
                let edge = p[0] - 100.0;
                soft(faces.max(hole).max(edge))
            })
            .collect())
    };
    let points = [
        [60.0, 0.0, 10.0],
        [60.0, 0.0, -10.0],
        [30.0, 0.0, 0.0],
        [0.0, -30.0, 0.0],
        [100.0, 50.0, 0.0],
    ];
    let expected = [
        [0.0, 0.0, 1.0],
        [0.0, 0.0, -1.0],
        // Into the hole, toward its axis.
        [-1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        // Out of the open edge.
        [1.0, 0.0, 0.0],
    ];
    assert_normals(
        &density_normals(&points, step, holed).unwrap(),
        &expected,
        "holed slab",
    );

    // A sheet 2 mm thick, a quarter of the step: the differences straddle it, yet on
    // each side the normal points to that side; on its mid-plane there is none, and
    // the prior is uniform there (the ratio of total irradiances), never a wrong
    // direction.
    let thin = |points: &[[f32; 3]]| -> Result<Vec<f32>, nelf_field::NetError> {
        Ok(points.iter().map(|p| soft(p[2].abs() - 1.0)).collect())
    };
    let points = [
        [5.0, 7.0, 1.0],
        [5.0, 7.0, -1.0],
        [5.0, 7.0, 4.0],
        [5.0, 7.0, 0.0],
    ];
    let normals = density_normals(&points, step, thin).unwrap();
    assert_normals(
        &normals[..3],
        &[[0.0, 0.0, 1.0], [0.0, 0.0, -1.0], [0.0, 0.0, 1.0]],
        "thin sheet",
    );
    assert!(normals[3].is_none(), "mid-plane: {:?}", normals[3]);
    assert!(
        lambert_transport(&normals[3..], IDENTITY)
            .iter()
            .all(|&x| x == 1.0)
    );
}

#[test]
fn the_lobe_peaks_at_the_normal_is_clamped_behind_it_and_uniform_without_a_normal() {
    let (row, col) = (3, 5);
    let n = net_texel_direction(row, col);
    let lt = lambert_transport(&[Some(n), None], IDENTITY);
    assert_eq!(lt.len(), 2 * LT_DIM);
    let peak = row * ENV_W + col;
    for c in 0..3 {
        let channel = &lt[c * ENV_TEXELS..(c + 1) * ENV_TEXELS];
        assert!((channel[peak] - 1.0).abs() < 1e-6);
        assert!(channel.iter().all(|&x| (0.0..=1.0 + 1e-6).contains(&x)));
        // The texel opposite the normal (row 7 − 3, column turned by half a turn) is dark.
        let opposite = (7 - row) * ENV_W + (col + ENV_W / 2) % ENV_W;
        assert_eq!(channel[opposite], 0.0);
        // Half the sphere faces away.
        let lit = channel.iter().filter(|&&x| x > 0.0).count();
        assert!((56..=72).contains(&lit), "{lit} texels lit");
    }
    assert!(lt[LT_DIM..].iter().all(|&x| x == 1.0));

    // A rotation of the frame turns the lobe: the normal given in a frame turned by π
    // about z peaks at the texel whose direction is the turned normal.
    let turn = [[-1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0]];
    let turned = lambert_transport(&[Some([-n[0], -n[1], n[2]])], turn);
    assert!((turned[peak] - 1.0).abs() < 1e-6);
}

#[test]
fn normalised_prior_reproduces_the_source_colours_and_relights_by_the_irradiance_ratio() {
    let device = Device::Cpu;
    let n = net_texel_direction(2, 9);
    let lobe = lambert_transport(&[Some(n)], IDENTITY);
    // A source light from one side, a target light from all around, per channel.
    let source: Vec<f32> = (0..LT_DIM).map(|i| 0.2 + ((i * 7) % 13) as f32 / 13.0).collect();
    let target: Vec<f32> = (0..LT_DIM).map(|i| 0.5 + ((i * 5) % 11) as f32 / 11.0).collect();
    let e_source = Tensor::from_vec(source.clone(), (3, ENV_TEXELS), &device).unwrap();
    let lt = Tensor::from_vec(lobe.clone(), (1, 1, LT_DIM), &device).unwrap();
    let normalised = normalise_to_source(&lt, &e_source)
        .unwrap()
        .flatten_all()
        .unwrap()
        .to_vec1::<f32>()
        .unwrap();
    for c in 0..3 {
        let range = c * ENV_TEXELS..(c + 1) * ENV_TEXELS;
        let dot = |l: &[f32], e: &[f32]| l.iter().zip(e).map(|(a, b)| a * b).sum::<f32>();
        let under_source = dot(&normalised[range.clone()], &source[range.clone()]);
        assert!((under_source - 1.0).abs() < 1e-5, "channel {c}: {under_source}");
        let ratio = dot(&lobe[range.clone()], &target[range.clone()])
            / dot(&lobe[range.clone()], &source[range.clone()]);
        let under_target = dot(&normalised[range.clone()], &target[range]);
        assert!(
            (under_target - ratio).abs() < 1e-5 * ratio,
            "channel {c}: {under_target} vs {ratio}"
        );
    }
}

#[test]
fn bad_prior_settings_are_refused() {
    for (step_mm, weight) in [(0.0, 1.0), (f32::NAN, 1.0), (2.0, 1.5), (2.0, -0.1)] {
        assert!(
            ShadingPrior { step_mm, weight }.validate().is_err(),
            "{step_mm} {weight}"
        );
    }
    assert!(
        ShadingPrior {
            step_mm: 2.0,
            weight: 0.5
        }
        .validate()
        .is_ok()
    );
}
