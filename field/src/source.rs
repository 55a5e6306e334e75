//! The NeLF network as the baker's field source ([`FieldSource`]): density and the
//! 384-vector of light transport at any points of our world.
//!
//! * **Units and frames**: points (metres, our world) go to the network as
//!   `1000 · net_from_world · x` ([`crate::capture`]); σ comes back in 1/mm and is
//!   multiplied by 1000 (1/m); light transport is dimensionless.
//! * **Light frame**: the network's 8 × 16 texels are exactly our texels in the
//!   light frame `world_from_light = R₀ᵀ·diag(−1, −1, 1)` with columns reversed
//!   ([`crate::light`]): no resampling. The network's solid angles
//!   (`sin θ · 2π²/128`) are folded into `T`, so `T·L` reproduces the network's own
//!   rendering exactly.
//! * **View dependence**: the network's σ and `T` depend on the target direction
//!   (through its direction MLP and the view blending); a baked voxel stores one.
//!   The [`ViewPolicy`] names the directions (our world, point → viewer); with
//!   several, σ and `T` are their means. [`NelfField::recommended_view_policy`] is
//!   the policy chosen by measurement (`field/README.md`).
//! * **Pruning**: outside the visual hull of the dilated masks σ = 0 and `T` = 0,
//!   as in the official renderer; [`FieldSource::bounds`] is the hull's box.
//! * **Throughput**: batches of [`crate::NelfConfig::batch_points`] run in parallel
//!   on all cores; memory is bounded by [`NelfField::chunk_points`] points at a time.

use glam::{DMat3, DVec3, Vec3};
use indicatif::ProgressBar;
use nelf_format::conventions::{LT_DIM, LatLong};
use nelf_scene::field::{FieldError, FieldSource, ViewPolicy, check_batch, check_density_batch};
use nelf_scene::tracer::MAX_AVERAGED_DIRECTIONS;

use crate::capture::{MM_PER_M, NetCapture};
use crate::error::NetError;
use crate::light::{latlong_to_net_light, net_light_to_latlong, net_to_ours};
use crate::model::Model;
use crate::views::{EncodedViews, Stage};

/// Cells per side of the grid that finds the hull's bounding box.
const BOUNDS_GRID: usize = 96;

/// The NeLF network over one capture, as a [`FieldSource`].
#[derive(Debug)]
pub struct NelfField {
    model: Model,
    encoded: EncodedViews,
    net_from_world: DMat3,
    world_from_light: DMat3,
    head_centre_m: DVec3,
    camera_centres_m: Vec<DVec3>,
    bounds: (Vec3, Vec3),
    stage: Stage,
    chunk_points: usize,
    /// `1/p_S` for a source-relative network told the source power, else 1.
    light_unit_scale: f32,
    /// The source-view calibration's gain ([`NelfField::calibrated_to_sources`]), else 1.
    source_gain: f32,
    /// `(V, H, W)` the source views' masks (the encoded views keep only dilated
    /// ones), for the calibration.
    source_masks: Vec<f32>,
}

impl NelfField {
    /// Encodes the capture's views and finds the hull's bounds.
    pub fn new(model: Model, capture: &NetCapture) -> Result<Self, NetError> {
        let encoded = model.encode(&capture.views)?;
        Self::from_encoded(model, encoded, capture)
    }

    /// A field over views `capture` already encoded by `model` (`encoded`).
    pub fn from_encoded(model: Model, encoded: EncodedViews, capture: &NetCapture) -> Result<Self, NetError> {
        if encoded.views() != capture.cameras.len() {
            return Err(NetError::input("the encoded views are not the capture's"));
        }
        let mut field = Self {
            model,
            encoded,
            net_from_world: capture.net_from_world,
            world_from_light: capture.world_from_light(),
            head_centre_m: capture.head_centre_m,
            camera_centres_m: capture
                .cameras
                .iter()
                .map(nelf_format::conventions::PinholeCamera::centre)
                .collect(),
            bounds: (Vec3::ZERO, Vec3::ZERO),
            stage: Stage::Fine,
            chunk_points: 16_384,
            light_unit_scale: 1.0,
            source_gain: 1.0,
            source_masks: capture.views.masks.clone(),
        };
        field.bounds = field.hull_bounds();
        Ok(field)
    }

