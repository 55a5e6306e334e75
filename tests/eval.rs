//! End-to-end tests of `nelf eval`: `pareto --quick` and `stability --quick` run on the
//! built-in procedural head, their JSON/CSV/HTML outputs parse and agree, a second run
//! resumes from the results file without measuring again, and bad inputs (a missing
//! capture, a capture with one view, an unreadable mesh) end in clear errors that
//! leave earlier results intact.
#![allow(clippy::unwrap_used)] // Test helpers outside #[test] functions unwrap too.

use std::ffi::OsStr;
use std::path::Path;
use std::process::{Command, Output};

use nelf_eval::{ParetoResults, StabilityResults};

fn nelf<S: AsRef<OsStr>>(args: &[S]) -> Output {
    match Command::new(env!("CARGO_BIN_EXE_nelf"))
        .arg("eval")
        .args(args)
        .output()
    {
        Ok(out) => out,
        Err(e) => panic!("cannot run nelf: {e}"),
    }
}

fn succeed<S: AsRef<OsStr>>(args: &[S]) -> String {
    let out = nelf(args);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8(out.stdout).unwrap()
}

fn fail<S: AsRef<OsStr>>(args: &[S]) -> String {
    let out = nelf(args);
    assert!(!out.status.success(), "should have failed");
    String::from_utf8(out.stderr).unwrap()
}

fn read(path: &Path) -> String {
    std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

#[test]
fn pareto_quick_runs_resumes_and_refuses_bad_input() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("pareto");
    let out_s = out.to_str().unwrap();
    let stdout = succeed(&["pareto", "--quick", "--quiet", "-o", out_s]);
    assert!(stdout.contains("Pareto front"), "{stdout}");

    let json = read(&out.join("results.json"));
    let results: ParetoResults = serde_json::from_str(&json).unwrap();
    // Quick: 2 resolutions × 2 ranks × 2 encodings.
    assert_eq!(results.rows.len(), 8);
    assert_eq!(results.views.len(), 2);
    for row in &results.rows {
        let s = &row.scores;
        assert!(s.psnr_db.is_finite() && s.psnr_fg_db.is_finite() && s.ssim > 0.0 && s.flip > 0.0);
        assert!(row.file_bytes > 0 && row.voxels > 0 && row.bake_secs > 0.0 && row.cpu_render_ms > 0.0);
        assert!(out.join(row.thumbnail.as_deref().unwrap()).is_file());
        assert!(out.join("assets").join(format!("{}.nelf", row.id)).is_file());
    }
    // The rank-8 grids beat the flat-colour baseline on the same views.
    assert!(
        results
            .rows
            .iter()
            .filter(|r| r.rank == 8)
            .all(|r| r.scores.psnr_db > r.scores.baseline_psnr_db + 3.0)
    );
    // The front is non-empty and holds the smallest file.
    let smallest = results.rows.iter().min_by_key(|r| r.file_bytes).unwrap();
    assert!(smallest.front_bytes);
    let csv = read(&out.join("results.csv"));
    assert_eq!(csv.lines().count(), 1 + results.rows.len());
    assert!(
        csv.lines()
            .next()
            .unwrap()
            .starts_with("id,resolution,rank,encoding")
    );
    let html = read(&out.join("report.html"));
    assert!(html.contains("<svg") && html.contains("data:image/png;base64,") && html.contains("<table"));

    // A second run resumes: nothing is measured again.
    succeed(&["pareto", "--quick", "--quiet", "-o", out_s]);
    let again: ParetoResults = serde_json::from_str(&read(&out.join("results.json"))).unwrap();
    assert_eq!(
        again
            .rows
            .iter()
            .map(|r| (&r.id, r.file_bytes, r.bake_secs))
            .collect::<Vec<_>>(),
        results
            .rows
            .iter()
            .map(|r| (&r.id, r.file_bytes, r.bake_secs))
            .collect::<Vec<_>>(),
        "a resumed run measured again"
    );
    let before = read(&out.join("results.json"));
    let capture_before = read(&out.join("capture/synth_config.json"));

    // Bad inputs: clear errors, earlier results intact.
    let missing = fail(&["pareto", "--quick", "--quiet", "-o", out_s, "/no/such/capture"]);
    assert!(missing.contains("/no/such/capture"), "{missing}");
    let garbage = tmp.path().join("broken.obj");
    std::fs::write(&garbage, "v 0 0 zero\nf 1 2 3\n").unwrap();
    let bad_mesh = fail(&[
        "pareto",
        "--quick",
        "--quiet",
        "-o",
        out_s,
        garbage.to_str().unwrap(),
    ]);
    assert!(bad_mesh.contains("broken.obj"), "{bad_mesh}");
    // A capture with one view.
    let one = tmp.path().join("one_view");
    copy_dir(&out.join("capture"), &one);
    let cameras = one.join("cameras.json");
    let mut value: serde_json::Value = serde_json::from_str(&read(&cameras)).unwrap();
    value["views"].as_array_mut().unwrap().truncate(1);
    std::fs::write(&cameras, serde_json::to_string_pretty(&value).unwrap()).unwrap();
    let one_view = fail(&["pareto", "--quick", "--quiet", "-o", out_s, one.to_str().unwrap()]);
    assert!(one_view.contains("view"), "{one_view}");
    assert_eq!(
        read(&out.join("results.json")),
        before,
        "a failed run changed earlier results"
    );
    assert_eq!(
        read(&out.join("capture/synth_config.json")),
        capture_before,
        "a failed run changed the earlier capture"
    );
}

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for entry in std::fs::read_dir(from).unwrap() {
        let entry = entry.unwrap();
        let target = to.join(entry.file_name());
        if entry.path().is_dir() {
            copy_dir(&entry.path(), &target);
        } else {
            std::fs::copy(entry.path(), &target).unwrap();
        }
    }
}

