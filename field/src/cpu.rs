//! Fused CPU kernels for the network's memory-bound steps, used when tensors live
//! on the CPU (other devices use candle's own ops). candle's CPU element-wise ops
//! run one pass per op on one core, so a composite such as softplus or group
//! normalisation + `PReLU` costs a dozen passes; here each is one or two passes,
//! split over all cores. The 3 × 3 convolutions use a tiled im2col followed by one
//! large matrix product (candle's gemm) per tile, which keeps the product large
//! enough to run near the machine's peak.
//!
//! Semantics are PyTorch's: `softplus(x) = x` above 20, else `log1p(eˣ)`;
//! `GroupNorm` with biased variance and `ε` inside the square root; `PReLU`
//! `max(0, x) + a_c·min(0, x)` over dimension 1; `Conv2d` with zero padding.

use std::sync::atomic::{AtomicBool, Ordering};

use candle_core::{CpuStorage, CustomOp1, CustomOp2, Device, Layout, Shape, Storage, Tensor};
use rayon::prelude::*;

static FUSED_KERNELS: AtomicBool = AtomicBool::new(true);

/// Enables (default) or disables the fused kernels process-wide. Disabled, CPU
/// tensors take the same candle ops as other devices (the CUDA code path), which
/// lets tests check that path on the CPU.
pub fn set_fused_kernels(enabled: bool) {
    FUSED_KERNELS.store(enabled, Ordering::Relaxed);
}

/// Whether `t` goes through the fused kernels: a CPU tensor, kernels enabled, and no
/// gradient to carry (the kernels work on raw buffers, outside candle's graph; layers
/// also check their own parameters, see [`crate::layers`]).
pub fn fused_for(t: &Tensor) -> bool {
    t.device().is_cpu() && FUSED_KERNELS.load(Ordering::Relaxed) && !t.track_op()
}

/// Whether `t` carries gradients on the CPU with the fused kernels enabled: then
/// the composites that have a hand-written backward ([`softplus_trainable`],
/// [`prelu_rows_trainable`], [`channel_dots_trainable`]) replace dozens of
/// single-threaded candle ops.
pub fn fused_trainable(t: &Tensor) -> bool {
    t.device().is_cpu() && FUSED_KERNELS.load(Ordering::Relaxed) && t.track_op()
}

/// Makes the C allocator keep freed memory for reuse: call once, first thing in a
/// program that trains or evaluates the network on the CPU. glibc's malloc hands
/// every block above its mmap threshold back to the kernel on free and trims the
/// heap's top; a training step allocates hundreds of such tensors, and each came
/// back as fresh pages to fault in and zero (18 % of a step of `nelf-small-run` on 2
/// cores: 1.30 → 1.08 s, both settings needed). Returns whether the allocator took
/// the settings (false off glibc, where nothing is changed).
pub fn keep_freed_memory() -> bool {
    keep_freed_memory_impl()
}

#[cfg(all(target_os = "linux", target_env = "gnu"))]
#[allow(
    unsafe_code,
    reason = "mallopt is glibc's C interface; it has no safe wrapper"
)]
fn keep_freed_memory_impl() -> bool {
    /// Blocks up to this size come from the heap, not from mmap.
    const MMAP_THRESHOLD: libc::c_int = 1 << 30;
    /// The heap's top is kept up to this size instead of being trimmed.
    const TRIM_THRESHOLD: libc::c_int = libc::c_int::MAX;
    // SAFETY: mallopt only changes the allocator's tuning parameters; glibc takes
    // its lock while doing so, and any values are valid (a refused one returns 0).
    let (mmap, trim) = unsafe {
        (
            libc::mallopt(libc::M_MMAP_THRESHOLD, MMAP_THRESHOLD),
            libc::mallopt(libc::M_TRIM_THRESHOLD, TRIM_THRESHOLD),
        )
    };
    mmap == 1 && trim == 1
}

#[cfg(not(all(target_os = "linux", target_env = "gnu")))]
fn keep_freed_memory_impl() -> bool {
    false
}

/// Elements per parallel work item of element-wise kernels.
const CHUNK: usize = 1 << 14;
/// Output pixels per im2col tile (bounds the column buffer to `C·k²·TILE` floats).
const CONV_TILE_PIXELS: usize = 16_384;

/// Runs `f` on the contiguous `f32` data of a CPU tensor.
fn with_data<R>(t: &Tensor, f: impl FnOnce(&[f32]) -> R) -> candle_core::Result<R> {
    let t = t.contiguous()?;
    let (storage, layout) = t.storage_and_layout();
    match &*storage {
        Storage::Cpu(cpu) => {
            let data = cpu.as_slice::<f32>()?;
            let start = layout.start_offset();
            Ok(f(&data[start..start + t.elem_count()]))
        }
        _ => candle_core::bail!("fused CPU kernel given a tensor on {:?}", t.device()),
    }
}

