//! Source views as the network takes them and the encoded state it keeps: images,
//! masks and cameras (millimetres, the network's world frame); after encoding, the
//! channel-last feature maps, dilated masks and the light estimate. Per point it
//! projects into every view, applies the visual-hull test (the official
//! `Σ_v sample_v == V` on the dilated masks, soft masks included:
//! [`crate::geometry::hull_inside`]) and gathers the network's inputs (colour,
//! latent, directions) with bilinear `grid_sample` lookups ([`crate::geometry`]).

use candle_core::{Device, Tensor};
use rayon::prelude::*;

use crate::error::NetError;
use crate::geometry::{NetCamera, Taps, hull_inside, project_normalized};
use crate::light::LightAggregation;
use crate::nelfnet::PointInputs;

/// Which per-point network (and which half of the source feature) to use.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stage {
    /// The coarse network, feature channels 0–31.
    Coarse,
    /// The fine network, feature channels 32–63.
    Fine,
}

impl Stage {
    /// First feature channel of this stage's latent, for `latent` channels per stage.
    pub fn feature_offset(self, latent: usize) -> usize {
        match self {
            Self::Coarse => 0,
            Self::Fine => latent,
        }
    }

    /// The fixtures' name of the stage.
    pub fn name(self) -> &'static str {
        match self {
            Self::Coarse => "coarse",
            Self::Fine => "fine",
        }
    }
}

/// `V ≥ 2` source views of one size, in the network's units.
#[derive(Debug, Clone)]
pub struct SourceViews {
    /// `(V, H, W, 3)` linear RGB, already multiplied by the masks.
    pub images: Vec<f32>,
    /// `(V, H, W)` masks in `[0, 1]`.
    pub masks: Vec<f32>,
    /// One camera per view (millimetres), each `width × height`.
    pub cameras: Vec<NetCamera>,
    /// Image width, a multiple of 16.
    pub width: usize,
    /// Image height, a multiple of 16.
    pub height: usize,
}

impl SourceViews {
    /// Number of views.
    pub fn views(&self) -> usize {
        self.cameras.len()
    }

    /// Checks sizes: at least 2 views, `H` and `W` positive multiples of 16, buffers
    /// and cameras matching, finite cameras.
    pub fn validate(&self) -> Result<(), NetError> {
        let (v, h, w) = (self.views(), self.height, self.width);
        if v < 2 {
            return Err(NetError::input(format!(
                "the network needs at least 2 views, got {v}"
            )));
        }
        if h == 0 || w == 0 || h % 16 != 0 || w % 16 != 0 {
            return Err(NetError::input(format!(
                "image size {w}×{h}: both must be positive multiples of 16"
            )));
        }
        if self.images.len() != v * h * w * 3 || self.masks.len() != v * h * w {
            return Err(NetError::input(format!(
                "{v} views of {w}×{h} need {} image and {} mask values, got {} and {}",
                v * h * w * 3,
                v * h * w,
                self.images.len(),
                self.masks.len()
            )));
        }
        for (i, cam) in self.cameras.iter().enumerate() {
            cam.validate()?;
            if cam.width != w || cam.height != h {
                return Err(NetError::input(format!(
                    "camera {i} is {}×{}, the images {w}×{h}",
                    cam.width, cam.height
                )));
            }
        }
        Ok(())
    }
}

/// The visual-hull test of a batch of points.
#[derive(Debug, Clone, PartialEq)]
pub struct HullTest {
    /// `(N, V, 2)`: normalised projections.
    pub pix: Vec<f32>,
    /// `(N, V)`: dilated-mask samples (`grid_sample`, zero padding).
    pub samples: Vec<f32>,
    /// `(N)`: inside the hull (`Σ_v samples == V` in `f32`, view order, as the
    /// official model; a soft mask value below 1 under a weighted neighbour
    /// excludes the point).
    pub inside: Vec<bool>,
}

/// Network inputs gathered on the host for `N` points, `V` views (row-major).
#[derive(Debug, Clone, PartialEq)]
pub struct HostPointInputs {
    /// Points.
    pub points: usize,
    /// Views.
    pub views: usize,
    /// `(N, V, 3)`.
    pub source_rgb: Vec<f32>,
    /// `(N, V, 32)`.
    pub latent: Vec<f32>,
    /// `(N, V, 3)`.
    pub source_dirc: Vec<f32>,
    /// `(N, 3)`.
    pub target_dirc: Vec<f32>,
}

