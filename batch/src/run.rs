//! Running one array index of a plan: each of its items, idempotently.
//!
//! An item is skipped when its done record holds the hash of its settings as they
//! are now and its output exists. Otherwise its command runs writing into a staging
//! folder beside the output (`<output>.part-<host>-<pid>.<n>`, on the same file system,
//! so the final rename is atomic); only a whole, successful output is renamed into
//! place, and the record is written last (atomically). A killed item leaves at most a
//! staging folder, which the next run on the same host removes once its process is
//! gone; two runs of the same index at once both finish and one whole output stays
//! (the commands are deterministic, so either is the same). A failed item records
//! its error and the run goes on with the index's other items, then reports failure.

use std::io::{BufRead, BufReader, Write};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Instant, SystemTime, UNIX_EPOCH};

use crate::error::{BatchError, Result};
use crate::manifest::{Item, Plan};
use crate::record::{
    ItemRecord, ItemStatus, OutputFile, output_file, read_figures, read_record, write_record,
};

/// How items are run.
#[derive(Debug, Clone)]
pub struct RunOptions {
    /// The program an item's arguments are given to (the `nelf` binary itself).
    pub program: PathBuf,
    /// Run even items whose done record matches.
    pub force: bool,
    /// Pass the commands' standard output through (otherwise it is dropped; their
    /// standard error always passes through, and its tail goes into a failed record).
    pub show_output: bool,
}

/// What happened to one item.
#[derive(Debug, Clone, PartialEq)]
pub enum ItemOutcome {
    /// Its done record matched: nothing ran.
    Skipped,
    /// It ran and succeeded.
    Done(ItemRecord),
    /// It ran and failed.
    Failed(ItemRecord),
}

/// This machine's name, as records and staging folders carry it.
pub fn host_name() -> String {
    let name = gethostname::gethostname().to_string_lossy().into_owned();
    let short = name.split('.').next().unwrap_or("host");
    crate::manifest::sanitize_id(short)
}

/// The array index to run: `--index`, else Slurm's `SLURM_ARRAY_TASK_ID`, else a
/// Kubernetes Indexed Job's `JOB_COMPLETION_INDEX`.
pub fn resolve_index(flag: Option<usize>, env: impl Fn(&str) -> Option<String>) -> Result<usize> {
    if let Some(index) = flag {
        return Ok(index);
    }
    for name in ["SLURM_ARRAY_TASK_ID", "JOB_COMPLETION_INDEX"] {
        if let Some(value) = env(name) {
            return value
                .trim()
                .parse()
                .map_err(|_| BatchError::Index(format!("{name}={value:?} is not an array index")));
        }
    }
    Err(BatchError::Index(
        "no array index: give --index N, or run inside a Slurm array (SLURM_ARRAY_TASK_ID) or a Kubernetes Indexed Job (JOB_COMPLETION_INDEX)"
            .into(),
    ))
}

/// Runs every item of array index `index` (a failed item does not stop the others:
/// its outcome says it failed); an error only when the batch itself cannot go on
/// (an index outside the plan, a record that cannot be written).
pub fn run_task(plan: &Plan, index: usize, options: &RunOptions) -> Result<Vec<ItemOutcome>> {
    plan.task_items(index)?
        .iter()
        .map(|item| run_item(plan, item, options))
        .collect()
}

/// Whether item `item` is done ([`crate::record::counts_as_done`]).
pub fn is_done(plan: &Plan, item: &Item) -> Result<bool> {
    Ok(read_record(&plan.results_dir(), &item.id)?.is_some_and(|r| crate::record::counts_as_done(item, &r)))
}

fn unix_now() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_secs())
}

/// A new sibling folder of `output` named `<name>.<tag>-<host>-<pid>.<n>`, the first
/// `n` free (two threads of one process running the same item get different ones),
/// created empty when `create`, else only named.
fn fresh_sibling(output: &Path, tag: &str, host: &str, pid: u32, create: bool) -> Result<PathBuf> {
    let base = output
        .file_name()
        .map(std::ffi::OsStr::to_os_string)
        .unwrap_or_default();
    for n in 0..10_000 {
        let mut name = base.clone();
        name.push(format!(".{tag}-{host}-{pid}.{n}"));
        let path = output.with_file_name(name);
        if !create {
            if !path.exists() {
                return Ok(path);
            }
            continue;
        }
        match std::fs::create_dir(&path) {
            Ok(()) => return Ok(path),
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {}
            Err(e) => return Err(BatchError::io(&path, &e)),
        }
    }
    Err(BatchError::Io {
        path: output.to_path_buf(),
        message: format!("10000 {tag} folders beside it: remove them"),
    })
}

