//! The whole NeLF model (official `NelfFt`): the image encoder, the light
//! aggregation and the coarse and fine per-point networks, loaded from a
//! safetensors file whose keys are the official `state_dict`'s (`layout.tsv` in the
//! parity fixtures). Per-point evaluation prunes points outside the visual hull
//! (σ = 0, colour 0 there, as the official `compute_color`) and runs the network
//! in bounded batches on all cores.

use std::path::Path;

use candle_core::{DType, Device, Tensor};
use candle_nn::VarBuilder;
use nelf_format::conventions::{ENV_TEXELS, LT_DIM};
use rayon::prelude::*;

pub use crate::architecture::Architecture;
use crate::encoder::{EncoderOutput, ImageEncoder};
use crate::error::NetError;
use crate::light::{aggregate_light, net_solid_angles};
use crate::nelfnet::{NelfNet, NelfNetTrace, PointInputs};
use crate::prior::ShadingPrior;
use crate::views::{EncodedViews, SourceViews, Stage};

/// zstd's frame magic number (RFC 8878, section 3.1.1), little-endian.
const ZSTD_MAGIC: [u8; 4] = [0x28, 0xB5, 0x2F, 0xFD];

/// Largest safetensors file a compressed one may expand to (4 GiB): a hostile frame
/// cannot make the reader allocate without bound.
const MAX_SAFETENSORS_BYTES: u64 = 4 << 30;

/// The bytes of a safetensors file, decompressed first when the file is a zstd frame
/// (recognised by its magic number, whatever its name): weights and fixtures are kept
/// compressed in the repository (`*.safetensors.zst`, about 10–25 % smaller).
pub fn read_safetensors_bytes(path: &Path) -> Result<Vec<u8>, NetError> {
    use std::io::Read;
    let bytes = std::fs::read(path).map_err(|e| NetError::file(path, e.to_string()))?;
    if !bytes.starts_with(&ZSTD_MAGIC) {
        return Ok(bytes);
    }
    let decoder = zstd::stream::read::Decoder::new(bytes.as_slice())
        .map_err(|e| NetError::file(path, format!("not a zstd frame: {e}")))?;
    let mut out = Vec::new();
    decoder
        .take(MAX_SAFETENSORS_BYTES + 1)
        .read_to_end(&mut out)
        .map_err(|e| NetError::file(path, format!("damaged zstd data: {e}")))?;
    if out.len() as u64 > MAX_SAFETENSORS_BYTES {
        return Err(NetError::file(
            path,
            format!("decompresses to more than {MAX_SAFETENSORS_BYTES} bytes"),
        ));
    }
    Ok(out)
}

/// Model arguments (official `config_nelf_ft` values by default).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NelfConfig {
    /// Coarse samples per ray (and inverse-CDF bins), 64.
    pub coarse_samples: usize,
    /// Importance samples per ray added for the fine pass, 128.
    pub fine_samples: usize,
    /// Radius around the head centre that bounds rays, millimetres (the official
    /// `head_diameter = 200`, used as a radius).
    pub head_radius_mm: f32,
    /// Points per network batch (bounds memory: about 20 KB per point and view).
    pub batch_points: usize,
    /// The network's widths ([`Model::load`] reads them from the weights).
    pub architecture: Architecture,
}

impl Default for NelfConfig {
    fn default() -> Self {
        Self {
            coarse_samples: 64,
            fine_samples: 128,
            head_radius_mm: 200.0,
            batch_points: 2048,
            architecture: Architecture::OFFICIAL,
        }
    }
}

impl NelfConfig {
    /// The defaults with a batch size suited to `device`: 2048 points on the CPU
    /// (cache-sized), 65536 on a GPU.
    pub fn for_device(device: &Device) -> Self {
        Self {
            batch_points: if device.is_cpu() { 2048 } else { 65_536 },
            ..Self::default()
        }
    }
}

/// The device the network should run on: CUDA device 0 when built with the `cuda`
/// feature and a GPU is present, else the CPU.
pub fn default_device() -> Device {
    Device::cuda_if_available(0).unwrap_or(Device::Cpu)
}

/// A short name of `device` for reports: `cpu`, `cuda` or `metal`.
pub fn device_name(device: &Device) -> &'static str {
    if device.is_cpu() {
        "cpu"
    } else if device.is_cuda() {
        "cuda"
    } else {
        "metal"
    }
}