/// `eˣ` for `x ≤ 0` (inputs below −87 give 0), branch-free so loops vectorise:
/// `x = n·ln 2 + r`, `|r| ≤ ln 2 / 2`, a degree-6 minimax polynomial for `eʳ`
/// (Cephes `expf`), scaled by `2ⁿ` through the exponent bits. Relative error ≈ 1e-7.
#[inline]
fn exp_nonpositive(x: f32) -> f32 {
    const LOG2E: f32 = std::f32::consts::LOG2_E;
    const LN2_HI: f32 = 0.693_359_4;
    const LN2_LO: f32 = -2.121_944_4e-4;
    let x = x.max(-87.0);
    let n = (x * LOG2E).round();
    let r = x - n * LN2_HI - n * LN2_LO;
    let p = 1.987_569_1e-4f32;
    let p = p * r + 1.398_199_9e-3;
    let p = p * r + 8.333_452e-3;
    let p = p * r + 4.166_579_6e-2;
    let p = p * r + 1.666_666_5e-1;
    let p = p * r + 5e-1;
    let e = p * r * r + r + 1.0;
    e * f32::from_bits(((n as i32 + 127) as u32) << 23)
}

/// `log(1 + y)` for `y ∈ [0, 1]`, branch-free: `u = fl(1 + y)` written as `m·2ᵏ`
/// with `m ∈ [1/√2, √2)`, `log m = 2·atanh(s)`, `s = (m − 1)/(m + 1)`, by its series
/// to `s⁹`, plus the rounding correction `(y − (u − 1))/u`. Absolute error ≈ 1e-7.
#[inline]
fn log1p_unit(y: f32) -> f32 {
    const LN2: f32 = std::f32::consts::LN_2;
    let u = 1.0 + y;
    let big = u >= std::f32::consts::SQRT_2;
    let m = if big { 0.5 * u } else { u };
    let k = if big { LN2 } else { 0.0 };
    let s = (m - 1.0) / (m + 1.0);
    let s2 = s * s;
    let series = 1.0 + s2 * (1.0 / 3.0 + s2 * (1.0 / 5.0 + s2 * (1.0 / 7.0 + s2 * (1.0 / 9.0))));
    k + 2.0 * s * series + (y - (u - 1.0)) / u
}

/// PyTorch's softplus `log(1 + eˣ)` (`x` itself above 20), as
/// `max(x, 0) + log1p(e^{−|x|})`; absolute error ≈ 2e-7.
#[inline]
pub fn softplus_scalar(x: f32) -> f32 {
    let tail = log1p_unit(exp_nonpositive(-x.abs()));
    if x > 20.0 { x } else { x.max(0.0) + tail }
}

/// PyTorch's softplus, one parallel, vectorised pass ([`softplus_scalar`]).
pub fn softplus(x: &Tensor) -> candle_core::Result<Tensor> {
    let out = with_data(x, |d| {
        let mut o = vec![0.0f32; d.len()];
        o.par_chunks_mut(CHUNK)
            .zip(d.par_chunks(CHUNK))
            .for_each(|(o, d)| {
                for (o, &v) in o.iter_mut().zip(d) {
                    *o = softplus_scalar(v);
                }
            });
        o
    })?;
    Tensor::from_vec(out, x.shape(), &Device::Cpu)
}

/// `(x + bias_c)` then `PReLU` with slopes `slope_c` (if any), channel `c` the last
/// dimension of a `(rows, C)` tensor; optionally plus `residual` (same shape).
pub fn bias_prelu_rows(
    x: &Tensor,
    bias: Option<&[f32]>,
    slope: Option<&[f32]>,
    residual: Option<&Tensor>,
) -> candle_core::Result<Tensor> {
    let (_, c) = x.dims2()?;
    let zeros = vec![0.0f32; c];
    let bias = bias.unwrap_or(&zeros);
    let rows_per_chunk = (CHUNK / c.max(1)).max(1);
    let run = |d: &[f32], res: Option<&[f32]>| {
        let mut o = vec![0.0f32; d.len()];
        o.par_chunks_mut(rows_per_chunk * c)
            .zip(d.par_chunks(rows_per_chunk * c))
            .enumerate()
            .for_each(|(k, (o, d))| {
                let base = k * rows_per_chunk * c;
                for (row, (o, d)) in o.chunks_mut(c).zip(d.chunks(c)).enumerate() {
                    for ((o, &v), &b) in o.iter_mut().zip(d).zip(bias) {
                        *o = v + b;
                    }
                    if let Some(s) = slope {
                        for (o, &a) in o.iter_mut().zip(s) {
                            *o = o.max(0.0) + a * o.min(0.0);
                        }
                    }
                    if let Some(r) = res {
                        let r = &r[base + row * c..base + (row + 1) * c];
                        for (o, &v) in o.iter_mut().zip(r) {
                            *o += v;
                        }
                    }
                }
            });
        o
    };
    let out = match residual {
        Some(r) => with_data(r, |rd| with_data(x, |d| run(d, Some(rd))))??,
        None => with_data(x, |d| run(d, None))?,
    };
    Tensor::from_vec(out, x.shape(), &Device::Cpu)
}

