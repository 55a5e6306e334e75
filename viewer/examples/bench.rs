//! Frame-time benchmark of the GPU renderer (a benchmark, not a test; docs/PLATFORM.md: on a
//! machine without a GPU this is Mesa's lavapipe, so figures are CPU-bound and noisy —
//! compare ratios taken in one run).
//!
//! ```text
//! cargo run --release -p nelf-viewer --example bench -- [ASSET.nelf ...] [--reps N] [--view] [--reflect] [--fine F]
//! ```
//!
//! Without assets it builds a synthetic portrait-sized asset (`nelf_format::synthetic`,
//! ≈ 300 k voxels, K = 12, 8-bit coefficients). `--view` gives every asset without one a
//! synthetic view-dependent part (format 1.2: J = 3 lobes, `K_v` = 8, 8-bit coefficients;
//! `nelf_format::synthetic::synthetic_view`); `--reflect` gives every asset with neither
//! part a synthetic reflection part (format 1.3, λ = 20, five eyes;
//! `nelf_format::synthetic::synthetic_reflection`); `--fine F` gives every asset without
//! one a fine density of factor `F` (format 1.4: its voxels' density interpolated at the
//! fine voxel centres, a stand-in with the asset's own occupancy); an asset file may
//! bring any of these parts itself. For each asset it prints, as markdown:
//! GPU memory, relight-pass ms, frame ms at 512² and 1920×1080 with relighting every
//! frame and without (the march alone over the precomputed RGBA atlas) and their ratio
//! (at a held camera: the frame relit per pixel from its cache where it fits the cache,
//! `gpu/replay.rs`, else the voxels it reads relit and marched; and the latter alone, with
//! the cache off; the first lighting change there, which builds the cache or marks the
//! voxels, is timed below the table),
//! jitter on and off, trilinear samples per frame and per second, and — as the ceiling
//! of a texture march on this device — the bare dense march of docs/PLATFORM.md (128³
//! RGBA16F, 512² rays × 128 steps, every ray taking all its steps) measured in the same
//! run ("of dense": samples taken per second against that ceiling; since the march grid
//! skips every sample whose σ is 0 — 96 % of them on a head — a faster march takes
//! fewer samples and this ratio falls: compare frame ms, and see the samples and loop
//! steps per ray in the notes below the table); plus how close the GPU image is to the
//! CPU reference (PSNR at 256²) and the CPU
//! reference's own time for that frame. For a view-dependent asset also frame ms at 512²
//! and 1080p with the camera static (the march alone) and moving every frame (view pass +
//! march), beside the same asset without its view part, as ratios, and the view pass's
//! own ms. For a reflection asset, at 512², frame ms beside the same asset without its
//! reflection part: static, moving, relit every frame (camera held; camera moving too)
//! and with the lighting turned every frame (the CPU's projection and, with the part,
//! its lobe filter included), and the reflect pass's own ms. For an asset with a fine
//! density, frame ms at 512² and 1080p beside the same asset without it (the march alone,
//! a full relight and march, and the march's samples per frame).

use std::path::PathBuf;
use std::time::Instant;

use glam::{DMat3, DVec3};
use nelf_format::conventions::{LatLong, PinholeCamera, direction, rotation_y};
use nelf_format::synthetic::SyntheticField;
use nelf_format::synthetic::{synthetic_reflection, synthetic_view};
use nelf_format::{Asset, CoefficientEncoding, FineDensity, WriteOptions, read_asset, write_asset};
use nelf_render::{BrickGrid, Image, MarchSettings, asset_density, render_asset};
use nelf_viewer::shaders::{DENSE_MARCH_WGSL, DenseParams, preprocess};
use nelf_viewer::{GpuRenderer, MarchPass, MarchView, ViewSettings};
use wgpu::util::DeviceExt as _;

type BoxError = Box<dyn std::error::Error>;

/// Wall-clock timings of a blocking GPU job, milliseconds.
#[derive(Debug, Clone, Copy)]
struct Timing {
    /// Fastest run: on a shared machine contention only adds time, so this is the
    /// closest to the device's own speed.
    min: f64,
    /// Median run.
    median: f64,
}

impl std::fmt::Display for Timing {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{:.1} (median {:.1})", self.min, self.median)
    }
}

/// Times `f` `reps` times after two warm-up calls.
fn time_ms(reps: usize, mut f: impl FnMut() -> Result<(), BoxError>) -> Result<Timing, BoxError> {
    for _ in 0..2 {
        f()?;
    }
    let mut times: Vec<f64> = Vec::with_capacity(reps.max(1));
    for _ in 0..reps.max(1) {
        let start = Instant::now();
        f()?;
        times.push(start.elapsed().as_secs_f64() * 1e3);
    }
    times.sort_by(f64::total_cmp);
    Ok(Timing {
        min: times[0],
        median: times[times.len() / 2],
    })
}

