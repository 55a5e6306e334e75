//! End-to-end tests of the viewer through the `nelf` command:
//!
//! * under Xvfb, `nelf view ASSET --screenshot PNG --frames 3 --exit` opens a window,
//!   draws frames, saves a screenshot of the right size showing the asset, and exits 0;
//! * a damaged asset or environment map shows an error in the window (red text in the
//!   screenshot) and the app still exits normally;
//! * `nelf render --gpu` writes the same image as the CPU path (PSNR ≥ 45 dB);
//! * on the shared head scan under a real HDRI, the GPU renderer equals the CPU reference
//!   and its marked relight equals a full one.
//!
//! Needs `xvfb-run` (Debian package `xvfb`) and a Vulkan driver (`mesa-vulkan-drivers`
//! gives lavapipe on machines without a GPU); `.ci/run` installs both.
#![allow(clippy::unwrap_used)] // Test helpers outside #[test] functions unwrap too.

mod common;

use std::ffi::OsStr;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

use nelf_format::synthetic::SyntheticField;
use nelf_format::{CoefficientEncoding, WriteOptions, write_asset};

const APT_HINT: &str = "install the packages: apt-get install -y xvfb mesa-vulkan-drivers";

/// Runs `nelf ARGS` under `xvfb-run` with a time limit.
fn nelf_under_xvfb<S: AsRef<OsStr>>(args: &[S]) -> Output {
    let probe = Command::new("xvfb-run").arg("--help").output();
    assert!(probe.is_ok(), "xvfb-run is missing: {APT_HINT}");
    let child = Command::new("xvfb-run")
        .args(["-a", "-s", "-screen 0 1280x800x24"])
        .arg(env!("CARGO_BIN_EXE_nelf"))
        .args(args)
        .env("NODEVICE_SELECT", "1")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn();
    let mut child = child.unwrap_or_else(|e| panic!("cannot start xvfb-run: {e}; {APT_HINT}"));
    let deadline = Instant::now() + Duration::from_secs(180);
    loop {
        if child.try_wait().unwrap().is_some() {
            return child.wait_with_output().unwrap();
        }
        if Instant::now() > deadline {
            let _ = child.kill();
            let out = child.wait_with_output().unwrap();
            panic!(
                "nelf view did not exit within 180 s; stderr:\n{}",
                String::from_utf8_lossy(&out.stderr)
            );
        }
        std::thread::sleep(Duration::from_millis(100));
    }
}

fn write_head(dir: &Path) -> PathBuf {
    let asset = SyntheticField::new(20_000, 4)
        .asset(6, CoefficientEncoding::U8Affine)
        .unwrap();
    let path = dir.join("head.nelf");
    write_asset(&path, &asset, &WriteOptions::default()).unwrap();
    path
}

/// Runs the viewer on `asset` with extra options, returns the screenshot (RGBA) and stderr.
fn screenshot(dir: &Path, asset: &Path, extra: &[&OsStr]) -> (image::RgbaImage, String) {
    let shot = dir.join("shot.png");
    let _ = std::fs::remove_file(&shot);
    let mut args: Vec<&OsStr> = vec![
        "view".as_ref(),
        asset.as_os_str(),
        "--screenshot".as_ref(),
        shot.as_os_str(),
        "--frames".as_ref(),
        "3".as_ref(),
        "--exit".as_ref(),
        "--size".as_ref(),
        "800x600".as_ref(),
    ];
    args.extend_from_slice(extra);
    let out = nelf_under_xvfb(&args);
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(
        out.status.success(),
        "nelf view failed ({}); stderr:\n{stderr}\n(if no adapter or display was found: {APT_HINT})",
        out.status
    );
    let image = image::open(&shot)
        .unwrap_or_else(|e| panic!("no screenshot at {}: {e}; stderr:\n{stderr}", shot.display()))
        .to_rgba8();
    (image, stderr)
}

/// Pixels that look like the app's red error text.
fn red_pixels(image: &image::RgbaImage) -> usize {
    image
        .pixels()
        .filter(|p| p[0] > 180 && p[1] < 140 && p[2] < 140 && i32::from(p[0]) - i32::from(p[1]) > 80)
        .count()
}

