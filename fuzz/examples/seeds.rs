//! Writes a seed corpus of small valid `.nelf` files for the `read` fuzz target:
//! `cargo run --example seeds -- corpus/read` (from `fuzz/`).

use std::path::PathBuf;

use nelf_format::io_error::IoResultExt;
use nelf_format::synthetic::{SyntheticField, synthetic_reflection, synthetic_view};
use nelf_format::{CoefficientEncoding, FormatError, WriteOptions, encode_asset};

fn main() -> Result<(), FormatError> {
    let dir = PathBuf::from(std::env::args().nth(1).unwrap_or_else(|| "corpus/read".into()));
    std::fs::create_dir_all(&dir).with_path(&dir)?;
    // One brick: small seeds keep the fuzzer fast.
    let field = SyntheticField::new(1, 1);
    let cases = [
        (CoefficientEncoding::U8Affine, 2, 1, true),
        (CoefficientEncoding::F16, 3, 2, false),
        (CoefficientEncoding::U8Affine, 4, 32, false),
        (CoefficientEncoding::F16, 1, 3, true),
    ];
    for (i, (encoding, rank, chunk_bricks, shuffle)) in cases.into_iter().enumerate() {
        let mut asset = field.asset(rank, encoding)?;
        if i >= 2 {
            // Format 1.2: a view-dependent part (VDEP, VCOF) in the last two seeds.
            asset.view = Some(synthetic_view(&asset, 2, 2, encoding, 1)?);
        }
        let options = WriteOptions {
            zstd_level: 3,
            chunk_bricks,
            shuffle,
        };
        let (bytes, _) = encode_asset(&asset, &options)?;
        let path = dir.join(format!("seed-{i}.nelf"));
        std::fs::write(&path, bytes).with_path(&path)?;
    }
    // Format 1.3: a reflection part (VREF, VRCO): 5 eyes, lobe exponent 20.
    let mut asset = field.asset(2, CoefficientEncoding::U8Affine)?;
    asset.reflection = Some(synthetic_reflection(&asset, 20.0, 1)?);
    let options = WriteOptions {
        zstd_level: 3,
        chunk_bricks: 1,
        shuffle: true,
    };
    let (bytes, _) = encode_asset(&asset, &options)?;
    let path = dir.join("seed-reflection.nelf");
    std::fs::write(&path, bytes).with_path(&path)?;
    Ok(())
}