/// A sky with a warm key light from the front right and a cool fill, 64 × 32.
fn sky() -> Result<LatLong, BoxError> {
    let key = DVec3::new(0.5, 0.45, 0.74).normalize();
    let mut texels = Vec::with_capacity(64 * 32);
    for row in 0..32 {
        for col in 0..64 {
            let theta = (f64::from(row) + 0.5) / 32.0 * std::f64::consts::PI;
            let phi = (f64::from(col) + 0.5) / 64.0 * std::f64::consts::TAU - std::f64::consts::PI;
            let d = direction(theta, phi);
            let spot = (6.0 * (d.dot(key) - 1.0)).exp();
            let up = 0.5 + 0.5 * d.y;
            texels.push([
                (0.2 + 0.3 * up + 5.0 * spot) as f32,
                (0.25 + 0.3 * up + 4.0 * spot) as f32,
                (0.35 + 0.35 * up + 3.0 * spot) as f32,
            ]);
        }
    }
    Ok(LatLong::new(64, 32, texels)?)
}

/// A portrait framing: the asset's box seen from the front (+z), slightly from the
/// right and above, with its bounding sphere filling the narrower field of view.
fn portrait_camera(asset: &Asset, width: u32, height: u32) -> PinholeCamera {
    orbit_camera(asset, width, height, 20.0)
}

/// [`portrait_camera`] from azimuth `azimuth_deg` (20° is the portrait's).
fn orbit_camera(asset: &Asset, width: u32, height: u32, azimuth_deg: f64) -> PinholeCamera {
    let lo = DVec3::from_array(asset.grid.bbox_min_m);
    let hi = DVec3::from_array(asset.grid.bbox_max_m());
    let centre = 0.5 * (lo + hi);
    let fov_x = 30f64.to_radians();
    let fov_y = 2.0 * ((0.5 * fov_x).tan() * f64::from(height) / f64::from(width)).atan();
    let distance = 0.5 * (hi - lo).length() / (0.5 * fov_x.min(fov_y)).sin();
    let (az, el) = (azimuth_deg.to_radians(), 10f64.to_radians());
    let eye = centre + distance * DVec3::new(el.cos() * az.sin(), el.sin(), el.cos() * az.cos());
    PinholeCamera::look_at(eye, centre, DVec3::Y, width, height, fov_x)
}

fn psnr(reference: &Image, test: &Image) -> f64 {
    let peak = reference.rgb.iter().flatten().fold(0.0f32, |m, &v| m.max(v));
    let mut sum = 0.0f64;
    for (a, b) in reference.rgb.iter().zip(&test.rgb) {
        for c in 0..3 {
            sum += (f64::from(a[c]) - f64::from(b[c])).powi(2);
        }
    }
    let mse = sum / (3 * reference.rgb.len()) as f64;
    10.0 * (f64::from(peak).powi(2) / mse.max(1e-30)).log10()
}