/// `GroupNorm(groups, ε)` with affine `gamma`, `beta`, then `PReLU` with `slope`
/// (if any), over `(B, C, …)`, one statistics pass and one output pass per group.
pub fn group_norm_prelu(
    x: &Tensor,
    groups: usize,
    eps: f64,
    gamma: &[f32],
    beta: &[f32],
    slope: Option<&[f32]>,
) -> candle_core::Result<Tensor> {
    let dims = x.dims();
    let (b, c) = (dims[0], dims[1]);
    let spatial: usize = dims[2..].iter().product();
    let per_group = c / groups;
    let block = per_group * spatial;
    let out = with_data(x, |d| {
        let mut o = vec![0.0f32; d.len()];
        o.par_chunks_mut(block)
            .zip(d.par_chunks(block))
            .enumerate()
            .for_each(|(k, (o, d))| {
                let g = k % groups;
                let n = d.len() as f64;
                let mean = d.iter().map(|&v| f64::from(v)).sum::<f64>() / n;
                let var = d.iter().map(|&v| (f64::from(v) - mean).powi(2)).sum::<f64>() / n;
                let inv = 1.0 / (var + eps).sqrt();
                for (j, (o, d)) in o.chunks_mut(spatial).zip(d.chunks(spatial)).enumerate() {
                    let ch = g * per_group + j;
                    let scale = (inv * f64::from(gamma[ch])) as f32;
                    let shift = (f64::from(beta[ch]) - mean * inv * f64::from(gamma[ch])) as f32;
                    let a = slope.map_or(1.0, |s| s[ch]);
                    for (o, &v) in o.iter_mut().zip(d) {
                        let y = v * scale + shift;
                        *o = if slope.is_some() {
                            y.max(0.0) + a * y.min(0.0)
                        } else {
                            y
                        };
                    }
                }
            });
        o
    })?;
    let _ = b;
    Tensor::from_vec(out, x.shape(), &Device::Cpu)
}

/// A 2-D convolution (square kernel `k`, `stride`, zero `padding`) of `x`
/// `(B, C_in, H, W)` with `weight` `(C_out, C_in·k·k)` (row-major `c, kh, kw`) and
/// `bias` `(C_out)`: tiled im2col, then `weight × columns` per tile.
pub fn conv2d(
    x: &Tensor,
    weight: &Tensor,
    bias: &[f32],
    k: usize,
    stride: usize,
    padding: usize,
) -> candle_core::Result<Tensor> {
    let (b, c_in, h, w) = x.dims4()?;
    let (c_out, kk) = weight.dims2()?;
    if kk != c_in * k * k {
        candle_core::bail!(
            "conv2d: weight {:?} for {c_in} channels and a {k}×{k} kernel",
            weight.dims()
        );
    }
    let h_out = (h + 2 * padding - k) / stride + 1;
    let w_out = (w + 2 * padding - k) / stride + 1;
    let pixels = h_out * w_out;
    let rows_per_tile = (CONV_TILE_PIXELS / w_out.max(1)).max(1);
    let mut out = vec![0.0f32; b * c_out * pixels];
    with_data(x, |data| -> candle_core::Result<()> {
        for image in 0..b {
            let src = &data[image * c_in * h * w..(image + 1) * c_in * h * w];
            let dst = &mut out[image * c_out * pixels..(image + 1) * c_out * pixels];
            for row0 in (0..h_out).step_by(rows_per_tile) {
                let rows = rows_per_tile.min(h_out - row0);
                let tile = rows * w_out;
                let mut col = vec![0.0f32; kk * tile];
                col.par_chunks_mut(tile).enumerate().for_each(|(r, col_row)| {
                    let (c, kh, kw) = (r / (k * k), (r / k) % k, r % k);
                    let plane = &src[c * h * w..(c + 1) * h * w];
                    for oy in 0..rows {
                        let iy = ((row0 + oy) * stride + kh) as isize - padding as isize;
                        if iy < 0 || iy >= h as isize {
                            continue;
                        }
                        let line = &plane[iy as usize * w..(iy as usize + 1) * w];
                        let out_line = &mut col_row[oy * w_out..(oy + 1) * w_out];
                        for (ox, o) in out_line.iter_mut().enumerate() {
                            let ix = (ox * stride + kw) as isize - padding as isize;
                            if ix >= 0 && ix < w as isize {
                                *o = line[ix as usize];
                            }
                        }
                    }
                });
                let cols = Tensor::from_vec(col, (kk, tile), &Device::Cpu)?;
                let product = weight.matmul(&cols)?;
                with_data(&product, |p| {
                    for co in 0..c_out {
                        let src_row = &p[co * tile..(co + 1) * tile];
                        let dst_row = &mut dst[co * pixels + row0 * w_out..co * pixels + row0 * w_out + tile];
                        for (o, v) in dst_row.iter_mut().zip(src_row) {
                            *o = v + bias[co];
                        }
                    }
                })?;
            }
        }
        Ok(())
    })??;
    Tensor::from_vec(out, (b, c_out, h_out, w_out), &Device::Cpu)
}

