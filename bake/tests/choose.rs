//! `--target-psnr` / `--max-bytes` (`nelf_bake::choose`) on a tiny synthetic capture
//! (path-traced head, five 64² views, two held-aside targets under other lightings):
//! the asset chosen meets its target when rendered exactly, a lower target chooses a
//! smaller asset, a budget is kept, and an unreachable target names the best reached.

#![allow(clippy::unwrap_used)] // Test helpers outside #[test] functions unwrap too.

mod common;

use nelf_bake::choose::held_aside_psnr;
use nelf_bake::eval::load_held_aside;
use nelf_bake::{
    BakeConfig, CaptureLoadOptions, ChoiceArgs, GroundTruth, Progress, bake_capture_to_target, load_capture,
};

#[test]
fn target_psnr_chooses_the_smallest_asset_that_meets_it() {
    let tmp = tempfile::tempdir().unwrap();
    let cap = tmp.path().join("capture");
    common::tiny_capture(&cap, 2);
    let capture = load_capture(&cap, &CaptureLoadOptions::default()).unwrap();
    let truth = GroundTruth::from_synth_capture(&cap).unwrap();
    let held = load_held_aside(capture.description().unwrap(), &cap).unwrap();
    let config = BakeConfig {
        resolution: 48,
        render_size: 64,
        ..BakeConfig::default()
    };
    let choose = |target: Option<f64>, max_bytes: Option<u64>| {
        let args = ChoiceArgs {
            target_psnr: target,
            max_bytes,
            ..ChoiceArgs::default()
        };
        bake_capture_to_target(&capture, &truth, &config, &args, &Progress::hidden())
    };
    let mut chosen = Vec::new();
    for target in [22.0, 29.0] {
        let (output, report) = choose(Some(target), None).unwrap();
        let c = &report.candidates[report.chosen];
        eprintln!(
            "target {target}: {} (resolutions {:?}, {:.1} s)",
            report.reason, report.resolutions_sampled, report.secs
        );
        for c in &report.candidates {
            eprintln!("  {c:?}");
        }
        let exact = held_aside_psnr(&output.asset, &held, config.step_voxels).unwrap();
        assert!((exact - report.verified_psnr_db).abs() < 1e-9);
        assert!(
            exact >= target,
            "chosen asset renders {exact} dB < target {target}"
        );
        assert_eq!(output.asset.rank(), c.rank);
        assert!(output.asset.metadata.get("choice").is_some());
        chosen.push((c.bytes.unwrap(), exact));
    }
    assert!(
        chosen[0].0 < chosen[1].0,
        "a lower target must choose a smaller asset: {chosen:?}"
    );

    // A budget between the two: the best asset within it.
    let budget = u64::midpoint(chosen[0].0, chosen[1].0);
    let (_, report) = choose(None, Some(budget)).unwrap();
    let c = &report.candidates[report.chosen];
    eprintln!("budget {budget}: {}", report.reason);
    assert!(c.bytes.unwrap() <= budget);
    assert!(report.verified_psnr_db >= chosen[0].1 - 0.5);

    // Unreachable: a clear message naming the best reached.
    let err = choose(Some(80.0), None).unwrap_err().to_string();
    eprintln!("{err}");
    assert!(err.contains("best reached") && err.contains("80"), "{err}");
}
