//! Training datasets: written, read back, resumed, refused when the settings
//! change or the settings file is damaged, and split into held-out identities and
//! lightings. Reads the repository's `data/envmaps` and `data/meshes/head.off`; a
//! missing file fails.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::SystemTime;

use indicatif::ProgressBar;
use nelf_format::conventions::{ENV_H, ENV_W, LT_DIM};
use nelf_scene::synth::SynthConfig;
use nelf_train::TrainError;
use nelf_train::data::plan::VAL_SEED_BIT;
use nelf_train::data::{
    DataConfig, Dataset, Distill, EnvCatalogue, Identity, LightSource, Split, SplitRecord, TargetMode,
    generate, head_dir,
};

fn repo(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..").join(rel)
}

/// The repository's test data, checked so that a missing file fails loudly.
fn repo_data() -> (PathBuf, PathBuf) {
    let envmaps = repo("data/envmaps");
    let scan = repo("data/meshes/head.off");
    for name in ["forest", "interior", "city", "courtyard"] {
        let file = envmaps.join(format!("{name}.exr"));
        assert!(file.is_file(), "missing test data {}", file.display());
    }
    assert!(scan.is_file(), "missing test data {}", scan.display());
    (envmaps, scan)
}

/// Two training heads (head 1 the scan) and one validation head, 32², cheapest tracer.
fn tiny() -> DataConfig {
    let (envmaps_dir, scan_mesh) = repo_data();
    DataConfig {
        size: 32,
        heads: 2,
        val_heads: 1,
        scan_every: 2,
        head_cells: 32,
        texel_samples: 1,
        indirect_samples: 2,
        bounces: 1,
        distill_points: 64,
        envmaps_dir,
        scan_mesh,
        ..DataConfig::default()
    }
}

/// Modification times of every file under `dir`.
fn mtimes(dir: &Path) -> BTreeMap<PathBuf, SystemTime> {
    let mut out = BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for entry in std::fs::read_dir(&d).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                stack.push(path);
            } else {
                out.insert(
                    path.clone(),
                    std::fs::metadata(&path).unwrap().modified().unwrap(),
                );
            }
        }
    }
    out
}

fn all_finite(values: impl IntoIterator<Item = f32>) -> bool {
    values.into_iter().all(f32::is_finite)
}

