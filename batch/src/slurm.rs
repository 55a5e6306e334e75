//! Slurm: an `sbatch` script that runs a plan as a job array (one array task per
//! index, `%max-parallel`, cpus, memory and time per task, logs in `plan.logs/`,
//! created before submission because Slurm does not create them and a task whose
//! log cannot be opened dies with signal 53), and its submission.

use std::path::{Path, PathBuf};
use std::process::Command;

use crate::error::{BatchError, Result};
use crate::manifest::{Plan, format_ranges};

/// What each array task asks Slurm for.
#[derive(Debug, Clone)]
pub struct SlurmOptions {
    /// The `nelf` binary every node runs (on the shared file system).
    pub program: PathBuf,
    /// CPUs per task.
    pub cpus: u32,
    /// Memory per task (`sbatch --mem`: `4G`, `8000M`).
    pub mem: String,
    /// Minutes per item: a task's time limit is this × the chunk.
    pub minutes_per_item: u32,
    /// Tasks running at once (`--array=…%N`); 0: no limit.
    pub max_parallel: usize,
    /// Partition (`-p`); none: the cluster's default.
    pub partition: Option<String>,
    /// Only these indices (`0-3,7`): to submit again what `status` lists.
    pub indices: Option<Vec<usize>>,
    /// More `#SBATCH` options, passed as they are (`--account=x`, `--gres=gpu:1`).
    pub extra: Vec<String>,
}

/// The script's path: `plan.sbatch` beside the plan.
pub fn script_path(plan: &Plan) -> PathBuf {
    plan.path.with_extension("sbatch")
}

/// Writes the `sbatch` script (and creates the log folder); returns its path.
pub fn write_script(plan: &Plan, options: &SlurmOptions) -> Result<PathBuf> {
    let logs = plan.logs_dir();
    std::fs::create_dir_all(&logs).map_err(|e| BatchError::io(&logs, &e))?;
    let indices = options
        .indices
        .clone()
        .unwrap_or_else(|| (0..plan.tasks()).collect());
    if let Some(bad) = indices.iter().find(|i| **i >= plan.tasks()) {
        return Err(BatchError::Index(format!(
            "index {bad} is outside the plan (indices 0–{})",
            plan.tasks() - 1
        )));
    }
    let mut array = format_ranges(&indices);
    if options.max_parallel > 0 {
        array = format!("{array}%{}", options.max_parallel);
    }
    let stem = plan
        .path
        .file_stem()
        .map_or_else(|| "plan".into(), |s| s.to_string_lossy().into_owned());
    let minutes = u64::from(options.minutes_per_item.max(1)) * plan.chunk as u64;
    let dir = plan.path.parent().unwrap_or(Path::new("/"));
    let mut lines = vec![
        "#!/bin/bash".to_string(),
        format!("#SBATCH --job-name=nelf-{}", crate::manifest::sanitize_id(&stem)),
        format!("#SBATCH --array={array}"),
        format!("#SBATCH --cpus-per-task={}", options.cpus.max(1)),
        format!("#SBATCH --mem={}", options.mem),
        format!("#SBATCH --time={minutes}"),
        format!("#SBATCH --chdir={}", dir.display()),
        format!("#SBATCH --output={}/%A_%a.out", logs.display()),
    ];
    if let Some(partition) = &options.partition {
        lines.push(format!("#SBATCH --partition={partition}"));
    }
    for extra in &options.extra {
        lines.push(format!("#SBATCH {extra}"));
    }
    lines.push(String::new());
    lines.push(format!(
        "# {} items in {} array tasks of up to {} (plan {}); each task runs its items, skipping done ones.",
        plan.items.len(),
        plan.tasks(),
        plan.chunk,
        plan.path.display()
    ));
    lines.push("set -euo pipefail".into());
    lines.push(format!(
        "exec {}",
        crate::command_line(
            &options.program,
            &[
                "batch".into(),
                "run".into(),
                plan.path.to_string_lossy().into_owned()
            ]
        )
    ));
    let script = script_path(plan);
    let text = lines.join("\n") + "\n";
    nelf_format::atomic::write_bytes_atomically(&script, text.as_bytes())
        .map_err(|e| BatchError::io(&script, &e))?;
    Ok(script)
}

/// Submits `script` with `sbatch --parsable`; returns the job id.
pub fn submit(script: &Path) -> Result<String> {
    let output = Command::new("sbatch")
        .arg("--parsable")
        .arg(script)
        .output()
        .map_err(|e| {
            BatchError::Scheduler(format!(
                "cannot run sbatch ({e}): is Slurm's client installed and SLURM_CONF set?"
            ))
        })?;
    let stdout = String::from_utf8_lossy(&output.stdout);
    let job = stdout
        .lines()
        .next()
        .unwrap_or_default()
        .split(';')
        .next()
        .unwrap_or_default()
        .trim()
        .to_string();
    if !output.status.success() || job.is_empty() {
        return Err(BatchError::Scheduler(format!(
            "sbatch {} refused the job: {}",
            script.display(),
            String::from_utf8_lossy(&output.stderr).trim()
        )));
    }
    Ok(job)
}

/// Waits until job `job` has no task left in `squeue`, asking every `poll` (`sbatch
/// --wait` backs off to half a minute between its own questions, which measured
/// 42 s for an array that ended after 10). A controller that does not answer ten
/// times in a row is an error; a failed task is not (the records say what failed).
pub fn wait_for(job: &str, poll: std::time::Duration) -> Result<()> {
    let mut silent = 0;
    loop {
        let output = Command::new("squeue")
            .args(["-h", "-o", "%i", "-j", job])
            .output()
            .map_err(|e| BatchError::Scheduler(format!("cannot run squeue: {e}")))?;
        if output.status.success() {
            silent = 0;
            if String::from_utf8_lossy(&output.stdout).trim().is_empty() {
                return Ok(());
            }
        } else {
            let stderr = String::from_utf8_lossy(&output.stderr);
            // A job the controller has already forgotten has ended.
            if stderr.contains("Invalid job id") {
                return Ok(());
            }
            silent += 1;
            if silent >= 10 {
                return Err(BatchError::Scheduler(format!(
                    "squeue failed ten times in a row while waiting for job {job}: {}",
                    stderr.trim()
                )));
            }
        }
        std::thread::sleep(poll);
    }
}
