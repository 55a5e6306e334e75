//! GPU renderer tests on a real adapter (in CI: Mesa's lavapipe, software Vulkan).
//!
//! * The GPU image equals the CPU reference renderer's (`nelf_render::render_asset`) for
//!   the same asset — written and read back through the file format — camera and
//!   lighting: PSNR ≥ 45 dB, for 8-bit and f16 coefficients, all and truncated ranks.
//! * Relighting after an environment rotation equals a fresh relight with the rotated map.
//! * A damaged or invalid asset is an error value, and the renderer keeps working.

#![allow(clippy::unwrap_used)] // Test helpers outside #[test] functions unwrap too.

use glam::{DMat3, DVec3};
use nelf_format::conventions::{ENV_W, LatLong, PinholeCamera, rotation_y};
use nelf_format::synthetic::SyntheticField;
use nelf_format::{Asset, CoefficientEncoding, Coefficients, WriteOptions, read_asset, write_asset};
use nelf_render::{Image, MarchSettings, render_asset};
use nelf_viewer::{
    DisplaySettings, GpuRenderer, MarchPass, MarchView, RelightView, ToneMap, ViewSettings, ViewerError,
};

fn renderer() -> GpuRenderer {
    GpuRenderer::new_headless().unwrap_or_else(|e| panic!("{e}"))
}

/// A synthetic head written to a file and read back (what the viewer would load).
fn asset_through_file(voxels: usize, rank: usize, encoding: CoefficientEncoding, seed: u64) -> Asset {
    let asset = SyntheticField::new(voxels, seed).asset(rank, encoding).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("head.nelf");
    write_asset(&path, &asset, &WriteOptions::default()).unwrap();
    let back = read_asset(&path).unwrap();
    assert_eq!(back, asset);
    back
}

/// `asset` without the bricks where `drop(coords)` holds: occupied bricks then border
/// missing ones with dense voxels on their faces (the apron and the corner lookup matter).
fn without_bricks(asset: &Asset, drop: impl Fn([u16; 3]) -> bool) -> Asset {
    let rank = asset.rank();
    let keep: Vec<usize> = (0..asset.bricks.len())
        .filter(|&i| !drop(asset.bricks[i]))
        .collect();
    let mut out = asset.clone();
    out.bricks = keep.iter().map(|&i| asset.bricks[i]).collect();
    out.density = keep
        .iter()
        .flat_map(|&i| asset.density[i * 512..(i + 1) * 512].to_vec())
        .collect();
    out.coefficients = match &asset.coefficients {
        Coefficients::U8Affine {
            scale, offset, codes, ..
        } => Coefficients::U8Affine {
            rank,
            scale: scale.clone(),
            offset: offset.clone(),
            codes: keep
                .iter()
                .flat_map(|&i| codes[i * 512 * rank..(i + 1) * 512 * rank].to_vec())
                .collect(),
        },
        Coefficients::F16 { values, .. } => Coefficients::F16 {
            rank,
            values: keep
                .iter()
                .flat_map(|&i| values[i * 512 * rank..(i + 1) * 512 * rank].to_vec())
                .collect(),
        },
    };
    out.validate().unwrap();
    out
}

/// A smooth sky with a warm key light, `width × height`, deterministic.
fn sky(width: usize, height: usize) -> LatLong {
    let key = DVec3::new(0.6, 0.5, 0.62).normalize();
    let mut texels = Vec::with_capacity(width * height);
    for row in 0..height {
        for col in 0..width {
            let theta = (row as f64 + 0.5) / height as f64 * std::f64::consts::PI;
            let phi = (col as f64 + 0.5) / width as f64 * std::f64::consts::TAU - std::f64::consts::PI;
            let d = nelf_format::conventions::direction(theta, phi);
            let spot = (8.0 * (d.dot(key) - 1.0)).exp();
            let up = 0.5 + 0.5 * d.y;
            texels.push([
                (0.3 * up + 4.0 * spot + 0.05 * (3.0 * phi).sin().abs()) as f32,
                (0.35 * up + 3.0 * spot) as f32,
                (0.5 * up + 2.0 * spot) as f32,
            ]);
        }
    }
    LatLong::new(width, height, texels).unwrap()
}

/// A camera looking at the head from an oblique direction.
fn camera(width: u32, height: u32) -> PinholeCamera {
    PinholeCamera::look_at(
        DVec3::new(0.17, 0.09, 0.42),
        DVec3::new(0.0, 0.01, 0.0),
        DVec3::Y,
        width,
        height,
        0.65,
    )
}

