//! GPU renderer tests on a real adapter (in CI: Mesa's lavapipe, software Vulkan).
//!
//! * The GPU image equals the CPU reference renderer's (`nelf_render::render_asset`) for
//!   the same asset — written and read back through the file format — camera and
//!   lighting: PSNR ≥ 45 dB, for 8-bit and f16 coefficients, all and truncated ranks.
//! * A view-dependent asset (format 1.2, also through a file) too, from two eyes on
//!   opposite sides, for 8-bit and f16 view coefficients; its image differs from the
//!   view-independent asset's and from the one with the view direction reversed by far
//!   more than the GPU's error.
//! * A reflection asset (format 1.3, also through a file) too, from three eyes (the
//!   highlights move), with and without missing bricks and after a light rotation; its
//!   image differs from the asset's without the reflection part by far more than the
//!   GPU's error.
//! * Relighting after an environment rotation equals a fresh relight with the rotated map;
//!   at a held camera only the voxels it reads are relit, with the same image.
//! * An asset with a fine density (format 1.4, factors 2 and 4, with missing bricks) too,
//!   in every pass that marches (fragment and compute, the per-pixel replay, the marked
//!   relight, the storage-free march of WebGL2); its image differs from the asset's
//!   without the fine density by far more than the GPU's error.
//! * A damaged or invalid asset is an error value, and the renderer keeps working.

#![allow(clippy::unwrap_used)] // Test helpers outside #[test] functions unwrap too.

use glam::{DMat3, DVec3};
use nelf_format::conventions::{ENV_W, LatLong, PinholeCamera, VIEW_HARMONICS, rotation_y};
use nelf_format::synthetic::{SyntheticField, synthetic_reflection};
use nelf_format::{
    Asset, CoefficientEncoding, Coefficients, FineDensity, Reflection, ViewDependence, WriteOptions,
    read_asset, write_asset,
};
use nelf_render::{Image, MarchSettings, render_asset};
use nelf_viewer::{
    DisplaySettings, GpuRenderer, MarchPass, MarchView, RelightKind, RelightView, ToneMap, ViewSettings,
    ViewerError,
};

fn renderer() -> GpuRenderer {
    GpuRenderer::new_headless().unwrap_or_else(|e| panic!("{e}"))
}

/// A synthetic head written to a file and read back (what the viewer would load).
fn asset_through_file(voxels: usize, rank: usize, encoding: CoefficientEncoding, seed: u64) -> Asset {
    through_file(&SyntheticField::new(voxels, seed).asset(rank, encoding).unwrap())
}

