//! Where a batch stands: each item done, failed, changed (a done record of other
//! settings: the manifest was edited) or missing (no record: not run, running, or
//! lost with its node), leftover staging folders, and the array indices to submit
//! again (`0-3,7`).

use std::path::PathBuf;

use serde::Serialize;

use crate::error::Result;
use crate::manifest::{Item, Plan, format_ranges};
use crate::record::{ItemRecord, ItemStatus, error_summary, read_record};

/// One item's state.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum ItemState {
    /// Done with its current settings; output present.
    Done,
    /// Its last run failed (with its current settings).
    Failed,
    /// Done or failed with other settings, or done but its output is gone (or, for
    /// a shared output, is another folder than the one it filled).
    Changed,
    /// No record yet.
    Missing,
}

/// A batch's state.
#[derive(Debug, Clone, Serialize)]
pub struct BatchStatus {
    /// The plan.
    pub plan: PathBuf,
    /// Items and array indices.
    pub items: usize,
    pub tasks: usize,
    pub done: usize,
    pub failed: usize,
    pub changed: usize,
    pub missing: usize,
    /// The ids of failed items with their error on one line.
    pub failures: Vec<(String, String)>,
    /// Array indices holding an item that is not done, as `0-3,7` (empty: all done).
    pub resubmit: String,
    /// Staging folders present (items running now, or killed on another host).
    pub staging: Vec<PathBuf>,
    /// Each item's state, in plan order.
    pub states: Vec<(String, ItemState)>,
}

impl BatchStatus {
    /// Whether every item is done.
    pub fn complete(&self) -> bool {
        self.done == self.items
    }
}

impl ItemState {
    /// Its name, as the JSON and CSV write it.
    pub fn name(self) -> &'static str {
        match self {
            Self::Done => "done",
            Self::Failed => "failed",
            Self::Changed => "changed",
            Self::Missing => "missing",
        }
    }
}

/// The state of `item` given its record: the one rule `status` and `collect` share.
pub fn item_state(item: &Item, record: Option<&ItemRecord>) -> ItemState {
    match record {
        None => ItemState::Missing,
        Some(r) if r.hash != item.settings_hash() => ItemState::Changed,
        Some(r) if r.status == ItemStatus::Failed => ItemState::Failed,
        Some(r) if crate::record::counts_as_done(item, r) => ItemState::Done,
        Some(_) => ItemState::Changed,
    }
}

/// Reads every item's record.
pub fn batch_status(plan: &Plan) -> Result<BatchStatus> {
    let results = plan.results_dir();
    let mut status = BatchStatus {
        plan: plan.path.clone(),
        items: plan.items.len(),
        tasks: plan.tasks(),
        done: 0,
        failed: 0,
        changed: 0,
        missing: 0,
        failures: Vec::new(),
        resubmit: String::new(),
        staging: Vec::new(),
        states: Vec::with_capacity(plan.items.len()),
    };
    let mut again = Vec::new();
    let mut parents = std::collections::BTreeSet::new();
    for (number, item) in plan.items.iter().enumerate() {
        let record = read_record(&results, &item.id)?;
        let state = item_state(item, record.as_ref());
        if let (ItemState::Failed, Some(r)) = (state, &record) {
            status.failures.push((item.id.clone(), error_summary(&r.error)));
        }
        match state {
            ItemState::Done => status.done += 1,
            ItemState::Failed => status.failed += 1,
            ItemState::Changed => status.changed += 1,
            ItemState::Missing => status.missing += 1,
        }
        if state != ItemState::Done {
            again.push(plan.task_of(number));
        }
        if !item.shared_output {
            if let Some(parent) = item.output.parent() {
                parents.insert(parent.to_path_buf());
            }
        }
        status.states.push((item.id.clone(), state));
    }
    for parent in parents {
        let Ok(entries) = std::fs::read_dir(&parent) else {
            continue;
        };
        for entry in entries.flatten() {
            if entry.file_name().to_string_lossy().contains(".part-") {
                status.staging.push(entry.path());
            }
        }
    }
    status.staging.sort();
    status.resubmit = format_ranges(&again);
    Ok(status)
}
