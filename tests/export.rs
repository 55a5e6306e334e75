//! End-to-end tests of `nelf export vdb`: the command writes exactly the bytes of
//! `nelf_export::encode_vdb` for the same asset, lighting and options (an env-map file
//! turned by `--rotate-deg`, and the default built-in studio map), saves its settings
//! and report beside the file, and refuses bad options with clear messages. What the
//! file holds is tested in `export/tests` (vdb-rs and OpenVDB 10 read it back).
#![allow(clippy::unwrap_used)] // Test helpers outside #[test] functions unwrap too.

use std::ffi::OsStr;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use nelf_export::{Compression, Lighting, VdbOptions, encode_vdb};
use nelf_format::synthetic::SyntheticField;
use nelf_format::{Asset, CoefficientEncoding, Coefficients, WriteOptions, write_asset};
use nelf_scene::envgen::{EnvFamily, EnvGenParams, procedural_envmap};

fn nelf<S: AsRef<OsStr>>(args: &[S]) -> Output {
    match Command::new(env!("CARGO_BIN_EXE_nelf"))
        .args(["export", "vdb"])
        .args(args)
        .output()
    {
        Ok(out) => out,
        Err(e) => panic!("cannot run nelf: {e}"),
    }
}

fn write_synthetic(dir: &Path) -> (PathBuf, Asset) {
    let field = SyntheticField::new(6000, 4);
    let pca = field.fit_pca(4, 300);
    let coefficients =
        Coefficients::quantize(&field.project(&pca), 4, CoefficientEncoding::U8Affine).unwrap();
    let asset = field.asset_with(pca, coefficients).unwrap();
    let path = dir.join("head.nelf");
    write_asset(&path, &asset, &WriteOptions::default()).unwrap();
    (path, asset)
}

#[test]
fn exports_what_the_library_encodes() {
    let dir = tempfile::tempdir().unwrap();
    let (asset_path, asset) = write_synthetic(dir.path());

    // An env-map file, turned, uncompressed, centimetres, Houdini's name, rank cut.
    let env_texels: Vec<[f32; 3]> = (0..32 * 16)
        .map(|i| [1.0 + (i % 32) as f32 / 8.0, 0.5 + (i / 32) as f32 / 16.0, 0.25])
        .collect();
    let env_path = dir.path().join("sky.exr");
    nelf_scene::image_io::write_exr_rgb(&env_path, 32, 16, &env_texels).unwrap();
    let out = dir.path().join("head.vdb");
    let run = nelf(&[
        asset_path.as_os_str(),
        "-o".as_ref(),
        out.as_os_str(),
        "--envmap".as_ref(),
        env_path.as_os_str(),
        "--rotate-deg".as_ref(),
        "-40".as_ref(),
        "--rank".as_ref(),
        "3".as_ref(),
        "--scale".as_ref(),
        "100".as_ref(),
        "--color-name".as_ref(),
        "Cd".as_ref(),
        "--compression".as_ref(),
        "none".as_ref(),
    ]);
    assert!(run.status.success(), "{}", String::from_utf8_lossy(&run.stderr));
    let stdout = String::from_utf8(run.stdout).unwrap();
    assert!(stdout.contains("rank 3 of 4"), "{stdout}");
    let env = nelf_scene::envmap::load_envmap(&env_path).unwrap();
    let lighting = Lighting::world(env, -40.0, &env_path.display().to_string());
    let options = VdbOptions {
        scale: 100.0,
        rank: Some(3),
        color_name: "Cd".into(),
        compression: Compression::None,
        pca_grids: nelf_export::vdb::PcaGrids::Float,
    };
    let (want, _) = encode_vdb(&asset, &lighting, &options).unwrap();
    assert!(
        std::fs::read(&out).unwrap() == want,
        "the command's file differs from the library's"
    );

    // The record beside it: the options and the report.
    let record: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("head.vdb.export.json")).unwrap())
            .unwrap();
    assert_eq!(record["config"]["rank"], 3);
    assert_eq!(record["config"]["compression"], "none");
    assert_eq!(record["report"]["file_size"], want.len());
    assert_eq!(record["report"]["density_unit"], "1/cm");
    let grids: Vec<&str> = record["report"]["grids"]
        .as_array()
        .unwrap()
        .iter()
        .map(|g| g["name"].as_str().unwrap())
        .collect();
    assert_eq!(grids, ["density", "Cd", "pca_00", "pca_01", "pca_02"]);
    assert_eq!(
        record["asset_file_size"],
        std::fs::metadata(&asset_path).unwrap().len()
    );

    // Defaults: the built-in studio map (the asset stores no estimated light), metres, zip.
    let out = dir.path().join("default.vdb");
    let run = nelf(&[asset_path.as_os_str(), "-o".as_ref(), out.as_os_str()]);
    assert!(run.status.success(), "{}", String::from_utf8_lossy(&run.stderr));
    let studio = procedural_envmap(
        1,
        &EnvGenParams {
            family: Some(EnvFamily::Studio),
            ..EnvGenParams::default()
        },
    );
    let lighting = Lighting::world(studio, 0.0, "built-in studio map (procedural, seed 1)");
    let (want, _) = encode_vdb(&asset, &lighting, &VdbOptions::default()).unwrap();
    assert!(
        std::fs::read(&out).unwrap() == want,
        "the default export differs from the library's"
    );
}

#[test]
fn refuses_bad_options() {
    let dir = tempfile::tempdir().unwrap();
    let (asset_path, _) = write_synthetic(dir.path());
    let out = dir.path().join("x.vdb");
    for (args, message) in [
        (vec!["--rank", "9"], "the asset has PCA rank 4"),
        (vec!["--scale", "0"], "scale 0 must be finite and positive"),
        (vec!["--color-name", "density"], "colour grid name"),
        (
            vec!["--envmap", "/no/such/map.exr"],
            "cannot load environment map",
        ),
    ] {
        let mut all: Vec<&OsStr> = vec![asset_path.as_os_str(), "-o".as_ref(), out.as_os_str()];
        all.extend(args.iter().map(OsStr::new));
        let run = nelf(&all);
        assert!(!run.status.success(), "{args:?} should fail");
        let stderr = String::from_utf8_lossy(&run.stderr);
        assert!(stderr.contains(message), "{args:?}: {stderr}");
        assert!(!out.exists(), "{args:?} left a file");
    }
    let run = nelf(&["/no/such/asset.nelf"]);
    assert!(!run.status.success());
    assert!(String::from_utf8_lossy(&run.stderr).contains("cannot read /no/such/asset.nelf"));
}