/// The bare dense march of docs/PLATFORM.md on `gpu`'s device: ms per frame and samples.
fn dense_baseline(gpu: &GpuRenderer, reps: usize) -> Result<(Timing, u64), BoxError> {
    let device = gpu.device();
    let queue = gpu.queue();
    let (size, steps, n) = (512u32, 128u32, 128u32);
    // A smooth, partly transparent volume (values do not matter to the speed).
    let mut texels = Vec::with_capacity((n * n * n * 4) as usize);
    for z in 0..n {
        for y in 0..n {
            for x in 0..n {
                let v = ((x ^ y ^ z) & 15) as f32 / 15.0;
                for c in [v, 1.0 - v, 0.5, 2.0 * v] {
                    texels.push(half::f16::from_f32(c));
                }
            }
        }
    }
    let volume = device.create_texture_with_data(
        queue,
        &wgpu::TextureDescriptor {
            label: Some("dense volume"),
            size: wgpu::Extent3d {
                width: n,
                height: n,
                depth_or_array_layers: n,
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D3,
            format: wgpu::TextureFormat::Rgba16Float,
            usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
            view_formats: &[],
        },
        wgpu::util::TextureDataOrder::LayerMajor,
        bytemuck::cast_slice(&texels),
    );
    let output = device.create_texture(&wgpu::TextureDescriptor {
        label: Some("dense output"),
        size: wgpu::Extent3d {
            width: size,
            height: size,
            depth_or_array_layers: 1,
        },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format: wgpu::TextureFormat::Rgba32Float,
        usage: wgpu::TextureUsages::STORAGE_BINDING,
        view_formats: &[],
    });
    let params = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("dense params"),
        contents: bytemuck::bytes_of(&DenseParams {
            image: [size, size, steps, 0],
        }),
        usage: wgpu::BufferUsages::UNIFORM,
    });
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some("dense_march.wgsl"),
        source: wgpu::ShaderSource::Wgsl(preprocess("dense_march.wgsl", DENSE_MARCH_WGSL)?.into()),
    });
    let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some("dense march"),
        layout: None,
        module: &module,
        entry_point: Some("dense_march"),
        compilation_options: wgpu::PipelineCompilationOptions::default(),
        cache: None,
    });
    let sampler = device.create_sampler(&wgpu::SamplerDescriptor {
        mag_filter: wgpu::FilterMode::Linear,
        min_filter: wgpu::FilterMode::Linear,
        ..Default::default()
    });
    let volume_view = volume.create_view(&wgpu::TextureViewDescriptor::default());
    let output_view = output.create_view(&wgpu::TextureViewDescriptor::default());
    let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("dense"),
        layout: &pipeline.get_bind_group_layout(0),
        entries: &[
            wgpu::BindGroupEntry {
                binding: 0,
                resource: params.as_entire_binding(),
            },
            wgpu::BindGroupEntry {
                binding: 1,
                resource: wgpu::BindingResource::TextureView(&volume_view),
            },
            wgpu::BindGroupEntry {
                binding: 2,
                resource: wgpu::BindingResource::Sampler(&sampler),
            },
            wgpu::BindGroupEntry {
                binding: 3,
                resource: wgpu::BindingResource::TextureView(&output_view),
            },
        ],
    });
    let timing = time_ms(reps, || {
        let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor::default());
        {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor::default());
            pass.set_pipeline(&pipeline);
            pass.set_bind_group(0, &bind_group, &[]);
            pass.dispatch_workgroups(size.div_ceil(8), size.div_ceil(8), 1);
        }
        queue.submit([encoder.finish()]);
        device.poll(wgpu::PollType::wait_indefinitely())?;
        Ok(())
    })?;
    Ok((timing, u64::from(size) * u64::from(size) * u64::from(steps)))
}

/// Interleaved timings of `jobs` blocking GPU jobs (`run(i)` runs job `i`): each job runs
/// twice to warm up, then the jobs take turns `reps` times, so that a change in the
/// machine's load (it is shared) weighs on all of them alike.
fn time_interleaved(
    reps: usize,
    jobs: usize,
    mut run: impl FnMut(usize) -> Result<(), BoxError>,
) -> Result<Vec<Timing>, BoxError> {
    for job in 0..jobs {
        run(job)?;
        run(job)?;
    }
    let mut times = vec![Vec::with_capacity(reps.max(1)); jobs];
    for _ in 0..reps.max(1) {
        for (job, t) in times.iter_mut().enumerate() {
            let start = Instant::now();
            run(job)?;
            t.push(start.elapsed().as_secs_f64() * 1e3);
        }
    }
    Ok(times
        .into_iter()
        .map(|mut t| {
            t.sort_by(f64::total_cmp);
            Timing {
                min: t[0],
                median: t[t.len() / 2],
            }
        })
        .collect())
}

