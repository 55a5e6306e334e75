//! Damaged and hostile `.nelf` files: truncations at every boundary and at random
//! offsets, bit flips in every section, hand-made hostile headers and sections (the
//! view-dependent parts of formats 1.2 and 1.3 and the fine density of 1.4 included), and a
//! seeded mini-fuzzer (all made by `common::damage`, which `c_reader.rs` shares). Every
//! case must give a typed error naming the problem (never a panic); the allocation
//! bound is checked in `alloc.rs`.
#![allow(clippy::unwrap_used)] // Test helpers outside #[test] functions unwrap too.

mod common;

use std::io::Cursor;
use std::panic::{AssertUnwindSafe, catch_unwind};

use common::damage::{self, Damaged, Expect};
use nelf_format::spec::{SectionCodec, SectionEntry};
use nelf_format::{Asset, AssetReader, FormatError, WriteOptions, encode_asset, read_asset_bytes};

/// Reads `bytes` both ways (whole, and random access of every brick plus verify),
/// failing the test on a panic. Returns the whole-read result; asserts that random
/// access fails too when the whole read fails.
fn read_both(bytes: &[u8], what: &str) -> Result<Asset, FormatError> {
    let whole = catch_unwind(AssertUnwindSafe(|| read_asset_bytes(bytes)))
        .unwrap_or_else(|_| panic!("read_asset_bytes panicked on {what}"));
    let random = catch_unwind(AssertUnwindSafe(|| -> Result<(), FormatError> {
        let mut reader = AssetReader::new(Cursor::new(bytes))?;
        for i in 0..reader.bricks().len() {
            reader.read_brick(i)?;
        }
        reader.verify()
    }))
    .unwrap_or_else(|_| panic!("AssetReader panicked on {what}"));
    assert_eq!(
        whole.is_ok(),
        random.is_ok(),
        "{what}: whole {whole:?} vs random access {random:?}"
    );
    whole
}

/// Reads every case and checks the answer it must give; returns the accepted assets.
fn check(cases: Vec<Damaged>) -> Vec<Asset> {
    assert!(!cases.is_empty());
    let mut accepted = Vec::new();
    for case in cases {
        let result = read_both(&case.bytes, &case.what);
        match (case.expect, result) {
            (Expect::Error(want), Err(err)) => assert!(want(&err), "{}: got {err}", case.what),
            (Expect::Error(_), Ok(_)) => panic!("{}: a damaged file was accepted", case.what),
            (Expect::Anything, Ok(asset)) => accepted.push(asset),
            (Expect::Anything, Err(_)) => {}
        }
    }
    accepted
}

#[test]
fn truncation_at_every_boundary_and_random_offsets() {
    check(damage::truncations());
}

#[test]
fn bit_flips_in_every_section_are_detected_and_named() {
    check(damage::bit_flips());
}

#[test]
fn hostile_headers_give_named_errors() {
    check(damage::hostile_headers());
}

#[test]
fn hostile_sections_give_named_errors() {
    check(damage::hostile_sections());
}

#[test]
fn every_byte_of_the_view_sections_is_checked() {
    check(damage::view_byte_flips());
}

#[test]
fn hostile_view_sections_give_named_errors() {
    // Only the file with a non-zero reserved VDEP field is valid (one per encoding).
    let accepted = check(damage::hostile_view_sections());
    assert_eq!(accepted.len(), 2);
    for asset in accepted {
        assert_eq!(asset.view.unwrap().lobe_count(), 3);
    }
}

#[test]
fn every_byte_of_the_reflection_sections_is_checked() {
    check(damage::reflection_byte_flips());
}

#[test]
fn hostile_reflection_sections_give_named_errors() {
    // Valid, per encoding: the exponents 1 and 200 and an offset of −0 for the scale.
    let accepted = check(damage::hostile_reflection_sections());
    assert_eq!(accepted.len(), 6);
    let mut exponents: Vec<f32> = accepted
        .iter()
        .map(|asset| asset.reflection.as_ref().unwrap().exponent)
        .collect();
    exponents.sort_by(f32::total_cmp);
    assert_eq!(exponents, [1.0, 1.0, 20.0, 20.0, 200.0, 200.0]);
    for asset in &accepted {
        asset.validate().unwrap();
        assert!(asset.view.is_none());
    }
}

#[test]
fn every_byte_of_the_fine_density_is_checked() {
    check(damage::fine_density_byte_flips());
}

#[test]
fn hostile_fine_density_sections_give_named_errors() {
    // Valid, per encoding: DNSF marked required, and a negative fine density with the
    // signed-density flag.
    let accepted = check(damage::hostile_fine_density_sections());
    assert_eq!(accepted.len(), 4);
    let negative = accepted
        .iter()
        .filter(|asset| nelf_format::has_negative_density(&asset.fine_density.as_ref().unwrap().values))
        .count();
    assert_eq!(negative, 2);
    for asset in &accepted {
        asset.validate().unwrap();
        assert_eq!(asset.fine_density.as_ref().unwrap().factor, 2);
    }
}

#[test]
fn mini_fuzzer_never_panics() {
    let accepted = check(damage::mutations());
    for asset in &accepted {
        // Only harmless mutations survive; what they give must be a valid asset.
        asset.validate().unwrap();
        encode_asset(asset, &WriteOptions::default()).unwrap();
    }
    let (n, total) = (accepted.len(), damage::MUTATIONS);
    eprintln!("mini-fuzzer: {n} of {total} mutated files were accepted");
    assert!(n < total / 10, "{n} of {total} mutations were accepted");
}

#[test]
fn section_entry_layout_is_stable() {
    // The 48-byte entry layout is part of the spec: check one entry byte by byte.
    let e = SectionEntry {
        kind: *b"DENS",
        required: true,
        codec: SectionCodec::ChunkedZstd,
        shuffle: 2,
        offset: 0x0102_0304_0506_0708,
        stored_length: 9,
        raw_length: 10,
        checksum: 11,
    };
    let b = e.to_bytes();
    assert_eq!(&b[0..4], b"DENS");
    assert_eq!(&b[4..8], &[1, 0, 2, 0]);
    assert_eq!(&b[8..12], &[2, 0, 0, 0]);
    assert_eq!(&b[16..24], &[8, 7, 6, 5, 4, 3, 2, 1]);
    assert_eq!(b[24], 9);
    assert_eq!(b[32], 10);
    assert_eq!(b[40], 11);
}
