//! The Blender add-on's math (`export/blender/nelf_relight`: `relight.py`, `vdbmeta.py`,
//! numpy, no Blender) against ours: Debian's Python runs it on maps and files made here.
//!
//! - the light projection equals `nelf_format::conventions::project_envmap` for turns
//!   about +y (the exact rule) and for a general rotation (the splat rule);
//! - the add-on reads a `nelf export vdb` file's metadata (PCA mean, basis, light frame,
//!   grid names) and, with the coefficients of the `pca_NN` grids, relights voxels to
//!   the colour grid's values (`nelf_render::voxel_radiance`);
//! - its frames: a Blender world turned by a Mapping node is the `nelf render --rotate-deg`
//!   it claims; Blender's Environment Texture lookup, written out, agrees with
//!   `ENV_FROM_BLENDER_MAP`;
//! - files it cannot use get errors that say why.
//!
//! Fails (does not skip) when `/usr/bin/python3` lacks numpy: `scripts/test` installs it.
#![allow(clippy::unwrap_used)]

mod common;

use std::path::{Path, PathBuf};
use std::process::Command;

use glam::DMat3;
use nelf_export::vdb::PcaGrids;
use nelf_export::{VdbOptions, write_vdb};
use nelf_format::conventions::{LatLong, project_envmap};
use serde_json::Value;

/// Debian's Python with Debian's numpy (docs/PLATFORM.md).
const PYTHON: &str = "/usr/bin/python3";

fn addon_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("blender/nelf_relight")
}

