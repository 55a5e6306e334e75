//! Writing what `nelf eval` measured: CSV tables of the rows, JSON, SVG charts
//! (drawn with `plotters`), and one self-contained HTML report (charts inline,
//! images as base64 data URIs, a table sortable by clicking its headers, no
//! external URLs). Every file is written atomically.
//!
//! Charts need no fonts: `plotters` is built without its font features, so it
//! estimates text extents for layout and writes the text as SVG `<text>` elements,
//! which the browser showing the report draws in its own `sans-serif` font.

use std::collections::BTreeSet;
use std::fmt::Write as _;
use std::ops::Range;
use std::path::{Path, PathBuf};

use plotters::coord::Shift;
use plotters::coord::ranged1d::{AsRangedCoord, ValueFormatter};
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use serde::Serialize;

use crate::rows::{ParetoRow, Scores, StabilityPoint};

/// What went wrong writing a report, and where.
#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    /// A file could not be written.
    #[error("could not write {}: {source}", .path.display())]
    Write {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// A file the report embeds could not be read.
    #[error("could not read {}: {source}", .path.display())]
    Read {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// A value could not be serialised to JSON.
    #[error("could not serialise JSON for {}: {source}", .path.display())]
    Json {
        /// The file it was for.
        path: PathBuf,
        /// The serialisation error.
        source: serde_json::Error,
    },
    /// `plotters` failed to draw a chart.
    #[error("could not draw the chart \"{title}\": {message}")]
    Chart {
        /// The chart's title.
        title: String,
        /// What `plotters` reported.
        message: String,
    },
}

fn write_file(path: &Path, bytes: &[u8]) -> Result<(), ReportError> {
    nelf_format::atomic::write_bytes_atomically(path, bytes).map_err(|source| ReportError::Write {
        path: path.to_path_buf(),
        source,
    })
}

// ---------------------------------------------------------------------------------
// CSV and JSON
// ---------------------------------------------------------------------------------

/// The columns the flattened [`Scores`] take in the CSV files, in order.
const SCORE_COLUMNS: [&str; 9] = [
    "psnr_db",
    "psnr_fg_db",
    "ssim",
    "ssim_fg",
    "flip",
    "flip_fg",
    "baseline_psnr_db",
    "baseline_psnr_fg_db",
    "views",
];

/// One CSV field with RFC 4180 quoting: fields holding a comma, a double quote, a
/// carriage return or a line feed are enclosed in double quotes, with the double
/// quotes inside doubled.
fn push_csv_field(line: &mut String, field: &str) {
    if !line.is_empty() {
        line.push(',');
    }
    if field.contains([',', '"', '\r', '\n']) {
        line.push('"');
        line.push_str(&field.replace('"', "\"\""));
        line.push('"');
    } else {
        line.push_str(field);
    }
}

fn csv_line(fields: impl IntoIterator<Item = String>) -> String {
    let mut line = String::new();
    for field in fields {
        push_csv_field(&mut line, &field);
    }
    line.push('\n');
    line
}

fn score_fields(s: &Scores) -> [String; 9] {
    [
        s.psnr_db.to_string(),
        s.psnr_fg_db.to_string(),
        s.ssim.to_string(),
        s.ssim_fg.to_string(),
        s.flip.to_string(),
        s.flip_fg.to_string(),
        s.baseline_psnr_db.to_string(),
        s.baseline_psnr_fg_db.to_string(),
        s.views.to_string(),
    ]
}

fn opt<T: ToString>(value: Option<&T>) -> String {
    value.map(ToString::to_string).unwrap_or_default()
}

/// The CSV text [`write_csv`] writes: one header line, then one line per row, `\n`
/// line ends; [`Scores`] flattened into their fields, `None` as an empty cell,
/// floats in Rust's shortest round-trip form (`NaN`, `inf` as such).
#[must_use]
pub fn pareto_csv(rows: &[ParetoRow]) -> String {
    let header = [
        "id",
        "resolution",
        "rank",
        "encoding",
        "voxels",
        "file_bytes",
        "bake_secs",
    ]
    .into_iter()
    .chain(SCORE_COLUMNS)
    .chain([
        "cpu_render_ms",
        "gpu_frame_ms_512",
        "gpu_frame_ms_1080p",
        "gpu_adapter",
        "thumbnail",
        "front_bytes",
        "front_frame",
    ])
    .map(String::from);
    let mut text = csv_line(header);
    for r in rows {
        let fields = [
            r.id.clone(),
            r.resolution.to_string(),
            r.rank.to_string(),
            r.encoding.clone(),
            r.voxels.to_string(),
            r.file_bytes.to_string(),
            r.bake_secs.to_string(),
        ]
        .into_iter()
        .chain(score_fields(&r.scores))
        .chain([
            r.cpu_render_ms.to_string(),
            opt(r.gpu_frame_ms_512.as_ref()),
            opt(r.gpu_frame_ms_1080p.as_ref()),
            opt(r.gpu_adapter.as_ref()),
            opt(r.thumbnail.as_ref()),
            r.front_bytes.to_string(),
            r.front_frame.to_string(),
        ]);
        text.push_str(&csv_line(fields));
    }
    text
}

/// The CSV text [`write_stability_csv`] writes, in [`pareto_csv`]'s form.
#[must_use]
pub fn stability_csv(points: &[StabilityPoint]) -> String {
    let header = ["axis", "value", "label"]
        .into_iter()
        .chain(SCORE_COLUMNS)
        .chain(["worst_psnr_db", "gallery", "failure"])
        .map(String::from);
    let mut text = csv_line(header);
    for p in points {
        let fields = [p.axis.clone(), p.value.to_string(), p.label.clone()]
            .into_iter()
            .chain(score_fields(&p.scores))
            .chain([
                p.worst_psnr_db.to_string(),
                opt(p.gallery.as_ref()),
                opt(p.failure.as_ref()),
            ]);
        text.push_str(&csv_line(fields));
    }
    text
}

/// Writes the rows of a Pareto sweep as CSV ([`pareto_csv`]), atomically.
pub fn write_csv(path: &Path, rows: &[ParetoRow]) -> Result<(), ReportError> {
    write_file(path, pareto_csv(rows).as_bytes())
}

/// Writes the points of stability axes as CSV ([`stability_csv`]), atomically.
pub fn write_stability_csv(path: &Path, points: &[StabilityPoint]) -> Result<(), ReportError> {
    write_file(path, stability_csv(points).as_bytes())
}

/// Writes `value` as pretty-printed JSON with a final line feed, atomically.
pub fn write_json(path: &Path, value: &impl Serialize) -> Result<(), ReportError> {
    let mut bytes = serde_json::to_vec_pretty(value).map_err(|source| ReportError::Json {
        path: path.to_path_buf(),
        source,
    })?;
    bytes.push(b'\n');
    write_file(path, &bytes)
}

// ---------------------------------------------------------------------------------
// Charts
// ---------------------------------------------------------------------------------

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
fn si_split(v: f64) -> (f64, &'static str) {
    match v.abs() {
        a if a >= 1e12 => (v / 1e12, "T"),
        a if a >= 1e9 => (v / 1e9, "G"),
        a if a >= 1e6 => (v / 1e6, "M"),
        a if a >= 1e3 => (v / 1e3, "k"),
        _ => (v, ""),
    }
}

/// `v` with three significant digits, trailing zeros trimmed.
fn sig3(v: f64) -> String {
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

// ---------------------------------------------------------------------------------
// HTML
// ---------------------------------------------------------------------------------

/// One cell of a [`Table`].
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Cell {
    /// What the cell shows (escaped when written).
    pub text: String,
    /// The value clicking the column header sorts by; `None` sorts as text, after
    /// the cells that have a key when the column has some. Non-finite keys other
    /// than ±∞ count as `None`.
    pub sort_key: Option<f64>,
    /// Drawn emphasised (e.g. on the Pareto front).
    pub highlight: bool,
}

impl Cell {
    /// A text cell.
    #[must_use]
    pub fn text(text: impl Into<String>) -> Self {
        Self {
            text: text.into(),
            ..Self::default()
        }
    }

    /// A numeric cell showing `text` and sorting by `key`.
    #[must_use]
    pub fn number(text: impl Into<String>, key: f64) -> Self {
        Self {
            text: text.into(),
            sort_key: Some(key),
            highlight: false,
        }
    }

    /// The same cell, highlighted if `on`.
    #[must_use]
    pub fn highlighted(mut self, on: bool) -> Self {
        self.highlight = on;
        self
    }
}

/// A table in a [`Section`]; clicking a header sorts the rows by that column.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Table {
    /// Column headers.
    pub columns: Vec<String>,
    /// Rows of cells (a row may be shorter than `columns`).
    pub rows: Vec<Vec<Cell>>,
}

/// One section of an HTML report ([`write_html_report`]).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Section {
    /// The section's heading.
    pub heading: String,
    /// Prose, escaped when written: blank lines separate paragraphs, single line
    /// feeds become line breaks.
    pub text: String,
    /// SVG documents (e.g. from [`chart_svg`]), inserted as they are.
    pub charts: Vec<String>,
    /// A sortable table.
    pub table: Option<Table>,
    /// `(caption, file)` of images (PNG, or JPEG by extension) to embed.
    pub images: Vec<(String, PathBuf)>,
}

