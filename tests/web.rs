//! The web viewer in a real browser. `nelf export web` writes the page of the shared head
//! scan (a real scan: open neck, holes, thin parts; baked small) under a real HDRI; a
//! local static server hosts it; headless Chromium, driven by Playwright
//! (`web/tests/shoot.mjs`), opens it and waits for its frames:
//!
//! * on WebGPU and on WebGL2 (WebGPU off: no compute shaders, so the relight runs on the
//!   CPU) the page's frame equals `nelf render` (the CPU reference) of the same camera
//!   (the page reports it) and lighting: PSNR ≥ 35 dB on 8-bit sRGB;
//! * a damaged asset shows its error on the page;
//! * the committed page (`web/dist`, which `nelf` embeds) is what `scripts/build_web.sh`
//!   builds from these sources.
//!
//! Needs Chromium (`/usr/bin/chromium` or `$CHROMIUM`), Node with `web/tests`'s packages
//! (`npm ci` there), the wasm32 target and wasm-bindgen-cli; `.ci/run` installs them.
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use std::io::{BufRead as _, BufReader, Write as _};
use std::net::TcpListener;
use std::path::{Path, PathBuf};
use std::process::Command;

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Serves `dir` over HTTP on a free loopback port (one thread per connection, GET
/// only); returns the base URL.
fn serve(dir: PathBuf) -> String {
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let port = listener.local_addr().unwrap().port();
    std::thread::spawn(move || {
        for stream in listener.incoming().flatten() {
            let dir = dir.clone();
            std::thread::spawn(move || {
                let mut reader = BufReader::new(&stream);
                let mut request = String::new();
                if reader.read_line(&mut request).is_err() {
                    return;
                }
                let mut line = String::new();
                while reader.read_line(&mut line).is_ok_and(|n| n > 2) {
                    line.clear();
                }
                let target = request.split_whitespace().nth(1).unwrap_or("/");
                let path = target
                    .split(['?', '#'])
                    .next()
                    .unwrap_or("/")
                    .trim_start_matches('/');
                let file = dir.join(if path.is_empty() { "index.html" } else { path });
                let mut out = &stream;
                match std::fs::read(&file) {
                    Ok(body) if !path.contains("..") => {
                        let kind = match file.extension().and_then(|e| e.to_str()) {
                            Some("html") => "text/html; charset=utf-8",
                            Some("js") => "text/javascript",
                            Some("wasm") => "application/wasm",
                            _ => "application/octet-stream",
                        };
                        let head = format!(
                            "HTTP/1.1 200 OK\r\nContent-Type: {kind}\r\nContent-Length: {}\r\nConnection: close\r\n\r\n",
                            body.len()
                        );
                        let _ = out.write_all(head.as_bytes()).and_then(|()| out.write_all(&body));
                    }
                    _ => {
                        let _ = out.write_all(
                            b"HTTP/1.1 404 Not Found\r\nContent-Length: 0\r\nConnection: close\r\n\r\n",
                        );
                    }
                }
            });
        }
    });
    format!("http://127.0.0.1:{port}")
}

/// Runs `shoot.mjs` on `url` with `backend` (and its further options); returns its
/// report (JSON).
fn shoot(url: &str, backend: &str, out: &Path, options: &[&str]) -> serde_json::Value {
    let tests = repo().join("web/tests");
    assert!(
        tests.join("node_modules/playwright-core").is_dir(),
        "Playwright is missing: run `npm ci` in {} (.ci/run does)",
        tests.display()
    );
    let result = Command::new("node")
        .arg(tests.join("shoot.mjs"))
        .args([url, &out.display().to_string(), backend])
        .args(options)
        .output()
        .expect("cannot run node (Node.js is needed for the browser tests)");
    assert!(
        result.status.success(),
        "shoot.mjs {backend} {url}: {}\n{}",
        String::from_utf8_lossy(&result.stdout),
        String::from_utf8_lossy(&result.stderr)
    );
    let text = std::fs::read_to_string(out.join("report.json")).unwrap();
    serde_json::from_str(&text).unwrap()
}

/// `nelf render` of `asset` from the camera in `camera_json` under `envmap` turned by
/// `rotate_deg`, written to `out` (8-bit sRGB PNG) and read back.
fn render_reference(
    asset: &Path,
    camera_json: &Path,
    envmap: &Path,
    rotate_deg: &str,
    out: &Path,
) -> image::RgbImage {
    common::succeed(&[
        "render".as_ref(),
        asset.as_os_str(),
        "--camera".as_ref(),
        camera_json.as_os_str(),
        "--envmap".as_ref(),
        envmap.as_os_str(),
        "--rotate-deg".as_ref(),
        rotate_deg.as_ref(),
        "-o".as_ref(),
        out.as_os_str(),
    ]);
    image::open(out).unwrap().to_rgb8()
}

/// PSNR (dB) of two 8-bit RGB images over the pixels `keep` selects.
fn psnr_u8(a: &image::RgbImage, b: &image::RgbImage, keep: impl Fn(&[u8; 3], &[u8; 3]) -> bool) -> f64 {
    let (mut sum, mut n) = (0.0, 0usize);
    for (p, q) in a.pixels().zip(b.pixels()) {
        if keep(&p.0, &q.0) {
            for c in 0..3 {
                let d = f64::from(p.0[c]) - f64::from(q.0[c]);
                sum += d * d;
            }
            n += 3;
        }
    }
    let mse = sum / n.max(1) as f64;
    10.0 * (255.0 * 255.0 / mse.max(1e-12)).log10()
}

#[test]
fn the_exported_page_draws_the_scan_like_nelf_render_on_webgpu_and_webgl2() {
    let data = repo().join("data");
    let env_path = data.join("envmaps/studio.exr");
    assert!(
        env_path.is_file(),
        "missing test data {} (see data/README.md)",
        env_path.display()
    );
    let dir = tempfile::tempdir().unwrap();
    let asset = common::bake_scan_head(dir.path());
    let site = dir.path().join("site");
    common::succeed(&[
        "export".as_ref(),
        "web".as_ref(),
        asset.as_os_str(),
        "--envmap".as_ref(),
        env_path.as_os_str(),
        "--rotate-deg".as_ref(),
        "40".as_ref(),
        "--orbit".as_ref(),
        "25,10".as_ref(),
        "-o".as_ref(),
        site.as_os_str(),
    ]);
    for name in [
        "index.html",
        "nelf_web.js",
        "nelf_web_bg.wasm",
        "scan.nelf",
        "studio.exr",
        "export.json",
    ] {
        assert!(site.join(name).is_file(), "export web wrote no {name}");
    }
    // A damaged copy of the asset (truncated) beside it, for the error check.
    let bytes = std::fs::read(&asset).unwrap();
    std::fs::write(site.join("damaged.nelf"), &bytes[..bytes.len() / 2]).unwrap();
    let base = serve(site.clone());

    // The page's defaults (asset, map, rotation, orbit) plus a linear tone curve, a black
    // background and no jitter, so that the frame is what `nelf render` writes; on WebGPU
    // (relight and march as natively) and on WebGL2 (no compute shaders: the relight on
    // the CPU, the storage-free march).
    let view_url = format!("{base}/index.html?tonemap=linear&background=0,0,0&jitter=0");
    let mut webgpu = None;
    for backend in ["webgpu", "webgl2"] {
        let shots = dir.path().join(backend);
        let report = shoot(&view_url, backend, &shots, &[]);
        let page = &report["data"];
        assert_eq!(
            page["nelfError"], "",
            "{backend}: the page reported an error: {report:#}"
        );
        let gpu = page["nelfGpu"].as_str().unwrap_or_default();
        let expected = if backend == "webgpu" {
            "BrowserWebGpu"
        } else {
            "Gl"
        };
        assert!(gpu.starts_with(expected), "{backend}: the page ran on {gpu}");
        let camera = page["nelfCamera"].as_str().expect("the page reported no camera");
        let camera_path = dir.path().join(format!("camera_{backend}.json"));
        std::fs::write(&camera_path, camera).unwrap();
        let reference = dir.path().join(format!("reference_{backend}.png"));
        let want = render_reference(&asset, &camera_path, &env_path, "40", &reference);
        let got = image::open(shots.join("view.png")).unwrap().to_rgb8();
        assert_eq!(
            got.dimensions(),
            want.dimensions(),
            "{backend}: screenshot vs render size"
        );
        let whole = psnr_u8(&got, &want, |_, _| true);
        let foreground = psnr_u8(&got, &want, |p, q| p.iter().chain(q).any(|&v| v > 0));
        // The trivial baseline on the same view: black everywhere.
        let black = image::RgbImage::new(want.width(), want.height());
        let baseline = psnr_u8(&black, &want, |_, _| true);
        eprintln!(
            "web ({gpu}) vs nelf render: {whole:.2} dB whole image, {foreground:.2} dB \
             foreground; black image {baseline:.2} dB; first frame {} ms after start",
            page["nelfFirstFrameMs"]
        );
        assert!(
            whole >= 35.0 && foreground >= 35.0,
            "{backend}: web vs nelf render: {whole:.2} / {foreground:.2} dB"
        );
        webgpu.get_or_insert((camera_path, want));
    }
    let (camera_path, want) = webgpu.unwrap();

    // A damaged asset, named by the link or dropped on the page: its error is on the page.
    let page_error = |report: &serde_json::Value| {
        report["data"]["nelfError"]
            .as_str()
            .unwrap_or_default()
            .to_owned()
    };
    let report = shoot(
        &format!("{base}/index.html?asset=damaged.nelf"),
        "webgpu",
        &dir.path().join("damaged"),
        &[],
    );
    assert!(
        page_error(&report).contains("damaged.nelf"),
        "damaged asset by URL: {report:#}"
    );
    let damaged = site.join("damaged.nelf").display().to_string();
    let report = shoot(
        &format!("{base}/index.html?continuous=1"),
        "webgpu",
        &dir.path().join("dropped"),
        &["--drop", &damaged, "--expect-error"],
    );
    assert!(
        report["dropped"] == "damaged.nelf" && page_error(&report).contains("damaged.nelf"),
        "damaged asset dropped on the page: {report:#}"
    );

    // A real HDRI dropped on the page relights it: the same view now equals `nelf render`
    // under that map (and no longer the studio one).
    let hdri = data.join("envmaps/sunset.exr");
    let relit_shots = dir.path().join("hdri");
    let report = shoot(
        &format!("{base}/index.html?tonemap=linear&background=0,0,0&jitter=0&continuous=1"),
        "webgpu",
        &relit_shots,
        &["--drop", &hdri.display().to_string()],
    );
    assert_eq!(report["data"]["nelfError"], "", "dropped HDRI: {report:#}");
    assert_eq!(report["dropped"], "sunset.exr", "{report:#}");
    let relit_reference = dir.path().join("reference_sunset.png");
    let relit = image::open(relit_shots.join("view.png")).unwrap().to_rgb8();
    let relit_want = render_reference(&asset, &camera_path, &hdri, "40", &relit_reference);
    let relit_psnr = psnr_u8(&relit, &relit_want, |_, _| true);
    let studio_psnr = psnr_u8(&relit_want, &want, |_, _| true);
    eprintln!(
        "the page after dropping the sunset HDRI vs nelf render under it: {relit_psnr:.2} dB \
         (the two references differ by {studio_psnr:.2} dB)"
    );
    assert!(
        relit_psnr >= 35.0 && studio_psnr < relit_psnr - 10.0,
        "dropped HDRI: {relit_psnr:.2} dB"
    );

    // Touch, as a phone sends it: one finger orbits, two fingers pinched apart zoom in
    // (the eye moves along the view axis, no turn), two fingers dragged pan (the eye
    // moves across the view axis, no turn).
    let report = shoot(&view_url, "webgpu", &dir.path().join("touch"), &["--touch"]);
    let cameras: Vec<(glam::DMat3, glam::DVec3)> = report["touch"]
        .as_array()
        .unwrap_or_else(|| panic!("no touch report: {report:#}"))
        .iter()
        .map(|c| page_camera(c.as_str().unwrap_or_default()))
        .collect();
    assert_eq!(cameras.len(), 4, "{report:#}");
    // The angle of the rotation between two camera rotations: cos θ = (tr(aᵀb) − 1) / 2.
    let turn_deg = |a: &glam::DMat3, b: &glam::DMat3| {
        let m = a.transpose() * *b;
        let cos = (m.x_axis.x + m.y_axis.y + m.z_axis.z - 1.0) / 2.0;
        cos.clamp(-1.0, 1.0).acos().to_degrees()
    };
    let (r0, _) = cameras[0];
    let (r1, c1) = cameras[1];
    let (r2, c2) = cameras[2];
    let (r3, c3) = cameras[3];
    let forward = |r: &glam::DMat3| r.row(2);
    assert!(
        turn_deg(&r0, &r1) > 5.0,
        "one-finger drag did not orbit: {report:#}"
    );
    let zoom = c2 - c1;
    assert!(
        turn_deg(&r1, &r2) < 0.5 && zoom.length() > 1e-3 && zoom.dot(forward(&r1)) > 0.9 * zoom.length(),
        "pinch did not zoom in along the view axis: moved {zoom:?}, turned {:.2}°",
        turn_deg(&r1, &r2)
    );
    let pan = c3 - c2;
    assert!(
        turn_deg(&r2, &r3) < 0.5 && pan.length() > 1e-3 && pan.dot(forward(&r2)).abs() < 0.1 * pan.length(),
        "two-finger drag did not pan: moved {pan:?}, turned {:.2}°",
        turn_deg(&r2, &r3)
    );
}

/// The page's reported camera (a `cameras.json` view object): world-to-camera rotation
/// and the camera centre in the world.
fn page_camera(json: &str) -> (glam::DMat3, glam::DVec3) {
    let v: serde_json::Value = serde_json::from_str(json).unwrap_or_else(|e| panic!("camera {json}: {e}"));
    let w = &v["world_to_camera"];
    let row = |i: usize| {
        glam::DVec3::from_array(std::array::from_fn(|j| {
            w["rotation"][i][j]
                .as_f64()
                .unwrap_or_else(|| panic!("camera {json}"))
        }))
    };
    let rotation = glam::DMat3::from_cols(row(0), row(1), row(2)).transpose();
    let t = glam::DVec3::from_array(std::array::from_fn(|j| {
        w["translation"][j]
            .as_f64()
            .unwrap_or_else(|| panic!("camera {json}"))
    }));
    (rotation, -(rotation.transpose() * t))
}

#[test]
fn the_committed_web_page_is_built_from_these_sources() {
    let dir = tempfile::tempdir().unwrap();
    let out = Command::new("bash")
        .arg(repo().join("scripts/build_web.sh"))
        .arg(dir.path())
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "scripts/build_web.sh failed:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    for name in ["index.html", "nelf_web.js", "nelf_web_bg.wasm"] {
        let built = std::fs::read(dir.path().join(name)).unwrap();
        let committed = std::fs::read(repo().join("web/dist").join(name)).unwrap();
        assert!(
            built == committed,
            "web/dist/{name} differs from a fresh build ({} vs {} bytes): run scripts/build_web.sh and commit web/dist",
            committed.len(),
            built.len()
        );
    }
}
