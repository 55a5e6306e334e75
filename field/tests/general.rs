//! Properties the parity fixtures (one square, five-view case) do not pin down:
//! any number of views, non-square images, fx ≠ fy, off-centre principal points,
//! invariance to translating the world and to reordering the non-reference views,
//! the linearity that lets a bake replace shading by `T·L`, and the field-source
//! contract (units, frames, hull pruning, determinism). Weights are deterministic
//! pseudo-random, so these run without the fixture files.

#![allow(clippy::unwrap_used)] // Test helpers outside #[test] functions unwrap too.

use candle_core::{DType, Device, Tensor};
use candle_nn::{VarBuilder, VarMap};
use glam::{DVec3, Vec3};
use nelf_field::capture::default_net_from_world;
use nelf_field::light::{net_light_to_latlong, net_to_ours};
use nelf_field::{Architecture, Model, NelfConfig, NelfField, NetCapture, Stage};
use nelf_format::conventions::{LT_DIM, PinholeCamera, is_rotation, shade};
use nelf_scene::field::{FieldSource, ViewPolicy};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

/// A model with deterministic weights: unit-ish group norms, `PReLU` slopes 0.25,
/// uniform `±√(3/fan_in)` matrices, small biases.
fn deterministic_model(seed: u64) -> Model {
    deterministic_trainable_model(seed, NelfConfig::default()).0
}

/// [`deterministic_model`] of any configuration, with its variables (trainable).
fn deterministic_trainable_model(seed: u64, config: NelfConfig) -> (Model, VarMap) {
    let varmap = VarMap::new();
    let vb = VarBuilder::from_varmap(&varmap, DType::F32, &Device::Cpu);
    let model = Model::new(&vb, config).unwrap();
    let mut rng = Pcg64::seed_from_u64(seed);
    let data = varmap.data().lock().unwrap();
    let mut names: Vec<&String> = data.keys().collect();
    names.sort();
    for name in names {
        let var = &data[name];
        let dims = var.dims().to_vec();
        let count: usize = dims.iter().product();
        let values: Vec<f32> = if dims.len() >= 2 {
            let fan_in: usize = dims[1..].iter().product();
            let bound = (3.0 / fan_in as f32).sqrt();
            (0..count).map(|_| rng.random_range(-bound..bound)).collect()
        } else if name.ends_with("norm.weight") {
            (0..count).map(|_| 1.0 + rng.random_range(-0.1f32..0.1)).collect()
        } else if name.ends_with("bias") {
            (0..count).map(|_| rng.random_range(-0.1f32..0.1)).collect()
        } else {
            vec![0.25; count]
        };
        var.set(&Tensor::from_vec(values, dims, &Device::Cpu).unwrap())
            .unwrap();
    }
    drop(data);
    (model, varmap)
}

/// `views` cameras about 1 m from `centre` (metres, +y up, view 0 on +z), `w × h`
/// images with fx ≠ fy and off-centre principal points, smooth masked images and
/// disk masks.
fn synthetic_capture(views: usize, w: u32, h: u32, centre: DVec3) -> NetCapture {
    let cameras: Vec<PinholeCamera> = (0..views)
        .map(|i| {
            let a = (i as f64 - 0.4 * views as f64) * 0.25;
            let e = 0.1 * (i % 2) as f64;
            let eye =
                centre + DVec3::new(a.sin() * e.cos(), e.sin(), a.cos() * e.cos()) * (1.0 + 0.05 * i as f64);
            let mut cam = PinholeCamera::look_at(eye, centre, DVec3::Y, w, h, 0.35);
            cam.fy *= 1.1;
            cam.cx += 1.5;
            cam.cy -= 2.0;
            cam
        })
        .collect();
    let (wu, hu) = (w as usize, h as usize);
    let images: Vec<Vec<[f32; 3]>> = (0..views)
        .map(|v| {
            (0..wu * hu)
                .map(|p| {
                    let (x, y) = ((p % wu) as f32 / wu as f32, (p / wu) as f32 / hu as f32);
                    [
                        0.5 + 0.4 * (6.0 * x + v as f32).sin(),
                        0.4 + 0.3 * (5.0 * y).cos(),
                        0.3 + 0.2 * x * y,
                    ]
                })
                .collect()
        })
        .collect();
    let masks: Vec<Vec<f32>> = cameras
        .iter()
        .map(|cam| {
            let c = cam.project(centre).unwrap();
            let r = 0.4 * f64::from(w.min(h));
            (0..wu * hu)
                .map(|p| {
                    let d = ((p % wu) as f64 + 0.5 - c.x).hypot((p / wu) as f64 + 0.5 - c.y);
                    if d < r { 1.0 } else { 0.0 }
                })
                .collect()
        })
        .collect();
    NetCapture::new(&cameras, &images, &masks, centre, default_net_from_world()).unwrap()
}