/// `asset` written to a file and read back.
fn through_file(asset: &Asset) -> Asset {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("head.nelf");
    write_asset(&path, asset, &WriteOptions::default()).unwrap();
    let back = read_asset(&path).unwrap();
    assert_eq!(&back, asset);
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

/// A uniform number in [−1, 1) from `i` (splitmix64).
fn noise(i: u64) -> f32 {
    let mut z = i.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^= z >> 31;
    (z >> 40) as f32 / (1u64 << 23) as f32 - 1.0
}

/// Index of the first degree-1 harmonic among a lobe's weights (degree 0, if the
/// convention has it, comes first).
const DEGREE_1: usize = VIEW_HARMONICS - 8;

/// `asset` with a view-dependent part (format 1.2), built by hand: `J = 4` lobes — the
/// three degree-1 harmonics (y, z, x: odd, so reversing the view direction flips them)
/// and a mix of the five degree-2 ones (and degree 0, if the convention has it) — over a
/// view basis of rank `K_v = 3`: the asset's normalised PCA mean (so a lobe brightens or
/// darkens the whole voxel) and its first two PCA components. Coefficients are seeded
/// noise around a few tens of percent of the voxel's own transport, quantized with
/// `encoding`.
fn with_view(asset: &Asset, encoding: CoefficientEncoding, seed: u64) -> Asset {
    const LOBES: usize = 4;
    const RANK: usize = 3;
    let mut lobes = vec![0.0f32; LOBES * VIEW_HARMONICS];
    for j in 0..3 {
        lobes[j * VIEW_HARMONICS + DEGREE_1 + j] = 1.0;
    }
    let mix = &mut lobes[3 * VIEW_HARMONICS..];
    mix[DEGREE_1 + 3..].copy_from_slice(&[0.6, -0.5, 0.8, 0.4, -0.7]);
    mix[..DEGREE_1].fill(0.3);
    let mean_norm = asset.pca.mean.iter().map(|m| m * m).sum::<f32>().sqrt();
    let mut basis: Vec<f32> = asset.pca.mean.iter().map(|m| m / mean_norm).collect();
    basis.extend_from_slice(asset.pca.component(0));
    basis.extend_from_slice(asset.pca.component(1));
    let pca = asset.coefficients.to_f32();
    let k = asset.rank();
    let strength = [0.6f32, 0.5, 0.7, 0.5];
    let mut values = Vec::with_capacity(asset.voxel_count() * LOBES * RANK);
    for v in 0..asset.voxel_count() {
        for (j, s) in strength.iter().enumerate() {
            let n = (((v * LOBES + j) as u64) << 4) ^ seed;
            values.push(mean_norm * s * (1.0 + 0.3 * noise(n)));
            values.push(0.5 * pca[v * k] * noise(n + 1));
            values.push(0.5 * pca[v * k + 1] * noise(n + 2));
        }
    }
    let mut out = asset.clone();
    out.view = Some(ViewDependence {
        lobes,
        basis,
        coefficients: Coefficients::quantize(&values, LOBES * RANK, encoding).unwrap(),
    });
    out.validate().unwrap();
    out
}

/// `asset` with its view part seen from the opposite side: `ω → −ω` negates the
/// degree-1 harmonics' weights (what a sign error in the view direction renders).
fn reversed_view(asset: &Asset) -> Asset {
    let mut out = asset.clone();
    if let Some(view) = &mut out.view {
        for lobe in view.lobes.chunks_exact_mut(VIEW_HARMONICS) {
            for w in lobe.iter_mut().skip(DEGREE_1).take(3) {
                *w = -*w;
            }
        }
    }
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

/// [`camera`]'s 96 × 80 view from another side (a camera that moved).
fn moved_camera() -> PinholeCamera {
    PinholeCamera::look_at(
        DVec3::new(-0.3, 0.05, 0.3),
        DVec3::new(0.0, 0.01, 0.0),
        DVec3::Y,
        96,
        80,
        0.65,
    )
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
fn gpu_matches_cpu_for_view_dependent_assets() {
    let mut gpu = renderer();
    let env = sky(64, 32);
    let env_rotation = rotation_y(0.7);
    let target = DVec3::new(0.0, 0.01, 0.0);
    // Two eyes on opposite sides of the head (and above / below it).
    let cameras = [DVec3::new(0.17, 0.09, 0.42), DVec3::new(-0.36, -0.12, -0.22)]
        .map(|eye| PinholeCamera::look_at(eye, target, DVec3::Y, 96, 80, 0.65));
    let reference = |asset: &Asset, cam: &PinholeCamera, rotation: DMat3| {
        render_asset(asset, cam, &env, rotation, None, &MarchSettings::default()).unwrap()
    };
    for encoding in [CoefficientEncoding::U8Affine, CoefficientEncoding::F16] {
        let mut flat = asset_through_file(40_000, 6, encoding, 5);
        if encoding == CoefficientEncoding::F16 {
            // Missing bricks: the view pass writes aprons and halo slots as the relight does.
            flat = without_bricks(&flat, |b| (b[0] + b[1] + 2 * b[2]) % 3 == 0);
        }
        let asset = through_file(&with_view(&flat, encoding, 3));
        // The view-independent asset first: the renderer then switches to the view path.
        gpu.load_asset(&flat).unwrap();
        assert_eq!(gpu.asset_info().unwrap().view, None);
        gpu.set_lighting(&env, env_rotation).unwrap();
        let flat_images = cameras.map(|cam| gpu.render(&cam, &no_jitter()).unwrap());
        let info = gpu.load_asset(&asset).unwrap();
        let view = info.view.unwrap();
        assert_eq!((view.lobes, view.rank, view.encoding), (4, 3, encoding));
        assert!(info.memory.view_bytes > 0);
        gpu.set_lighting(&env, env_rotation).unwrap();
        let mut images = Vec::new();
        for (i, cam) in cameras.iter().enumerate() {
            let got = gpu.render(cam, &no_jitter()).unwrap();
            let want = reference(&asset, cam, env_rotation);
            let covered = want.alpha.iter().filter(|&&a| a > 0.5).count();
            assert!(covered > 500, "the head covers only {covered} pixels");
            let compute = ViewSettings {
                pass: MarchPass::Compute,
                ..no_jitter()
            };
            assert_eq!(gpu.render(cam, &compute).unwrap(), got);
            let db = psnr(&want, &got);
            // The view part matters far beyond the GPU's error: without it, or toward the
            // opposite direction (a sign error of ω), the image is much further off.
            let without = psnr(&want, &flat_images[i]);
            let reversed = psnr(&want, &reference(&reversed_view(&asset), cam, env_rotation));
            eprintln!(
                "{encoding:?} eye {i}: PSNR {db:.1} dB; view-independent {without:.1} dB, ω reversed {reversed:.1} dB"
            );
            assert!(db >= 45.0, "{encoding:?} eye {i}: PSNR {db:.2} dB");
            assert!(
                without < 35.0 && reversed < 35.0,
                "{encoding:?} eye {i}: the view part barely shows ({without:.1} dB without it, {reversed:.1} dB reversed)"
            );
            images.push(got);
        }
        // Back to the first eye, lighting unchanged: the view pass runs again.
        assert_eq!(gpu.render(&cameras[0], &no_jitter()).unwrap(), images[0]);
        // A debug view of one PCA component and back.
        gpu.set_relight_view(RelightView::Component(1));
        assert_ne!(gpu.render(&cameras[0], &no_jitter()).unwrap(), images[0]);
        gpu.set_relight_view(RelightView::Shaded);
        assert_eq!(gpu.render(&cameras[0], &no_jitter()).unwrap(), images[0]);
        // A lighting change at the same eye relights and reruns the view pass.
        let turned = rotation_y(-1.1);
        gpu.set_light_rotation(turned).unwrap();
        let got = gpu.render(&cameras[1], &no_jitter()).unwrap();
        let db = psnr(&reference(&asset, &cameras[1], turned), &got);
        assert!(db >= 45.0, "{encoding:?} after a light rotation: PSNR {db:.2} dB");
        assert!(psnr(&images[1], &got) < 40.0, "the rotation changed nothing");
    }
}

/// How much brighter the reflection part of [`gpu_matches_cpu_for_reflection_assets`] is
/// than `synthetic_reflection`'s, a sheen of a few percent of `T` whose whole effect on
/// the test head's image is far inside the GPU = CPU tolerance (≈ 60 dB against the image
/// without it): a gloss that a wrong normal, mirror direction, table lookup or eye shows.
const SHEEN_TO_GLOSS: f32 = 100.0;

/// `part` with every voxel's scale multiplied by `factor` (decoded, then quantized again).
fn strengthened(part: &Reflection, voxels: usize, factor: f32) -> Reflection {
    let (normals, scales): (Vec<[f32; 3]>, Vec<f32>) = (0..voxels)
        .map(|v| {
            let (n, s) = part.voxel(v);
            (n, factor * s)
        })
        .unzip();
    Reflection::new(part.exponent, part.eyes_m.clone(), &normals, &scales).unwrap()
}

#[test]
fn gpu_matches_cpu_for_reflection_assets() {
    let mut gpu = renderer();
    let env = sky(64, 32);
    let env_rotation = rotation_y(0.7);
    let target = DVec3::new(0.0, 0.01, 0.0);
    // Three eyes: two in front (near the part's eyes, +z, and off to the side) and one
    // behind and below, where the mirror directions (and highlights) are elsewhere.
    let cameras = [
        DVec3::new(0.17, 0.09, 0.42),
        DVec3::new(-0.3, 0.05, 0.3),
        DVec3::new(-0.36, -0.12, -0.22),
    ]
    .map(|eye| PinholeCamera::look_at(eye, target, DVec3::Y, 96, 80, 0.65));
    let reference = |asset: &Asset, cam: &PinholeCamera, rotation: DMat3| {
        render_asset(asset, cam, &env, rotation, None, &MarchSettings::default()).unwrap()
    };
    for (holes, exponent) in [(false, 20.0), (true, 40.0)] {
        let mut flat = asset_through_file(40_000, 6, CoefficientEncoding::U8Affine, 5);
        if holes {
            // Missing bricks: the reflect pass writes aprons and halo slots as the relight does.
            flat = without_bricks(&flat, |b| (b[0] + b[1] + 2 * b[2]) % 3 == 0);
        }
        let mut asset = flat.clone();
        let part = synthetic_reflection(&flat, exponent, 3).unwrap();
        asset.reflection = Some(strengthened(&part, flat.voxel_count(), SHEEN_TO_GLOSS));
        let asset = through_file(&asset);
        // The asset without its reflection part first: the renderer then switches.
        gpu.load_asset(&flat).unwrap();
        assert_eq!(gpu.asset_info().unwrap().reflection, None);
        gpu.set_lighting(&env, env_rotation).unwrap();
        let flat_images = cameras.map(|cam| gpu.render(&cam, &no_jitter()).unwrap());
        let info = gpu.load_asset(&asset).unwrap();
        let part = info.reflection.unwrap();
        assert_eq!((part.exponent, part.eyes), (exponent, 5));
        assert_eq!(info.view, None);
        assert!(info.memory.view_bytes > 0);
        gpu.set_lighting(&env, env_rotation).unwrap();
        let mut images = Vec::new();
        for (i, cam) in cameras.iter().enumerate() {
            let got = gpu.render(cam, &no_jitter()).unwrap();
            let want = reference(&asset, cam, env_rotation);
            let covered = want.alpha.iter().filter(|&&a| a > 0.5).count();
            assert!(covered > 500, "the head covers only {covered} pixels");
            let compute = ViewSettings {
                pass: MarchPass::Compute,
                ..no_jitter()
            };
            assert_eq!(gpu.render(cam, &compute).unwrap(), got);
            let db = psnr(&want, &got);
            // The reflection part matters far beyond the GPU's error.
            let without = psnr(&want, &flat_images[i]);
            eprintln!(
                "λ {exponent} holes {holes} eye {i}: PSNR {db:.1} dB; without the reflection part {without:.1} dB"
            );
            assert!(db >= 45.0, "λ {exponent} holes {holes} eye {i}: PSNR {db:.2} dB");
            assert!(
                without < 35.0,
                "λ {exponent} holes {holes} eye {i}: the reflection part barely shows ({without:.1} dB without it)"
            );
            images.push(got);
        }
        // The highlights move: the part's change to the image differs between the eyes
        // (the flat images of two eyes differ only by the camera, so compare the change).
        let change = |i: usize| -> Vec<f32> {
            images[i]
                .rgb
                .iter()
                .zip(&flat_images[i].rgb)
                .map(|(a, b)| (a[0] - b[0]) + (a[1] - b[1]) + (a[2] - b[2]))
                .collect()
        };
        let (front, side) = (change(0), change(1));
        let brightened = |c: &[f32]| c.iter().filter(|&&d| d > 0.01).count();
        eprintln!(
            "λ {exponent} holes {holes}: pixels brightened by the part: eye 0 {}, eye 1 {}, eye 2 {}",
            brightened(&front),
            brightened(&side),
            brightened(&change(2))
        );
        assert!(brightened(&front) > 20 && brightened(&side) > 20);
        // Back to the first eye, lighting unchanged: the reflect pass runs again.
        assert_eq!(gpu.render(&cameras[0], &no_jitter()).unwrap(), images[0]);
        // A debug view of one PCA component and back.
        gpu.set_relight_view(RelightView::Component(1));
        assert_ne!(gpu.render(&cameras[0], &no_jitter()).unwrap(), images[0]);
        gpu.set_relight_view(RelightView::Shaded);
        assert_eq!(gpu.render(&cameras[0], &no_jitter()).unwrap(), images[0]);
        // A lighting change at the same eye relights, refilters and reruns the reflect pass.
        let turned = rotation_y(-1.1);
        gpu.set_light_rotation(turned).unwrap();
        let got = gpu.render(&cameras[1], &no_jitter()).unwrap();
        let db = psnr(&reference(&asset, &cameras[1], turned), &got);
        assert!(db >= 45.0, "λ {exponent} after a light rotation: PSNR {db:.2} dB");
        assert!(psnr(&images[1], &got) < 40.0, "the rotation changed nothing");
        assert_eq!(gpu.last_relight(), Some(RelightKind::Full));
    }
}

/// A sphere's signed ramp for a lattice of voxel size `voxel`, at `p`: 0 a quarter voxel
/// outside the surface, transmittance ½ a quarter voxel further in, negative outside
/// (signed density), capped two voxels deep (render/tests/fine.rs, the baker's ramp scaled
/// to the lattice).
fn sphere_ramp(centre: DVec3, radius: f64, voxel: f64, p: DVec3) -> half::f16 {
    let (lead, r) = (0.25 * voxel, 0.25 * voxel);
    let slope = 2.0 * std::f64::consts::LN_2 / (r * r);
    let cap = slope * (lead + 2.0 * voxel);
    let d = (p - centre).length() - radius;
    half::f16::from_f64((slope * (lead - d)).clamp(-cap, cap))
}

/// `asset` with a sphere's ramp as its voxels' density and, with `factor`, the same
/// sphere's ramp at the fine voxels (format 1.4; each lattice's ramp scaled to its own
/// voxel, as the baker stores it), written to a file and read back.
fn with_fine_sphere(asset: &Asset, factor: Option<u32>) -> Asset {
    let centre = DVec3::new(0.0, 0.01, 0.0);
    let lo = DVec3::from_array(asset.grid.bbox_min_m);
    let radius = 0.3 * (DVec3::from_array(asset.grid.bbox_max_m()) - lo).min_element();
    let voxel = asset.grid.voxel_size_m;
    let mut out = asset.clone();
    out.density = (0..asset.voxel_count())
        .map(|v| sphere_ramp(centre, radius, voxel, asset.voxel_position_m(v)))
        .collect();
    out.fine_density = factor.map(|factor| {
        let edge = 8 * factor as usize;
        let fine_voxel = voxel / f64::from(factor);
        let mut values = Vec::with_capacity(asset.bricks.len() * edge * edge * edge);
        for b in &asset.bricks {
            for k in 0..edge {
                for j in 0..edge {
                    for i in 0..edge {
                        let ijk = [
                            usize::from(b[0]) * edge + i,
                            usize::from(b[1]) * edge + j,
                            usize::from(b[2]) * edge + k,
                        ];
                        let p =
                            lo + (DVec3::new(ijk[0] as f64, ijk[1] as f64, ijk[2] as f64) + 0.5) * fine_voxel;
                        values.push(sphere_ramp(centre, radius, fine_voxel, p));
                    }
                }
            }
        }
        FineDensity { factor, values }
    });
    through_file(&out)
}

#[test]
fn gpu_matches_cpu_for_fine_density() {
    // A sphere's ramp at the voxels and, 2× and 4× finer, in the fine density, over a head
    // with missing bricks (aprons and halo slots of both atlases matter): the GPU takes σ
    // from the fine lattice with the fine step, as the CPU reference does, in the fragment
    // and compute march, the per-pixel replay and the marked relight at a held camera, and
    // the storage-free march of WebGL2; the image without the fine density is far off.
    let mut gpu = renderer();
    let mut plain =
        GpuRenderer::from_device_without_storage(gpu.device().clone(), gpu.queue().clone()).unwrap();
    let env = sky(64, 32);
    let cam = camera(96, 80);
    let head = without_bricks(
        &asset_through_file(30_000, 6, CoefficientEncoding::U8Affine, 7),
        |b| (b[0] + 2 * b[1] + b[2]) % 4 == 0,
    );
    let coarse = with_fine_sphere(&head, None);
    let reference = |asset: &Asset, angle: f64, march: &MarchSettings| {
        render_asset(asset, &cam, &env, rotation_y(angle), None, march).unwrap()
    };
    for factor in [2u32, 4] {
        let asset = with_fine_sphere(&head, Some(factor));
        let info = gpu.load_asset(&asset).unwrap();
        assert_eq!(
            (info.fine_density, info.fine_density_ignored),
            (Some(factor), None)
        );
        assert!(info.memory.fine_density_bytes > 0);
        gpu.set_lighting(&env, rotation_y(0.7)).unwrap();
        for step_voxels in [0.5f32, 1.3] {
            let march = MarchSettings {
                step_voxels,
                ..MarchSettings::default()
            };
            let settings = ViewSettings { march, ..no_jitter() };
            let got = gpu.render(&cam, &settings).unwrap();
            let compute = ViewSettings {
                pass: MarchPass::Compute,
                ..settings
            };
            assert_eq!(
                gpu.render(&cam, &compute).unwrap(),
                got,
                "F {factor}: compute pass"
            );
            let want = reference(&asset, 0.7, &march);
            let covered = want.alpha.iter().filter(|&&a| a > 0.5).count();
            assert!(covered > 500, "the sphere covers only {covered} pixels");
            let db = psnr(&want, &got);
            // The same asset without its fine density (the voxels' ramp, what a renderer
            // that ignored the section would draw).
            let without = psnr(&want, &reference(&coarse, 0.7, &march));
            eprintln!(
                "fine density F {factor}, step {step_voxels}: PSNR {db:.1} dB ({covered} pixels covered); \
                 without it {without:.1} dB"
            );
            assert!(db >= 45.0, "F {factor} step {step_voxels}: PSNR {db:.2} dB");
            assert!(
                without < 35.0,
                "F {factor} step {step_voxels}: the fine density changes too little ({without:.1} dB)"
            );
        }
        // Lighting changes at the held camera replay its pixels, then (without the cache)
        // relight the voxels its march read: both read σ from the fine lattice.
        for (budget, kind) in [
            (nelf_viewer::DEFAULT_REPLAY_BUDGET_BYTES, RelightKind::Replay),
            (0, RelightKind::Marked),
        ] {
            gpu.set_replay_budget_bytes(budget);
            gpu.load_asset(&asset).unwrap();
            gpu.set_lighting(&env, rotation_y(0.7)).unwrap();
            gpu.render(&cam, &no_jitter()).unwrap();
            for angle in [1.4, 2.6] {
                gpu.set_light_rotation(rotation_y(angle)).unwrap();
                let got = gpu.render(&cam, &no_jitter()).unwrap();
                let db = psnr(&reference(&asset, angle, &MarchSettings::default()), &got);
                eprintln!(
                    "F {factor}, {:?} at {angle} rad: PSNR {db:.1} dB",
                    gpu.last_relight()
                );
                assert!(db >= 45.0, "F {factor} {kind:?} at {angle} rad: PSNR {db:.2} dB");
            }
            assert_eq!(gpu.last_relight(), Some(kind), "F {factor}");
        }
        gpu.set_replay_budget_bytes(nelf_viewer::DEFAULT_REPLAY_BUDGET_BYTES);
        // WebGL2's march (no storage bindings, the relight on the CPU) reads it too.
        let info = plain.load_asset(&asset).unwrap();
        assert_eq!(info.fine_density, Some(factor));
        plain.set_lighting(&env, rotation_y(2.6)).unwrap();
        let got = plain.render(&cam, &no_jitter()).unwrap();
        let db = psnr(&reference(&asset, 2.6, &MarchSettings::default()), &got);
        assert!(db >= 45.0, "F {factor}, storage-free: PSNR {db:.2} dB");
    }
    // Without a fine density nothing of it is reported or allocated.
    let info = gpu.load_asset(&coarse).unwrap();
    assert_eq!((info.fine_density, info.fine_density_ignored), (None, None));
    assert_eq!(info.memory.fine_density_bytes, 0);
}

/// A renderer on a device whose 3D textures are at most `max_3d` texels a side.
fn renderer_with_3d_textures(max_3d: u32) -> GpuRenderer {
    pollster::block_on(async {
        let instance = wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
        let adapter = instance
            .request_adapter(&wgpu::RequestAdapterOptions::default())
            .await
            .unwrap();
        let limits = wgpu::Limits {
            max_texture_dimension_3d: max_3d,
            ..wgpu::Limits::default()
        };
        let (device, queue) = adapter
            .request_device(&wgpu::DeviceDescriptor {
                label: Some("small 3D textures"),
                required_limits: limits,
                ..Default::default()
            })
            .await
            .unwrap();
        GpuRenderer::from_device(device, queue).unwrap()
    })
}

#[test]
fn a_fine_density_whose_atlas_does_not_fit_is_left_out_and_said_so() {
    // On a device with 3D textures of 128 texels (WebGL2 under eframe allows 256) the fine
    // density atlas of this head's 64 slots fits at F = 2 (7 slots of 18 texels a side, of
    // which the layout's powers of two use 4 × 4 × 7) but not at F = 4 (3 slots of 34
    // texels: 2 × 2 × 3): there the renderer shows the voxels' density, pixel for pixel
    // the asset without the fine density, and says what it left out.
    let mut gpu = renderer_with_3d_textures(128);
    assert_eq!(gpu.device().limits().max_texture_dimension_3d, 128);
    let env = sky(32, 16);
    let cam = camera(96, 80);
    let head = asset_through_file(30_000, 5, CoefficientEncoding::U8Affine, 3);
    let coarse = with_fine_sphere(&head, None);
    gpu.load_asset(&coarse).unwrap();
    gpu.set_lighting(&env, rotation_y(0.3)).unwrap();
    let coarse_image = gpu.render(&cam, &no_jitter()).unwrap();
    let fine2 = with_fine_sphere(&head, Some(2));
    let info = gpu.load_asset(&fine2).unwrap();
    assert!(
        info.bricks + info.halo_slots > 2 * 2 * 3,
        "too few slots to overflow at F = 4"
    );
    assert_eq!((info.fine_density, info.fine_density_ignored), (Some(2), None));
    gpu.set_lighting(&env, rotation_y(0.3)).unwrap();
    let shown = gpu.render(&cam, &no_jitter()).unwrap();
    let want = render_asset(
        &fine2,
        &cam,
        &env,
        rotation_y(0.3),
        None,
        &MarchSettings::default(),
    )
    .unwrap();
    let db = psnr(&want, &shown);
    assert!(db >= 45.0, "F 2 on small textures: PSNR {db:.2} dB");
    let info = gpu.load_asset(&with_fine_sphere(&head, Some(4))).unwrap();
    assert_eq!((info.fine_density, info.fine_density_ignored), (None, Some(4)));
    assert_eq!(info.memory.fine_density_bytes, 0);
    gpu.set_lighting(&env, rotation_y(0.3)).unwrap();
    assert!(
        gpu.render(&cam, &no_jitter()).unwrap() == coarse_image,
        "F 4 left out: not the coarse image"
    );
}

/// Runs `f32_to_half` and `half_to_f32` (common.wgsl; the lobe buffer's conversions) on
/// the GPU over `values`: (half bits, the half back as f32) per value.
fn convert_halves_on_gpu(gpu: &GpuRenderer, values: &[f32]) -> Vec<(u16, f32)> {
    use wgpu::util::DeviceExt as _;
    let device = gpu.device();
    let source = nelf_viewer::shaders::preprocess(
        "halves.wgsl",
        "#import \"common.wgsl\"
@group(0) @binding(0) var<storage, read_write> data: array<u32>;
@compute @workgroup_size(64)
fn convert(@builtin(global_invocation_id) gid: vec3<u32>) {
    let n = arrayLength(&data) / 2u;
    if gid.x < n {
        let half = f32_to_half(bitcast<f32>(data[gid.x]));
        data[n + gid.x] = half;
        data[gid.x] = bitcast<u32>(half_of(half, 0u));
    }
}
",
    )
    .unwrap();
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some("halves.wgsl"),
        source: wgpu::ShaderSource::Wgsl(source.into()),
    });
    let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some("halves"),
        layout: None,
        module: &module,
        entry_point: Some("convert"),
        compilation_options: wgpu::PipelineCompilationOptions::default(),
        cache: None,
    });
    let mut words: Vec<u32> = values.iter().map(|v| v.to_bits()).collect();
    words.resize(2 * values.len(), 0);
    let size = (words.len() * 4) as u64;
    let data = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("halves"),
        contents: bytemuck::cast_slice(&words),
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
    });
    let readback = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("halves read-back"),
        size,
        usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
        mapped_at_creation: false,
    });
    let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("halves"),
        layout: &pipeline.get_bind_group_layout(0),
        entries: &[wgpu::BindGroupEntry {
            binding: 0,
            resource: data.as_entire_binding(),
        }],
    });
    let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor::default());
    {
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor::default());
        pass.set_pipeline(&pipeline);
        pass.set_bind_group(0, &bind_group, &[]);
        pass.dispatch_workgroups((values.len() as u32).div_ceil(64), 1, 1);
    }
    encoder.copy_buffer_to_buffer(&data, 0, &readback, 0, size);
    gpu.queue().submit([encoder.finish()]);
    readback.map_async(wgpu::MapMode::Read, .., |r| r.unwrap());
    device.poll(wgpu::PollType::wait_indefinitely()).unwrap();
    let out: Vec<u32> = bytemuck::cast_slice(&readback.get_mapped_range(..).unwrap()).to_vec();
    let n = values.len();
    (0..n)
        .map(|i| (out[n + i] as u16, f32::from_bits(out[i])))
        .collect()
}

