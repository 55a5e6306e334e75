//! SPEC.md §17, "A worked example", checked against the code: the test builds the
//! example asset, writes it with the default options, and compares every fenced
//! block of SPEC.md tagged `spec-example-…` with what the writer produced (bytes,
//! the values written beside them, the reconstructed and relit voxel, the projected
//! lighting), so that changing the spec or the code without the other fails here,
//! naming the block and line that disagree.
//!
//! Blocks (the tag is the second word of the opening fence):
//!
//! * `hex spec-example-file-NAME`: lines `OFFSET  BB BB …  [NOTE]`, `OFFSET` decimal
//!   from the start of the file, `BB` bytes in hex; the bytes must be the file's.
//! * `hex spec-example-raw-KIND`: the same for the decoded bytes of section `KIND`
//!   (after decompression and unshuffle), offsets from the section's first decoded byte.
//! * `hex spec-example-decompressed-KIND`: the zstd output before unshuffle.
//! * A `NOTE` of the form `NAME = VALUE …` is checked too: `VALUE` is `"text"`
//!   (ASCII), `0x…` or a decimal integer (unsigned little-endian over the line's
//!   bytes), a number with `.` or `e` (f16, f32 or f64 by the line's width), or a
//!   comma-separated list of these that splits the bytes evenly.
//! * `text spec-example-voxel`, `-projection`, `-reflection` and `-view`: lines
//!   `KEY = VALUE` whose keys and values must be exactly those this test computes
//!   (bit for bit, or within the stated tolerance for the rounded ones).
//!
//! To regenerate the blocks after an intended change of the writer, run
//! `SPEC_EXAMPLE_PRINT=1 cargo test -p nelf-format --release --test spec_example -- --nocapture`
//! and paste them. Stored lengths, checksums and offsets after the first zstd section
//! depend on the zstd library (Cargo.lock pins zstd-sys 2.1.2+zstd.1.5.7, level 19).
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::io::Cursor;

use glam::{DMat3, DVec3, Mat3, Vec3};
use half::f16;
use nelf_format::asset::local_voxel_coords;
use nelf_format::conventions::{
    ENV_H, ENV_TEXELS, ENV_W, LT_DIM, LatLong, VIEW_HARMONICS, col_phi_bounds, direction, lobe_table_corners,
    lobe_table_direction, project_envmap, row_theta_bounds, shade, view_harmonics,
};
use nelf_format::spec::{
    CHUNK_ENTRY_SIZE, HEADER_CHECKSUM_OFFSET, HEADER_SIZE, KIND_COEFFICIENTS, KIND_METADATA, KIND_PCA,
    KIND_REFLECTION, KIND_REFLECTION_VALUES, KIND_VIEW, KIND_VIEW_COEFFICIENTS, SECTION_ENTRY_SIZE,
    SectionCodec, SectionEntry, checksum, header_checksum, unshuffle,
};
use nelf_format::{
    Asset, AssetReader, Coefficients, FormatError, GridGeometry, PcaModel, Reflection, ViewDependence,
    WriteOptions, encode_asset, read_asset_bytes,
};

const SPEC: &str = include_str!("../SPEC.md");

const REGENERATE: &str = "if the change is intended, regenerate the blocks with \
     `SPEC_EXAMPLE_PRINT=1 cargo test -p nelf-format --release --test spec_example -- --nocapture` \
     and paste them into SPEC.md §17 (compressed sizes and checksums also change with the zstd version)";

// ---------------------------------------------------------------------------------
// The example asset (SPEC.md §17.1).

/// Voxel edge, 2⁻⁸ m: every coordinate below is exact in binary.
const VOXEL_SIZE_M: f64 = 0.003_906_25;
const BBOX_MIN_M: [f64; 3] = [-0.031_25, 0.0, -0.015_625];
const GRID_BRICKS: [u32; 3] = [2, 1, 1];
const BRICK: [u16; 3] = [1, 0, 0];
/// 8-bit parameters: steps 2⁻⁶ and 2⁻⁷, offsets on the step lattice (code 128 is 0).
const SCALE: [f32; 2] = [0.015_625, 0.007_812_5];
const OFFSET: [f32; 2] = [-2.0, -1.0];
/// Density inside the ball, 1/m.
const SIGMA: f32 = 100.0;
/// The voxel §17 reconstructs and relights: local (3, 4, 2).
const VOXEL: usize = 163;
/// The bright texel of the second lighting (row 2, column 5) and its radiance.
const BRIGHT_TEXEL: usize = 37;
const BRIGHT: f32 = 10.0;

/// Whether local voxel `l` is inside the ball of radius 3 voxels around the brick centre.
fn inside(l: usize) -> bool {
    let d2: f64 = local_voxel_coords(l)
        .iter()
        .map(|&x| (x as f64 - 3.5).powi(2))
        .sum();
    d2 < 9.0
}

/// `world_from_light`: a quarter turn about +y, rows (0, 0, 1), (0, 1, 0), (−1, 0, 0).
fn quarter_turn_y() -> DMat3 {
    DMat3::from_cols(DVec3::NEG_Z, DVec3::Y, DVec3::X)
}

fn example_asset() -> Asset {
    let density = (0..512)
        .map(|l| f16::from_f32(if inside(l) { SIGMA } else { 0.0 }))
        .collect();
    let codes = (0..512)
        .flat_map(|l| {
            let [i, j, k] = local_voxel_coords(l).map(|x| x as i32);
            if inside(l) {
                [(100 + 10 * j) as u8, (128 + 4 * (i - k)) as u8]
            } else {
                [128, 128]
            }
        })
        .collect();
    let upper = |j: usize| (j % ENV_TEXELS) / ENV_W < ENV_H / 2;
    let mean = (0..LT_DIM).map(|j| {
        if upper(j) {
            (3 - j / ENV_TEXELS) as f32 / 1024.0
        } else {
            0.0
        }
    });
    let b0 = (0..LT_DIM).map(|j| if upper(j) { 1.0 / 256.0 } else { -1.0 / 256.0 });
    let b1 = (0..LT_DIM).map(|j| if j < ENV_TEXELS { 1.0 / 512.0 } else { 0.0 });
    Asset {
        grid: GridGeometry {
            bbox_min_m: BBOX_MIN_M,
            voxel_size_m: VOXEL_SIZE_M,
            grid_bricks: GRID_BRICKS,
        },
        world_from_light: quarter_turn_y(),
        bricks: vec![BRICK],
        density,
        pca: PcaModel {
            mean: mean.collect(),
            basis: b0.chain(b1).collect(),
        },
        coefficients: Coefficients::U8Affine {
            rank: 2,
            scale: SCALE.to_vec(),
            offset: OFFSET.to_vec(),
            codes,
        },
        view: None,
        reflection: None,
        fine_density: None,
        metadata: serde_json::json!({"example": "SPEC.md section 17"}),
    }
}

/// The example file and its section table.
fn example_file() -> (Vec<u8>, Vec<SectionEntry>) {
    encode_asset(&example_asset(), &WriteOptions::default()).unwrap()
}

// ---------------------------------------------------------------------------------
// Decoding by the spec's rules alone (zstd, unshuffle), not through our reader.

/// A section's zstd output before unshuffle (chunks concatenated) and its decoded bytes.
fn decode_section(file: &[u8], e: &SectionEntry) -> (Vec<u8>, Vec<u8>) {
    let stored = &file[e.offset as usize..(e.offset + e.stored_length) as usize];
    match e.codec {
        SectionCodec::Raw => (stored.to_vec(), stored.to_vec()),
        SectionCodec::Zstd => {
            let out = zstd::bulk::decompress(stored, e.raw_length as usize).unwrap();
            let raw = unshuffle(&out, e.shuffle as usize);
            (out, raw)
        }
        SectionCodec::ChunkedZstd => {
            let bricks = u32::from_le_bytes(file[104..108].try_into().unwrap()) as u64;
            let chunk_bricks = u32::from_le_bytes(file[108..112].try_into().unwrap()) as u64;
            let per_brick = e.raw_length / bricks;
            let (mut out, mut raw) = (Vec::new(), Vec::new());
            for i in 0..bricks.div_ceil(chunk_bricks) {
                let t = &stored[(i as usize) * CHUNK_ENTRY_SIZE..][..CHUNK_ENTRY_SIZE];
                let at = |o: usize| u64::from_le_bytes(t[o..o + 8].try_into().unwrap()) as usize;
                let chunk = &stored[at(0)..at(0) + at(8)];
                assert_eq!(checksum(chunk), at(16) as u64);
                let n = (bricks - i * chunk_bricks).min(chunk_bricks) * per_brick;
                let plain = zstd::bulk::decompress(chunk, n as usize).unwrap();
                raw.extend(unshuffle(&plain, e.shuffle as usize));
                out.extend(plain);
            }
            (out, raw)
        }
        SectionCodec::Unknown(c) => panic!("codec {c}"),
    }
}

