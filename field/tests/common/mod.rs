//! Shared parity checks against the official NeLF fixtures (see `parity.rs`).
#![allow(clippy::unwrap_used, dead_code)] // Test helpers unwrap; not every test binary uses every helper.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use candle_core::{DType, Device, Tensor};
use nelf_field::geometry::{NetCamera, hull_inside};
use nelf_field::light::{net_solid_angles, net_texel_direction};
use nelf_field::model::irradiance_values;
use nelf_field::nelfnet::NelfNet;
use nelf_field::render::{NetRay, RayUniforms, render_rays};
use nelf_field::{EncodedViews, Model, NelfConfig, SourceViews, Stage, read_safetensors_bytes};

/// The official fixture kept in the repository (zstd-compressed safetensors).
const DEFAULT_DIR: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../data/nelf-oracle");

/// The case name of a fixture file: `io_seed0.safetensors[.zst]` → `seed0.safetensors[.zst]`
/// for `prefix` `io_`, or `None` for other files.
fn case_of(path: &Path, prefix: &str) -> Option<String> {
    let name = path.file_name()?.to_str()?;
    let case = name.strip_prefix(prefix)?;
    (case.ends_with(".safetensors") || case.ends_with(".safetensors.zst")).then(|| case.to_string())
}

/// `(io file, weights file)` pairs to check: the repository's fixture folder, or the
/// folders and files `NELF_ORACLE_FIXTURES` names (`:`-separated). Missing data fails.
pub fn fixture_pairs() -> Vec<(PathBuf, PathBuf)> {
    let io_files: Vec<PathBuf> = if let Some(spec) = std::env::var_os("NELF_ORACLE_FIXTURES") {
        let spec = spec.to_string_lossy().to_string();
        let mut files = Vec::new();
        for part in spec.split(':').filter(|s| !s.is_empty()) {
            let p = PathBuf::from(part);
            if p.is_dir() {
                files.extend(io_files_in(&p));
            } else {
                assert!(
                    p.is_file(),
                    "NELF_ORACLE_FIXTURES names {}, which does not exist",
                    p.display()
                );
                files.push(p);
            }
        }
        assert!(
            !files.is_empty(),
            "NELF_ORACLE_FIXTURES={spec} names no io_*.safetensors[.zst]"
        );
        files
    } else {
        let dir = Path::new(DEFAULT_DIR);
        assert!(
            dir.is_dir(),
            "the parity fixtures are missing: no folder {DEFAULT_DIR} (it is part of the repository)"
        );
        let files = io_files_in(dir);
        assert!(!files.is_empty(), "{DEFAULT_DIR} holds no io_*.safetensors[.zst]");
        files
    };
    io_files
        .into_iter()
        .map(|io| {
            let case = case_of(&io, "io_")
                .unwrap_or_else(|| panic!("{} is not named io_<case>.safetensors[.zst]", io.display()));
            let stem = case.trim_end_matches(".zst");
            let weights = [format!("fixture_{stem}"), format!("fixture_{stem}.zst")]
                .into_iter()
                .map(|name| io.with_file_name(name))
                .find(|p| p.is_file())
                .unwrap_or_else(|| {
                    panic!(
                        "{} has no weights file fixture_{stem}[.zst] beside it",
                        io.display()
                    )
                });
            (io, weights)
        })
        .collect()
}

fn io_files_in(dir: &Path) -> Vec<PathBuf> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap_or_else(|e| panic!("cannot list {}: {e}", dir.display()))
        .map(|e| e.unwrap().path())
        .filter(|p| case_of(p, "io_").is_some())
        .collect();
    files.sort();
    files
}

pub struct Fixture {
    name: String,
    io: HashMap<String, Tensor>,
    model: Model,
}

impl Fixture {
    pub fn load(io: &Path, weights: &Path) -> Self {
        let device = Device::Cpu;
        Self {
            name: io.file_name().unwrap().to_string_lossy().to_string(),
            io: candle_core::safetensors::load_buffer(&read_safetensors_bytes(io).unwrap(), &device).unwrap(),
            model: Model::load(weights, NelfConfig::default(), &device).unwrap(),
        }
    }

    fn tensor(&self, name: &str) -> &Tensor {
        self.io
            .get(name)
            .unwrap_or_else(|| panic!("{}: no tensor {name}", self.name))
    }