#[test]
fn dataset_is_written_read_back_and_resumed() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("data");
    let config = tiny();
    let report = generate(&dir, &config, &ProgressBar::hidden()).unwrap();
    // Validation heads (ids after the training heads) are rendered first.
    assert_eq!(report.written, vec![2, 0, 1]);
    assert!(report.skipped.is_empty());

    let dataset = Dataset::open(&dir).unwrap();
    assert_eq!(dataset.config, config);
    assert_eq!(dataset.train_ids(), vec![0, 1]);
    assert_eq!(dataset.val_ids(), vec![2]);
    let pixels = 32 * 32;
    for id in [0, 1, 2] {
        let sample = dataset.load(id).unwrap();
        assert_eq!(sample.id, id);
        assert_eq!(sample.spec.split, if id < 2 { Split::Train } else { Split::Val });
        assert_eq!(sample.spec.identity == Identity::Scan, id == 1);
        assert_eq!(sample.source_cameras.len(), 5);
        assert_eq!(sample.source_images.len(), 5);
        assert_eq!(sample.source_masks.len(), 5);
        for ((camera, image), mask) in sample
            .source_cameras
            .iter()
            .zip(&sample.source_images)
            .zip(&sample.source_masks)
        {
            assert_eq!((camera.width, camera.height), (32, 32));
            assert_eq!((image.len(), mask.len()), (pixels, pixels));
            assert!(image.iter().flatten().all(|v| v.is_finite() && *v >= 0.0));
            assert!(mask.iter().all(|m| (0.0..=1.0).contains(m)));
            assert!(mask.iter().any(|&m| m > 0.99), "head {id}: the head is in view");
            assert!(mask.contains(&0.0), "head {id}: background is in view");
            let lit = image
                .iter()
                .zip(mask)
                .filter(|(c, m)| **m > 0.99 && c.iter().sum::<f32>() > 0.0);
            assert!(lit.count() > 10, "head {id}: the head is lit");
        }
        assert!(sample.head_centre_m.is_finite());
        assert_eq!(
            (sample.source_light.width(), sample.source_light.height()),
            (ENV_W, ENV_H)
        );

        let modes: Vec<TargetMode> = sample.targets.iter().map(|t| t.mode).collect();
        assert_eq!(modes, [TargetMode::SelfRotation, TargetMode::NovelLight]);
        for target in &sample.targets {
            assert_eq!((target.camera.width, target.camera.height), (32, 32));
            assert_eq!(target.image.len(), pixels);
            assert_eq!(target.alpha.len(), pixels);
            assert_eq!(target.depth_m.len(), pixels);
            assert!(target.image.iter().flatten().all(|v| v.is_finite() && *v >= 0.0));
            assert!(target.alpha.iter().all(|a| (0.0..=1.0).contains(a)));
            let distance = (target.camera.centre() - sample.head_centre_m).length() as f32;
            for (&alpha, &depth) in target.alpha.iter().zip(&target.depth_m) {
                // Depth and alpha come from the same sub-pixel rays.
                assert_eq!(
                    alpha > 0.0,
                    depth > 0.0,
                    "head {id}: alpha {alpha}, depth {depth}"
                );
                if depth > 0.0 {
                    assert!((depth - distance).abs() < 0.25, "depth {depth} m at {distance} m");
                }
            }
            assert!(target.alpha.iter().any(|&a| a > 0.99));
            assert_eq!((target.light.width(), target.light.height()), (ENV_W, ENV_H));
            assert!(all_finite(target.light.texels().iter().flatten().copied()));
        }
        // Self-rotation: lighting A turned (power kept, map changed); novel light: another map.
        let power = |l: &nelf_format::conventions::LatLong| l.integral().iter().sum::<f64>();
        let (a, rotated, b) = (
            &sample.source_light,
            &sample.targets[0].light,
            &sample.targets[1].light,
        );
        assert!(
            (power(a) - power(rotated)).abs() <= 1e-3 * power(a),
            "turning keeps the power"
        );
        assert_ne!(a.texels(), rotated.texels());
        assert_ne!(a.texels(), b.texels());
        assert!(sample.spec.self_rotation_deg.abs() >= config.rotation_min_deg);

        let distill = &sample.distill;
        assert_eq!(distill.len(), 64);
        assert_eq!(distill.lt.len(), 64 * LT_DIM);
        assert_eq!(distill.sigma_per_m.len(), 64);
        assert!(all_finite(distill.points_m.iter().flatten().copied()));
        assert!(all_finite(distill.lt.iter().copied()));
        assert!(distill.sigma_per_m.iter().all(|s| s.is_finite() && *s >= 0.0));
        assert!(
            distill.sigma_per_m.iter().any(|&s| s > 0.0),
            "some points are inside the shell"
        );
        let near = distill
            .signed_distance_m
            .iter()
            .filter(|d| d.abs() < 0.01)
            .count();
        assert!(
            near >= 40,
            "most points lie within a centimetre of the surface ({near} of 64)"
        );
        for d in &distill.view_dirs {
            let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            assert!((len - 1.0).abs() < 1e-4);
        }
        assert!(distill.lt.iter().any(|&t| t > 0.0));

        // Source-relative preparation divides every lighting the network is given by
        // the source map's mean radiance and changes nothing else (the images, the
        // truth and the distilled radiance stay as rendered).
        let p_a = sample.source_light.mean_radiance();
        let expected = sample.source_light.integral().iter().sum::<f64>() / (12.0 * std::f64::consts::PI);
        assert!((p_a - expected).abs() <= 1e-12 * expected);
        assert!(
            (p_a - 1.0).abs() > 1e-3,
            "head {id}: a source power other than 1 ({p_a})"
        );
        let absolute = nelf_train::trainer::prepare(&sample, 32, false).unwrap();
        let relative = nelf_train::trainer::prepare(&sample, 32, true).unwrap();
        let divided = |a: &[f32], r: &[f32]| {
            assert_eq!(a.len(), r.len());
            for (a, r) in a.iter().zip(r) {
                assert!(
                    (f64::from(*a) / p_a - f64::from(*r)).abs()
                        <= 1e-6 * (f64::from(*a) / p_a).abs().max(1e-6)
                );
            }
        };
        divided(&absolute.source_light_net, &relative.source_light_net);
        for (a, r) in absolute.targets.iter().zip(&relative.targets) {
            divided(&a.light_net, &r.light_net);
            assert_eq!(a.image, r.image);
        }
        for (a, r) in absolute.distill_lights.iter().zip(&relative.distill_lights) {
            divided(a, r);
        }
        assert_eq!(absolute.distill_radiance, relative.distill_radiance);
        assert_eq!(absolute.capture.views.images, relative.capture.views.images);

        // The network's capture loader reads a head folder.
        let (net, _) = nelf_field::capture::load_capture_dir(
            dataset.head_dir(id),
            nelf_field::capture::default_net_from_world(),
        )
        .unwrap();
        assert_eq!(net.cameras.len(), 5);
        assert!((net.head_centre_m - sample.head_centre_m).length() < 1e-6);
    }
    assert!(matches!(
        dataset.load(3),
        Err(TrainError::MissingHead { id: 3, .. })
    ));

    // Resume: only the removed head is rendered again; a killed run's leftover is cleared.
    let before_0 = mtimes(&head_dir(&dir, 0));
    let before_2 = mtimes(&head_dir(&dir, 2));
    std::fs::remove_dir_all(head_dir(&dir, 1)).unwrap();
    let leftover = dir.join("heads/.tmp-h00001");
    std::fs::create_dir_all(&leftover).unwrap();
    std::fs::write(leftover.join("images"), b"half a head").unwrap();
    assert_eq!(Dataset::open(&dir).unwrap().train_ids(), vec![0]);
    let report = generate(&dir, &config, &ProgressBar::hidden()).unwrap();
    assert_eq!(report.written, vec![1]);
    assert_eq!(report.skipped, vec![2, 0]);
    assert!(!leftover.exists());
    assert_eq!(mtimes(&head_dir(&dir, 0)), before_0);
    assert_eq!(mtimes(&head_dir(&dir, 2)), before_2);
    assert_eq!(Dataset::open(&dir).unwrap().train_ids(), vec![0, 1]);
    dataset.load(1).unwrap();

    // Other settings in the same folder are refused before anything is rendered.
    let other = DataConfig {
        seed: 7,
        ..config.clone()
    };
    let err = generate(&dir, &other, &ProgressBar::hidden()).unwrap_err();
    assert!(matches!(err, TrainError::ConfigMismatch { .. }), "{err}");
    let message = err.to_string();
    assert!(
        message.contains("data_config.json") && message.contains("seed"),
        "{message}"
    );
    assert_eq!(mtimes(&head_dir(&dir, 0)), before_0);

    // Held out: the validation head's files name no training map or seed, and no
    // training head's names a validation map.
    for id in [0, 1, 2] {
        let text = std::fs::read_to_string(head_dir(&dir, id).join("synth_config.json")).unwrap();
        let synth: SynthConfig = serde_json::from_str(&text).unwrap();
        let files: Vec<PathBuf> = synth.envmap.iter().chain(&synth.target_envmap).cloned().collect();
        assert_eq!(files.len(), 3);
        for file in files {
            let stem = file.file_stem().unwrap().to_str().unwrap().to_owned();
            assert!(file.is_file(), "{}", file.display());
            if let Some(hex) = stem.strip_prefix("procedural_") {
                let seed = u64::from_str_radix(hex, 16).unwrap();
                assert_eq!(seed >= VAL_SEED_BIT, id == 2, "head {id}: env seed {seed}");
            } else {
                assert_eq!(
                    config.val_envmaps.contains(&stem),
                    id == 2,
                    "head {id}: HDRI {stem}"
                );
            }
        }
        if synth.mesh.is_none() {
            assert_eq!(synth.head_seed >= VAL_SEED_BIT, id == 2);
        }
    }
}