/// A view-dependent asset against itself without its view part: frame ms at 512² and
/// 1080p with the camera static (march only) and moving every frame (a new eye, so view
/// pass and march for the view-dependent asset), their ratios, and the view pass alone.
/// The five measurements are interleaved, on three renderers (the view-independent
/// asset; the view-dependent one with a static camera; the same moving), so that no
/// measurement disturbs another's state.
fn bench_view_dependence(gpu: &mut GpuRenderer, asset: &Asset, reps: usize) -> Result<(), BoxError> {
    let Some(view) = &asset.view else {
        return Ok(());
    };
    let mut flat = asset.clone();
    flat.view = None;
    let env = sky()?;
    let mut flat_gpu = GpuRenderer::new_headless()?;
    flat_gpu.load_asset(&flat)?;
    flat_gpu.set_lighting(&env, DMat3::IDENTITY)?;
    let mut static_gpu = GpuRenderer::new_headless()?;
    static_gpu.load_asset(asset)?;
    static_gpu.set_lighting(&env, DMat3::IDENTITY)?;
    gpu.load_asset(asset)?;
    gpu.set_lighting(&env, DMat3::IDENTITY)?;
    let settings = ViewSettings {
        march: MarchSettings::default(),
        jitter: false,
        frame_index: 0,
        view: MarchView::Shaded,
        pass: MarchPass::Fragment,
    };
    println!(
        "\nView dependence (J = {} lobes, K_v = {}, {:?} coefficients): frame ms (fragment march) of \
         the asset against itself without its view part, the five measurements interleaved; moving = \
         a new eye every frame (0.25° of orbit); ratio = view-dependent / view-independent (fastest runs)\n",
        view.lobe_count(),
        view.rank(),
        view.coefficients.encoding()
    );
    println!(
        "| frame | view-independent, static (ms) | view-dependent, static (ms) | ratio | view-independent, moving (ms) | view-dependent, moving (ms) | ratio | view pass alone (ms) |"
    );
    println!("| --- | --- | --- | --- | --- | --- | --- | --- |");
    for (w, h) in [(512u32, 512u32), (1920, 1080)] {
        let camera = portrait_camera(asset, w, h);
        let mut frame = 0u32;
        let times = time_interleaved(reps, 5, |job| {
            frame += 1;
            let moving = orbit_camera(asset, w, h, 20.0 + 0.25 * f64::from(frame % 40));
            match job {
                0 => flat_gpu.frame_blocking(&camera, &settings)?,
                1 => static_gpu.frame_blocking(&camera, &settings)?,
                2 => flat_gpu.frame_blocking(&moving, &settings)?,
                3 => gpu.frame_blocking(&moving, &settings)?,
                _ => gpu.view_pass_blocking(&moving)?,
            }
            Ok(())
        })?;
        let [flat_fixed, fixed, flat_moving, moving, view_pass] =
            [times[0], times[1], times[2], times[3], times[4]];
        println!(
            "| {w}×{h} | {flat_fixed} | {fixed} | {:.2} | {flat_moving} | {moving} | {:.2} | {view_pass} |",
            fixed.min / flat_fixed.min,
            moving.min / flat_moving.min
        );
    }
    Ok(())
}

/// A reflection asset against itself without its reflection part, at 512²: frame ms with
/// the camera static (the march alone), moving every frame (a new eye: reflect pass +
/// march with the part), relit every frame at a held camera (without the part the viewer
/// replays the held frame's pixels, `gpu/replay.rs`; with it, relight + `reflect_mean` +
/// reflect pass + march), relit every frame with the camera moving too (a full relight
/// and march either way) and with the lighting turned every frame at a held camera (the
/// CPU's projection, with the part also its lobe filter, plus the GPU's work), and the
/// reflect pass alone. The eleven measurements are interleaved, each on its own renderer,
/// so that no measurement disturbs another's state.
fn bench_reflection(asset: &Asset, reps: usize) -> Result<(), BoxError> {
    // Jobs 2k without the part, 2k + 1 with it; job 10 the reflect pass alone.
    const ROWS: [&str; 5] = [
        "static (march)",
        "moving (new eye every frame)",
        "relit every frame, camera held",
        "relit every frame, camera moving",
        "lighting turned every frame, camera held (CPU projection + GPU)",
    ];
    let Some(reflection) = &asset.reflection else {
        return Ok(());
    };
    let mut flat = asset.clone();
    flat.reflection = None;
    let env = sky()?;
    let (w, h) = (512u32, 512u32);
    let camera = portrait_camera(asset, w, h);
    let settings = ViewSettings {
        march: MarchSettings::default(),
        jitter: false,
        frame_index: 0,
        view: MarchView::Shaded,
        pass: MarchPass::Fragment,
    };
    let mut renderers = Vec::with_capacity(2 * ROWS.len() + 1);
    for job in 0..=2 * ROWS.len() {
        let mut gpu = GpuRenderer::new_headless()?;
        gpu.load_asset(if job % 2 == 0 && job < 2 * ROWS.len() {
            &flat
        } else {
            asset
        })?;
        gpu.set_lighting(&env, DMat3::IDENTITY)?;
        renderers.push(gpu);
    }
    let mut frame = 0u32;
    let mut angle = 0.0f64;
    let times = time_interleaved(reps, renderers.len(), |job| {
        frame += 1;
        let moving = orbit_camera(asset, w, h, 20.0 + 0.25 * f64::from(frame % 40));
        let gpu = &mut renderers[job];
        match job / 2 {
            0 => gpu.frame_blocking(&camera, &settings)?,
            1 => gpu.frame_blocking(&moving, &settings)?,
            2 => {
                gpu.invalidate_lighting();
                gpu.frame_blocking(&camera, &settings)?;
            }
            3 => {
                gpu.invalidate_lighting();
                gpu.frame_blocking(&moving, &settings)?;
            }
            4 => {
                angle += 0.1;
                gpu.set_light_rotation(rotation_y(angle))?;
                gpu.frame_blocking(&camera, &settings)?;
            }
            _ => gpu.view_pass_blocking(&moving)?,
        }
        Ok(())
    })?;
    println!(
        "\nReflection part (λ = {}, {} eyes): frame ms (fragment march) at {w}×{h} of the asset against \
         itself without its reflection part, the {} measurements interleaved, each on its own renderer; \
         ratio = with / without (fastest runs)\n",
        reflection.exponent,
        reflection.eyes_m.len(),
        times.len()
    );
    println!("| 512² frame | without the part (ms) | with the part (ms) | ratio |");
    println!("| --- | --- | --- | --- |");
    for (row, what) in ROWS.iter().enumerate() {
        let (without, with) = (times[2 * row], times[2 * row + 1]);
        println!("| {what} | {without} | {with} | {:.2} |", with.min / without.min);
    }
    println!("| reflect pass alone | — | {} | — |", times[2 * ROWS.len()]);
    Ok(())
}

