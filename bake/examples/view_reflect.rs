//! Could a reflection-aligned lobe carry the view dependence (a measurement, not a
//! test)? Issue 17's candidates so far are bases over the outgoing direction in the
//! world frame (spherical harmonics of degree ≤ 2, lobes learned from them); a glossy
//! highlight follows the mirror direction and is too narrow for them. This fits, per
//! voxel, the model of [`nelf_render::reflection`],
//!
//! `T(x, ω_o)[c·128 + i] = T̄(x)[c·128 + i] + s_c(x) · (h_i(r) − h̄_i(x))`,
//!
//! with `T̄` the transport averaged toward the source cameras (what the asset stores
//! today), `n` the density's outward normal (central differences of the field's density,
//! 1 mm) and the scales fitted by [`nelf_bake::view::fit_reflection`] on the
//! transport toward the bake's Fibonacci sphere of directions.
//!
//! Then, per held-aside target and per lobe exponent, bakes the capture with each voxel's
//! transport taken as the model's prediction toward that target's eye and scores the
//! target, beside the usual bake (`T̄` only): the same measurement as `view_oracle`
//! (which takes the exact transport toward the eye), so the two bound and test the model.
//! (The first version of this example, commit 546fbf6, also tried `h` modulated by the
//! voxel's own transport per light texel, i.e. with visibility: it gained nothing.)
//!
//! `cargo run --release -p nelf-bake --example view_reflect -- CAPTURE_DIR [--resolution N] [--lambdas 10,20] [--grey] [--dump PATH] [--fit-normal DEG]`
//!
//! `--grey` adds, per exponent, the model with one scale for the three channels.
//! `--fit-normal DEG` fits the normal too: of the density's and twelve around it (six at
//! `DEG / 2`, six at `DEG`), the one whose lobe explains most of the residual.
//! `--dump PATH` writes, per model, what the asset would store per voxel as byte planes
//! (`PATH.<model>`: the normal's two octahedral coordinates, then the scales, 8 bits
//! each, voxels in z, y, x order), to be measured with `zstd -19` (the writer's level, its
//! byte shuffle being the planes).

use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::{Mutex, RwLock};

use glam::{DVec3, Vec3};
use nelf_bake::eval::{TruthCapture, load_truth_capture, score_view};
use nelf_bake::view::{fit_reflection, normal_candidates, sample_directions, seen_weights};
use nelf_bake::{BakeConfig, FieldBake, Progress, ViewChoice, bake_field, with_capture_job};
use nelf_format::conventions::{ENV_TEXELS, LT_DIM};
use nelf_render::ReflectionLobe;
use nelf_scene::field::{FieldError, FieldSource, ViewPolicy};
use rayon::prelude::*;

type Error = Box<dyn std::error::Error>;

/// One voxel's fit.
struct PointFit {
    sigma: f32,
    tbar: Vec<f32>,
    /// The density's outward normal.
    normal: Option<Vec3>,
    /// `s_c` per lobe, and the normal it was fitted with (the density's, or the best of
    /// the candidates around it with `--fit-normal`).
    scale: Vec<([f32; 3], Vec3)>,
}

/// The model as a field: the transport toward `current`'s eye under lobe `current.0`
/// (`None`: `T̄` only). Fits every point once, on first sight.
struct Reflect<'a> {
    inner: &'a dyn FieldSource,
    cams: Vec<Vec3>,
    /// The models tried: a lobe and whether its scale is one for all channels.
    lobes: Vec<(ReflectionLobe, bool)>,
    /// Search the normal within this many degrees of the density's (0: no search).
    normal_search_deg: f32,
    current: Mutex<(Option<usize>, Vec3)>,
    cache: RwLock<HashMap<[u32; 3], PointFit>>,
}

fn key(p: Vec3) -> [u32; 3] {
    [p.x.to_bits(), p.y.to_bits(), p.z.to_bits()]
}