    /// Evaluates with `stage`'s network (default: fine, as the final render).
    #[must_use]
    pub fn with_stage(mut self, stage: Stage) -> Self {
        self.stage = stage;
        self
    }

    /// Bounds memory: at most `points` are evaluated at a time (default 16384).
    #[must_use]
    pub fn with_chunk_points(mut self, points: usize) -> Self {
        self.chunk_points = points.max(1);
        self
    }

    /// Tells a field whose network takes source-relative lightings
    /// ([`Model::source_relative_light`]) the mean radiance `p_S` of the capture's
    /// source lighting (`Σ Ω L / 4π`, known for a synthetic or calibrated capture):
    /// its light transport is then divided by `p_S`, into physical units. A network
    /// in absolute units ignores it. Without it a source-relative field's `T` is
    /// `T·p_S`: relit under a map of mean radiance 1 it is as bright as the capture.
    ///
    /// # Errors
    /// `p_S` must be finite and positive.
    pub fn with_source_light_power(mut self, mean_radiance: f64) -> Result<Self, NetError> {
        if !(mean_radiance.is_finite() && mean_radiance > 0.0) {
            return Err(NetError::input(format!(
                "the source lighting's mean radiance {mean_radiance} is not a positive number"
            )));
        }
        if self.model.source_relative_light() {
            self.light_unit_scale = (1.0 / mean_radiance) as f32;
        }
        Ok(self)
    }

    /// This field with its light transport multiplied by the gain that makes the
    /// network reproduce its own source views under `source_light`, the lighting they
    /// were taken in (8 × 16, this field's light frame, physical units), with the
    /// fit ([`crate::calibrate`]). Call it after [`NelfField::with_source_light_power`].
    ///
    /// # Errors
    /// Rendering errors, or source masks with too few pixels fully inside.
    pub fn calibrated_to_sources(
        mut self,
        source_light: &LatLong,
    ) -> Result<(Self, crate::calibrate::SourceGain), NetError> {
        self.source_gain = 1.0;
        let light = self.net_light(source_light)?;
        let head_centre_mm = (self.net_from_world * self.head_centre_m * MM_PER_M)
            .as_vec3()
            .to_array();
        let fit = crate::calibrate::source_view_gain(
            &self.model,
            &self.encoded,
            &self.source_masks,
            &light,
            head_centre_mm,
        )?;
        self.source_gain = fit.gain;
        Ok((self, fit))
    }

    /// This field with every view's light transport normalised, point by point, to
    /// `source_light` (8 × 16, this field's light frame, physical units), the lighting
    /// the views were taken in ([`Model::with_source_normalisation`]), and with the
    /// Lambertian shading `prior` mixed in ([`crate::prior`]): the network then
    /// reproduces its source colours exactly under that lighting, its transport is in
    /// physical units (no source power, no gain), and it keeps only the shape of its
    /// transport over the 128 directions. Replaces [`NelfField::calibrated_to_sources`].
    ///
    /// # Errors
    /// A source lighting that is not 8 × 16, or a prior out of range.
    pub fn normalised_to_sources(
        mut self,
        source_light: &LatLong,
        prior: Option<crate::prior::ShadingPrior>,
    ) -> Result<Self, NetError> {
        let light = latlong_to_net_light(source_light)?;
        self.model = self
            .model
            .with_source_normalisation(Some(&light))?
            .with_shading_prior(prior)?;
        self.source_gain = 1.0;
        Ok(self)
    }

    /// The factor this field applies to the network's light transport: `1/p_S` after
    /// [`NelfField::with_source_light_power`] (else 1) times the source-view gain after
    /// [`NelfField::calibrated_to_sources`] (else 1); 1 after
    /// [`NelfField::normalised_to_sources`].
    pub fn light_transport_scale(&self) -> f32 {
        // Normalised to the source lighting, the transport is in physical units as it is.
        if self.model.source_normalised() {
            1.0
        } else {
            self.light_unit_scale * self.source_gain
        }
    }

    /// The source-view calibration's gain (1 when not calibrated).
    pub fn source_gain(&self) -> f32 {
        self.source_gain
    }

    /// `light` (8 × 16, this field's light frame) in the network's layout and units,
    /// for renderers that drive the network directly: the light transport scale folded
    /// in, so that they render what this field bakes.
    pub fn net_light(&self, light: &LatLong) -> Result<Vec<f32>, NetError> {
        Ok(latlong_to_net_light(light)?
            .into_iter()
            .map(|v| v * self.light_transport_scale())
            .collect())
    }