fn bench_asset(gpu: &mut GpuRenderer, name: &str, asset: &Asset, reps: usize) -> Result<(), BoxError> {
    let mut notes = Vec::new();
    let start = Instant::now();
    let info = gpu.load_asset(asset)?;
    let upload_ms = start.elapsed().as_secs_f64() * 1e3;
    let env = sky()?;
    gpu.set_lighting(&env, DMat3::IDENTITY)?;
    let m = info.memory;
    println!("\n### {name}\n");
    println!(
        "{} bricks + {} halo slots, {} voxels, K = {}, {}, atlas {}×{}×{} texels; upload {upload_ms:.0} ms",
        info.bricks,
        info.halo_slots,
        info.bricks * 512,
        info.rank,
        match (info.view, info.reflection) {
            (Some(v), _) => format!("view-dependent (J = {}, K_v = {})", v.lobes, v.rank),
            (None, Some(r)) => format!("reflection part (λ = {}, {} eyes)", r.exponent, r.eyes),
            (None, None) => "view-independent".to_string(),
        },
        info.atlas_texels[0],
        info.atlas_texels[1],
        info.atlas_texels[2]
    );
    let mib = |b: u64| b as f64 / (1024.0 * 1024.0);
    println!(
        "GPU memory: {:.2} MiB total = atlas {:.2} + fine density {:.2} + coefficients {:.2} + density {:.2} + view part {:.2} + neighbour blocks {:.3} + march grid {:.3} + other {:.3}\n",
        mib(m.total()),
        mib(m.atlas_bytes),
        mib(m.fine_density_bytes),
        mib(m.coefficient_bytes),
        mib(m.density_bytes),
        mib(m.view_bytes),
        mib(m.neighbour_bytes),
        mib(m.march_grid_bytes),
        mib(m.other_bytes)
    );
    for used in [0usize, 1, 4, 12, 32, 64] {
        if used > info.rank {
            break;
        }
        gpu.set_rank(Some(used));
        let t = time_ms(reps, || Ok(gpu.relight_blocking()?))?;
        eprintln!("relight pass with rank {used}: {t} ms");
    }
    gpu.set_rank(None);
    let relight = time_ms(reps, || Ok(gpu.relight_blocking()?))?;
    println!("relight pass (K = {}): {relight} ms", info.rank);
    // A relight after a rotation: the projection on the CPU plus the pass.
    let mut angle = 0.0;
    let rotate = time_ms(reps, || {
        angle += 0.1;
        gpu.set_light_rotation(rotation_y(angle))?;
        Ok(gpu.relight_blocking()?)
    })?;
    println!("lighting rotation (project_light on the CPU + relight pass): {rotate} ms\n");

    // The ceiling, measured now (the machine's load changes).
    let (dense, dense_samples) = dense_baseline(gpu, reps)?;
    let dense_rate = dense_samples as f64 / (dense.min * 1e-3) / 1e6;
    println!(
        "bare dense march (docs/PLATFORM.md; 512² rays × 128 steps in a 128³ RGBA16F texture): {dense} ms = {dense_rate:.0} M trilinear samples/s\n"
    );
    println!(
        "| frame | march, fragment pass (ms) | march, compute pass (ms) | relit frame (ms) | ratio | marked relight + march (ms) | ratio | jitter on (ms) | samples/frame | M samples/s | of dense |"
    );
    println!("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |");
    for (w, h) in [(512u32, 512u32), (1920, 1080)] {
        let camera = portrait_camera(asset, w, h);
        let settings = ViewSettings {
            march: MarchSettings::default(),
            jitter: false,
            frame_index: 0,
            view: MarchView::Shaded,
            pass: MarchPass::Fragment,
        };
        let compute = ViewSettings {
            pass: MarchPass::Compute,
            ..settings
        };
        let mut frame = 0u32;
        let jittered = |frame: u32| ViewSettings {
            jitter: true,
            frame_index: frame,
            ..settings
        };
        let march = time_ms(reps, || Ok(gpu.frame_blocking(&camera, &settings)?))?;
        let march_compute = time_ms(reps, || Ok(gpu.frame_blocking(&camera, &compute)?))?;
        // Relighting every frame at the held camera: its pixels from the per-pixel cache
        // where the frame fits it (replay.rs), else the marked voxels and a march; then the
        // marked relight alone (no cache), for comparison.
        let both = time_ms(reps, || {
            gpu.invalidate_lighting();
            Ok(gpu.frame_blocking(&camera, &settings)?)
        })?;
        let relit_kind = gpu.last_relight();
        gpu.set_replay_budget_bytes(0);
        let marked = time_ms(reps, || {
            gpu.invalidate_lighting();
            Ok(gpu.frame_blocking(&camera, &settings)?)
        })?;
        gpu.set_replay_budget_bytes(nelf_viewer::DEFAULT_REPLAY_BUDGET_BYTES);
        let jitter = time_ms(reps, || {
            frame += 1;
            Ok(gpu.frame_blocking(&camera, &jittered(frame))?)
        })?;
        // The first lighting change at a held camera builds the per-pixel cache (or, with
        // the cache off, relights in full and marks the voxels the march reads): its cost
        // against a full relight plus a march, the camera alternating between two nearby
        // orbits so that neither is cached or marked.
        let nearby = orbit_camera(asset, w, h, 21.0);
        for (what, budget) in [
            (
                "cache build + per-pixel relight",
                nelf_viewer::DEFAULT_REPLAY_BUDGET_BYTES,
            ),
            ("full relight + marking march", 0),
        ] {
            gpu.set_replay_budget_bytes(budget);
            let mut first_ms = Vec::with_capacity(reps.max(1));
            for rep in 0..reps.max(1) + 2 {
                let cam = if rep % 2 == 0 { &nearby } else { &camera };
                gpu.frame_blocking(cam, &settings)?;
                gpu.invalidate_lighting();
                let start = Instant::now();
                gpu.frame_blocking(cam, &settings)?;
                if rep >= 2 {
                    first_ms.push(start.elapsed().as_secs_f64() * 1e3);
                }
            }
            first_ms.sort_by(f64::total_cmp);
            notes.push(format!(
                "{w}×{h}: first lighting change at a held camera ({what}, {:?}) {:.1} (median {:.1}) ms, \
                 {:.2}× a full relight ({:.1} ms) plus a march",
                gpu.last_relight(),
                first_ms[0],
                first_ms[first_ms.len() / 2],
                first_ms[0] / (relight.min + march.min),
                relight.min
            ));
        }
        gpu.set_replay_budget_bytes(nelf_viewer::DEFAULT_REPLAY_BUDGET_BYTES);
        let counters = gpu.count_samples(&camera, &settings)?;
        let rate = f64::from(counters.samples) / (march.min * 1e-3) / 1e6;
        println!(
            "| {w}×{h} | {march} = {:.1} fps | {march_compute} | {both} ({}) | {:.2} | {marked} | {:.2} | {jitter} | {} | {rate:.0} | {:.2} |",
            1e3 / march.min,
            relit_kind.map_or_else(|| "none".to_string(), |k| format!("{k:?}")),
            both.min / march.min,
            marked.min / march.min,
            counters.samples,
            rate / dense_rate
        );
        // Where the samples go (rays entering the grid box), and SIMD lane use: lavapipe
        // runs 8 invocations in lock step, so a group of 8 pixels costs its slowest ray.
        let cost = gpu.render(
            &camera,
            &ViewSettings {
                view: MarchView::Cost,
                pass: MarchPass::Compute,
                ..settings
            },
        )?;
        let (mut useful, mut paid) = (0.0f64, 0.0f64);
        for row in cost.rgb.chunks(w as usize) {
            for group in row.chunks(8) {
                useful += group.iter().map(|c| f64::from(c[0])).sum::<f64>();
                paid += 8.0 * group.iter().map(|c| f64::from(c[0])).fold(0.0, f64::max);
            }
        }
        let entering = cost.rgb.iter().filter(|c| c[2] > 0.0).count().max(1) as f64;
        let total = |i: usize| cost.rgb.iter().map(|c| f64::from(c[i])).sum::<f64>() / entering;
        notes.push(format!(
            "{w}×{h}: {:.0} % of rays enter the grid box; each takes {:.1} samples in {:.1} loop steps out of {:.1} lattice samples; lane use {:.2}",
            100.0 * entering / cost.rgb.len() as f64,
            total(0),
            total(1),
            total(2),
            useful / paid.max(1.0)
        ));
    }
    for note in &notes {
        println!("\n{note}");
    }
    // Accuracy beside speed: the GPU frame against the CPU reference at 256², both under
    // the sky as stored.
    gpu.set_light_rotation(DMat3::IDENTITY)?;
    let camera = portrait_camera(asset, 256, 256);
    let settings = ViewSettings::default();
    let got = gpu.render(&camera, &settings)?;
    let start = Instant::now();
    let want = render_asset(
        asset,
        &camera,
        &env,
        DMat3::IDENTITY,
        None,
        &MarchSettings::default(),
    )?;
    let cpu_ms = start.elapsed().as_secs_f64() * 1e3;
    let gpu_frame = time_ms(reps, || Ok(gpu.frame_blocking(&camera, &settings)?))?;
    println!(
        "\nGPU vs CPU reference at 256²: PSNR {:.1} dB; CPU reference (project, relight, march; rayon) {cpu_ms:.0} ms, GPU march {gpu_frame} ms",
        psnr(&want, &got)
    );
    // The same camera held while the lighting turns: frames replayed per pixel (or, over
    // the cache budget, marked relights) against the CPU reference under each lighting.
    let mut worst = f64::INFINITY;
    let mut kind = None;
    for step in 1..=3 {
        let turn = rotation_y(0.7 * f64::from(step));
        gpu.set_light_rotation(turn)?;
        let got = gpu.render(&camera, &settings)?;
        let want = render_asset(asset, &camera, &env, turn, None, &MarchSettings::default())?;
        worst = worst.min(psnr(&want, &got));
        kind = gpu.last_relight();
    }
    println!(
        "held camera at 256², lighting turned 3 times ({kind:?}): PSNR vs CPU reference ≥ {worst:.1} dB"
    );
    bench_view_dependence(gpu, asset, reps)?;
    bench_reflection(asset, reps)?;
    bench_fine_density(asset, reps)
}