/// The NeLF model.
#[derive(Debug, Clone)]
pub struct Model {
    encoder: ImageEncoder,
    coarse: NelfNet,
    fine: NelfNet,
    config: NelfConfig,
    device: Device,
    working_image_size: Option<usize>,
    source_relative_light: bool,
    /// `(3, 128)` irradiance `L_S·Ω` of the capture's known source lighting when the
    /// light transport is normalised to it ([`Model::with_source_normalisation`]).
    source_irradiance: Option<Tensor>,
    /// The Lambertian shading prior mixed into the normalised light transport
    /// ([`Model::with_shading_prior`]).
    shading_prior: Option<ShadingPrior>,
    /// The shading prior the weights' last training steps went through, as their
    /// file says ([`SHADING_PRIOR_MM_KEY`], [`SHADING_PRIOR_WEIGHT_KEY`]).
    trained_shading_prior: Option<ShadingPrior>,
}

/// The key of the optional one-element tensor in a weights file that holds the image
/// side, pixels, the network was trained at (`nelf train` writes it): captures are
/// reduced to about that size before encoding, as the encoder's receptive field is
/// measured in pixels.
pub const WORKING_IMAGE_SIZE_KEY: &str = "nelf.working_image_size";

/// The key of the optional one-element tensor (value 1) in a weights file that says
/// the network was trained with every lighting in units of the capture's source
/// lighting (each map divided by the source map's mean radiance, `nelf train run
/// --source-relative-light`): its light transport is then `T·p_S`, the physical
/// transport times the source lighting's mean radiance `p_S`, which the images alone
/// cannot tell. Absent: lightings in absolute units.
pub const SOURCE_RELATIVE_LIGHT_KEY: &str = "nelf.source_relative_light";

/// The keys of the optional one-element tensors in a weights file that give the
/// shading prior ([`crate::prior`]) the network's last training steps rendered through
/// (`nelf train run --shading-prior-mm`): its gradient step, mm, and its weight. Both
/// or neither. Such weights learned to complement that prior; used without it (or
/// with another) they are off the distribution they were last fitted to.
pub const SHADING_PRIOR_MM_KEY: &str = "nelf.shading_prior_mm";

/// See [`SHADING_PRIOR_MM_KEY`].
pub const SHADING_PRIOR_WEIGHT_KEY: &str = "nelf.shading_prior_weight";

/// Per-point outputs of a batch: density and colour or light transport, zero
/// outside the hull.
#[derive(Debug, Clone, PartialEq)]
pub struct PointValues {
    /// `(N)` σ, 1/mm.
    pub sigma: Vec<f32>,
    /// `(N, C)` values per point (`C = 3` colours, or 384 light transport).
    pub values: Vec<f32>,
    /// `(N)` whether the point is inside the hull (and was evaluated).
    pub inside: Vec<bool>,
}

impl Model {
    /// Builds the model from `vb` (root prefix: keys `image_encoder.*`,
    /// `coarse_appearance_encoder.*`, `fine_appearance_encoder.*`).
    pub fn new(vb: &VarBuilder, config: NelfConfig) -> Result<Self, NetError> {
        if config.coarse_samples < 2
            || config.batch_points == 0
            || !config.head_radius_mm.is_finite()
            || config.head_radius_mm <= 0.0
            || config.architecture.validate().is_err()
        {
            return Err(NetError::input(format!(
                "unusable model configuration {config:?}"
            )));
        }
        Ok(Self {
            encoder: ImageEncoder::new(&vb.pp("image_encoder"), &config.architecture)?,
            coarse: NelfNet::new(&vb.pp("coarse_appearance_encoder"), &config.architecture)?,
            fine: NelfNet::new(&vb.pp("fine_appearance_encoder"), &config.architecture)?,
            config,
            device: vb.device().clone(),
            working_image_size: None,
            source_relative_light: false,
            source_irradiance: None,
            shading_prior: None,
            trained_shading_prior: None,
        })
    }

    /// The image side the network was trained at, if its weights say
    /// ([`WORKING_IMAGE_SIZE_KEY`]).
    pub fn working_image_size(&self) -> Option<usize> {
        self.working_image_size
    }

    /// The model with its working image size set.
    #[must_use]
    pub fn with_working_image_size(self, size: Option<usize>) -> Self {
        Self {
            working_image_size: size,
            ..self
        }
    }

    /// The model rendering with `coarse` evenly spaced and `fine` importance samples
    /// per ray (the weights are shared, not copied).
    #[must_use]
    pub fn with_samples(self, coarse: usize, fine: usize) -> Self {
        Self {
            config: NelfConfig {
                coarse_samples: coarse,
                fine_samples: fine,
                ..self.config
            },
            ..self
        }
    }

