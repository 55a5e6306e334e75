//! Could a reflection-aligned lobe carry the view dependence (a measurement, not a
//! test)? Issue 17's candidates so far are bases over the outgoing direction in the
//! world frame (spherical harmonics of degree ≤ 2, lobes learned from them); a glossy
//! highlight follows the mirror direction `r = reflect(−ω_o, n)` and is too narrow for
//! them. This fits, per voxel, the model
//!
//! `T(x, ω_o)[i, c] = T̄(x)[i, c] + s_c(x) · (h_i(r) − mean_cams h_i(r_cam))`
//!
//! with `h_i(r) = max(0, r·ω_i)^λ · max(0, n·ω_i) · ΔΩ_i` (a Phong lobe about the
//! mirror direction, `ω_i` light texel `i`), `T̄` the transport averaged toward the
//! source cameras (what the asset stores today), `n` the density's outward normal and
//! three scalars `s_c` per voxel fitted by weighted least squares on the transport toward
//! a Fibonacci sphere of directions (weights as the bake's view stage: the directions
//! the voxel is seen from, most near the cameras). Without visibility in `h`, the shaded
//! radiance is `s_c · (E_λ(r) − Ē_λ)` with `E_λ` the environment map prefiltered with
//! the lobe, a lookup per voxel per camera move. The variant `vis` multiplies `h_i` by
//! the voxel's own `T̄` luminance per light texel (visibility included, not cheap to
//! render) to show what visibility is worth.
//!
//! Then, per held-aside target and per model, bakes the capture with each voxel's
//! transport taken as the model's prediction toward that target's eye and scores the
//! target, beside the usual bake (`T̄` only) and the exact transport toward the eye.
//!
//! `cargo run --release -p nelf-bake --example view_reflect -- CAPTURE_DIR [--resolution N] [--lambdas 10,20]`

use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::{Mutex, RwLock};

use rayon::prelude::*;

use glam::{DVec3, Vec3};
use nelf_bake::eval::{load_held_aside, score_view};
use nelf_bake::{
    BakeConfig, CaptureLoadOptions, FieldBake, GroundTruth, Progress, ViewChoice, bake_field, load_capture,
    with_capture_job,
};
use nelf_format::conventions::{
    ENV_H, ENV_TEXELS, ENV_W, LT_DIM, col_phi_bounds, direction, row_theta_bounds, texel_center_direction,
};
use nelf_scene::field::{FieldError, FieldSource, ViewPolicy};

type Error = Box<dyn std::error::Error>;

/// Fitting directions (a Fibonacci sphere).
const FIT_DIRECTIONS: usize = 48;

/// One voxel's fit.
struct PointFit {
    sigma: f32,
    tbar: Vec<f32>,
    normal: Option<Vec3>,
    /// `s_c` per model (`models` order).
    scale: Vec<[f32; 3]>,
}

#[derive(Clone, Copy, Debug)]
struct Model {
    lambda: f32,
    visibility: bool,
}

struct Reflect<'a> {
    inner: &'a dyn FieldSource,
    cams: Vec<Vec3>,
    /// Light texels: the centre direction in the world and 3 × 3 sub-directions with
    /// their solid angles (the lobe is narrower than a texel's 22.5°).
    texels: Vec<(Vec3, Vec<(Vec3, f32)>)>,
    fit_dirs: Vec<Vec3>,
    models: Vec<Model>,
    /// `(model index or None for T̄ only, target eye)`.
    current: Mutex<(Option<usize>, Vec3)>,
    cache: RwLock<HashMap<[u32; 3], PointFit>>,
}

fn key(p: Vec3) -> [u32; 3] {
    [p.x.to_bits(), p.y.to_bits(), p.z.to_bits()]
}

fn reflect(toward_eye: Vec3, n: Vec3) -> Vec3 {
    // Mirror of ω_o about n: 2 (n·ω_o) n − ω_o.
    (2.0 * n.dot(toward_eye) * n - toward_eye).normalize_or_zero()
}

