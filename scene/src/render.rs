//! Ground-truth images of a mesh through a pinhole camera, two independent ways:
//!
//! * [`render_lt_images`] / [`render_lt_image`]: per pixel the light-transport
//!   vector `T` of [`LtTracer::light_transport`], shaded as `radiance_c = Σ_k
//!   T[c][k] L_k[c]` under one or several 8 × 16 maps (no per-pixel storage of `T`);
//!   [`render_lt_buffer`] keeps `T` for covered pixels, for relighting later.
//! * [`render_direct_image`]: path tracing against the map itself as a piecewise
//!   constant radiance function (cosine-weighted sampling, no texel stratification;
//!   [`LtTracer::path_radiance`]). Agreement of the two checks the tracer.
//!
//! Pixel model (both renderers): colour is the mean radiance over the
//! `pixel_grid²` regularly spaced sub-pixel points whose primary rays hit the mesh
//! (when none does but the pixel is partly covered, the first covering
//! `coverage_grid²` point is used), and `alpha` is the fraction of the
//! `coverage_grid²` sub-pixel rays that hit. `rgb` is straight (not premultiplied):
//! composite as `rgb·α + background·(1 − α)`. Pixels with `α = 0` have `rgb = 0`.
//! Random streams are per pixel and colour point, so results do not depend on
//! threads.

use glam::{DVec2, Vec3};
use indicatif::ProgressBar;
use nelf_format::conventions::{ConventionError, ENV_H, ENV_W, LT_DIM, LatLong, PinholeCamera, shade};
use rayon::prelude::*;

use crate::tracer::{LtTracer, SurfacePoint, stream_rng};

/// Errors from the image renderers.
#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    /// The camera's parameters are invalid.
    #[error(transparent)]
    Camera(#[from] ConventionError),
    /// A light-transport render needs maps of the basis size.
    #[error("lighting for a light-transport render must be {ENV_W}×{ENV_H}, got {width}×{height}")]
    LightSize {
        /// Width of the offending map.
        width: usize,
        /// Height of the offending map.
        height: usize,
    },
    /// The per-pixel light-transport buffer would exceed the caller's limit.
    #[error("per-pixel light transport needs {bytes} bytes, more than the limit of {max_bytes}")]
    TooLarge {
        /// Bytes needed.
        bytes: usize,
        /// The limit given.
        max_bytes: usize,
    },
    /// A setting is out of range.
    #[error("invalid render settings: {0}")]
    Settings(String),
}

/// A rendered image: straight linear RGB radiance and coverage.
#[derive(Debug, Clone, PartialEq)]
pub struct RenderedImage {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Row-major linear RGB radiance of the object (straight alpha).
    pub rgb: Vec<[f32; 3]>,
    /// Row-major coverage in `[0, 1]`.
    pub alpha: Vec<f32>,
}

impl RenderedImage {
    /// Radiance at pixel `(u, v)`.
    pub fn pixel(&self, u: u32, v: u32) -> [f32; 3] {
        self.rgb[(v * self.width + u) as usize]
    }

    /// The image composited over a constant background, `rgb·α + bg·(1 − α)`.
    pub fn over(&self, background: [f32; 3]) -> Vec<[f32; 3]> {
        self.rgb
            .iter()
            .zip(&self.alpha)
            .map(|(c, &a)| std::array::from_fn(|i| c[i] * a + background[i] * (1.0 - a)))
            .collect()
    }
}

/// Per-pixel light-transport vectors of the covered pixels of an image.
#[derive(Debug, Clone, PartialEq)]
pub struct LtImage {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Row-major coverage.
    pub alpha: Vec<f32>,
    /// Row-major indices (`v·width + u`) of the pixels that have a vector, ascending.
    pub pixels: Vec<u32>,
    /// `pixels.len() × 384` floats: the vector of `pixels[i]` at `[i·384, (i+1)·384)`.
    pub lt: Vec<f32>,
}

impl LtImage {
    /// The vector at pixel `(u, v)`, if it is covered.
    pub fn lt_at(&self, u: u32, v: u32) -> Option<&[f32]> {
        let index = v * self.width + u;
        let i = self.pixels.binary_search(&index).ok()?;
        Some(&self.lt[i * LT_DIM..(i + 1) * LT_DIM])
    }

    /// Relights the image under an 8 × 16 map in the tracer's light frame.
    pub fn shade(&self, light: &LatLong) -> Result<RenderedImage, RenderError> {
        check_light(light)?;
        let mut rgb = vec![[0.0f32; 3]; self.alpha.len()];
        for (i, &p) in self.pixels.iter().enumerate() {
            rgb[p as usize] = shade(&self.lt[i * LT_DIM..(i + 1) * LT_DIM], light);
        }
        Ok(RenderedImage {
            width: self.width,
            height: self.height,
            rgb,
            alpha: self.alpha.clone(),
        })
    }