/// Per view, the dot product of each channel's 128 light-transport values with a
/// weight per (channel, texel): `lt` `(N, V, 3·P)`, `weights` `(3·P)` → `(N, V, 3)`.
pub fn channel_dots(lt: &Tensor, weights: &[f32]) -> candle_core::Result<Tensor> {
    let (n, v, d) = lt.dims3()?;
    if d != weights.len() || d % 3 != 0 {
        candle_core::bail!("channel_dots: {d} values per view, {} weights", weights.len());
    }
    let texels = d / 3;
    let out = with_data(lt, |data| {
        let mut o = vec![0.0f32; n * v * 3];
        o.par_chunks_mut(3).zip(data.par_chunks(d)).for_each(|(o, row)| {
            for (c, oc) in o.iter_mut().enumerate() {
                let range = c * texels..(c + 1) * texels;
                *oc = row[range.clone()]
                    .iter()
                    .zip(&weights[range])
                    .map(|(a, b)| a * b)
                    .sum();
            }
        });
        o
    })?;
    Tensor::from_vec(out, (n, v, 3), &Device::Cpu)
}

/// The contiguous `f32` values of a CPU storage under `layout`.
fn storage_slice<'a>(storage: &'a CpuStorage, layout: &Layout) -> candle_core::Result<&'a [f32]> {
    let data = storage.as_slice::<f32>()?;
    match layout.contiguous_offsets() {
        Some((start, end)) => Ok(&data[start..end]),
        None => candle_core::bail!("fused CPU kernel given a non-contiguous tensor"),
    }
}

/// Softplus with its backward `g·sigmoid(x)` (1 above PyTorch's threshold 20).
#[derive(Debug)]
struct SoftplusOp;

impl CustomOp1 for SoftplusOp {
    fn name(&self) -> &'static str {
        "nelf-softplus"
    }

    fn cpu_fwd(&self, storage: &CpuStorage, layout: &Layout) -> candle_core::Result<(CpuStorage, Shape)> {
        let d = storage_slice(storage, layout)?;
        let mut o = vec![0.0f32; d.len()];
        o.par_chunks_mut(CHUNK)
            .zip(d.par_chunks(CHUNK))
            .for_each(|(o, d)| {
                for (o, &v) in o.iter_mut().zip(d) {
                    *o = softplus_scalar(v);
                }
            });
        Ok((CpuStorage::F32(o), layout.shape().clone()))
    }

    fn bwd(&self, arg: &Tensor, _res: &Tensor, grad_res: &Tensor) -> candle_core::Result<Option<Tensor>> {
        let x = with_data(arg, <[f32]>::to_vec)?;
        let g = with_data(grad_res, |g| {
            let mut o = vec![0.0f32; g.len()];
            o.par_chunks_mut(CHUNK)
                .zip(g.par_chunks(CHUNK).zip(x.par_chunks(CHUNK)))
                .for_each(|(o, (g, x))| {
                    for ((o, &g), &x) in o.iter_mut().zip(g).zip(x) {
                        let slope = if x > 20.0 { 1.0 } else { 1.0 / (1.0 + (-x).exp()) };
                        *o = g * slope;
                    }
                });
            o
        })?;
        Ok(Some(Tensor::from_vec(g, arg.shape(), &Device::Cpu)?))
    }
}

/// [`softplus`] for a tensor that carries gradients: one parallel pass forward and
/// one backward.
pub fn softplus_trainable(x: &Tensor) -> candle_core::Result<Tensor> {
    x.contiguous()?.apply_op1(SoftplusOp)
}

/// `PReLU` over the channels (last dimension) of `(rows, C)` with live slopes `(C)`,
/// and its backward: `∂x = g·(1 if x > 0 else a_c)`, `∂a_c = Σ_rows g·min(x, 0)`.
/// candle's composite `relu(x) + min(x, 0)·a` takes about 30 passes over the
/// activations forward and backward (masks, dtype casts, zeroed buffers); this is one
/// pass each way (the per-channel sum is folded into the backward pass per chunk).
#[derive(Debug)]
struct PreluRowsOp;

