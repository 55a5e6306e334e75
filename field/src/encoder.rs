//! The NeLF image encoder (Sun et al. 2021, §4.1; official `image_encoder`): a
//! residual U-Net over each source view that yields a per-pixel feature map at half
//! resolution and a per-patch lighting estimate at 1/16 resolution.
//!
//! * encoder: four [`ResConvBlock`]s, 3 → 32 → 64 → 128 → 256 channels, H → H/16;
//! * light head: `lightpred` ([`NormActConv`] 256 → 512, 3×3), then `lightpred_final`
//!   (GroupNorm(32, 512) → softplus): 512 = 4 maps (RGB estimate, confidence) of 8 × 16;
//! * decoder, for i = 0, 1, 2: `x ← catconv_i(cat[upconv_i(up2(x)), enc_{2−i}])` with
//!   `up2` bilinear ×2 (`align_corners = false`); catconv kernels 3, 3, 1; the last output
//!   (64 channels, H/2 × W/2) is the source feature: channels 0–31 feed the coarse
//!   network, 32–63 the fine one.

use candle_core::{Module, Tensor};
use candle_nn::VarBuilder;

use crate::architecture::Architecture;
use crate::error::NetError;
use crate::layers::{GroupNormLayer, NormActConv, ResConvBlock, softplus, upsample2_bilinear};

/// Channels of the light head: 4 maps × 8 × 16 texels.
pub const LIGHT_FEATURE_CHANNELS: usize = 512;
/// Channels of the official source feature map (coarse half then fine half); other
/// widths: [`Architecture::feature_channels`].
pub const SOURCE_FEATURE_CHANNELS: usize = 64;

/// Every intermediate of one encoder pass, named as in the parity fixtures
/// (`output.encoder.*`). Shapes for `V` views of `H × W`.
#[derive(Debug, Clone)]
pub struct EncoderOutput {
    /// Encoder stages: `(V,32,H/2,W/2)`, `(V,64,H/4,W/4)`, `(V,128,H/8,W/8)`, `(V,256,H/16,W/16)`.
    pub resblocks: [Tensor; 4],
    /// Light head conv output `(V,512,H/16,W/16)`.
    pub lightpred_conv: Tensor,
    /// Light feature after `GroupNorm` + softplus `(V,512,H/16,W/16)`.
    pub light_feature: Tensor,
    /// Decoder up-convs: `(V,128,H/8,W/8)`, `(V,64,H/4,W/4)`, `(V,32,H/2,W/2)`.
    pub upconvs: [Tensor; 3],
    /// Decoder concat-convs 0 and 1: `(V,128,H/8,W/8)`, `(V,64,H/4,W/4)`.
    pub catconvs: [Tensor; 2],
    /// Source feature (= catconv 2) `(V,64,H/2,W/2)`.
    pub feature: Tensor,
}

/// The official `image_encoder` (parameters under `resblocks`, `lightpred`,
/// `lightpred_final`, `upconvs`, `catconvs`; the training-only `reproduces` head is
/// not loaded).
#[derive(Debug, Clone)]
pub struct ImageEncoder {
    resblocks: Vec<ResConvBlock>,
    lightpred: NormActConv,
    lightpred_final: GroupNormLayer,
    upconvs: Vec<NormActConv>,
    catconvs: Vec<NormActConv>,
}

impl ImageEncoder {
    /// Loads the encoder of widths `arch` from `vb` (the `image_encoder` prefix).
    pub fn new(vb: &VarBuilder, arch: &Architecture) -> Result<Self, NetError> {
        let [c0, c1, c2, c3] = arch.encoder_channels;
        let stages = [3, c0, c1, c2, c3];
        let resblocks = (0..4)
            .map(|i| ResConvBlock::new(stages[i], stages[i + 1], &vb.pp("resblocks").pp(i)))
            .collect::<Result<Vec<_>, _>>()?;
        let lightpred = NormActConv::new(c3, LIGHT_FEATURE_CHANNELS, 3, 1, &vb.pp("lightpred"))?;
        let lightpred_final =
            GroupNormLayer::new(LIGHT_FEATURE_CHANNELS, &vb.pp("lightpred_final").pp("norm"))?;
        let up = [(c3, c2), (c2, c1), (c1, c0)];
        let upconvs = up
            .iter()
            .enumerate()
            .map(|(i, &(a, b))| NormActConv::new(a, b, 3, 1, &vb.pp("upconvs").pp(i)))
            .collect::<Result<Vec<_>, _>>()?;
        let cat = [
            (2 * c2, c2, 3),
            (2 * c1, c1, 3),
            (2 * c0, arch.feature_channels(), 1),
        ];
        let catconvs = cat
            .iter()
            .enumerate()
            .map(|(i, &(a, b, k))| NormActConv::new(a, b, k, 1, &vb.pp("catconvs").pp(i)))
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Self {
            resblocks,
            lightpred,
            lightpred_final,
            upconvs,
            catconvs,
        })
    }

    /// Runs the encoder on `images` `(V,3,H,W)` (linear RGB, masked), H and W
    /// divisible by 16.
    pub fn forward(&self, images: &Tensor) -> Result<EncoderOutput, NetError> {
        let (_, channels, height, width) = images.dims4()?;
        if channels != 3 || height % 16 != 0 || width % 16 != 0 || height == 0 || width == 0 {
            return Err(NetError::input(format!(
                "encoder input must be (V,3,H,W) with H and W positive multiples of 16, got {:?}",
                images.dims()
            )));
        }
        let mut enc: Vec<Tensor> = Vec::with_capacity(4);
        let mut x = images.clone();
        for block in &self.resblocks {
            x = block.forward(&x)?;
            enc.push(x.clone());
        }
        let lightpred_conv = self.lightpred.forward(&x)?;
        let light_feature = softplus(&self.lightpred_final.forward_act(&lightpred_conv, None)?)?;
        let mut upconvs = Vec::with_capacity(3);
        let mut catconvs = Vec::with_capacity(3);
        for i in 0..3 {
            let up = upsample2_bilinear(&x)?;
            let u = self.upconvs[i].forward(&up)?;
            x = self.catconvs[i].forward(&Tensor::cat(&[&u, &enc[2 - i]], 1)?)?;
            upconvs.push(u);
            catconvs.push(x.clone());
        }
        let [r0, r1, r2, r3] = <[Tensor; 4]>::try_from(enc).map_err(|_| NetError::input("encoder stages"))?;
        let [u0, u1, u2] = <[Tensor; 3]>::try_from(upconvs).map_err(|_| NetError::input("decoder stages"))?;
        Ok(EncoderOutput {
            resblocks: [r0, r1, r2, r3],
            lightpred_conv,
            light_feature,
            upconvs: [u0, u1, u2],
            catconvs: [catconvs[0].clone(), catconvs[1].clone()],
            feature: x,
        })
    }
}
