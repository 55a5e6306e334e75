//! The single-header C reader (`include/nelf.h`) against the Rust reader.
//!
//! The test compiles `tests/c/nelf_dump.c` (and the README's `include/example.c`) with
//! the system C compiler (`$NELF_C_READER_CC`, else `$CC`, else `cc`) in C99 with `-Wall -Wextra -Werror` and
//! `AddressSanitizer` + `UndefinedBehaviorSanitizer` (no recovery, leak checking on), then:
//!
//! * on valid files written by our writer (both coefficient encodings, signed density,
//!   ranks 1 to 384, zero bricks, raw and compressed sections, unknown optional
//!   sections, harmonic view parts (1.2) and reflection parts (1.3)), checks that every
//!   number the C reader gives equals the Rust reader's **bit for bit**: header, section
//!   table, metadata bytes, PCA model, every voxel's density, centre, dequantized
//!   coefficients and reconstructed `T`, and its radiance under a fixed 8 × 16 map both
//!   through the projected lighting and as a plain dot product (the Rust side of the
//!   projection mirrors `nelf_render::light`, which this crate cannot depend on); with a
//!   view part its view coefficients and `T` toward an eye; with a reflection part its
//!   parameters, every voxel's values, decoded normal and scale, and the octahedral
//!   decoding and lobe-table corners of fixed directions; with a fine density (1.4, at
//!   factors 2 and 4) the header's factor, every fine voxel's density and centre;
//! * on every damaged file of `common::damage` (the generator `damage.rs` uses) and on
//!   metadata edge cases, checks that the C reader refuses exactly the files the Rust
//!   reader refuses, with the matching error code and a message naming the same
//!   section, chunk, voxel or offset, from memory and by path, with and without
//!   reading every brick first, within its allocation bound, and without a sanitizer
//!   report.
//!
//! A missing compiler, header or library fails the test with the Debian packages to
//! install (`scripts/test` lists them); it is never skipped. Sanitizers are required;
//! `NELF_C_READER_NO_SANITIZERS=1` allows a compiler without them (and says so).
#![allow(clippy::unwrap_used)] // Test helpers outside #[test] functions unwrap too.

mod common;

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::OnceLock;

use common::damage::{self, Expect};
use common::{FileParts, small_asset, with_fine_density};
use nelf_format::conventions::VIEW_HARMONICS;
use nelf_format::conventions::{
    ENV_TEXELS, LT_DIM, LatLong, lobe_table_corners, octahedral_decode, shade, view_harmonics,
};
use nelf_format::spec::{
    BRICK_VOXELS, KIND_METADATA, KIND_PCA, SectionCodec, SectionEntry, checksum, shuffle, unshuffle,
};
use nelf_format::synthetic::{SyntheticField, synthetic_reflection, synthetic_view};
use nelf_format::{
    Asset, AssetReader, CoefficientEncoding, Coefficients, FormatError, PcaModel, Reflection, WriteOptions,
    encode_asset, encode_density, read_asset_bytes,
};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;
use xxhash_rust::xxh3::xxh3_64;

/// The Debian packages the C reader's tests need (also in `scripts/test`).
const PACKAGES: &str = "gcc libzstd-dev libxxhash-dev";

/// The compiled C programs.
struct CPrograms {
    dump: PathBuf,
    example: PathBuf,
}

/// Compiles the C programs once per test process.
fn programs() -> &'static CPrograms {
    static PROGRAMS: OnceLock<CPrograms> = OnceLock::new();
    PROGRAMS.get_or_init(compile)
}

fn repo_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .unwrap()
        .to_path_buf()
}

fn compile() -> CPrograms {
    // NELF_C_READER_CC changes the compiler of this test only (CC would rebuild the
    // -sys crates that cc-rs builds).
    let cc = std::env::var("NELF_C_READER_CC")
        .or_else(|_| std::env::var("CC"))
        .unwrap_or_else(|_| "cc".into());
    let out = Path::new(env!("CARGO_TARGET_TMPDIR")).join("c_reader");
    std::fs::create_dir_all(&out).unwrap();
    let version = Command::new(&cc).arg("--version").output();
    assert!(
        version.as_ref().is_ok_and(|o| o.status.success()),
        "the C reader tests need a C compiler (`{cc}`, or set $NELF_C_READER_CC): install the Debian packages {PACKAGES} \
         (scripts/test lists them): {version:?}"
    );
    let sanitize = ["-fsanitize=address,undefined", "-fno-sanitize-recover=all"];
    let probe = out.join("probe.c");
    std::fs::write(&probe, "int main(void) { return 0; }\n").unwrap();
    let probe_ok = Command::new(&cc)
        .args(sanitize)
        .arg(&probe)
        .arg("-o")
        .arg(out.join("probe"))
        .output()
        .is_ok_and(|o| o.status.success());
    let sanitize: &[&str] = if probe_ok {
        &sanitize
    } else if std::env::var_os("NELF_C_READER_NO_SANITIZERS").is_some_and(|v| v == "1") {
        eprintln!("c_reader: `{cc}` cannot link AddressSanitizer/UBSan; testing WITHOUT sanitizers");
        &[]
    } else {
        panic!(
            "`{cc}` cannot build with -fsanitize=address,undefined (GCC needs libasan and libubsan, \
             installed with the Debian package gcc); set NELF_C_READER_NO_SANITIZERS=1 to test without"
        );
    };
    let root = repo_root();
    let build = |source: PathBuf, name: &str| -> PathBuf {
        let binary = out.join(name);
        let output = Command::new(&cc)
            .args(["-std=c99", "-Wall", "-Wextra", "-Werror", "-O1", "-g"])
            .args(sanitize)
            .arg("-I")
            .arg(root.join("include"))
            .arg(&source)
            .arg("-o")
            .arg(&binary)
            .args(["-lzstd", "-lxxhash", "-lm"])
            .output()
            .unwrap();
        assert!(
            output.status.success(),
            "compiling {} failed; the C reader needs the Debian packages {PACKAGES} (scripts/test lists \
             them):\n{}",
            source.display(),
            String::from_utf8_lossy(&output.stderr)
        );
        binary
    };
    CPrograms {
        dump: build(root.join("format/tests/c/nelf_dump.c"), "nelf_dump"),
        example: build(root.join("include/example.c"), "nelf_example"),
    }
}

/// Runs a C program; asserts that no sanitizer (or anything else) wrote to stderr.
fn run(program: &Path, args: &[&std::ffi::OsStr]) -> Output {
    let output = Command::new(program)
        .args(args)
        .env("ASAN_OPTIONS", "detect_leaks=1:abort_on_error=0:exitcode=86")
        .env("UBSAN_OPTIONS", "print_stacktrace=1:halt_on_error=1:exitcode=87")
        .output()
        .unwrap();
    assert!(
        output.stderr.is_empty(),
        "{} {args:?} wrote to stderr (exit {:?}):\n{}",
        program.display(),
        output.status.code(),
        String::from_utf8_lossy(&output.stderr)
    );
    output
}

// ------------------------------------------------------------------ valid files

/// A fixed lighting map with varied (some zero, some negative) texels.
fn light() -> [[f32; 3]; ENV_TEXELS] {
    std::array::from_fn(|t| {
        [
            (t % 7) as f32 * 0.25 + 0.1,
            ((t * 5) % 11) as f32 / 3.0,
            match t % 17 {
                0 => -0.5,
                5 => 0.0,
                _ => 1.0 / (1.0 + t as f32),
            },
        ]
    })
}

