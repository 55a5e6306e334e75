//! The measured rows as CSV tables (RFC 4180, one line per row, [`Scores`] flattened)
//! and as JSON; each file written atomically (`nelf_format::atomic`).

use std::path::Path;

use serde::Serialize;

use super::error::ReportError;
use crate::rows::{ParetoRow, Scores, StabilityPoint};

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
    nelf_format::atomic::write_bytes_atomically(path, pareto_csv(rows).as_bytes())
        .map_err(ReportError::writing(path))
}

/// Writes the points of stability axes as CSV ([`stability_csv`]), atomically.
pub fn write_stability_csv(path: &Path, points: &[StabilityPoint]) -> Result<(), ReportError> {
    nelf_format::atomic::write_bytes_atomically(path, stability_csv(points).as_bytes())
        .map_err(ReportError::writing(path))
}

/// Writes `value` as pretty-printed JSON with a final line feed, atomically.
pub fn write_json(path: &Path, value: &impl Serialize) -> Result<(), ReportError> {
    let mut bytes = serde_json::to_vec_pretty(value).map_err(|source| ReportError::Json {
        path: path.to_path_buf(),
        source,
    })?;
    bytes.push(b'\n');
    nelf_format::atomic::write_bytes_atomically(path, &bytes).map_err(ReportError::writing(path))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::report::test_support::{TestResult, point, row};

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
}
