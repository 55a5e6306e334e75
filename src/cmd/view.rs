//! `nelf view ASSET`: the interactive viewer (`nelf_viewer::run_viewer`). The command
//! supplies what the viewer library must not depend on: built-in environment maps
//! (procedural studio, outdoor and indoor skies from `nelf_scene::envgen`, plus every
//! EXR/HDR file of `--envmap-dir`). `--screenshot PATH --frames N --exit` saves the window
//! after N frames and closes it (for scripted checks under Xvfb).

use std::path::PathBuf;

use anyhow::Context as _;
use clap::Args;
use nelf_viewer::{NamedEnvmap, ViewerConfig, run_viewer};

/// Options of `nelf view`.
#[derive(Debug, Args)]
pub struct ViewArgs {
    /// The .nelf asset to show (omit to start empty and drop one on the window).
    pub asset: Option<PathBuf>,
    /// Environment map (EXR or HDR, lat-long) to light the asset with.
    #[arg(long)]
    pub envmap: Option<PathBuf>,
    /// Folder whose EXR/HDR files are offered in the environment-map picker.
    #[arg(long)]
    pub envmap_dir: Option<PathBuf>,
    /// Save a screenshot of the window to this PNG after `--frames` frames.
    #[arg(long)]
    pub screenshot: Option<PathBuf>,
    /// Frames to draw before the screenshot.
    #[arg(long, default_value_t = 3)]
    pub frames: u32,
    /// Close the window once the screenshot is saved.
    #[arg(long, requires = "screenshot")]
    pub exit: bool,
    /// Window size in points, `WIDTHxHEIGHT`.
    #[arg(long, default_value = "1280x800", value_parser = parse_size)]
    pub size: [f32; 2],
}

fn parse_size(text: &str) -> Result<[f32; 2], String> {
    let (w, h) = text
        .split_once(['x', 'X'])
        .ok_or_else(|| format!("{text:?} is not WIDTHxHEIGHT"))?;
    let parse = |s: &str| {
        s.trim()
            .parse::<f32>()
            .ok()
            .filter(|v| v.is_finite() && (64.0..=16384.0).contains(v))
            .ok_or_else(|| format!("{s:?} must be a number of points in 64..=16384"))
    };
    Ok([parse(w)?, parse(h)?])
}

/// Built-in maps: one procedural map per family, then the files of `dir`.
fn builtin_envmaps(dir: Option<&PathBuf>) -> anyhow::Result<Vec<NamedEnvmap>> {
    let mut maps: Vec<NamedEnvmap> = nelf_scene::envgen::builtin_envmaps()
        .into_iter()
        .map(|(name, env)| NamedEnvmap { name, env })
        .collect();
    if let Some(dir) = dir {
        let found = nelf_scene::envmap::envmaps_in_dir(dir).context("cannot list the environment maps")?;
        for (path, env) in found {
            match env {
                Ok(env) => maps.push(NamedEnvmap {
                    name: path.file_name().map_or_else(
                        || path.display().to_string(),
                        |n| n.to_string_lossy().into_owned(),
                    ),
                    env,
                }),
                Err(e) => eprintln!("nelf view: skipping {}: {e}", path.display()),
            }
        }
    }
    Ok(maps)
}

/// Runs `nelf view`.
pub fn run(args: &ViewArgs) -> anyhow::Result<()> {
    let mut config = ViewerConfig::new(args.asset.clone());
    config.envmap_path.clone_from(&args.envmap);
    config.builtin_envmaps = builtin_envmaps(args.envmap_dir.as_ref())?;
    config.screenshot_path.clone_from(&args.screenshot);
    config.screenshot_after_frames = args.frames;
    config.exit_after_screenshot = args.exit;
    config.window_size = args.size;
    run_viewer(config).context("nelf view")
}