    /// Points evaluated at a time.
    pub fn chunk_points(&self) -> usize {
        self.chunk_points
    }

    /// The model.
    pub fn model(&self) -> &Model {
        &self.model
    }

    /// The encoded views.
    pub fn encoded(&self) -> &EncodedViews {
        &self.encoded
    }

    /// The head centre, metres.
    pub fn head_centre_m(&self) -> DVec3 {
        self.head_centre_m
    }

    /// The source cameras' centres, metres.
    pub fn camera_centres_m(&self) -> &[DVec3] {
        &self.camera_centres_m
    }

    /// The network's estimate of the capture's lighting: an 8 × 16 map of radiance
    /// in this field's light frame ([`FieldSource::world_from_light`]).
    /// A source-relative network's estimate has mean radiance near 1 unless the field
    /// knows the source power ([`NelfField::with_source_light_power`]).
    pub fn source_light(&self) -> Result<LatLong, NetError> {
        let unit = 1.0 / self.light_unit_scale;
        let light: Vec<f32> = self
            .encoded
            .light()
            .source_light
            .iter()
            .map(|v| v * unit)
            .collect();
        net_light_to_latlong(&light)
    }

    /// The policy chosen by measuring baked-vs-direct PSNR (`field/README.md`,
    /// "View policy"): `T` toward the mean of the source cameras' centres. It baked
    /// as well as the mean over the directions toward every camera and as the
    /// oracle (toward each novel view's own camera), at a fifth of the cost of the
    /// average for five views.
    pub fn recommended_view_policy(&self) -> ViewPolicy {
        let n = self.camera_centres_m.len().max(1) as f64;
        let mean = self.camera_centres_m.iter().copied().sum::<DVec3>() / n;
        ViewPolicy::TowardPoint(mean.as_vec3())
    }

    /// The mean over the directions toward every source camera (at most 64), the
    /// alternative measured against [`NelfField::recommended_view_policy`].
    pub fn average_cameras_view_policy(&self) -> ViewPolicy {
        ViewPolicy::AverageTowardPoints(
            self.camera_centres_m
                .iter()
                .take(MAX_AVERAGED_DIRECTIONS)
                .map(|c| c.as_vec3())
                .collect(),
        )
    }

    /// A point of our world in the network's (mm).
    fn to_net(&self, p: Vec3) -> [f32; 3] {
        (self.net_from_world * p.as_dvec3() * MM_PER_M)
            .as_vec3()
            .to_array()
    }

    /// Unit direction toward the mean source camera from `x`: where a policy's
    /// direction is undefined.
    fn fallback_direction(&self, x: Vec3) -> Vec3 {
        let n = self.camera_centres_m.len().max(1) as f64;
        let mean = self.camera_centres_m.iter().copied().sum::<DVec3>() / n;
        (mean.as_vec3() - x).normalize_or(Vec3::Z)
    }

    /// The box of the visual hull inside the sphere the renderer samples (the head
    /// radius around the head centre), grown by one cell of a 96³ search grid.
    fn hull_bounds(&self) -> (Vec3, Vec3) {
        let radius_m = f64::from(self.model.config().head_radius_mm) / MM_PER_M;
        let cell = 2.0 * radius_m / BOUNDS_GRID as f64;
        let origin = self.head_centre_m - DVec3::splat(radius_m);
        let centres: Vec<DVec3> = (0..BOUNDS_GRID.pow(3))
            .map(|i| {
                let (x, y, z) = (
                    i % BOUNDS_GRID,
                    (i / BOUNDS_GRID) % BOUNDS_GRID,
                    i / BOUNDS_GRID.pow(2),
                );
                origin + (DVec3::new(x as f64, y as f64, z as f64) + 0.5) * cell
            })
            .collect();
        let net: Vec<[f32; 3]> = centres.iter().map(|p| self.to_net(p.as_vec3())).collect();
        let inside = self.encoded.hull(&net).inside;
        let mut lo = DVec3::splat(f64::INFINITY);
        let mut hi = DVec3::splat(f64::NEG_INFINITY);
        for (p, _) in centres.iter().zip(&inside).filter(|(_, i)| **i) {
            lo = lo.min(*p);
            hi = hi.max(*p);
        }
        if lo.x > hi.x {
            let c = self.head_centre_m.as_vec3();
            return (c, c);
        }
        ((lo - cell).as_vec3(), (hi + cell).as_vec3())
    }

