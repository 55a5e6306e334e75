//! End-to-end test of `nelf inspect`: a synthetic asset is written, inspected as text
//! and as JSON, and a damaged copy makes the command fail with a clear message.

use std::process::Command;

use nelf_format::synthetic::SyntheticField;
use nelf_format::{CoefficientEncoding, WriteOptions, write_asset};

fn nelf(args: &[&std::ffi::OsStr]) -> std::process::Output {
    match Command::new(env!("CARGO_BIN_EXE_nelf")).args(args).output() {
        Ok(out) => out,
        Err(e) => panic!("cannot run nelf: {e}"),
    }
}

#[test]
fn inspect_prints_text_and_json_and_rejects_damage() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("head.nelf");
    let asset = SyntheticField::new(3000, 7)
        .asset(6, CoefficientEncoding::U8Affine)
        .unwrap();
    let report = write_asset(&path, &asset, &WriteOptions::default()).unwrap();

    let out = nelf(&["inspect".as_ref(), path.as_os_str()]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let text = String::from_utf8(out.stdout).unwrap();
    for needle in [
        "format:            .nelf v1.1".to_string(),
        format!("bricks:            {}", asset.bricks.len()),
        format!("voxels:            {}", asset.voxel_count()),
        "PCA rank:          6".to_string(),
        "coefficients:      u8-affine".to_string(),
        "checksums:         all verified".to_string(),
        "COEF".to_string(),
        "QPRM".to_string(),
        "nelf_format::synthetic".to_string(),
    ] {
        assert!(text.contains(&needle), "missing {needle:?} in:\n{text}");
    }

    let out = nelf(&["inspect".as_ref(), "--json".as_ref(), path.as_os_str()]);
    assert!(out.status.success());
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(json["version"], "1.1");
    assert_eq!(json["pca_rank"], 6);
    assert_eq!(json["brick_count"], asset.bricks.len());
    assert_eq!(json["voxel_count"], asset.voxel_count());
    assert_eq!(json["file_size"], report.file_size);
    assert_eq!(json["coefficient_encoding"], "u8-affine");
    assert_eq!(json["metadata"], asset.metadata);
    let sections = json["sections"].as_array().unwrap();
    assert_eq!(sections.len(), report.sections.len());
    let coef = sections.iter().find(|s| s["kind"] == "COEF").unwrap();
    let want = report.sections.iter().find(|s| s.name() == "COEF").unwrap();
    assert_eq!(coef["stored_bytes"], want.stored_length);
    assert_eq!(coef["raw_bytes"], want.raw_length);
    assert_eq!(coef["codec"], "chunked-zstd");
    for (a, b) in json["bbox_max_m"]
        .as_array()
        .unwrap()
        .iter()
        .zip(asset.grid.bbox_max_m())
    {
        assert!((a.as_f64().unwrap() - b).abs() < 1e-12);
    }

    // Flip one byte inside the coefficient section: non-zero exit naming the damage.
    let mut bytes = std::fs::read(&path).unwrap();
    let at = (want.offset + want.stored_length / 2) as usize;
    bytes[at] ^= 0x10;
    let damaged = dir.path().join("damaged.nelf");
    std::fs::write(&damaged, &bytes).unwrap();
    let out = nelf(&["inspect".as_ref(), damaged.as_os_str()]);
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("damaged.nelf"), "{stderr}");
    assert!(stderr.contains("checksum mismatch in section COEF"), "{stderr}");

    // Truncated and missing files fail clearly too.
    std::fs::write(&damaged, &bytes[..bytes.len() / 2]).unwrap();
    let out = nelf(&["inspect".as_ref(), damaged.as_os_str()]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("truncated"));
    let out = nelf(&["inspect".as_ref(), dir.path().join("missing.nelf").as_os_str()]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("missing.nelf"));
}
