//! The SVG chart engine: scatter charts of [`Series`] with highlighted points joined
//! (Pareto fronts), an optional dashed threshold, log or linear x axes and a legend in
//! the emptiest corner, drawn with `plotters` ([`chart_svg`]).
//!
//! Charts need no fonts: `plotters` is built without its font features, so it
//! estimates text extents for layout and writes the text as SVG `<text>` elements,
//! which the browser showing the report draws in its own `sans-serif` font.

use std::ops::Range;

use plotters::coord::Shift;
use plotters::coord::ranged1d::{AsRangedCoord, ValueFormatter};
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use super::error::ReportError;

/// One set of points on a [`Chart`], in one colour with one legend entry.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Series {
    /// Legend text; empty for no legend entry.
    pub name: String,
    /// `(x, y)` points. Non-finite points (and points with `x ≤ 0` on a log x axis)
    /// are left out.
    pub points: Vec<(f64, f64)>,
    /// Per point (missing entries count as `false`): drawn larger, and joined in
    /// order of x by a line (e.g. the points on a Pareto front).
    pub highlight: Vec<bool>,
}

/// A scatter chart of one or more [`Series`], drawn by [`chart_svg`].
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Chart {
    /// Caption above the chart.
    pub title: String,
    /// X axis description.
    pub x_label: String,
    /// Y axis description.
    pub y_label: String,
    /// Logarithmic x axis.
    pub log_x: bool,
    /// The series, drawn in order (later ones on top).
    pub series: Vec<Series>,
    /// A dashed horizontal line at this y, labelled with its value.
    pub threshold_y: Option<f64>,
}

const CHART_SIZE: (u32, u32) = (760, 440);

/// Okabe–Ito colours, told apart by people with colour-vision deficiencies.
const PALETTE: [RGBColor; 7] = [
    RGBColor(0, 114, 178),
    RGBColor(213, 94, 0),
    RGBColor(0, 158, 115),
    RGBColor(204, 121, 167),
    RGBColor(230, 159, 0),
    RGBColor(86, 180, 233),
    RGBColor(0, 0, 0),
];

const THRESHOLD_COLOUR: RGBColor = RGBColor(200, 30, 30);

/// A finite, non-empty plotting range covering `values` with a margin; a single
/// value or none gets a range around it (or a default one).
fn axis_range(values: impl Iterator<Item = f64>, log: bool) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in values.filter(|v| v.is_finite() && (!log || *v > 0.0)) {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    let default = if log { (1.0, 10.0) } else { (0.0, 1.0) };
    if lo > hi {
        return default;
    }
    let (lo, hi) = if log {
        let factor = if lo == hi { 2.0 } else { (hi / lo).powf(0.05) };
        (lo / factor, hi * factor)
    } else {
        let pad = if lo == hi {
            if lo == 0.0 { 1.0 } else { lo.abs() * 0.1 }
        } else {
            (hi - lo) * 0.05
        };
        (lo - pad, hi + pad)
    };
    if lo < hi && (hi - lo).is_finite() && lo.is_finite() && hi.is_finite() && (!log || lo > 0.0) {
        (lo, hi)
    } else {
        default
    }
}

/// A tick label with at most three significant digits and an SI suffix from 10³ up
/// (`512`, `2.5k`, `12M`), for logarithmic axes.
fn si_label(v: f64) -> String {
    if !v.is_finite() || v == 0.0 {
        return v.to_string();
    }
    let a = v.abs();
    if a < 1e-3 {
        return format!("{v:.1e}");
    }
    let (m, suffix) = si_split(v);
    format!("{}{suffix}", sig3(m))
}

/// `v` as a mantissa and SI suffix (`k` from 10³ to `T` from 10¹²).
pub(super) fn si_split(v: f64) -> (f64, &'static str) {
    match v.abs() {
        a if a >= 1e12 => (v / 1e12, "T"),
        a if a >= 1e9 => (v / 1e9, "G"),
        a if a >= 1e6 => (v / 1e6, "M"),
        a if a >= 1e3 => (v / 1e3, "k"),
        _ => (v, ""),
    }
}

/// `v` with three significant digits, trailing zeros trimmed.
pub(super) fn sig3(v: f64) -> String {
    let decimals = (2 - v.abs().log10().floor() as i32).clamp(0, 9) as usize;
    let s = format!("{v:.decimals$}");
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    }
}

/// Of the four corners, the one with the fewest points near it, for the legend.
fn emptiest_corner(points: &[(f64, f64)], x: (f64, f64), y: (f64, f64), log_x: bool) -> SeriesLabelPosition {
    let fx = |v: f64| {
        if log_x {
            (v.ln() - x.0.ln()) / (x.1.ln() - x.0.ln())
        } else {
            (v - x.0) / (x.1 - x.0)
        }
    };
    let fy = |v: f64| (v - y.0) / (y.1 - y.0);
    let corners = [
        (SeriesLabelPosition::UpperRight, true, true),
        (SeriesLabelPosition::LowerRight, true, false),
        (SeriesLabelPosition::UpperLeft, false, true),
        (SeriesLabelPosition::LowerLeft, false, false),
    ];
    let mut best = (SeriesLabelPosition::UpperRight, usize::MAX);
    for (corner, right, upper) in corners {
        let count = points
            .iter()
            .filter(|&&(px, py)| {
                let (u, v) = (fx(px), fy(py));
                (if right { u > 0.55 } else { u < 0.45 }) && (if upper { v > 0.6 } else { v < 0.4 })
            })
            .count();
        if count < best.1 {
            best = (corner, count);
        }
    }
    best.0
}