/// PSNR (dB) of `test` against `reference` over premultiplied rgb and alpha, peak = the
/// reference's largest value.
fn psnr(reference: &Image, test: &Image) -> f64 {
    let mut peak = 0.0f64;
    let mut sum = 0.0f64;
    let mut n = 0usize;
    for (a, b) in reference.rgb.iter().zip(&test.rgb) {
        for c in 0..3 {
            peak = peak.max(f64::from(a[c]));
            sum += (f64::from(a[c]) - f64::from(b[c])).powi(2);
            n += 1;
        }
    }
    for (a, b) in reference.alpha.iter().zip(&test.alpha) {
        peak = peak.max(f64::from(*a));
        sum += (f64::from(*a) - f64::from(*b)).powi(2);
        n += 1;
    }
    assert!(peak > 0.0, "the reference image is black");
    10.0 * (peak * peak / (sum / n as f64).max(1e-30)).log10()
}

fn no_jitter() -> ViewSettings {
    ViewSettings {
        march: MarchSettings::default(),
        jitter: false,
        frame_index: 0,
        view: MarchView::Shaded,
        pass: MarchPass::Fragment,
    }
}

#[test]
fn gpu_matches_cpu_reference() {
    let mut gpu = renderer();
    let env = sky(64, 32);
    let env_rotation = rotation_y(0.7);
    let cam = camera(96, 80);
    for (encoding, rank, truncate, holes, signed) in [
        (CoefficientEncoding::U8Affine, 8, None, false, false),
        (CoefficientEncoding::U8Affine, 8, Some(3), false, false),
        (CoefficientEncoding::F16, 6, None, false, false),
        (CoefficientEncoding::U8Affine, 8, None, true, false),
        (CoefficientEncoding::U8Affine, 8, None, true, true),
    ] {
        let mut asset = asset_through_file(40_000, rank, encoding, 5);
        if holes {
            asset = without_bricks(&asset, |b| (b[0] + b[1] + 2 * b[2]) % 3 == 0);
        }
        if signed {
            // Signed density (SPEC 1.1): shift so the thinner parts go negative; both
            // renderers clip max(0, ·) after interpolating.
            let max = asset.density.iter().fold(0.0f32, |m, d| m.max(d.to_f32()));
            for d in &mut asset.density {
                *d = half::f16::from_f32(2.0 * d.to_f32() - 0.3 * max);
            }
            assert!(nelf_format::has_negative_density(&asset.density));
        }
        gpu.load_asset(&asset).unwrap();
        gpu.set_lighting(&env, env_rotation).unwrap();
        gpu.set_rank(truncate);
        let got = gpu.render(&cam, &no_jitter()).unwrap();
        let want = render_asset(
            &asset,
            &cam,
            &env,
            env_rotation,
            truncate,
            &MarchSettings::default(),
        )
        .unwrap();
        let covered = want.alpha.iter().filter(|&&a| a > 0.5).count();
        assert!(covered > 500, "the head covers only {covered} pixels");
        // The compute pass marches the same pixels as the fragment pass.
        let compute = ViewSettings {
            pass: MarchPass::Compute,
            ..no_jitter()
        };
        assert_eq!(gpu.render(&cam, &compute).unwrap(), got);
        let db = psnr(&want, &got);
        eprintln!(
            "{encoding:?} rank {rank} truncated {truncate:?} holes {holes} signed {signed}: PSNR {db:.1} dB"
        );
        assert!(
            db >= 45.0,
            "{encoding:?} rank {rank} truncated {truncate:?} holes {holes} signed {signed}: PSNR {db:.2} dB"
        );
    }
}

#[test]
fn gpu_matches_cpu_from_inside_the_grid_and_with_coarse_steps() {
    // A camera inside the grid box (t_entry = 0, in a corner outside the head) and a
    // longer step exercise the interval and skip logic on other lattice positions.
    let mut gpu = renderer();
    let asset = asset_through_file(20_000, 5, CoefficientEncoding::U8Affine, 9);
    let env = sky(32, 16);
    gpu.load_asset(&asset).unwrap();
    gpu.set_lighting(&env, DMat3::IDENTITY).unwrap();
    let cam = PinholeCamera::look_at(DVec3::new(0.105, 0.09, 0.1), DVec3::ZERO, DVec3::Y, 72, 64, 1.0);
    let grid = asset.grid;
    assert!((0..3).all(|a| cam.centre()[a] > grid.bbox_min_m[a] && cam.centre()[a] < grid.bbox_max_m()[a]));
    for step_voxels in [0.5f32, 1.3] {
        let settings = ViewSettings {
            march: MarchSettings {
                step_voxels,
                min_transmittance: 1e-3,
                ..MarchSettings::default()
            },
            ..no_jitter()
        };
        let got = gpu.render(&cam, &settings).unwrap();
        let want = render_asset(&asset, &cam, &env, DMat3::IDENTITY, None, &settings.march).unwrap();
        let covered = want.alpha.iter().filter(|&&a| a > 0.5).count();
        assert!(covered > 800, "the head covers only {covered} pixels");
        let db = psnr(&want, &got);
        eprintln!("inside, step {step_voxels}: PSNR {db:.1} dB, {covered} pixels covered");
        assert!(db >= 45.0, "step {step_voxels}: PSNR {db:.2} dB");
    }
}