/// An asset on one brick with a random (not orthonormal) PCA model of rank `rank`
/// (component 1, if any, all −0).
fn random_pca_asset(rank: usize, encoding: CoefficientEncoding, seed: u64) -> Asset {
    let field = SyntheticField::new(1, seed);
    let mut rng = Pcg64::seed_from_u64(seed);
    let mut pca = PcaModel {
        mean: (0..LT_DIM).map(|_| rng.random_range(-0.01..0.01)).collect(),
        basis: (0..rank * LT_DIM).map(|_| rng.random_range(-0.1..0.1)).collect(),
    };
    if rank > 1 {
        // A component of −0s: its projection onto the lighting is −0 only if sums
        // start from −0 as the reference's do.
        pca.basis[LT_DIM..2 * LT_DIM].fill(-0.0);
    }
    let values: Vec<f32> = (0..field.voxel_count() * rank)
        .map(|_| rng.random_range(-2.0..2.0))
        .collect();
    let coefficients = Coefficients::quantize(&values, rank, encoding).unwrap();
    field.asset_with(pca, coefficients).unwrap()
}

/// `asset` without any brick (nor view coefficients or reflection values).
fn without_bricks(mut asset: Asset) -> Asset {
    asset.bricks.clear();
    asset.density.clear();
    let clear = |c: &mut Coefficients| match c {
        Coefficients::U8Affine { codes, .. } => codes.clear(),
        Coefficients::F16 { values, .. } => values.clear(),
    };
    clear(&mut asset.coefficients);
    if let Some(view) = &mut asset.view {
        clear(&mut view.coefficients);
    }
    if let Some(part) = &mut asset.reflection {
        clear(&mut part.coefficients);
    }
    if let Some(fine) = &mut asset.fine_density {
        fine.values.clear();
    }
    asset
}

/// `asset` with a synthetic reflection part (format 1.3) of lobe exponent `exponent`.
fn with_reflection(mut asset: Asset, exponent: f32) -> Asset {
    asset.reflection = Some(synthetic_reflection(&asset, exponent, 19).unwrap());
    asset
}

/// `asset` with a reflection part of `eyes` eyes around the grid (1 to 16), random unit
/// normals and scales spread over 0..0.2 (some exactly 0), lobe exponent `exponent`.
fn with_random_reflection(mut asset: Asset, exponent: f32, eyes: usize, seed: u64) -> Asset {
    let mut rng = Pcg64::seed_from_u64(seed);
    let voxels = asset.voxel_count();
    let normals: Vec<[f32; 3]> = (0..voxels)
        .map(|_| {
            let n = glam::Vec3::new(
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
            );
            n.normalize_or(glam::Vec3::Y).to_array()
        })
        .collect();
    let scales: Vec<f32> = (0..voxels)
        .map(|v| {
            if v % 5 == 0 {
                0.0
            } else {
                rng.random_range(0.0..0.2)
            }
        })
        .collect();
    let eyes_m: Vec<[f32; 3]> = (0..eyes)
        .map(|e| {
            let angle = e as f32 * 0.4;
            [0.5 * angle.sin(), 0.1 * (e % 3) as f32, 0.5 * angle.cos()]
        })
        .collect();
    asset.reflection = Some(Reflection::new(exponent, eyes_m, &normals, &scales).unwrap());
    asset
}

/// `asset` with a synthetic view-dependent part (format 1.2).
fn with_view(mut asset: Asset, lobes: usize, rank: usize, encoding: CoefficientEncoding) -> Asset {
    asset.view = Some(synthetic_view(&asset, lobes, rank, encoding, 31).unwrap());
    asset
}

/// `asset` with negative densities (every third voxel) and some −0.
fn with_signed_density(mut asset: Asset, negatives: bool) -> Asset {
    let sigma: Vec<f32> = asset
        .density
        .iter()
        .enumerate()
        .map(|(i, d)| match (i % 3, i % 7) {
            (0, _) if negatives => -d.to_f32() - 0.5,
            (_, 0) => -0.0,
            _ => d.to_f32(),
        })
        .collect();
    asset.density = encode_density(&sigma).unwrap();
    asset
}

/// The file of `bytes` with PCAB stored raw, metadata compressed and shuffled (with
/// escapes and non-ASCII text), and two unknown optional sections (one with a codec
/// this reader does not know).
fn with_extra_sections(bytes: &[u8], asset: &Asset) -> Vec<u8> {
    let mut p = FileParts::parse(bytes);
    let pca: Vec<u8> = asset
        .pca
        .mean
        .iter()
        .chain(&asset.pca.basis)
        .flat_map(|v| v.to_le_bytes())
        .collect();
    let n = pca.len() as u64;
    p.replace(KIND_PCA, SectionCodec::Raw, 0, pca, n);
    let mut text = r#"{"name":"caf\u00e9 \ud83d\ude00 \"q\" \\ \/ \b\f\n\r\t","raw":"é ✓ 😀","n":[1,-0.5e-3,1E+2,0,-0,{"deep":[[[]]]}],"t":true,"f":false,"z":null, "": {} }"#
        .as_bytes()
        .to_vec();
    if text.len() % 2 == 1 {
        text.push(b' ');
    }
    let n = text.len() as u64;
    let stored = zstd::bulk::compress(&shuffle(&text, 2), 3).unwrap();
    p.replace(KIND_METADATA, SectionCodec::Zstd, 2, stored, n);
    for (kind, codec, data) in [
        (*b"XTRA", SectionCodec::Unknown(7), vec![7u8; 13]),
        (*b"x\x01\xffz", SectionCodec::Raw, b"opaque".to_vec()),
    ] {
        let entry = SectionEntry {
            kind,
            required: false,
            codec,
            shuffle: 3,
            offset: 0,
            stored_length: data.len() as u64,
            raw_length: 12_345,
            checksum: checksum(&data),
        };
        p.sections.insert(1, (entry, data));
    }
    p.build()
}

