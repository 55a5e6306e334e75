//! Codec benchmark for `.nelf` v1 (`cargo bench -p nelf-format --bench codec`):
//! a synthetic 200k-voxel asset (`nelf_format::synthetic`), PCA rank K ∈ {4, 8, 16, 32},
//! coefficients as 8-bit affine or f16, with and without the byte shuffle before zstd.
//! Prints markdown tables: compressed size, encode/decode throughput in MB/s of decoded
//! payload (medians), and the error of the reconstructed light-transport vectors T
//! (quantization alone, and the PCA truncation it sits on), then sweeps of zstd level
//! and chunk size, and random access to single bricks.

use std::hint::black_box;
use std::io::Cursor;
use std::time::{Duration, Instant};

use nelf_format::conventions::LT_DIM;
use nelf_format::synthetic::SyntheticField;
use nelf_format::{
    Asset, AssetReader, CoefficientEncoding, Coefficients, FormatError, PcaModel, WriteOptions, encode_asset,
    read_asset_bytes,
};

const VOXELS: usize = 200_000;
const MAX_RANK: usize = 32;

/// Median wall time of `reps` runs of `f`.
fn median_time(reps: usize, mut f: impl FnMut()) -> Duration {
    let mut times: Vec<Duration> = (0..reps)
        .map(|_| {
            let t = Instant::now();
            f();
            t.elapsed()
        })
        .collect();
    times.sort();
    times[times.len() / 2]
}

fn mb_per_s(bytes: u64, t: Duration) -> f64 {
    bytes as f64 / 1e6 / t.as_secs_f64()
}

/// First `rank` of every voxel's `MAX_RANK` coefficients.
fn leading(coefficients: &[f32], rank: usize) -> Vec<f32> {
    coefficients
        .chunks_exact(MAX_RANK)
        .flat_map(|c| c[..rank].iter().copied())
        .collect()
}

/// Max and RMS over all voxels and 384 entries of `Σ_k (ĉ_k − c_k) B_k`, the change in
/// reconstructed T caused by quantization.
fn quantization_error(pca: &PcaModel, exact: &[f32], quantized: &Coefficients) -> (f64, f64) {
    let rank = pca.rank();
    let dequantized = quantized.to_f32();
    let (mut max, mut sum2) = (0.0f64, 0.0f64);
    let mut dt = vec![0.0f32; LT_DIM];
    for (e, q) in exact.chunks_exact(rank).zip(dequantized.chunks_exact(rank)) {
        dt.fill(0.0);
        for k in 0..rank {
            let d = q[k] - e[k];
            for (x, b) in dt.iter_mut().zip(pca.component(k)) {
                *x += d * b;
            }
        }
        for &x in &dt {
            max = max.max(f64::from(x.abs()));
            sum2 += f64::from(x) * f64::from(x);
        }
    }
    (max, (sum2 / (exact.len() / rank * LT_DIM) as f64).sqrt())
}

/// RMS of T and RMS of (T − PCA reconstruction with exact coefficients) over every 8th voxel.
fn truncation_error(field: &SyntheticField, pca: &PcaModel, exact: &[f32]) -> (f64, f64) {
    let rank = pca.rank();
    let (mut t2, mut e2, mut n) = (0.0f64, 0.0f64, 0usize);
    let (mut t, mut r) = (vec![0.0f32; LT_DIM], vec![0.0f32; LT_DIM]);
    for v in (0..field.voxel_count()).step_by(8) {
        field.lt(v, &mut t);
        pca.reconstruct_into(&exact[v * rank..(v + 1) * rank], &mut r);
        for (a, b) in t.iter().zip(&r) {
            t2 += f64::from(*a).powi(2);
            e2 += f64::from(a - b).powi(2);
        }
        n += LT_DIM;
    }
    ((t2 / n as f64).sqrt(), (e2 / n as f64).sqrt())
}

struct Measured {
    file_bytes: usize,
    raw_bytes: u64,
    encode: Duration,
    decode: Duration,
}

fn measure(asset: &Asset, options: &WriteOptions, reps: usize) -> Result<Measured, FormatError> {
    let (bytes, sections) = encode_asset(asset, options)?;
    let raw_bytes: u64 = sections.iter().map(|s| s.raw_length).sum();
    assert!(read_asset_bytes(&bytes)? == *asset, "round trip");
    // Both calls succeeded above; inside the timed loops only the work counts.
    let encode = median_time(reps, || {
        let _ = black_box(encode_asset(black_box(asset), options));
    });
    let decode = median_time(reps, || {
        let _ = black_box(read_asset_bytes(black_box(&bytes)));
    });
    Ok(Measured {
        file_bytes: bytes.len(),
        raw_bytes,
        encode,
        decode,
    })
}