    /// Whether the network takes lightings in units of the source lighting's mean
    /// radiance ([`SOURCE_RELATIVE_LIGHT_KEY`]).
    pub fn source_relative_light(&self) -> bool {
        self.source_relative_light
    }

    /// The model with [`Model::source_relative_light`] set.
    #[must_use]
    pub fn with_source_relative_light(self, relative: bool) -> Self {
        Self {
            source_relative_light: relative,
            ..self
        }
    }

    /// The model with every view's light transport normalised to the source lighting
    /// `light` (network layout `(3, 8, 16)`, radiance), or without normalisation for
    /// `None`: each per-view vector `lt_v` is divided, per channel, by `lt_v·(L_S·Ω)`
    /// ([`crate::nelfnet::normalise_to_source`]), so that the network reproduces its
    /// source colours exactly under the lighting they were taken in, and its light
    /// transport is in the units of `light`.
    pub fn with_source_normalisation(self, light: Option<&[f32]>) -> Result<Self, NetError> {
        let source_irradiance = light.map(|l| self.irradiance(l)).transpose()?;
        Ok(Self {
            source_irradiance,
            ..self
        })
    }

    /// Whether the light transport is normalised to a source lighting
    /// ([`Model::with_source_normalisation`]).
    pub fn source_normalised(&self) -> bool {
        self.source_irradiance.is_some()
    }

    /// The model with the Lambertian shading prior ([`crate::prior`]) mixed into its
    /// light transport (`None`: the network's own). The prior is normalised to the
    /// source lighting, so the model must have one ([`Model::with_source_normalisation`]).
    pub fn with_shading_prior(self, prior: Option<ShadingPrior>) -> Result<Self, NetError> {
        if let Some(p) = &prior {
            p.validate()?;
            if self.source_irradiance.is_none() {
                return Err(NetError::input(
                    "the shading prior needs the source lighting (with_source_normalisation)",
                ));
            }
        }
        Ok(Self {
            shading_prior: prior,
            ..self
        })
    }

    /// The source irradiance `(3, 128)` the light transport is normalised to, if any
    /// ([`Model::with_source_normalisation`]).
    pub fn source_irradiance(&self) -> Option<&Tensor> {
        self.source_irradiance.as_ref()
    }

    /// The shading prior, if any ([`Model::with_shading_prior`]).
    pub fn shading_prior(&self) -> Option<ShadingPrior> {
        self.shading_prior
    }

    /// The shading prior the weights were last trained through, if their file says
    /// ([`SHADING_PRIOR_MM_KEY`]).
    pub fn trained_shading_prior(&self) -> Option<ShadingPrior> {
        self.trained_shading_prior
    }

    /// The model with [`Model::trained_shading_prior`] set.
    #[must_use]
    pub fn with_trained_shading_prior(self, prior: Option<ShadingPrior>) -> Self {
        Self {
            trained_shading_prior: prior,
            ..self
        }
    }

    /// The per-view transport `lt` `(N, V, 384)` of `points` (mm, seen along
    /// `target_dirc`) with the model's shading prior mixed in ([`crate::prior`]), or
    /// `None` when the model has none. `density` gives σ of a batch of probe points
    /// seen along the given directions (without gradients); `encoded` supplies the
    /// view-0 camera the prior's directions are expressed in.
    pub fn shading_prior_transport<E: From<NetError>>(
        &self,
        encoded: &EncodedViews,
        points: &[[f32; 3]],
        target_dirc: &[[f32; 3]],
        lt: &Tensor,
        density: impl Fn(&[[f32; 3]], &[[f32; 3]]) -> Result<Vec<f32>, E>,
    ) -> Result<Option<Tensor>, E> {
        let (Some(prior), Some(e)) = (&self.shading_prior, &self.source_irradiance) else {
            return Ok(None);
        };
        let dirs: Vec<[f32; 3]> = target_dirc.iter().flat_map(|d| [*d; 6]).collect();
        let normals = crate::prior::density_normals(points, prior.step_mm, |probes| density(probes, &dirs))?;
        let cam0 = encoded
            .cameras()
            .first()
            .ok_or_else(|| NetError::input("no source views"))?
            .rotation();
        Ok(Some(crate::prior::shading_prior(prior, lt, e, &normals, cam0)?))
    }

