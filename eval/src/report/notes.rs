//! What a report section shows instead of a chart that could not be drawn or an
//! image that is missing: a note in its text, so one bad part does not lose the report.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use super::chart::{Chart, chart_svg};

/// A chart's rendering, or a note saying why there is none (so one bad chart does
/// not lose the report).
pub(super) fn chart_or_note(chart: &Chart, charts: &mut Vec<String>, text: &mut String) {
    match chart_svg(chart) {
        Ok(svg) => charts.push(svg),
        Err(e) => {
            let _ = write!(text, "\n\n{e}");
        }
    }
}

/// The images among `wanted` (`(caption, path relative to report_dir)`) that exist,
/// and a note naming those that do not.
pub(super) fn existing_images(
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
