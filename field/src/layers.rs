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
use candle_nn::{Conv2d, Conv2dConfig, GroupNorm, Linear, VarBuilder};

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

/// PyTorch's `softplus(x) = log(1 + eˣ)` (β = 1), evaluated stably for every `x`.
pub fn softplus(x: &Tensor) -> candle_core::Result<Tensor> {
    let tail = log1p_nonneg(&x.abs()?.neg()?.exp()?)?;
    x.relu()? + tail
}

/// Parametric `ReLU` with one slope per channel; the channel is dimension 1, as in
/// PyTorch (use `(rows, features)` inputs for MLPs).
#[derive(Debug, Clone)]
pub struct PRelu {
    weight: Tensor,
}

impl PRelu {
    /// Loads `weight` (`[channels]`).
    pub fn new(channels: usize, vb: &VarBuilder) -> Result<Self, NetError> {
        Ok(Self {
            weight: vb.get(channels, "weight")?,
        })
    }
}

impl Module for PRelu {
    fn forward(&self, x: &Tensor) -> candle_core::Result<Tensor> {
        let mut shape = vec![1usize; x.rank()];
        if x.rank() >= 2 {
            shape[1] = self.weight.elem_count();
        }
        let slope = self.weight.reshape(shape)?;
        x.relu()? + x.minimum(0f32)?.broadcast_mul(&slope)?
    }
}

/// `Linear, (PReLU, Linear)…` through the widths `dims`, parameters under `layers.{i}`.
#[derive(Debug, Clone)]
pub struct Mlp {
    linears: Vec<Linear>,
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
            linears.push(candle_nn::linear(pair[0], pair[1], layers.pp(2 * i))?);
        }
        Ok(Self { linears, activations })
    }
}

impl Module for Mlp {
    /// `x`: `(rows, dims[0])`.
    fn forward(&self, x: &Tensor) -> candle_core::Result<Tensor> {
        let mut h = self.linears[0].forward(x)?;
        for (act, lin) in self.activations.iter().zip(&self.linears[1..]) {
            h = lin.forward(&act.forward(&h)?)?;
        }
        Ok(h)
    }
}

/// One pre-activation residual block of [`ResMlp`].
#[derive(Debug, Clone)]
struct ResBlock {
    prelu_0: PRelu,
    fc_0: Linear,
    prelu_1: PRelu,
    fc_1: Linear,
    shortcut: Option<Linear>,
}

impl Module for ResBlock {
    fn forward(&self, x: &Tensor) -> candle_core::Result<Tensor> {
        let h = self.fc_0.forward(&self.prelu_0.forward(x)?)?;
        let h = self.fc_1.forward(&self.prelu_1.forward(&h)?)?;
        match &self.shortcut {
            Some(s) => s.forward(x)? + h,
            None => x + h,
        }
    }
}

/// `input_layer` (Linear `in → hidden`) and `blocks.{i}`: residual blocks at width
/// `hidden`, the last one mapping to `out` (with a bias-free `shortcut` when
/// `out ≠ hidden`). No final activation.
#[derive(Debug, Clone)]
pub struct ResMlp {
    input_layer: Linear,
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
        let input_layer = candle_nn::linear(in_dim, hidden, vb.pp("input_layer"))?;
        let list = (0..blocks)
            .map(|i| {
                let b = vb.pp("blocks").pp(i);
                let out = if i + 1 == blocks { out_dim } else { hidden };
                Ok(ResBlock {
                    prelu_0: PRelu::new(hidden, &b.pp("prelu_0"))?,
                    fc_0: candle_nn::linear(hidden, hidden, b.pp("fc_0"))?,
                    prelu_1: PRelu::new(hidden, &b.pp("prelu_1"))?,
                    fc_1: candle_nn::linear(hidden, out, b.pp("fc_1"))?,
                    shortcut: if out == hidden {
                        None
                    } else {
                        Some(candle_nn::linear_no_bias(hidden, out, b.pp("shortcut"))?)
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
pub fn group_norm(channels: usize, vb: &VarBuilder) -> Result<GroupNorm, NetError> {
    Ok(candle_nn::group_norm(
        channels.min(32),
        channels,
        1e-5,
        vb.clone(),
    )?)
}

/// `GroupNorm → PReLU → Conv2d` (`norm`, `act`, `conv`).
#[derive(Debug, Clone)]
pub struct NormActConv {
    norm: GroupNorm,
    act: PRelu,
    conv: Conv2d,
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
        let config = Conv2dConfig {
            padding: (kernel - 1) / 2,
            stride,
            ..Conv2dConfig::default()
        };
        Ok(Self {
            norm: group_norm(in_ch, &vb.pp("norm"))?,
            act: PRelu::new(in_ch, &vb.pp("act"))?,
            conv: candle_nn::conv2d(in_ch, out_ch, kernel, config, vb.pp("conv"))?,
        })
    }
}

impl Module for NormActConv {
    fn forward(&self, x: &Tensor) -> candle_core::Result<Tensor> {
        self.conv.forward(&self.act.forward(&self.norm.forward(x)?)?)
    }
}

/// Residual down-sampling block: `shortcut(x) + normactconv1(normactconv0(x))`,
/// halving the resolution.
#[derive(Debug, Clone)]
pub struct ResConvBlock {
    shortcut: Conv2d,
    normactconv0: NormActConv,
    normactconv1: NormActConv,
}

impl ResConvBlock {
    /// `in_ch → out_ch` at half the input resolution.
    pub fn new(in_ch: usize, out_ch: usize, vb: &VarBuilder) -> Result<Self, NetError> {
        let shortcut_config = Conv2dConfig {
            stride: 2,
            ..Conv2dConfig::default()
        };
        Ok(Self {
            shortcut: candle_nn::conv2d(in_ch, out_ch, 1, shortcut_config, vb.pp("shortcut"))?,
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