impl HostPointInputs {
    /// Uploads to `device`.
    pub fn to_tensors(&self, device: &Device) -> Result<PointInputs, NetError> {
        let (n, v) = (self.points, self.views);
        let latent = self.latent.len() / (n * v).max(1);
        Ok(PointInputs {
            source_rgb: Tensor::from_slice(&self.source_rgb, (n, v, 3), device)?,
            latent: Tensor::from_slice(&self.latent, (n, v, latent), device)?,
            source_dirc: Tensor::from_slice(&self.source_dirc, (n, v, 3), device)?,
            target_dirc: Tensor::from_slice(&self.target_dirc, (n, 3), device)?,
        })
    }
}

/// What a differentiable gather needs for `N` points, `V` views: the inputs that
/// do not depend on the network (colours, directions) and the bilinear taps of each
/// point's projection into the feature maps, so that the latent can be gathered
/// from a feature tensor that carries gradients (`Σ_k w_k · rows[index_k]`).
#[derive(Debug, Clone, PartialEq)]
pub struct FeatureTaps {
    /// `(N, V, 3)`: source colours at the projections.
    pub source_rgb: Vec<f32>,
    /// `(N, V, 3)`: unit directions from each point to each source camera.
    pub source_dirc: Vec<f32>,
    /// `(4, N·V)`: rows of the `(V·H/2·W/2, F)` feature matrix (view-major,
    /// channel-last), tap-major.
    pub rows: [Vec<u32>; 4],
    /// `(4, N·V)`: the taps' bilinear weights (0 outside the map: zero padding).
    pub weights: [Vec<f32>; 4],
}

/// Encoded source views: what the per-point networks read.
#[derive(Debug, Clone)]
pub struct EncodedViews {
    pub(crate) width: usize,
    pub(crate) height: usize,
    pub(crate) cameras: Vec<NetCamera>,
    pub(crate) projections: Vec<[[f32; 4]; 3]>,
    pub(crate) centres: Vec<[f32; 3]>,
    /// `(V, H, W, 3)`.
    pub(crate) images: Vec<f32>,
    /// `(V, H, W)`.
    pub(crate) masks_dilated: Vec<f32>,
    /// `(V, H/2, W/2, F)`, channel-last.
    pub(crate) features: Vec<f32>,
    /// `F`, channels of the source feature (both stages' latents).
    pub(crate) feature_channels: usize,
    pub(crate) light: LightAggregation,
}

impl EncodedViews {
    /// Number of views.
    pub fn views(&self) -> usize {
        self.cameras.len()
    }

    /// The geometry of `views` without encoding them (no features, no light
    /// estimate): for the hull test and [`EncodedViews::gather_taps`] while training,
    /// where the encoder runs on a graph of its own.
    pub fn geometry_only(views: &SourceViews) -> Result<Self, NetError> {
        views.validate()?;
        let (w, h) = (views.width, views.height);
        Ok(Self {
            width: w,
            height: h,
            cameras: views.cameras.clone(),
            projections: views.cameras.iter().map(NetCamera::projection).collect(),
            centres: views.cameras.iter().map(NetCamera::centre).collect(),
            images: views.images.clone(),
            masks_dilated: crate::geometry::dilate_masks(&views.masks, w, h),
            features: Vec::new(),
            feature_channels: 0,
            light: LightAggregation {
                sample_grid: Vec::new(),
                feature_reshaped: Vec::new(),
                aligned: Vec::new(),
                confidence_norm: Vec::new(),
                source_light: Vec::new(),
            },
        })
    }

    /// The host-side inputs of `points` (mm) and their taps into the feature maps
    /// (half resolution), as [`EncodedViews::gather`] computes them.
    pub fn gather_taps(&self, points: &[[f32; 3]]) -> FeatureTaps {
        let (n, v) = (points.len(), self.views());
        let (w, h) = (self.width, self.height);
        let (fw, fh) = (w / 2, h / 2);
        let mut source_rgb = vec![0.0f32; n * v * 3];
        let mut source_dirc = vec![0.0f32; n * v * 3];
        let mut taps = vec![Taps::NONE; n * v];
        source_rgb
            .par_chunks_mut(v * 3)
            .zip(source_dirc.par_chunks_mut(v * 3))
            .zip(taps.par_chunks_mut(v))
            .zip(points.par_iter())
            .for_each(|(((rgb, dirc), tap), x)| {
                for view in 0..v {
                    let g = project_normalized(&self.projections[view], w, h, *x);
                    let image = &self.images[view * w * h * 3..(view + 1) * w * h * 3];
                    Taps::bilinear(g[0], g[1], w, h).sample_into(image, &mut rgb[view * 3..view * 3 + 3]);
                    let mut t = Taps::bilinear(g[0], g[1], fw, fh);
                    for index in &mut t.index {
                        *index += (view * fw * fh) as u32;
                    }
                    tap[view] = t;
                    let c = self.centres[view];
                    let d = [c[0] - x[0], c[1] - x[1], c[2] - x[2]];
                    let norm = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt().max(1e-12);
                    for k in 0..3 {
                        dirc[view * 3 + k] = d[k] / norm;
                    }
                }
            });
        let rows = std::array::from_fn(|k| taps.iter().map(|t| t.index[k]).collect());
        let weights = std::array::from_fn(|k| taps.iter().map(|t| t.weight[k]).collect());
        FeatureTaps {
            source_rgb,
            source_dirc,
            rows,
            weights,
        }
    }

