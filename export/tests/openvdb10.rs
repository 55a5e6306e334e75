//! OpenVDB 10 itself reads our files: Debian's `pyopenvdb` (package `python3-openvdb`,
//! which `scripts/test` installs) loads each file with `readAll`, and a Python script
//! dumps every grid's type, class, active voxel count and bounding box, transform,
//! metadata, every active value and their sums. Counts and values must equal what the
//! asset holds — the colour grid must equal `nelf-render`'s relit voxel radiance bit
//! for bit — and the file metadata must carry the PCA mean and basis exactly.
//!
//! Without `pyopenvdb` these tests FAIL (they do not skip): CI must read our files with
//! OpenVDB.
#![allow(clippy::unwrap_used)]

mod common;

use std::collections::BTreeMap;
use std::path::Path;
use std::process::Command;

use nelf_export::{Compression, Lighting, VdbOptions, write_vdb};
use serde_json::Value;

/// Debian's Python, the one that imports Debian's Python packages (docs/PLATFORM.md).
const PYTHON: &str = "/usr/bin/python3";

/// Dumps an OpenVDB file as JSON on stdout.
const DUMP: &str = r#"
import json, math, sys
import pyopenvdb as vdb

def plain(v):
    return list(v) if isinstance(v, tuple) else v

grids, meta = vdb.readAll(sys.argv[1])
out = {"library": list(vdb.LIBRARY_VERSION), "file_metadata": {k: plain(v) for k, v in meta.items()}, "grids": []}
for g in grids:
    values, tiles, sums = [], 0, None
    for item in g.citerOnValues():
        if item.count != 1:
            tiles += 1
            continue
        v = item.value
        v = list(v) if isinstance(v, tuple) else [v]
        values.append(list(item.min) + v)
    channels = len(values[0]) - 3 if values else 0
    sums = [math.fsum(row[3 + c] for row in values) for c in range(channels)]
    t = g.transform
    out["grids"].append({
        "name": g.name,
        "value_type": g.valueTypeName,
        "class": str(g.gridClass),
        "active": g.activeVoxelCount(),
        "bbox": [list(c) for c in g.evalActiveVoxelBoundingBox()],
        "tiles": tiles,
        "voxel_size": list(t.voxelSize()),
        "index_origin_world": list(t.indexToWorld((0, 0, 0))),
        "index_one_world": list(t.indexToWorld((1, 1, 1))),
        "metadata": {k: plain(v) for k, v in g.metadata.items()},
        "values": values,
        "sums": sums,
    })
json.dump(out, sys.stdout)
"#;

/// Fails, with what to install, when OpenVDB's Python module is missing.
fn require_pyopenvdb() {
    let ok = Command::new(PYTHON)
        .args(["-c", "import pyopenvdb"])
        .output()
        .is_ok_and(|o| o.status.success());
    assert!(
        ok,
        "`{PYTHON} -c \"import pyopenvdb\"` fails: these tests read our .vdb files with OpenVDB 10 \
         through Debian's python3-openvdb. Run ./scripts/test (it installs the package as root) or \
         `apt-get install -y python3-openvdb`."
    );
}

fn dump(path: &Path) -> Value {
    let out = Command::new(PYTHON)
        .arg("-c")
        .arg(DUMP)
        .arg(path)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "OpenVDB could not read {}: {}",
        path.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap()
}

fn f32s(v: &Value) -> Vec<f32> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap() as f32)
        .collect()
}

