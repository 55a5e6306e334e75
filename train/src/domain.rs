//! The domain-adaptation hook: an auto-encoding loss on real portraits through the
//! image encoder (Sun et al., "NeLF", EGSR 2021: the domain adaptation module, which
//! the official implementation trains as the `reproduces` head of its fine-tuning
//! model).
//!
//! The network is trained on rendered heads; its encoder has never seen a photograph.
//! The hook feeds one real portrait `x` (linear RGB in `[0, 1]`, background black) per
//! step through the encoder and a small decoder `D` on the encoder's last skip
//! connection (a transparent background counts as black: colours are premultiplied
//! by their alpha), and adds
//!
//! `L_real = λ_r · mean over pixels and channels of m·|D(E(x)) − x|`,  `m = [max_c x_c > 0]`,
//!
//! so that the features the per-point networks read stay faithful to real images. `D`
//! is the official layout under the official key names (`image_encoder.reproduces.*`:
//! a 3×3 conv over the concatenated decoder and first encoder stage, ×2 bilinear
//! up-sampling, a 3×3 and a 1×1 conv, each after `GroupNorm` + `PReLU`, then `GroupNorm`
//! and a sigmoid); it is trained with the encoder's step size, saved in the checkpoint
//! and in the exported weights, and never used at inference (the model ignores it).
//!
//! The real-portrait set the paper used cannot be fetched here, so no shipped weights
//! were trained with the hook (`train/README.md`); it is tested on a public-domain
//! photograph in `data/metrics`.

use std::path::{Path, PathBuf};

use candle_core::{Module, Tensor};
use candle_nn::VarBuilder;
use image::imageops::FilterType;
use nelf_field::encoder::EncoderOutput;
use nelf_field::layers::{GroupNormLayer, NormActConv, upsample2_bilinear};
use nelf_field::{Architecture, Model};
use nelf_format::io_error::IoResultExt;
use nelf_scene::mesh_io::srgb_to_linear;
use rand::SeedableRng;
use rand_pcg::Pcg64;

use crate::error::TrainError;

/// Prefix of the head's variables (the official key names).
pub const HEAD_PREFIX: &str = "image_encoder.reproduces.";

/// Whether the variable `name` belongs to the head (a checkpoint or weights file
/// saved without the hook lacks it; it then starts from its initial values).
pub fn is_head_variable(name: &str) -> bool {
    name.starts_with(HEAD_PREFIX)
}

/// Image extensions read from a real-portrait folder.
const IMAGE_EXTENSIONS: [&str; 4] = ["png", "jpg", "jpeg", "exr"];

/// The decoder that reproduces an encoder input from the encoder's last skip stage.
#[derive(Debug, Clone)]
pub struct ReproduceHead {
    convs: [NormActConv; 3],
    norm: GroupNormLayer,
}

impl ReproduceHead {
    /// The head for encoder widths `arch`, its variables under `vb`'s
    /// `image_encoder.reproduces`.
    pub fn new(vb: &VarBuilder, arch: &Architecture) -> Result<Self, TrainError> {
        let c0 = arch.encoder_channels[0];
        let vb = vb.pp("image_encoder").pp("reproduces");
        Ok(Self {
            convs: [
                NormActConv::new(2 * c0, c0, 3, 1, &vb.pp(0))?,
                NormActConv::new(c0, c0, 3, 1, &vb.pp(1))?,
                NormActConv::new(c0, 3, 1, 1, &vb.pp(2))?,
            ],
            norm: GroupNormLayer::new(3, &vb.pp(3).pp("norm"))?,
        })
    }

    /// The reproduced image `(V, 3, H, W)` from the encoder's outputs on `(V, 3, H, W)`.
    pub fn forward(&self, out: &EncoderOutput) -> Result<Tensor, TrainError> {
        let [_, _, up] = &out.upconvs;
        let skip = Tensor::cat(&[up, &out.resblocks[0]], 1)?;
        let x = self.convs[0].forward(&skip)?;
        let x = upsample2_bilinear(&x)?;
        let x = self.convs[2].forward(&self.convs[1].forward(&x)?)?;
        Ok(candle_nn::ops::sigmoid(&self.norm.forward_act(&x, None)?)?)
    }
}

/// A folder of real portraits, each centre-cropped to a square, decoded to linear RGB
/// premultiplied by its alpha and resized to the network's image size (a triangle
/// filter as wide as the reduction).
#[derive(Debug, Clone)]
pub struct RealImages {
    size: usize,
    images: Vec<(PathBuf, Vec<f32>)>,
}