    fn f32s(&self, name: &str) -> Vec<f32> {
        self.tensor(name)
            .to_dtype(DType::F32)
            .unwrap()
            .flatten_all()
            .unwrap()
            .to_vec1::<f32>()
            .unwrap()
    }

    fn dims(&self, name: &str) -> Vec<usize> {
        self.tensor(name).dims().to_vec()
    }

    /// Asserts `got` matches tensor `name` (same element count) within `atol + rtol·|want|`.
    fn check(&self, name: &str, got: &[f32], atol: f32, rtol: f32) {
        let want = self.f32s(name);
        assert_eq!(
            got.len(),
            want.len(),
            "{}: {name}: {} values, want {}",
            self.name,
            got.len(),
            want.len()
        );
        let mut worst = (0usize, 0.0f32);
        for (i, (g, w)) in got.iter().zip(&want).enumerate() {
            let err = (g - w).abs();
            let excess = err - (atol + rtol * w.abs());
            assert!(g.is_finite(), "{}: {name}[{i}] = {g}", self.name);
            if excess > worst.1 {
                worst = (i, excess);
            }
        }
        let max_err = got
            .iter()
            .zip(&want)
            .map(|(g, w)| (g - w).abs())
            .fold(0.0f32, f32::max);
        assert!(
            worst.1 <= 0.0,
            "{}: {name}: element {} is {} vs {} (max |err| {max_err:e}, atol {atol:e}, rtol {rtol:e})",
            self.name,
            worst.0,
            got[worst.0],
            want[worst.0]
        );
        eprintln!("{}: {name}: max |err| {max_err:.3e}", self.name);
    }

    fn check_tensor(&self, name: &str, got: &Tensor, atol: f32, rtol: f32) {
        assert_eq!(
            got.dims(),
            self.dims(name).as_slice(),
            "{}: {name} shape",
            self.name
        );
        self.check(
            name,
            &got.flatten_all().unwrap().to_vec1::<f32>().unwrap(),
            atol,
            rtol,
        );
    }

    fn camera(intrinsic: &[f32], extrinsic: &[f32], width: usize, height: usize) -> NetCamera {
        NetCamera {
            intrinsic: std::array::from_fn(|r| std::array::from_fn(|c| intrinsic[r * 3 + c])),
            extrinsic: std::array::from_fn(|r| std::array::from_fn(|c| extrinsic[r * 4 + c])),
            width,
            height,
        }
    }

    fn source_views(&self) -> SourceViews {
        let dims = self.dims("input.source_images");
        let (v, h, w) = (dims[0], dims[1], dims[2]);
        let shape = self
            .tensor("input.source_shape")
            .to_dtype(DType::I64)
            .unwrap()
            .flatten_all()
            .unwrap()
            .to_vec1::<i64>()
            .unwrap();
        assert!(
            shape.chunks(2).all(|s| s == [h as i64, w as i64]),
            "{}: source_shape",
            self.name
        );
        let k = self.f32s("input.source_intrinsics");
        let e = self.f32s("input.source_extrinsics");
        SourceViews {
            images: self.f32s("input.source_images"),
            masks: self.f32s("input.source_masks"),
            cameras: (0..v)
                .map(|i| Self::camera(&k[i * 9..i * 9 + 9], &e[i * 12..i * 12 + 12], w, h))
                .collect(),
            width: w,
            height: h,
        }
    }

    fn encode(&self) -> EncodedViews {
        self.model.encode(&self.source_views()).unwrap()
    }

    fn rays(&self) -> Vec<NetRay> {
        self.f32s("input.rays")
            .chunks(8)
            .map(|r| NetRay::from_array(std::array::from_fn(|k| r[k])))
            .collect()
    }

    fn light(&self) -> Vec<f32> {
        // (1, 3, 8, 16) is the network layout c·128 + row·16 + col.
        self.f32s("input.target_light")
    }
}

const ENC_ATOL: f32 = 5e-4;
const ENC_RTOL: f32 = 1e-4;