#[test]
fn view_opens_a_window_draws_the_asset_and_saves_a_screenshot() {
    let dir = tempfile::tempdir().unwrap();
    let asset = write_head(dir.path());
    let (image, stderr) = screenshot(dir.path(), &asset, &[]);
    assert_eq!(image.dimensions(), (800, 600), "stderr:\n{stderr}");
    // The central viewport (right of the 280-point control panel) shows a lit head:
    // many pixels much brighter than the dark background.
    let lit = (400..760)
        .flat_map(|x| (150..450).map(move |y| (x, y)))
        .filter(|&(x, y)| {
            let p = image.get_pixel(x, y);
            u32::from(p[0]) + u32::from(p[1]) + u32::from(p[2]) > 150
        })
        .count();
    assert!(
        lit > 10_000,
        "only {lit} lit pixels in the viewport; stderr:\n{stderr}"
    );
    assert_eq!(red_pixels(&image), 0, "an error is shown; stderr:\n{stderr}");
}

#[test]
fn damaged_asset_or_envmap_shows_an_error_and_exits_normally() {
    let dir = tempfile::tempdir().unwrap();
    let asset = write_head(dir.path());
    let mut bytes = std::fs::read(&asset).unwrap();
    let middle = bytes.len() / 2;
    for b in &mut bytes[middle..middle + 32] {
        *b = !*b;
    }
    let damaged = dir.path().join("damaged.nelf");
    std::fs::write(&damaged, &bytes).unwrap();
    let (image, stderr) = screenshot(dir.path(), &damaged, &[]);
    assert!(
        red_pixels(&image) > 50,
        "no error text in the window; stderr:\n{stderr}"
    );

    let bad_env = dir.path().join("sky.exr");
    std::fs::write(&bad_env, b"not an EXR file").unwrap();
    let (image, stderr) = screenshot(dir.path(), &asset, &["--envmap".as_ref(), bad_env.as_os_str()]);
    assert!(
        red_pixels(&image) > 50,
        "no error text in the window; stderr:\n{stderr}"
    );
}

#[test]
fn render_gpu_writes_the_same_image_as_the_cpu_path() {
    let dir = tempfile::tempdir().unwrap();
    let asset = write_head(dir.path());
    let env_path = dir.path().join("sky.exr");
    let sky: Vec<[f32; 3]> = (0..32 * 16)
        .map(|i| {
            let (row, col) = (i / 32, i % 32);
            [
                1.5 - row as f32 * 0.08 + if col == 5 { 6.0 } else { 0.0 },
                1.0 - row as f32 * 0.05,
                0.8 + (col as f32 * 0.3).sin() * 0.2,
            ]
        })
        .collect();
    nelf_scene::image_io::write_exr_rgb(&env_path, 32, 16, &sky).unwrap();
    let mut images = Vec::new();
    for (name, gpu) in [("cpu.exr", false), ("gpu.exr", true)] {
        let out_path = dir.path().join(name);
        let mut command = Command::new(env!("CARGO_BIN_EXE_nelf"));
        command
            .arg("render")
            .arg(&asset)
            .args([
                "--orbit",
                "35,15",
                "--width",
                "96",
                "--height",
                "80",
                "--rotate-deg",
                "40",
            ])
            .arg("--envmap")
            .arg(&env_path)
            .arg("-o")
            .arg(&out_path)
            .env("NODEVICE_SELECT", "1");
        if gpu {
            command.arg("--gpu");
        }
        let out = command.output().unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(
            out.status.success(),
            "{name}: {stderr}\n(if no adapter was found: {APT_HINT})"
        );
        let record: serde_json::Value = serde_json::from_str(
            &std::fs::read_to_string(dir.path().join(format!("{name}.render.json"))).unwrap(),
        )
        .unwrap();
        assert_eq!(record["device"], if gpu { "gpu" } else { "cpu" });
        // The env-map loader reads any RGB EXR (radiance is non-negative here).
        images.push(nelf_scene::envmap::load_envmap(&out_path).unwrap());
    }
    let (cpu, gpu) = (&images[0], &images[1]);
    assert_eq!((gpu.width(), gpu.height()), (96, 80));
    let psnr = psnr(cpu.texels(), gpu.texels());
    assert!(psnr >= 45.0, "GPU vs CPU render: PSNR {psnr:.1} dB");
}