/// Median time to read one brick at random (a fresh chunk each time: strided order).
fn random_access(asset: &Asset, options: &WriteOptions) -> Result<Duration, FormatError> {
    let (bytes, _) = encode_asset(asset, options)?;
    let mut reader = AssetReader::new(Cursor::new(&bytes))?;
    let n = asset.bricks.len();
    let chunk = reader.header().chunk_bricks as usize;
    // Visit bricks so that consecutive reads fall in different chunks.
    let order: Vec<usize> = (0..n).map(|i| (i * (chunk + 1) * 7919) % n).collect();
    let t = Instant::now();
    for &i in &order {
        black_box(reader.read_brick(i)?);
    }
    Ok(t.elapsed() / n as u32)
}

fn main() -> Result<(), FormatError> {
    let t = Instant::now();
    let field = SyntheticField::new(VOXELS, 1);
    let voxels = field.voxel_count();
    let pca32 = field.fit_pca(MAX_RANK, 8192);
    let exact32 = field.project(&pca32);
    println!(
        "# .nelf codec benchmark\n\nSynthetic field: {voxels} voxels in {} bricks (grid {:?} bricks, voxel {:.3} mm), \
         PCA fitted on 8192 voxels; setup {:.1} s.\n",
        field.bricks().len(),
        field.grid().grid_bricks,
        1e3 * field.grid().voxel_size_m,
        t.elapsed().as_secs_f64()
    );
    println!(
        "Encode = `encode_asset` (quantized asset → bytes); decode = `read_asset_bytes` (bytes → validated \
         asset, all checksums); MB/s of decoded payload (all sections), median of 3. Errors are over all \
         {voxels} voxels × 384 entries of T: quantization = reconstruct(dequantized) − reconstruct(exact \
         coefficients); PCA = RMS of T − reconstruct(exact), every 8th voxel. Default options: zstd level {}, {}-brick chunks.\n",
        WriteOptions::default().zstd_level,
        WriteOptions::default().chunk_bricks
    );
    println!(
        "| K | coefficients | shuffle | file bytes | bytes/voxel | ratio | encode MB/s | decode MB/s | quant. max abs(ΔT) | quant. RMS ΔT | PCA RMS error | RMS T |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|");
    for rank in [4usize, 8, 16, 32] {
        let pca = pca32.truncated(rank);
        let exact = leading(&exact32, rank);
        let (t_rms, pca_rms) = truncation_error(&field, &pca, &exact);
        for encoding in [CoefficientEncoding::U8Affine, CoefficientEncoding::F16] {
            let quantized = Coefficients::quantize(&exact, rank, encoding)?;
            let (q_max, q_rms) = quantization_error(&pca, &exact, &quantized);
            let asset = field.asset_with(pca.clone(), quantized)?;
            for shuffle in [false, true] {
                let options = WriteOptions {
                    shuffle,
                    ..WriteOptions::default()
                };
                let m = measure(&asset, &options, 3)?;
                println!(
                    "| {rank} | {} | {} | {} | {:.2} | {:.2} | {:.0} | {:.0} | {:.2e} | {:.2e} | {:.2e} | {:.2e} |",
                    encoding.name(),
                    if shuffle { "yes" } else { "no" },
                    m.file_bytes,
                    m.file_bytes as f64 / voxels as f64,
                    m.raw_bytes as f64 / m.file_bytes as f64,
                    mb_per_s(m.raw_bytes, m.encode),
                    mb_per_s(m.raw_bytes, m.decode),
                    q_max,
                    q_rms,
                    pca_rms,
                    t_rms
                );
            }
        }
    }

    // Level and chunk-size sweeps at K = 16, 8-bit, shuffled.
    let rank = 16;
    let pca = pca32.truncated(rank);
    let quantized = Coefficients::quantize(&leading(&exact32, rank), rank, CoefficientEncoding::U8Affine)?;
    let asset = field.asset_with(pca, quantized)?;
    println!("\n## zstd level, chunk size and shuffle (K = 16, u8-affine)\n");
    println!(
        "Random brick read: `AssetReader::read_brick` in an order that decodes a new chunk every time \
         (mean over all bricks).\n"
    );
    println!(
        "| zstd level | chunk bricks | shuffle | file bytes | encode MB/s | decode MB/s | random brick read µs |"
    );
    println!("|---|---|---|---|---|---|---|");
    let sweep = [
        (1, 64, true),
        (3, 64, true),
        (9, 64, true),
        (15, 64, true),
        (17, 64, true),
        (19, 64, true),
        (19, 64, false),
        (3, 8, true),
        (3, 16, true),
        (3, 32, true),
        (3, 256, true),
        (19, 16, true),
        (19, 32, true),
        (19, 256, true),
    ];
    for (level, chunk_bricks, shuffle) in sweep {
        let options = WriteOptions {
            zstd_level: level,
            chunk_bricks,
            shuffle,
        };
        let reps = if level >= 9 { 1 } else { 5 };
        let m = measure(&asset, &options, reps)?;
        let per_brick = random_access(&asset, &options)?;
        println!(
            "| {level} | {chunk_bricks} | {} | {} | {:.0} | {:.0} | {:.0} |",
            if shuffle { "yes" } else { "no" },
            m.file_bytes,
            mb_per_s(m.raw_bytes, m.encode),
            mb_per_s(m.raw_bytes, m.decode),
            per_brick.as_secs_f64() * 1e6
        );
    }
    Ok(())
}