/// Checks one grid of the dump against expected values by index coordinate.
fn check_grid<const N: usize>(
    grid: &Value,
    name: &str,
    value_type: &str,
    want: &BTreeMap<[i32; 3], [f32; N]>,
) {
    assert_eq!(grid["name"], name);
    assert_eq!(grid["value_type"], value_type, "{name}");
    assert_eq!(grid["tiles"], 0, "{name}: no active tiles");
    assert_eq!(
        grid["active"].as_u64().unwrap(),
        want.len() as u64,
        "{name}: active voxel count"
    );
    assert_eq!(
        grid["metadata"]["file_voxel_count"].as_u64().unwrap(),
        want.len() as u64
    );
    let mut got = BTreeMap::new();
    for row in grid["values"].as_array().unwrap() {
        let row = row.as_array().unwrap();
        let ijk: [i32; 3] = std::array::from_fn(|a| row[a].as_i64().unwrap() as i32);
        let value: [f32; N] = std::array::from_fn(|c| row[3 + c].as_f64().unwrap() as f32);
        assert!(got.insert(ijk, value).is_none(), "{name}: {ijk:?} twice");
    }
    if let Some((ijk, v)) = want.iter().find(|(ijk, v)| got.get(*ijk) != Some(*v)) {
        panic!(
            "{name}: at {ijk:?} OpenVDB reads {:?}, expected {v:?}",
            got.get(ijk)
        );
    }
    assert_eq!(got.len(), want.len());
    // Sums, as OpenVDB's reader saw them, against the asset's.
    let sums = f32s(&grid["sums"]);
    for (c, sum) in sums.iter().enumerate() {
        let mut exact = 0.0f64;
        let mut magnitude = 0.0f64;
        for v in want.values() {
            exact += f64::from(v[c]);
            magnitude += f64::from(v[c]).abs();
        }
        assert!(
            (f64::from(*sum) - exact).abs() <= 1e-6 * magnitude + 1e-30,
            "{name} channel {c}: sum {sum} vs {exact}"
        );
    }
    // Index bounding box.
    let lo: [i32; 3] = std::array::from_fn(|a| want.keys().map(|k| k[a]).min().unwrap());
    let hi: [i32; 3] = std::array::from_fn(|a| want.keys().map(|k| k[a]).max().unwrap());
    assert_eq!(grid["bbox"], serde_json::json!([lo, hi]), "{name}");
}

fn scalar(map: &BTreeMap<[i32; 3], f32>) -> BTreeMap<[i32; 3], [f32; 1]> {
    map.iter().map(|(k, v)| (*k, [*v])).collect()
}

fn check(options: &VdbOptions, lighting: &Lighting) {
    require_pyopenvdb();
    let asset = common::asset();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("head.vdb");
    let report = write_vdb(&path, &asset, lighting, options).unwrap();
    let rank = options.rank.unwrap_or(asset.rank());
    let want = common::expected(&asset, lighting, rank, options.scale);
    let got = dump(&path);
    assert_eq!(
        got["library"],
        serde_json::json!([10, 0, 1]),
        "the OpenVDB that read the file"
    );

    // readAll does not keep the file's grid order: find grids by name.
    let grids = got["grids"].as_array().unwrap();
    assert_eq!(grids.len(), 2 + rank);
    assert_eq!(report.grids.len(), grids.len());
    let by_name = |name: &str| {
        let found: Vec<&Value> = grids.iter().filter(|g| g["name"] == name).collect();
        assert_eq!(found.len(), 1, "one grid named {name}");
        found[0]
    };
    let density = by_name("density");
    check_grid(density, "density", "float", &scalar(&want.density));
    assert_eq!(density["class"], "fog volume");
    assert_eq!(density["metadata"]["nelf_unit"], options.density_unit());
    check_grid(
        by_name(&options.color_name),
        &options.color_name,
        "vec3s",
        &want.color,
    );
    for k in 0..rank {
        let name = format!("pca_{k:02}");
        check_grid(by_name(&name), &name, "float", &scalar(&want.pca[k]));
    }

    // Transform: voxel size and the world position of index (0, 0, 0) and (1, 1, 1).
    let s = options.scale;
    let voxel = asset.grid.voxel_size_m;
    for grid in grids {
        let origin = f32s(&grid["index_origin_world"]);
        let one = f32s(&grid["index_one_world"]);
        for a in 0..3 {
            let o = s * (asset.grid.bbox_min_m[a] + 0.5 * voxel);
            assert!((f64::from(origin[a]) - o).abs() < 1e-6 * s, "{}", grid["name"]);
            assert!((f64::from(one[a]) - (o + s * voxel)).abs() < 1e-6 * s);
            assert!((grid["voxel_size"][a].as_f64().unwrap() - s * voxel).abs() < 1e-12 * s);
        }
    }

    // File metadata: the PCA model exactly, the light frame, the convention.
    let meta = &got["file_metadata"];
    assert_eq!(meta["nelf_pca_rank"], rank);
    assert_eq!(meta["nelf_pca_stored_rank"], asset.rank());
    let mean: Vec<f32> = serde_json::from_str(meta["nelf_pca_mean"].as_str().unwrap()).unwrap();
    assert_eq!(mean, asset.pca.mean);
    let basis: Vec<Vec<f32>> = serde_json::from_str(meta["nelf_pca_basis"].as_str().unwrap()).unwrap();
    assert_eq!(basis.len(), rank);
    for (k, b) in basis.iter().enumerate() {
        assert_eq!(b.as_slice(), asset.pca.component(k));
    }
    let rows: [[f64; 3]; 3] = serde_json::from_str(meta["nelf_world_from_light"].as_str().unwrap()).unwrap();
    for (r, row) in rows.iter().enumerate() {
        assert_eq!(*row, asset.world_from_light.row(r).to_array());
    }
    assert_eq!(
        (meta["nelf_env_height"].as_u64(), meta["nelf_env_width"].as_u64()),
        (Some(8), Some(16))
    );
    assert!(
        meta["nelf_envmap_convention"]
            .as_str()
            .unwrap()
            .contains("lat-long 8x16")
    );
    assert_eq!(meta["nelf_color_lighting"], lighting.name());
    assert_eq!(meta["nelf_color_grid"], options.color_name.as_str());
}

