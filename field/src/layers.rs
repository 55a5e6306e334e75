//! The building blocks of the official NeLF modules, with the official parameter
//! names (`vb.pp(..)` paths equal `state_dict` keys):
//!
//! * [`PRelu`]: `max(0, x) + a_c · min(0, x)` with one slope per channel (dim 1);
//! * [`Mlp`]: `Linear, (PReLU, Linear)…` with no final activation (`layers.{i}`);
//! * [`ResMlp`]: `input_layer`, then pre-activation residual blocks
//!   `x ↦ s(x) + fc_1(prelu_1(fc_0(prelu_0(x))))` where `s` is the identity or, when
//!   the width changes, a bias-free `shortcut` Linear;
//! * [`NormActConv`]: `GroupNorm(min(32, C)) → PReLU(C) → Conv2d(k, pad (k−1)/2)`;
//! * [`ResConvBlock`]: `shortcut` 1×1 stride-2 conv plus two `NormActConv`s, the
//!   first with stride 2;
//! * [`softplus`]: PyTorch's `softplus` (β = 1), computed as
//!   `max(x, 0) + log1p(e^{−|x|})` with an accurate `log1p`.

use candle_core::{Module, Tensor};
use candle_nn::{Conv2d, Conv2dConfig, GroupNorm, VarBuilder};

use crate::cpu;
use crate::error::NetError;

/// `log(1 + y)` for `y ≥ 0`, accurate to a few ulps (Goldberg's trick:
/// `log(u)·y/(u − 1)` with `u = fl(1 + y)`, and `y` itself where `u = 1`).
fn log1p_nonneg(y: &Tensor) -> candle_core::Result<Tensor> {
    let u = (y + 1.0)?;
    let denom = (&u - 1.0)?;
    let exact = denom.eq(0f32)?;
    // Where u = 1 the quotient is 0/0; divide by 1 there instead and select y.
    let safe_denom = exact.where_cond(&denom.ones_like()?, &denom)?;
    let ratio = (u.log()? * y)?.div(&safe_denom)?;
    exact.where_cond(y, &ratio)
}

/// PyTorch's `softplus(x) = log(1 + eˣ)` (β = 1, threshold 20), evaluated stably for
/// every `x` (a fused kernel on the CPU).
pub fn softplus(x: &Tensor) -> candle_core::Result<Tensor> {
    if cpu::fused_for(x) {
        return cpu::softplus(x);
    }
    if cpu::fused_trainable(x) {
        return cpu::softplus_trainable(x);
    }
    let tail = log1p_nonneg(&x.abs()?.neg()?.exp()?)?;
    x.relu()? + tail
}

/// Bilinear ×2 up-sampling of `(B, C, H, W)` (PyTorch's `align_corners = False`):
/// output `2i` is `¾·x[i] + ¼·x[i−1]`, output `2i+1` is `¾·x[i] + ¼·x[i+1]`, the
/// neighbour index clamped to the edge. candle's own kernel has no backward pass, so
/// tensors that carry gradients take this composition of differentiable ops.
pub fn upsample2_bilinear(x: &Tensor) -> candle_core::Result<Tensor> {
    if !x.track_op() {
        return x.upsample_bilinear2d_with_scale(2.0, 2.0, false);
    }
    let x = upsample2_along(x, 3)?;
    upsample2_along(&x, 2)
}

/// [`upsample2_bilinear`] along one dimension `dim` of a rank-4 tensor.
fn upsample2_along(x: &Tensor, dim: usize) -> candle_core::Result<Tensor> {
    let n = x.dim(dim)?;
    let (before, after) = if n > 1 {
        (
            Tensor::cat(&[&x.narrow(dim, 0, 1)?, &x.narrow(dim, 0, n - 1)?], dim)?,
            Tensor::cat(&[&x.narrow(dim, 1, n - 1)?, &x.narrow(dim, n - 1, 1)?], dim)?,
        )
    } else {
        (x.clone(), x.clone())
    };
    let even = ((x * 0.75)? + (before * 0.25)?)?;
    let odd = ((x * 0.75)? + (after * 0.25)?)?;
    let mut dims = x.dims().to_vec();
    dims[dim] *= 2;
    Tensor::stack(&[&even, &odd], dim + 1)?.reshape(dims)
}