impl Reflect<'_> {
    fn lobe(&self, model: &Model, r: Vec3, n: Vec3, tbar: &[f32], out: &mut [f32; ENV_TEXELS]) {
        for (i, (centre, subs)) in self.texels.iter().enumerate() {
            // The texel's corners are within 17° of its centre; cos^λ < 1e-3 beyond 60°.
            if r.dot(*centre) < 0.2 {
                out[i] = 0.0;
                continue;
            }
            let mut h = 0.0;
            for (w, solid) in subs {
                let cos_r = r.dot(*w);
                if cos_r > 0.0 {
                    let cos_n = if model.visibility { 1.0 } else { n.dot(*w).max(0.0) };
                    h += cos_r.powf(model.lambda) * cos_n * solid;
                }
            }
            if model.visibility {
                // T̄ ∝ visibility · cos · ΔΩ already: it stands in for cos (the lobe's
                // solid-angle integral is kept, normalised by the texel's).
                let lum =
                    0.2126 * tbar[i] + 0.7152 * tbar[ENV_TEXELS + i] + 0.0722 * tbar[2 * ENV_TEXELS + i];
                let texel_solid: f32 = subs.iter().map(|(_, a)| a).sum();
                h *= lum.max(0.0) / texel_solid;
            }
            out[i] = h;
        }
    }

    /// `mean_cams h(r_cam)` at `x`.
    fn lobe_mean(&self, model: &Model, x: Vec3, n: Vec3, tbar: &[f32]) -> [f32; ENV_TEXELS] {
        let mut mean = [0.0f32; ENV_TEXELS];
        let mut one = [0.0f32; ENV_TEXELS];
        for c in &self.cams {
            let toward = (*c - x).normalize_or_zero();
            self.lobe(model, reflect(toward, n), n, tbar, &mut one);
            for (m, h) in mean.iter_mut().zip(one) {
                *m += h / self.cams.len() as f32;
            }
        }
        mean
    }

    fn fit(&self, points: &[Vec3]) -> Result<Vec<PointFit>, FieldError> {
        let count = points.len();
        let mut sigma = vec![0.0f32; count];
        let mut tbar = vec![0.0f32; count * LT_DIM];
        self.inner.evaluate(
            points,
            &ViewPolicy::AverageTowardPoints(self.cams.clone()),
            &mut sigma,
            &mut tbar,
        )?;
        let dirs = self.fit_dirs.len();
        let mut lt = vec![0.0f32; count * dirs * LT_DIM];
        let mut dens = vec![0.0f32; count];
        self.inner
            .evaluate_directions(points, &self.fit_dirs, &mut dens, &mut lt)?;
        // Outward normals from the density gradient (central differences, 1 mm).
        let h = 1e-3f32;
        let mut probes = Vec::with_capacity(count * 6);
        for p in points {
            for axis in [Vec3::X, Vec3::Y, Vec3::Z] {
                probes.push(*p + axis * h);
                probes.push(*p - axis * h);
            }
        }
        let mut probe_sigma = vec![0.0f32; probes.len()];
        self.inner.evaluate_density(&probes, &mut probe_sigma)?;
        let fits = points
            .par_iter()
            .enumerate()
            .map(|(p_index, x)| {
                let s = &probe_sigma[p_index * 6..p_index * 6 + 6];
                let grad = Vec3::new(s[0] - s[1], s[2] - s[3], s[4] - s[5]);
                let normal = (grad.length() > 1e-6).then(|| -grad.normalize());
                let t = &tbar[p_index * LT_DIM..(p_index + 1) * LT_DIM];
                let mut scale = vec![[0.0f32; 3]; self.models.len()];
                if let Some(n) = normal {
                    // Weights: seen from there, most near the cameras (the bake's view stage).
                    let cam_dirs: Vec<Vec3> =
                        self.cams.iter().map(|c| (*c - *x).normalize_or_zero()).collect();
                    let weights: Vec<f32> = self
                        .fit_dirs
                        .iter()
                        .map(|w| {
                            let near = cam_dirs
                                .iter()
                                .map(|c| (8.0 * (c.dot(*w) - 1.0)).exp())
                                .sum::<f32>()
                                / cam_dirs.len() as f32;
                            n.dot(*w).max(0.0) * (near + 0.02)
                        })
                        .collect();
                    for (m, model) in self.models.iter().enumerate() {
                        let mean = self.lobe_mean(model, *x, n, t);
                        let mut one = [0.0f32; ENV_TEXELS];
                        let (mut num, mut den) = ([0.0f64; 3], [0.0f64; 3]);
                        for (d, w) in self.fit_dirs.iter().enumerate() {
                            if weights[d] <= 0.0 {
                                continue;
                            }
                            self.lobe(model, reflect(*w, n), n, t, &mut one);
                            let sample = &lt[(p_index * dirs + d) * LT_DIM..][..LT_DIM];
                            for c in 0..3 {
                                for i in 0..ENV_TEXELS {
                                    let dh = f64::from(one[i] - mean[i]);
                                    let res = f64::from(sample[c * ENV_TEXELS + i] - t[c * ENV_TEXELS + i]);
                                    num[c] += f64::from(weights[d]) * dh * res;
                                    den[c] += f64::from(weights[d]) * dh * dh;
                                }
                            }
                        }
                        for c in 0..3 {
                            scale[m][c] = if den[c] > 0.0 {
                                (num[c] / den[c]).max(0.0) as f32
                            } else {
                                0.0
                            };
                        }
                    }
                }
                PointFit {
                    sigma: sigma[p_index],
                    tbar: t.to_vec(),
                    normal,
                    scale,
                }
            })
            .collect();
        Ok(fits)
    }
}