/// The valid files the C reader must read exactly as the Rust reader does, with
/// whether to compare every voxel in full (else hashes per brick).
fn valid_files() -> Vec<(&'static str, Vec<u8>, bool)> {
    use CoefficientEncoding::{F16, U8Affine};
    let encode = |asset: &Asset, options: WriteOptions| encode_asset(asset, &options).unwrap().0;
    let default = WriteOptions::default();
    let plain = WriteOptions {
        zstd_level: 3,
        chunk_bricks: 3,
        shuffle: false,
    };
    let one = WriteOptions {
        zstd_level: 1,
        chunk_bricks: 1,
        shuffle: true,
    };
    let huge_chunks = WriteOptions {
        zstd_level: -1,
        chunk_bricks: 1000,
        shuffle: false,
    };
    let u8_k4 = small_asset(U8Affine, 4, 21);
    let u8_k4_bytes = encode(&u8_k4, default);
    vec![
        ("u8 rank 4", u8_k4_bytes.clone(), true),
        (
            "f16 rank 6 unshuffled",
            encode(&small_asset(F16, 6, 5), plain),
            true,
        ),
        (
            "u8 rank 1 one-brick chunks",
            encode(&small_asset(U8Affine, 1, 7), one),
            true,
        ),
        (
            "f16 rank 1 one chunk",
            encode(&small_asset(F16, 1, 8), huge_chunks),
            true,
        ),
        (
            "u8 signed density",
            encode(&with_signed_density(small_asset(U8Affine, 3, 4), true), one),
            true,
        ),
        (
            "f16 signed density",
            encode(&with_signed_density(small_asset(F16, 2, 6), true), default),
            true,
        ),
        (
            "f16 with -0 densities",
            encode(&with_signed_density(small_asset(F16, 2, 9), false), plain),
            true,
        ),
        (
            "u8 rank 384",
            encode(&random_pca_asset(384, U8Affine, 11), default),
            true,
        ),
        (
            "f16 rank 384",
            encode(&random_pca_asset(384, F16, 12), plain),
            true,
        ),
        (
            "u8 rank 2 random basis",
            encode(&random_pca_asset(2, U8Affine, 13), one),
            true,
        ),
        (
            "u8 zero bricks",
            encode(&without_bricks(small_asset(U8Affine, 3, 2)), default),
            true,
        ),
        (
            "f16 zero bricks",
            encode(&without_bricks(small_asset(F16, 5, 3)), plain),
            true,
        ),
        ("extra sections", with_extra_sections(&u8_k4_bytes, &u8_k4), true),
        (
            "view u8 3 lobes rank 2, PCA u8",
            encode(&with_view(small_asset(U8Affine, 4, 21), 3, 2, U8Affine), default),
            true,
        ),
        (
            "view f16 1 lobe rank 5, PCA u8, one-brick chunks",
            encode(&with_view(small_asset(U8Affine, 2, 7), 1, 5, F16), one),
            true,
        ),
        (
            "view u8 all lobes rank 1, PCA f16, unshuffled",
            encode(
                &with_view(small_asset(F16, 3, 5), VIEW_HARMONICS, 1, U8Affine),
                plain,
            ),
            true,
        ),
        (
            "view f16 all lobes × rank 42, PCA f16 rank 384",
            encode(
                &with_view(
                    random_pca_asset(384, F16, 14),
                    VIEW_HARMONICS,
                    384 / VIEW_HARMONICS,
                    F16,
                ),
                default,
            ),
            true,
        ),
        (
            "view u8 zero bricks",
            encode(
                &without_bricks(with_view(small_asset(U8Affine, 3, 2), 2, 3, U8Affine)),
                default,
            ),
            true,
        ),
        (
            "view u8 2 lobes rank 4, 40k voxels",
            encode(
                &with_view(
                    SyntheticField::new(40_000, 3).asset(8, F16).unwrap(),
                    2,
                    4,
                    U8Affine,
                ),
                default,
            ),
            false,
        ),
        (
            "reflection λ 20, PCA u8",
            encode(&with_reflection(small_asset(U8Affine, 4, 21), 20.0), default),
            true,
        ),
        (
            "reflection 1 eye λ 1, PCA f16, one-brick chunks",
            encode(&with_random_reflection(small_asset(F16, 3, 5), 1.0, 1, 41), one),
            true,
        ),
        (
            "reflection 16 eyes λ 200, PCA u8 rank 1, unshuffled",
            encode(
                &with_random_reflection(small_asset(U8Affine, 1, 7), 200.0, 16, 42),
                plain,
            ),
            true,
        ),
        (
            "reflection zero bricks",
            encode(
                &without_bricks(with_reflection(small_asset(U8Affine, 3, 2), 40.0)),
                default,
            ),
            true,
        ),
        (
            "reflection λ 30, PCA f16 rank 8, 40k voxels, one chunk",
            encode(
                &with_reflection(SyntheticField::new(40_000, 3).asset(8, F16).unwrap(), 30.0),
                huge_chunks,
            ),
            false,
        ),
        (
            "u8 rank 16, 40k voxels",
            encode(
                &SyntheticField::new(40_000, 3).asset(16, U8Affine).unwrap(),
                default,
            ),
            false,
        ),
        (
            "fine density F 2, PCA u8",
            encode(
                &with_fine_density(small_asset(U8Affine, 4, 21), 2, false),
                default,
            ),
            true,
        ),
        (
            "fine density F 4 with negatives, PCA f16, one-brick chunks",
            encode(&with_fine_density(small_asset(F16, 3, 5), 4, true), one),
            true,
        ),
        (
            "fine density F 2 and signed density, unshuffled",
            encode(
                &with_fine_density(with_signed_density(small_asset(U8Affine, 2, 4), true), 2, true),
                plain,
            ),
            true,
        ),
        (
            "fine density F 4 and reflection λ 20",
            encode(
                &with_reflection(with_fine_density(small_asset(U8Affine, 4, 21), 4, false), 20.0),
                default,
            ),
            true,
        ),
        (
            "fine density F 2 and view f16 2 lobes rank 3",
            encode(
                &with_view(with_fine_density(small_asset(U8Affine, 3, 6), 2, true), 2, 3, F16),
                one,
            ),
            true,
        ),
        (
            "fine density F 4 zero bricks",
            encode(
                &without_bricks(with_fine_density(small_asset(F16, 2, 3), 4, false)),
                default,
            ),
            true,
        ),
        (
            "fine density F 4, PCA f16 rank 8, 40k voxels, 64-brick chunks",
            encode(
                &with_fine_density(SyntheticField::new(40_000, 3).asset(8, F16).unwrap(), 4, true),
                huge_chunks,
            ),
            false,
        ),
    ]
}

/// Appends `" XXXXXXXX"` (the bits in hex) for every value.
fn hex32<'a>(s: &mut String, values: impl IntoIterator<Item = &'a f32>) {
    for v in values {
        write!(s, " {:08x}", v.to_bits()).unwrap();
    }
}

/// Bytes as lowercase hex, two digits each.
fn hex_bytes(bytes: &[u8]) -> String {
    bytes.iter().fold(String::new(), |mut s, b| {
        write!(s, "{b:02x}").unwrap();
        s
    })
}

fn hash_f32(v: &[f32]) -> u64 {
    xxh3_64(&v.iter().flat_map(|x| x.to_le_bytes()).collect::<Vec<u8>>())
}

fn hash_f64(v: &[f64]) -> u64 {
    xxh3_64(&v.iter().flat_map(|x| x.to_le_bytes()).collect::<Vec<u8>>())
}

/// The decoded bytes of the metadata section (`{}` without one).
fn metadata_bytes(bytes: &[u8]) -> Vec<u8> {
    let parts = FileParts::parse(bytes);
    match parts.sections.iter().find(|(e, _)| e.kind == KIND_METADATA) {
        None => b"{}".to_vec(),
        Some((e, data)) if e.codec == SectionCodec::Raw => data.clone(),
        Some((e, data)) => unshuffle(
            &zstd::bulk::decompress(data, e.raw_length as usize).unwrap(),
            e.shuffle as usize,
        ),
    }
}

/// Mirror of `nelf_render::light::project_light_texels` for one vector and channel:
/// `Σ_t v[c·128 + t] · L[t][c]` in `f64` (summed from −0 in order, as `Iterator::sum`),
/// rounded to `f32`.
fn project(v: &[f32], light: &[[f32; 3]], c: usize) -> f32 {
    v[c * ENV_TEXELS..(c + 1) * ENV_TEXELS]
        .iter()
        .zip(light)
        .map(|(&t, l)| f64::from(t) * f64::from(l[c]))
        .sum::<f64>() as f32
}

/// The eye `nelf_dump` evaluates view-dependent transport toward (`ω = EYE − centre`,
/// the difference in `f64`, then `f32`, as `nelf_render::view` does).
const EYE: glam::DVec3 = glam::DVec3::new(0.31, 0.17, 0.52);

/// The directions whose harmonics `nelf_dump` prints (zero, axes, unnormalised, tiny,
/// overflowing, NaN).
const HARMONIC_DIRECTIONS: [[f32; 3]; 8] = [
    [0.0, 0.0, 0.0],
    [1.0, 0.0, 0.0],
    [0.0, -2.0, 0.0],
    [3.0, 4.0, 12.0],
    [-0.3, 0.7, 0.2],
    [1e-30, 2e-30, -1e-30],
    [1e20, 0.0, 1.0],
    [f32::NAN, 1.0, 1.0],
];

/// The octahedral `(u, v)` pairs whose decoding `nelf_dump` prints (inside, on and
/// outside the square, −0).
const OCTAHEDRAL_POINTS: [[f32; 2]; 8] = [
    [0.0, 0.0],
    [1.0, 1.0],
    [-1.0, 1.0],
    [0.3, -0.9],
    [2.0, -3.0],
    [-0.5, -0.5],
    [0.0, -1.0],
    [-0.0, 0.7],
];