/// Draws `chart` as an SVG document (`<svg …>…</svg>`, 760 × 440 user units).
/// Empty series, single points, constant values and non-finite values are drawn
/// without failing (the axes then get a range around the value, or a default one).
pub fn chart_svg(chart: &Chart) -> Result<String, ReportError> {
    let usable = |&(x, y): &(f64, f64)| x.is_finite() && y.is_finite() && (!chart.log_x || x > 0.0);
    let series: Vec<Plotted> = chart
        .series
        .iter()
        .map(|s| {
            let points = s
                .points
                .iter()
                .enumerate()
                .filter(|(_, p)| usable(p))
                .map(|(i, &p)| (p, s.highlight.get(i).copied().unwrap_or(false)))
                .collect();
            (s.name.clone(), points)
        })
        .collect();
    let all: Vec<(f64, f64)> = series
        .iter()
        .flat_map(|(_, ps)| ps.iter().map(|&(p, _)| p))
        .collect();
    let threshold = chart.threshold_y.filter(|t| t.is_finite());
    let x = axis_range(all.iter().map(|p| p.0), chart.log_x);
    let y = axis_range(all.iter().map(|p| p.1).chain(threshold), false);
    // Whole-number x values over a short span (view counts, category indices): a
    // tick at each whole number and no fractional labels.
    let integer_ticks =
        (!chart.log_x && !all.is_empty() && all.iter().all(|p| p.0.fract() == 0.0) && x.1 - x.0 <= 22.0)
            .then(|| (x.1 - x.0).floor() as usize + 1);
    let layout = Layout {
        threshold,
        legend_at: emptiest_corner(&all, x, y, chart.log_x),
        integer_ticks,
    };

    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, CHART_SIZE).into_drawing_area();
        let drawn = if chart.log_x {
            draw_chart(&root, chart, &series, &layout, (x.0..x.1).log_scale(), y.0..y.1)
        } else {
            draw_chart(&root, chart, &series, &layout, x.0..x.1, y.0..y.1)
        };
        drawn
            .and_then(|()| root.present().map_err(|e| e.to_string()))
            .map_err(|message| ReportError::Chart {
                title: chart.title.clone(),
                message,
            })?;
    }
    Ok(svg)
}

/// A series' name and its drawable points, each with its highlight flag.
type Plotted = (String, Vec<((f64, f64), bool)>);

/// What [`chart_svg`] works out about a chart before drawing it.
struct Layout {
    /// The finite threshold, if any.
    threshold: Option<f64>,
    /// Where the legend goes.
    legend_at: SeriesLabelPosition,
    /// Label only whole-number x ticks, about this many.
    integer_ticks: Option<usize>,
}