/// Whether process `pid` of this host is running: it has a `/proc` entry and is not
/// a zombie (a killed runner whose parent died too may wait unreaped for as long as
/// the machine's init leaves it).
fn process_alive(pid: u32) -> bool {
    let Ok(stat) = std::fs::read_to_string(format!("/proc/{pid}/stat")) else {
        return false;
    };
    // `pid (command) state …`: the command may hold spaces and parentheses.
    let state = stat
        .rsplit_once(')')
        .and_then(|(_, rest)| rest.trim_start().chars().next());
    !matches!(state, Some('Z' | 'X'))
}

/// Removes staging and set-aside folders of `output` left by processes of this host
/// that are gone (killed runs); another host's are left alone (`status` lists them).
fn remove_stale(output: &Path, host: &str) -> Result<()> {
    let (Some(parent), Some(name)) = (output.parent(), output.file_name()) else {
        return Ok(());
    };
    let Ok(entries) = std::fs::read_dir(parent) else {
        return Ok(());
    };
    let name = name.to_string_lossy();
    for entry in entries.flatten() {
        let entry_name = entry.file_name().to_string_lossy().into_owned();
        for tag in ["part", "old"] {
            let prefix = format!("{name}.{tag}-{host}-");
            let Some(pid) = entry_name
                .strip_prefix(&prefix)
                .and_then(|p| p.split('.').next())
                .and_then(|p| p.parse::<u32>().ok())
            else {
                continue;
            };
            if !process_alive(pid) {
                let path = entry.path();
                remove_any(&path)?;
            }
        }
    }
    Ok(())
}

fn remove_any(path: &Path) -> Result<()> {
    let removed = if path.is_dir() {
        std::fs::remove_dir_all(path)
    } else {
        std::fs::remove_file(path)
    };
    match removed {
        Err(e) if e.kind() != std::io::ErrorKind::NotFound => Err(BatchError::io(path, &e)),
        _ => Ok(()),
    }
}

/// Runs `args` under `program`, passing stderr through and keeping its last lines.
fn run_command(
    program: &Path,
    args: &[String],
    workdir: &Path,
    show_output: bool,
) -> Result<(Option<i32>, String)> {
    let mut command = Command::new(program);
    if !workdir.as_os_str().is_empty() {
        command.current_dir(workdir);
    }
    let mut child = command
        .args(args)
        // The record keeps the error's last lines: the message, not a backtrace.
        .env("RUST_BACKTRACE", "0")
        .env("RUST_LIB_BACKTRACE", "0")
        .stdin(Stdio::null())
        .stdout(if show_output {
            Stdio::inherit()
        } else {
            Stdio::null()
        })
        .stderr(Stdio::piped())
        .spawn()
        .map_err(|e| BatchError::io(program, &e))?;
    let mut tail: std::collections::VecDeque<String> = std::collections::VecDeque::new();
    if let Some(stderr) = child.stderr.take() {
        let mut ours = std::io::stderr();
        for line in BufReader::new(stderr).split(b'\n').map_while(std::io::Result::ok) {
            let line = String::from_utf8_lossy(&line).into_owned();
            // Progress bars redraw with carriage returns; keep what a person would see.
            let shown = line.rsplit('\r').next().unwrap_or_default().to_string();
            // Our own stderr may be closed (a scheduler that dropped the log): the
            // item's outcome does not depend on it.
            let _ = writeln!(ours, "{shown}");
            if !shown.trim().is_empty() {
                tail.push_back(shown);
                if tail.len() > 20 {
                    tail.pop_front();
                }
            }
        }
    }
    let status = child.wait().map_err(|e| BatchError::io(program, &e))?;
    let mut text = tail.into_iter().collect::<Vec<_>>().join("\n");
    if !status.success() && status.code().is_none() {
        text.push_str("\n(killed by a signal)");
    }
    Ok((status.code(), text))
}

/// Puts the finished `staging` folder at `output`. When `output` already holds a
/// whole output of the same settings (another run of the same index got there
/// first) ours is dropped; an output of other settings is set aside and removed.
fn publish(plan: &Plan, item: &Item, staging: &Path, host: &str, pid: u32) -> Result<()> {
    match std::fs::rename(staging, &item.output) {
        Ok(()) => return Ok(()),
        Err(_) if item.output.exists() => {}
        Err(e) => return Err(BatchError::io(&item.output, &e)),
    }
    if is_done(plan, item)? {
        return remove_any(staging);
    }
    let aside = fresh_sibling(&item.output, "old", host, pid, false)?;
    std::fs::rename(&item.output, &aside).map_err(|e| BatchError::io(&item.output, &e))?;
    match std::fs::rename(staging, &item.output) {
        Ok(()) => remove_any(&aside),
        // Another run put its (equal) output there between our two renames.
        Err(_) if item.output.exists() => {
            remove_any(&aside)?;
            remove_any(staging)
        }
        Err(e) => Err(BatchError::io(&item.output, &e)),
    }
}