/// Points near `centre` (metres), inside the hull for the captures above.
fn points_near(centre: DVec3, count: usize, seed: u64) -> Vec<Vec3> {
    let mut rng = Pcg64::seed_from_u64(seed);
    (0..count)
        .map(|_| {
            let o = DVec3::new(
                rng.random_range(-0.04..0.04),
                rng.random_range(-0.04..0.04),
                rng.random_range(-0.04..0.04),
            );
            (centre + o).as_vec3()
        })
        .collect()
}

/// [`points_near`] in `capture`'s network frame (millimetres).
fn net_points_near(capture: &NetCapture, centre: DVec3, count: usize, seed: u64) -> Vec<[f32; 3]> {
    points_near(centre, count, seed)
        .iter()
        .map(|p| capture.to_net_point(p.as_dvec3()))
        .collect()
}

fn evaluate(field: &NelfField, points: &[Vec3], view: &ViewPolicy) -> (Vec<f32>, Vec<f32>) {
    let mut density = vec![0.0f32; points.len()];
    let mut lt = vec![0.0f32; points.len() * LT_DIM];
    field.evaluate(points, view, &mut density, &mut lt).unwrap();
    (density, lt)
}

fn assert_close(a: &[f32], b: &[f32], rtol: f32, what: &str) {
    assert_eq!(a.len(), b.len());
    let scale = a.iter().map(|v| v.abs()).fold(0.0f32, f32::max).max(1e-12);
    for (i, (x, y)) in a.iter().zip(b).enumerate() {
        assert!(
            (x - y).abs() <= rtol * scale,
            "{what}[{i}]: {x} vs {y} (scale {scale})"
        );
    }
}

#[test]
fn non_square_views_of_any_count_are_translation_invariant() {
    let model = deterministic_model(1);
    let shift = DVec3::new(0.1, -0.05, 0.2);
    let a = NelfField::new(model.clone(), &synthetic_capture(3, 48, 32, DVec3::ZERO)).unwrap();
    let b = NelfField::new(model, &synthetic_capture(3, 48, 32, shift)).unwrap();
    assert_eq!(a.encoded().views(), 3);
    assert_eq!(a.encoded().size(), (48, 32));
    let points = points_near(DVec3::ZERO, 64, 2);
    let moved: Vec<Vec3> = points.iter().map(|p| *p + shift.as_vec3()).collect();
    let eye = Vec3::new(0.3, 0.1, 1.0);
    let (da, ta) = evaluate(&a, &points, &ViewPolicy::TowardPoint(eye));
    let (db, tb) = evaluate(&b, &moved, &ViewPolicy::TowardPoint(eye + shift.as_vec3()));
    assert!(
        da.iter().filter(|&&d| d > 0.0).count() > 32,
        "most points are inside the hull"
    );
    assert_close(&da, &db, 1e-3, "density");
    assert_close(&ta, &tb, 1e-3, "light transport");
    assert_close(
        &a.encoded().light().source_light,
        &b.encoded().light().source_light,
        1e-4,
        "source light",
    );
    let (lo_a, hi_a) = a.bounds();
    let (lo_b, hi_b) = b.bounds();
    let cell = 0.4 / 96.0 + 1e-4;
    assert!((lo_b - lo_a - shift.as_vec3()).abs().max_element() <= cell);
    assert!((hi_b - hi_a - shift.as_vec3()).abs().max_element() <= cell);
}