/// `text` with `& < > " '` replaced by character references, for HTML text and
/// attribute values.
#[must_use]
pub fn escape_html(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            _ => out.push(c),
        }
    }
    out
}

/// Standard base64 (RFC 4648, with `=` padding), for data URIs.
fn base64(bytes: &[u8]) -> String {
    const ALPHABET: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::with_capacity(bytes.len().div_ceil(3) * 4);
    for chunk in bytes.chunks(3) {
        let b = [chunk[0], *chunk.get(1).unwrap_or(&0), *chunk.get(2).unwrap_or(&0)];
        let n = (u32::from(b[0]) << 16) | (u32::from(b[1]) << 8) | u32::from(b[2]);
        for i in 0..4 {
            if i <= chunk.len() {
                out.push(char::from(ALPHABET[(n >> (18 - 6 * i) & 63) as usize]));
            } else {
                out.push('=');
            }
        }
    }
    out
}

fn mime_type(path: &Path) -> &'static str {
    match path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
        .as_deref()
    {
        Some("jpg" | "jpeg") => "image/jpeg",
        Some("svg") => "image/svg+xml",
        Some("webp") => "image/webp",
        _ => "image/png",
    }
}

const STYLE: &str = "body{font-family:system-ui,-apple-system,'Segoe UI',sans-serif;color:#222;\
max-width:1200px;margin:2em auto;padding:0 1em;line-height:1.45}\
h1{font-size:1.7em}h2{font-size:1.3em;border-bottom:1px solid #ccc;padding-bottom:.2em;margin-top:2.2em}\
nav ul{padding-left:1.2em}.chart svg{max-width:100%;height:auto;display:block;margin:1em 0}\
.scroll{overflow-x:auto}table{border-collapse:collapse;font-size:.85em;margin:1em 0}\
th,td{border:1px solid #ddd;padding:.25em .55em;text-align:right;white-space:nowrap}\
td.t,th{text-align:left}th{background:#f2f2f2;cursor:pointer;user-select:none}\
th[aria-sort=ascending]::after{content:' \\25B2'}th[aria-sort=descending]::after{content:' \\25BC'}\
td.hi{background:#fff1b8;font-weight:600}.gallery{display:flex;flex-wrap:wrap;gap:1em}\
figure{margin:0;max-width:100%}figure img{max-width:100%;display:block}\
figcaption{font-size:.85em;color:#555}";