#[test]
fn stability_quick_runs_every_axis_and_names_where_it_breaks() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("stability");
    let out_s = out.to_str().unwrap();
    // The real HDRIs of the repository for the `hdri` axis.
    let hdris = Path::new(env!("CARGO_MANIFEST_DIR")).join("data/envmaps");
    let stdout = succeed(&[
        "stability",
        "--quick",
        "--quiet",
        "-o",
        out_s,
        "--hdri-dir",
        hdris.to_str().unwrap(),
    ]);
    assert!(stdout.contains("below"), "{stdout}");
    let results: StabilityResults = serde_json::from_str(&read(&out.join("stability.json"))).unwrap();
    let axes: Vec<&str> = results.breaks.iter().map(|(a, _)| a.as_str()).collect();
    assert_eq!(axes, nelf_eval::stability::AXES.to_vec());
    for p in &results.points {
        match &p.failure {
            None => {
                assert!(p.scores.psnr_db.is_finite() && p.scores.views > 0, "{p:?}");
                assert!(out.join(p.gallery.as_deref().unwrap()).is_file());
            }
            Some(why) => assert!(!why.is_empty()),
        }
    }
    // Physical sense: rank 1 is worse than rank 16 at the same views.
    let at = |axis: &str, label: &str| {
        results
            .points
            .iter()
            .find(|p| p.axis == axis && p.label == label)
            .map(|p| p.scores.psnr_db)
            .unwrap()
    };
    assert!(at("rank", "rank 1") < at("rank", "rank 16"));
    // Two views 30° apart leave the hull unbounded along their rays; it is clipped
    // around the head (--max-hull-radius-m), so they still bake.
    let two = results.points.iter().find(|p| p.label == "2 views").unwrap();
    assert!(two.failure.is_none(), "{:?}", two.failure);
    // The frontal view at full rank beats rank 1.
    assert!(at("target_angle_deg", "0°") > at("rank", "rank 1"));
    let csv = read(&out.join("stability.csv"));
    assert_eq!(csv.lines().count(), 1 + results.points.len());
    let html = read(&out.join("report.html"));
    assert!(html.matches("<svg").count() >= axes.len());
}