/// Runs `script` with the add-on's pure-numpy modules importable; returns stdout as JSON.
fn python(script: &str, args: &[&Path]) -> Value {
    let out = Command::new(PYTHON)
        .env("PYTHONPATH", addon_dir())
        .arg("-c")
        .arg(script)
        .args(args)
        .output()
        .unwrap_or_else(|e| {
            panic!("cannot run {PYTHON}: {e}; run ./scripts/test, which installs python3-numpy")
        });
    assert!(
        out.status.success(),
        "{PYTHON} failed (numpy missing? ./scripts/test installs python3-numpy):\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap()
}

/// A deterministic map with texel-to-texel contrast (so a texel off by one shows).
fn test_map(width: usize, height: usize) -> LatLong {
    let mut state = 0x2545_f491_4f6c_dd1d_u64;
    let texels = (0..width * height)
        .map(|_| {
            std::array::from_fn(|_| {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                (state >> 40) as f32 / (1u64 << 24) as f32 * 4.0
            })
        })
        .collect();
    LatLong::new(width, height, texels).unwrap()
}

fn write_map(map: &LatLong, path: &Path) {
    let bytes: Vec<u8> = map
        .texels()
        .iter()
        .flatten()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    std::fs::write(path, bytes).unwrap();
}

fn rows(m: DMat3) -> Vec<Vec<f64>> {
    (0..3).map(|r| (0..3).map(|c| m.col(c)[r]).collect()).collect()
}

#[test]
fn projection_matches_ours_for_turns_and_general_rotations() {
    compare_projection(&test_map(40, 20), 1e-6);
}

#[test]
fn projection_matches_ours_on_a_real_hdri() {
    // A real map of the repository (data/envmaps, its own licence), with its sun and sky.
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../data/envmaps/forest.exr");
    let map = nelf_scene::envmap::load_envmap(&path).unwrap();
    // The same pieces land in the same texels here: equal to f32 rounding.
    compare_projection(&map, 1e-6);
}

/// The add-on's projection of `map` against `project_envmap`, under turns about +y (exact
/// rule, relative error ≤ 1e-6) and a general rotation (splat rule, ≤ `splat_tolerance`).
fn compare_projection(map: &LatLong, splat_tolerance: f64) {
    let dir = tempfile::tempdir().unwrap();
    let map_path = dir.path().join("map.f32");
    write_map(map, &map_path);
    let rotations = [
        ("identity", DMat3::IDENTITY),
        ("turn 37 deg", DMat3::from_rotation_y(37f64.to_radians())),
        ("turn -90 deg", DMat3::from_rotation_y(-90f64.to_radians())),
        (
            "general",
            DMat3::from_rotation_x(0.5) * DMat3::from_rotation_y(0.3),
        ),
    ];
    let spec: Vec<Value> = rotations
        .iter()
        .map(|(_, m)| serde_json::json!(rows(*m)))
        .collect();
    let spec_path = dir.path().join("rotations.json");
    std::fs::write(&spec_path, serde_json::to_vec(&spec).unwrap()).unwrap();
    let got = python(
        r#"
import json, sys
import numpy as np
import relight
rotations = json.load(open(sys.argv[2]))
texels = np.fromfile(sys.argv[1], dtype="<f4").reshape(int(sys.argv[3]), int(sys.argv[4]), 3)
json.dump([relight.project_envmap(texels, np.array(r)).tolist() for r in rotations], sys.stdout)
"#,
        &[
            &map_path,
            &spec_path,
            Path::new(&map.height().to_string()),
            Path::new(&map.width().to_string()),
        ],
    );
    for ((what, m), python_light) in rotations.iter().zip(got.as_array().unwrap()) {
        let ours = project_envmap(map, *m).unwrap();
        let mut worst = 0.0f64;
        for (t, rgb) in ours.texels().iter().enumerate() {
            for (c, v) in rgb.iter().enumerate() {
                let theirs = python_light[t][c].as_f64().unwrap();
                worst = worst.max((theirs - f64::from(*v)).abs() / f64::from(v.abs()).max(1e-3));
            }
        }
        // Rule a is exact (f64 sums in another order); rule b's pieces land in the same
        // texels but for ties on an edge (none on these maps: both agree to f32 rounding).
        let tolerance = if *what == "general" { splat_tolerance } else { 1e-6 };
        assert!(
            worst <= tolerance,
            "{what}: the add-on's projection is off by {worst:e} (relative)"
        );
    }
}

#[test]
fn addon_reads_the_metadata_and_relights_to_the_colour_grid() {
    relights_to_the_colour_grid(PcaGrids::Float);
}

#[test]
fn addon_reads_vec3_coefficient_grids_too() {
    relights_to_the_colour_grid(PcaGrids::Vec3);
}

fn relights_to_the_colour_grid(pca_grids: PcaGrids) {
    let dir = tempfile::tempdir().unwrap();
    let asset = common::asset();
    let lighting = common::lighting();
    let vdb = dir.path().join("asset.vdb");
    let options = VdbOptions {
        pca_grids,
        ..VdbOptions::default()
    };
    write_vdb(&vdb, &asset, &lighting, &options).unwrap();
    let expected = common::expected(&asset, &lighting, asset.rank(), 1.0);
    // The lighting's map and turn, and a few voxels' coefficients, for the add-on.
    let nelf_export::Lighting::World {
        env, world_from_env, ..
    } = &lighting
    else {
        panic!("test lighting is a world map");
    };
    let map_path = dir.path().join("map.f32");
    write_map(env, &map_path);
    let voxels: Vec<Value> = expected
        .color
        .keys()
        .step_by(97)
        .map(|ijk| {
            let c: Vec<f32> = expected.pca.iter().map(|g| g[ijk]).collect();
            serde_json::json!({"ijk": ijk, "c": c})
        })
        .collect();
    let input = serde_json::json!({
        "width": env.width(), "height": env.height(),
        "world_from_env": rows(*world_from_env), "voxels": voxels,
    });
    let input_path = dir.path().join("input.json");
    std::fs::write(&input_path, serde_json::to_vec(&input).unwrap()).unwrap();
    let got = python(
        r#"
import json, sys
import numpy as np
import relight, vdbmeta
asset = vdbmeta.read_nelf_vdb(sys.argv[1])
spec = json.load(open(sys.argv[3]))
texels = np.fromfile(sys.argv[2], dtype="<f4").reshape(spec["height"], spec["width"], 3)
e = np.array(spec["world_from_env"]).T @ np.array(asset.world_from_light)
p_mean, p = relight.relight_terms(asset.mean, asset.basis, relight.project_envmap(texels, e))
out = {"grids": asset.pca_grids, "per_grid": asset.components_per_grid, "rank": asset.rank,
       "density": asset.density_grid, "color": asset.color_grid,
       "voxel_size": asset.voxel_size, "mean0": asset.mean[0], "radiance": []}
for v in spec["voxels"]:
    out["radiance"].append((p_mean + np.array(v["c"]) @ p).tolist())
json.dump(out, sys.stdout)
"#,
        &[&vdb, &map_path, &input_path],
    );
    assert_eq!(got["grids"], serde_json::json!(pca_grids.names(asset.rank())));
    assert_eq!(got["rank"], asset.rank());
    assert_eq!(got["per_grid"], if pca_grids == PcaGrids::Vec3 { 3 } else { 1 });
    assert_eq!(got["density"], "density");
    assert_eq!(got["color"], "color");
    assert_eq!(got["voxel_size"].as_f64().unwrap(), asset.grid.voxel_size_m);
    assert_eq!(got["mean0"].as_f64().unwrap() as f32, asset.pca.mean[0]);
    let radiance = got["radiance"].as_array().unwrap();
    assert!(radiance.len() >= 10, "too few voxels checked: {}", radiance.len());
    for (ijk, theirs) in expected.color.keys().step_by(97).zip(radiance) {
        let ours = expected.color[ijk];
        for c in 0..3 {
            let t = theirs[c].as_f64().unwrap();
            let o = f64::from(ours[c]);
            assert!(
                (t - o).abs() <= 2e-5 * o.abs().max(1e-2),
                "voxel {ijk:?} channel {c}: the add-on relights to {t}, the colour grid holds {o}"
            );
        }
    }
}

#[test]
fn blender_frames_agree_with_nelf_render_turns() {
    // Blender's Environment Texture (Cycles' equirectangular lookup): u = 1/2 − atan2(y, x)/2π,
    // v = 1/2 + asin(z)/π. For directions d_B, the texel it reads must be the texel our
    // lat-long convention reads for ENV_FROM_BLENDER_MAP · d_B; and a world turned by a
    // Mapping node about Z by β is `nelf render --rotate-deg −(β + 90)` for an asset the
    // add-on imported (stood up by +90° about X).
    let got = python(
        r#"
import json, math, sys
import numpy as np
import relight
rng = np.random.default_rng(7)
d = rng.normal(size=(2000, 3))
d /= np.linalg.norm(d, axis=1)[:, None]
W, H = 64, 32
u = 0.5 - np.arctan2(d[:, 1], d[:, 0]) / (2 * math.pi)
v = 0.5 + np.arcsin(d[:, 2]) / math.pi
blender_col = np.floor(np.mod(u, 1.0) * W).astype(int) % W
blender_row_from_top = np.clip(H - 1 - np.floor(v * H).astype(int), 0, H - 1)
e = d @ relight.ENV_FROM_BLENDER_MAP.T
theta = np.arccos(np.clip(e[:, 1], -1, 1))
phi = np.arctan2(e[:, 0], -e[:, 2])
our_col = np.floor((phi + math.pi) / (2 * math.pi) * W).astype(int) % W
our_row = np.clip(np.floor(theta / math.pi * H).astype(int), 0, H - 1)
agree = float(np.mean((our_col == blender_col) & (our_row == blender_row_from_top)))
turns = {}
for beta in (0.0, 30.0, 90.0, -45.0):
    wfl = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])
    e = relight.env_from_light_in_blender(wfl, relight.BLENDER_FROM_NELF, relight.rotation_to_blender_euler_z(beta))
    turns[str(beta)] = relight.nelf_rotate_deg(e, wfl)
json.dump({"agree": agree, "turns": turns}, sys.stdout)
"#,
        &[],
    );
    // Directions on a texel edge may round either way.
    assert!(got["agree"].as_f64().unwrap() > 0.995, "{got}");
    for (beta, alpha) in got["turns"].as_object().unwrap() {
        let beta: f64 = beta.parse().unwrap();
        let alpha = alpha.as_f64().unwrap();
        let want = -(beta + 90.0);
        let d = (alpha - want).rem_euclid(360.0);
        assert!(
            d.min(360.0 - d) < 1e-9,
            "Mapping Z {beta}: rotate {alpha}, want {want}"
        );
    }
}