/// Sorts a table's body by the clicked column: numerically by `data-sort` where
/// both cells have one (cells without sort after), else as text; a second click
/// reverses.
const SCRIPT: &str = r"document.querySelectorAll('table.sortable').forEach(function (table) {
  var heads = table.querySelectorAll('th');
  heads.forEach(function (th, col) {
    th.addEventListener('click', function () {
      var asc = th.getAttribute('aria-sort') !== 'ascending';
      heads.forEach(function (h) { h.removeAttribute('aria-sort'); });
      th.setAttribute('aria-sort', asc ? 'ascending' : 'descending');
      var body = table.tBodies[0];
      var rows = Array.prototype.slice.call(body.rows);
      rows.sort(function (a, b) {
        var x = a.cells[col], y = b.cells[col];
        var kx = x ? x.getAttribute('data-sort') : null;
        var ky = y ? y.getAttribute('data-sort') : null;
        if (kx !== null && ky === null) return -1;
        if (kx === null && ky !== null) return 1;
        var c = kx !== null ? parseFloat(kx) - parseFloat(ky)
          : (x ? x.textContent : '').localeCompare(y ? y.textContent : '');
        if (c !== c) c = 0;
        return asc ? c : -c;
      });
      rows.forEach(function (r) { body.appendChild(r); });
    });
  });
});";