#[test]
fn reordering_views_other_than_the_first_changes_nothing() {
    let model = deterministic_model(3);
    let capture = synthetic_capture(4, 32, 48, DVec3::ZERO);
    let mut swapped = capture.clone();
    let plane = 32 * 48;
    let (v2, v3) = (2 * plane, 3 * plane);
    let images = &mut swapped.views.images;
    let tail: Vec<f32> = images[3 * v2..3 * (v2 + plane)].to_vec();
    images.copy_within(3 * v3..3 * (v3 + plane), 3 * v2);
    images[3 * v3..3 * (v3 + plane)].copy_from_slice(&tail);
    swapped.views.masks.swap_with_slice_at(v2, v3, plane);
    swapped.views.cameras.swap(2, 3);
    swapped.cameras.swap(2, 3);
    let a = NelfField::new(model.clone(), &capture).unwrap();
    let b = NelfField::new(model, &swapped).unwrap();
    assert_close(
        &a.encoded().light().source_light,
        &b.encoded().light().source_light,
        1e-5,
        "source light",
    );
    let points = points_near(DVec3::ZERO, 48, 4);
    let view = ViewPolicy::Direction(Vec3::new(0.2, 0.0, 1.0));
    let (da, ta) = evaluate(&a, &points, &view);
    let (db, tb) = evaluate(&b, &points, &view);
    assert_close(&da, &db, 1e-5, "density");
    assert_close(&ta, &tb, 1e-5, "light transport");
}

trait SwapRanges {
    fn swap_with_slice_at(&mut self, a: usize, b: usize, len: usize);
}

impl SwapRanges for Vec<f32> {
    fn swap_with_slice_at(&mut self, a: usize, b: usize, len: usize) {
        let (lo, hi) = self.split_at_mut(b);
        lo[a..a + len].swap_with_slice(&mut hi[..len]);
    }
}

#[test]
fn light_transport_reproduces_the_networks_shading() {
    let model = deterministic_model(5);
    let capture = synthetic_capture(3, 32, 32, DVec3::ZERO);
    let encoded = model.encode(&capture.views).unwrap();
    let points = net_points_near(&capture, DVec3::ZERO, 40, 6);
    let dirs: Vec<[f32; 3]> = (0..points.len())
        .map(|i| {
            let d = DVec3::new(0.1 * (i % 3) as f64, -1.0, 0.2).normalize();
            d.as_vec3().to_array()
        })
        .collect();
    let mut rng = Pcg64::seed_from_u64(7);
    let light: Vec<f32> = (0..LT_DIM).map(|_| rng.random_range(0.0f32..2.0)).collect();
    for stage in [Stage::Coarse, Stage::Fine] {
        let shaded = model
            .shade_points(&encoded, &points, &dirs, stage, &light)
            .unwrap();
        let lt = model
            .light_transport_points(&encoded, &points, &dirs, stage)
            .unwrap();
        assert_eq!(shaded.inside, lt.inside);
        assert!(shaded.inside.iter().filter(|&&i| i).count() > 20);
        assert_eq!(shaded.sigma, lt.sigma);
        let ours_light = net_light_to_latlong(&light).unwrap();
        let mut dot = Vec::new();
        let mut ours = vec![0.0f32; LT_DIM];
        for i in 0..points.len() {
            // In the network's layout and, reordered, in ours with conventions::shade.
            let t = &lt.values[i * LT_DIM..(i + 1) * LT_DIM];
            net_to_ours(t, &mut ours);
            let rgb = shade(&ours, &ours_light);
            for c in 0..3 {
                let direct: f32 = (0..128).map(|k| t[c * 128 + k] * light[c * 128 + k]).sum();
                assert!((direct - rgb[c]).abs() <= 1e-5 * direct.abs().max(1e-3));
            }
            dot.extend(rgb);
        }
        assert_close(&dot, &shaded.values, 1e-5, "T·L vs shaded rgb");
    }
}

