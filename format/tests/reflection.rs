//! The reflection part (format 1.3, `VREF`/`VRCO`): round trip, version, brick access
//! and the rule of one view-dependent part per file.
#![allow(clippy::unwrap_used)] // Test helpers outside #[test] functions unwrap too.

use nelf_format::spec::{KIND_REFLECTION, KIND_REFLECTION_VALUES, VERSION_MINOR_REFLECTION};
use nelf_format::synthetic::{SyntheticField, synthetic_reflection, synthetic_view};
use nelf_format::{AssetReader, CoefficientEncoding, WriteOptions, encode_asset, read_asset_bytes};

fn asset_with_reflection() -> nelf_format::Asset {
    let mut asset = SyntheticField::new(4096, 7)
        .asset(6, CoefficientEncoding::U8Affine)
        .unwrap();
    asset.reflection = Some(synthetic_reflection(&asset, 20.0, 3).unwrap());
    asset
}

#[test]
fn a_reflection_part_round_trips_as_version_1_3_with_optional_sections() {
    let asset = asset_with_reflection();
    let (bytes, sections) = encode_asset(&asset, &WriteOptions::default()).unwrap();
    assert_eq!(
        u16::from_le_bytes([bytes[10], bytes[11]]),
        VERSION_MINOR_REFLECTION
    );
    assert_eq!(VERSION_MINOR_REFLECTION, 3);
    for kind in [KIND_REFLECTION, KIND_REFLECTION_VALUES] {
        let entry = sections.iter().find(|s| s.kind == kind).unwrap();
        assert!(!entry.required, "{kind:?} must be optional");
    }
    let back = read_asset_bytes(&bytes).unwrap();
    assert_eq!(back, asset);
    // Brick by brick: the same dequantized values.
    let mut reader = AssetReader::new(std::io::Cursor::new(bytes)).unwrap();
    let part = reader.reflection_params().unwrap().clone();
    assert_eq!(part.exponent, 20.0);
    assert_eq!(part.eyes_m.len(), 5);
    let stored = asset.reflection.as_ref().unwrap();
    for index in [0, asset.bricks.len() / 2, asset.bricks.len() - 1] {
        let brick = reader.read_brick(index).unwrap();
        assert_eq!(brick.reflection.len(), 512 * 3);
        assert!(brick.view_coefficients.is_empty());
        let mut want = [0.0f32; 3];
        for local in [0, 100, 511] {
            stored.coefficients.voxel_f32(index * 512 + local, &mut want);
            assert_eq!(&brick.reflection[local * 3..local * 3 + 3], &want);
        }
    }
    // Normals decode to unit vectors; scales are never negative.
    for v in (0..asset.voxel_count()).step_by(97) {
        let (n, s) = stored.voxel(v);
        let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
        assert!((len - 1.0).abs() < 1e-5 && s >= 0.0);
    }
}

#[test]
fn an_asset_holds_at_most_one_view_dependent_part() {
    let mut asset = asset_with_reflection();
    asset.view = Some(synthetic_view(&asset, 2, 3, CoefficientEncoding::U8Affine, 1).unwrap());
    let err = encode_asset(&asset, &WriteOptions::default()).unwrap_err();
    assert!(err.to_string().contains("at most one"), "{err}");
}

#[test]
fn bad_reflection_parameters_are_refused_with_the_section_named() {
    let mut asset = asset_with_reflection();
    let part = asset.reflection.as_mut().unwrap();
    part.exponent = 0.5;
    let err = encode_asset(&asset, &WriteOptions::default()).unwrap_err();
    assert!(err.to_string().contains("VREF"), "{err}");
    let mut asset = asset_with_reflection();
    asset.reflection.as_mut().unwrap().eyes_m.clear();
    let err = encode_asset(&asset, &WriteOptions::default()).unwrap_err();
    assert!(err.to_string().contains("eyes"), "{err}");
}