/// The light-frame directions whose lobe-table corners `nelf_dump` prints (poles, either
/// side of the seam at φ = ±π, unnormalised, zero, overflowing).
const LOBE_DIRECTIONS: [[f32; 3]; 10] = [
    [0.0, 1.0, 0.0],
    [0.0, -1.0, 0.0],
    [0.0, 0.0, 1.0],
    [1e-4, 0.0, 1.0],
    [-1e-4, 0.2, 1.0],
    [3.0, 4.0, -12.0],
    [-0.3, 0.7, 0.2],
    [0.0, 0.0, 0.0],
    [1e20, 1e20, 0.0],
    [0.6, -0.3, -0.74],
];

/// What `nelf_dump dump` must print for `bytes`, from the Rust reader.
fn expected_dump(bytes: &[u8], full: bool) -> String {
    let reader = AssetReader::new(std::io::Cursor::new(bytes)).unwrap();
    let h = reader.header().clone();
    let sections = reader.sections().to_vec();
    drop(reader);
    let asset = read_asset_bytes(bytes).unwrap();
    let rank = asset.rank();
    let light = light();
    let basis_map = LatLong::basis(light);
    let mut s = String::new();
    write!(
        s,
        "header {} {} {} {:016x}",
        h.version_major, h.version_minor, h.section_count, h.flags
    )
    .unwrap();
    for v in h.grid.bbox_min_m.iter().chain(&h.grid.bbox_max_m()) {
        write!(s, " {:016x}", v.to_bits()).unwrap();
    }
    let g = h.grid.grid_bricks;
    write!(
        s,
        " {:016x} {} {} {} {} {}",
        h.grid.voxel_size_m.to_bits(),
        g[0],
        g[1],
        g[2],
        h.brick_count,
        h.chunk_bricks
    )
    .unwrap();
    for v in h.world_from_light.transpose().to_cols_array() {
        write!(s, " {:016x}", v.to_bits()).unwrap();
    }
    let stored_checksum = u64::from_le_bytes(bytes[248..256].try_into().unwrap());
    writeln!(
        s,
        " {} {} {} {} {} {} {stored_checksum:016x}",
        h.env_height,
        h.env_width,
        h.pca_rank,
        h.coefficient_encoding.to_u32(),
        h.fine_density_factor,
        h.file_size
    )
    .unwrap();
    for (i, e) in sections.iter().enumerate() {
        writeln!(
            s,
            "section {i} {} {} {} {} {} {} {} {:016x}",
            hex_bytes(&e.kind),
            u16::from(e.required),
            e.codec.to_u16(),
            e.shuffle,
            e.offset,
            e.stored_length,
            e.raw_length,
            e.checksum
        )
        .unwrap();
    }
    writeln!(s, "meta {}", hex_bytes(&metadata_bytes(bytes))).unwrap();
    if full {
        s.push_str("mean");
        hex32(&mut s, &asset.pca.mean);
        s.push_str("\nbasis");
        hex32(&mut s, &asset.pca.basis);
        s.push('\n');
    } else {
        writeln!(s, "mean {:016x}", hash_f32(&asset.pca.mean)).unwrap();
        writeln!(s, "basis {:016x}", hash_f32(&asset.pca.basis)).unwrap();
    }
    if let Coefficients::U8Affine { scale, offset, .. } = &asset.coefficients {
        s.push_str("scale");
        hex32(&mut s, scale);
        s.push_str("\noffset");
        hex32(&mut s, offset);
        s.push('\n');
    }
    if let Some(view) = &asset.view {
        writeln!(
            s,
            "view {} {} {}",
            view.lobe_count(),
            view.rank(),
            view.coefficients.encoding().to_u32()
        )
        .unwrap();
        if full {
            s.push_str("view_lobes");
            hex32(&mut s, &view.lobes);
            s.push_str("\nview_basis");
            hex32(&mut s, &view.basis);
            s.push('\n');
        } else {
            writeln!(s, "view_lobes {:016x}", hash_f32(&view.lobes)).unwrap();
            writeln!(s, "view_basis {:016x}", hash_f32(&view.basis)).unwrap();
        }
        if let Coefficients::U8Affine { scale, offset, .. } = &view.coefficients {
            s.push_str("view_scale");
            hex32(&mut s, scale);
            s.push_str("\nview_offset");
            hex32(&mut s, offset);
            s.push('\n');
        }
    }
    if let Some(part) = &asset.reflection {
        writeln!(
            s,
            "reflection {} {:08x}",
            part.eyes_m.len(),
            part.exponent.to_bits()
        )
        .unwrap();
        s.push_str("reflection_eyes");
        hex32(&mut s, part.eyes_m.iter().flatten());
        if let Coefficients::U8Affine { scale, offset, .. } = &part.coefficients {
            s.push_str("\nreflection_scale");
            hex32(&mut s, scale);
            s.push_str("\nreflection_offset");
            hex32(&mut s, offset);
        }
        s.push('\n');
    }
    s.push_str("octahedral");
    for [u, v] in OCTAHEDRAL_POINTS {
        hex32(&mut s, &octahedral_decode(u, v));
    }
    s.push_str("\nlobe_corners");
    for d in LOBE_DIRECTIONS {
        for (index, weight) in lobe_table_corners(d) {
            write!(s, " {index}:{:08x}", weight.to_bits()).unwrap();
        }
    }
    s.push('\n');
    s.push_str("harmonics");
    for omega in HARMONIC_DIRECTIONS {
        hex32(&mut s, &view_harmonics(omega));
    }
    s.push('\n');
    let mean_rgb: [f32; 3] = std::array::from_fn(|c| project(&asset.pca.mean, &light, c));
    let components: Vec<[f32; 3]> = (0..rank)
        .map(|k| std::array::from_fn(|c| project(asset.pca.component(k), &light, c)))
        .collect();
    s.push_str("light_mean");
    hex32(&mut s, &mean_rgb);
    s.push_str("\nlight_components");
    hex32(&mut s, components.iter().flatten());
    s.push('\n');
    let mut c = vec![0.0f32; rank];
    let per_view = asset.view.as_ref().map_or(0, |v| v.coefficients.rank());
    let mut d = vec![0.0f32; per_view];
    for (b, coord) in asset.bricks.iter().enumerate() {
        // The reflection part's three values per voxel, then its normal and scale.
        let mut reflection_values = Vec::new();
        let mut shapes = Vec::new();
        let mut view_coefficients = Vec::with_capacity(per_view * BRICK_VOXELS);
        let mut toward = Vec::with_capacity(LT_DIM * BRICK_VOXELS);
        let mut density = Vec::with_capacity(BRICK_VOXELS);
        let mut centres = Vec::with_capacity(3 * BRICK_VOXELS);
        let mut coefficients = Vec::with_capacity(rank * BRICK_VOXELS);
        let mut lts = Vec::with_capacity(LT_DIM * BRICK_VOXELS);
        let mut relit = Vec::with_capacity(6 * BRICK_VOXELS);
        for local in 0..BRICK_VOXELS {
            let v = b * BRICK_VOXELS + local;
            asset.coefficients_f32(v, &mut c);
            let t = asset.reconstruct_lt(v);
            let mut rgb = mean_rgb;
            for (ck, p) in c.iter().zip(&components) {
                for ch in 0..3 {
                    rgb[ch] += ck * p[ch];
                }
            }
            density.push(asset.density_at(v));
            centres.extend(asset.voxel_position_m(v).to_array());
            coefficients.extend_from_slice(&c);
            lts.extend_from_slice(&t);
            relit.extend(rgb);
            relit.extend(shade(&t, &basis_map));
            if let Some(view) = &asset.view {
                view.coefficients.voxel_f32(v, &mut d);
                view_coefficients.extend_from_slice(&d);
                let omega = (EYE - asset.voxel_position_m(v)).as_vec3().to_array();
                toward.extend(asset.reconstruct_lt_toward(v, omega));
            }
            if let Some(part) = &asset.reflection {
                let mut values = [0.0f32; Reflection::VALUES_PER_VOXEL];
                part.coefficients.voxel_f32(v, &mut values);
                reflection_values.extend(values);
                let (normal, scale) = part.voxel(v);
                shapes.extend(normal);
                shapes.push(scale);
            }
        }
        if full {
            writeln!(s, "brick {b} {} {} {}", coord[0], coord[1], coord[2]).unwrap();
            for local in 0..BRICK_VOXELS {
                write!(
                    s,
                    "v {} {:08x}",
                    b * BRICK_VOXELS + local,
                    density[local].to_bits()
                )
                .unwrap();
                for x in &centres[3 * local..3 * local + 3] {
                    write!(s, " {:016x}", x.to_bits()).unwrap();
                }
                hex32(&mut s, &coefficients[rank * local..rank * (local + 1)]);
                s.push_str(" |");
                hex32(&mut s, &lts[LT_DIM * local..LT_DIM * (local + 1)]);
                s.push_str(" |");
                hex32(&mut s, &relit[6 * local..6 * local + 6]);
                if per_view > 0 {
                    s.push_str(" |");
                    hex32(
                        &mut s,
                        &view_coefficients[per_view * local..per_view * (local + 1)],
                    );
                    s.push_str(" |");
                    hex32(&mut s, &toward[LT_DIM * local..LT_DIM * (local + 1)]);
                }
                if asset.reflection.is_some() {
                    s.push_str(" |");
                    hex32(&mut s, &reflection_values[3 * local..3 * local + 3]);
                    s.push_str(" |");
                    hex32(&mut s, &shapes[4 * local..4 * local + 4]);
                }
                s.push('\n');
            }
        } else {
            writeln!(
                s,
                "brick {b} {} {} {} {:016x} {:016x} {:016x} {:016x} {:016x}",
                coord[0],
                coord[1],
                coord[2],
                hash_f32(&density),
                hash_f64(&centres),
                hash_f32(&coefficients),
                hash_f32(&lts),
                hash_f32(&relit)
            )
            .unwrap();
            if per_view > 0 {
                writeln!(
                    s,
                    "view_brick {b} {:016x} {:016x}",
                    hash_f32(&view_coefficients),
                    hash_f32(&toward)
                )
                .unwrap();
            }
            if asset.reflection.is_some() {
                writeln!(
                    s,
                    "reflection_brick {b} {:016x} {:016x}",
                    hash_f32(&reflection_values),
                    hash_f32(&shapes)
                )
                .unwrap();
            }
        }
        if let Some(fine) = &asset.fine_density {
            // Every fine density value, and the centres of the fine voxels by SPEC.md
            // section 6: bbox_min + (8F·brick + (i, j, k) + ½)·Δ/F per axis, in f64.
            let (n, edge, f) = (fine.voxels_per_brick(), fine.brick_edge(), f64::from(fine.factor));
            let values: Vec<f32> = fine.values[b * n..(b + 1) * n]
                .iter()
                .map(|v| v.to_f32())
                .collect();
            let centres: Vec<f64> = (0..n)
                .flat_map(|local| {
                    let ijk = [local % edge, local / edge % edge, local / (edge * edge)];
                    (0..3).map(move |a| {
                        let index = f64::from(coord[a]) * edge as f64 + ijk[a] as f64 + 0.5;
                        asset.grid.bbox_min_m[a] + index * asset.grid.voxel_size_m / f
                    })
                })
                .collect();
            if full {
                write!(s, "fine {b}").unwrap();
                hex32(&mut s, &values);
                writeln!(s, " | {:016x}", hash_f64(&centres)).unwrap();
            } else {
                writeln!(
                    s,
                    "fine_brick {b} {:016x} {:016x}",
                    hash_f32(&values),
                    hash_f64(&centres)
                )
                .unwrap();
            }
        }
    }
    s.push_str("end\n");
    s
}