pub fn check_encoder(fx: &Fixture) {
    {
        let views = fx.source_views();
        let (encoded, out) = fx.model.encode_traced(&views).unwrap();
        for (i, t) in out.resblocks.iter().enumerate() {
            fx.check_tensor(&format!("output.encoder.resblock{i}"), t, ENC_ATOL, ENC_RTOL);
        }
        fx.check_tensor(
            "output.encoder.lightpred_conv",
            &out.lightpred_conv,
            ENC_ATOL,
            ENC_RTOL,
        );
        fx.check_tensor(
            "output.encoder.light_feature",
            &out.light_feature,
            ENC_ATOL,
            ENC_RTOL,
        );
        for (i, t) in out.upconvs.iter().enumerate() {
            fx.check_tensor(&format!("output.encoder.upconv{i}"), t, ENC_ATOL, ENC_RTOL);
        }
        for (i, t) in out.catconvs.iter().enumerate() {
            fx.check_tensor(&format!("output.encoder.catconv{i}"), t, ENC_ATOL, ENC_RTOL);
        }
        fx.check_tensor("output.encoder.feature", &out.feature, ENC_ATOL, ENC_RTOL);
        fx.check("output.source_mask_dilated", encoded.masks_dilated(), 0.0, 0.0);
        let centres: Vec<f32> = encoded.camera_centres().iter().flatten().copied().collect();
        fx.check("output.source_cam_pos", &centres, 1e-3, 1e-6);
        let coord: Vec<f32> = (0..128)
            .flat_map(|t| net_texel_direction(t / 16, t % 16))
            .collect();
        fx.check("output.light.coord", &coord, 1e-6, 0.0);
        fx.check("output.light.solid_angle", &net_solid_angles(), 1e-7, 1e-6);
        let light = encoded.light();
        fx.check("output.light.sample_grid", &light.sample_grid, 1e-5, 0.0);
        fx.check(
            "output.light.feature_reshaped",
            &light.feature_reshaped,
            ENC_ATOL,
            ENC_RTOL,
        );
        fx.check("output.light.aligned", &light.aligned, ENC_ATOL, ENC_RTOL);
        fx.check("output.light.confidence_norm", &light.confidence_norm, 1e-5, 1e-4);
        fx.check("output.source_light", &light.source_light, 1e-4, 1e-4);
    }
}

pub fn check_points(fx: &Fixture) {
    {
        let encoded = fx.encode();
        let v = encoded.views();
        let rays = fx.rays();
        let depth = fx.f32s("input.points.depth");
        let samples = fx.dims("input.points.depth")[1];
        let n_all = rays.len() * samples;
        let pos: Vec<[f32; 3]> = (0..n_all).map(|i| rays[i / samples].at(depth[i])).collect();
        let dirc: Vec<[f32; 3]> = (0..n_all).map(|i| rays[i / samples].toward_camera()).collect();
        fx.check("output.points.pos", &pos.concat(), 1e-3, 1e-6);
        fx.check("output.points.dirc", &dirc.concat(), 1e-7, 0.0);
        let hull = encoded.hull(&pos);
        fx.check("output.points.pix", &hull.pix, 1e-5, 1e-6);
        // (N, V) → (V, R, S).
        let by_view: Vec<f32> = (0..v)
            .flat_map(|k| (0..n_all).map(move |i| (i, k)))
            .map(|(i, k)| hull.samples[i * v + k])
            .collect();
        fx.check("output.points.hull_sample", &by_view, 1e-5, 0.0);
        let mask: Vec<f32> = hull.inside.iter().map(|&b| f32::from(u8::from(b))).collect();
        fx.check("output.points.hull_mask", &mask, 0.0, 0.0);
        // The official rule on the fixture's own numbers: inside iff the f32 sum of its
        // samples, view 0 first, == V (what `geometry::hull_inside` computes on ours).
        let official = fx.f32s("output.points.hull_sample");
        let official_mask = fx.f32s("output.points.hull_mask");
        for i in 0..n_all {
            let samples: Vec<f32> = (0..v).map(|k| official[k * n_all + i]).collect();
            assert_eq!(
                hull_inside(&samples),
                official_mask[i] == 1.0,
                "{}: point {i}: official samples {samples:?}",
                fx.name
            );
        }

        let index: Vec<usize> = (0..n_all).filter(|&i| hull.inside[i]).collect();
        let p: Vec<[f32; 3]> = index.iter().map(|&i| pos[i]).collect();
        let d: Vec<[f32; 3]> = index.iter().map(|&i| dirc[i]).collect();
        let light = fx.light();
        let irradiance_host = irradiance_values(&light).unwrap();
        fx.check("output.points.target_irradiance", &irradiance_host, 1e-6, 1e-5);
        let irradiance = fx.model.irradiance(&light).unwrap();
        for stage in [Stage::Coarse, Stage::Fine] {
            let m = stage.name();
            let (inputs, trace) = fx.model.run_points(&encoded, &p, &d, stage).unwrap();
            fx.check_tensor("output.points.source_rgb", &inputs.source_rgb, 1e-5, 1e-5);
            fx.check_tensor("output.points.source_dirc", &inputs.source_dirc, 1e-6, 1e-5);
            fx.check_tensor("output.points.target_dirc", &inputs.target_dirc, 1e-7, 0.0);
            fx.check_tensor(
                &format!("output.points.{m}.latent"),
                &inputs.latent,
                ENC_ATOL,
                ENC_RTOL,
            );
            for (name, t) in trace.named() {
                let (atol, rtol) = match name {
                    "density" => (1e-6, 1e-4),
                    _ => (1e-4, 1e-4),
                };
                fx.check_tensor(&format!("output.points.{m}.{name}"), t, atol, rtol);
            }
            let shaded = NelfNet::shade(&trace, &inputs.source_rgb, &irradiance).unwrap();
            fx.check_tensor(
                &format!("output.points.{m}.rgb_perview"),
                &shaded.rgb_perview,
                1e-4,
                1e-4,
            );
            fx.check_tensor(&format!("output.points.{m}.rgb"), &shaded.rgb, 1e-4, 1e-4);
            // The batched, hull-pruned path gives the grids (zeros outside the hull).
            let values = fx
                .model
                .shade_points(&encoded, &pos, &dirc, stage, &light)
                .unwrap();
            assert_eq!(values.inside, hull.inside);
            fx.check(
                &format!("output.points.{m}.sigma_grid"),
                &values.sigma,
                1e-6,
                1e-4,
            );
            fx.check(&format!("output.points.{m}.rgb_grid"), &values.values, 1e-4, 1e-4);
        }
    }
}

