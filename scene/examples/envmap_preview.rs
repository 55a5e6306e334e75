//! Looks at environment maps: writes a tone-mapped sRGB PNG of each map and of its
//! 8 × 16 projection (auto exposure), and prints size, load time, power `Σ Ω L`
//! of the map and of the projection, and the brightest texel's direction.
//!
//! ```text
//! cargo run --release -p nelf-scene --example envmap_preview -- OUT_DIR [MAP.exr|MAP.hdr|gen:SEED]…
//! ```
//! With no maps it previews `data/envmaps/*.exr` and procedural seeds 0–5.

use std::path::{Path, PathBuf};

use nelf_format::conventions::{LatLong, texel_center_direction};
use nelf_scene::envgen::{EnvGenParams, procedural_env};
use nelf_scene::envmap::{auto_exposure, envmap_to_basis, load_envmap, luminance, save_envmap_preview};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let out = PathBuf::from(
        args.next()
            .ok_or("usage: envmap_preview OUT_DIR [MAP|gen:SEED]…")?,
    );
    std::fs::create_dir_all(&out)?;
    let mut sources: Vec<String> = args.collect();
    if sources.is_empty() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../data/envmaps");
        let mut files: Vec<String> = std::fs::read_dir(&dir)?
            .filter_map(Result::ok)
            .map(|e| e.path())
            .filter(|p| p.extension().is_some_and(|e| e == "exr"))
            .map(|p| p.display().to_string())
            .collect();
        files.sort();
        sources = files;
        sources.extend((0..6).map(|s| format!("gen:{s}")));
    }
    for source in &sources {
        let start = std::time::Instant::now();
        let (name, map) = if let Some(seed) = source.strip_prefix("gen:") {
            let env = procedural_env(seed.parse()?, &EnvGenParams::default());
            let sun = env
                .sun_direction
                .map(|d| format!(" sun {d:.3}"))
                .unwrap_or_default();
            (format!("gen{seed}_{:?}{sun}", env.family), env.map)
        } else {
            let stem = Path::new(source)
                .file_stem()
                .map_or_else(|| "map".to_string(), |s| s.to_string_lossy().into_owned());
            (stem, load_envmap(source)?)
        };
        let elapsed_ms = start.elapsed().as_secs_f64() * 1e3;
        let basis = envmap_to_basis(&map, 0.0);
        let stops = auto_exposure(&map);
        let file = name.split_whitespace().next().unwrap_or("map").to_string();
        save_envmap_preview(out.join(format!("{file}.png")), &map, stops)?;
        save_envmap_preview(out.join(format!("{file}_8x16.png")), &basis, stops)?;
        let (power, basis_power) = (map.integral(), basis.integral());
        let relative = (0..3)
            .map(|c| (basis_power[c] - power[c]).abs() / power[c].max(1e-30))
            .fold(0.0f64, f64::max);
        println!(
            "{name}: {}×{} in {elapsed_ms:.1} ms, power {power:.4?}, 8×16 power error {relative:.2e}, \
             brightest toward {}, exposure {stops:+.2} stops",
            map.width(),
            map.height(),
            brightest_direction(&map)
        );
    }
    Ok(())
}

/// Direction of the texel with the largest luminance, formatted.
fn brightest_direction(map: &LatLong) -> String {
    let mut best = (0usize, f32::NEG_INFINITY);
    for (i, t) in map.texels().iter().enumerate() {
        let l = luminance(*t);
        if l > best.1 {
            best = (i, l);
        }
    }
    let (row, col) = (best.0 / map.width(), best.0 % map.width());
    let d = texel_center_direction(row, col, map.height(), map.width());
    format!("({:+.2}, {:+.2}, {:+.2}) row {row}", d.x, d.y, d.z)
}