/// Asserts two dumps are equal, showing the first differing line.
fn assert_same_dump(what: &str, got: &str, want: &str) {
    if got == want {
        return;
    }
    let short = |l: &str| l.chars().take(400).collect::<String>();
    for (i, (g, w)) in got.lines().zip(want.lines()).enumerate() {
        if g != w {
            let token = g
                .split(' ')
                .zip(w.split(' '))
                .position(|(a, b)| a != b)
                .unwrap_or(0);
            panic!(
                "{what}: line {} differs at token {token}:\n  C:    {}\n  Rust: {}",
                i + 1,
                short(g),
                short(w)
            );
        }
    }
    panic!(
        "{what}: C printed {} lines, Rust expects {}; last C line: {}",
        got.lines().count(),
        want.lines().count(),
        short(got.lines().last().unwrap_or(""))
    );
}

#[test]
fn valid_files_read_bit_for_bit_like_the_rust_reader() {
    let programs = programs();
    let dir = tempfile::tempdir().unwrap();
    let light_path = dir.path().join("light.txt");
    let light_text = light().iter().flatten().fold(String::new(), |mut s, v| {
        writeln!(s, "{:08x}", v.to_bits()).unwrap();
        s
    });
    std::fs::write(&light_path, light_text).unwrap();
    for (i, (what, bytes, full)) in valid_files().into_iter().enumerate() {
        let path = dir.path().join(format!("valid-{i}.nelf"));
        std::fs::write(&path, &bytes).unwrap();
        // From memory with every voxel (or hashes for the big file), and by path with hashes.
        let modes: &[(&str, bool)] = if full {
            &[("mem", true), ("path", false)]
        } else {
            &[("mem", false), ("path", false)]
        };
        for &(mode, full) in modes {
            let detail = if full { "full" } else { "hashed" };
            let output = run(
                &programs.dump,
                &[
                    "dump".as_ref(),
                    path.as_os_str(),
                    light_path.as_os_str(),
                    mode.as_ref(),
                    detail.as_ref(),
                ],
            );
            let got = String::from_utf8(output.stdout).unwrap();
            assert!(
                output.status.success(),
                "{what} ({mode}): the C reader refused a valid file: {}",
                got.lines().last().unwrap_or("")
            );
            assert_same_dump(
                &format!("{what} ({mode}, {detail})"),
                &got,
                &expected_dump(&bytes, full),
            );
        }
        eprintln!("c_reader: {what}: {} bytes identical", bytes.len());
    }
}