/// Host copy of a 1-D parameter.
fn host(t: &Tensor) -> Result<Vec<f32>, NetError> {
    Ok(t.flatten_all()?.to_vec1::<f32>()?)
}

/// Parametric `ReLU` with one slope per channel; the channel is dimension 1, as in
/// PyTorch (use `(rows, features)` inputs for MLPs).
#[derive(Debug, Clone)]
pub struct PRelu {
    weight: Tensor,
    slopes: Vec<f32>,
}

impl PRelu {
    /// Loads `weight` (`[channels]`).
    pub fn new(channels: usize, vb: &VarBuilder) -> Result<Self, NetError> {
        let weight = vb.get(channels, "weight")?;
        Ok(Self {
            slopes: host(&weight)?,
            weight,
        })
    }

    /// The slopes, one per channel.
    pub fn slopes(&self) -> &[f32] {
        &self.slopes
    }
}

impl Module for PRelu {
    fn forward(&self, x: &Tensor) -> candle_core::Result<Tensor> {
        if cpu::fused_for(x) && x.rank() == 2 && !self.weight.track_op() {
            return cpu::bias_prelu_rows(x, None, Some(&self.slopes), None);
        }
        if x.rank() == 2 && (cpu::fused_trainable(x) || cpu::fused_trainable(&self.weight)) {
            return cpu::prelu_rows_trainable(x, &self.weight);
        }
        let mut shape = vec![1usize; x.rank()];
        if x.rank() >= 2 {
            shape[1] = self.weight.elem_count();
        }
        let slope = self.weight.reshape(shape)?;
        x.relu()? + x.minimum(0f32)?.broadcast_mul(&slope)?
    }
}

/// A fully connected layer (`weight` `[out, in]`, optional `bias`) on `(rows, in)`.
#[derive(Debug, Clone)]
pub struct Dense {
    /// `[out, in]`, as loaded: a trainable variable is read live from here.
    weight: Tensor,
    /// `Wᵀ`, contiguous, for inference (a copy: stale once a variable is updated).
    weight_t: Tensor,
    bias: Option<Tensor>,
    bias_host: Option<Vec<f32>>,
}

impl Dense {
    /// Loads `weight` and, if `with_bias`, `bias`.
    pub fn new(in_dim: usize, out_dim: usize, with_bias: bool, vb: &VarBuilder) -> Result<Self, NetError> {
        let weight = vb.get((out_dim, in_dim), "weight")?;
        let bias = if with_bias {
            Some(vb.get(out_dim, "bias")?)
        } else {
            None
        };
        Ok(Self {
            weight_t: weight.t()?.contiguous()?,
            weight,
            bias_host: bias.as_ref().map(host).transpose()?,
            bias,
        })
    }

    /// `x·Wᵀ + b`, then `PReLU(slopes)` if given, then `+ residual` if given.
    pub fn forward_fused(
        &self,
        x: &Tensor,
        slopes: Option<&PRelu>,
        residual: Option<&Tensor>,
    ) -> candle_core::Result<Tensor> {
        if self.weight.track_op() {
            // Training: the live parameters, through differentiable ops only.
            let y = x.matmul(&self.weight.t()?)?;
            let mut y = match &self.bias {
                Some(b) => y.broadcast_add(b)?,
                None => y,
            };
            if let Some(act) = slopes {
                y = act.forward(&y)?;
            }
            return match residual {
                Some(r) => y + r,
                None => Ok(y),
            };
        }
        let y = x.matmul(&self.weight_t)?;
        if cpu::fused_for(&y) {
            return cpu::bias_prelu_rows(&y, self.bias_host.as_deref(), slopes.map(PRelu::slopes), residual);
        }
        let mut y = match &self.bias {
            Some(b) => y.broadcast_add(b)?,
            None => y,
        };
        if let Some(act) = slopes {
            y = act.forward(&y)?;
        }
        match residual {
            Some(r) => y + r,
            None => Ok(y),
        }
    }
}

impl Module for Dense {
    fn forward(&self, x: &Tensor) -> candle_core::Result<Tensor> {
        self.forward_fused(x, None, None)
    }
}