    /// Image size `(width, height)`.
    pub fn size(&self) -> (usize, usize) {
        (self.width, self.height)
    }

    /// The cameras (millimetres).
    pub fn cameras(&self) -> &[NetCamera] {
        &self.cameras
    }

    /// Camera centres `−Rᵀt` (millimetres).
    pub fn camera_centres(&self) -> &[[f32; 3]] {
        &self.centres
    }

    /// Dilated masks `(V, H, W)`.
    pub fn masks_dilated(&self) -> &[f32] {
        &self.masks_dilated
    }

    /// The light aggregation, with the source light estimate (network layout).
    pub fn light(&self) -> &LightAggregation {
        &self.light
    }

    /// Whether `x` (mm) is inside the visual hull, writing the projections and mask samples.
    fn hull_one(&self, x: [f32; 3], pix: &mut [f32], samples: &mut [f32]) -> bool {
        let plane = self.width * self.height;
        for (v, proj) in self.projections.iter().enumerate() {
            let g = project_normalized(proj, self.width, self.height, x);
            pix[2 * v] = g[0];
            pix[2 * v + 1] = g[1];
            let taps = Taps::bilinear(g[0], g[1], self.width, self.height);
            let s = taps.sample_scalar(&self.masks_dilated[v * plane..(v + 1) * plane]);
            samples[v] = s;
        }
        hull_inside(samples)
    }

    /// Whether `x` (mm) is inside the visual hull.
    pub fn in_hull(&self, x: [f32; 3]) -> bool {
        let v = self.views();
        let mut pix = vec![0.0f32; 2 * v];
        let mut samples = vec![0.0f32; v];
        self.hull_one(x, &mut pix, &mut samples)
    }

    /// Projections, mask samples and the hull test of every point (mm).
    pub fn hull(&self, points: &[[f32; 3]]) -> HullTest {
        let v = self.views();
        let mut pix = vec![0.0f32; points.len() * v * 2];
        let mut samples = vec![0.0f32; points.len() * v];
        let mut inside = vec![false; points.len()];
        pix.par_chunks_mut(2 * v)
            .zip(samples.par_chunks_mut(v))
            .zip(inside.par_iter_mut())
            .zip(points.par_iter())
            .for_each(|(((p, s), i), x)| *i = self.hull_one(*x, p, s));
        HullTest { pix, samples, inside }
    }

    /// Gathers the network inputs of `points` (mm) seen from unit directions
    /// `target_dirc` (point → target camera), for `stage`. No hull test.
    pub fn gather(
        &self,
        points: &[[f32; 3]],
        target_dirc: &[[f32; 3]],
        stage: Stage,
    ) -> Result<HostPointInputs, NetError> {
        if points.len() != target_dirc.len() {
            return Err(NetError::input(format!(
                "{} points and {} target directions",
                points.len(),
                target_dirc.len()
            )));
        }
        let (n, v) = (points.len(), self.views());
        let channels = self.feature_channels;
        let latent_channels = channels / 2;
        let offset = stage.feature_offset(latent_channels);
        // The taps of the differentiable gather, applied to the host feature maps
        // (channel-last rows; the same sums, in the same order, as `Taps::sample_into`).
        let taps = self.gather_taps(points);
        let mut latent = vec![0.0f32; n * v * latent_channels];
        latent
            .par_chunks_mut(latent_channels)
            .enumerate()
            .for_each(|(i, lat)| {
                for (rows, weights) in taps.rows.iter().zip(&taps.weights) {
                    let w = weights[i];
                    if w != 0.0 {
                        let base = rows[i] as usize * channels + offset;
                        for (o, x) in lat.iter_mut().zip(&self.features[base..base + latent_channels]) {
                            *o += w * x;
                        }
                    }
                }
            });
        let FeatureTaps {
            source_rgb,
            source_dirc,
            ..
        } = taps;
        Ok(HostPointInputs {
            points: n,
            views: v,
            source_rgb,
            latent,
            source_dirc,
            target_dirc: target_dirc.iter().flatten().copied().collect(),
        })
    }
}