#[test]
fn example_program_runs() {
    let programs = programs();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("example.nelf");
    let asset = small_asset(CoefficientEncoding::U8Affine, 3, 1);
    std::fs::write(&path, encode_asset(&asset, &WriteOptions::default()).unwrap().0).unwrap();
    // The README shows the example as it is (after its two comment lines).
    let root = repo_root();
    let source = std::fs::read_to_string(root.join("include/example.c")).unwrap();
    let body = source.split_once("*/\n").unwrap().1;
    let readme = std::fs::read_to_string(root.join("include/README.md")).unwrap();
    assert!(
        readme.contains(&format!("```c\n{body}```")),
        "include/README.md no longer shows include/example.c"
    );
    let output = run(&programs.example, &[path.as_os_str()]);
    let text = String::from_utf8(output.stdout).unwrap();
    assert!(output.status.success(), "{text}");
    assert!(
        text.starts_with(&format!("{} bricks, rank 3,", asset.bricks.len())),
        "{text}"
    );
    assert!(text.contains("voxel 100: density"), "{text}");
    assert!(!text.contains("reflect"), "{text}");
    // With a reflection part (format 1.3): its exponent, eyes and one voxel's normal.
    let reflecting = with_reflection(asset, 20.0);
    std::fs::write(
        &path,
        encode_asset(&reflecting, &WriteOptions::default()).unwrap().0,
    )
    .unwrap();
    let output = run(&programs.example, &[path.as_os_str()]);
    let text = String::from_utf8(output.stdout).unwrap();
    assert!(output.status.success(), "{text}");
    assert!(
        text.contains("\nreflection part: lobe exponent 20, 5 eyes\n"),
        "{text}"
    );
    let (n, s) = reflecting.reflection.as_ref().unwrap().voxel(100);
    let want = format!(
        "voxel 100 reflects: normal {:.3} {:.3} {:.3}, scale",
        n[0], n[1], n[2]
    );
    assert!(text.contains(&want), "{text} lacks {want}");
    assert!(s >= 0.0);
    assert!(!text.contains("fine"), "{text}");
    // With a fine density (format 1.4): its factor and the last fine voxel of brick 0.
    let fine = with_fine_density(small_asset(CoefficientEncoding::U8Affine, 3, 1), 4, false);
    std::fs::write(&path, encode_asset(&fine, &WriteOptions::default()).unwrap().0).unwrap();
    let output = run(&programs.example, &[path.as_os_str()]);
    let text = String::from_utf8(output.stdout).unwrap();
    assert!(output.status.success(), "{text}");
    assert!(text.contains("\nfine density: 4 x finer per axis\n"), "{text}");
    let last = fine.fine_density.as_ref().unwrap().values[32_767].to_f32();
    assert!(last > 0.0, "{last}");
    // printf's %g: six significant digits.
    let printed: f64 = text
        .split_once("fine voxel 32767: density ")
        .and_then(|(_, rest)| rest.split_once(" 1/m"))
        .map_or_else(
            || panic!("{text} lacks fine voxel 32767"),
            |(number, _)| number.parse().unwrap(),
        );
    assert!(
        (printed - f64::from(last)).abs() <= 1e-5 * f64::from(last),
        "{printed} vs {last}"
    );
    // A damaged file: a message and exit status 1.
    std::fs::write(&path, b"not a nelf file at all").unwrap();
    let output = Command::new(&programs.example).arg(&path).output().unwrap();
    assert_eq!(output.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&output.stderr).contains("bad magic"));
}

// ------------------------------------------------------------------ damaged files

/// The C code the C reader must give for a Rust reader error (one per variant; the
/// variants that carry a field or a place map to the C reader's finer codes).
fn c_code(err: &FormatError) -> &'static str {
    use FormatError as E;
    match err {
        E::Io(_) | E::Stream { .. } => "NELF_ERR_IO",
        E::BadMagic { .. } => "NELF_ERR_BAD_MAGIC",
        E::UnsupportedVersion { .. } => "NELF_ERR_UNSUPPORTED_VERSION",
        E::Truncated { .. } => "NELF_ERR_TRUNCATED",
        E::FileSizeMismatch { .. } => "NELF_ERR_FILE_SIZE_MISMATCH",
        E::InvalidHeader { field, reason } => match *field {
            "header_size" => "NELF_ERR_HEADER_SIZE",
            "section_entry_size" => "NELF_ERR_SECTION_ENTRY_SIZE",
            "grid" => "NELF_ERR_GRID",
            "bbox_max" => "NELF_ERR_BBOX_MAX",
            "brick_size" => "NELF_ERR_BRICK_SIZE",
            "world_from_light" => "NELF_ERR_NOT_A_ROTATION",
            "env_size" => "NELF_ERR_ENV_SIZE",
            "coefficient_encoding" if reason.contains("QPRM") => "NELF_ERR_UNEXPECTED_QPRM",
            "coefficient_encoding" => "NELF_ERR_BAD_ENCODING",
            "chunk_bricks" => "NELF_ERR_CHUNK_BRICKS",
            "fine_density_factor" => "NELF_ERR_FINE_DENSITY_FACTOR",
            _ => "unmapped InvalidHeader field",
        },
        E::UnsupportedFeature { .. } => "NELF_ERR_UNSUPPORTED_FEATURE",
        E::NonFinite { what } if what.starts_with("header field") => "NELF_ERR_NONFINITE_HEADER",
        E::NonFinite { what } if what.starts_with("PCA") => "NELF_ERR_NONFINITE_PCA",
        E::NonFinite { what } if what.contains("VDEP") || what.contains("VREF") => "NELF_ERR_NONFINITE_VIEW",
        E::NonFinite { what } if what.contains("QPRM") => "NELF_ERR_NONFINITE_QPRM",
        E::NonFinite { what } if what.contains("DENS") || what.contains("DNSF") => {
            "NELF_ERR_NONFINITE_DENSITY"
        }
        E::NonFinite { what } if what.contains("COEF") || what.contains("VCOF") => {
            "NELF_ERR_NONFINITE_COEFFICIENT"
        }
        E::NonFinite { .. } => "unmapped NonFinite",
        E::BadRank { .. } => "NELF_ERR_BAD_RANK",
        E::TooManySections { .. } => "NELF_ERR_TOO_MANY_SECTIONS",
        E::SectionOutOfBounds { .. } => "NELF_ERR_SECTION_OUT_OF_BOUNDS",
        E::Misaligned { .. } => "NELF_ERR_MISALIGNED",
        E::SectionsOverlap { .. } => "NELF_ERR_SECTIONS_OVERLAP",
        E::DuplicateSection { .. } => "NELF_ERR_DUPLICATE_SECTION",
        E::MissingSection { .. } => "NELF_ERR_MISSING_SECTION",
        E::UnknownRequiredSection { .. } => "NELF_ERR_UNKNOWN_REQUIRED_SECTION",
        E::BadCodec { .. } => "NELF_ERR_BAD_CODEC",
        E::SectionLength { .. } => "NELF_ERR_SECTION_LENGTH",
        E::ImplausibleLength { .. } => "NELF_ERR_IMPLAUSIBLE_LENGTH",
        E::CountTooLarge { what, .. } if what.starts_with("chunks in") => "NELF_ERR_CHUNK_COUNT",
        E::CountTooLarge { what, .. } if what.contains("decoded length") => "NELF_ERR_METADATA_TOO_LARGE",
        E::CountTooLarge { .. } => "NELF_ERR_CHUNK_TOO_LARGE",
        E::ChecksumMismatch { what, .. } if what == "header and section table" => "NELF_ERR_HEADER_CHECKSUM",
        E::ChecksumMismatch { what, .. } if what.contains(" chunk ") => "NELF_ERR_CHUNK_CHECKSUM",
        E::ChecksumMismatch { .. } => "NELF_ERR_SECTION_CHECKSUM",
        E::BadChunkTable { .. } => "NELF_ERR_BAD_CHUNK_TABLE",
        E::Zstd { .. } => "NELF_ERR_ZSTD",
        E::Json(_) => "NELF_ERR_METADATA_JSON",
        E::MetadataNotObject { .. } => "NELF_ERR_METADATA_NOT_OBJECT",
        E::InvalidBricks(_) => "NELF_ERR_INVALID_BRICKS",
        E::InvalidValue { what, .. } if what.contains("DENS") || what.contains("DNSF") => {
            "NELF_ERR_NEGATIVE_DENSITY"
        }
        E::InvalidValue { .. } => "NELF_ERR_NEGATIVE_SCALE",
        E::NonZeroPadding { .. } => "NELF_ERR_NONZERO_PADDING",
        E::BrickOutOfRange { .. } => "NELF_ERR_BRICK_OUT_OF_RANGE",
        E::InvalidView(_) => "NELF_ERR_BAD_VIEW",
        E::InvalidAsset(_) => "unmapped InvalidAsset",
    }
}