impl CustomOp2 for PreluRowsOp {
    fn name(&self) -> &'static str {
        "nelf-prelu-rows"
    }

    fn cpu_fwd(
        &self,
        x: &CpuStorage,
        x_layout: &Layout,
        a: &CpuStorage,
        a_layout: &Layout,
    ) -> candle_core::Result<(CpuStorage, Shape)> {
        let (_, c) = x_layout.shape().dims2()?;
        let d = storage_slice(x, x_layout)?;
        let slopes = storage_slice(a, a_layout)?;
        if slopes.len() != c {
            candle_core::bail!("prelu: {} slopes for {c} channels", slopes.len());
        }
        let rows_per_chunk = (CHUNK / c.max(1)).max(1);
        let mut o = vec![0.0f32; d.len()];
        o.par_chunks_mut(rows_per_chunk * c)
            .zip(d.par_chunks(rows_per_chunk * c))
            .for_each(|(o, d)| {
                for (o, d) in o.chunks_mut(c).zip(d.chunks(c)) {
                    for ((o, &v), &a) in o.iter_mut().zip(d).zip(slopes) {
                        *o = v.max(0.0) + a * v.min(0.0);
                    }
                }
            });
        Ok((CpuStorage::F32(o), x_layout.shape().clone()))
    }

    fn bwd(
        &self,
        x: &Tensor,
        a: &Tensor,
        _res: &Tensor,
        grad_res: &Tensor,
    ) -> candle_core::Result<(Option<Tensor>, Option<Tensor>)> {
        let (_, c) = x.dims2()?;
        let slopes = with_data(a, <[f32]>::to_vec)?;
        let rows_per_chunk = (CHUNK / c.max(1)).max(1);
        let (dx, da) = with_data(x, |x| {
            with_data(grad_res, |g| {
                let mut dx = vec![0.0f32; x.len()];
                let da = dx
                    .par_chunks_mut(rows_per_chunk * c)
                    .zip(
                        x.par_chunks(rows_per_chunk * c)
                            .zip(g.par_chunks(rows_per_chunk * c)),
                    )
                    .map(|(dx, (x, g))| {
                        let mut da = vec![0.0f32; c];
                        for ((dx, x), g) in dx.chunks_mut(c).zip(x.chunks(c)).zip(g.chunks(c)) {
                            for k in 0..c {
                                let (v, gv) = (x[k], g[k]);
                                dx[k] = if v > 0.0 { gv } else { gv * slopes[k] };
                                da[k] += gv * v.min(0.0);
                            }
                        }
                        da
                    })
                    .reduce(
                        || vec![0.0f32; c],
                        |mut a, b| {
                            for (a, b) in a.iter_mut().zip(b) {
                                *a += b;
                            }
                            a
                        },
                    );
                (dx, da)
            })
        })??;
        Ok((
            Some(Tensor::from_vec(dx, x.shape(), &Device::Cpu)?),
            Some(Tensor::from_vec(da, a.shape(), &Device::Cpu)?),
        ))
    }
}

/// `PReLU` of `(rows, C)` with slopes `(C)` (live parameters) that carries gradients
/// to both ([`PreluRowsOp`]).
pub fn prelu_rows_trainable(x: &Tensor, slopes: &Tensor) -> candle_core::Result<Tensor> {
    x.contiguous()?.apply_op2(&slopes.contiguous()?, PreluRowsOp)
}

/// [`channel_dots`] with its backward `∂lt[n, v, c·P + p] = g[n, v, c]·w[c·P + p]`.
#[derive(Debug)]
struct ChannelDotsOp {
    weights: Vec<f32>,
}

impl CustomOp1 for ChannelDotsOp {
    fn name(&self) -> &'static str {
        "nelf-channel-dots"
    }

    fn cpu_fwd(&self, storage: &CpuStorage, layout: &Layout) -> candle_core::Result<(CpuStorage, Shape)> {
        let (n, v, d) = layout.shape().dims3()?;
        let data = storage_slice(storage, layout)?;
        let texels = d / 3;
        let w = &self.weights;
        let mut o = vec![0.0f32; n * v * 3];
        o.par_chunks_mut(3).zip(data.par_chunks(d)).for_each(|(o, row)| {
            for (c, oc) in o.iter_mut().enumerate() {
                let range = c * texels..(c + 1) * texels;
                *oc = row[range.clone()].iter().zip(&w[range]).map(|(a, b)| a * b).sum();
            }
        });
        Ok((CpuStorage::F32(o), Shape::from((n, v, 3))))
    }

    fn bwd(&self, arg: &Tensor, _res: &Tensor, grad_res: &Tensor) -> candle_core::Result<Option<Tensor>> {
        let (n, v, d) = arg.dims3()?;
        let texels = d / 3;
        let w = &self.weights;
        let g = with_data(grad_res, |g| {
            let mut o = vec![0.0f32; n * v * d];
            o.par_chunks_mut(d).zip(g.par_chunks(3)).for_each(|(row, g)| {
                for (c, gc) in g.iter().enumerate() {
                    let range = c * texels..(c + 1) * texels;
                    for (o, wv) in row[range.clone()].iter_mut().zip(&w[range]) {
                        *o = gc * wv;
                    }
                }
            });
            o
        })?;
        Ok(Some(Tensor::from_vec(g, (n, v, d), &Device::Cpu)?))
    }
}

