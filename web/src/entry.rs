//! The wasm entry point: URL parameters → fetches → eframe's `WebRunner` on the page's
//! canvas → a report of every frame in `<body data-nelf-…>`.

use std::sync::Arc;
use std::sync::mpsc::{Sender, channel};

use eframe::egui_wgpu::{WgpuConfiguration, WgpuSetup, WgpuSetupCreateNew};
use eframe::wgpu;
use nelf_format::conventions::PinholeCamera;
use nelf_viewer::{FrameReport, IncomingFile, ViewerConfig, create_app};
use wasm_bindgen::JsCast as _;
use wasm_bindgen::prelude::*;
use wasm_bindgen_futures::JsFuture;

use crate::params::WebParams;

/// The canvas the page provides.
const CANVAS_ID: &str = "nelf_canvas";

/// Starts the viewer when the module loads.
#[wasm_bindgen(start)]
pub fn start() -> Result<(), JsValue> {
    let window = web_sys::window().ok_or("no window")?;
    let document = window.document().ok_or("no document")?;
    let started_ms = window.performance().map_or(0.0, |p| p.now());
    // The page's defaults (an exported page names its asset and map), then the link's.
    let defaults = document
        .query_selector("meta[name=nelf-defaults]")?
        .and_then(|m| m.get_attribute("content"))
        .unwrap_or_default();
    let search = window.location().search()?;
    let query = format!("{defaults}&{}", search.trim_start_matches('?'));
    let params = match WebParams::parse(&query) {
        Ok(p) => p,
        Err(e) => {
            set_data(&document, "nelfError", &e.to_string());
            show_message(&document, &e.to_string());
            return Ok(());
        }
    };
    let canvas = document
        .get_element_by_id(CANVAS_ID)
        .ok_or("the page has no canvas #nelf_canvas")?
        .dyn_into::<web_sys::HtmlCanvasElement>()?;

    let (sender, receiver) = channel();
    for url in [params.asset.clone(), params.env.clone()].into_iter().flatten() {
        wasm_bindgen_futures::spawn_local(fetch_into(url, sender.clone()));
    }
    drop(sender);

    let mut config = ViewerConfig::new(None);
    config.incoming = Some(receiver);
    config.start = params.start;
    let report_document = document.clone();
    let mut first_frame_ms: Option<f64> = None;
    config.on_frame = Some(Box::new(move |report: &FrameReport| {
        if first_frame_ms.is_none() && report.frames_with_asset > 0 {
            let now = web_sys::window()
                .and_then(|w| w.performance())
                .map_or(0.0, |p| p.now());
            first_frame_ms = Some(now - started_ms);
        }
        write_report(&report_document, report, first_frame_ms);
    }));

    let setup = WgpuSetupCreateNew {
        device_descriptor: Arc::new(|adapter: &wgpu::Adapter| wgpu::DeviceDescriptor {
            label: Some("nelf web"),
            // The adapter's own limits: eframe's defaults cap 3D textures and buffers
            // below what a head's atlas needs.
            required_limits: adapter.limits(),
            ..Default::default()
        }),
        ..WgpuSetupCreateNew::without_display_handle()
    };
    let options = eframe::WebOptions {
        wgpu_options: WgpuConfiguration {
            wgpu_setup: WgpuSetup::CreateNew(setup),
            ..Default::default()
        },
        ..Default::default()
    };
    wasm_bindgen_futures::spawn_local(async move {
        let started = eframe::WebRunner::new()
            .start(canvas, options, Box::new(move |cc| Ok(create_app(cc, config))))
            .await;
        if let Err(e) = started {
            let message = format!("cannot start the viewer: {}", js_text(&e));
            set_data(&document, "nelfError", &message);
            show_message(&document, &message);
        }
    });
    Ok(())
}

/// Fetches `url` and sends its bytes (or why not) to the app.
async fn fetch_into(url: String, sender: Sender<IncomingFile>) {
    let bytes = fetch_bytes(&url).await;
    let name = url.split(['?', '#']).next().unwrap_or(&url).to_owned();
    let _ = sender.send(IncomingFile { name, bytes });
}

async fn fetch_bytes(url: &str) -> Result<Vec<u8>, String> {
    let window = web_sys::window().ok_or("no window")?;
    let response: web_sys::Response = JsFuture::from(window.fetch_with_str(url))
        .await
        .map_err(|e| js_text(&e))?
        .dyn_into()
        .map_err(|e| js_text(&e))?;
    if !response.ok() {
        return Err(format!("HTTP {} {}", response.status(), response.status_text()));
    }
    let buffer = JsFuture::from(response.array_buffer().map_err(|e| js_text(&e))?)
        .await
        .map_err(|e| js_text(&e))?;
    Ok(js_sys::Uint8Array::new(&buffer).to_vec())
}

/// A JavaScript error as text.
fn js_text(value: &JsValue) -> String {
    value
        .as_string()
        .or_else(|| {
            value
                .dyn_ref::<js_sys::Error>()
                .map(|e| String::from(e.message()))
        })
        .unwrap_or_else(|| format!("{value:?}"))
}

fn set_data(document: &web_sys::Document, key: &str, value: &str) {
    if let Some(body) = document.body() {
        let _ = body.dataset().set(key, value);
    }
}

/// Shows `message` in the page's `#nelf_message` element (the app is not running).
fn show_message(document: &web_sys::Document, message: &str) {
    if let Some(element) = document.get_element_by_id("nelf_message") {
        element.set_text_content(Some(message));
    }
}

/// Writes a frame's report into `<body data-nelf-…>`.
fn write_report(document: &web_sys::Document, report: &FrameReport, first_frame_ms: Option<f64>) {
    set_data(document, "nelfFrames", &report.frames_with_asset.to_string());
    let [x, y, w, h] = report.view_rect_px;
    set_data(document, "nelfRect", &format!("{x},{y},{w},{h}"));
    set_data(
        document,
        "nelfMarch",
        &format!("{},{}", report.march_size[0], report.march_size[1]),
    );
    set_data(document, "nelfFrameMs", &format!("{:.2}", report.frame_ms));
    set_data(document, "nelfGpu", &report.gpu);
    if let Some(ms) = first_frame_ms {
        set_data(document, "nelfFirstFrameMs", &format!("{ms:.0}"));
    }
    if let Some(camera) = &report.camera {
        set_data(document, "nelfCamera", &camera_json(camera));
    }
    set_data(document, "nelfError", &report.errors.join("\n"));
}

/// A camera as a `cameras.json` view object (what `nelf render --camera` reads).
fn camera_json(camera: &PinholeCamera) -> String {
    let row = |i: usize| {
        let v = camera.rotation.row(i);
        format!("[{:?},{:?},{:?}]", v.x, v.y, v.z)
    };
    let t = camera.translation;
    format!(
        "{{\"width\":{},\"height\":{},\"intrinsics\":{{\"fx\":{:?},\"fy\":{:?},\"cx\":{:?},\"cy\":{:?}}},\
         \"world_to_camera\":{{\"rotation\":[{},{},{}],\"translation\":[{:?},{:?},{:?}]}}}}",
        camera.width,
        camera.height,
        camera.fx,
        camera.fy,
        camera.cx,
        camera.cy,
        row(0),
        row(1),
        row(2),
        t.x,
        t.y,
        t.z
    )
}