impl Reflect<'_> {
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
        let dirs = sample_directions();
        let mut lt = vec![0.0f32; count * dirs.len() * LT_DIM];
        let mut dens = vec![0.0f32; count];
        self.inner
            .evaluate_directions(points, &dirs, &mut dens, &mut lt)?;
        let h = 1e-3f32;
        let probes: Vec<Vec3> = points
            .iter()
            .flat_map(|p| {
                [Vec3::X, Vec3::Y, Vec3::Z]
                    .into_iter()
                    .flat_map(move |a| [*p + a * h, *p - a * h])
            })
            .collect();
        let mut probe_sigma = vec![0.0f32; probes.len()];
        self.inner.evaluate_density(&probes, &mut probe_sigma)?;
        let eyes: Vec<DVec3> = self.cams.iter().map(|c| c.as_dvec3()).collect();
        Ok(points
            .par_iter()
            .enumerate()
            .map(|(p, x)| {
                let s = &probe_sigma[p * 6..p * 6 + 6];
                let grad = Vec3::new(s[0] - s[1], s[2] - s[3], s[4] - s[5]);
                let normal = (grad.length() > 1e-6).then(|| -grad.normalize());
                let t = &tbar[p * LT_DIM..(p + 1) * LT_DIM];
                let scale = match normal {
                    None => vec![([0.0; 3], Vec3::Z); self.lobes.len()],
                    Some(n) => {
                        let weights = seen_weights(x.as_dvec3(), n.as_dvec3(), &eyes, &dirs);
                        let residual: Vec<f32> = lt[p * dirs.len() * LT_DIM..(p + 1) * dirs.len() * LT_DIM]
                            .chunks_exact(LT_DIM)
                            .flat_map(|td| td.iter().zip(t).map(|(a, b)| a - b))
                            .collect();
                        self.lobes
                            .iter()
                            .map(|(lobe, grey)| {
                                normal_candidates(n, self.normal_search_deg)
                                    .into_iter()
                                    .map(|m| {
                                        let fit = fit_reflection(
                                            lobe, *x, m, &self.cams, &dirs, &weights, &residual, *grey,
                                        );
                                        (fit, m)
                                    })
                                    .max_by(|a, b| a.0.explained.total_cmp(&b.0.explained))
                                    .map_or(([0.0; 3], n), |(fit, m)| (fit.scales, m))
                            })
                            .collect()
                    }
                };
                PointFit {
                    sigma: sigma[p],
                    tbar: t.to_vec(),
                    normal,
                    scale,
                }
            })
            .collect())
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
            let cache = self
                .cache
                .read()
                .unwrap_or_else(std::sync::PoisonError::into_inner);
            points
                .iter()
                .copied()
                .filter(|p| !cache.contains_key(&key(*p)))
                .collect()
        };
        if !missing.is_empty() {
            let fits = self.fit(&missing)?;
            let mut cache = self
                .cache
                .write()
                .unwrap_or_else(std::sync::PoisonError::into_inner);
            for (p, f) in missing.iter().zip(fits) {
                cache.insert(key(*p), f);
            }
        }
        let (lobe, eye) = *self
            .current
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        let cache = self
            .cache
            .read()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        density
            .par_iter_mut()
            .zip(lt.par_chunks_mut(LT_DIM))
            .zip(points.par_iter())
            .for_each(|((sigma, out), p)| {
                let fit = &cache[&key(*p)];
                *sigma = fit.sigma;
                out.copy_from_slice(&fit.tbar);
                if let (Some(m), Some(_)) = (lobe, fit.normal) {
                    let (scale, n) = fit.scale[m];
                    let mean = self.lobes[m].0.mean_transport(*p, n, &self.cams);
                    let seen = self.lobes[m].0.transport((eye - *p).normalize_or_zero(), n);
                    for c in 0..3 {
                        for t in 0..ENV_TEXELS {
                            out[c * ENV_TEXELS + t] += scale[c] * (seen[t] - mean[t]);
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

/// Octahedral coordinates of a unit vector in [0, 1]² (Meyer et al. 2010).
fn octahedral(n: Vec3) -> [f32; 2] {
    let n = n / (n.x.abs() + n.y.abs() + n.z.abs()).max(1e-12);
    let (u, v) = if n.z >= 0.0 {
        (n.x, n.y)
    } else {
        ((1.0 - n.y.abs()) * n.x.signum(), (1.0 - n.x.abs()) * n.y.signum())
    };
    [0.5 * u + 0.5, 0.5 * v + 0.5]
}

/// Writes `path.<model>` per model (see `--dump`).
fn dump_planes(reflect: &Reflect<'_>, models: &[(f32, bool)], path: &std::path::Path) -> std::io::Result<()> {
    let cache = reflect
        .cache
        .read()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    let mut voxels: Vec<(&[u32; 3], &PointFit)> = cache.iter().collect();
    let coordinate = |k: &[u32; 3]| [2, 1, 0].map(|a| f32::from_bits(k[a]));
    voxels.sort_by(|a, b| {
        coordinate(a.0)
            .partial_cmp(&coordinate(b.0))
            .unwrap_or(std::cmp::Ordering::Equal)
    });
    let quantize = |x: f32| (x.clamp(0.0, 1.0) * 255.0).round() as u8;
    for (m, model) in models.iter().enumerate() {
        let channels = if model.1 { 1 } else { 3 };
        let max: Vec<f32> = (0..channels)
            .map(|c| {
                voxels
                    .iter()
                    .map(|(_, f)| f.scale[m].0[c])
                    .fold(0.0, f32::max)
                    .max(1e-30)
            })
            .collect();
        let mut planes = vec![Vec::with_capacity(voxels.len()); 2 + channels];
        for (_, fit) in &voxels {
            let oct = fit.normal.map_or([0.5, 0.5], |_| octahedral(fit.scale[m].1));
            planes[0].push(quantize(oct[0]));
            planes[1].push(quantize(oct[1]));
            for c in 0..channels {
                planes[2 + c].push(quantize(fit.scale[m].0[c] / max[c]));
            }
        }
        let file = path.with_extension(label(*model).replace(' ', "-").replace('λ', "lambda"));
        std::fs::write(&file, planes.concat())?;
        println!(
            "{}: {} voxels, {} planes",
            file.display(),
            voxels.len(),
            2 + channels
        );
    }
    Ok(())
}

/// `λ20`, `λ20 grey`.
fn label((lambda, grey): (f32, bool)) -> String {
    format!("λ{lambda}{}", if grey { " grey" } else { "" })
}

fn main() -> Result<(), Error> {
    let mut args = std::env::args().skip(1);
    let dir = PathBuf::from(args.next().ok_or(
        "usage: view_reflect CAPTURE_DIR [--resolution N] [--lambdas 10,20] [--grey] [--dump PATH]",
    )?);
    let mut resolution = 128;
    let mut lambdas = vec![10.0f32, 20.0];
    let mut grey = false;
    let mut normal_search_deg = 0.0f32;
    let mut dump: Option<PathBuf> = None;
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
            "--grey" => grey = true,
            "--fit-normal" => normal_search_deg = args.next().ok_or("--fit-normal needs degrees")?.parse()?,
            "--dump" => dump = Some(PathBuf::from(args.next().ok_or("--dump needs a path")?)),
            other => return Err(format!("unknown argument {other}").into()),
        }
    }
    let TruthCapture { capture, truth, held } = load_truth_capture(&dir)?;
    let config = BakeConfig {
        resolution,
        view_dependence: ViewChoice::Off,
        ..BakeConfig::default()
    };
    let progress = Progress::hidden();
    with_capture_job(&capture, &truth, &config, &progress, |job, prior| {
        let world_from_light = job.field.world_from_light();
        let models: Vec<(f32, bool)> = lambdas
            .iter()
            .flat_map(|&l| std::iter::once((l, false)).chain(grey.then_some((l, true))))
            .collect();
        let reflect = Reflect {
            inner: job.field,
            cams: job.cameras.iter().map(|c| c.centre().as_vec3()).collect(),
            lobes: models
                .iter()
                .map(|&(l, grey)| (ReflectionLobe::new(l, world_from_light), grey))
                .collect(),
            normal_search_deg,
            current: Mutex::new((None, Vec3::ZERO)),
            cache: RwLock::new(HashMap::new()),
        };
        let started = std::time::Instant::now();
        let mut sums = vec![0.0f64; models.len() + 1];
        for (t, camera) in held.cameras.iter().enumerate() {
            let eye = camera.centre().as_vec3();
            let mut line = vec![format!("{}:", held.names[t])];
            for m in std::iter::once(None).chain((0..models.len()).map(Some)) {
                *reflect
                    .current
                    .lock()
                    .unwrap_or_else(std::sync::PoisonError::into_inner) = (m, eye);
                let bake = FieldBake {
                    field: &reflect,
                    plan: job.plan.clone(),
                    cameras: job.cameras.clone(),
                    view_policy: ViewPolicy::TowardPoint(eye),
                    reference: job.reference.clone(),
                    provenance: job.provenance.clone(),
                    held: nelf_bake::eval::HeldAside::default(),
                    fine_field: None,
                };
                let asset = bake_field(&bake, &config, &progress, prior)?.asset;
                let (score, _) = score_view(&asset, camera, &held.envs[t], &held.images[t], "model")?;
                let label = m.map_or("T̄".to_owned(), |m| label(models[m]));
                line.push(format!("{label} {:.2}", score.psnr_db));
                sums[m.map_or(0, |m| m + 1)] += score.psnr_db;
            }
            println!("{}   ({:.0} s)", line.join(" "), started.elapsed().as_secs_f64());
        }
        let n = held.len().max(1) as f64;
        let mut line = vec![format!("mean: T̄ {:.2}", sums[0] / n)];
        for (m, model) in models.iter().enumerate() {
            line.push(format!(
                "{} {:.2} ({:+.2})",
                label(*model),
                sums[m + 1] / n,
                (sums[m + 1] - sums[0]) / n
            ));
        }
        println!("{}", line.join(" "));
        if let Some(path) = &dump {
            dump_planes(&reflect, &models, path)
                .map_err(|e| nelf_bake::BakeError::Settings(format!("dump: {e}")))?;
        }
        Ok(())
    })?;
    Ok(())
}