fn push_paragraphs(html: &mut String, text: &str) {
    for para in text.split("\n\n").map(str::trim).filter(|p| !p.is_empty()) {
        let lines: Vec<String> = para.lines().map(escape_html).collect();
        let _ = writeln!(html, "<p>{}</p>", lines.join("<br>"));
    }
}

fn push_table(html: &mut String, table: &Table) {
    html.push_str("<div class=\"scroll\"><table class=\"sortable\">\n<thead><tr>");
    for c in &table.columns {
        let _ = write!(html, "<th>{}</th>", escape_html(c));
    }
    html.push_str("</tr></thead>\n<tbody>\n");
    for row in &table.rows {
        html.push_str("<tr>");
        for cell in row {
            let mut classes = Vec::new();
            if cell.sort_key.is_none() {
                classes.push("t");
            }
            if cell.highlight {
                classes.push("hi");
            }
            html.push_str("<td");
            if !classes.is_empty() {
                let _ = write!(html, " class=\"{}\"", classes.join(" "));
            }
            match cell.sort_key {
                Some(k) if k.is_finite() => {
                    let _ = write!(html, " data-sort=\"{k}\"");
                }
                Some(k) if k == f64::INFINITY => html.push_str(" data-sort=\"Infinity\""),
                Some(k) if k == f64::NEG_INFINITY => html.push_str(" data-sort=\"-Infinity\""),
                _ => {}
            }
            let _ = write!(html, ">{}</td>", escape_html(&cell.text));
        }
        html.push_str("</tr>\n");
    }
    html.push_str("</tbody></table></div>\n");
}

/// An SVG document without an XML declaration or doctype before `<svg`, to inline.
fn inline_svg(svg: &str) -> &str {
    svg.find("<svg").map_or(svg, |i| &svg[i..])
}

/// The HTML text [`write_html_report`] writes; reads the images.
pub fn html_report(title: &str, sections: &[Section]) -> Result<String, ReportError> {
    let mut html = String::new();
    let _ = writeln!(
        html,
        "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n\
         <meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n\
         <title>{}</title>\n<style>{STYLE}</style>\n</head>\n<body>\n<h1>{}</h1>",
        escape_html(title),
        escape_html(title),
    );
    if sections.len() > 1 {
        html.push_str("<nav><ul>\n");
        for (i, s) in sections.iter().enumerate() {
            let _ = writeln!(html, "<li><a href=\"#s{i}\">{}</a></li>", escape_html(&s.heading));
        }
        html.push_str("</ul></nav>\n");
    }
    for (i, s) in sections.iter().enumerate() {
        let _ = writeln!(
            html,
            "<section id=\"s{i}\">\n<h2>{}</h2>",
            escape_html(&s.heading)
        );
        push_paragraphs(&mut html, &s.text);
        for svg in &s.charts {
            let _ = writeln!(html, "<div class=\"chart\">{}</div>", inline_svg(svg));
        }
        if let Some(table) = &s.table {
            push_table(&mut html, table);
        }
        if !s.images.is_empty() {
            html.push_str("<div class=\"gallery\">\n");
            for (caption, path) in &s.images {
                let bytes = std::fs::read(path).map_err(|source| ReportError::Read {
                    path: path.clone(),
                    source,
                })?;
                let caption = escape_html(caption);
                let _ = writeln!(
                    html,
                    "<figure><img src=\"data:{};base64,{}\" alt=\"{caption}\">\
                     <figcaption>{caption}</figcaption></figure>",
                    mime_type(path),
                    base64(&bytes),
                );
            }
            html.push_str("</div>\n");
        }
        html.push_str("</section>\n");
    }
    let _ = writeln!(html, "<script>\n{SCRIPT}\n</script>\n</body>\n</html>");
    Ok(html)
}