    /// Runs `stage`'s per-point network on `inputs`, with the source normalisation
    /// when the model has one: every caller that shades or reads light transport
    /// goes through here.
    pub fn forward_points(&self, stage: Stage, inputs: &PointInputs) -> Result<NelfNetTrace, NetError> {
        let mut trace = self.net(stage).forward(inputs)?;
        if let Some(e) = &self.source_irradiance {
            trace.lt_scale = crate::nelfnet::normalise_to_source(&trace.lt_scale, e)?;
        }
        Ok(trace)
    }

    /// Loads the weights from a safetensors file (official key names; f32, or any
    /// float type, converted) onto `device`. The file may be zstd-compressed
    /// (`*.safetensors.zst`, see [`read_safetensors_bytes`]). The widths come from the
    /// file (`config.architecture` is replaced by [`Architecture::from_tensors`]).
    pub fn load(path: impl AsRef<Path>, config: NelfConfig, device: &Device) -> Result<Self, NetError> {
        let path = path.as_ref();
        let bytes = read_safetensors_bytes(path)?;
        Self::from_safetensors_bytes(&bytes, path, config, device)
    }

    /// [`Model::load`] from the bytes of a safetensors file; `origin` names them in errors.
    pub fn from_safetensors_bytes(
        bytes: &[u8],
        origin: &Path,
        config: NelfConfig,
        device: &Device,
    ) -> Result<Self, NetError> {
        let mut tensors = candle_core::safetensors::load_buffer(bytes, device)
            .map_err(|e| NetError::file(origin, format!("not a safetensors file: {e}")))?;
        // A metadata entry: `None` when absent, `Some(None)` when it is not one number.
        let mut metadata = |key: &str| -> Option<Option<f32>> {
            tensors.remove(key).map(|t| {
                t.flatten_all()
                    .and_then(|t| t.to_dtype(DType::F32))
                    .and_then(|t| t.to_vec1::<f32>())
                    .ok()
                    .filter(|v| v.len() == 1)
                    .and_then(|v| v.first().copied())
            })
        };
        let working_image_size = match metadata(WORKING_IMAGE_SIZE_KEY) {
            None => None,
            Some(Some(v)) if v.is_finite() && (16.0..=16_384.0).contains(&v) && v.fract() == 0.0 => {
                Some(v as usize)
            }
            Some(_) => {
                return Err(NetError::file(
                    origin,
                    format!("`{WORKING_IMAGE_SIZE_KEY}` is not an image side of 16 to 16384 pixels"),
                ));
            }
        };
        let source_relative_light = match metadata(SOURCE_RELATIVE_LIGHT_KEY) {
            None | Some(Some(0.0)) => false,
            Some(Some(1.0)) => true,
            Some(_) => {
                return Err(NetError::file(
                    origin,
                    format!("`{SOURCE_RELATIVE_LIGHT_KEY}` is neither 0 nor 1"),
                ));
            }
        };
        let trained_shading_prior = match (metadata(SHADING_PRIOR_MM_KEY), metadata(SHADING_PRIOR_WEIGHT_KEY))
        {
            (None, None) => None,
            (Some(Some(step_mm)), Some(Some(weight)))
                if (ShadingPrior { step_mm, weight }).validate().is_ok() =>
            {
                Some(ShadingPrior { step_mm, weight })
            }
            _ => {
                return Err(NetError::file(
                    origin,
                    format!(
                        "`{SHADING_PRIOR_MM_KEY}` and `{SHADING_PRIOR_WEIGHT_KEY}` must both be given, a \
                         positive step in mm and a weight in [0, 1], or neither"
                    ),
                ));
            }
        };
        let architecture = Architecture::from_tensors(&tensors)
            .map_err(|e| NetError::file(origin, format!("not NeLF weights: {e}")))?;
        let vb = VarBuilder::from_tensors(tensors, DType::F32, device);
        Self::new(
            &vb,
            NelfConfig {
                architecture,
                ..config
            },
        )
        .map(|m| {
            m.with_working_image_size(working_image_size)
                .with_source_relative_light(source_relative_light)
                .with_trained_shading_prior(trained_shading_prior)
        })
        .map_err(|e| NetError::file(origin, format!("not NeLF weights: {e}")))
    }

    /// The configuration.
    pub fn config(&self) -> &NelfConfig {
        &self.config
    }

    /// The device the network runs on.
    pub fn device(&self) -> &Device {
        &self.device
    }

    /// The image encoder.
    pub fn encoder(&self) -> &ImageEncoder {
        &self.encoder
    }

    /// The per-point network of `stage`.
    pub fn net(&self, stage: Stage) -> &NelfNet {
        match stage {
            Stage::Coarse => &self.coarse,
            Stage::Fine => &self.fine,
        }
    }