/// A fine density of factor `factor` for `asset` (format 1.4): its voxels' density
/// interpolated trilinearly at the fine voxel centres (the renderers' rule), the same
/// field with the asset's own occupancy, so that a timing compares like with like.
fn upsampled_fine_density(asset: &Asset, factor: u32) -> Result<FineDensity, BoxError> {
    let grid = BrickGrid::from_asset(asset)?;
    let density = asset_density(asset);
    let edge = 8 * factor as usize;
    let fine_voxel = asset.grid.voxel_size_m / f64::from(factor);
    let origin = DVec3::from_array(asset.grid.bbox_min_m);
    let mut values = Vec::with_capacity(asset.bricks.len() * edge * edge * edge);
    let mut corners = [(0usize, 0.0f32); 8];
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
                        origin + (DVec3::new(ijk[0] as f64, ijk[1] as f64, ijk[2] as f64) + 0.5) * fine_voxel;
                    let n = grid.trilinear(p, &mut corners);
                    let sigma: f32 = corners[..n].iter().map(|&(v, w)| w * density[v]).sum();
                    values.push(half::f16::from_f32(sigma));
                }
            }
        }
    }
    Ok(FineDensity { factor, values })
}

/// An asset with a fine density against itself without it: frame ms (fragment march) at
/// 512² and 1080p with the camera and lighting held (the march alone) and relit every
/// frame at a moving camera (a full relight and march), interleaved on two renderers, and
/// the march's samples per frame.
fn bench_fine_density(asset: &Asset, reps: usize) -> Result<(), BoxError> {
    let Some(fine) = &asset.fine_density else {
        return Ok(());
    };
    let mut coarse = asset.clone();
    coarse.fine_density = None;
    let env = sky()?;
    let mut coarse_gpu = GpuRenderer::new_headless()?;
    coarse_gpu.load_asset(&coarse)?;
    coarse_gpu.set_lighting(&env, DMat3::IDENTITY)?;
    let mut fine_gpu = GpuRenderer::new_headless()?;
    let info = fine_gpu.load_asset(asset)?;
    fine_gpu.set_lighting(&env, DMat3::IDENTITY)?;
    let settings = ViewSettings {
        march: MarchSettings::default(),
        jitter: false,
        frame_index: 0,
        view: MarchView::Shaded,
        pass: MarchPass::Fragment,
    };
    println!(
        "\nFine density (F = {}, {:.1} MiB on the GPU; shown: {:?}): frame ms (fragment march) of the asset \
         against itself without it, interleaved; moving = a new camera every frame (0.25° steps of orbit, never the static one) with a \
         full relight; ratio = with / without (fastest runs)\n",
        fine.factor,
        info.memory.fine_density_bytes as f64 / f64::from(1u32 << 20),
        info.fine_density
    );
    println!(
        "| frame | without, static (ms) | with, static (ms) | ratio | without, moving + relit (ms) | with, moving + relit (ms) | ratio | samples/frame without | with |"
    );
    println!("| --- | --- | --- | --- | --- | --- | --- | --- | --- |");
    for (w, h) in [(512u32, 512u32), (1920, 1080)] {
        let camera = portrait_camera(asset, w, h);
        let mut frame = 0u32;
        let times = time_interleaved(reps, 4, |job| {
            frame += 1;
            // Never the static camera (a held camera would replay its pixels).
            let moving = orbit_camera(asset, w, h, 20.0 + 0.25 * f64::from(1 + frame % 40));
            let gpu = if job % 2 == 0 {
                &mut coarse_gpu
            } else {
                &mut fine_gpu
            };
            if job < 2 {
                gpu.frame_blocking(&camera, &settings)?;
            } else {
                gpu.invalidate_lighting();
                gpu.frame_blocking(&moving, &settings)?;
            }
            Ok(())
        })?;
        let [without, with, without_moving, with_moving] = [times[0], times[1], times[2], times[3]];
        let samples_without = coarse_gpu.count_samples(&camera, &settings)?.samples;
        let samples_with = fine_gpu.count_samples(&camera, &settings)?.samples;
        println!(
            "| {w}×{h} | {without} | {with} | {:.2} | {without_moving} | {with_moving} | {:.2} | {samples_without} | {samples_with} |",
            with.min / without.min,
            with_moving.min / without_moving.min
        );
    }
    Ok(())
}