impl RealImages {
    /// Reads every PNG, JPEG or EXR file of `dir` (sorted by name) at `size`² pixels.
    /// The background must be black or transparent (colours are premultiplied by their
    /// alpha; black pixels are left out of the loss); at least one pixel of each
    /// image must not be.
    pub fn load(dir: &Path, size: usize) -> Result<Self, TrainError> {
        if size == 0 {
            return Err(TrainError::Settings(
                "real portraits need a positive image size".into(),
            ));
        }
        let entries = std::fs::read_dir(dir).with_path(dir)?;
        let mut paths = Vec::new();
        for entry in entries {
            let path = entry.with_path(dir)?.path();
            let known = path
                .extension()
                .and_then(|e| e.to_str())
                .is_some_and(|e| IMAGE_EXTENSIONS.contains(&e.to_ascii_lowercase().as_str()));
            if known && path.is_file() {
                paths.push(path);
            }
        }
        paths.sort();
        if paths.is_empty() {
            return Err(TrainError::File {
                path: dir.to_path_buf(),
                message: format!(
                    "no real portraits here (files ending in {})",
                    IMAGE_EXTENSIONS.join(", ")
                ),
            });
        }
        let images = paths
            .into_iter()
            .map(|path| {
                let pixels = read_portrait(&path, size)?;
                Ok((path, pixels))
            })
            .collect::<Result<Vec<_>, TrainError>>()?;
        Ok(Self { size, images })
    }

    /// Number of portraits.
    pub fn len(&self) -> usize {
        self.images.len()
    }

    /// Whether there are none (never, once loaded).
    pub fn is_empty(&self) -> bool {
        self.images.is_empty()
    }

    /// Side of the square images, pixels.
    pub fn size(&self) -> usize {
        self.size
    }

    /// Portrait `i`: its file and its pixels (`size² × 3`, row-major, linear RGB).
    pub fn get(&self, i: usize) -> Option<(&Path, &[f32])> {
        self.images.get(i).map(|(p, x)| (p.as_path(), x.as_slice()))
    }

    /// The portrait step `step` of a run seeded `seed` trains on: drawn from a stream
    /// of its own, so that the rest of the step's random choices are those of a run
    /// without the hook.
    pub fn pick(&self, seed: u64, step: u64) -> usize {
        use rand::Rng;
        let mut rng = Pcg64::seed_from_u64(seed ^ 0x5245_414C ^ step.wrapping_mul(0xD1B5_4A32_D192_ED03));
        rng.random_range(0..self.images.len())
    }
}

/// One portrait file at `size`²: centre-cropped square, linear RGB premultiplied by
/// its alpha, resized with a triangle filter as wide as the reduction.
fn read_portrait(path: &Path, size: usize) -> Result<Vec<f32>, TrainError> {
    let decoded = crate::data::read::decode(path)?;
    let is_linear = path
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("exr"));
    let rgba = decoded.to_rgba32f();
    let (w, h) = rgba.dimensions();
    let side = w.min(h);
    if side == 0 {
        return Err(TrainError::File {
            path: path.to_path_buf(),
            message: "the image is empty".into(),
        });
    }
    let square = image::imageops::crop_imm(&rgba, (w - side) / 2, (h - side) / 2, side, side).to_image();
    // Linear RGB premultiplied by alpha, before filtering: a transparent background
    // becomes black, and the filter averages light, not encoded values.
    let linear = image::Rgb32FImage::from_fn(side, side, |x, y| {
        let p = square.get_pixel(x, y).0;
        let alpha = p[3].clamp(0.0, 1.0);
        image::Rgb([0, 1, 2].map(|c| {
            alpha
                * if is_linear {
                    p[c].clamp(0.0, 1.0)
                } else {
                    srgb_to_linear(p[c])
                }
        }))
    });
    let side_px =
        u32::try_from(size).map_err(|_| TrainError::Settings(format!("image size {size} is too large")))?;
    let small = image::imageops::resize(&linear, side_px, side_px, FilterType::Triangle);
    let pixels: Vec<f32> = small.into_raw().into_iter().map(|v| v.clamp(0.0, 1.0)).collect();
    if !pixels.iter().any(|&v| v > 0.0) {
        return Err(TrainError::File {
            path: path.to_path_buf(),
            message: "every pixel is black: a real portrait needs a foreground".into(),
        });
    }
    Ok(pixels)
}

/// `mean(m·|D(E(x)) − x|)` of one portrait `pixels` (`size² × 3`, linear RGB) through
/// `model`'s encoder and `head`, with the graph for its gradients.
pub fn reproduction_loss(
    model: &Model,
    head: &ReproduceHead,
    pixels: &[f32],
    size: usize,
) -> Result<Tensor, TrainError> {
    if pixels.len() != size * size * 3 || size % 16 != 0 {
        return Err(TrainError::Settings(format!(
            "a real portrait of {} values is not {size}² RGB pixels with {size} a multiple of 16",
            pixels.len()
        )));
    }
    let device = model.device();
    let x = Tensor::from_slice(pixels, (1, size, size, 3), device)?
        .permute((0, 3, 1, 2))?
        .contiguous()?;
    let out = model.encoder().forward(&x)?;
    let reproduced = head.forward(&out)?;
    let mask: Vec<f32> = pixels
        .chunks_exact(3)
        .map(|p| if p.iter().any(|&v| v > 0.0) { 1.0 } else { 0.0 })
        .collect();
    let mask = Tensor::from_vec(mask, (1, 1, size, size), device)?;
    Ok(reproduced.sub(&x)?.abs()?.broadcast_mul(&mask)?.mean_all()?)
}