fn draw_chart<XR>(
    root: &DrawingArea<SVGBackend<'_>, Shift>,
    chart: &Chart,
    series: &[Plotted],
    layout: &Layout,
    x: XR,
    y: Range<f64>,
) -> Result<(), String>
where
    XR: AsRangedCoord<Value = f64>,
    XR::CoordDescType: ValueFormatter<f64>,
{
    let err = |e: &dyn std::fmt::Display| e.to_string();
    root.fill(&WHITE).map_err(|e| err(&e))?;
    let mut ctx = ChartBuilder::on(root)
        .caption(&chart.title, ("sans-serif", 20))
        .margin(12)
        .x_label_area_size(46)
        .y_label_area_size(64)
        .build_cartesian_2d(x, y.clone())
        .map_err(|e| err(&e))?;
    let x_range = ctx.x_range();
    let si = |v: &f64| si_label(*v);
    let mut mesh = ctx.configure_mesh();
    mesh.x_desc(&chart.x_label)
        .y_desc(&chart.y_label)
        .label_style(("sans-serif", 13))
        .axis_desc_style(("sans-serif", 15))
        .light_line_style(RGBColor(235, 235, 235))
        .bold_line_style(RGBColor(215, 215, 215));
    let whole = |v: &f64| {
        if v.fract() == 0.0 {
            format!("{v:.0}")
        } else {
            String::new()
        }
    };
    if chart.log_x {
        mesh.x_label_formatter(&si);
    } else if let Some(n) = layout.integer_ticks {
        mesh.x_labels(n.clamp(2, 24)).x_label_formatter(&whole);
    }
    mesh.draw().map_err(|e| err(&e))?;

    let mut labelled = false;
    if let Some(t) = layout.threshold {
        ctx.draw_series(DashedLineSeries::new(
            [(x_range.start, t), (x_range.end, t)],
            8,
            5,
            THRESHOLD_COLOUR.stroke_width(2),
        ))
        .map_err(|e| err(&e))?
        .label(format!("threshold {t}"))
        .legend(|(px, py)| PathElement::new([(px, py), (px + 16, py)], THRESHOLD_COLOUR.stroke_width(2)));
        let style = ("sans-serif", 13)
            .into_font()
            .color(&THRESHOLD_COLOUR)
            .pos(Pos::new(HPos::Left, VPos::Bottom));
        ctx.draw_series(std::iter::once(Text::new(
            format!("threshold {t}"),
            (x_range.start, t),
            style,
        )))
        .map_err(|e| err(&e))?;
        labelled = true;
    }

    for (i, (name, points)) in series.iter().enumerate() {
        let colour = PALETTE[i % PALETTE.len()];
        let mut front: Vec<(f64, f64)> = points.iter().filter(|(_, h)| *h).map(|&(p, _)| p).collect();
        front.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.total_cmp(&b.1)));
        if front.len() > 1 {
            ctx.draw_series(LineSeries::new(front, colour.stroke_width(2)))
                .map_err(|e| err(&e))?;
        }
        let drawn = ctx
            .draw_series(points.iter().map(|&(p, h)| {
                if h {
                    Circle::new(p, 5, colour.filled())
                } else {
                    Circle::new(p, 4, colour.mix(0.6).filled())
                }
            }))
            .map_err(|e| err(&e))?;
        if !name.is_empty() {
            drawn
                .label(name.as_str())
                .legend(move |(px, py)| Circle::new((px + 8, py), 4, colour.filled()));
            labelled = true;
        }
    }

    if labelled {
        ctx.configure_series_labels()
            .position(layout.legend_at.clone())
            .label_font(("sans-serif", 13))
            .background_style(WHITE.mix(0.85))
            .border_style(RGBColor(190, 190, 190))
            .draw()
            .map_err(|e| err(&e))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::report::test_support::{TestResult, has_text_element};

    #[test]
    fn charts_draw_degenerate_inputs_with_their_labels_as_text() -> TestResult {
        let series = |points: Vec<(f64, f64)>, highlight: Vec<bool>| Series {
            name: "s & t".into(),
            points,
            highlight,
        };
        let cases = [
            vec![],
            vec![series(vec![], vec![])],
            vec![series(vec![(1.0, 2.0)], vec![true])],
            vec![series(
                vec![(3.0, 5.0), (3.0, 5.0), (3.0, 5.0)],
                vec![true, false],
            )],
            vec![series(vec![(0.0, 0.0), (0.0, 0.0)], vec![true, true])],
            vec![series(
                vec![
                    (f64::NAN, 1.0),
                    (1.0, f64::INFINITY),
                    (-5.0, 2.0),
                    (0.0, 3.0),
                    (1e6, 4.0),
                ],
                vec![true; 5],
            )],
            vec![
                series(
                    vec![(1e3, 20.0), (1e4, 25.0), (1e5, 31.0)],
                    vec![true, false, true],
                ),
                series(vec![(2e3, 22.0)], vec![]),
            ],
        ];
        for log_x in [false, true] {
            for (i, case) in cases.iter().enumerate() {
                for threshold_y in [None, Some(20.0), Some(f64::NAN)] {
                    let chart = Chart {
                        title: format!("case {i} <&>"),
                        x_label: "file bytes".into(),
                        y_label: "PSNR (dB)".into(),
                        log_x,
                        series: case.clone(),
                        threshold_y,
                    };
                    let svg = chart_svg(&chart)?;
                    assert!(svg.starts_with("<svg"), "{svg}");
                    assert!(svg.trim_end().ends_with("</svg>"));
                    assert!(has_text_element(&svg, "file bytes"), "case {i}: {svg}");
                    assert!(has_text_element(&svg, "PSNR (dB)"), "case {i}");
                    assert!(
                        has_text_element(&svg, &format!("case {i} &lt;&amp;&gt;")),
                        "case {i}"
                    );
                    assert!(!svg.contains("NaN"), "case {i}: {svg}");
                    if threshold_y == Some(20.0) {
                        assert!(has_text_element(&svg, "threshold 20"), "case {i}");
                    }
                    if case.iter().any(|s| !s.points.is_empty()) {
                        assert!(has_text_element(&svg, "s &amp; t"), "legend, case {i}");
                    }
                }
            }
        }
        // The log axis labels its ticks with SI suffixes.
        let chart = Chart {
            log_x: true,
            series: vec![series(vec![(1e3, 1.0), (1e6, 2.0)], vec![])],
            ..Chart::default()
        };
        let svg = chart_svg(&chart)?;
        assert!(
            has_text_element(&svg, "10k") || has_text_element(&svg, "100k"),
            "{svg}"
        );
        Ok(())
    }
}
