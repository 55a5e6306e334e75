//! Writes a seed corpus of small valid `.nelf` files for the `read` fuzz target:
//! `cargo run --example seeds -- corpus/read` (from `fuzz/`).

use std::path::PathBuf;

use nelf_format::io_error::IoResultExt;
use nelf_format::synthetic::{SyntheticField, synthetic_reflection, synthetic_view};
use nelf_format::{
    Asset, CoefficientEncoding, FineDensity, FormatError, WriteOptions, encode_asset, encode_density,
};

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
    // Format 1.4: a fine density (DNSF) at factor 2 with a negative value (so the
    // signed-density flag), and at factor 4 beside the reflection part.
    let mut fine = field.asset(2, CoefficientEncoding::F16)?;
    fine.fine_density = Some(fine_density(&fine, 2, true)?);
    asset.fine_density = Some(fine_density(&asset, 4, false)?);
    for (i, asset) in [fine, asset].iter().enumerate() {
        let (bytes, _) = encode_asset(asset, &options)?;
        let path = dir.join(format!("seed-fine-density-{i}.nelf"));
        std::fs::write(&path, bytes).with_path(&path)?;
    }
    Ok(())
}

/// The fine density of `asset` at factor `factor`: every fine voxel takes the density of
/// the voxel holding it, the first one negated when `negative`.
fn fine_density(asset: &Asset, factor: u32, negative: bool) -> Result<FineDensity, FormatError> {
    let f = factor as usize;
    let edge = 8 * f;
    let per_brick = edge * edge * edge;
    let mut values: Vec<_> = (0..asset.bricks.len() * per_brick)
        .map(|g| {
            let (b, local) = (g / per_brick, g % per_brick);
            let (i, j, k) = (local % edge, local / edge % edge, local / (edge * edge));
            asset.density[b * 512 + i / f + 8 * (j / f + 8 * (k / f))]
        })
        .collect();
    if let (true, Some(first)) = (negative, values.first_mut()) {
        *first = encode_density(&[-first.to_f32().abs() - 0.5])?[0];
    }
    Ok(FineDensity { factor, values })
}