/// Writes a self-contained HTML report (no external URLs: charts inline, images
/// embedded as base64 data URIs, inline CSS and a small script that sorts tables
/// by a clicked header), atomically. Fails if an image cannot be read.
pub fn write_html_report(path: &Path, title: &str, sections: &[Section]) -> Result<(), ReportError> {
    let html = html_report(title, sections)?;
    write_file(path, html.as_bytes())
}

/// Writes every chart of `sections` as its own SVG file in `dir` (created), named
/// after its section's heading (`quality-against-size.svg`,
/// `flip-against-size.svg`, `stability-views.svg`, …; a second chart of a section
/// gets `-2`): for documents that show one chart without
/// the whole report. Returns the paths written.
pub fn write_chart_files(dir: &Path, sections: &[Section]) -> Result<Vec<std::path::PathBuf>, ReportError> {
    std::fs::create_dir_all(dir).map_err(|source| ReportError::Write {
        path: dir.to_path_buf(),
        source,
    })?;
    let mut written = Vec::new();
    for section in sections {
        let title = section.heading.replace('ꟻ', "f");
        let slug: String = title
            .chars()
            .map(|c| {
                if c.is_ascii_alphanumeric() {
                    c.to_ascii_lowercase()
                } else {
                    '-'
                }
            })
            .collect::<String>()
            .split('-')
            .filter(|w| !w.is_empty())
            .collect::<Vec<_>>()
            .join("-");
        for (i, svg) in section.charts.iter().enumerate() {
            let name = if i == 0 {
                format!("{slug}.svg")
            } else {
                format!("{slug}-{}.svg", i + 1)
            };
            let path = dir.join(name);
            write_file(&path, svg.as_bytes())?;
            written.push(path);
        }
    }
    Ok(written)
}

// ---------------------------------------------------------------------------------
// The report's sections
// ---------------------------------------------------------------------------------

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

/// A chart's rendering, or a note saying why there is none (so one bad chart does
/// not lose the report).
fn chart_or_note(chart: &Chart, charts: &mut Vec<String>, text: &mut String) {
    match chart_svg(chart) {
        Ok(svg) => charts.push(svg),
        Err(e) => {
            let _ = write!(text, "\n\n{e}");
        }
    }
}