impl FieldSource for Reflect<'_> {
    fn evaluate(
        &self,
        points: &[Vec3],
        _view: &ViewPolicy,
        density: &mut [f32],
        lt: &mut [f32],
    ) -> Result<(), FieldError> {
        let missing: Vec<Vec3> = {
            let cache = self.cache.read().unwrap_or_else(|e| e.into_inner());
            points
                .iter()
                .copied()
                .filter(|p| !cache.contains_key(&key(*p)))
                .collect()
        };
        if !missing.is_empty() {
            let fits = self.fit(&missing)?;
            let mut cache = self.cache.write().unwrap_or_else(|e| e.into_inner());
            for (p, f) in missing.iter().zip(fits) {
                cache.insert(key(*p), f);
            }
        }
        let (model, eye) = *self.current.lock().unwrap_or_else(|e| e.into_inner());
        let cache = self.cache.read().unwrap_or_else(|e| e.into_inner());
        density
            .par_iter_mut()
            .zip(lt.par_chunks_mut(LT_DIM))
            .zip(points.par_iter())
            .for_each(|((sigma, out), p)| {
                let fit = &cache[&key(*p)];
                *sigma = fit.sigma;
                out.copy_from_slice(&fit.tbar);
                if let (Some(m), Some(n)) = (model, fit.normal) {
                    let spec = &self.models[m];
                    let mean = self.lobe_mean(spec, *p, n, &fit.tbar);
                    let mut one = [0.0f32; ENV_TEXELS];
                    self.lobe(
                        spec,
                        reflect((eye - *p).normalize_or_zero(), n),
                        n,
                        &fit.tbar,
                        &mut one,
                    );
                    for c in 0..3 {
                        for t in 0..ENV_TEXELS {
                            out[c * ENV_TEXELS + t] += fit.scale[m][c] * (one[t] - mean[t]);
                        }
                    }
                }
            });
        Ok(())
    }

    fn evaluate_density(&self, points: &[Vec3], density: &mut [f32]) -> Result<(), FieldError> {
        self.inner.evaluate_density(points, density)
    }

    fn bounds(&self) -> (Vec3, Vec3) {
        self.inner.bounds()
    }

    fn world_from_light(&self) -> glam::DMat3 {
        self.inner.world_from_light()
    }
}