/// `Linear, (PReLU, Linear)…` through the widths `dims`, parameters under `layers.{i}`.
#[derive(Debug, Clone)]
pub struct Mlp {
    linears: Vec<Dense>,
    activations: Vec<PRelu>,
}

impl Mlp {
    /// Builds the MLP `dims[0] → dims[1] → … → dims[last]` (at least two widths).
    pub fn new(dims: &[usize], vb: &VarBuilder) -> Result<Self, NetError> {
        if dims.len() < 2 {
            return Err(NetError::input("an MLP needs at least two widths"));
        }
        let layers = vb.pp("layers");
        let mut linears = Vec::new();
        let mut activations = Vec::new();
        for (i, pair) in dims.windows(2).enumerate() {
            if i > 0 {
                activations.push(PRelu::new(pair[0], &layers.pp(2 * i - 1))?);
            }
            linears.push(Dense::new(pair[0], pair[1], true, &layers.pp(2 * i))?);
        }
        Ok(Self { linears, activations })
    }
}

impl Module for Mlp {
    /// `x`: `(rows, dims[0])`.
    fn forward(&self, x: &Tensor) -> candle_core::Result<Tensor> {
        let mut h = x.clone();
        for (i, lin) in self.linears.iter().enumerate() {
            h = lin.forward_fused(&h, self.activations.get(i), None)?;
        }
        Ok(h)
    }
}

/// One pre-activation residual block of [`ResMlp`].
#[derive(Debug, Clone)]
struct ResBlock {
    prelu_0: PRelu,
    fc_0: Dense,
    prelu_1: PRelu,
    fc_1: Dense,
    shortcut: Option<Dense>,
}

impl Module for ResBlock {
    fn forward(&self, x: &Tensor) -> candle_core::Result<Tensor> {
        let h = self
            .fc_0
            .forward_fused(&self.prelu_0.forward(x)?, Some(&self.prelu_1), None)?;
        let skip = match &self.shortcut {
            Some(s) => s.forward(x)?,
            None => x.clone(),
        };
        self.fc_1.forward_fused(&h, None, Some(&skip))
    }
}

/// `input_layer` (Linear `in → hidden`) and `blocks.{i}`: residual blocks at width
/// `hidden`, the last one mapping to `out` (with a bias-free `shortcut` when
/// `out ≠ hidden`). No final activation.
#[derive(Debug, Clone)]
pub struct ResMlp {
    input_layer: Dense,
    blocks: Vec<ResBlock>,
}

impl ResMlp {
    /// Builds `in_dim → hidden` and `blocks` residual blocks, the last one `hidden → out_dim`.
    pub fn new(
        in_dim: usize,
        hidden: usize,
        out_dim: usize,
        blocks: usize,
        vb: &VarBuilder,
    ) -> Result<Self, NetError> {
        if blocks == 0 {
            return Err(NetError::input("a residual MLP needs at least one block"));
        }
        let input_layer = Dense::new(in_dim, hidden, true, &vb.pp("input_layer"))?;
        let list = (0..blocks)
            .map(|i| {
                let b = vb.pp("blocks").pp(i);
                let out = if i + 1 == blocks { out_dim } else { hidden };
                Ok(ResBlock {
                    prelu_0: PRelu::new(hidden, &b.pp("prelu_0"))?,
                    fc_0: Dense::new(hidden, hidden, true, &b.pp("fc_0"))?,
                    prelu_1: PRelu::new(hidden, &b.pp("prelu_1"))?,
                    fc_1: Dense::new(hidden, out, true, &b.pp("fc_1"))?,
                    shortcut: if out == hidden {
                        None
                    } else {
                        Some(Dense::new(hidden, out, false, &b.pp("shortcut"))?)
                    },
                })
            })
            .collect::<Result<Vec<_>, NetError>>()?;
        Ok(Self {
            input_layer,
            blocks: list,
        })
    }
}

impl Module for ResMlp {
    fn forward(&self, x: &Tensor) -> candle_core::Result<Tensor> {
        let mut h = self.input_layer.forward(x)?;
        for block in &self.blocks {
            h = block.forward(&h)?;
        }
        Ok(h)
    }
}