/// [`channel_dots`] for a `lt` that carries gradients (`weights` constant).
pub fn channel_dots_trainable(lt: &Tensor, weights: &[f32]) -> candle_core::Result<Tensor> {
    let (_, _, d) = lt.dims3()?;
    if d != weights.len() || d % 3 != 0 {
        candle_core::bail!("channel_dots: {d} values per view, {} weights", weights.len());
    }
    lt.contiguous()?.apply_op1(ChannelDotsOp {
        weights: weights.to_vec(),
    })
}

/// `T[n, c·P + p] = Σ_v per_view[n, v, c] · lt[n, v, c·P + p] · omega[p]`:
/// `lt` `(N, V, 3·P)`, `per_view` `(N, V, 3)`, `omega` `(P)` → `(N, 3·P)`.
pub fn blend_light_transport(lt: &Tensor, per_view: &Tensor, omega: &[f32]) -> candle_core::Result<Tensor> {
    let (n, v, d) = lt.dims3()?;
    let texels = omega.len();
    if d != 3 * texels || per_view.dims() != [n, v, 3] {
        candle_core::bail!(
            "blend_light_transport: lt {:?}, per-view weights {:?}, {texels} texels",
            lt.dims(),
            per_view.dims()
        );
    }
    let weights = with_data(per_view, <[f32]>::to_vec)?;
    let out = with_data(lt, |data| {
        let mut o = vec![0.0f32; n * d];
        o.par_chunks_mut(d).enumerate().for_each(|(i, out)| {
            for view in 0..v {
                let row = &data[(i * v + view) * d..(i * v + view + 1) * d];
                for c in 0..3 {
                    let w = weights[(i * v + view) * 3 + c];
                    let range = c * texels..(c + 1) * texels;
                    for (o, x) in out[range.clone()].iter_mut().zip(&row[range]) {
                        *o += w * x;
                    }
                }
            }
            for chunk in out.chunks_mut(texels) {
                for (o, w) in chunk.iter_mut().zip(omega) {
                    *o *= w;
                }
            }
        });
        o
    })?;
    Tensor::from_vec(out, (n, d), &Device::Cpu)
}

#[cfg(test)]
mod tests {
    use candle_core::Module;
    use candle_nn::{Conv2dConfig, VarBuilder};

    use super::*;

    fn ramp(shape: &[usize], seed: f32) -> Tensor {
        let n: usize = shape.iter().product();
        let v: Vec<f32> = (0..n).map(|i| (i as f32 * 0.37 + seed).sin() * 1.7).collect();
        Tensor::from_vec(v, shape, &Device::Cpu).unwrap()
    }

    fn max_diff(a: &Tensor, b: &Tensor) -> f32 {
        (a - b)
            .unwrap()
            .abs()
            .unwrap()
            .flatten_all()
            .unwrap()
            .max(0)
            .unwrap()
            .to_scalar::<f32>()
            .unwrap()
    }

    #[test]
    fn conv_matches_candle_for_strides_paddings_and_kernels() {
        for (c_in, c_out, h, w, k, stride) in [
            (3, 5, 9, 12, 3, 2),
            (4, 6, 8, 7, 3, 1),
            (5, 3, 6, 10, 1, 2),
            (2, 4, 5, 5, 1, 1),
        ] {
            let x = ramp(&[2, c_in, h, w], 0.3);
            let weight = ramp(&[c_out, c_in, k, k], 1.1);
            let bias: Vec<f32> = (0..c_out).map(|i| i as f32 * 0.1 - 0.2).collect();
            let vb = VarBuilder::from_tensors(
                [
                    ("weight".to_string(), weight.clone()),
                    (
                        "bias".to_string(),
                        Tensor::new(bias.as_slice(), &Device::Cpu).unwrap(),
                    ),
                ]
                .into_iter()
                .collect(),
                candle_core::DType::F32,
                &Device::Cpu,
            );
            let config = Conv2dConfig {
                padding: (k - 1) / 2,
                stride,
                ..Conv2dConfig::default()
            };
            let reference = candle_nn::conv2d(c_in, c_out, k, config, vb)
                .unwrap()
                .forward(&x)
                .unwrap();
            let flat = weight.reshape((c_out, c_in * k * k)).unwrap();
            let got = conv2d(&x, &flat, &bias, k, stride, (k - 1) / 2).unwrap();
            assert_eq!(got.dims(), reference.dims());
            assert!(
                max_diff(&got, &reference) < 1e-4,
                "{c_in}->{c_out} k{k} s{stride}"
            );
        }
    }