#[test]
fn files_it_cannot_use_get_errors_that_say_why() {
    let dir = tempfile::tempdir().unwrap();
    let not_vdb = dir.path().join("head.nelf.vdb");
    std::fs::write(&not_vdb, b"NELF this is not an OpenVDB file at all").unwrap();
    let vdb = dir.path().join("asset.vdb");
    write_vdb(
        &vdb,
        &common::asset(),
        &common::lighting(),
        &VdbOptions::default(),
    )
    .unwrap();
    let bytes = std::fs::read(&vdb).unwrap();
    let truncated = dir.path().join("truncated.vdb");
    std::fs::write(&truncated, &bytes[..200]).unwrap();
    // An OpenVDB file without our keys: the same header, no metadata entries.
    let foreign = dir.path().join("foreign.vdb");
    let mut plain = bytes[..8 + 12 + 1 + 36].to_vec();
    plain.extend_from_slice(&0u32.to_le_bytes());
    std::fs::write(&foreign, plain).unwrap();
    let got = python(
        r#"
import json, sys
import vdbmeta
out = []
for path in sys.argv[1:]:
    try:
        vdbmeta.read_nelf_vdb(path)
        out.append("read")
    except vdbmeta.VdbMetaError as err:
        out.append(str(err))
json.dump(out, sys.stdout)
"#,
        &[&not_vdb, &truncated, &foreign],
    );
    let messages: Vec<&str> = got
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_str().unwrap())
        .collect();
    assert!(messages[0].contains("not an OpenVDB file"), "{}", messages[0]);
    assert!(messages[1].contains("file ends inside"), "{}", messages[1]);
    assert!(
        messages[2].contains("nelf_vdb_layout") && messages[2].contains("nelf export vdb"),
        "{}",
        messages[2]
    );
    for (m, path) in messages.iter().zip([&not_vdb, &truncated, &foreign]) {
        assert!(
            m.contains(&*path.to_string_lossy()),
            "the message names the file: {m}"
        );
    }
}