#[test]
fn field_source_contract() {
    let model = deterministic_model(8);
    let capture = synthetic_capture(3, 32, 32, DVec3::new(0.0, 1.6, 0.0));
    let field = NelfField::new(model.clone(), &capture)
        .unwrap()
        .with_chunk_points(7);
    let centre = capture.head_centre_m;
    assert!(is_rotation(field.world_from_light(), 1e-9));
    // world_from_light = R₀ᵀ·diag(−1, −1, 1): the light frame's −z (our map centre,
    // θ = π/2, φ = 0) is the view-0 camera's −z, i.e. toward the camera.
    let toward_cam0 = (capture.cameras[0].centre() - centre).normalize();
    assert!((field.world_from_light() * DVec3::NEG_Z).abs_diff_eq(toward_cam0, 0.05));
    let (lo, hi) = field.bounds();
    assert!(lo.cmplt(centre.as_vec3()).all() && hi.cmpgt(centre.as_vec3()).all());
    assert!((hi - lo).max_element() < 0.41);

    let mut points = points_near(centre, 30, 9);
    points.push(centre.as_vec3() + Vec3::new(0.0, 0.0, 0.6)); // outside the hull
    let view = field.recommended_view_policy();
    let (density, lt) = evaluate(&field, &points, &view);
    let last = points.len() - 1;
    assert_eq!(density[last], 0.0);
    assert!(lt[last * LT_DIM..].iter().all(|&v| v == 0.0));
    assert!(density[..last].iter().filter(|&&d| d > 0.0).count() > 20);
    assert!(lt.iter().all(|v| v.is_finite() && *v >= 0.0));
    // Units: σ in 1/m is 1000 × the network's 1/mm.
    let net_points: Vec<[f32; 3]> = points
        .iter()
        .map(|p| capture.to_net_point(p.as_dvec3()))
        .collect();
    let toward = |p: &Vec3, eye: DVec3| capture.to_net_direction((eye - p.as_dvec3()).normalize());
    let eye = capture.cameras[1].centre();
    let dirs: Vec<[f32; 3]> = points.iter().map(|p| toward(p, eye)).collect();
    let direct = model
        .density_points(field.encoded(), &net_points, &dirs, Stage::Fine)
        .unwrap();
    let (single, _) = evaluate(&field, &points, &ViewPolicy::TowardPoint(eye.as_vec3()));
    for (s, d) in single.iter().zip(&direct.sigma) {
        assert!(
            (s - 1000.0 * d).abs() <= 1e-4 * s.abs().max(1e-3),
            "{s} vs 1000 × {d}"
        );
    }
    // An average of one direction twice is that direction.
    let (twice, twice_lt) = evaluate(
        &field,
        &points,
        &ViewPolicy::AverageTowardPoints(vec![eye.as_vec3(), eye.as_vec3()]),
    );
    let (_, single_lt) = evaluate(&field, &points, &ViewPolicy::TowardPoint(eye.as_vec3()));
    assert_close(&twice, &single, 1e-6, "averaged density");
    assert_close(&twice_lt, &single_lt, 1e-6, "averaged light transport");
    // Batching does not matter; evaluate_density matches evaluate's density.
    let whole = NelfField::new(model, &capture).unwrap();
    let (d2, t2) = evaluate(&whole, &points, &view);
    assert_close(&density, &d2, 1e-6, "density across chunk sizes");
    assert_close(&lt, &t2, 1e-6, "light transport across chunk sizes");
    let mut only = vec![0.0f32; points.len()];
    field.evaluate_density(&points, &mut only).unwrap();
    assert_close(&only, &density, 1e-5, "evaluate_density");
    // Errors, not panics, on bad buffers and points.
    let mut short = vec![0.0f32; 2];
    assert!(field.evaluate(&points, &view, &mut short, &mut []).is_err());
    let mut d1 = vec![0.0f32; 1];
    let mut t1 = vec![0.0f32; LT_DIM];
    assert!(field.evaluate(&[Vec3::NAN], &view, &mut d1, &mut t1).is_err());
}