    /// Bytes held by the vectors.
    pub fn bytes(&self) -> usize {
        self.lt.len() * std::mem::size_of::<f32>()
    }
}

/// Settings of [`render_direct_image`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DirectSettings {
    /// Paths per pixel (split evenly over the colour points). Default 8,192.
    pub paths_per_pixel: u32,
    /// Base seed of the path streams (independent of the tracer's). Default 7.
    pub seed: u64,
}

impl Default for DirectSettings {
    fn default() -> Self {
        Self {
            paths_per_pixel: 8192,
            seed: 7,
        }
    }
}

/// The sub-pixel points of one pixel that produce colour, and its coverage.
#[derive(Debug, Clone)]
struct PixelSamples {
    coverage: f32,
    /// `(colour point index, surface point, outgoing direction)`.
    points: Vec<(u32, SurfacePoint, Vec3)>,
}

fn check_light(light: &LatLong) -> Result<(), RenderError> {
    if light.width() != ENV_W || light.height() != ENV_H {
        return Err(RenderError::LightSize {
            width: light.width(),
            height: light.height(),
        });
    }
    Ok(())
}

/// Primary rays of pixel `(u, v)`: coverage and the colour points that hit.
fn pixel_samples(tracer: &LtTracer, camera: &PinholeCamera, u: u32, v: u32) -> PixelSamples {
    let settings = tracer.settings();
    let eye = camera.centre();
    let trace = |grid: u32, i: u32, j: u32| {
        let pixel = DVec2::new(
            f64::from(u) + (f64::from(i) + 0.5) / f64::from(grid),
            f64::from(v) + (f64::from(j) + 0.5) / f64::from(grid),
        );
        let dir = camera.ray_direction(pixel);
        let origin = eye.as_vec3();
        let dir_f = dir.as_vec3();
        tracer
            .intersect(origin, dir_f)
            .map(|hit| (tracer.surface_at_hit(&hit, dir_f), -dir_f))
    };
    let cg = settings.coverage_grid;
    let mut covered = 0u32;
    let mut first_cover = None;
    for j in 0..cg {
        for i in 0..cg {
            if let Some(s) = trace(cg, i, j) {
                covered += 1;
                if first_cover.is_none() {
                    first_cover = Some(s);
                }
            }
        }
    }
    let pg = settings.pixel_grid;
    let mut points = Vec::new();
    for j in 0..pg {
        for i in 0..pg {
            if let Some((sp, wo)) = trace(pg, i, j) {
                points.push((j * pg + i, sp, wo));
            }
        }
    }
    if points.is_empty()
        && let Some((sp, wo)) = first_cover
    {
        points.push((pg * pg, sp, wo));
    }
    if covered == 0 {
        points.clear();
    }
    PixelSamples {
        coverage: covered as f32 / (cg * cg) as f32,
        points,
    }
}

/// Stream number of colour point `point` of pixel `index`.
fn stream(index: u64, point: u32) -> u64 {
    (index << 16) | u64::from(point)
}

/// Runs `per_pixel` over every pixel in parallel rows, ticking `progress` per row.
fn for_rows<T: Send>(
    camera: &PinholeCamera,
    progress: Option<&ProgressBar>,
    per_pixel: impl Fn(u32, u32) -> T + Sync,
) -> Vec<T> {
    if let Some(pb) = progress {
        pb.set_length(u64::from(camera.height));
    }
    (0..camera.height)
        .into_par_iter()
        .flat_map_iter(|v| {
            let row: Vec<T> = (0..camera.width).map(|u| per_pixel(u, v)).collect();
            if let Some(pb) = progress {
                pb.inc(1);
            }
            row
        })
        .collect()
}

/// Renders `T·L` images under several 8 × 16 maps (in the tracer's light frame) at
/// once: `T` is computed once per colour point and shaded with every map.
pub fn render_lt_images(
    tracer: &LtTracer,
    camera: &PinholeCamera,
    lights: &[LatLong],
    progress: Option<&ProgressBar>,
) -> Result<Vec<RenderedImage>, RenderError> {
    camera.validate()?;
    for light in lights {
        check_light(light)?;
    }
    let pixels = for_rows(camera, progress, |u, v| {
        let index = u64::from(v) * u64::from(camera.width) + u64::from(u);
        let samples = pixel_samples(tracer, camera, u, v);
        let mut rgb = vec![[0.0f32; 3]; lights.len()];
        if samples.points.is_empty() {
            return (samples.coverage, rgb);
        }
        let weight = 1.0 / samples.points.len() as f32;
        for (point, sp, wo) in &samples.points {
            let mut rng = stream_rng(tracer.settings().seed, stream(index, *point));
            let lt = tracer.light_transport(sp, *wo, &mut rng);
            for (out, light) in rgb.iter_mut().zip(lights) {
                let c = shade(&lt, light);
                for i in 0..3 {
                    out[i] += weight * c[i];
                }
            }
        }
        (samples.coverage, rgb)
    });
    let alpha: Vec<f32> = pixels.iter().map(|p| p.0).collect();
    Ok((0..lights.len())
        .map(|l| RenderedImage {
            width: camera.width,
            height: camera.height,
            rgb: pixels.iter().map(|p| p.1[l]).collect(),
            alpha: alpha.clone(),
        })
        .collect())
}