#[test]
fn missing_or_damaged_settings_are_errors_naming_the_file() {
    let tmp = tempfile::tempdir().unwrap();
    let err = Dataset::open(tmp.path()).unwrap_err();
    assert!(err.to_string().contains("data_config.json"), "{err}");

    let path = tmp.path().join("data_config.json");
    std::fs::write(&path, "{ \"size\": 12").unwrap();
    let err = Dataset::open(tmp.path()).unwrap_err();
    assert!(err.to_string().contains("data_config.json"), "{err}");
    let err = generate(tmp.path(), &tiny(), &ProgressBar::hidden()).unwrap_err();
    assert!(err.to_string().contains("data_config.json"), "{err}");

    // Valid JSON with a value out of range.
    let bad = DataConfig { size: 3, ..tiny() };
    std::fs::write(&path, serde_json::to_string(&bad).unwrap()).unwrap();
    let err = Dataset::open(tmp.path()).unwrap_err();
    assert!(err.to_string().contains("data_config.json"), "{err}");
}

#[test]
fn validation_heads_are_held_out() {
    let (envmaps_dir, scan_mesh) = repo_data();
    let config = DataConfig {
        envmaps_dir,
        scan_mesh,
        ..DataConfig::default()
    };
    let envs = EnvCatalogue::scan(&config).unwrap();
    assert_eq!(envs.val, ["forest", "interior"]);
    assert_eq!(envs.train.len(), 6);
    assert!(envs.train.iter().all(|n| !envs.val.contains(n)));
    let split = SplitRecord::new(&config, &envs);
    assert_eq!(split.heads.len(), 208);

    let mut hdris = [BTreeMap::new(), BTreeMap::new()];
    let mut seeds = [Vec::new(), Vec::new()];
    let mut scans = 0;
    for head in &split.heads {
        let val = head.split == Split::Val;
        assert_eq!(val, head.id >= 200);
        match head.identity {
            Identity::Procedural { seed } => seeds[usize::from(val)].push(seed),
            Identity::Scan => {
                assert!(!val, "the scan is a training identity only");
                scans += 1;
            }
        }
        for light in [&head.light_a, &head.light_b] {
            match &light.source {
                LightSource::Hdri { name } => {
                    *hdris[usize::from(val)].entry(name.clone()).or_insert(0) += 1;
                }
                LightSource::Procedural { seed } => seeds[usize::from(val)].push(*seed),
            }
        }
        assert_ne!(head.light_a.source, head.light_b.source);
        assert!(head.min_distance_m <= head.max_distance_m);
        assert!((0.0..=0.3).contains(&head.specular_weight));
    }
    assert_eq!(scans, 20);
    assert!(seeds[0].iter().all(|&s| s < VAL_SEED_BIT));
    assert!(
        seeds[1]
            .iter()
            .all(|&s| (VAL_SEED_BIT..2 * VAL_SEED_BIT).contains(&s))
    );
    let train_maps: Vec<&String> = hdris[0].keys().collect();
    assert_eq!(train_maps.len(), 6, "every training map is drawn: {train_maps:?}");
    assert!(hdris[1].keys().all(|n| envs.val.contains(n)), "{:?}", hdris[1]);
    assert!(!hdris[1].is_empty());
    // Deterministic: the same settings draw the same heads.
    assert_eq!(SplitRecord::new(&config, &envs), split);
}