fn main() -> Result<(), BoxError> {
    let mut paths: Vec<PathBuf> = Vec::new();
    let mut reps = 9usize;
    let mut add_view = false;
    let mut add_reflection = false;
    let mut fine_factor: Option<u32> = None;
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        if a == "--reps" {
            reps = args.next().ok_or("--reps needs a number")?.parse()?;
        } else if a == "--view" {
            add_view = true;
        } else if a == "--reflect" {
            add_reflection = true;
        } else if a == "--fine" {
            fine_factor = Some(args.next().ok_or("--fine needs a factor (2 or 4)")?.parse()?);
        } else {
            paths.push(PathBuf::from(a));
        }
    }
    let mut gpu = GpuRenderer::new_headless()?;
    if let Some(info) = gpu.adapter_info() {
        println!(
            "adapter: {} ({:?}, {:?})",
            info.name, info.backend, info.device_type
        );
    }
    if paths.is_empty() {
        let start = Instant::now();
        let asset = SyntheticField::new(300_000, 7).asset(12, CoefficientEncoding::U8Affine)?;
        let dir = std::env::temp_dir().join("nelf-viewer-bench");
        std::fs::create_dir_all(&dir)?;
        let path = dir.join("synthetic-300k-k12.nelf");
        write_asset(&path, &asset, &WriteOptions::default())?;
        eprintln!("synthetic asset built in {:.1} s", start.elapsed().as_secs_f64());
        paths.push(path);
    }
    for path in &paths {
        let mut asset = read_asset(path)?;
        let mut name = path.display().to_string();
        if add_view && asset.view.is_none() && asset.reflection.is_none() {
            asset.view = Some(synthetic_view(&asset, 3, 8, CoefficientEncoding::U8Affine, 7)?);
            asset.validate()?;
            name.push_str(" + synthetic view part (J = 3, K_v = 8)");
        }
        if add_reflection && asset.view.is_none() && asset.reflection.is_none() {
            asset.reflection = Some(synthetic_reflection(&asset, 20.0, 7)?);
            asset.validate()?;
            name.push_str(" + synthetic reflection part (λ = 20)");
        }
        if let Some(factor) = fine_factor.filter(|_| asset.fine_density.is_none()) {
            asset.fine_density = Some(upsampled_fine_density(&asset, factor)?);
            asset.validate()?;
            name = format!("{name} + fine density (F = {factor}, upsampled)");
        }
        bench_asset(&mut gpu, &name, &asset, reps)?;
    }
    Ok(())
}