/// The images among `wanted` (`(caption, path relative to report_dir)`) that exist,
/// and a note naming those that do not.
fn existing_images(
    report_dir: &Path,
    wanted: impl IntoIterator<Item = (String, String)>,
) -> (Vec<(String, PathBuf)>, Option<String>) {
    let mut found = Vec::new();
    let mut missing = Vec::new();
    for (caption, rel) in wanted {
        let path = report_dir.join(&rel);
        if path.is_file() {
            found.push((caption, path));
        } else {
            missing.push(rel);
        }
    }
    let note = (!missing.is_empty()).then(|| {
        format!(
            "{} image(s) not found under {} and left out: {}.",
            missing.len(),
            report_dir.display(),
            missing.join(", ")
        )
    });
    (found, note)
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

    type TestResult = Result<(), Box<dyn std::error::Error>>;

    /// A minimal RFC 4180 reader: records of fields.
    fn parse_csv(text: &str) -> Vec<Vec<String>> {
        let mut records = Vec::new();
        let mut record = Vec::new();
        let mut field = String::new();
        let mut quoted = false;
        let mut chars = text.chars().peekable();
        while let Some(c) = chars.next() {
            match (quoted, c) {
                (true, '"') if chars.peek() == Some(&'"') => {
                    chars.next();
                    field.push('"');
                }
                (true, '"') => quoted = false,
                (false, '"') => quoted = true,
                (false, ',') => record.push(std::mem::take(&mut field)),
                (false, '\n') => {
                    record.push(std::mem::take(&mut field));
                    records.push(std::mem::take(&mut record));
                }
                (_, c) => field.push(c),
            }
        }
        assert!(field.is_empty() && record.is_empty(), "text ends mid-record");
        records
    }

    fn row(id: &str, bytes: u64, psnr: f64, frame: Option<f64>) -> ParetoRow {
        ParetoRow {
            id: id.into(),
            resolution: 128,
            rank: 16,
            encoding: "u8".into(),
            voxels: 1000,
            file_bytes: bytes,
            bake_secs: 2.5,
            scores: Scores {
                psnr_db: psnr,
                psnr_fg_db: psnr - 3.0,
                ssim: 0.9,
                ssim_fg: 0.8,
                flip: 0.1 - psnr / 1000.0,
                flip_fg: 0.2,
                baseline_psnr_db: 12.0,
                baseline_psnr_fg_db: 9.0,
                views: 4,
            },
            cpu_render_ms: 120.0,
            gpu_frame_ms_512: frame,
            gpu_frame_ms_1080p: None,
            gpu_adapter: frame.map(|_| "Test GPU".into()),
            thumbnail: None,
            front_bytes: false,
            front_frame: false,
        }
    }

    fn point(axis: &str, value: f64, label: &str, psnr: f64) -> StabilityPoint {
        StabilityPoint {
            axis: axis.into(),
            value,
            label: label.into(),
            scores: Scores {
                psnr_db: psnr,
                psnr_fg_db: psnr - 2.0,
                baseline_psnr_db: 11.0,
                views: 3,
                ..Scores::default()
            },
            worst_psnr_db: psnr - 4.0,
            gallery: None,
            failure: None,
        }
    }

    /// Whether `svg` holds `text` as the content of a `<text>` element.
    fn has_text_element(svg: &str, text: &str) -> bool {
        svg.split("<text").skip(1).any(|element| {
            element
                .split_once('>')
                .and_then(|(_, rest)| rest.split_once("</text>"))
                .is_some_and(|(content, _)| content.trim() == text)
        })
    }

    fn tiny_png(path: &Path) -> TestResult {
        let img = image::RgbImage::from_fn(2, 2, |x, y| image::Rgb([x as u8 * 200, y as u8 * 200, 7]));
        img.save(path)?;
        Ok(())
    }

    #[test]
    fn base64_matches_rfc_4648_vectors() {
        let cases = [
            ("", ""),
            ("f", "Zg=="),
            ("fo", "Zm8="),
            ("foo", "Zm9v"),
            ("foob", "Zm9vYg=="),
            ("fooba", "Zm9vYmE="),
            ("foobar", "Zm9vYmFy"),
        ];
        for (plain, encoded) in cases {
            assert_eq!(base64(plain.as_bytes()), encoded);
        }
        assert_eq!(base64(&[0xff, 0xfe, 0xfd]), "//79");
    }

    #[test]
    fn csv_has_one_header_a_line_per_row_and_quotes_where_needed() -> TestResult {
        let mut rows = vec![
            row("plain", 100, 30.0, Some(1.5)),
            row("r,1 \"x\"", 200, 31.0, None),
        ];
        rows[1].gpu_adapter = Some("line\nbreak".into());
        let text = pareto_csv(&rows);
        let records = parse_csv(&text);
        assert_eq!(records.len(), 1 + rows.len());
        let header = &records[0];
        assert_eq!(header.len(), 23);
        assert_eq!(header[0], "id");
        assert_eq!(header[7..16], SCORE_COLUMNS.map(String::from));
        assert!(records.iter().all(|r| r.len() == header.len()));
        assert!(text.contains("\"r,1 \"\"x\"\"\""), "{text}");
        assert_eq!(records[2][0], "r,1 \"x\"");
        let col = |name: &str| header.iter().position(|h| h == name).ok_or(name.to_string());
        assert_eq!(records[1][col("gpu_frame_ms_512")?], "1.5");
        assert_eq!(records[2][col("gpu_frame_ms_512")?], "", "None is an empty cell");
        assert_eq!(records[2][col("gpu_adapter")?], "line\nbreak");
        assert_eq!(records[1][col("views")?], "4");

        let dir = tempfile::tempdir()?;
        let path = dir.path().join("pareto.csv");
        write_csv(&path, &rows)?;
        assert_eq!(std::fs::read_to_string(&path)?, text);

        let mut points = vec![
            point("views", 2.0, "2 views", 18.0),
            point("hdri", 0.0, "a, b.exr", 25.0),
        ];
        points[0].gallery = Some("g/2.png".into());
        let path = dir.path().join("stability.csv");
        write_stability_csv(&path, &points)?;
        let records = parse_csv(&std::fs::read_to_string(&path)?);
        assert_eq!(records.len(), 3);
        assert_eq!(records[0].len(), 3 + 9 + 3);
        assert_eq!(records[0][..3], ["axis", "value", "label"].map(String::from));
        assert_eq!(records[2][2], "a, b.exr");
        let gallery = records[0].len() - 2;
        assert_eq!(records[1][gallery], "g/2.png");
        assert_eq!(records[2][gallery], "");
        assert_eq!(records[1].last().map(String::as_str), Some(""), "no failure");
        Ok(())
    }

    #[test]
    fn json_round_trips() -> TestResult {
        let dir = tempfile::tempdir()?;
        let path = dir.path().join("rows.json");
        let rows = vec![row("a", 1, 20.0, None)];
        write_json(&path, &rows)?;
        let back: Vec<ParetoRow> = serde_json::from_str(&std::fs::read_to_string(&path)?)?;
        assert_eq!(back, rows);
        Ok(())
    }

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

    #[test]
    fn html_report_is_self_contained_with_charts_table_and_images() -> TestResult {
        let dir = tempfile::tempdir()?;
        let png = dir.path().join("tiny.png");
        tiny_png(&png)?;
        let svg = chart_svg(&Chart {
            title: "chart one".into(),
            x_label: "x".into(),
            y_label: "y".into(),
            series: vec![Series {
                name: "pts".into(),
                points: vec![(1.0, 1.0), (2.0, 3.0)],
                highlight: vec![true, true],
            }],
            ..Chart::default()
        })?;
        let sections = [
            Section {
                heading: "First <one>".into(),
                text: "a & b\nnext line\n\nsecond \"paragraph\"".into(),
                charts: vec![svg.clone()],
                table: Some(Table {
                    columns: vec!["name".into(), "value".into()],
                    rows: vec![
                        vec![Cell::text("x<y"), Cell::number("1.50", 1.5).highlighted(true)],
                        vec![Cell::text("z"), Cell::number("∞", f64::INFINITY)],
                        vec![Cell::text("w"), Cell::number("?", f64::NAN)],
                    ],
                }),
                images: vec![("tiny & small".into(), png.clone())],
            },
            Section {
                heading: "Second".into(),
                ..Section::default()
            },
        ];
        let path = dir.path().join("report.html");
        write_html_report(&path, "Report <title>", &sections)?;
        let html = std::fs::read_to_string(&path)?;
        assert!(html.starts_with("<!DOCTYPE html>"));
        assert!(html.contains("<title>Report &lt;title&gt;</title>"));
        assert!(html.contains("<h2>First &lt;one&gt;</h2>"));
        assert!(html.contains("<p>a &amp; b<br>next line</p>"));
        assert!(html.contains("<p>second &quot;paragraph&quot;</p>"));
        assert!(html.contains(&svg), "the chart inline, as it is");
        assert!(html.contains("<table class=\"sortable\">"));
        assert!(html.contains("<th>name</th><th>value</th>"));
        assert!(html.contains("<td class=\"t\">x&lt;y</td><td class=\"hi\" data-sort=\"1.5\">1.50</td>"));
        assert!(html.contains("data-sort=\"Infinity\""));
        assert!(!html.contains("data-sort=\"NaN\""));
        let data_uri = format!("data:image/png;base64,{}", base64(&std::fs::read(&png)?));
        assert!(data_uri.starts_with("data:image/png;base64,iVBORw0KGgo"), "a PNG");
        assert!(html.contains(&format!("<img src=\"{data_uri}\" alt=\"tiny &amp; small\">")));
        assert!(html.contains("<script>") && html.contains("addEventListener('click'"));
        assert!(html.contains("href=\"#s1\">Second</a>"));
        // No external resources: the only URL is the SVG namespace name.
        let without_ns = html.replace("xmlns=\"http://www.w3.org/2000/svg\"", "");
        assert!(
            !without_ns.contains("http:") && !without_ns.contains("https:") && !without_ns.contains("//cdn")
        );

        let missing = [Section {
            images: vec![("gone".into(), dir.path().join("gone.png"))],
            ..Section::default()
        }];
        let Err(ReportError::Read { path: bad, .. }) = write_html_report(&path, "t", &missing) else {
            panic!("a missing image is an error");
        };
        assert!(bad.ends_with("gone.png"));
        assert_eq!(std::fs::read_to_string(&path)?, html, "the old report is kept");
        Ok(())
    }

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
