//! Writing what `nelf eval` measured: CSV tables of the rows, JSON, SVG charts
//! (drawn with `plotters`), and one self-contained HTML report (charts inline,
//! images as base64 data URIs, a table sortable by clicking its headers, no
//! external URLs). Every file is written atomically (`nelf_format::atomic`).
//!
//! * `csv`: the rows as CSV and JSON files.
//! * `chart`: the SVG chart engine ([`Chart`], [`chart_svg`]).
//! * `html`: the HTML report's templating and image embedding ([`Section`],
//!   [`write_html_report`]), and the charts as SVG files.
//! * `pareto`, `stability`: the two reports' content ([`pareto_sections`],
//!   [`stability_sections`]).
//! * `notes`: what a section says instead of a chart or image it cannot show.
//! * `error`: [`ReportError`].

mod chart;
mod csv;
mod error;
mod html;
mod notes;
mod pareto;
mod stability;
#[cfg(test)]
mod test_support;

pub use chart::{Chart, Series, chart_svg};
pub use csv::{pareto_csv, stability_csv, write_csv, write_json, write_stability_csv};
pub use error::ReportError;
pub use html::{Cell, Section, Table, escape_html, html_report, write_chart_files, write_html_report};
pub use pareto::pareto_sections;
pub use stability::stability_sections;