#[test]
fn openvdb_reads_the_default_export() {
    check(&VdbOptions::default(), &common::lighting());
}

#[test]
fn openvdb_reads_a_raw_scaled_cut_houdini_export() {
    check(
        &VdbOptions {
            scale: 100.0,
            rank: Some(2),
            color_name: "Cd".into(),
            compression: Compression::None,
            pca_grids: nelf_export::vdb::PcaGrids::Float,
        },
        &common::white(),
    );
}

/// Reads the `density` grid of `path` at world points: OpenVDB's `worldToIndex` of each
/// (density and `pca_00`), the voxel it falls in and the density's value there.
const PROBE: &str = r#"
import json, sys
import pyopenvdb as vdb
density = vdb.read(sys.argv[1], "density")
pca = vdb.read(sys.argv[1], "pca_00")
acc = density.getConstAccessor()
out = {"voxel_size": list(density.transform.voxelSize()),
       "pca_voxel_size": list(pca.transform.voxelSize()), "points": []}
for p in json.load(open(sys.argv[2])):
    ijk = density.transform.worldToIndexCellCentered(tuple(p))
    out["points"].append({"index": list(density.transform.worldToIndex(tuple(p))),
                          "ijk": list(ijk), "value": acc.getValue(ijk),
                          "pca_index": list(pca.transform.worldToIndex(tuple(p)))})
json.dump(out, sys.stdout)
"#;