fn main() -> Result<(), Error> {
    let mut args = std::env::args().skip(1);
    let dir = PathBuf::from(
        args.next()
            .ok_or("usage: view_reflect CAPTURE_DIR [--resolution N] [--lambdas 10,20]")?,
    );
    let mut resolution = 128;
    let mut lambdas = vec![10.0f32, 20.0];
    while let Some(a) = args.next() {
        match a.as_str() {
            "--resolution" => resolution = args.next().ok_or("--resolution needs a value")?.parse()?,
            "--lambdas" => {
                lambdas = args
                    .next()
                    .ok_or("--lambdas needs a value")?
                    .split(',')
                    .map(str::parse)
                    .collect::<Result<_, _>>()?;
            }
            other => return Err(format!("unknown argument {other}").into()),
        }
    }
    let capture = load_capture(&dir, &CaptureLoadOptions::default())?;
    let truth = GroundTruth::from_synth_capture(&dir)?;
    let held = load_held_aside(capture.description().ok_or("not a cameras.json capture")?, &dir)?;
    let config = BakeConfig {
        resolution,
        view_dependence: ViewChoice::Off,
        ..BakeConfig::default()
    };
    let progress = Progress::hidden();
    let mut models: Vec<Model> = lambdas
        .iter()
        .map(|&lambda| Model {
            lambda,
            visibility: false,
        })
        .collect();
    models.extend(lambdas.iter().map(|&lambda| Model {
        lambda,
        visibility: true,
    }));
    with_capture_job(&capture, &truth, &config, &progress, |job, prior| {
        let world_from_light = job.field.world_from_light();
        let texels = (0..ENV_TEXELS)
            .map(|i| {
                let (row, col) = (i / ENV_W, i % ENV_W);
                let centre = world_from_light * texel_center_direction(row, col, ENV_H, ENV_W);
                let (t0, t1) = row_theta_bounds(row, ENV_H);
                let (p0, p1) = col_phi_bounds(col, ENV_W);
                let mut subs = Vec::with_capacity(9);
                for a in 0..3 {
                    let (ta, tb) = (
                        t0 + (t1 - t0) * a as f64 / 3.0,
                        t0 + (t1 - t0) * (a + 1) as f64 / 3.0,
                    );
                    for b in 0..3 {
                        let phi = p0 + (p1 - p0) * (b as f64 + 0.5) / 3.0;
                        let solid = (p1 - p0) / 3.0 * (ta.cos() - tb.cos());
                        let d = world_from_light * direction(0.5 * (ta + tb), phi);
                        subs.push((d.as_vec3(), solid as f32));
                    }
                }
                (centre.as_vec3(), subs)
            })
            .collect();
        let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
        let fit_dirs = (0..FIT_DIRECTIONS)
            .map(|i| {
                let y = 1.0 - 2.0 * (i as f64 + 0.5) / FIT_DIRECTIONS as f64;
                let r = (1.0 - y * y).max(0.0).sqrt();
                let phi = golden * i as f64;
                DVec3::new(r * phi.cos(), y, r * phi.sin()).as_vec3()
            })
            .collect();
        let cams: Vec<Vec3> = job.cameras.iter().map(|c| c.centre().as_vec3()).collect();
        let reflect = Reflect {
            inner: job.field,
            cams,
            texels,
            fit_dirs,
            models: models.clone(),
            current: Mutex::new((None, Vec3::ZERO)),
            cache: RwLock::new(HashMap::new()),
        };
        let started = std::time::Instant::now();
        let mut sums = vec![0.0f64; models.len() + 2];
        for (t, camera) in held.cameras.iter().enumerate() {
            let eye = camera.centre().as_vec3();
            let mut line = format!("{}:", held.names[t]);
            for m in std::iter::once(None).chain((0..models.len()).map(Some)) {
                *reflect.current.lock().unwrap_or_else(|e| e.into_inner()) = (m, eye);
                let bake = FieldBake {
                    field: &reflect,
                    plan: job.plan.clone(),
                    cameras: job.cameras.clone(),
                    view_policy: ViewPolicy::TowardPoint(eye),
                    reference: job.reference.clone(),
                    provenance: job.provenance.clone(),
                    held: nelf_bake::eval::HeldAside::default(),
                };
                let asset = bake_field(&bake, &config, &progress, prior)?.asset;
                let (score, _) = score_view(&asset, camera, &held.envs[t], &held.images[t], "model")?;
                let label = m.map_or("T̄".to_owned(), |m| {
                    let model = models[m];
                    format!("λ{}{}", model.lambda, if model.visibility { "+vis" } else { "" })
                });
                line += &format!(" {label} {:.2}", score.psnr_db);
                sums[m.map_or(0, |m| m + 1)] += score.psnr_db;
            }
            println!("{line}   ({:.0} s)", started.elapsed().as_secs_f64());
        }
        let n = held.len().max(1) as f64;
        let mut line = "mean:".to_owned();
        line += &format!(" T̄ {:.2}", sums[0] / n);
        for (m, model) in models.iter().enumerate() {
            line += &format!(
                " λ{}{} {:.2} ({:+.2})",
                model.lambda,
                if model.visibility { "+vis" } else { "" },
                sums[m + 1] / n,
                (sums[m + 1] - sums[0]) / n
            );
        }
        println!("{line}");
        Ok(())
    })?;
    Ok(())
}