    #[test]
    fn group_norm_prelu_matches_candle() {
        let x = ramp(&[2, 6, 5, 4], 0.7);
        let gamma: Vec<f32> = (0..6).map(|i| 1.0 + 0.1 * i as f32).collect();
        let beta: Vec<f32> = (0..6).map(|i| 0.05 * i as f32 - 0.1).collect();
        let slope: Vec<f32> = (0..6).map(|i| 0.2 + 0.01 * i as f32).collect();
        let gn = candle_nn::GroupNorm::new(
            Tensor::new(gamma.as_slice(), &Device::Cpu).unwrap(),
            Tensor::new(beta.as_slice(), &Device::Cpu).unwrap(),
            6,
            3,
            1e-5,
        )
        .unwrap();
        let y = gn.forward(&x).unwrap();
        let a = Tensor::new(slope.as_slice(), &Device::Cpu)
            .unwrap()
            .reshape((1, 6, 1, 1))
            .unwrap();
        let want = (y.relu().unwrap() + y.minimum(0f32).unwrap().broadcast_mul(&a).unwrap()).unwrap();
        let got = group_norm_prelu(&x, 3, 1e-5, &gamma, &beta, Some(&slope)).unwrap();
        assert!(max_diff(&got, &want) < 1e-5);
        let plain = group_norm_prelu(&x, 3, 1e-5, &gamma, &beta, None).unwrap();
        assert!(max_diff(&plain, &y) < 1e-5);
    }

    #[test]
    fn blends_and_dots_match_tensor_ops() {
        let (n, v, p) = (4usize, 3usize, 5usize);
        let lt = ramp(&[n, v, 3 * p], 0.2).abs().unwrap();
        let per_view = ramp(&[n, v, 3], 0.9);
        let omega: Vec<f32> = (0..p).map(|i| 0.1 + 0.05 * i as f32).collect();
        let got = blend_light_transport(&lt, &per_view, &omega).unwrap();
        let omega_t = Tensor::new(omega.as_slice(), &Device::Cpu)
            .unwrap()
            .reshape((1, 1, p))
            .unwrap();
        let want = lt
            .reshape((n, v, 3, p))
            .unwrap()
            .broadcast_mul(&per_view.unsqueeze(3).unwrap())
            .unwrap()
            .sum(1)
            .unwrap()
            .broadcast_mul(&omega_t)
            .unwrap()
            .reshape((n, 3 * p))
            .unwrap();
        assert!(max_diff(&got, &want) < 1e-5);
        let weights: Vec<f32> = (0..3 * p).map(|i| 0.3 - 0.02 * i as f32).collect();
        let dots = channel_dots(&lt, &weights).unwrap();
        let w = Tensor::new(weights.as_slice(), &Device::Cpu)
            .unwrap()
            .reshape((1, 1, 3, p))
            .unwrap();
        let want = lt
            .reshape((n, v, 3, p))
            .unwrap()
            .broadcast_mul(&w)
            .unwrap()
            .sum(3)
            .unwrap();
        assert!(max_diff(&dots, &want) < 1e-5);
    }

    #[test]
    fn fast_softplus_is_accurate() {
        let mut worst = 0.0f64;
        for i in 0..=200_000 {
            let x = -40.0 + 70.0 * f64::from(i) / 200_000.0;
            let want = if x > 20.0 { x } else { x.exp().ln_1p() };
            let got = f64::from(softplus_scalar(x as f32));
            let want32 = f64::from(want as f32);
            worst = worst.max((got - want).abs() / want.abs().max(1.0));
            assert!(
                (got - want32).abs() <= 3e-7 * want.abs().max(1.0),
                "x={x}: {got} vs {want}"
            );
        }
        assert!(worst < 3e-7, "{worst}");
        // Relative accuracy of small outputs (densities), e.g. softplus(−5) ≈ 6.7e-3.
        for x in [-5.0f32, -10.0, -16.0] {
            let want = f64::from(x).exp().ln_1p();
            assert!((f64::from(softplus_scalar(x)) - want).abs() < 1e-6 * want, "{x}");
        }
    }