    /// Encodes the source views, keeping every encoder intermediate.
    pub fn encode_traced(&self, views: &SourceViews) -> Result<(EncodedViews, EncoderOutput), NetError> {
        views.validate()?;
        let (v, h, w) = (views.views(), views.height, views.width);
        let images = Tensor::from_slice(&views.images, (v, h, w, 3), &self.device)?
            .permute((0, 3, 1, 2))?
            .contiguous()?;
        let out = self.encoder.forward(&images)?;
        let features = out
            .feature
            .permute((0, 2, 3, 1))?
            .flatten_all()?
            .to_vec1::<f32>()?;
        let feature_channels = self.config.architecture.feature_channels();
        debug_assert_eq!(features.len(), v * (h / 2) * (w / 2) * feature_channels);
        let light_feature = out.light_feature.flatten_all()?.to_vec1::<f32>()?;
        let rotations: Vec<_> = views
            .cameras
            .iter()
            .map(crate::geometry::NetCamera::rotation)
            .collect();
        let light = aggregate_light(&light_feature, &rotations, h / 16, w / 16)?;
        let encoded = EncodedViews {
            width: w,
            height: h,
            cameras: views.cameras.clone(),
            projections: views
                .cameras
                .iter()
                .map(crate::geometry::NetCamera::projection)
                .collect(),
            centres: views
                .cameras
                .iter()
                .map(crate::geometry::NetCamera::centre)
                .collect(),
            images: views.images.clone(),
            masks_dilated: crate::geometry::dilate_masks(&views.masks, w, h),
            features,
            feature_channels,
            light,
        };
        Ok((encoded, out))
    }

    /// Encodes the source views.
    pub fn encode(&self, views: &SourceViews) -> Result<EncodedViews, NetError> {
        Ok(self.encode_traced(views)?.0)
    }

    /// Runs `stage`'s network on `points` (mm) toward unit `target_dirc`, without
    /// the hull test, returning its inputs and every intermediate.
    pub fn run_points(
        &self,
        encoded: &EncodedViews,
        points: &[[f32; 3]],
        target_dirc: &[[f32; 3]],
        stage: Stage,
    ) -> Result<(PointInputs, NelfNetTrace), NetError> {
        let inputs = encoded
            .gather(points, target_dirc, stage)?
            .to_tensors(&self.device)?;
        let mut trace = self.forward_points(stage, &inputs)?;
        if let Some(lt) =
            self.shading_prior_transport(encoded, points, target_dirc, &trace.lt_scale, |probes, dirs| {
                let inputs = encoded.gather(probes, dirs, stage)?.to_tensors(&self.device)?;
                Ok::<_, NetError>(
                    self.net(stage)
                        .density(&inputs)?
                        .flatten_all()?
                        .to_vec1::<f32>()?,
                )
            })?
        {
            trace.lt_scale = lt;
        }
        Ok((inputs, trace))
    }

    /// Evaluates the points inside the hull in parallel batches through `stage`'s
    /// whole network; `per_batch` turns one batch's network pass into rows of `width`
    /// values.
    fn evaluate_in_hull(
        &self,
        encoded: &EncodedViews,
        points: &[[f32; 3]],
        target_dirc: &[[f32; 3]],
        stage: Stage,
        width: usize,
        per_batch: &(dyn Fn(&PointInputs, &NelfNetTrace) -> Result<Tensor, NetError> + Sync),
    ) -> Result<PointValues, NetError> {
        self.batches_in_hull(encoded, points, target_dirc, width, |p, d| {
            let (inputs, trace) = self.run_points(encoded, p, d, stage)?;
            let sigma = trace.density.flatten_all()?.to_vec1::<f32>()?;
            let values = per_batch(&inputs, &trace)?.flatten_all()?.to_vec1::<f32>()?;
            Ok((sigma, values))
        })
    }