/// Renders the `T·L` image under one 8 × 16 map in the tracer's light frame.
pub fn render_lt_image(
    tracer: &LtTracer,
    camera: &PinholeCamera,
    light: &LatLong,
    progress: Option<&ProgressBar>,
) -> Result<RenderedImage, RenderError> {
    let mut images = render_lt_images(tracer, camera, std::slice::from_ref(light), progress)?;
    images
        .pop()
        .ok_or_else(|| RenderError::Settings("no image rendered".into()))
}

/// Per-pixel light-transport vectors (the mean over a pixel's colour points) of the
/// covered pixels, for relighting under many maps later. Costs 1,536 bytes per
/// covered pixel (a fully covered 512² image: 403 MB); errors before tracing if that
/// exceeds `max_bytes`.
pub fn render_lt_buffer(
    tracer: &LtTracer,
    camera: &PinholeCamera,
    max_bytes: usize,
    progress: Option<&ProgressBar>,
) -> Result<LtImage, RenderError> {
    camera.validate()?;
    // Coverage first (cheap: primary rays only) to size the buffer.
    let coverage: Vec<f32> = for_rows(camera, None, |u, v| pixel_samples(tracer, camera, u, v).coverage);
    let covered = coverage.iter().filter(|&&a| a > 0.0).count();
    let bytes = covered * LT_DIM * std::mem::size_of::<f32>();
    if bytes > max_bytes {
        return Err(RenderError::TooLarge { bytes, max_bytes });
    }
    let vectors = for_rows(camera, progress, |u, v| {
        let index = u64::from(v) * u64::from(camera.width) + u64::from(u);
        let samples = pixel_samples(tracer, camera, u, v);
        if samples.points.is_empty() {
            return None;
        }
        let mut acc = vec![0.0f32; LT_DIM];
        let mut omegas = [Vec3::ZERO; 1];
        for (point, sp, wo) in &samples.points {
            let mut rng = stream_rng(tracer.settings().seed, stream(index, *point));
            omegas[0] = *wo;
            tracer.light_transport_averaged(sp, &omegas, &mut rng, &mut acc);
        }
        let weight = 1.0 / samples.points.len() as f32;
        for x in &mut acc {
            *x *= weight;
        }
        Some(acc)
    });
    let mut pixels = Vec::with_capacity(covered);
    let mut lt = Vec::with_capacity(covered * LT_DIM);
    for (i, v) in vectors.into_iter().enumerate() {
        if let Some(v) = v {
            pixels.push(i as u32);
            lt.extend_from_slice(&v);
        }
    }
    Ok(LtImage {
        width: camera.width,
        height: camera.height,
        alpha: coverage,
        pixels,
        lt,
    })
}

/// Path-traces the image directly against `light` (any resolution, in the tracer's
/// light frame, piecewise constant): the independent estimator that cross-checks
/// [`render_lt_image`]. Same pixel model, bounces and BRDF as the tracer's settings.
pub fn render_direct_image(
    tracer: &LtTracer,
    camera: &PinholeCamera,
    light: &LatLong,
    settings: &DirectSettings,
    progress: Option<&ProgressBar>,
) -> Result<RenderedImage, RenderError> {
    camera.validate()?;
    if settings.paths_per_pixel == 0 {
        return Err(RenderError::Settings("paths_per_pixel must be at least 1".into()));
    }
    let pixels = for_rows(camera, progress, |u, v| {
        let index = u64::from(v) * u64::from(camera.width) + u64::from(u);
        let samples = pixel_samples(tracer, camera, u, v);
        let mut rgb = [0.0f32; 3];
        let n = samples.points.len() as u32;
        if n == 0 {
            return (samples.coverage, rgb);
        }
        let mut rng = stream_rng(settings.seed, index);
        // Paths split evenly over the colour points (rounded up).
        let paths = settings.paths_per_pixel.div_ceil(n);
        for (_, sp, wo) in &samples.points {
            let mut sum = [0.0f64; 3];
            for _ in 0..paths {
                let r = tracer.path_radiance(sp, *wo, light, &mut rng);
                for c in 0..3 {
                    sum[c] += f64::from(r[c]);
                }
            }
            let weight = 1.0 / (f64::from(paths) * f64::from(n));
            for c in 0..3 {
                rgb[c] += (sum[c] * weight) as f32;
            }
        }
        (samples.coverage, rgb)
    });
    Ok(RenderedImage {
        width: camera.width,
        height: camera.height,
        rgb: pixels.iter().map(|p| p.1).collect(),
        alpha: pixels.iter().map(|p| p.0).collect(),
    })
}