/// Training reads its variables through differentiable ops; inference reads loaded
/// tensors through the fused CPU kernels. A small architecture saved from variables
/// and loaded back must be recognised from its shapes and give the same numbers on
/// both paths (encoder, light estimate, per-point networks).
#[test]
fn trainable_and_loaded_weights_agree_and_small_widths_round_trip() {
    let arch = Architecture {
        encoder_channels: [16, 32, 32, 64],
        latent_channels: 8,
        geometry_features: 16,
        lt_hidden: 32,
    };
    let config = NelfConfig {
        architecture: arch,
        ..NelfConfig::default()
    };
    let (trainable, varmap) = deterministic_trainable_model(7, config);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("small.safetensors");
    varmap.save(&path).unwrap();
    let loaded = Model::load(&path, NelfConfig::default(), &Device::Cpu).unwrap();
    assert_eq!(loaded.config().architecture, arch);

    let centre = DVec3::new(0.1, 1.6, -0.2);
    let capture = synthetic_capture(3, 64, 48, centre);
    let a = trainable.encode(&capture.views).unwrap();
    let b = loaded.encode(&capture.views).unwrap();
    assert_close(
        &a.light().source_light,
        &b.light().source_light,
        1e-4,
        "source light",
    );
    let points = net_points_near(&capture, centre, 64, 3);
    let dirs = vec![[0.0f32, -1.0, 0.0]; points.len()];
    for stage in [Stage::Coarse, Stage::Fine] {
        let (_, ta) = trainable.run_points(&a, &points, &dirs, stage).unwrap();
        let (_, tb) = loaded.run_points(&b, &points, &dirs, stage).unwrap();
        let flat = |t: &Tensor| t.flatten_all().unwrap().to_vec1::<f32>().unwrap();
        assert_close(&flat(&ta.density), &flat(&tb.density), 1e-4, "density");
        assert_close(&flat(&ta.lt_scale), &flat(&tb.lt_scale), 1e-4, "lt");
        assert_close(&flat(&ta.blend_softmax), &flat(&tb.blend_softmax), 1e-4, "blend");
    }
}

/// The source-view calibration (`nelf_field::calibrate`): the gain scales the light
/// transport and nothing else, it never raises the source views' error, refitting is
/// idempotent, and it is exactly inverse to the lighting's scale (the objective at
/// gain `g` under `c·L` is the objective at `c·g` under `L`).
#[test]
fn source_calibration_scales_light_transport_inversely_to_the_lighting() {
    let capture = synthetic_capture(3, 32, 32, DVec3::ZERO);
    // Small widths keep the dozens of source-view renderings cheap.
    let small = NelfConfig {
        architecture: Architecture {
            encoder_channels: [16, 32, 32, 32],
            latent_channels: 16,
            geometry_features: 32,
            lt_hidden: 32,
        },
        ..NelfConfig::default()
    };
    let model = deterministic_trainable_model(21, small).0;
    let plain = NelfField::new(model.clone(), &capture).unwrap();
    let mut field = NelfField::new(model, &capture).unwrap();
    let mut rng = Pcg64::seed_from_u64(22);
    let base: Vec<f32> = (0..LT_DIM).map(|_| rng.random_range(0.2f32..1.0)).collect();
    let light =
        |scale: f32| net_light_to_latlong(&base.iter().map(|v| v * scale).collect::<Vec<_>>()).unwrap();
    // Rescale the lighting until the fitted gain is 1 (inside the searched range).
    let mut unit = 1.0f32;
    for _ in 0..3 {
        let (next, fit) = field.calibrated_to_sources(&light(unit)).unwrap();
        unit *= fit.gain;
        field = next;
    }
    let (mut field, fit) = field.calibrated_to_sources(&light(unit)).unwrap();
    assert!((fit.gain - 1.0).abs() < 0.01, "{fit:?}");
    assert!(fit.rmse_after <= fit.rmse_before && fit.pixels >= nelf_field::calibrate::MIN_PIXELS);
    let points = points_near(DVec3::ZERO, 20, 23);
    let view = plain.recommended_view_policy();
    let (d_raw, t_raw) = evaluate(&plain, &points, &view);
    for c in [0.8f32, 1.25] {
        let (calibrated, fit_c) = field.calibrated_to_sources(&light(unit * c)).unwrap();
        assert!(
            (fit_c.gain * c - fit.gain).abs() < 0.005,
            "c {c}: {fit_c:?} vs {fit:?}"
        );
        assert!((calibrated.light_transport_scale() - fit_c.gain).abs() < 1e-6);
        assert_eq!(calibrated.source_gain(), fit_c.gain);
        // The light transport is the uncalibrated one times the gain; σ is untouched.
        let (d_cal, t_cal) = evaluate(&calibrated, &points, &view);
        assert_close(&d_cal, &d_raw, 1e-6, "density is not calibrated");
        let scaled: Vec<f32> = t_raw.iter().map(|v| v * fit_c.gain).collect();
        assert_close(&t_cal, &scaled, 1e-5, "light transport × gain");
        // Refitting under the same lighting gives the same gain (it starts from 1).
        let (refitted, refit) = calibrated.calibrated_to_sources(&light(unit * c)).unwrap();
        assert_eq!(refit.gain, fit_c.gain);
        field = refitted;
    }
}

