//! End-to-end test of `nelf render --field`: a small synthetic capture is rendered
//! straight from the NeLF network (the parity fixtures' weights) from one of its
//! views, and the EXR equals the library's render of the same rays; orbits work and
//! the options are checked.
#![allow(clippy::unwrap_used)] // Test helpers outside #[test] functions unwrap too.

mod common;

use common::{fixture_weights, nelf, succeed, tiny_capture};
use nelf_field::capture::{default_net_from_world, load_capture_dir};
use nelf_field::light::latlong_to_net_light;
use nelf_field::render::{ImageSettings, render_image};
use nelf_field::{Model, NelfConfig, NelfField};
use nelf_format::conventions::PinholeCamera;
use nelf_scene::envmap::load_envmap;

#[test]
fn render_field_matches_the_library() {
    let weights = fixture_weights();
    let dir = tempfile::tempdir().unwrap();
    let capture = tiny_capture(dir.path(), 64, 1, &[]);
    let cap = capture.to_str().unwrap();
    let out = dir.path().join("field.exr");
    let view_of = format!("{cap}:view_001");
    succeed(&[
        "render",
        "--field",
        cap,
        "--weights",
        weights,
        "--view-of",
        &view_of,
        "--width",
        "12",
        "--height",
        "12",
        "--estimated-light",
        // The library render below is uncalibrated (nelf_field::calibrate).
        "--no-source-calibration",
        "-o",
        out.to_str().unwrap(),
    ]);
    let got = load_envmap(&out).unwrap();
    assert_eq!((got.width(), got.height()), (12, 12));
    let record: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("field.exr.render.json")).unwrap())
            .unwrap();
    assert_eq!(record["device"], "nelf-network (cpu)");

    // The library, same camera (the view at 12 × 12), same light, same sampling.
    let (prepared, description) = load_capture_dir(&capture, default_net_from_world()).unwrap();
    let model = Model::load(weights, NelfConfig::default(), &candle_core::Device::Cpu).unwrap();
    let field = NelfField::new(model, &prepared).unwrap();
    let view = description.view("view_001").unwrap().camera;
    let s = 12.0 / 64.0;
    let camera = PinholeCamera {
        width: 12,
        height: 12,
        fx: view.fx * s,
        fy: view.fy * s,
        cx: view.cx * s,
        cy: view.cy * s,
        ..view
    };
    let light = latlong_to_net_light(&field.source_light().unwrap()).unwrap();
    let settings = ImageSettings {
        head_centre: prepared.head_centre_net(),
        ..ImageSettings::default()
    };
    let want = render_image(
        field.model(),
        field.encoded(),
        &prepared.net_camera(&camera),
        &light,
        &settings,
        None,
    )
    .unwrap();
    let scale = want.rgb.iter().flatten().fold(0.0f32, |a, b| a.max(*b));
    assert!(scale > 0.0, "the head is visible");
    for (a, b) in got.texels().iter().zip(&want.rgb) {
        for c in 0..3 {
            assert!((a[c] - b[c]).abs() <= 1e-5 * scale, "{a:?} vs {b:?}");
        }
    }

    // An orbit around the hull box, PNG output.
    let png = dir.path().join("orbit.png");
    succeed(&[
        "render",
        "--field",
        cap,
        "--weights",
        weights,
        "--orbit",
        "20,5",
        "--width",
        "8",
        "--height",
        "8",
        "-o",
        png.to_str().unwrap(),
    ]);
    assert!(png.is_file());

    // Without --weights, --field renders with the shipped network; an asset and
    // --field exclude each other.
    let shipped_png = dir.path().join("shipped.png");
    succeed(&[
        "render",
        "--field",
        cap,
        "--width",
        "8",
        "--height",
        "8",
        "-o",
        shipped_png.to_str().unwrap(),
    ]);
    assert!(shipped_png.is_file());
    let out = nelf(&["render", "some.nelf", "--field", cap, "--weights", weights]);
    assert!(!out.status.success());
}