/// Lists the files under `staging` (sizes and hashes, for the record), first
/// rewriting, in every text file, the staging folder's path to the final output's:
/// commands record where they wrote (a bake's sidecar names its asset), and the files
/// must name where they will be. Binary files are left as they are. Each file is
/// read once.
fn relocate_and_list(staging: &Path, output: &Path) -> Result<Vec<OutputFile>> {
    let from = staging.to_string_lossy().into_owned();
    let to = output.to_string_lossy().into_owned();
    crate::record::files_under(staging)?
        .into_iter()
        .map(|path| {
            let bytes = std::fs::read(&path).map_err(|e| BatchError::io(&path, &e))?;
            let relocated = std::str::from_utf8(&bytes)
                .ok()
                .filter(|text| !text.contains('\0') && text.contains(&from))
                .map(|text| text.replace(&from, &to));
            match relocated {
                Some(text) => {
                    nelf_format::atomic::write_bytes_atomically(&path, text.as_bytes())
                        .map_err(|e| BatchError::io(&path, &e))?;
                    Ok(output_file(staging, &path, text.as_bytes()))
                }
                None => Ok(output_file(staging, &path, &bytes)),
            }
        })
        .collect()
}

/// Runs one item (module docs).
pub fn run_item(plan: &Plan, item: &Item, options: &RunOptions) -> Result<ItemOutcome> {
    if !options.force && is_done(plan, item)? {
        return Ok(ItemOutcome::Skipped);
    }
    let start = Instant::now();
    let host = host_name();
    let pid = std::process::id();
    let parent = item.output.parent().unwrap_or(Path::new("."));
    std::fs::create_dir_all(parent).map_err(|e| BatchError::io(parent, &e))?;
    remove_stale(&item.output, &host)?;
    let target = if item.shared_output {
        std::fs::create_dir_all(&item.output).map_err(|e| BatchError::io(&item.output, &e))?;
        item.output.clone()
    } else {
        fresh_sibling(&item.output, "part", &host, pid, true)?
    };
    let command_start = Instant::now();
    let (exit_code, stderr_tail) = run_command(
        &options.program,
        &item.args_writing_to(&target),
        &item.workdir,
        options.show_output,
    )?;
    let secs = command_start.elapsed().as_secs_f64();
    let succeeded = exit_code == Some(0);
    let mut record = ItemRecord {
        id: item.id.clone(),
        kind: item.kind.clone(),
        hash: item.settings_hash(),
        status: if succeeded {
            ItemStatus::Done
        } else {
            ItemStatus::Failed
        },
        secs,
        item_secs: 0.0,
        host: host.clone(),
        pid,
        finished_unix: 0,
        exit_code,
        error: String::new(),
        output: item.output.clone(),
        outputs: Vec::new(),
        output_folder: None,
        figures: serde_json::Map::new(),
    };
    if succeeded {
        if item.shared_output {
            record.output_folder = crate::record::folder_identity(&item.output);
        } else {
            record.outputs = relocate_and_list(&target, &item.output)?;
            record.figures = read_figures(&target);
            publish(plan, item, &target, &host, pid)?;
        }
    } else {
        if !item.shared_output {
            remove_any(&target)?;
        }
        record.error = if stderr_tail.trim().is_empty() {
            format!("exit code {exit_code:?} and no message")
        } else {
            // Name the output the item writes, not the staging folder that is gone.
            stderr_tail.replace(&*target.to_string_lossy(), &item.output.to_string_lossy())
        };
    }
    record.item_secs = start.elapsed().as_secs_f64();
    record.finished_unix = unix_now();
    write_record(&plan.results_dir(), &record)?;
    Ok(if succeeded {
        ItemOutcome::Done(record)
    } else {
        ItemOutcome::Failed(record)
    })
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::process_alive;

    #[test]
    fn a_zombie_counts_as_gone() {
        assert!(process_alive(std::process::id()));
        let mut child = std::process::Command::new("sleep").arg("30").spawn().unwrap();
        assert!(process_alive(child.id()));
        child.kill().unwrap();
        // Killed but not yet reaped: a zombie with a /proc entry.
        let start = std::time::Instant::now();
        while process_alive(child.id()) && start.elapsed().as_secs() < 5 {
            std::thread::sleep(std::time::Duration::from_millis(10));
        }
        assert!(!process_alive(child.id()));
        assert!(std::path::Path::new(&format!("/proc/{}", child.id())).exists());
        child.wait().unwrap();
        assert!(!process_alive(u32::MAX));
    }
}
