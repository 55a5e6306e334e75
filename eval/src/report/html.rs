//! The self-contained HTML report: [`Section`]s of prose, inline SVG charts, a table
//! sortable by clicking its headers ([`Table`]) and images embedded as base64 data URIs
//! (inline CSS and script, no external URLs); and the charts as SVG files of their
//! own. Every file is written atomically (`nelf_format::atomic`).

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use super::error::ReportError;

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
    /// SVG documents (e.g. from [`super::chart_svg`]), inserted as they are.
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
    nelf_format::atomic::write_bytes_atomically(path, html.as_bytes()).map_err(ReportError::writing(path))
}

/// Writes every chart of `sections` as its own SVG file in `dir` (created), named
/// after its section's heading (`quality-against-size.svg`,
/// `flip-against-size.svg`, `stability-views.svg`, …; a second chart of a section
/// gets `-2`): for documents that show one chart without
/// the whole report. Returns the paths written.
pub fn write_chart_files(dir: &Path, sections: &[Section]) -> Result<Vec<std::path::PathBuf>, ReportError> {
    std::fs::create_dir_all(dir).map_err(ReportError::writing(dir))?;
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
            nelf_format::atomic::write_bytes_atomically(&path, svg.as_bytes())
                .map_err(ReportError::writing(&path))?;
            written.push(path);
        }
    }
    Ok(written)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::report::test_support::{TestResult, tiny_png};
    use crate::report::{Chart, Series, chart_svg};

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
}
