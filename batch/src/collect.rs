//! Merging a batch's records into one table: `plan.results.json` (every record, and a
//! `missing` entry for items without one) and `plan.results.csv` (one row per item:
//! state, seconds, host, error, and a column per figure any item reported).

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use serde::Serialize;

use crate::error::{BatchError, Result};
use crate::manifest::Plan;
use crate::record::{ItemRecord, error_summary, read_record};
use crate::status::{ItemState, item_state};

/// One item in the merged table.
#[derive(Debug, Clone, Serialize)]
pub struct CollectedItem {
    /// The item's id and kind.
    pub id: String,
    pub kind: String,
    /// Done, failed, changed (a record of other settings, or its output gone) or
    /// missing, as `status` judges it.
    pub state: ItemState,
    /// Its record, when it has one.
    pub record: Option<ItemRecord>,
}

/// What `collect` wrote.
#[derive(Debug, Clone)]
pub struct Collected {
    /// The merged files.
    pub json: PathBuf,
    pub csv: PathBuf,
    /// Items by state.
    pub done: usize,
    pub failed: usize,
    pub other: usize,
}

fn csv_field(text: &str) -> String {
    if text.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", text.replace('"', "\"\""))
    } else {
        text.to_string()
    }
}

fn figure_text(value: &serde_json::Value) -> String {
    match value {
        serde_json::Value::String(s) => s.clone(),
        other => other.to_string(),
    }
}

/// Merges the records of `plan` into `<out>/…` or, without `out`, beside the plan.
pub fn collect(plan: &Plan, out: Option<&Path>) -> Result<Collected> {
    let results = plan.results_dir();
    let mut items = Vec::with_capacity(plan.items.len());
    for item in &plan.items {
        let record = read_record(&results, &item.id)?;
        items.push(CollectedItem {
            id: item.id.clone(),
            kind: item.kind.clone(),
            state: item_state(item, record.as_ref()),
            record,
        });
    }
    let (json, csv) = match out {
        Some(dir) => {
            std::fs::create_dir_all(dir).map_err(|e| BatchError::io(dir, &e))?;
            (dir.join("results.json"), dir.join("results.csv"))
        }
        None => (
            plan.path.with_extension("results.json"),
            plan.path.with_extension("results.csv"),
        ),
    };
    let text = serde_json::to_string_pretty(&items).map_err(|e| BatchError::Io {
        path: json.clone(),
        message: e.to_string(),
    })? + "\n";
    nelf_format::atomic::write_bytes_atomically(&json, text.as_bytes())
        .map_err(|e| BatchError::io(&json, &e))?;

    let figures: BTreeSet<&String> = items
        .iter()
        .filter_map(|i| i.record.as_ref())
        .flat_map(|r| r.figures.keys())
        .collect();
    let mut table = String::from("id,kind,state,secs,item_secs,host,exit_code,output,error");
    for name in &figures {
        table.push(',');
        table.push_str(&csv_field(name));
    }
    table.push('\n');
    for item in &items {
        let mut row = vec![
            csv_field(&item.id),
            csv_field(&item.kind),
            item.state.name().to_string(),
        ];
        match &item.record {
            Some(r) => {
                row.push(format!("{:.3}", r.secs));
                row.push(format!("{:.3}", r.item_secs));
                row.push(csv_field(&r.host));
                row.push(r.exit_code.map(|c| c.to_string()).unwrap_or_default());
                row.push(csv_field(&r.output.to_string_lossy()));
                row.push(if r.error.is_empty() {
                    String::new()
                } else {
                    csv_field(&error_summary(&r.error))
                });
                for name in &figures {
                    row.push(
                        r.figures
                            .get(*name)
                            .map(figure_text)
                            .map(|t| csv_field(&t))
                            .unwrap_or_default(),
                    );
                }
            }
            None => row.extend(std::iter::repeat_n(String::new(), 6 + figures.len())),
        }
        table.push_str(&row.join(","));
        table.push('\n');
    }
    nelf_format::atomic::write_bytes_atomically(&csv, table.as_bytes())
        .map_err(|e| BatchError::io(&csv, &e))?;
    let count = |state: ItemState| items.iter().filter(|i| i.state == state).count();
    Ok(Collected {
        json,
        csv,
        done: count(ItemState::Done),
        failed: count(ItemState::Failed),
        other: count(ItemState::Missing) + count(ItemState::Changed),
    })
}