pub fn check_render(fx: &Fixture) {
    {
        let encoded = fx.encode();
        let rays = fx.rays();
        let uniforms = RayUniforms {
            coarse_jitter: fx.f32s("input.render.coarse_jitter"),
            fine_u: fx.f32s("input.render.fine_u"),
            fine_jitter: fx.f32s("input.render.fine_jitter"),
        };
        let out = render_rays(&fx.model, &encoded, &rays, &uniforms, &fx.light()).unwrap();
        for (m, c) in [("coarse", &out.coarse), ("fine", &out.fine)] {
            fx.check(
                &format!("output.render.{m}.depth_samples"),
                &c.depth_samples,
                2e-3,
                0.0,
            );
            fx.check(&format!("output.render.{m}.sigma"), &c.sigma, 1e-6, 1e-4);
            fx.check(
                &format!("output.render.{m}.rgb_samples"),
                &c.rgb_samples,
                1e-4,
                1e-4,
            );
            fx.check(&format!("output.render.{m}.weights"), &c.weights, 1e-5, 1e-4);
            fx.check(&format!("output.render.{m}.rgb"), &c.rgb, 1e-4, 1e-4);
            fx.check(&format!("output.render.{m}.depth"), &c.depth, 2e-3, 0.0);
            fx.check(&format!("output.render.{m}.alpha"), &c.alpha, 1e-5, 0.0);
        }
        fx.check(
            "output.render.fine.new_depth_samples",
            &out.fine_new_depth_samples,
            2e-3,
            0.0,
        );
    }
}

pub fn check_rays(fx: &Fixture) {
    {
        let shape = fx
            .tensor("input.target_shape")
            .to_dtype(DType::I64)
            .unwrap()
            .to_vec1::<i64>()
            .unwrap();
        let camera = Fixture::camera(
            &fx.f32s("input.target_intrinsic"),
            &fx.f32s("input.target_extrinsic"),
            shape[1] as usize,
            shape[0] as usize,
        );
        let radius = fx.model.config().head_radius_mm;
        // The official rays pass through integer pixel coordinates; the head is at the origin.
        let rays: Vec<f32> = fx
            .f32s("input.ray_pixels")
            .chunks(2)
            .flat_map(|p| {
                let r = NetRay::through_pixel(&camera, f64::from(p[0]), f64::from(p[1]), [0.0; 3], radius);
                [r.origin.to_vec(), r.dir.to_vec(), vec![r.near, r.far]].concat()
            })
            .collect();
        fx.check("input.rays", &rays, 2e-3, 1e-6);
    }
}
