//! Running a whole plan on this machine, `jobs` array indices at a time, with a
//! progress bar: for users without a cluster, and the baseline a cluster is
//! measured against. Each index runs exactly as an array task would.

use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

use indicatif::{ProgressBar, ProgressStyle};

use crate::error::{BatchError, Result};
use crate::manifest::Plan;
use crate::run::{ItemOutcome, RunOptions, run_task};

/// What a local run did.
#[derive(Debug, Clone, Default)]
pub struct LocalReport {
    /// Items run and done, skipped (already done), failed.
    pub done: usize,
    pub skipped: usize,
    pub failed: usize,
    /// What failed: `id: its error on one line`.
    pub errors: Vec<String>,
    /// Wall seconds.
    pub secs: f64,
}

/// Runs every index of `plan` with `jobs` workers.
pub fn run_local(
    plan: &Plan,
    jobs: usize,
    options: &RunOptions,
    progress: &ProgressBar,
) -> Result<LocalReport> {
    let start = Instant::now();
    progress.set_length(plan.items.len() as u64);
    progress.set_style(
        ProgressStyle::with_template("{bar:40} {pos}/{len} items, {elapsed} (eta {eta}) {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let next = AtomicUsize::new(0);
    let report = Mutex::new(LocalReport::default());
    let worker = || {
        loop {
            let index = next.fetch_add(1, Ordering::SeqCst);
            if index >= plan.tasks() {
                break;
            }
            let result = run_task(plan, index, options);
            let Ok(mut report) = report.lock() else { break };
            match result {
                Ok(outcomes) => {
                    for outcome in &outcomes {
                        match outcome {
                            ItemOutcome::Skipped => report.skipped += 1,
                            ItemOutcome::Done(_) => report.done += 1,
                            ItemOutcome::Failed(record) => {
                                report.failed += 1;
                                let error = crate::record::error_summary(&record.error);
                                report.errors.push(format!("{}: {error}", record.id));
                            }
                        }
                    }
                    progress.inc(outcomes.len() as u64);
                }
                Err(error) => {
                    let items = plan.task_items(index).map_or(0, <[_]>::len);
                    report.failed += items;
                    report.errors.push(format!("index {index}: {error}"));
                    progress.inc(items as u64);
                }
            }
            if report.failed > 0 {
                progress.set_message(format!("{} failed", report.failed));
            }
        }
    };
    std::thread::scope(|scope| {
        for _ in 0..jobs.max(1) {
            scope.spawn(worker);
        }
    });
    progress.finish_and_clear();
    let mut report = report
        .into_inner()
        .map_err(|_| BatchError::Settings("a worker panicked".into()))?;
    report.secs = start.elapsed().as_secs_f64();
    Ok(report)
}