    #[test]
    fn softplus_and_bias_prelu_are_exact() {
        let x = Tensor::new(&[[-30.0f32, -1.0, 0.0], [0.5, 19.9, 25.0]], &Device::Cpu).unwrap();
        let got = softplus(&x).unwrap().to_vec2::<f32>().unwrap();
        for (row, xs) in got.iter().zip([[-30.0f32, -1.0, 0.0], [0.5, 19.9, 25.0]]) {
            for (g, v) in row.iter().zip(xs) {
                let want = if v > 20.0 { v } else { v.exp().ln_1p() };
                assert!((g - want).abs() <= 3e-7 * want.abs().max(1.0));
            }
        }
        let r = Tensor::new(&[[1.0f32, 1.0, 1.0], [2.0, 2.0, 2.0]], &Device::Cpu).unwrap();
        let y = bias_prelu_rows(&x, Some(&[1.0, 0.0, -1.0]), Some(&[0.5, 0.5, 0.5]), Some(&r))
            .unwrap()
            .to_vec2::<f32>()
            .unwrap();
        assert_eq!(y[0], vec![1.0 - 14.5, 1.0 - 0.5, 1.0 - 0.5]);
        assert_eq!(y[1], vec![2.0 + 1.5, 2.0 + 19.9, 2.0 + 24.0]);
    }

    /// The trainable kernels give candle's values and gradients: softplus against
    /// its composition of candle ops, channel dots against `broadcast_mul + sum`.
    #[test]
    fn trainable_kernels_match_candle_values_and_gradients() {
        let x = candle_core::Var::from_tensor(&(ramp(&[4, 3, 6], 0.3) * 8.0).unwrap()).unwrap();
        let w: Vec<f32> = (0..6).map(|i| 0.2 + 0.1 * i as f32).collect();
        let weights = Tensor::from_vec(w.clone(), (1, 1, 3, 2), &Device::Cpu).unwrap();
        let upstream = ramp(&[4, 3, 3], 1.1);

        let fused = channel_dots_trainable(&softplus_trainable(x.as_tensor()).unwrap(), &w).unwrap();
        let tail = (x.as_tensor().abs().unwrap().neg().unwrap().exp().unwrap() + 1.0)
            .unwrap()
            .log()
            .unwrap();
        let plain_softplus = (x.as_tensor().relu().unwrap() + tail).unwrap();
        let plain = plain_softplus
            .reshape((4, 3, 3, 2))
            .unwrap()
            .broadcast_mul(&weights)
            .unwrap()
            .sum(3)
            .unwrap();
        assert!(
            max_diff(&fused, &plain) < 1e-4,
            "values {}",
            max_diff(&fused, &plain)
        );
        let g_fused = (fused * &upstream)
            .unwrap()
            .sum_all()
            .unwrap()
            .backward()
            .unwrap();
        let g_plain = (plain * &upstream)
            .unwrap()
            .sum_all()
            .unwrap()
            .backward()
            .unwrap();
        let (a, b) = (
            g_fused.get(x.as_tensor()).unwrap(),
            g_plain.get(x.as_tensor()).unwrap(),
        );
        assert!(max_diff(a, b) < 1e-4, "gradients {}", max_diff(a, b));
    }

    /// The trainable `PReLU` gives candle's composite's values and gradients, to the
    /// input and to the slopes (inputs kept off 0, where the composite's gradient is
    /// a convention: it splits ties).
    #[test]
    fn trainable_prelu_matches_candle_values_and_gradients() {
        let (rows, c) = (1_000, 7);
        let x = candle_core::Var::from_tensor(&ramp(&[rows, c], 0.7)).unwrap();
        let slopes = candle_core::Var::from_tensor(&(ramp(&[c], 2.0) * 0.2).unwrap()).unwrap();
        let upstream = ramp(&[rows, c], 0.1);
        let fused = prelu_rows_trainable(x.as_tensor(), slopes.as_tensor()).unwrap();
        let plain = (x.as_tensor().relu().unwrap()
            + x.as_tensor()
                .minimum(0f32)
                .unwrap()
                .broadcast_mul(&slopes.as_tensor().reshape((1, c)).unwrap())
                .unwrap())
        .unwrap();
        assert!(
            max_diff(&fused, &plain) < 1e-6,
            "values {}",
            max_diff(&fused, &plain)
        );
        let loss = |t: Tensor| (t * &upstream).unwrap().sum_all().unwrap().backward().unwrap();
        let (g_fused, g_plain) = (loss(fused), loss(plain));
        for var in [&x, &slopes] {
            let (a, b) = (
                g_fused.get(var.as_tensor()).unwrap(),
                g_plain.get(var.as_tensor()).unwrap(),
            );
            let scale = b.abs().unwrap().max_all().unwrap().to_scalar::<f32>().unwrap();
            assert!(scale > 0.1, "a gradient worth comparing");
            assert!(
                max_diff(a, b) <= 1e-4 * scale,
                "gradients {} (scale {scale})",
                max_diff(a, b)
            );
        }
    }
}