#[test]
fn distillation_file_round_trips_and_refuses_damage() {
    let distill = Distill {
        points_m: vec![[0.1, -0.2, 0.3], [0.0, 0.05, -0.01]],
        sigma_per_m: vec![0.0, 5e4],
        lt: (0..2 * LT_DIM).map(|i| i as f32 * 1e-4).collect(),
        view_dirs: vec![[0.0, 0.0, 1.0], [1.0, 0.0, 0.0]],
        signed_distance_m: vec![0.01, -0.002],
    };
    let path = Path::new("heads/h00000/distill.bin");
    let bytes = distill.to_bytes();
    assert_eq!(bytes.len(), 24 + 2 * 800);
    let back = Distill::from_bytes(&bytes, path).unwrap();
    assert_eq!(back.points_m, distill.points_m);
    assert_eq!(back.sigma_per_m, distill.sigma_per_m);
    for (a, b) in back.lt.iter().zip(&distill.lt) {
        assert!((a - b).abs() <= 1e-3 * b.abs() + 1e-7, "f16: {a} vs {b}");
    }
    let err = Distill::from_bytes(&bytes[..bytes.len() - 1], path).unwrap_err();
    assert!(err.to_string().contains("distill.bin"), "{err}");
    let mut wrong = bytes.clone();
    wrong[0] = b'X';
    assert!(Distill::from_bytes(&wrong, path).is_err());
}