#[test]
fn source_normalisation_reproduces_the_source_colours_under_the_source_light() {
    let model = deterministic_model(11);
    let capture = synthetic_capture(3, 32, 32, DVec3::ZERO);
    let encoded = model.encode(&capture.views).unwrap();
    let points = net_points_near(&capture, DVec3::ZERO, 40, 12);
    let mut rng = Pcg64::seed_from_u64(13);
    let source: Vec<f32> = (0..LT_DIM).map(|_| rng.random_range(0.2f32..2.0)).collect();
    let target: Vec<f32> = (0..LT_DIM).map(|_| rng.random_range(0.0f32..3.0)).collect();
    let normalised = model.clone().with_source_normalisation(Some(&source)).unwrap();
    assert!(normalised.source_normalised() && !model.source_normalised());
    let inside: Vec<[f32; 3]> = points
        .iter()
        .zip(encoded.hull(&points).inside)
        .filter_map(|(p, i)| i.then_some(*p))
        .collect();
    assert!(inside.len() > 20, "{} points inside", inside.len());
    let dirs = vec![[0.0f32, -0.2, 0.98]; inside.len()];
    for stage in [Stage::Coarse, Stage::Fine] {
        // Under the source light each point's colour is the blend of its source colours.
        let (inputs, trace) = normalised.run_points(&encoded, &inside, &dirs, stage).unwrap();
        let blended = inputs
            .source_rgb
            .broadcast_mul(&trace.blend_softmax)
            .unwrap()
            .sum(1)
            .unwrap()
            .flatten_all()
            .unwrap()
            .to_vec1::<f32>()
            .unwrap();
        let under_source = normalised
            .shade_points(&encoded, &inside, &dirs, stage, &source)
            .unwrap();
        assert_close(
            &under_source.values,
            &blended,
            1e-4,
            "source light vs blended photos",
        );
        let raw = model
            .shade_points(&encoded, &inside, &dirs, stage, &source)
            .unwrap();
        let off: f32 = raw
            .values
            .iter()
            .zip(&blended)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f32::max);
        assert!(off > 1e-2, "the raw network already matched its photos ({off})");
        // The normalisation fixes the units: a source light k times as bright makes the
        // same colours under any other light 1/k as bright; σ is untouched.
        let k = 2.5f32;
        let brighter: Vec<f32> = source.iter().map(|v| v * k).collect();
        let a = normalised
            .shade_points(&encoded, &inside, &dirs, stage, &target)
            .unwrap();
        let b = model
            .clone()
            .with_source_normalisation(Some(&brighter))
            .unwrap()
            .shade_points(&encoded, &inside, &dirs, stage, &target)
            .unwrap();
        let scaled: Vec<f32> = b.values.iter().map(|v| v * k).collect();
        assert_close(&scaled, &a.values, 1e-4, "normalised to k·L_S, times k");
        assert_eq!(a.sigma, raw.sigma);
    }
}
