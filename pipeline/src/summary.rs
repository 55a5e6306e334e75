//! What `nelf bake` prints of a bake: the written asset and its report
//! ([`describe_bake`]), and a choice among bakes ([`describe_choice`]).

use std::fmt::Write as _;
use std::path::Path;

use nelf_bake::view::ViewCandidate;
use nelf_bake::{BakeReport, ChoiceReport, sidecar_path};

/// The candidates a choice tried (those with measured bytes) and what it chose, one
/// line each.
pub fn describe_choice(report: &ChoiceReport) -> String {
    let mut text = format!(
        "choice over {} held-aside views, resolutions sampled {:?}, {:.1} s:\n",
        report.views.len(),
        report.resolutions_sampled,
        report.secs
    );
    text.push_str("  resolution  rank  encoding  est. PSNR (dB)  bytes\n");
    for (i, c) in report.candidates.iter().enumerate() {
        if let Some(bytes) = c.bytes {
            let _ = writeln!(
                text,
                "  {:>10}  {:>4}  {:>8}  {:>14.2}  {bytes}{}",
                c.resolution,
                c.rank,
                format!("{:?}", c.encoding).to_lowercase(),
                c.psnr_db,
                if i == report.chosen { "  <- chosen" } else { "" }
            );
        }
    }
    let _ = writeln!(text, "  chose {}", report.reason);
    text
}

/// The asset written to `out` and its report: sizes, rank, view dependence, seconds
/// per stage and where the settings went, one line each.
pub fn describe_bake(out: &Path, r: &BakeReport) -> String {
    let t = &r.timings;
    let mut text = format!(
        "wrote {} ({} bytes): {} bricks, {} voxels ({:.2} mm), light transport at {} voxels\n",
        out.display(),
        r.file_size,
        r.bricks,
        r.voxels,
        r.voxel_size_m * 1e3,
        r.lt_voxels
    );
    let _ = writeln!(
        text,
        "  PCA rank K = {} (energy kept {:.5}, rendered loss {:.4} dB{}; unquantized grid SNR {:.2} dB)",
        r.rank,
        r.energy_kept,
        r.loss_db,
        if r.met_target { "" } else { ", target NOT met" },
        -10.0 * r.reference_relative_error.log10()
    );
    if let Some(v) = &r.view {
        let kept = v.chosen_index.map(|i| &v.candidates[i]);
        let gain = |c: &ViewCandidate| {
            c.gain_db
                .map_or_else(|| "not judged".into(), |g| format!("{g:+.2} dB"))
        };
        let _ = match kept {
            Some(c) => match c.exponent {
                Some(exponent) => writeln!(
                    text,
                    "  view dependence {} ({}): a glossy lobe of exponent {exponent} about each voxel's mirror direction, {} at {}",
                    v.chosen,
                    v.requested,
                    gain(c),
                    v.judged_at
                ),
                None => writeln!(
                    text,
                    "  view dependence {} ({}): {} lobes × view rank {}, {} at {}",
                    v.chosen,
                    v.requested,
                    c.lobes,
                    c.rank,
                    gain(c),
                    v.judged_at
                ),
            },
            None => writeln!(
                text,
                "  view dependence off ({}): {}",
                v.requested,
                if let Some(p) = v.probe.as_ref().filter(|p| !p.band_fitted) {
                    format!(
                        "probed on {} of {} band voxels ({:.1} s): the best candidate would gain about {:+.3} dB over the whole band at {} (extrapolated {:+.3} / {}), below --view-min-gain-db; the band was not fitted",
                        p.voxels,
                        p.band_voxels,
                        p.secs,
                        p.best_extrapolated_gain_db / nelf_bake::view::PROBE_OVERSELL,
                        v.judged_at,
                        p.best_extrapolated_gain_db,
                        nelf_bake::view::PROBE_OVERSELL
                    )
                } else if let (true, Some(residual)) = (v.candidates.is_empty(), v.residual_ratio) {
                    format!("residual {residual:.1e} of the transport, nothing to fit")
                } else if v.candidates.is_empty() {
                    "not fitted: no views to judge a candidate at (no held-aside targets, no named lighting)"
                        .to_string()
                } else {
                    let best = v.best_gain_db();
                    format!(
                        "best candidate {best:+.2} dB at {}, below the threshold",
                        v.judged_at
                    )
                }
            ),
        };
    }
    let _ = writeln!(
        text,
        "  seconds: hull {:.2}, reference {:.2}, density {:.2}, weights {:.2}, light {:.2}, pca {:.2}, rank {:.2}, view {:.2}, fine density {:.2}, write {:.2}",
        t.hull_secs,
        t.reference_secs,
        t.density_secs,
        t.weights_secs,
        t.lt_secs,
        t.pca_secs,
        t.rank_secs,
        t.view_secs,
        t.fine_density_secs,
        t.write_secs
    );
    for note in &r.notes {
        let _ = writeln!(text, "  note: {note}");
    }
    let _ = writeln!(text, "  settings and report: {}", sidecar_path(out).display());
    text
}