/// The add-on reads a fine density's factor (file metadata `nelf_density_factor`), says on
/// import how far Cycles shows that grid from `nelf render`'s placement (½ − 1/(2F) voxel:
/// Cycles offsets each grid by half of its own voxel), says nothing for a file without
/// one, and refuses a factor the format does not have.
#[test]
fn addon_reads_the_fine_density_factor() {
    let dir = tempfile::tempdir().unwrap();
    let coarse = common::asset();
    let lighting = common::lighting();
    let mut paths = Vec::new();
    for (name, asset) in [
        ("coarse.vdb", coarse.clone()),
        ("fine2.vdb", common::with_fine_density(coarse.clone(), 2)),
        ("fine4.vdb", common::with_fine_density(coarse.clone(), 4)),
    ] {
        let path = dir.path().join(name);
        write_vdb(&path, &asset, &lighting, &VdbOptions::default()).unwrap();
        paths.push(path);
    }
    let (mut file, _) = nelf_export::build_vdb(&coarse, &lighting, &VdbOptions::default()).unwrap();
    file.insert_meta("nelf_density_factor", 3);
    let bad = dir.path().join("bad.vdb");
    std::fs::write(&bad, file.encode(nelf_export::Compression::None).unwrap()).unwrap();
    paths.push(bad);
    let args: Vec<&Path> = paths.iter().map(PathBuf::as_path).collect();
    let got = python(
        r#"
import json, sys
import vdbmeta
out = []
for path in sys.argv[1:]:
    try:
        a = vdbmeta.read_nelf_vdb(path)
        out.append({"factor": a.density_factor, "offset": a.density_offset_voxels,
                    "warning": a.placement_warning(), "voxel_size": a.voxel_size})
    except vdbmeta.VdbMetaError as err:
        out.append({"error": str(err)})
json.dump(out, sys.stdout)
"#,
        &args,
    );
    let voxel = coarse.grid.voxel_size_m;
    assert_eq!(got[0]["factor"], 1);
    assert_eq!(got[0]["offset"].as_f64(), Some(0.0));
    assert!(got[0]["warning"].is_null(), "{}", got[0]);
    for (g, factor, offset) in [(&got[1], 2, 0.25), (&got[2], 4, 0.375)] {
        assert_eq!(g["factor"], factor);
        assert_eq!(g["offset"].as_f64(), Some(offset));
        // The object is still moved by half a voxel of the coefficient grids.
        assert_eq!(g["voxel_size"].as_f64(), Some(voxel));
        let warning = g["warning"].as_str().unwrap();
        assert!(
            warning.contains(&format!("{factor} times finer"))
                && warning.contains(&format!("lies {offset} voxel")),
            "{warning}"
        );
    }
    let error = got[3]["error"].as_str().unwrap();
    assert!(error.contains("nelf_density_factor 3"), "{error}");
}
