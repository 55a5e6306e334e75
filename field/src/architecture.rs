//! The network's widths ([`Architecture`]): the official ones by default, smaller
//! ones for faster training, read back from a weights file's tensor shapes. A leaf
//! module: the encoder, the per-point networks and the model all size their layers
//! from it.

use std::collections::HashMap;

use candle_core::Tensor;

use crate::error::NetError;

/// The widths of the network: the official ones by default (checkpoint-compatible);
/// smaller ones train faster. Every other width (the direction MLP's 16, the density
/// MLP's 32, the blend MLP's 32 and 16, the light head's 512 = 4 maps × 128 texels) is
/// fixed. Read from a weights file's tensor shapes by [`Architecture::from_tensors`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Architecture {
    /// Channels of the four encoder stages (official 32, 64, 128, 256), each at most
    /// 32 or a multiple of 32 (`GroupNorm` takes `min(32, C)` groups).
    pub encoder_channels: [usize; 4],
    /// Latent channels per stage (official 32): the source feature has twice as many,
    /// the first half for the coarse network, the second for the fine one.
    pub latent_channels: usize,
    /// Width of the geometry feature (official 64).
    pub geometry_features: usize,
    /// Hidden width of the light-transport MLP (official 128).
    pub lt_hidden: usize,
}

impl Default for Architecture {
    fn default() -> Self {
        Self::OFFICIAL
    }
}

impl Architecture {
    /// The official widths.
    pub const OFFICIAL: Self = Self {
        encoder_channels: [32, 64, 128, 256],
        latent_channels: 32,
        geometry_features: 64,
        lt_hidden: 128,
    };

    /// Channels of the source feature map (both stages' latents).
    pub fn feature_channels(&self) -> usize {
        2 * self.latent_channels
    }

    /// Checks that every width is positive and that `GroupNorm` can split the
    /// encoder's channels (`min(32, C)` groups must divide `C`).
    pub fn validate(&self) -> Result<(), NetError> {
        let groups_ok = |c: usize| c > 0 && c % c.min(32) == 0;
        let widths = [self.latent_channels, self.geometry_features, self.lt_hidden];
        if !self.encoder_channels.iter().all(|&c| groups_ok(c))
            || !groups_ok(self.feature_channels())
            || widths.contains(&0)
        {
            return Err(NetError::input(format!("unusable network widths {self:?}")));
        }
        Ok(())
    }

    /// The widths of a set of weights, read from the shapes of the tensors that
    /// carry them (official key names).
    pub fn from_tensors(tensors: &HashMap<String, Tensor>) -> Result<Self, NetError> {
        let rows = |key: &str| -> Result<usize, NetError> {
            let t = tensors
                .get(key)
                .ok_or_else(|| NetError::input(format!("no tensor `{key}`")))?;
            Ok(t.dims().first().copied().unwrap_or(0))
        };
        let mut encoder_channels = [0usize; 4];
        for (i, c) in encoder_channels.iter_mut().enumerate() {
            *c = rows(&format!("image_encoder.resblocks.{i}.shortcut.weight"))?;
        }
        let feature = rows("image_encoder.catconvs.2.conv.weight")?;
        if feature % 2 != 0 {
            return Err(NetError::input(format!(
                "the source feature has {feature} channels, not two equal halves"
            )));
        }
        let arch = Self {
            encoder_channels,
            latent_channels: feature / 2,
            geometry_features: rows("coarse_appearance_encoder.geometry_mlp.input_layer.weight")?,
            lt_hidden: rows("coarse_appearance_encoder.lt_mlp.input_layer.weight")?,
        };
        arch.validate()?;
        Ok(arch)
    }
}