/// `GroupNorm` with `min(32, C)` groups and ε = 1e-5, parameters `weight`, `bias`.
#[derive(Debug, Clone)]
pub struct GroupNormLayer {
    norm: GroupNorm,
    /// `weight` as loaded (a trainable variable is read live by `norm`).
    weight: Tensor,
    groups: usize,
    gamma: Vec<f32>,
    beta: Vec<f32>,
}

/// The `GroupNorm` ε.
const GROUP_NORM_EPS: f64 = 1e-5;

impl GroupNormLayer {
    /// Loads `weight` and `bias` for `channels`.
    pub fn new(channels: usize, vb: &VarBuilder) -> Result<Self, NetError> {
        let groups = channels.min(32);
        let norm = candle_nn::group_norm(groups, channels, GROUP_NORM_EPS, vb.clone())?;
        let weight = vb.get(channels, "weight")?;
        Ok(Self {
            norm,
            groups,
            gamma: host(&weight)?,
            weight,
            beta: host(&vb.get(channels, "bias")?)?,
        })
    }

    /// Normalises `x` `(B, C, H, W)`, then applies `act` if given.
    pub fn forward_act(&self, x: &Tensor, act: Option<&PRelu>) -> candle_core::Result<Tensor> {
        let trainable = self.weight.track_op() || act.is_some_and(|a| a.weight.track_op());
        if cpu::fused_for(x) && !trainable {
            return cpu::group_norm_prelu(
                x,
                self.groups,
                GROUP_NORM_EPS,
                &self.gamma,
                &self.beta,
                act.map(PRelu::slopes),
            );
        }
        let y = self.norm.forward(x)?;
        match act {
            Some(a) => a.forward(&y),
            None => Ok(y),
        }
    }
}

/// A convolution with a square kernel, zero padding `(k − 1)/2` unless given.
#[derive(Debug, Clone)]
pub struct ConvLayer {
    conv: Conv2d,
    weight_flat: Tensor,
    bias: Vec<f32>,
    kernel: usize,
    stride: usize,
    padding: usize,
}

impl ConvLayer {
    /// Loads `weight` `[out, in, k, k]` and `bias` `[out]`.
    pub fn new(
        in_ch: usize,
        out_ch: usize,
        kernel: usize,
        stride: usize,
        padding: usize,
        vb: &VarBuilder,
    ) -> Result<Self, NetError> {
        let config = Conv2dConfig {
            padding,
            stride,
            ..Conv2dConfig::default()
        };
        let conv = candle_nn::conv2d(in_ch, out_ch, kernel, config, vb.clone())?;
        Ok(Self {
            weight_flat: conv
                .weight()
                .reshape((out_ch, in_ch * kernel * kernel))?
                .contiguous()?,
            bias: conv
                .bias()
                .map(host)
                .transpose()?
                .unwrap_or_else(|| vec![0.0; out_ch]),
            conv,
            kernel,
            stride,
            padding,
        })
    }
}

impl Module for ConvLayer {
    fn forward(&self, x: &Tensor) -> candle_core::Result<Tensor> {
        if cpu::fused_for(x) && !self.conv.weight().track_op() {
            return cpu::conv2d(
                x,
                &self.weight_flat,
                &self.bias,
                self.kernel,
                self.stride,
                self.padding,
            );
        }
        self.conv.forward(x)
    }
}

/// `GroupNorm → PReLU → Conv2d` (`norm`, `act`, `conv`).
#[derive(Debug, Clone)]
pub struct NormActConv {
    norm: GroupNormLayer,
    act: PRelu,
    conv: ConvLayer,
}

impl NormActConv {
    /// `in_ch → out_ch` with a square `kernel` (odd), padding `(kernel − 1)/2`, `stride`.
    pub fn new(
        in_ch: usize,
        out_ch: usize,
        kernel: usize,
        stride: usize,
        vb: &VarBuilder,
    ) -> Result<Self, NetError> {
        Ok(Self {
            norm: GroupNormLayer::new(in_ch, &vb.pp("norm"))?,
            act: PRelu::new(in_ch, &vb.pp("act"))?,
            conv: ConvLayer::new(in_ch, out_ch, kernel, stride, (kernel - 1) / 2, &vb.pp("conv"))?,
        })
    }
}

