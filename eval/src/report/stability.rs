//! The stability report's content ([`stability_sections`]): a summary table, then per
//! axis a chart of PSNR against the axis value with the threshold, where PSNR first
//! falls below it, and the worst views.

use std::fmt::Write as _;
use std::path::Path;

use super::chart::{Chart, Series};
use super::html::{Cell, Section, Table};
use super::notes::{chart_or_note, existing_images};
use crate::rows::StabilityPoint;

/// Axes whose values are names, not numbers: plotted at x = 0, 1, … in the order
/// given, with the names listed in the text.
const CATEGORICAL_AXES: [&str; 2] = ["mesh_defect", "hdri"];

/// Axes along which a larger value is the easier setting: walked from the largest
/// value down when looking for the first point below the threshold.
const EASIER_WHEN_LARGER: [&str; 2] = ["views", "rank"];

/// The sections of a stability report: a summary table, then per axis (in the order
/// they first appear) a chart of whole-image, foreground and baseline PSNR against
/// the axis value with `threshold_db` dashed (joined by lines, except on categorical
/// axes), a line naming the first point (walking
/// from the easiest setting to the hardest) whose PSNR falls below the threshold, or
/// saying none does, and the gallery image (worst view) of every point. A NaN PSNR
/// counts as below. Gallery paths are resolved against `report_dir`; missing ones
/// are left out with a note.
#[must_use]
pub fn stability_sections(points: &[StabilityPoint], threshold_db: f64, report_dir: &Path) -> Vec<Section> {
    let mut axes: Vec<(&str, Vec<&StabilityPoint>)> = Vec::new();
    for p in points {
        match axes.iter_mut().find(|(a, _)| *a == p.axis) {
            Some((_, ps)) => ps.push(p),
            None => axes.push((&p.axis, vec![p])),
        }
    }
    let below = |v: f64| v.partial_cmp(&threshold_db).is_none_or(std::cmp::Ordering::is_lt);
    let mut summary_rows = Vec::new();
    let mut sections = Vec::new();
    for (axis, mut pts) in axes {
        let categorical = CATEGORICAL_AXES.contains(&axis) || pts.iter().any(|p| !p.value.is_finite());
        if !categorical {
            pts.sort_by(|a, b| a.value.total_cmp(&b.value));
        }
        let xs: Vec<f64> = if categorical {
            (0..pts.len()).map(|i| i as f64).collect()
        } else {
            pts.iter().map(|p| p.value).collect()
        };
        let series = |name: &str, f: &dyn Fn(&StabilityPoint) -> f64| Series {
            name: name.into(),
            points: xs.iter().zip(&pts).map(|(&x, p)| (x, f(p))).collect(),
            highlight: vec![!categorical; pts.len()],
        };
        let chart = Chart {
            title: format!("Stability: {axis}"),
            x_label: if categorical {
                format!("{axis} (see the list)")
            } else {
                axis.to_string()
            },
            y_label: "PSNR (dB)".into(),
            log_x: false,
            series: vec![
                series("PSNR", &|p| p.scores.psnr_db),
                series("PSNR foreground", &|p| p.scores.psnr_fg_db),
                series("baseline PSNR", &|p| p.scores.baseline_psnr_db),
            ],
            threshold_y: Some(threshold_db),
        };

        // Walk from the easiest setting to the hardest.
        let walk: Vec<&StabilityPoint> = if !categorical && EASIER_WHEN_LARGER.contains(&axis) {
            pts.iter().rev().copied().collect()
        } else {
            pts.clone()
        };
        let name_point = |p: &StabilityPoint| {
            if categorical {
                format!("\"{}\"", p.label)
            } else {
                format!("\"{}\" ({axis} = {})", p.label, p.value)
            }
        };
        let first_below =
            |f: &dyn Fn(&StabilityPoint) -> f64, what: &str| match walk.iter().find(|p| below(f(p))) {
                Some(p) => format!("{what} first falls below {threshold_db} dB at {}.", name_point(p)),
                None => format!("{what} never falls below {threshold_db} dB on this axis."),
            };
        let whole = first_below(&|p| p.scores.psnr_db, "Whole-image PSNR");
        let fg = first_below(&|p| p.scores.psnr_fg_db, "Foreground PSNR");
        let mut text = String::new();
        if let (Some(first), Some(last)) = (walk.first(), walk.last()) {
            let _ = write!(
                text,
                "{} points, from {} to {}. {whole} {fg}",
                pts.len(),
                name_point(first),
                name_point(last)
            );
        }
        let failures: Vec<String> = pts
            .iter()
            .filter_map(|p| p.failure.as_ref().map(|why| format!("\"{}\": {why}", p.label)))
            .collect();
        if !failures.is_empty() {
            let _ = write!(
                text,
                "\n\nNo asset could be made at {} (charted at 0 dB): {}.",
                failures.len(),
                failures.join("; ")
            );
        }
        if categorical {
            let list: Vec<String> = pts
                .iter()
                .enumerate()
                .map(|(i, p)| format!("{i} = {}", p.label))
                .collect();
            let _ = write!(text, "\nx: {}.", list.join(", "));
        }
        let mut charts = Vec::new();
        chart_or_note(&chart, &mut charts, &mut text);

        let wanted = pts.iter().filter_map(|p| {
            p.gallery.as_ref().map(|g| {
                (
                    format!(
                        "{}: worst view {:.2} dB (mean {:.2} dB)",
                        p.label, p.worst_psnr_db, p.scores.psnr_db
                    ),
                    g.clone(),
                )
            })
        });
        let (images, note) = existing_images(report_dir, wanted);
        if let Some(note) = note {
            let _ = write!(text, "\n\n{note}");
        }

        let worst = pts
            .iter()
            .min_by(|a, b| a.scores.psnr_db.total_cmp(&b.scores.psnr_db));
        let first = walk.iter().find(|p| below(p.scores.psnr_db));
        summary_rows.push(vec![
            Cell::text(axis),
            Cell::number(pts.len().to_string(), pts.len() as f64),
            worst.map_or_else(
                || Cell::text("–"),
                |w| Cell::number(format!("{:.2} ({})", w.scores.psnr_db, w.label), w.scores.psnr_db),
            ),
            first.map_or_else(|| Cell::text("never"), |p| Cell::text(&p.label).highlighted(true)),
        ]);
        sections.push(Section {
            heading: format!("Stability: {axis}"),
            text,
            charts,
            images,
            ..Section::default()
        });
    }
    let summary = Section {
        heading: "Stability summary".into(),
        text: if points.is_empty() {
            "No stability points were measured.".into()
        } else {
            format!(
                "Per axis: the lowest whole-image PSNR and the first setting (walking from the \
                 easiest to the hardest) whose PSNR falls below {threshold_db} dB."
            )
        },
        table: (!summary_rows.is_empty()).then(|| Table {
            columns: ["axis", "points", "lowest PSNR dB", "first below threshold"]
                .map(String::from)
                .to_vec(),
            rows: summary_rows,
        }),
        ..Section::default()
    };
    sections.insert(0, summary);
    sections
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::report::test_support::{TestResult, has_text_element, point, tiny_png};

    #[test]
    fn stability_sections_name_where_psnr_falls_below_the_threshold() -> TestResult {
        let dir = tempfile::tempdir()?;
        tiny_png(&dir.path().join("worst.png"))?;
        let mut points = vec![
            point("views", 8.0, "8 views", 30.0),
            point("views", 2.0, "2 views", 15.0),
            point("views", 4.0, "4 views", 19.0),
            point("pose_noise_deg", 0.5, "0.5°", 29.0),
            point("pose_noise_deg", 1.0, "1°", 28.0),
            point("hdri", 0.0, "studio.exr", 26.0),
            point("hdri", 0.0, "sunset.exr", f64::NAN),
        ];
        points[1].gallery = Some("worst.png".into());
        points[2].gallery = Some("missing.png".into());
        let sections = stability_sections(&points, 20.0, dir.path());
        assert_eq!(sections.len(), 4);
        assert_eq!(sections[0].heading, "Stability summary");
        let Some(summary) = &sections[0].table else {
            panic!("no summary table");
        };
        assert_eq!(summary.rows.len(), 3);
        assert_eq!(summary.rows[0][3].text, "4 views", "walked from 8 views down");
        assert_eq!(summary.rows[1][3].text, "never");
        assert_eq!(summary.rows[2][3].text, "sunset.exr", "NaN counts as below");

        let views = &sections[1];
        assert_eq!(views.heading, "Stability: views");
        assert!(
            views
                .text
                .contains("Whole-image PSNR first falls below 20 dB at \"4 views\" (views = 4)"),
            "{}",
            views.text
        );
        assert_eq!(views.charts.len(), 1);
        assert!(views.charts[0].contains("threshold 20"));
        assert_eq!(views.images.len(), 1);
        assert!(views.text.contains("missing.png"));
        assert!(
            sections[2]
                .text
                .contains("Whole-image PSNR never falls below 20 dB")
        );
        let hdri = &sections[3];
        assert!(
            hdri.text.contains("0 = studio.exr, 1 = sunset.exr"),
            "{}",
            hdri.text
        );
        assert_eq!(hdri.charts.len(), 1);
        for (tick, shown) in [("0", true), ("1", true), ("0.5", false)] {
            assert_eq!(has_text_element(&hdri.charts[0], tick), shown, "x tick {tick}");
        }

        let empty = stability_sections(&[], 20.0, dir.path());
        assert_eq!(empty.len(), 1);
        assert!(empty[0].table.is_none());
        Ok(())
    }
}