/// The places a Rust error message names (known section kinds, "chunk 3", "voxel 700",
/// "offset 1234", ...), which the C reader's message must name too.
fn anchors(message: &str) -> Vec<String> {
    let mut out: Vec<String> = [
        "BRCK", "DENS", "DNSF", "PCAB", "QPRM", "COEF", "VDEP", "VCOF", "VREF", "VRCO", "META",
    ]
    .into_iter()
    .filter(|k| message.contains(k))
    .map(String::from)
    .collect();
    for key in ["chunk", "voxel", "component", "brick", "offset", "element", "eye"] {
        let pattern = format!("{key} ");
        for (i, _) in message.match_indices(&pattern) {
            let digits: String = message[i + pattern.len()..]
                .chars()
                .take_while(char::is_ascii_digit)
                .collect();
            if !digits.is_empty() {
                out.push(format!("{key} {digits}"));
            }
        }
    }
    out
}

/// One line of `nelf_dump check`.
#[derive(Debug)]
struct CheckLine {
    whole: String,
    random: String,
    path: String,
    peak: u64,
    detail: String,
}

/// Runs `nelf_dump check` on many files at once.
fn c_check(files: &[(String, Vec<u8>)]) -> Vec<CheckLine> {
    let programs = programs();
    let dir = tempfile::tempdir().unwrap();
    let mut bundle = Vec::new();
    for (name, bytes) in files {
        bundle.extend_from_slice(&(name.len() as u32).to_le_bytes());
        bundle.extend_from_slice(name.as_bytes());
        bundle.extend_from_slice(&(bytes.len() as u64).to_le_bytes());
        bundle.extend_from_slice(bytes);
    }
    let bundle_path = dir.path().join("bundle");
    std::fs::write(&bundle_path, bundle).unwrap();
    let scratch = dir.path().join("scratch.nelf");
    let output = run(
        &programs.dump,
        &["check".as_ref(), bundle_path.as_os_str(), scratch.as_os_str()],
    );
    assert!(output.status.success(), "nelf_dump check failed");
    let text = String::from_utf8(output.stdout).unwrap();
    let lines: Vec<CheckLine> = text
        .lines()
        .enumerate()
        .map(|(i, line)| {
            let f: Vec<&str> = line.splitn(6, '\t').collect();
            assert_eq!(f.len(), 6, "bad line {line}");
            assert_eq!(f[0], i.to_string());
            CheckLine {
                whole: f[1].into(),
                random: f[2].into(),
                path: f[3].into(),
                peak: f[4].parse().unwrap(),
                detail: f[5].into(),
            }
        })
        .collect();
    assert_eq!(lines.len(), files.len(), "the C checker stopped early");
    lines
}

/// Checks the C reader's answers against the Rust reader's for every file; returns
/// the number of files both refused.
fn compare_with_rust(files: &[(String, Vec<u8>)]) -> usize {
    let lines = c_check(files);
    let mut refused = 0;
    let mut worst_margin = i128::MAX;
    for ((what, bytes), c) in files.iter().zip(&lines) {
        assert_eq!(
            c.path, c.whole,
            "{what}: by path {} but from memory {}",
            c.path, c.whole
        );
        // Bounded allocation: the reader's own blocks never exceed three times the file
        // (brick list, its copy, chunk tables) plus the format's fixed limits (five
        // 4 MiB chunk buffers: DENS, COEF, VCOF or VRCO, DNSF and the unshuffle; 1 MiB
        // metadata and its unshuffle, the PCA model, VDEP and the brick buffers).
        let bound = 3 * bytes.len() as u64 + (26 << 20);
        assert!(c.peak <= bound, "{what}: the C reader allocated {} bytes", c.peak);
        worst_margin = worst_margin.min(i128::from(bound) - i128::from(c.peak));
        match read_asset_bytes(bytes) {
            Ok(_) => {
                assert_eq!(
                    (c.whole.as_str(), c.random.as_str()),
                    ("NELF_OK", "NELF_OK"),
                    "{what}: the Rust reader accepts it, the C reader says {}",
                    c.detail
                );
            }
            Err(err) => {
                refused += 1;
                assert_eq!(
                    c.whole,
                    c_code(&err),
                    "{what}: Rust says {err}; C says {}",
                    c.detail
                );
                assert_ne!(c.random, "NELF_OK", "{what}: random access accepted it");
                for anchor in anchors(&err.to_string()) {
                    assert!(
                        c.detail.contains(&anchor),
                        "{what}: Rust says {err}; C says {} (without {anchor:?})",
                        c.detail
                    );
                }
            }
        }
    }
    eprintln!(
        "c_reader: {} files, {refused} refused by both readers; smallest allocation margin {worst_margin} bytes",
        files.len()
    );
    refused
}

#[test]
fn damaged_files_fail_like_the_rust_reader() {
    let cases = damage::all();
    let mut must_fail = 0;
    let files: Vec<(String, Vec<u8>)> = cases
        .into_iter()
        .map(|case| {
            if matches!(case.expect, Expect::Error(_)) {
                must_fail += 1;
            }
            (case.what, case.bytes)
        })
        .collect();
    let refused = compare_with_rust(&files);
    assert!(refused >= must_fail, "{refused} refused, {must_fail} must be");
}