impl Module for NormActConv {
    fn forward(&self, x: &Tensor) -> candle_core::Result<Tensor> {
        self.conv.forward(&self.norm.forward_act(x, Some(&self.act))?)
    }
}

/// Residual down-sampling block: `shortcut(x) + normactconv1(normactconv0(x))`,
/// halving the resolution.
#[derive(Debug, Clone)]
pub struct ResConvBlock {
    shortcut: ConvLayer,
    normactconv0: NormActConv,
    normactconv1: NormActConv,
}

impl ResConvBlock {
    /// `in_ch → out_ch` at half the input resolution.
    pub fn new(in_ch: usize, out_ch: usize, vb: &VarBuilder) -> Result<Self, NetError> {
        Ok(Self {
            shortcut: ConvLayer::new(in_ch, out_ch, 1, 2, 0, &vb.pp("shortcut"))?,
            normactconv0: NormActConv::new(in_ch, out_ch, 3, 2, &vb.pp("normactconv0"))?,
            normactconv1: NormActConv::new(out_ch, out_ch, 3, 1, &vb.pp("normactconv1"))?,
        })
    }
}

impl Module for ResConvBlock {
    fn forward(&self, x: &Tensor) -> candle_core::Result<Tensor> {
        let main = self.normactconv1.forward(&self.normactconv0.forward(x)?)?;
        self.shortcut.forward(x)? + main
    }
}

#[cfg(test)]
mod tests {
    use candle_core::{DType, Device};

    use super::*;

    #[test]
    fn softplus_matches_reference_values() {
        let xs = [-80.0f32, -30.0, -5.0, -1e-3, 0.0, 1e-3, 2.0, 19.0, 25.0, 80.0];
        let t = Tensor::new(&xs[..], &Device::Cpu).unwrap();
        let got = softplus(&t).unwrap().to_vec1::<f32>().unwrap();
        for (x, g) in xs.iter().zip(got) {
            let x = f64::from(*x);
            let want = if x > 20.0 { x } else { x.exp().ln_1p() };
            let err = (f64::from(g) - want).abs();
            assert!(
                err <= 4.0 * f64::from(f32::EPSILON) * want.abs().max(1e-300),
                "x={x}: {g} vs {want}"
            );
        }
    }

    #[test]
    fn differentiable_upsampling_matches_candles_kernel() {
        let values: Vec<f32> = (0..2 * 3 * 5 * 4)
            .map(|i| ((i * 37) % 23) as f32 - 11.0)
            .collect();
        let plain = Tensor::from_vec(values, (2, 3, 5, 4), &Device::Cpu).unwrap();
        let var = candle_core::Var::from_tensor(&plain).unwrap();
        let want = plain.upsample_bilinear2d_with_scale(2.0, 2.0, false).unwrap();
        let got = upsample2_bilinear(var.as_tensor()).unwrap();
        assert_eq!(got.dims(), &[2, 3, 10, 8]);
        let diff = (got.clone() - want)
            .unwrap()
            .abs()
            .unwrap()
            .max_all()
            .unwrap()
            .to_scalar::<f32>()
            .unwrap();
        assert!(diff < 1e-5, "max difference {diff}");
        // Each input value spreads weights summing to 4 (¾ + ¼ per axis, twice).
        let grads = got.sum_all().unwrap().backward().unwrap();
        let g = grads.get(var.as_tensor()).unwrap();
        let total = g.sum_all().unwrap().to_scalar::<f32>().unwrap();
        assert!((total - 4.0 * 120.0).abs() < 1e-3, "gradient total {total}");
    }

    #[test]
    fn prelu_uses_dimension_one() {
        let vb = VarBuilder::from_tensors(
            [(
                "weight".to_string(),
                Tensor::new(&[0.5f32, -2.0], &Device::Cpu).unwrap(),
            )]
            .into_iter()
            .collect(),
            DType::F32,
            &Device::Cpu,
        );
        let act = PRelu::new(2, &vb).unwrap();
        let x = Tensor::new(&[[-1.0f32, -1.0], [3.0, -4.0]], &Device::Cpu).unwrap();
        let y = act.forward(&x).unwrap().to_vec2::<f32>().unwrap();
        assert_eq!(y, vec![vec![-0.5, 2.0], vec![3.0, 8.0]]);
    }
}