#[test]
fn shader_half_conversions_round_to_nearest_even() {
    let gpu = renderer();
    // Every f16 value and the midpoints between neighbours (ties), just below and above
    // them, past the largest half, zeros and a spread of f32 bit patterns.
    let mut values = Vec::new();
    for bits in 0..=0x7bffu16 {
        let h = half::f16::from_bits(bits).to_f32();
        let next = half::f16::from_bits(bits + 1).to_f32();
        let mid = 0.5 * (h + next);
        for v in [
            h,
            mid,
            f32::from_bits(mid.to_bits() - 1),
            f32::from_bits(mid.to_bits() + 1),
        ] {
            values.extend([v, -v]);
        }
    }
    values.extend([65520.0, 1e6, f32::MAX, -0.0, 1e-30, 2.9e-8, 3.0e-8]);
    values.extend((0..20_000u32).map(|i| f32::from_bits(i.wrapping_mul(2_654_435_761) & 0x7fff_ffff)));
    values.retain(|v| v.is_finite());
    let got = convert_halves_on_gpu(&gpu, &values);
    for (v, (bits, back)) in values.iter().zip(got) {
        let want = half::f16::from_f32(*v);
        assert_eq!(bits, want.to_bits(), "f32_to_half({v:e})");
        if want.is_finite() {
            assert_eq!(back.to_bits(), want.to_f32().to_bits(), "half_to_f32 of {v:e}");
        }
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

#[test]
fn empty_space_costs_no_samples() {
    // The march grid skips every sample whose trilinear σ is 0: an asset with its bricks
    // but no density anywhere takes no sample at all, and each ray crosses the box in
    // a jump or two; with density, far fewer samples than lattice points are taken and
    // the image still equals the reference (gpu_matches_cpu_reference).
    let mut gpu = renderer();
    let env = sky(64, 32);
    let cam = camera(96, 80);
    let cost = ViewSettings {
        view: MarchView::Cost,
        pass: MarchPass::Compute,
        ..no_jitter()
    };
    let mut asset = asset_through_file(40_000, 8, CoefficientEncoding::U8Affine, 5);
    gpu.load_asset(&asset).unwrap();
    gpu.set_lighting(&env, rotation_y(0.7)).unwrap();
    let counts = gpu.render(&cam, &cost).unwrap();
    let total = |i: usize| counts.rgb.iter().map(|c| f64::from(c[i])).sum::<f64>();
    let (samples, steps, lattice) = (total(0), total(1), total(2));
    eprintln!("with density: {samples} samples in {steps} steps of {lattice} lattice samples");
    assert!(samples > 0.0);
    assert!(samples <= steps && steps <= lattice);
    assert!(samples < 0.5 * lattice, "{samples} samples of {lattice}");

    for d in &mut asset.density {
        *d = half::f16::ZERO;
    }
    gpu.load_asset(&asset).unwrap();
    let counts = gpu.render(&cam, &cost).unwrap();
    let entering = counts.rgb.iter().filter(|c| c[2] > 0.0).count();
    assert!(entering > 1000, "{entering} rays enter the grid box");
    for c in &counts.rgb {
        assert_eq!(c[0], 0.0, "a sample was taken in empty space");
        assert!(c[1] <= 2.0, "{} steps through empty space", c[1]);
    }
    let image = gpu.render(&cam, &no_jitter()).unwrap();
    assert!(image.rgb.iter().flatten().all(|&v| v == 0.0));
}

#[test]
fn the_march_pass_follows_the_device() {
    // Measured: fragment on a CPU device (lavapipe), compute on a GPU.
    assert_eq!(MarchPass::for_device(wgpu::DeviceType::Cpu), MarchPass::Fragment);
    for gpu_type in [
        wgpu::DeviceType::DiscreteGpu,
        wgpu::DeviceType::IntegratedGpu,
        wgpu::DeviceType::VirtualGpu,
    ] {
        assert_eq!(MarchPass::for_device(gpu_type), MarchPass::Compute);
    }
    let gpu = renderer();
    let info = gpu.adapter_info().unwrap().clone();
    assert_eq!(
        gpu.preferred_march_pass(),
        MarchPass::for_device(info.device_type)
    );
}

#[test]
fn a_held_camera_relights_only_what_it_reads() {
    // An asset with holes (aprons next to missing bricks matter) and a held camera whose
    // frame does not fit the per-pixel cache (budget 0): the first lighting change there
    // relights in full and marks the voxels the camera reads, the next ones relight only
    // those, and the image is bit for bit a fresh renderer's (full relight) and matches
    // the CPU reference; moving the camera then relights in full, and reading the atlas
    // back gives the fully relit atlas.
    let asset = without_bricks(
        &asset_through_file(40_000, 8, CoefficientEncoding::U8Affine, 5),
        |b| (b[0] + b[1] + 2 * b[2]) % 3 == 0,
    );
    let env = sky(64, 32);
    let cam = camera(96, 80);
    let moved = moved_camera();
    let fresh = |camera: &PinholeCamera, angle: f64| {
        let mut gpu = renderer();
        gpu.load_asset(&asset).unwrap();
        gpu.set_lighting(&env, rotation_y(angle)).unwrap();
        let image = gpu.render(camera, &no_jitter()).unwrap();
        assert_eq!(gpu.last_relight(), Some(RelightKind::Full));
        (image, gpu.read_atlas().unwrap())
    };
    let mut gpu = renderer();
    gpu.set_replay_budget_bytes(0);
    gpu.load_asset(&asset).unwrap();
    gpu.set_lighting(&env, rotation_y(0.7)).unwrap();
    gpu.render(&cam, &no_jitter()).unwrap();
    assert_eq!(gpu.last_relight(), Some(RelightKind::Full));
    gpu.set_light_rotation(rotation_y(1.2)).unwrap();
    let got = gpu.render(&cam, &no_jitter()).unwrap();
    assert_eq!(
        gpu.last_relight(),
        Some(RelightKind::Full),
        "the first change at a held camera"
    );
    assert_eq!(got, fresh(&cam, 1.2).0);
    for angle in [1.9, 3.4] {
        gpu.set_light_rotation(rotation_y(angle)).unwrap();
        let got = gpu.render(&cam, &no_jitter()).unwrap();
        assert_eq!(gpu.last_relight(), Some(RelightKind::Marked));
        assert_eq!(got, fresh(&cam, angle).0, "marked relight at {angle} rad");
        let want = render_asset(
            &asset,
            &cam,
            &env,
            rotation_y(angle),
            None,
            &MarchSettings::default(),
        )
        .unwrap();
        let db = psnr(&want, &got);
        assert!(db >= 45.0, "marked relight at {angle} rad: PSNR {db:.2} dB");
    }
    // Another jitter seed reads other voxels: a full relight; a held seed is marked like
    // a held camera.
    gpu.set_light_rotation(rotation_y(3.0)).unwrap();
    let jittered = ViewSettings {
        jitter: true,
        frame_index: 7,
        ..no_jitter()
    };
    gpu.render(&cam, &jittered).unwrap();
    assert_eq!(gpu.last_relight(), Some(RelightKind::Full));
    gpu.set_light_rotation(rotation_y(3.1)).unwrap();
    gpu.render(&cam, &jittered).unwrap();
    assert_eq!(gpu.last_relight(), Some(RelightKind::Full));
    gpu.set_light_rotation(rotation_y(3.2)).unwrap();
    let got = gpu.render(&cam, &jittered).unwrap();
    assert_eq!(gpu.last_relight(), Some(RelightKind::Marked));
    let mut other = renderer();
    other.load_asset(&asset).unwrap();
    other.set_lighting(&env, rotation_y(3.2)).unwrap();
    assert_eq!(got, other.render(&cam, &jittered).unwrap());
    // Back without jitter: the marks are the jittered frame's, so a full relight (the
    // atlas was stale), then marking again at the first change.
    gpu.render(&cam, &no_jitter()).unwrap();
    assert_eq!(gpu.last_relight(), Some(RelightKind::Full));
    gpu.set_light_rotation(rotation_y(3.3)).unwrap();
    gpu.render(&cam, &no_jitter()).unwrap();
    assert_eq!(gpu.last_relight(), Some(RelightKind::Full));
    gpu.set_light_rotation(rotation_y(3.4)).unwrap();
    gpu.render(&cam, &no_jitter()).unwrap();
    assert_eq!(gpu.last_relight(), Some(RelightKind::Marked));
    // The atlas was left stale elsewhere: a new camera relights everything.
    let got = gpu.render(&moved, &no_jitter()).unwrap();
    assert_eq!(gpu.last_relight(), Some(RelightKind::Full));
    let (want, want_atlas) = fresh(&moved, 3.4);
    assert_eq!(got, want);
    gpu.set_light_rotation(rotation_y(1.0)).unwrap();
    gpu.render(&moved, &no_jitter()).unwrap();
    assert_eq!(
        gpu.last_relight(),
        Some(RelightKind::Full),
        "the moved camera is marked now"
    );
    gpu.set_light_rotation(rotation_y(3.4)).unwrap();
    gpu.render(&moved, &no_jitter()).unwrap();
    assert_eq!(gpu.last_relight(), Some(RelightKind::Marked));
    assert_eq!(gpu.read_atlas().unwrap(), want_atlas);
}

#[test]
fn a_held_camera_replays_its_pixels_under_new_lighting() {
    // At a held camera whose frame fits the per-pixel cache, lighting changes are a dot
    // product per pixel (replay.wgsl), no march: the image must be a fresh renderer's (full
    // relight + march) to rounding and the CPU reference's, with brick holes, 8-bit and
    // f16 coefficients, a rank over 64 (two build dispatches), a truncated rank, a jitter
    // seed and both passes; moving the camera relights the atlas in full again.
    let holed = |asset: &Asset| without_bricks(asset, |b| (b[0] + 2 * b[1] + b[2]) % 4 == 0);
    let cases = [
        (
            holed(&asset_through_file(30_000, 8, CoefficientEncoding::U8Affine, 11)),
            MarchPass::Fragment,
        ),
        (
            holed(&asset_through_file(30_000, 70, CoefficientEncoding::F16, 12)),
            MarchPass::Compute,
        ),
        (
            asset_through_file(20_000, 67, CoefficientEncoding::U8Affine, 13),
            MarchPass::Fragment,
        ),
    ];
    let env = sky(64, 32);
    let cam = camera(96, 80);
    let moved = moved_camera();
    for (case, (asset, pass)) in cases.iter().enumerate() {
        let settings = ViewSettings {
            pass: *pass,
            ..no_jitter()
        };
        let jittered = ViewSettings {
            jitter: true,
            frame_index: 5,
            ..settings
        };
        let fresh = |camera: &PinholeCamera, settings: &ViewSettings, angle: f64, rank: Option<usize>| {
            let mut gpu = renderer();
            gpu.load_asset(asset).unwrap();
            gpu.set_rank(rank);
            gpu.set_lighting(&env, rotation_y(angle)).unwrap();
            let image = gpu.render(camera, settings).unwrap();
            assert_eq!(gpu.last_relight(), Some(RelightKind::Full));
            image
        };
        let mut gpu = renderer();
        gpu.load_asset(asset).unwrap();
        gpu.set_lighting(&env, rotation_y(0.7)).unwrap();
        gpu.render(&cam, &settings).unwrap();
        assert_eq!(gpu.last_relight(), Some(RelightKind::Full));
        for (step, (angle, rank, view)) in [
            (1.2, None, &settings),
            (2.3, None, &settings),
            (2.9, Some(5), &settings),
            (4.0, None, &jittered),
            (4.4, None, &jittered),
        ]
        .into_iter()
        .enumerate()
        {
            gpu.set_rank(rank);
            gpu.set_light_rotation(rotation_y(angle)).unwrap();
            let got = gpu.render(&cam, view).unwrap();
            // The jittered frames: the first at a new seed is a march, then replays.
            let want_kind = if step == 3 {
                RelightKind::Full
            } else {
                RelightKind::Replay
            };
            assert_eq!(gpu.last_relight(), Some(want_kind), "case {case}, {angle} rad");
            let want = fresh(&cam, view, angle, rank);
            assert_eq!(got.alpha, want.alpha, "case {case}, {angle} rad: alpha");
            let db = psnr(&want, &got);
            assert!(
                db >= 70.0,
                "case {case}, {angle} rad: replay vs march PSNR {db:.2} dB"
            );
            if !view.jitter {
                let march = MarchSettings::default();
                let reference = render_asset(asset, &cam, &env, rotation_y(angle), rank, &march).unwrap();
                let db = psnr(&reference, &got);
                assert!(
                    db >= 45.0,
                    "case {case}, {angle} rad: replay vs CPU PSNR {db:.2} dB"
                );
            }
        }
        assert!(gpu.replay_bytes() > 0);
        // The atlas was left stale: a new camera relights it in full and marches.
        gpu.set_rank(None);
        let got = gpu.render(&moved, &settings).unwrap();
        assert_eq!(gpu.last_relight(), Some(RelightKind::Full));
        assert_eq!(
            got,
            fresh(&moved, &settings, 4.4, None),
            "case {case}: moved camera"
        );
    }
}

#[test]
fn the_storage_free_path_of_webgl2_draws_the_same_atlas_and_image() {
    // WebGL2 has no compute shaders and no storage bindings: there the renderer relights
    // on the CPU (atlas::relight_atlas_cpu, uploaded) and marches with
    // march_nostorage.wgsl. Run on this device beside the compute path, it must give the
    // same atlas (to f16 rounding) and the same image, with holes in the brick set, f16
    // coefficients, a truncated rank and the component view, and after a rotation.
    let mut gpu = renderer();
    let mut plain =
        GpuRenderer::from_device_without_storage(gpu.device().clone(), gpu.queue().clone()).unwrap();
    assert!(gpu.uses_storage() && !plain.uses_storage());
    let env = sky(64, 32);
    let cam = camera(96, 80);
    for (encoding, rank, truncate, holes, view) in [
        (CoefficientEncoding::U8Affine, 8, None, true, RelightView::Shaded),
        (CoefficientEncoding::F16, 6, Some(3), false, RelightView::Shaded),
        (
            CoefficientEncoding::U8Affine,
            8,
            None,
            false,
            RelightView::Component(2),
        ),
    ] {
        let mut asset = asset_through_file(30_000, rank, encoding, 9);
        if holes {
            asset = without_bricks(&asset, |b| (b[0] + 2 * b[1] + b[2]) % 3 == 0);
        }
        for turn in [0.4, -1.1] {
            for r in [&mut gpu, &mut plain] {
                r.load_asset(&asset).unwrap();
                r.set_lighting(&env, rotation_y(turn)).unwrap();
                r.set_rank(truncate);
                r.set_relight_view(view);
            }
            let want = gpu.render(&cam, &no_jitter()).unwrap();
            let got = plain.render(&cam, &no_jitter()).unwrap();
            let (want_atlas, got_atlas) = (gpu.read_atlas().unwrap(), plain.read_atlas().unwrap());
            assert_eq!(want_atlas.len(), got_atlas.len());
            let worst = want_atlas
                .iter()
                .zip(&got_atlas)
                .flat_map(|(a, b)| (0..4).map(move |c| (a[c] - b[c]).abs() / a[c].abs().max(1e-3)))
                .fold(0.0f32, f32::max);
            let db = psnr(&want, &got);
            eprintln!(
                "{encoding:?} {view:?} holes {holes} turn {turn}: atlas within {worst:.1e}, image {db:.1} dB"
            );
            assert!(
                worst <= 2e-3,
                "{encoding:?} {view:?}: CPU relight differs by {worst} (relative)"
            );
            assert!(
                db >= 60.0,
                "{encoding:?} {view:?}: storage-free image {db:.1} dB from the compute path's"
            );
        }
    }
    // Without compute the view-dependent parts are left out, said so, and what is shown is
    // the view-averaged asset, pixel for pixel the same asset without those parts.
    let base = asset_through_file(20_000, 6, CoefficientEncoding::U8Affine, 4);
    plain.load_asset(&base).unwrap();
    plain.set_lighting(&env, rotation_y(0.4)).unwrap();
    let averaged = plain.render(&cam, &no_jitter()).unwrap();
    let view_asset = with_view(&base, CoefficientEncoding::U8Affine, 4);
    let mut reflection_asset = base.clone();
    reflection_asset.reflection = Some(synthetic_reflection(&base, 20.0, 4).unwrap());
    for (asset, part) in [
        (&view_asset, "view-dependent part (format 1.2)"),
        (&reflection_asset, "reflection part (format 1.3)"),
    ] {
        let info = plain.load_asset(asset).unwrap();
        assert_eq!(info.view_part_ignored, Some(part));
        assert!(info.view.is_none() && info.reflection.is_none());
        plain.set_lighting(&env, rotation_y(0.4)).unwrap();
        let shown = plain.render(&cam, &no_jitter()).unwrap();
        assert!(
            shown == averaged,
            "{part}: WebGL2 shows other pixels than the view-averaged asset"
        );
        // With compute nothing is left out.
        let info = gpu.load_asset(asset).unwrap();
        assert_eq!(info.view_part_ignored, None);
        assert!(info.view.is_some() || info.reflection.is_some());
    }
}