// ---------------------------------------------------------------------------------
// SPEC.md's blocks.

#[derive(Debug)]
struct Block {
    tag: &'static str,
    /// 1-based line of the opening fence in SPEC.md.
    line: usize,
    body: Vec<(usize, &'static str)>,
}

impl Block {
    fn at(&self, line: usize) -> String {
        format!(
            "SPEC.md block `{}` (opened at line {}), line {line}",
            self.tag, self.line
        )
    }
}

/// Every fenced block whose info string has a word starting with `spec-example-`.
fn spec_blocks() -> Vec<Block> {
    let mut blocks = Vec::new();
    let mut open: Option<Option<Block>> = None;
    for (n, text) in SPEC.lines().enumerate() {
        let n = n + 1;
        let fence = text.trim_start().strip_prefix("```");
        match (&mut open, fence) {
            (None, Some(info)) => {
                let tag = info.split_whitespace().find(|w| w.starts_with("spec-example-"));
                open = Some(tag.map(|tag| Block {
                    tag,
                    line: n,
                    body: Vec::new(),
                }));
            }
            (Some(block), Some(_)) => {
                blocks.extend(block.take());
                open = None;
            }
            (Some(Some(block)), None) => block.body.push((n, text)),
            _ => {}
        }
    }
    assert!(open.is_none(), "SPEC.md ends inside a fenced block");
    blocks
}

/// One line of a hex block.
#[derive(Debug)]
struct HexLine {
    line: usize,
    offset: usize,
    bytes: Vec<u8>,
    note: Vec<&'static str>,
}

fn parse_hex(block: &Block) -> Result<Vec<HexLine>, String> {
    let mut out = Vec::new();
    for &(n, text) in &block.body {
        let text = text.trim();
        if text.is_empty() || text.starts_with('#') {
            continue;
        }
        let mut tokens = text.split_whitespace().peekable();
        let offset = tokens
            .next()
            .and_then(|t| t.parse::<usize>().ok())
            .ok_or_else(|| format!("{}: expected a decimal offset first: `{text}`", block.at(n)))?;
        let mut bytes = Vec::new();
        while let Some(b) = tokens
            .peek()
            .filter(|t| t.len() == 2)
            .and_then(|t| u8::from_str_radix(t, 16).ok())
        {
            bytes.push(b);
            tokens.next();
        }
        if bytes.is_empty() {
            return Err(format!("{}: no bytes after the offset: `{text}`", block.at(n)));
        }
        out.push(HexLine {
            line: n,
            offset,
            bytes,
            note: tokens.collect(),
        });
    }
    Ok(out)
}

/// Checks a note `NAME = VALUE …` against the line's bytes; other notes are free text.
fn check_note(line: &HexLine) -> Result<(), String> {
    let [_, "=", value, ..] = line.note[..] else {
        return Ok(());
    };
    if let Some(text) = value.strip_prefix('"').and_then(|v| v.strip_suffix('"')) {
        return if text.as_bytes() == line.bytes {
            Ok(())
        } else {
            Err(format!("`{value}` is not the bytes {}", hex(&line.bytes)))
        };
    }
    let items: Vec<&str> = value.split(',').collect();
    if line.bytes.len() % items.len() != 0 {
        return Err(format!("{} values for {} bytes", items.len(), line.bytes.len()));
    }
    let width = line.bytes.len() / items.len();
    for (item, b) in items.iter().zip(line.bytes.chunks(width)) {
        check_value(item, b).map_err(|e| format!("value `{item}` for bytes {}: {e}", hex(b)))?;
    }
    Ok(())
}

fn check_value(item: &str, b: &[u8]) -> Result<(), String> {
    let mut wide = [0u8; 8];
    if b.len() > 8 {
        return Err("more than 8 bytes for one value".into());
    }
    wide[..b.len()].copy_from_slice(b);
    let unsigned = u64::from_le_bytes(wide);
    let ok = if let Some(h) = item.strip_prefix("0x") {
        u64::from_str_radix(h, 16).map_err(|e| e.to_string())? == unsigned
    } else if item.contains(['.', 'e', 'E']) || item.contains("inf") || item.contains("NaN") {
        match b.len() {
            2 => {
                let v: f32 = item.parse().map_err(|e| format!("{e}"))?;
                f16::from_bits(unsigned as u16).to_f32().to_bits() == v.to_bits()
            }
            4 => item.parse::<f32>().map_err(|e| format!("{e}"))?.to_bits() == unsigned as u32,
            8 => item.parse::<f64>().map_err(|e| format!("{e}"))?.to_bits() == unsigned,
            w => return Err(format!("no float is {w} bytes wide")),
        }
    } else {
        item.parse::<u64>().map_err(|e| e.to_string())? == unsigned
    };
    if ok {
        Ok(())
    } else {
        Err("the bytes hold another value".into())
    }
}

fn hex(bytes: &[u8]) -> String {
    bytes
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect::<Vec<_>>()
        .join(" ")
}

/// `KEY = VALUE` lines of a text block.
fn parse_text(block: &Block) -> Result<Vec<(usize, &'static str, &'static str)>, String> {
    let mut out = Vec::new();
    for &(n, text) in &block.body {
        if text.trim().is_empty() || text.trim_start().starts_with('#') {
            continue;
        }
        let (key, value) = text
            .split_once(" = ")
            .ok_or_else(|| format!("{}: expected `KEY = VALUE`: `{text}`", block.at(n)))?;
        out.push((n, key.trim(), value.trim()));
    }
    Ok(out)
}

/// What a text block's value must be.
#[derive(Debug, Clone)]
enum Expected {
    /// Integers, exactly.
    Int(Vec<i64>),
    /// f32 values, bit for bit (the text is parsed as f32).
    F32(Vec<f32>),
    /// f64 values, bit for bit.
    F64(Vec<f64>),
    /// Values to within an absolute tolerance (printed rounded).
    Approx(Vec<f64>, f64),
    /// Values to within a relative tolerance (printed to 7 significant digits): those
    /// that depend on the C library's `acosf`, `atan2f`, `powf`, `sin`, `cos`.
    Rel(Vec<f64>, f64),
}

/// `x` to 7 significant digits, in plain decimals.
fn significant(x: f64) -> String {
    if x == 0.0 {
        return "0.0".into();
    }
    let decimals = (6 - x.abs().log10().floor() as i32).max(1) as usize;
    format!("{x:.decimals$}")
}

impl Expected {
    fn text(&self) -> String {
        let list = |items: Vec<String>| {
            if items.len() == 1 {
                items[0].clone()
            } else {
                format!("({})", items.join(", "))
            }
        };
        match self {
            Self::Int(v) => list(v.iter().map(ToString::to_string).collect()),
            // The shortest f64 text of an f32 is exact for the short binary fractions used here.
            Self::F32(v) => list(v.iter().map(|&x| format!("{:?}", f64::from(x))).collect()),
            Self::F64(v) => list(v.iter().map(|x| format!("{x:?}")).collect()),
            Self::Approx(v, _) => list(v.iter().map(|x| format!("{x:.6}")).collect()),
            Self::Rel(v, _) => list(v.iter().map(|&x| significant(x)).collect()),
        }
    }