/// A fine density (format 1.4): OpenVDB reads the `density` grid at voxel size `Δ/F` with
/// every fine value, the other grids at `Δ` unchanged, and at the world centre of a fine
/// voxel (SPEC.md §6) finds an integer index holding that voxel's σ / scale, which the
/// coefficient grids see between their voxels, `(i + ½)/F − ½` along each axis.
#[test]
fn openvdb_reads_a_fine_density_at_its_own_voxel_size() {
    require_pyopenvdb();
    let factor = 2;
    let asset = common::with_fine_density(common::asset(), factor);
    let options = VdbOptions {
        scale: 100.0,
        ..VdbOptions::default()
    };
    let s = options.scale;
    let lighting = common::white();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("fine.vdb");
    write_vdb(&path, &asset, &lighting, &options).unwrap();
    let got = dump(&path);
    let grids = got["grids"].as_array().unwrap();
    let by_name = |name: &str| grids.iter().find(|g| g["name"] == name).unwrap();

    let density = by_name("density");
    let fine = common::expected_fine_density(&asset, s);
    check_grid(density, "density", "float", &scalar(&fine));
    assert_eq!(density["class"], "fog volume");
    assert_eq!(density["metadata"]["nelf_density_factor"], factor);
    assert_eq!(got["file_metadata"]["nelf_density_factor"], factor);
    let want = common::expected(&asset, &lighting, asset.rank(), s);
    check_grid(by_name("pca_00"), "pca_00", "float", &scalar(&want.pca[0]));
    let fine_voxel = asset.grid.voxel_size_m / f64::from(factor);
    for a in 0..3 {
        let origin = s * (asset.grid.bbox_min_m[a] + 0.5 * fine_voxel);
        let read = density["index_origin_world"][a].as_f64().unwrap();
        assert!((read - origin).abs() < 1e-9 * s, "{read} vs {origin}");
        assert!((density["voxel_size"][a].as_f64().unwrap() - s * fine_voxel).abs() < 1e-12 * s);
        let pca = by_name("pca_00")["voxel_size"][a].as_f64().unwrap();
        assert!((pca - s * asset.grid.voxel_size_m).abs() < 1e-12 * s);
    }

    // Known world points: SPEC's centres of a few fine voxels.
    let edge = 8 * factor as usize;
    let mut points = Vec::new();
    let mut wanted = Vec::new();
    for (b, brick) in asset.bricks.iter().enumerate().step_by(3) {
        for ijk in [[0, 0, 0], [edge - 1, 2, 5], [7, edge - 1, 8]] {
            points.push(common::fine_voxel_centre(&asset, *brick, ijk, s));
            let index: [i32; 3] = std::array::from_fn(|a| edge as i32 * i32::from(brick[a]) + ijk[a] as i32);
            let fine = asset.fine_density.as_ref().unwrap();
            let v = b * fine.voxels_per_brick() + ijk[0] + edge * (ijk[1] + edge * ijk[2]);
            let sigma = (f64::from(fine.values[v].to_f32()) / s) as f32;
            let coarse: [f64; 3] = std::array::from_fn(|a| {
                8.0 * f64::from(brick[a]) + (ijk[a] as f64 + 0.5) / f64::from(factor) - 0.5
            });
            wanted.push((index, sigma, coarse));
        }
    }
    let points_path = dir.path().join("points.json");
    std::fs::write(&points_path, serde_json::to_vec(&points).unwrap()).unwrap();
    let out = Command::new(PYTHON)
        .arg("-c")
        .arg(PROBE)
        .arg(&path)
        .arg(&points_path)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let probe: Value = serde_json::from_slice(&out.stdout).unwrap();
    for a in 0..3 {
        let size = probe["voxel_size"][a].as_f64().unwrap();
        assert!((size - s * fine_voxel).abs() < 1e-12 * s, "voxel size {size}");
    }
    let read = probe["points"].as_array().unwrap();
    assert_eq!(read.len(), wanted.len());
    for (p, (index, sigma, coarse)) in read.iter().zip(&wanted) {
        for a in 0..3 {
            let i = p["index"][a].as_f64().unwrap();
            assert!((i - f64::from(index[a])).abs() < 1e-6, "{p} vs {index:?}");
            assert_eq!(p["ijk"][a].as_i64().unwrap(), i64::from(index[a]), "{p}");
            let c = p["pca_index"][a].as_f64().unwrap();
            assert!(
                (c - coarse[a]).abs() < 1e-6,
                "{p}: coefficient index {c} vs {}",
                coarse[a]
            );
        }
        assert_eq!(p["value"].as_f64().unwrap() as f32, *sigma, "{p}");
    }
}