#[test]
fn relight_after_rotation_equals_fresh_relight_of_rotated_map() {
    let asset = asset_through_file(20_000, 6, CoefficientEncoding::U8Affine, 2);
    let width = 2 * ENV_W;
    let env = sky(width, 16);
    // Turning the map by `shift` of its columns: rotation_y(α) takes d(θ, φ) to d(θ, φ − α),
    // so the world sees at azimuth φ what the map holds at φ + α: column j + shift.
    let shift = 5;
    let alpha = shift as f64 * std::f64::consts::TAU / width as f64;
    let shifted: Vec<[f32; 3]> = (0..16)
        .flat_map(|row| (0..width).map(move |col| (row, col)))
        .map(|(row, col)| env.get(row, (col + shift) % width))
        .collect();
    let rotated_map = LatLong::new(width, 16, shifted).unwrap();

    let mut a = renderer();
    a.load_asset(&asset).unwrap();
    a.set_lighting(&env, DMat3::IDENTITY).unwrap();
    let before = a.read_atlas().unwrap();
    a.set_light_rotation(rotation_y(alpha)).unwrap();
    let after = a.read_atlas().unwrap();

    let mut b = renderer();
    b.load_asset(&asset).unwrap();
    b.set_lighting(&rotated_map, DMat3::IDENTITY).unwrap();
    let fresh = b.read_atlas().unwrap();

    assert_eq!(after.len(), fresh.len());
    let scale = fresh
        .iter()
        .flat_map(|t| t[..3].iter())
        .fold(0.0f32, |m, v| m.max(v.abs()));
    assert!(scale > 0.0);
    let max_diff = after
        .iter()
        .zip(&fresh)
        .flat_map(|(x, y)| (0..4).map(move |c| (x[c] - y[c]).abs()))
        .fold(0.0f32, f32::max);
    // Both are the same f32 sums rounded to f16: at most an ulp or two apart.
    assert!(
        max_diff <= 2e-3 * scale,
        "max difference {max_diff} (scale {scale})"
    );
    let changed = before
        .iter()
        .zip(&after)
        .flat_map(|(x, y)| (0..3).map(move |c| (x[c] - y[c]).abs()))
        .fold(0.0f32, f32::max);
    assert!(
        changed > 0.05 * scale,
        "rotation changed the relit atlas by only {changed}"
    );
}

#[test]
fn damaged_or_invalid_assets_are_errors_and_the_renderer_keeps_working() {
    let asset = asset_through_file(8_000, 4, CoefficientEncoding::U8Affine, 1);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("head.nelf");
    write_asset(&path, &asset, &WriteOptions::default()).unwrap();
    let mut bytes = std::fs::read(&path).unwrap();
    let middle = bytes.len() / 2;
    for b in &mut bytes[middle..middle + 64] {
        *b ^= 0x5a;
    }
    let damaged = dir.path().join("damaged.nelf");
    std::fs::write(&damaged, &bytes).unwrap();
    let truncated = dir.path().join("truncated.nelf");
    std::fs::write(&truncated, &bytes[..100]).unwrap();

    let mut gpu = renderer();
    for p in [&damaged, &truncated, &dir.path().join("missing.nelf")] {
        let err = gpu.load_asset_file(p).unwrap_err();
        assert!(matches!(err, ViewerError::Format(_)), "{p:?}: {err}");
    }
    assert!(matches!(
        gpu.render(&camera(8, 8), &no_jitter()),
        Err(ViewerError::NoAsset)
    ));

    gpu.load_asset_file(&path).unwrap();
    gpu.set_lighting(&sky(32, 16), DMat3::IDENTITY).unwrap();
    let good = gpu.render(&camera(48, 40), &no_jitter()).unwrap();

    // In-memory damage the reader would have refused: still an error, old asset kept.
    let mut bad = asset.clone();
    bad.bricks[0] = [60_000, 0, 0];
    assert!(gpu.load_asset(&bad).is_err());
    let mut bad = asset.clone();
    bad.pca.mean[3] = f32::NAN;
    assert!(gpu.load_asset(&bad).is_err());
    let again = gpu.render(&camera(48, 40), &no_jitter()).unwrap();
    assert_eq!(good, again);

    // Bad lighting and settings are errors too.
    let not_rotation = DMat3::from_diagonal(DVec3::new(1.0, 1.0, -1.0));
    assert!(gpu.set_lighting(&sky(32, 16), not_rotation).is_err());
    let mut broken = camera(48, 40);
    broken.fx = f64::NAN;
    assert!(gpu.render(&broken, &no_jitter()).is_err());
    let settings = ViewSettings {
        march: MarchSettings {
            step_voxels: 0.0,
            min_transmittance: 1e-3,
            ..MarchSettings::default()
        },
        ..no_jitter()
    };
    assert!(gpu.render(&camera(48, 40), &settings).is_err());
}

