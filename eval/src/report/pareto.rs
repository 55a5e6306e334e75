//! The Pareto sweep's report content ([`pareto_sections`]): quality against size
//! and against frame time with their fronts, ꟻLIP against size, a table of every
//! setting, and the thumbnails.

use std::collections::BTreeSet;
use std::fmt::Write as _;
use std::path::Path;

use super::chart::{Chart, Series, si_split, sig3};
use super::html::{Cell, Section, Table};
use super::notes::{chart_or_note, existing_images};
use crate::rows::ParetoRow;

fn fmt_bytes(bytes: u64) -> String {
    if bytes < 1000 {
        format!("{bytes} B")
    } else {
        let (m, suffix) = si_split(bytes as f64);
        format!("{} {suffix}B", sig3(m))
    }
}

fn fixed(v: f64, decimals: usize) -> String {
    format!("{v:.decimals$}")
}

/// The sections of a Pareto sweep's report: PSNR against file bytes (log x) with
/// its front, PSNR against GPU frame time at 512² with its front (if any row has a
/// frame time), ꟻLIP against file bytes with the ꟻLIP front, a table of every row,
/// and the rows' thumbnails. Fronts are read from the rows' `front_bytes` and
/// `front_frame` (set them with [`crate::front::mark_fronts`] first). Thumbnails are
/// resolved against `report_dir`; missing ones are left out with a note.
#[must_use]
pub fn pareto_sections(rows: &[ParetoRow], input_name: &str, report_dir: &Path) -> Vec<Section> {
    if rows.is_empty() {
        return vec![Section {
            heading: format!("Pareto sweep: {input_name}"),
            text: "No settings were measured.".into(),
            ..Section::default()
        }];
    }
    let mut sections = Vec::new();
    let baseline = rows.iter().map(|r| r.scores.baseline_psnr_db).sum::<f64>() / rows.len() as f64;
    let views = rows.iter().map(|r| r.scores.views).max().unwrap_or(0);

    // Quality against size.
    let mut text = format!(
        "{} settings of {input_name}, scored at {views} held-aside views. The Pareto front \
         (settings no other setting beats on both size and PSNR) is drawn larger and joined. \
         For scale: the trivial baseline (each view's mean foreground colour, flat) scores \
         {baseline:.2} dB.",
        rows.len()
    );
    let front_series =
        |name: &str, pick: &dyn Fn(&ParetoRow) -> Option<(f64, f64)>, on: &dyn Fn(&ParetoRow) -> bool| {
            let all: Vec<(f64, f64)> = rows.iter().filter_map(pick).collect();
            let front: Vec<(f64, f64)> = rows.iter().filter(|r| on(r)).filter_map(pick).collect();
            vec![
                Series {
                    name: "settings".into(),
                    points: all,
                    highlight: Vec::new(),
                },
                Series {
                    name: name.into(),
                    highlight: vec![true; front.len()],
                    points: front,
                },
            ]
        };
    let mut charts = Vec::new();
    chart_or_note(
        &Chart {
            title: format!("PSNR against file size: {input_name}"),
            x_label: "file bytes".into(),
            y_label: "PSNR (dB)".into(),
            log_x: true,
            series: front_series(
                "Pareto front",
                &|r| Some((r.file_bytes as f64, r.scores.psnr_db)),
                &|r| r.front_bytes,
            ),
            threshold_y: None,
        },
        &mut charts,
        &mut text,
    );
    sections.push(Section {
        heading: "Quality against size".into(),
        text,
        charts,
        ..Section::default()
    });

    // Quality against frame time.
    if rows.iter().any(|r| r.gpu_frame_ms_512.is_some()) {
        let adapters: BTreeSet<&str> = rows.iter().filter_map(|r| r.gpu_adapter.as_deref()).collect();
        let mut text = format!(
            "GPU frame time at 512 × 512 (relit once, then marched) on {}; settings without a \
             frame time are left out. The front is drawn larger and joined.",
            if adapters.is_empty() {
                "an unnamed adapter".to_string()
            } else {
                adapters.into_iter().collect::<Vec<_>>().join(", ")
            }
        );
        let mut charts = Vec::new();
        chart_or_note(
            &Chart {
                title: format!("PSNR against GPU frame time: {input_name}"),
                x_label: "GPU frame time at 512², ms".into(),
                y_label: "PSNR (dB)".into(),
                log_x: true,
                series: front_series(
                    "Pareto front",
                    &|r| r.gpu_frame_ms_512.map(|ms| (ms, r.scores.psnr_db)),
                    &|r| r.front_frame,
                ),
                threshold_y: None,
            },
            &mut charts,
            &mut text,
        );
        sections.push(Section {
            heading: "Quality against frame time".into(),
            text,
            charts,
            ..Section::default()
        });
    }

    // ꟻLIP against size, with its own front (lower ꟻLIP is better).
    let flip_front = crate::front::pareto_front(
        &rows
            .iter()
            .map(|r| (r.file_bytes as f64, -r.scores.flip))
            .collect::<Vec<_>>(),
    );
    let mut text = "Mean ꟻLIP (lower is better) against file size; the settings no other \
                    setting beats on both are drawn larger and joined."
        .to_string();
    let mut charts = Vec::new();
    let flip_points: Vec<(f64, f64)> = rows
        .iter()
        .map(|r| (r.file_bytes as f64, r.scores.flip))
        .collect();
    chart_or_note(
        &Chart {
            title: format!("ꟻLIP against file size: {input_name}"),
            x_label: "file bytes".into(),
            y_label: "mean ꟻLIP".into(),
            log_x: true,
            series: vec![
                Series {
                    name: "settings".into(),
                    points: flip_points.clone(),
                    highlight: Vec::new(),
                },
                Series {
                    name: "ꟻLIP front".into(),
                    points: flip_points
                        .iter()
                        .zip(&flip_front)
                        .filter(|(_, on)| **on)
                        .map(|(p, _)| *p)
                        .collect(),
                    highlight: vec![true; flip_front.iter().filter(|on| **on).count()],
                },
            ],
            threshold_y: None,
        },
        &mut charts,
        &mut text,
    );
    sections.push(Section {
        heading: "ꟻLIP against size".into(),
        text,
        charts,
        ..Section::default()
    });

    // Every row.
    let columns = [
        "id",
        "resolution",
        "rank",
        "encoding",
        "voxels",
        "bytes",
        "bake s",
        "PSNR dB",
        "PSNR fg dB",
        "SSIM",
        "ꟻLIP",
        "baseline PSNR dB",
        "CPU ms",
        "GPU ms 512²",
        "GPU ms 1080p",
        "front: bytes",
        "front: frame",
    ];
    let optional_ms = |v: Option<f64>| v.map_or_else(|| Cell::text("–"), |ms| Cell::number(fixed(ms, 2), ms));
    let mark = |on: bool| Cell::number(if on { "✓" } else { "" }, f64::from(u8::from(on))).highlighted(on);
    let table_rows = rows
        .iter()
        .map(|r| {
            let s = &r.scores;
            vec![
                Cell::text(&r.id).highlighted(r.front_bytes || r.front_frame),
                Cell::number(r.resolution.to_string(), f64::from(r.resolution)),
                Cell::number(r.rank.to_string(), r.rank as f64),
                Cell::text(&r.encoding),
                Cell::number(r.voxels.to_string(), r.voxels as f64),
                Cell::number(fmt_bytes(r.file_bytes), r.file_bytes as f64).highlighted(r.front_bytes),
                Cell::number(fixed(r.bake_secs, 1), r.bake_secs),
                Cell::number(fixed(s.psnr_db, 2), s.psnr_db).highlighted(r.front_bytes || r.front_frame),
                Cell::number(fixed(s.psnr_fg_db, 2), s.psnr_fg_db),
                Cell::number(fixed(s.ssim, 4), s.ssim),
                Cell::number(fixed(s.flip, 4), s.flip),
                Cell::number(fixed(s.baseline_psnr_db, 2), s.baseline_psnr_db),
                Cell::number(fixed(r.cpu_render_ms, 1), r.cpu_render_ms),
                optional_ms(r.gpu_frame_ms_512).highlighted(r.front_frame),
                optional_ms(r.gpu_frame_ms_1080p),
                mark(r.front_bytes),
                mark(r.front_frame),
            ]
        })
        .collect();
    sections.push(Section {
        heading: "Every setting".into(),
        text: "Click a header to sort. Highlighted: on a Pareto front (bytes, frame time).".into(),
        table: Some(Table {
            columns: columns.iter().map(|c| (*c).to_string()).collect(),
            rows: table_rows,
        }),
        ..Section::default()
    });

    // Thumbnails.
    let wanted: Vec<(String, String)> = rows
        .iter()
        .filter_map(|r| {
            r.thumbnail.as_ref().map(|t| {
                (
                    format!(
                        "{}: {:.2} dB, {}",
                        r.id,
                        r.scores.psnr_db,
                        fmt_bytes(r.file_bytes)
                    ),
                    t.clone(),
                )
            })
        })
        .collect();
    if !wanted.is_empty() {
        let (images, note) = existing_images(report_dir, wanted);
        let mut text = "The first held-aside view, rendered from each setting.".to_string();
        if let Some(note) = note {
            let _ = write!(text, "\n\n{note}");
        }
        sections.push(Section {
            heading: "Thumbnails".into(),
            text,
            images,
            ..Section::default()
        });
    }
    sections
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::report::test_support::{TestResult, row, tiny_png};
    use crate::report::write_html_report;

    #[test]
    fn pareto_sections_chart_tabulate_and_note_missing_thumbnails() -> TestResult {
        let dir = tempfile::tempdir()?;
        std::fs::create_dir(dir.path().join("thumbs"))?;
        tiny_png(&dir.path().join("thumbs/a.png"))?;
        let mut rows = vec![
            row("a", 1_000, 25.0, Some(2.0)),
            row("b", 10_000, 30.0, Some(4.0)),
            row("c", 20_000, 28.0, None),
        ];
        rows[0].thumbnail = Some("thumbs/a.png".into());
        rows[1].thumbnail = Some("thumbs/missing.png".into());
        crate::front::mark_fronts(&mut rows);
        let sections = pareto_sections(&rows, "head.obj", dir.path());
        let headings: Vec<&str> = sections.iter().map(|s| s.heading.as_str()).collect();
        assert_eq!(
            headings,
            [
                "Quality against size",
                "Quality against frame time",
                "ꟻLIP against size",
                "Every setting",
                "Thumbnails"
            ]
        );
        for s in &sections[..3] {
            assert_eq!(s.charts.len(), 1, "{}: {}", s.heading, s.text);
        }
        assert!(sections[1].text.contains("Test GPU"));
        let Some(table) = &sections[3].table else {
            panic!("no table");
        };
        assert_eq!(table.columns.len(), 17);
        assert_eq!(table.rows.len(), 3);
        assert!(table.rows.iter().all(|r| r.len() == 17));
        assert_eq!(table.rows[1][5].text, "10 kB");
        assert_eq!(table.rows[2][13].text, "–");
        let thumbs = &sections[4];
        assert_eq!(thumbs.images.len(), 1);
        assert!(thumbs.text.contains("thumbs/missing.png"), "{}", thumbs.text);
        let path = dir.path().join("report.html");
        write_html_report(&path, "sweep", &sections)?;
        assert!(std::fs::read_to_string(&path)?.contains("data:image/png;base64,"));

        // Without frame times or thumbnails: no such sections; no rows: one note.
        let plain = vec![row("a", 1_000, 25.0, None)];
        assert_eq!(pareto_sections(&plain, "x", dir.path()).len(), 3);
        let empty = pareto_sections(&[], "x", dir.path());
        assert_eq!(empty.len(), 1);
        assert!(empty[0].charts.is_empty());
        Ok(())
    }
}