/// Metadata texts around the edges of JSON as `serde_json` (the reference) reads it.
fn metadata_cases() -> Vec<Vec<u8>> {
    let big = "179769313486231580793728971405303415079934132710037826936173778980444968292764750946649017977\
               587207096330286416692887910946555547851940402630657488671505820681908902000708383676273854845\
               817711531764475730270069855571366959622842914819860834936475292719074168444365510704342711559\
               699508093042880177904174497792";
    let below = format!("{}1", &big[..big.len() - 1]);
    let nest = |depth: usize| format!("{{\"a\":{}{}}}", "[".repeat(depth), "]".repeat(depth));
    let mut texts: Vec<Vec<u8>> = [
        "{}",
        " \t\r\n{ \"a\" : 1 } \n",
        "{\"a\":1,\"a\":2}",
        "{\"\":{},\"b\":[true,false,null,\"x\",-0,0.5e-7,12E+3,1e-400,0e999999999999]}",
        "{\"s\":\"\\u00e9\\uD83D\\uDE00\\/\\b\\f\\n\\r\\t\\\"\\\\\"}",
        "{\"s\":\"é ✓ 😀 \u{7f}\"}",
        "",
        " ",
        "{",
        "}",
        "{\"a\"}",
        "{\"a\":}",
        "{\"a\":1,}",
        "{\"a\":[1,]}",
        "{,}",
        "{a:1}",
        "{'a':1}",
        "{\"a\":01}",
        "{\"a\":-01}",
        "{\"a\":1.}",
        "{\"a\":.5}",
        "{\"a\":-}",
        "{\"a\":+1}",
        "{\"a\":1e}",
        "{\"a\":1e+}",
        "{\"a\":0x10}",
        "{\"a\":NaN}",
        "{\"a\":Infinity}",
        "{\"a\":tru}",
        "{\"a\":True}",
        "{\"a\":nul}",
        "{\"a\":\"\\x\"}",
        "{\"a\":\"\\u12\"}",
        "{\"a\":\"\\u12G4\"}",
        "{\"a\":\"\\ud800\"}",
        "{\"a\":\"\\udc00\"}",
        "{\"a\":\"\\ud800\\u0041\"}",
        "{\"a\":\"\\ud800\\ud800\"}",
        "{\"a\":\"\\ud800x\"}",
        "{\"a\":\"\\ud800\\n\"}",
        "{\"a\":\"unterminated}",
        "{\"a\":\"tab\tinside\"}",
        "{\"a\":1e308}",
        "{\"a\":1.7976931348623157e308}",
        "{\"a\":1.7976931348623158e308}",
        "{\"a\":1.7976931348623159e308}",
        "{\"a\":-1.7976931348623159e308}",
        "{\"a\":1e309}",
        "{\"a\":0.0001e313}",
        "{\"a\":0.00001e313}",
        "{\"a\":1e99999999999999999999}",
        "{\"a\":1e-99999999999999999999}",
        "{\"a\":0e99999999999999999999}",
        "{\"a\":123456789012345678901234567890}",
        "{\"a\":18446744073709551616}",
        "{\"a\":-9223372036854775809}",
        "{} x",
        "{}{}",
        "{}\u{c}",
        "\u{feff}{}",
        "[]",
        "[1, 2]",
        "1",
        "\"s\"",
        "null",
        "true",
    ]
    .iter()
    .map(|s| s.as_bytes().to_vec())
    .collect();
    for number in [
        big.to_string(),
        below.clone(),
        format!("-{big}"),
        format!("{big}.0000"),
        format!("{below}.99999"),
        format!("0.{below}e309"),
        format!("0.{big}e309"),
        format!("0.000{big}e312"),
        format!("{}e1", &big[..200]),
    ] {
        texts.push(format!("{{\"n\":{number}}}").into_bytes());
    }
    for depth in [1, 125, 126, 127, 128, 200] {
        texts.push(nest(depth).into_bytes());
    }
    // Raw bytes that are not UTF-8 (or are, at the edges), inside a string.
    for bad in [
        &[0xC0, 0x80][..],
        &[0xC1, 0xBF],
        &[0xC2, 0x80],
        &[0xDF, 0xBF],
        &[0xE0, 0x80, 0x80],
        &[0xE0, 0xA0, 0x80],
        &[0xED, 0x9F, 0xBF],
        &[0xED, 0xA0, 0x80],
        &[0xEF, 0xBF, 0xBF],
        &[0xF0, 0x8F, 0xBF, 0xBF],
        &[0xF0, 0x90, 0x80, 0x80],
        &[0xF4, 0x8F, 0xBF, 0xBF],
        &[0xF4, 0x90, 0x80, 0x80],
        &[0xF5, 0x80, 0x80, 0x80],
        &[0xFF],
        &[0x80],
        &[0xE2, 0x82],
        &[0xE2, 0x82, 0x41],
        &[0x01],
        &[0x1F],
    ] {
        let mut text = b"{\"a\":\"x".to_vec();
        text.extend_from_slice(bad);
        text.extend_from_slice(b"y\"}");
        texts.push(text);
    }
    texts
}

#[test]
fn metadata_json_is_judged_like_serde_json() {
    let (_, bytes) = damage::encoded(CoefficientEncoding::U8Affine);
    let files: Vec<(String, Vec<u8>)> = metadata_cases()
        .into_iter()
        .map(|text| {
            let mut p = FileParts::parse(&bytes);
            let n = text.len() as u64;
            let name = format!(
                "metadata {:?}",
                String::from_utf8_lossy(&text[..text.len().min(60)])
            );
            p.replace(KIND_METADATA, SectionCodec::Raw, 0, text, n);
            (name, p.build())
        })
        .collect();
    let refused = compare_with_rust(&files);
    // Both outcomes are exercised.
    assert!(
        refused > 20 && refused + 20 < files.len(),
        "{refused} of {}",
        files.len()
    );
}

// ------------------------------------------------------------------ fuzz seeds

/// Small valid files (few bricks, every encoding and codec path) for the C fuzzer's seed
/// corpus (`include/fuzz/run.sh` sets `NELF_C_FUZZ_SEEDS` to a folder to write them to).
#[test]
fn fuzz_seeds_are_read_by_the_c_reader() {
    use CoefficientEncoding::{F16, U8Affine};
    let field = SyntheticField::new(1, 1);
    let mut seeds: Vec<(String, Vec<u8>)> = Vec::new();
    let cases = [
        (U8Affine, 2, 1, true),
        (F16, 3, 2, false),
        (U8Affine, 4, 32, false),
        (F16, 1, 3, true),
    ];
    for (i, (encoding, rank, chunk_bricks, shuffle)) in cases.into_iter().enumerate() {
        let asset = field.asset(rank, encoding).unwrap();
        let options = WriteOptions {
            zstd_level: 3,
            chunk_bricks,
            shuffle,
        };
        let bytes = encode_asset(&asset, &options).unwrap().0;
        if i == 0 {
            seeds.push(("seed-extra.nelf".into(), with_extra_sections(&bytes, &asset)));
            let signed = with_signed_density(asset.clone(), true);
            seeds.push((
                "seed-signed.nelf".into(),
                encode_asset(&signed, &options).unwrap().0,
            ));
            seeds.push((
                "seed-empty.nelf".into(),
                encode_asset(&without_bricks(asset), &options).unwrap().0,
            ));
        }
        seeds.push((format!("seed-{i}.nelf"), bytes));
    }
    // View-dependent files (format 1.2), both encodings.
    for (i, encoding) in [U8Affine, F16].into_iter().enumerate() {
        let asset = with_view(field.asset(2, encoding).unwrap(), 2, 2, encoding);
        let options = WriteOptions {
            zstd_level: 3,
            chunk_bricks: 1,
            shuffle: i == 0,
        };
        seeds.push((
            format!("seed-view-{i}.nelf"),
            encode_asset(&asset, &options).unwrap().0,
        ));
    }
    // Reflection parts (format 1.3): several eyes, and one eye with one-brick chunks.
    for (i, (eyes, chunk_bricks)) in [(5, 2), (1, 1)].into_iter().enumerate() {
        let base = field.asset(2, U8Affine).unwrap();
        let asset = if eyes == 5 {
            with_reflection(base, 20.0)
        } else {
            with_random_reflection(base, 8.0, eyes, 3)
        };
        let options = WriteOptions {
            zstd_level: 3,
            chunk_bricks,
            shuffle: i == 0,
        };
        seeds.push((
            format!("seed-reflection-{i}.nelf"),
            encode_asset(&asset, &options).unwrap().0,
        ));
    }
    // Fine densities (format 1.4): factor 2 with negative values (signed-density flag) in
    // one-brick chunks, and factor 4 beside a reflection part.
    let base = field.asset(2, U8Affine).unwrap();
    for (i, asset) in [
        with_fine_density(base.clone(), 2, true),
        with_reflection(with_fine_density(base, 4, false), 20.0),
    ]
    .into_iter()
    .enumerate()
    {
        let options = WriteOptions {
            zstd_level: 3,
            chunk_bricks: 1,
            shuffle: i == 0,
        };
        seeds.push((
            format!("seed-fine-density-{i}.nelf"),
            encode_asset(&asset, &options).unwrap().0,
        ));
    }
    // A few bricks in one-brick chunks, so that mutations reach the brick-order checks.
    let several = SyntheticField::new(3 * BRICK_VOXELS, 2)
        .asset(1, U8Affine)
        .unwrap();
    let options = WriteOptions {
        zstd_level: 3,
        chunk_bricks: 1,
        shuffle: true,
    };
    seeds.push((
        "seed-bricks.nelf".into(),
        encode_asset(&several, &options).unwrap().0,
    ));
    let refused = compare_with_rust(&seeds);
    assert_eq!(refused, 0);
    if let Some(dir) = std::env::var_os("NELF_C_FUZZ_SEEDS") {
        let dir = PathBuf::from(dir);
        std::fs::create_dir_all(&dir).unwrap();
        for (name, bytes) in &seeds {
            std::fs::write(dir.join(name), bytes).unwrap();
        }
        eprintln!("c_reader: wrote {} fuzz seeds to {}", seeds.len(), dir.display());
    }
}