#[test]
fn display_pass_and_debug_views() {
    let asset = asset_through_file(8_000, 4, CoefficientEncoding::F16, 3);
    let mut gpu = renderer();
    let info = gpu.load_asset(&asset).unwrap();
    assert!(info.memory.total() > info.memory.atlas_bytes);
    gpu.set_lighting(&LatLong::constant(16, 8, [1.0; 3]), DMat3::IDENTITY)
        .unwrap();
    let cam = camera(64, 48);
    let display = DisplaySettings {
        exposure_ev: 0.0,
        tone_map: ToneMap::Linear,
        background: [0.25, 0.0, 0.5],
    };
    let shown = gpu.render_display(&cam, &no_jitter(), &display).unwrap();
    let linear = gpu.render(&cam, &no_jitter()).unwrap();
    assert_eq!(shown.rgba.len(), 64 * 48 * 4);
    let srgb = |x: f32| {
        let c = x.clamp(0.0, 1.0);
        let e = if c <= 0.003_130_8 {
            12.92 * c
        } else {
            1.055 * c.powf(1.0 / 2.4) - 0.055
        };
        (e * 255.0).round()
    };
    for (i, px) in shown.rgba.chunks_exact(4).enumerate() {
        let a = linear.alpha[i];
        for (c, &value) in px[..3].iter().enumerate() {
            let want = srgb(linear.rgb[i][c] + (1.0 - a) * display.background[c]);
            assert!(
                (f32::from(value) - want).abs() <= 1.0,
                "pixel {i} channel {c}: {value} vs {want}"
            );
        }
        assert_eq!(px[3], 255);
    }
    // Alpha view: grey = alpha of the shaded image.
    let alpha_view = ViewSettings {
        view: MarchView::Alpha,
        ..no_jitter()
    };
    let alpha = gpu.render(&cam, &alpha_view).unwrap();
    for (i, rgb) in alpha.rgb.iter().enumerate() {
        assert!((rgb[0] - linear.alpha[i]).abs() < 1e-6);
    }
    // Density view: the largest density seen maps to 1.
    let density_view = ViewSettings {
        view: MarchView::Density {
            sigma_white_per_m: info.max_density_per_m,
        },
        ..no_jitter()
    };
    let density = gpu.render(&cam, &density_view).unwrap();
    let brightest = density.rgb.iter().map(|c| c[0]).fold(0.0f32, f32::max);
    assert!(brightest > 0.5 && brightest <= 1.0 + 1e-3, "{brightest}");
    // One component's view differs from the shaded image and is non-negative.
    gpu.set_relight_view(RelightView::Component(1));
    let component = gpu.render(&cam, &no_jitter()).unwrap();
    assert!(component.rgb.iter().all(|c| c.iter().all(|&v| v >= 0.0)));
    assert_ne!(component.rgb, linear.rgb);
    // Jitter changes samples, not the picture: close to the lattice render.
    gpu.set_relight_view(RelightView::Shaded);
    let jittered = gpu
        .render(
            &cam,
            &ViewSettings {
                jitter: true,
                frame_index: 7,
                ..no_jitter()
            },
        )
        .unwrap();
    assert_ne!(jittered.rgb, linear.rgb);
    let db = psnr(&linear, &jittered);
    assert!(
        db > 25.0,
        "jittered render too far from the lattice render: {db:.1} dB"
    );
}