    fn matches(&self, text: &str) -> bool {
        let inner = text
            .strip_prefix('(')
            .and_then(|t| t.strip_suffix(')'))
            .unwrap_or(text);
        let items: Vec<&str> = inner.split(',').map(str::trim).collect();
        let same = |n: usize| items.len() == n;
        match self {
            Self::Int(v) => same(v.len()) && v.iter().zip(&items).all(|(x, t)| t.parse::<i64>() == Ok(*x)),
            Self::F32(v) => {
                same(v.len())
                    && v.iter()
                        .zip(&items)
                        .all(|(x, t)| t.parse::<f32>().is_ok_and(|y| y.to_bits() == x.to_bits()))
            }
            Self::F64(v) => {
                same(v.len())
                    && v.iter()
                        .zip(&items)
                        .all(|(x, t)| t.parse::<f64>().is_ok_and(|y| y.to_bits() == x.to_bits()))
            }
            Self::Approx(v, tol) => {
                same(v.len())
                    && v.iter()
                        .zip(&items)
                        .all(|(x, t)| t.parse::<f64>().is_ok_and(|y| (y - x).abs() <= *tol))
            }
            Self::Rel(v, tol) => {
                same(v.len())
                    && v.iter()
                        .zip(&items)
                        .all(|(x, t)| t.parse::<f64>().is_ok_and(|y| (y - x).abs() <= tol * x.abs()))
            }
        }
    }
}

// ---------------------------------------------------------------------------------
// The values of §17.5 (one voxel) and §17.6 (projecting a user's map).

fn voxel_values(asset: &Asset) -> Vec<(String, Expected)> {
    let lt = asset.reconstruct_lt(VOXEL);
    let uniform = LatLong::constant(ENV_W, ENV_H, [1.0; 3]);
    let mut texels = [[0.0f32; 3]; ENV_TEXELS];
    texels[BRIGHT_TEXEL] = [BRIGHT; 3];
    let bright = LatLong::basis(texels);
    let (brick, local) = asset.voxel_location(VOXEL);
    let mut c = [0.0f32; 2];
    asset.coefficients_f32(VOXEL, &mut c);
    let Coefficients::U8Affine { codes, .. } = &asset.coefficients else {
        unreachable!()
    };
    let project = |v: &[f32]| shade(v, &uniform).to_vec();
    let mut out = vec![
        ("voxel".to_string(), Expected::Int(vec![VOXEL as i64])),
        (
            "brick".into(),
            Expected::Int(brick.iter().map(|&x| i64::from(x)).collect()),
        ),
        (
            "local".into(),
            Expected::Int(local.iter().map(|&x| x as i64).collect()),
        ),
        (
            "centre_m".into(),
            Expected::F64(asset.voxel_position_m(VOXEL).to_array().to_vec()),
        ),
        ("sigma".into(), Expected::F32(vec![asset.density_at(VOXEL)])),
        (
            "codes".into(),
            Expected::Int(
                codes[2 * VOXEL..2 * VOXEL + 2]
                    .iter()
                    .map(|&x| i64::from(x))
                    .collect(),
            ),
        ),
        ("c".into(), Expected::F32(c.to_vec())),
    ];
    for j in [0usize, 37, 100, 165, 293] {
        out.push((format!("T[{j}]"), Expected::F32(vec![lt[j]])));
    }
    out.extend([
        (
            "P_mean_uniform".to_string(),
            Expected::F32(project(&asset.pca.mean)),
        ),
        (
            "P_0_uniform".into(),
            Expected::F32(project(asset.pca.component(0))),
        ),
        (
            "P_1_uniform".into(),
            Expected::F32(project(asset.pca.component(1))),
        ),
        (
            "radiance_uniform".into(),
            Expected::F32(shade(&lt, &uniform).to_vec()),
        ),
        (
            "radiance_texel37".into(),
            Expected::F32(shade(&lt, &bright).to_vec()),
        ),
        (
            "voxel0_codes".into(),
            Expected::Int(codes[..2].iter().map(|&x| i64::from(x)).collect()),
        ),
        (
            "voxel0_radiance_uniform".into(),
            Expected::F32(shade(&asset.reconstruct_lt(0), &uniform).to_vec()),
        ),
    ]);
    out
}

/// The user's map of §17.6: 5 × 3 texels, texel (row r, col c) = (1 + 5r + c, 1, 0).
fn user_map() -> LatLong {
    let texels = (0..15).map(|i| [1.0 + i as f32, 1.0, 0.0]).collect();
    LatLong::new(5, 3, texels).unwrap()
}

/// Rotation about +x by `angle` (right-handed), rows (1, 0, 0), (0, cos, −sin), (0, sin, cos).
fn rotation_x(angle: f64) -> DMat3 {
    DMat3::from_rotation_x(angle)
}

fn projection_values() -> Vec<(String, Expected)> {
    let map = user_map();
    let world_from_light = quarter_turn_y();
    let mut out = Vec::new();
    // A: world_from_env = I (exact path, a turn about +y); B: world_from_env = R_x(0.5) (splat).
    let cases = [
        (
            "A",
            DMat3::IDENTITY,
            &[(0, 0), (2, 3), (4, 12), (7, 15)][..],
            1e-6,
        ),
        ("B", rotation_x(0.5), &[(0, 0), (3, 8), (7, 15)][..], 1e-6),
    ];
    for (name, world_from_env, texels, tol) in cases {
        let light = project_envmap(&map, world_from_env.transpose() * world_from_light).unwrap();
        for &(row, col) in texels {
            let t = light.get(row, col);
            out.push((
                format!("{name} L({row},{col})"),
                Expected::Approx(t.iter().map(|&v| f64::from(v)).collect(), tol),
            ));
        }
    }
    out
}

fn check_text_block(block: &Block, expected: &[(String, Expected)], errors: &mut Vec<String>) {
    let lines = match parse_text(block) {
        Ok(lines) => lines,
        Err(e) => return errors.push(e),
    };
    let want: BTreeMap<&str, &Expected> = expected.iter().map(|(k, v)| (k.as_str(), v)).collect();
    for &(n, key, value) in &lines {
        match want.get(key) {
            None => errors.push(format!("{}: this test computes no `{key}`", block.at(n))),
            Some(e) if !e.matches(value) => errors.push(format!(
                "{}: `{key} = {value}` in SPEC.md, but the code gives `{}`",
                block.at(n),
                e.text()
            )),
            Some(_) => {}
        }
    }
    for key in want.keys() {
        if !lines.iter().any(|(_, k, _)| k == key) {
            errors.push(format!(
                "SPEC.md block `{}` (line {}) lacks `{key}`",
                block.tag, block.line
            ));
        }
    }
}

// ---------------------------------------------------------------------------------
// The test.

/// Hex blocks that must exist (and cover the header and table byte for byte).
const HEX_BLOCKS: [&str; 12] = [
    "spec-example-file-header",
    "spec-example-file-table",
    "spec-example-file-BRCK",
    "spec-example-file-DENS",
    "spec-example-file-PCAB",
    "spec-example-file-QPRM",
    "spec-example-file-COEF",
    "spec-example-file-META",
    "spec-example-raw-DENS",
    "spec-example-decompressed-DENS",
    "spec-example-raw-PCAB",
    "spec-example-raw-COEF",
];

#[test]
fn spec_example_matches_the_writer() {
    if std::env::var_os("SPEC_EXAMPLE_PRINT").is_some() {
        println!("{}", print_blocks());
        println!(
            "{}",
            print_text_block("spec-example-reflection", &reflection_values())
        );
        println!("{}", print_text_block("spec-example-view", &view_values().0));
    }
    let (file, entries) = example_file();
    let decoded: BTreeMap<String, (Vec<u8>, Vec<u8>)> = entries
        .iter()
        .map(|e| (e.name(), decode_section(&file, e)))
        .collect();
    let blocks = spec_blocks();
    let mut errors = Vec::new();
    for name in HEX_BLOCKS.iter().chain(&[
        "spec-example-voxel",
        "spec-example-projection",
        "spec-example-reflection",
        "spec-example-view",
    ]) {
        match blocks.iter().filter(|b| b.tag == *name).count() {
            1 => {}
            n => errors.push(format!("SPEC.md has {n} blocks tagged `{name}`, expected one")),
        }
    }
    for block in &blocks {
        match block.tag {
            "spec-example-voxel" => check_text_block(block, &voxel_values(&example_asset()), &mut errors),
            "spec-example-projection" => check_text_block(block, &projection_values(), &mut errors),
            "spec-example-reflection" => check_text_block(block, &reflection_values(), &mut errors),
            "spec-example-view" => check_text_block(block, &view_values().0, &mut errors),
            tag => check_hex_block(block, tag, &file, &decoded, &mut errors),
        }
    }
    assert!(
        errors.is_empty(),
        "SPEC.md §17 disagrees with the code ({} problems); {REGENERATE}:\n{}",
        errors.len(),
        errors.join("\n")
    );
}

fn check_hex_block(
    block: &Block,
    tag: &str,
    file: &[u8],
    decoded: &BTreeMap<String, (Vec<u8>, Vec<u8>)>,
    errors: &mut Vec<String>,
) {
    let lines = match parse_hex(block) {
        Ok(lines) => lines,
        Err(e) => return errors.push(e),
    };
    let rest = tag.strip_prefix("spec-example-").unwrap_or(tag);
    let (what, data): (String, &[u8]) = if rest.starts_with("file-") {
        ("the file".into(), file)
    } else if let Some((stage, kind)) = rest.split_once('-')
        && let Some((plain, raw)) = decoded.get(kind)
    {
        match stage {
            "raw" => (format!("decoded section {kind}"), raw),
            "decompressed" => (format!("section {kind} before unshuffle"), plain),
            _ => {
                return errors.push(format!(
                    "SPEC.md block `{tag}` (line {}): unknown tag",
                    block.line
                ));
            }
        }
    } else {
        return errors.push(format!(
            "SPEC.md block `{tag}` (line {}): unknown tag",
            block.line
        ));
    };
    for l in &lines {
        let actual = data.get(l.offset..l.offset + l.bytes.len());
        if actual != Some(&l.bytes[..]) {
            errors.push(format!(
                "{}: SPEC.md shows `{}` at offset {} of {what}, the writer wrote `{}`",
                block.at(l.line),
                hex(&l.bytes),
                l.offset,
                actual.map_or_else(|| "nothing (past the end)".into(), hex)
            ));
        }
        if let Err(e) = check_note(l) {
            errors.push(format!("{}: note `{}`: {e}", block.at(l.line), l.note.join(" ")));
        }
    }
    let section_count = u32::from_le_bytes(file[16..20].try_into().unwrap()) as usize;
    let span = match tag {
        "spec-example-file-header" => Some((0, HEADER_SIZE)),
        "spec-example-file-table" => Some((HEADER_SIZE, HEADER_SIZE + section_count * SECTION_ENTRY_SIZE)),
        _ => None,
    };
    if let Some((start, end)) = span {
        let mut at = start;
        for l in &lines {
            if l.offset != at {
                errors.push(format!(
                    "{}: expected the line for offset {at} (the block shows every byte of {start}..{end} in order)",
                    block.at(l.line)
                ));
            }
            at = l.offset + l.bytes.len();
        }
        if at != end {
            errors.push(format!(
                "SPEC.md block `{tag}` (line {}) ends at offset {at}, not {end}",
                block.line
            ));
        }
    }
}

// ---------------------------------------------------------------------------------
// Printing the blocks (SPEC_EXAMPLE_PRINT=1).

/// One annotated line: offset, bytes, note.
fn line(out: &mut String, offset: usize, bytes: &[u8], note: &str) {
    writeln!(out, "{offset:>4}  {:<47}  {note}", hex(bytes)).unwrap();
}

fn print_blocks() -> String {
    let (file, entries) = example_file();
    let mut out = String::new();
    let u = |o: usize, n: usize| {
        let mut w = [0u8; 8];
        w[..n].copy_from_slice(&file[o..o + n]);
        u64::from_le_bytes(w)
    };
    let f = |o: usize| f64::from_le_bytes(file[o..o + 8].try_into().unwrap());
    out.push_str("```hex spec-example-file-header\n");
    line(&mut out, 0, &file[0..8], "magic");
    for (o, n, name) in [
        (8, 2, "version_major"),
        (10, 2, "version_minor"),
        (12, 4, "header_size"),
        (16, 4, "section_count"),
        (20, 4, "section_entry_size"),
    ] {
        line(&mut out, o, &file[o..o + n], &format!("{name} = {}", u(o, n)));
    }
    line(&mut out, 24, &file[24..32], &format!("flags = 0x{:x}", u(24, 8)));
    for (base, name) in [(32, "bbox_min_m"), (56, "bbox_max_m")] {
        for (a, axis) in ["x", "y", "z"].iter().enumerate() {
            let o = base + 8 * a;
            line(
                &mut out,
                o,
                &file[o..o + 8],
                &format!("{name}.{axis} = {:?}", f(o)),
            );
        }
    }
    line(
        &mut out,
        80,
        &file[80..88],
        &format!("voxel_size_m = {:?}", f(80)),
    );
    for (a, axis) in ["x", "y", "z"].iter().enumerate() {
        let o = 88 + 4 * a;
        line(
            &mut out,
            o,
            &file[o..o + 4],
            &format!("grid_bricks.{axis} = {}", u(o, 4)),
        );
    }
    for (o, name) in [(100, "brick_size"), (104, "brick_count"), (108, "chunk_bricks")] {
        line(&mut out, o, &file[o..o + 4], &format!("{name} = {}", u(o, 4)));
    }
    for i in 0..9 {
        let o = 112 + 8 * i;
        let name = format!("world_from_light[{}][{}]", i / 3, i % 3);
        line(&mut out, o, &file[o..o + 8], &format!("{name} = {:?}", f(o)));
    }
    for (o, n, name) in [
        (184, 2, "env_height"),
        (186, 2, "env_width"),
        (188, 4, "pca_rank"),
        (192, 4, "coefficient_encoding"),
        (196, 4, "reserved"),
        (200, 8, "file_size"),
    ] {
        line(&mut out, o, &file[o..o + n], &format!("{name} = {}", u(o, n)));
    }
    for (o, n) in [(208, 16), (224, 16), (240, 8)] {
        line(&mut out, o, &file[o..o + n], "reserved");
    }
    line(
        &mut out,
        248,
        &file[248..256],
        &format!("header_checksum = 0x{:016x}", u(248, 8)),
    );
    out.push_str("```\n\n```hex spec-example-file-table\n");
    for (i, e) in entries.iter().enumerate() {
        let b = HEADER_SIZE + i * SECTION_ENTRY_SIZE;
        writeln!(out, "# entry {i}: {}", e.name()).unwrap();
        line(&mut out, b, &file[b..b + 4], &format!("kind = \"{}\"", e.name()));
        for (o, n, name) in [
            (4, 2, "flags"),
            (6, 2, "codec"),
            (8, 4, "shuffle"),
            (12, 4, "reserved"),
            (16, 8, "offset"),
            (24, 8, "stored_length"),
            (32, 8, "raw_length"),
        ] {
            line(
                &mut out,
                b + o,
                &file[b + o..b + o + n],
                &format!("{name} = {}", u(b + o, n)),
            );
        }
        line(
            &mut out,
            b + 40,
            &file[b + 40..b + 48],
            &format!("checksum = 0x{:016x}", e.checksum),
        );
    }
    out.push_str("```\n");
    let mut end_of_previous = HEADER_SIZE + entries.len() * SECTION_ENTRY_SIZE;
    for e in &entries {
        let o = e.offset as usize;
        writeln!(out, "\n```hex spec-example-file-{}", e.name()).unwrap();
        if o > end_of_previous {
            line(&mut out, end_of_previous, &file[end_of_previous..o], "padding");
        }
        match e.codec {
            SectionCodec::ChunkedZstd => {
                for (k, name) in ["offset", "stored_length", "checksum"].iter().enumerate() {
                    let at = o + 8 * k;
                    let v = u(at, 8);
                    let v = if k == 2 {
                        format!("0x{v:016x}")
                    } else {
                        v.to_string()
                    };
                    line(&mut out, at, &file[at..at + 8], &format!("chunk[0].{name} = {v}"));
                }
                line(
                    &mut out,
                    o + 24,
                    &file[o + 24..o + 28],
                    "zstd frame magic 0xFD2FB528: chunk 0 starts",
                );
            }
            SectionCodec::Zstd => line(&mut out, o, &file[o..o + 4], "zstd frame magic 0xFD2FB528"),
            _ if e.name() == "BRCK" => {
                for (k, r) in file[o..o + e.stored_length as usize].chunks(6).enumerate() {
                    let xyz: Vec<String> = r
                        .chunks(2)
                        .map(|p| u16::from_le_bytes([p[0], p[1]]).to_string())
                        .collect();
                    line(&mut out, o + 6 * k, r, &format!("brick[{k}] = {}", xyz.join(",")));
                }
            }
            _ if e.name() == "QPRM" => {
                for (k, v) in file[o..o + e.stored_length as usize].chunks(4).enumerate() {
                    let name = if k % 2 == 0 { "scale" } else { "offset" };
                    let value = f32::from_le_bytes(v.try_into().unwrap());
                    line(&mut out, o + 4 * k, v, &format!("{name}_{} = {value:?}", k / 2));
                }
            }
            _ => {
                for (k, piece) in file[o..o + e.stored_length as usize].chunks(16).enumerate() {
                    line(&mut out, o + 16 * k, piece, &String::from_utf8_lossy(piece));
                }
            }
        }
        writeln!(out, "```").unwrap();
        end_of_previous = o + e.stored_length as usize;
    }
    let decoded: BTreeMap<String, (Vec<u8>, Vec<u8>)> = entries
        .iter()
        .map(|e| (e.name(), decode_section(&file, e)))
        .collect();
    let (plain, raw) = &decoded["DENS"];
    let f16s = |b: &[u8]| {
        b.chunks(2)
            .map(|p| format!("{:?}", f16::from_le_bytes([p[0], p[1]]).to_f32()))
            .collect::<Vec<_>>()
            .join(",")
    };
    out.push_str("\n```hex spec-example-raw-DENS\n");
    line(
        &mut out,
        320,
        &raw[320..336],
        &format!("sigma[160..168] = {}", f16s(&raw[320..336])),
    );
    out.push_str("```\n\n```hex spec-example-decompressed-DENS\n");
    line(&mut out, 160, &plain[160..168], "low bytes of sigma[160..168]");
    line(&mut out, 672, &plain[672..680], "high bytes of sigma[160..168]");
    out.push_str("```\n\n```hex spec-example-raw-PCAB\n");
    let (_, pca) = &decoded["PCAB"];
    let f32_at = |o: usize| f32::from_le_bytes(pca[o..o + 4].try_into().unwrap());
    for (j, name) in [
        (0, "m[0]"),
        (64, "m[64]"),
        (128, "m[128]"),
        (256, "m[256]"),
        (384, "B_0[0]"),
        (448, "B_0[64]"),
        (768, "B_1[0]"),
        (896, "B_1[128]"),
    ] {
        let o = 4 * j;
        line(&mut out, o, &pca[o..o + 4], &format!("{name} = {:?}", f32_at(o)));
    }
    out.push_str("```\n\n```hex spec-example-raw-COEF\n");
    let (_, coef) = &decoded["COEF"];
    let list = |b: &[u8]| b.iter().map(ToString::to_string).collect::<Vec<_>>().join(",");
    line(
        &mut out,
        0,
        &coef[0..2],
        &format!("codes[0] = {}", list(&coef[0..2])),
    );
    line(
        &mut out,
        320,
        &coef[320..336],
        &format!("codes[160..168] = {}", list(&coef[320..336])),
    );
    out.push_str("```\n\n```text spec-example-voxel\n");
    for (k, v) in voxel_values(&example_asset()) {
        writeln!(out, "{k} = {}", v.text()).unwrap();
    }
    out.push_str("```\n\n```text spec-example-projection\n");
    for (k, v) in projection_values() {
        writeln!(out, "{k} = {}", v.text()).unwrap();
    }
    out.push_str("```\n");
    out
}

// ---------------------------------------------------------------------------------
// Claims of §4, §5, §6 and §11 that the example pins down.

/// Lays out `sections` after `header` (8-byte aligned, in order), fixing offsets,
/// `section_count`, `file_size` and the header checksum.
fn assemble(header: &[u8], sections: &[(SectionEntry, Vec<u8>)]) -> Vec<u8> {
    let mut out = header[..HEADER_SIZE].to_vec();
    out[16..20].copy_from_slice(&(sections.len() as u32).to_le_bytes());
    let mut offset = HEADER_SIZE + sections.len() * SECTION_ENTRY_SIZE;
    let mut entries = Vec::new();
    for (e, data) in sections {
        offset = offset.next_multiple_of(8);
        let mut e = *e;
        e.offset = offset as u64;
        e.stored_length = data.len() as u64;
        e.checksum = checksum(data);
        entries.push(e);
        offset += data.len();
    }
    for e in &entries {
        out.extend_from_slice(&e.to_bytes());
    }
    for (e, (_, data)) in entries.iter().zip(sections) {
        out.resize(e.offset as usize, 0);
        out.extend_from_slice(data);
    }
    let size = out.len() as u64;
    out[200..208].copy_from_slice(&size.to_le_bytes());
    resign(&mut out);
    out
}

/// Recomputes the header checksum after editing the header or the table.
fn resign(bytes: &mut [u8]) {
    let count = u32::from_le_bytes(bytes[16..20].try_into().unwrap()) as usize;
    let sum = header_checksum(
        &bytes[..HEADER_SIZE],
        &bytes[HEADER_SIZE..HEADER_SIZE + count * SECTION_ENTRY_SIZE],
    );
    bytes[HEADER_CHECKSUM_OFFSET..HEADER_SIZE].copy_from_slice(&sum.to_le_bytes());
}

/// The example's sections with their stored bytes.
fn example_sections() -> (Vec<u8>, Vec<(SectionEntry, Vec<u8>)>) {
    let (file, entries) = example_file();
    let sections = entries
        .iter()
        .map(|e| {
            (
                *e,
                file[e.offset as usize..(e.offset + e.stored_length) as usize].to_vec(),
            )
        })
        .collect();
    (file, sections)
}

#[test]
fn example_reads_back() {
    let (file, _) = example_file();
    assert_eq!(read_asset_bytes(&file).unwrap(), example_asset());
}

#[test]
fn reserved_fields_and_unknown_entry_flag_bits_are_ignored() {
    // §3, §4: writers write 0, readers ignore. (Bytes 196..200 were reserved before 1.4;
    // they are now fine_density_factor, which a reader checks.)
    let (mut file, entries) = example_file();
    let mut factor = file.clone();
    factor[196] = 0xAB;
    resign(&mut factor);
    assert!(matches!(
        read_asset_bytes(&factor),
        Err(FormatError::InvalidHeader {
            field: "fine_density_factor",
            ..
        })
    ));
    file[208..248].fill(0xCD);
    for i in 0..entries.len() {
        let e = HEADER_SIZE + i * SECTION_ENTRY_SIZE;
        file[e + 4] |= 0xFE; // flags bits 1..7
        file[e + 5] = 0xFF; // flags bits 8..15
        file[e + 12..e + 16].fill(0xEE);
    }
    resign(&mut file);
    assert_eq!(read_asset_bytes(&file).unwrap(), example_asset());
}

#[test]
fn zstd_data_may_be_several_frames() {
    // §5: codec 1 and every chunk of codec 2 are one or more zstd frames (skippable
    // frames included) that decode to exactly the declared length.
    let (file, mut sections) = example_sections();
    let frames = |plain: &[u8]| {
        let mut skippable = 0x184D_2A50u32.to_le_bytes().to_vec();
        skippable.extend_from_slice(&3u32.to_le_bytes());
        skippable.extend_from_slice(b"abc");
        let (a, b) = plain.split_at(plain.len() / 3);
        let mut out = zstd::bulk::compress(a, 3).unwrap();
        out.extend(skippable);
        out.extend(zstd::bulk::compress(b, 3).unwrap());
        out
    };
    for (e, data) in &mut sections {
        if e.kind == KIND_PCA {
            let (plain, _) = decode_section(&file, e);
            *data = frames(&plain);
        }
        if e.kind == KIND_COEFFICIENTS {
            let (plain, _) = decode_section(&file, e);
            let chunk = frames(&plain);
            let mut table = (CHUNK_ENTRY_SIZE as u64).to_le_bytes().to_vec();
            table.extend_from_slice(&(chunk.len() as u64).to_le_bytes());
            table.extend_from_slice(&checksum(&chunk).to_le_bytes());
            table.extend(chunk);
            *data = table;
        }
    }
    let bytes = assemble(&file, &sections);
    assert_eq!(read_asset_bytes(&bytes).unwrap(), example_asset());
}

#[test]
fn optional_sections_are_checked_by_full_reads() {
    // §10, §12: an unknown optional section's checksum is verified by a full read
    // (`read_asset`, `nelf inspect`) but not at open; a damaged META is rejected at open.
    let (file, mut sections) = example_sections();
    let extra = b"future".to_vec();
    let entry = SectionEntry {
        kind: *b"XTRA",
        required: false,
        codec: SectionCodec::Unknown(9),
        shuffle: 12345,
        offset: 0,
        stored_length: 0,
        raw_length: u64::MAX,
        checksum: 0,
    };
    sections.push((entry, extra));
    let mut bytes = assemble(&file, &sections);
    assert_eq!(read_asset_bytes(&bytes).unwrap(), example_asset());
    let xtra = bytes.len() - 6;
    bytes[xtra] ^= 1;
    assert!(AssetReader::new(Cursor::new(&bytes)).is_ok(), "open skips it");
    let err = read_asset_bytes(&bytes).unwrap_err();
    assert!(
        matches!(&err, FormatError::ChecksumMismatch { what, .. } if what == "section XTRA"),
        "{err}"
    );

    let (mut file, entries) = example_file();
    let meta = entries.iter().find(|e| e.kind == KIND_METADATA).unwrap();
    file[meta.offset as usize + 1] ^= 1;
    let err = AssetReader::new(Cursor::new(&file)).unwrap_err();
    assert!(
        matches!(&err, FormatError::ChecksumMismatch { what, .. } if what == "section META"),
        "{err}"
    );
}

#[test]
fn metadata_json_limits() {
    // §6 META: JSON as our parser (serde_json) takes it.
    let (file, sections) = example_sections();
    let with_meta = |json: &[u8]| {
        let mut s = sections.clone();
        let meta = s.iter_mut().find(|(e, _)| e.kind == KIND_METADATA).unwrap();
        meta.0.codec = SectionCodec::Raw;
        meta.0.shuffle = 0;
        meta.0.raw_length = json.len() as u64;
        meta.1 = json.to_vec();
        read_asset_bytes(&assemble(&file, &s))
    };
    let nested = |depth: usize| {
        let mut s = "{\"a\":".repeat(depth);
        s.push('1');
        s.push_str(&"}".repeat(depth));
        s.into_bytes()
    };
    assert!(with_meta(b" {\"a\": [1, 2.5e300, \"\\u00e9\"]} \n").is_ok());
    assert!(
        with_meta(&nested(127)).is_ok(),
        "127 levels, the top-level object included"
    );
    assert!(with_meta(&nested(128)).is_err(), "128 levels");
    assert!(with_meta(b"{\"a\": 1e400}").is_err(), "beyond the f64 range");
    assert!(with_meta(b"\xEF\xBB\xBF{}").is_err(), "a byte-order mark");
    assert!(with_meta(b"{\"a\": \"\xFF\"}").is_err(), "not UTF-8");
    assert!(with_meta(b"[]").is_err(), "not an object");
    assert!(with_meta(b"{\"a\": 1, \"a\": 2}").is_ok(), "repeated keys");
}

// ---------------------------------------------------------------------------------
// §17.7: the same asset with a reflection part (format 1.3), one voxel relit by the
// steps of SPEC.md §6 `VREF` ("Precision"), which are those of `nelf_render::reflection`.

/// The lobe exponent λ.
const EXPONENT: f32 = 20.0;
/// The eyes `T̄` was averaged over (E = 2), metres.
const EYES_M: [[f32; 3]; 2] = [[-0.25, 0.125, 0.5], [0.25, 0.0, 0.4375]];
/// The camera centre the voxel is seen from, metres.
const CAMERA_M: [f64; 3] = [0.0, 0.0625, 0.5];
/// `VREF`'s 8-bit parameters of u, v (step 2⁻⁷ from −1) and s (step 2⁻⁸ from 0).
const REFLECTION_SCALE: [f32; 3] = [0.007_812_5, 0.007_812_5, 0.003_906_25];
const REFLECTION_OFFSET: [f32; 3] = [-1.0, -1.0, 0.0];
/// Codes of the voxels in the ball: u = 0.25, v = 0.125, s = 0.25; elsewhere s = 0.
const BALL_CODES: [u8; 3] = [160, 144, 64];
const OUTSIDE_CODES: [u8; 3] = [128, 128, 0];

fn reflection_asset() -> Asset {
    let codes = (0..512)
        .flat_map(|l| if inside(l) { BALL_CODES } else { OUTSIDE_CODES })
        .collect();
    Asset {
        reflection: Some(Reflection {
            exponent: EXPONENT,
            eyes_m: EYES_M.to_vec(),
            coefficients: Coefficients::U8Affine {
                rank: 3,
                scale: REFLECTION_SCALE.to_vec(),
                offset: REFLECTION_OFFSET.to_vec(),
                codes,
            },
        }),
        metadata: serde_json::json!({"example": "SPEC.md section 17.7"}),
        ..example_asset()
    }
}

/// The sky of §17.7: radiance 1 in the upper light rows (0–3), 0 below.
fn sky() -> LatLong {
    let texels = (0..ENV_TEXELS)
        .map(|i| if i / ENV_W < ENV_H / 2 { [1.0; 3] } else { [0.0; 3] })
        .collect();
    LatLong::new(ENV_W, ENV_H, texels).unwrap()
}

/// `g_i(node)` for every light texel (§6 `VREF`, Precision step 1).
fn lobe_at_node(node: usize) -> [f32; ENV_TEXELS] {
    let m = lobe_table_direction(node).as_vec3();
    std::array::from_fn(|i| {
        let (t0, t1) = row_theta_bounds(i / ENV_W, ENV_H);
        let (p0, p1) = col_phi_bounds(i % ENV_W, ENV_W);
        let mut g = 0.0f32;
        for a in 0..3 {
            for b in 0..3 {
                let (a, b) = (f64::from(a), f64::from(b));
                let (ta, tb) = (t0 + (t1 - t0) * a / 3.0, t0 + (t1 - t0) * (a + 1.0) / 3.0);
                let phi = p0 + (p1 - p0) * (b + 0.5) / 3.0;
                let solid = ((p1 - p0) / 3.0 * (ta.cos() - tb.cos())) as f32;
                let c = m.dot(direction(0.5 * (ta + tb), phi).as_vec3());
                g += if c > 0.0 { c.powf(EXPONENT) * solid } else { 0.0 };
            }
        }
        g
    })
}

/// `F_c(node)` under `light` (Precision step 2).
fn filtered_at_node(node: usize, light: &LatLong) -> [f32; 3] {
    let g = lobe_at_node(node);
    let mut sum = [0.0f64; 3];
    for (gi, l) in g.iter().zip(light.texels()) {
        for c in 0..3 {
            sum[c] += f64::from(*gi) * f64::from(l[c]);
        }
    }
    sum.map(|v| v as f32)
}

/// What one direction toward an eye gives (Precision step 3).
struct Seen {
    omega: Vec3,
    cos: f32,
    r: Vec3,
    r_light: Vec3,
    corners: [(usize, f32); 4],
    nodes: [[f32; 3]; 4],
    filtered: [f32; 3],
    term: [f32; 3],
}

fn seen_from(eye: DVec3, centre: DVec3, n: Vec3, light_from_world: Mat3, light: &LatLong) -> Seen {
    let omega = (eye - centre).normalize_or_zero().as_vec3();
    let cos = n.dot(omega);
    let r = (2.0 * cos * n - omega).normalize_or_zero();
    let r_light = light_from_world * r;
    let corners = lobe_table_corners(r_light.to_array());
    let nodes = corners.map(|(node, _)| filtered_at_node(node, light));
    let mut filtered = [0.0f32; 3];
    for ((_, w), e) in corners.iter().zip(&nodes) {
        for c in 0..3 {
            filtered[c] += w * e[c];
        }
    }
    let term = if cos > 0.0 {
        filtered.map(|e| cos * e)
    } else {
        [0.0; 3]
    };
    Seen {
        omega,
        cos,
        r,
        r_light,
        corners,
        nodes,
        filtered,
        term,
    }
}

fn reflection_values() -> Vec<(String, Expected)> {
    let asset = reflection_asset();
    let (file, entries) = encode_asset(&asset, &WriteOptions::default()).unwrap();
    let vref = entries.iter().find(|e| e.kind == KIND_REFLECTION).unwrap();
    let (_, raw) = decode_section(&file, vref);
    let word = |o: usize| u32::from_le_bytes(raw[o..o + 4].try_into().unwrap());
    let real = |o: usize| f32::from_le_bytes(raw[o..o + 4].try_into().unwrap());
    let eyes = word(0) as usize;
    let vrco = entries.iter().find(|e| e.kind == KIND_REFLECTION_VALUES).unwrap();
    let (_, codes) = decode_section(&file, vrco);
    let codes = &codes[3 * VOXEL..3 * VOXEL + 3];
    let part = asset.reflection.as_ref().unwrap();
    let mut values = [0.0f32; 3];
    part.coefficients.voxel_f32(VOXEL, &mut values);
    let (n, s) = part.voxel(VOXEL);
    let n = Vec3::from_array(n);
    let light = sky();
    let pca = radiance_pca(&asset, &light);
    let centre = asset.voxel_position_m(VOXEL);
    let light_from_world = asset.world_from_light.transpose().as_mat3();
    let camera = seen_from(DVec3::from_array(CAMERA_M), centre, n, light_from_world, &light);
    let share = 1.0 / part.eyes_m.len() as f32;
    let mut mean = [0.0f32; 3];
    let mut out = version_and_length(&file, "VREF", vref.raw_length);
    out.extend([
        ("VREF.E".into(), Expected::Int(vec![eyes as i64])),
        ("VREF.exponent".into(), Expected::F32(vec![real(4)])),
    ]);
    for e in 0..eyes {
        out.push((
            format!("VREF.eye{e}_m"),
            Expected::F32((0..3).map(|a| real(8 + 12 * e + 4 * a)).collect()),
        ));
    }
    out.push((
        "VREF.scale_offset".into(),
        Expected::F32((0..6).map(|k| real(8 + 12 * eyes + 4 * k)).collect()),
    ));
    out.extend([
        (
            "VRCO.codes".to_string(),
            Expected::Int(codes.iter().map(|&c| i64::from(c)).collect()),
        ),
        ("values".into(), Expected::F32(values.to_vec())),
        ("n".into(), Expected::F32(n.to_array().to_vec())),
        ("s".into(), Expected::F32(vec![s])),
        ("radiance_pca".into(), Expected::F32(pca.to_vec())),
    ]);
    let mut seen = |name: &str, v: &Seen| {
        out.extend([
            (
                format!("{name} omega"),
                Expected::F32(v.omega.to_array().to_vec()),
            ),
            (format!("{name} n.omega"), Expected::F32(vec![v.cos])),
        ]);
        if v.cos <= 0.0 {
            return;
        }
        out.extend([
            (format!("{name} r"), Expected::F32(v.r.to_array().to_vec())),
            (
                format!("{name} r_light"),
                Expected::F32(v.r_light.to_array().to_vec()),
            ),
            (
                format!("{name} nodes"),
                Expected::Int(v.corners.iter().map(|&(i, _)| i as i64).collect()),
            ),
            (
                format!("{name} weights"),
                Expected::Approx(v.corners.iter().map(|&(_, w)| f64::from(w)).collect(), 1e-4),
            ),
            (
                format!("{name} F(nodes)"),
                Expected::Rel(v.nodes.iter().map(|e| f64::from(e[0])).collect(), 1e-5),
            ),
            (
                format!("{name} F(r)"),
                Expected::Rel(vec![f64::from(v.filtered[0])], 1e-4),
            ),
            (
                format!("{name} term"),
                Expected::Rel(vec![f64::from(v.term[0])], 1e-4),
            ),
        ]);
    };
    seen("camera", &camera);
    for (e, eye) in part.eyes_m.iter().enumerate() {
        let eye = DVec3::from_array(eye.map(f64::from));
        let v = seen_from(eye, centre, n, light_from_world, &light);
        for (m, t) in mean.iter_mut().zip(v.term) {
            *m += share * t;
        }
        seen(&format!("eye{e}"), &v);
    }
    let radiance: [f32; 3] = std::array::from_fn(|c| pca[c] + s * (camera.term[c] - mean[c]));
    out.extend([
        ("Fbar".to_string(), Expected::Rel(vec![f64::from(mean[0])], 1e-4)),
        (
            "radiance".into(),
            Expected::Rel(radiance.iter().map(|&v| f64::from(v)).collect(), 1e-4),
        ),
    ]);
    out
}

/// A `text` block as the code computes it: f32 values as their shortest text, which
/// parses back to the same f32.
fn print_text_block(tag: &str, values: &[(String, Expected)]) -> String {
    let mut out = format!("```text {tag}\n");
    for (key, value) in values {
        let text = match value {
            Expected::F32(v) if v.len() == 1 => format!("{:?}", v[0]),
            Expected::F32(v) => format!(
                "({})",
                v.iter().map(|x| format!("{x:?}")).collect::<Vec<_>>().join(", ")
            ),
            _ => value.text(),
        };
        writeln!(out, "{key} = {text}").unwrap();
    }
    out.push_str("```\n");
    out
}

// ---------------------------------------------------------------------------------
// §17.8: the same asset with a harmonic view-dependent part (format 1.2), one voxel relit
// and seen along one direction by the steps of SPEC.md §6 `VDEP` and §8 ("The
// view-dependent part"), which are those of `nelf_render::view`. Every value is read
// from the decoded sections by the spec's layout and computed in plain IEEE arithmetic
// (no C library function), so the block holds them bit for bit.

/// The lobes' weights over the 9 harmonics: `Y_0 = y_2 = a·z`, `Y_1 = ½ y_3 + ¼ y_6`.
const VIEW_LOBES: [[f32; VIEW_HARMONICS]; 2] = [
    [0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    [0.0, 0.0, 0.0, 0.5, 0.0, 0.0, 0.25, 0.0, 0.0],
];
/// View basis rank `K_v`.
const VIEW_RANK: usize = 2;
/// `VDEP`'s 8-bit parameters, the same for the `R = 4` view coefficients: step 2⁻⁷ from −1
/// (code 128 is 0).
const VIEW_SCALE: f32 = 0.007_812_5;
const VIEW_OFFSET: f32 = -1.0;
/// View codes of the voxels in the ball, `m = j·K_v + i`: `d = (0.25, 0.125, −0.125,
/// 0.0625)`; elsewhere 128 (`d = 0`, no view part).
const VIEW_BALL_CODES: [u8; 4] = [160, 144, 112, 136];

fn view_asset() -> Asset {
    let per_voxel = VIEW_LOBES.len() * VIEW_RANK;
    let codes = (0..512)
        .flat_map(|l| if inside(l) { VIEW_BALL_CODES } else { [128; 4] })
        .collect();
    let upper = |j: usize| (j % ENV_TEXELS) / ENV_W < ENV_H / 2;
    // V_0: 1/1024 in the upper hemisphere (all channels), 0 below; V_1: 1/512 in green.
    let v0 = (0..LT_DIM).map(|j| if upper(j) { 1.0 / 1024.0 } else { 0.0 });
    let v1 = (0..LT_DIM).map(|j| if j / ENV_TEXELS == 1 { 1.0 / 512.0 } else { 0.0 });
    Asset {
        view: Some(ViewDependence {
            lobes: VIEW_LOBES.concat(),
            basis: v0.chain(v1).collect(),
            coefficients: Coefficients::U8Affine {
                rank: per_voxel,
                scale: vec![VIEW_SCALE; per_voxel],
                offset: vec![VIEW_OFFSET; per_voxel],
                codes,
            },
        }),
        metadata: serde_json::json!({"example": "SPEC.md section 17.8"}),
        ..example_asset()
    }
}

/// The PCA part of voxel `VOXEL` under `light`: `P_mean + Σ_k c_k P_k`, the projections
/// as [`projected`], the sum in f32 with `k` ascending (`nelf_render::light`).
fn radiance_pca(asset: &Asset, light: &LatLong) -> [f32; 3] {
    let mut pca = projected(&asset.pca.mean, light);
    let mut coefficients = vec![0.0f32; asset.rank()];
    asset.coefficients_f32(VOXEL, &mut coefficients);
    for (k, ck) in coefficients.iter().enumerate() {
        let p = projected(asset.pca.component(k), light);
        for ch in 0..3 {
            pca[ch] += ck * p[ch];
        }
    }
    pca
}

/// The first lines of a worked example's block: the file's minor version and the decoded
/// length of its section `tag`.
fn version_and_length(file: &[u8], tag: &str, raw_length: u64) -> Vec<(String, Expected)> {
    vec![
        (
            "version_minor".to_string(),
            Expected::Int(vec![i64::from(u16::from_le_bytes([file[10], file[11]]))]),
        ),
        (
            format!("{tag}.raw_length"),
            Expected::Int(vec![raw_length as i64]),
        ),
    ]
}

/// `Σ_j v[c·128 + j] · L[j][c]` per channel, in f64, rounded once (`nelf_render::light`).
fn projected(v: &[f32], light: &LatLong) -> [f32; 3] {
    std::array::from_fn(|c| {
        v[c * ENV_TEXELS..(c + 1) * ENV_TEXELS]
            .iter()
            .zip(light.texels())
            .map(|(&t, l)| f64::from(t) * f64::from(l[c]))
            .sum::<f64>() as f32
    })
}

/// The 9 harmonics of `d` by the words of SPEC.md §6 `VDEP` (normalise, then the products
/// left to right), to hold `view_harmonics` to them.
fn harmonics_as_specified(d: [f32; 3]) -> ([f32; 3], [f32; VIEW_HARMONICS]) {
    let (c0, a, b, c) = (0.282_094_8f32, 0.488_602_5f32, 1.092_548_4f32, 0.315_391_57f32);
    let len = ((d[0] * d[0] + d[1] * d[1]) + d[2] * d[2]).sqrt();
    assert!(len > 0.0 && len.is_finite());
    let [x, y, z] = d.map(|v| v / len);
    let harmonics = [
        c0,
        a * y,
        a * z,
        a * x,
        (b * x) * y,
        (b * y) * z,
        c * ((3.0 * z) * z - 1.0),
        (b * x) * z,
        (0.5 * b) * (x * x - y * y),
    ];
    ([x, y, z], harmonics)
}

/// The values of §17.8, with the `f32` radiance (for the cross-checks of
/// `view_example_agrees_with_the_transport`).
fn view_values() -> (Vec<(String, Expected)>, [f32; 3]) {
    let asset = view_asset();
    let (file, entries) = encode_asset(&asset, &WriteOptions::default()).unwrap();
    let vdep = entries.iter().find(|e| e.kind == KIND_VIEW).unwrap();
    let vcof = entries.iter().find(|e| e.kind == KIND_VIEW_COEFFICIENTS).unwrap();
    let (_, raw) = decode_section(&file, vdep);
    let word = |o: usize| u32::from_le_bytes(raw[o..o + 4].try_into().unwrap()) as usize;
    let real = |o: usize| f32::from_le_bytes(raw[o..o + 4].try_into().unwrap());
    let (lobes, rank, encoding) = (word(0), word(4), word(8));
    let per_voxel = lobes * rank;
    let basis_at = 16 + 4 * VIEW_HARMONICS * lobes;
    let params_at = basis_at + 4 * LT_DIM * rank;
    let basis: Vec<f32> = (0..LT_DIM * rank).map(|e| real(basis_at + 4 * e)).collect();
    let (_, codes) = decode_section(&file, vcof);
    let codes = &codes[per_voxel * VOXEL..per_voxel * (VOXEL + 1)];
    // d_m = offset_m + scale_m · code (§9), m = j·K_v + i.
    let d: Vec<f32> = codes
        .iter()
        .enumerate()
        .map(|(m, &code)| real(params_at + 8 * m + 4) + real(params_at + 8 * m) * f32::from(code))
        .collect();

    let light = sky();
    let pca = radiance_pca(&asset, &light);
    // ω: the difference in f64, rounded to f32, normalised by `view_harmonics`.
    let diff = (DVec3::from_array(CAMERA_M) - asset.voxel_position_m(VOXEL))
        .as_vec3()
        .to_array();
    let y = view_harmonics(diff);
    let (omega, as_specified) = harmonics_as_specified(diff);
    assert_eq!(
        y.map(f32::to_bits),
        as_specified.map(f32::to_bits),
        "view_harmonics differs from SPEC.md §6 VDEP's steps"
    );
    let lobe_values: Vec<f32> = (0..lobes)
        .map(|j| {
            let mut s = 0.0f32;
            for (l, yl) in y.iter().enumerate() {
                s += real(16 + 4 * (j * VIEW_HARMONICS + l)) * yl;
            }
            s
        })
        .collect();
    let view_light: Vec<[f32; 3]> = basis.chunks_exact(LT_DIM).map(|v| projected(v, &light)).collect();
    // C_j = Σ_i d_ji P^v_i, f32, i ascending; then radiance = radiance_pca + Σ_j Y_j C_j.
    let colours: Vec<[f32; 3]> = (0..lobes)
        .map(|j| {
            let mut rgb = [0.0f32; 3];
            for (i, p) in view_light.iter().enumerate() {
                for ch in 0..3 {
                    rgb[ch] += d[j * rank + i] * p[ch];
                }
            }
            rgb
        })
        .collect();
    let mut radiance = pca;
    for (yj, cj) in lobe_values.iter().zip(&colours) {
        for ch in 0..3 {
            radiance[ch] += yj * cj[ch];
        }
    }

    let mut out = version_and_length(&file, "VDEP", vdep.raw_length);
    out.extend([
        ("VDEP.J".into(), Expected::Int(vec![lobes as i64])),
        ("VDEP.K_v".into(), Expected::Int(vec![rank as i64])),
        ("VDEP.encoding".into(), Expected::Int(vec![encoding as i64])),
    ]);
    for j in 0..lobes {
        out.push((
            format!("VDEP.lobe{j}"),
            Expected::F32(
                (0..VIEW_HARMONICS)
                    .map(|l| real(16 + 4 * (j * VIEW_HARMONICS + l)))
                    .collect(),
            ),
        ));
    }
    for (i, e) in [(0, 0), (0, 64), (1, 0), (1, 128)] {
        out.push((
            format!("VDEP.V_{i}[{e}]"),
            Expected::F32(vec![basis[i * LT_DIM + e]]),
        ));
    }
    out.extend([
        (
            "VDEP.scale_offset".to_string(),
            Expected::F32((0..2 * per_voxel).map(|k| real(params_at + 4 * k)).collect()),
        ),
        (
            "VCOF.raw_length".into(),
            Expected::Int(vec![vcof.raw_length as i64]),
        ),
        (
            "VCOF.codes".into(),
            Expected::Int(codes.iter().map(|&x| i64::from(x)).collect()),
        ),
        ("d".into(), Expected::F32(d.clone())),
        ("radiance_pca".into(), Expected::F32(pca.to_vec())),
        ("eye - p".into(), Expected::F32(diff.to_vec())),
        ("omega".into(), Expected::F32(omega.to_vec())),
        ("y".into(), Expected::F32(y.to_vec())),
        ("Y".into(), Expected::F32(lobe_values)),
    ]);
    for (i, p) in view_light.iter().enumerate() {
        out.push((format!("P^v_{i}"), Expected::F32(p.to_vec())));
    }
    for (j, cj) in colours.iter().enumerate() {
        out.push((format!("C_{j}"), Expected::F32(cj.to_vec())));
    }
    out.push(("radiance".into(), Expected::F32(radiance.to_vec())));
    (out, radiance)
}

#[test]
fn view_example_agrees_with_the_transport() {
    // §17.8's steps against the format crate: the file reads back as the asset, the lobe
    // values are `ViewDependence::lobe_values`, and the radiance is the sky's dot product
    // with `T(x, ω)` (SPEC.md §8: equal up to rounding).
    let asset = view_asset();
    let (file, _) = encode_asset(&asset, &WriteOptions::default()).unwrap();
    assert_eq!(read_asset_bytes(&file).unwrap(), asset);
    let (values, radiance) = view_values();
    let diff = (DVec3::from_array(CAMERA_M) - asset.voxel_position_m(VOXEL))
        .as_vec3()
        .to_array();
    let lobes = asset.view.as_ref().unwrap().lobe_values(diff);
    let Some((_, Expected::F32(printed))) = values.iter().find(|(k, _)| k == "Y") else {
        panic!("no Y")
    };
    assert_eq!(printed, &lobes);
    let transport = shade(&asset.reconstruct_lt_toward(VOXEL, diff), &sky());
    for (a, b) in radiance.iter().zip(transport) {
        assert!((a - b).abs() <= 1e-6 * b.abs(), "{radiance:?} vs {transport:?}");
    }
}