/// PSNR (dB) of `test` against `reference`, peak = the reference's largest value (which
/// must be positive).
fn psnr(reference: &[[f32; 3]], test: &[[f32; 3]]) -> f64 {
    assert_eq!(reference.len(), test.len());
    let peak = reference.iter().flatten().fold(0.0f32, |m, &v| m.max(v));
    assert!(peak > 0.0);
    let mse = reference
        .iter()
        .zip(test)
        .flat_map(|(a, b)| (0..3).map(move |c| f64::from(a[c] - b[c]).powi(2)))
        .sum::<f64>()
        / (3 * reference.len()) as f64;
    10.0 * (f64::from(peak).powi(2) / mse.max(1e-30)).log10()
}

#[test]
fn gpu_march_and_marked_relight_on_the_scanned_head_under_a_real_hdri() {
    // Real data, not a procedural head: the shared head scan (open at the neck, holes
    // and thin parts) baked small, lit by a real HDRI. The GPU march (empty-space skipping
    // through the march grid) equals the CPU reference, and at a held camera the relight
    // of only the voxels it reads gives the same image as a fresh renderer's full relight,
    // and the per-pixel replay (the default there) the same to rounding.
    let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("data");
    let env_path = data.join("envmaps/studio.exr");
    assert!(
        env_path.is_file(),
        "missing test data {} (see data/README.md)",
        env_path.display()
    );
    let dir = tempfile::tempdir().unwrap();
    let asset_path = common::bake_scan_head(dir.path());
    let asset = nelf_format::read_asset(&asset_path).unwrap();
    let env = nelf_scene::envmap::load_envmap(&env_path).unwrap();
    let lo = glam::DVec3::from_array(asset.grid.bbox_min_m);
    let hi = glam::DVec3::from_array(asset.grid.bbox_max_m());
    let centre = 0.5 * (lo + hi);
    let camera = nelf_format::conventions::PinholeCamera::look_at(
        centre + 2.2 * (hi - lo).length() * glam::DVec3::new(0.4, 0.15, 0.9).normalize(),
        centre,
        glam::DVec3::Y,
        96,
        80,
        0.6,
    );
    let settings = nelf_viewer::ViewSettings::default();
    let turn = |deg: f64| nelf_format::conventions::rotation_y(deg.to_radians());
    for (budget, kind) in [
        (0, nelf_viewer::RelightKind::Marked),
        (
            nelf_viewer::DEFAULT_REPLAY_BUDGET_BYTES,
            nelf_viewer::RelightKind::Replay,
        ),
    ] {
        let mut gpu = nelf_viewer::GpuRenderer::new_headless().unwrap_or_else(|e| panic!("{e}; {APT_HINT}"));
        gpu.set_replay_budget_bytes(budget);
        gpu.load_asset(&asset).unwrap();
        gpu.set_lighting(&env, turn(0.0)).unwrap();
        gpu.render(&camera, &settings).unwrap();
        for deg in [40.0, 80.0, 120.0] {
            gpu.set_light_rotation(turn(deg)).unwrap();
            let got = gpu.render(&camera, &settings).unwrap();
            let want = nelf_render::render_asset(
                &asset,
                &camera,
                &env,
                turn(deg),
                None,
                &nelf_render::MarchSettings::default(),
            )
            .unwrap();
            let db = psnr(&want.rgb, &got.rgb);
            assert!(db >= 45.0, "scan at {deg}°: GPU vs CPU PSNR {db:.1} dB");
            let mut fresh = nelf_viewer::GpuRenderer::new_headless().unwrap();
            fresh.load_asset(&asset).unwrap();
            fresh.set_lighting(&env, turn(deg)).unwrap();
            let want = fresh.render(&camera, &settings).unwrap();
            if kind == nelf_viewer::RelightKind::Marked {
                assert_eq!(got, want, "scan at {deg}°");
            } else {
                let db = psnr(&want.rgb, &got.rgb);
                assert!(db >= 70.0, "scan at {deg}°: replay vs march PSNR {db:.1} dB");
                assert_eq!(got.alpha, want.alpha, "scan at {deg}°");
            }
        }
        // With the cache off the first change at the held camera relit in full and marked,
        // the later ones only the voxels it reads; with it on, all were replayed.
        assert_eq!(gpu.last_relight(), Some(kind));
    }
}