    /// The network-frame target directions of `points` for each of the policy's
    /// directions: `count` lists of `points.len()`.
    fn target_directions(&self, points: &[Vec3], view: &ViewPolicy) -> Vec<Vec<[f32; 3]>> {
        let mut lists: Vec<Vec<[f32; 3]>> = Vec::new();
        let mut omegas = [Vec3::ZERO; MAX_AVERAGED_DIRECTIONS];
        for (i, x) in points.iter().enumerate() {
            let count = view.directions_at(*x, self.fallback_direction(*x), &mut omegas);
            if i == 0 {
                lists = vec![Vec::with_capacity(points.len()); count];
            }
            for (list, w) in lists.iter_mut().zip(&omegas[..count]) {
                let d = (self.net_from_world * w.as_dvec3()).normalize_or(DVec3::Z);
                list.push(d.as_vec3().to_array());
            }
        }
        lists
    }

    /// [`FieldSource::evaluate`] with an optional progress bar (length set to the
    /// number of points, ticked per chunk).
    pub fn evaluate_with_progress(
        &self,
        points: &[Vec3],
        view: &ViewPolicy,
        density: &mut [f32],
        lt: &mut [f32],
        progress: Option<&ProgressBar>,
    ) -> Result<(), FieldError> {
        check_batch(points, density, lt)?;
        view.validate()?;
        if let Some(pb) = progress {
            pb.set_length(points.len() as u64);
        }
        let chunk = self.chunk_points;
        for ((p, d), t) in points
            .chunks(chunk)
            .zip(density.chunks_mut(chunk))
            .zip(lt.chunks_mut(chunk * LT_DIM))
        {
            let net: Vec<[f32; 3]> = p.iter().map(|x| self.to_net(*x)).collect();
            let directions = self.target_directions(p, view);
            let scale = 1.0 / directions.len().max(1) as f32;
            let lt_scale = scale * self.light_transport_scale();
            d.fill(0.0);
            t.fill(0.0);
            for dirs in &directions {
                let values = self
                    .model
                    .light_transport_points(&self.encoded, &net, dirs, self.stage)?;
                let mut ours = vec![0.0f32; LT_DIM];
                for (i, (sigma, out)) in d.iter_mut().zip(t.chunks_mut(LT_DIM)).enumerate() {
                    if !values.inside[i] {
                        continue;
                    }
                    *sigma += scale * values.sigma[i] * MM_PER_M as f32;
                    net_to_ours(&values.values[i * LT_DIM..(i + 1) * LT_DIM], &mut ours);
                    for (o, v) in out.iter_mut().zip(&ours) {
                        *o += lt_scale * v;
                    }
                }
            }
            if let Some(pb) = progress {
                pb.inc(p.len() as u64);
            }
        }
        Ok(())
    }
}

impl FieldSource for NelfField {
    fn evaluate(
        &self,
        points: &[Vec3],
        view: &ViewPolicy,
        density: &mut [f32],
        lt: &mut [f32],
    ) -> Result<(), FieldError> {
        self.evaluate_with_progress(points, view, density, lt, None)
    }

    fn bounds(&self) -> (Vec3, Vec3) {
        self.bounds
    }

    fn world_from_light(&self) -> DMat3 {
        self.world_from_light
    }

    /// σ under [`NelfField::recommended_view_policy`] (the mean over its
    /// directions if it has several), without the light-transport network.
    fn evaluate_density(&self, points: &[Vec3], density: &mut [f32]) -> Result<(), FieldError> {
        check_density_batch(points, density)?;
        let view = self.recommended_view_policy();
        for (p, d) in points
            .chunks(self.chunk_points)
            .zip(density.chunks_mut(self.chunk_points))
        {
            let net: Vec<[f32; 3]> = p.iter().map(|x| self.to_net(*x)).collect();
            let directions = self.target_directions(p, &view);
            let scale = MM_PER_M as f32 / directions.len().max(1) as f32;
            d.fill(0.0);
            for dirs in &directions {
                let values = self.model.density_points(&self.encoded, &net, dirs, self.stage)?;
                for (o, s) in d.iter_mut().zip(&values.sigma) {
                    *o += scale * s;
                }
            }
        }
        Ok(())
    }
}