    /// The visual-hull filter and batching every per-point evaluation shares: keeps
    /// the points inside the hull, runs `batch` on them in parallel chunks of
    /// [`NelfConfig::batch_points`] (points and directions), which returns σ and
    /// `width` values per point, and scatters the results back (zero outside).
    fn batches_in_hull(
        &self,
        encoded: &EncodedViews,
        points: &[[f32; 3]],
        target_dirc: &[[f32; 3]],
        width: usize,
        batch: impl Fn(&[[f32; 3]], &[[f32; 3]]) -> Result<(Vec<f32>, Vec<f32>), NetError> + Sync,
    ) -> Result<PointValues, NetError> {
        if points.len() != target_dirc.len() {
            return Err(NetError::input(format!(
                "{} points and {} target directions",
                points.len(),
                target_dirc.len()
            )));
        }
        let inside = encoded.hull(points).inside;
        let index: Vec<usize> = (0..points.len()).filter(|&i| inside[i]).collect();
        let batches: Vec<(Vec<f32>, Vec<f32>)> = index
            .par_chunks(self.config.batch_points)
            .map(|chunk| {
                let p: Vec<[f32; 3]> = chunk.iter().map(|&i| points[i]).collect();
                let d: Vec<[f32; 3]> = chunk.iter().map(|&i| target_dirc[i]).collect();
                batch(&p, &d)
            })
            .collect::<Result<_, NetError>>()?;
        let mut sigma = vec![0.0f32; points.len()];
        let mut values = vec![0.0f32; points.len() * width];
        for (chunk, (s, vals)) in index.chunks(self.config.batch_points).zip(batches) {
            for (k, &i) in chunk.iter().enumerate() {
                sigma[i] = s[k];
                values[i * width..(i + 1) * width].copy_from_slice(&vals[k * width..(k + 1) * width]);
            }
        }
        Ok(PointValues {
            sigma,
            values,
            inside,
        })
    }

    /// σ (1/mm) and colour (`values`: `(N, 3)`) of `points` (mm) seen along unit
    /// `target_dirc` (point → viewer) under the network-layout light `light`
    /// (`(3, 8, 16)` radiance); zero outside the hull.
    pub fn shade_points(
        &self,
        encoded: &EncodedViews,
        points: &[[f32; 3]],
        target_dirc: &[[f32; 3]],
        stage: Stage,
        light: &[f32],
    ) -> Result<PointValues, NetError> {
        let irradiance = self.irradiance(light)?;
        self.evaluate_in_hull(encoded, points, target_dirc, stage, 3, &|inputs, trace| {
            Ok(NelfNet::shade(trace, &inputs.source_rgb, &irradiance)?.rgb)
        })
    }

    /// σ (1/mm) and light-transport vectors (`values`: `(N, 384)`, network layout,
    /// the network's solid angles folded in) of `points` (mm) seen along unit
    /// `target_dirc`; zero outside the hull.
    pub fn light_transport_points(
        &self,
        encoded: &EncodedViews,
        points: &[[f32; 3]],
        target_dirc: &[[f32; 3]],
        stage: Stage,
    ) -> Result<PointValues, NetError> {
        let omega = Tensor::from_slice(&net_solid_angles(), ENV_TEXELS, &self.device)?;
        self.evaluate_in_hull(encoded, points, target_dirc, stage, LT_DIM, &|inputs, trace| {
            NelfNet::light_transport(trace, &inputs.source_rgb, &omega)
        })
    }

    /// σ (1/mm) of `points` (mm) seen along unit `target_dirc`, zero outside the
    /// hull (`values` empty); skips the light-transport and blend networks.
    pub fn density_points(
        &self,
        encoded: &EncodedViews,
        points: &[[f32; 3]],
        target_dirc: &[[f32; 3]],
        stage: Stage,
    ) -> Result<PointValues, NetError> {
        self.batches_in_hull(encoded, points, target_dirc, 0, |p, d| {
            let inputs = encoded.gather(p, d, stage)?.to_tensors(&self.device)?;
            let sigma = self
                .net(stage)
                .density(&inputs)?
                .flatten_all()?
                .to_vec1::<f32>()?;
            Ok((sigma, Vec::new()))
        })
    }

    /// The irradiance tensor `(3, 128)` = `light · Ω` of a network-layout light.
    pub fn irradiance(&self, light: &[f32]) -> Result<Tensor, NetError> {
        Ok(Tensor::from_vec(
            irradiance_values(light)?,
            (3, ENV_TEXELS),
            &self.device,
        )?)
    }
}

/// `light · Ω` for a network-layout light `(3, 8, 16)` (the official `target_irradiance`).
pub fn irradiance_values(light: &[f32]) -> Result<Vec<f32>, NetError> {
    if light.len() != LT_DIM {
        return Err(NetError::input(format!(
            "a light has {LT_DIM} values, got {}",
            light.len()
        )));
    }
    let omega = net_solid_angles();
    Ok(light
        .iter()
        .enumerate()
        .map(|(i, l)| l * omega[i % ENV_TEXELS])
        .collect())
}
