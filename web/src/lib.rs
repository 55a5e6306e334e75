//! `nelf-web`: the `nelf-viewer` app in a browser. The same crates, WGSL and egui
//! panels as `nelf view`, built for `wasm32-unknown-unknown` by `scripts/build_web.sh`
//! (wasm-bindgen output plus `web/index.html`, written to `web/dist/`, which
//! `nelf export web` embeds).
//!
//! * [`params`]: the page's URL parameters (`?asset=…&env=…&orbit=AZ,EL,DIST&rotate=DEG`
//!   and display options), parsed the same natively (tested) and in the browser.
//! * On wasm32 only, the entry point: fetches the asset and map the URL names, starts
//!   eframe's `WebRunner` on the page's canvas (WebGPU; the device gets the adapter's
//!   own limits, so large atlases fit) and writes every frame's report into the page's
//!   `<body data-nelf-…>` attributes: frames drawn, the 3D view's rectangle, its camera
//!   (as a `cameras.json` view object, which `nelf render --camera` reads), the frame
//!   time, the time to the first frame and any error. Tests and timings read them.
//!
//! What the page cannot do: WebGL2 (no compute shaders, no storage buffers) gets a clear
//! message instead of a picture; the relight and march passes need WebGPU.

pub mod params;

#[cfg(target_arch = "wasm32")]
mod entry;
