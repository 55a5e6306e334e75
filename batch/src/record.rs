//! The record an item leaves in `plan.results/<id>.json` when it finishes: done or
//! failed, the settings hash it ran with, seconds, host, its output files (bytes and
//! an xxh3 of each) and its figures. A done record whose hash matches the item's
//! settings, beside an existing output, is what makes a rerun skip the item.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::error::{BatchError, Result};

/// How an item ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ItemStatus {
    /// Its command succeeded and its output is in place.
    Done,
    /// Its command failed (the record holds the error).
    Failed,
}

/// One output file of a finished item.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct OutputFile {
    /// Path relative to the item's output folder.
    pub path: String,
    /// Size in bytes.
    pub bytes: u64,
    /// xxh3-64 of the contents, hex.
    pub xxh3: String,
}

/// `plan.results/<id>.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ItemRecord {
    /// The item's id.
    pub id: String,
    /// The item's kind.
    pub kind: String,
    /// The settings hash the item ran with.
    pub hash: String,
    /// Done or failed.
    pub status: ItemStatus,
    /// Wall seconds of the item's command.
    pub secs: f64,
    /// Wall seconds of the whole item, ours included (staging, rename, hashing).
    pub item_secs: f64,
    /// Host that ran it.
    pub host: String,
    /// Process id of the `nelf batch run` that ran it.
    pub pid: u32,
    /// When it finished, seconds since the Unix epoch.
    pub finished_unix: u64,
    /// The command's exit code (`None`: killed by a signal).
    pub exit_code: Option<i32>,
    /// For a failed item: the last lines the command wrote to stderr.
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub error: String,
    /// The item's output folder.
    pub output: PathBuf,
    /// Its files (private outputs only; a shared output is listed by its own tool).
    #[serde(default)]
    pub outputs: Vec<OutputFile>,
    /// For a shared output: which folder it filled ([`folder_identity`]), so that a record of
    /// a folder since deleted and made again — by the first of the other shards to
    /// start, say — does not count as done.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub output_folder: Option<u64>,
    /// Numbers the item's own report holds (a bake's size, rank, voxels …).
    #[serde(default)]
    pub figures: serde_json::Map<String, serde_json::Value>,
}

/// One line for a failed item's error: a Rust command's `Error: …` line followed
/// by its causes (`Caused by: 0: … 1: …`), joined with `: ` (a cause its message
/// already ends with is left out); otherwise the last line the command wrote.
pub fn error_summary(text: &str) -> String {
    let lines: Vec<&str> = text.lines().map(str::trim).filter(|l| !l.is_empty()).collect();
    if let Some(start) = lines.iter().rposition(|l| l.starts_with("Error: ")) {
        let mut parts = vec![lines[start].trim_start_matches("Error: ").to_string()];
        for line in &lines[start + 1..] {
            if *line == "Caused by:" {
                continue;
            }
            // "0: message" → "message"
            let cause = line
                .split_once(": ")
                .filter(|(n, _)| n.chars().all(|c| c.is_ascii_digit()))
                .map_or(*line, |(_, rest)| rest);
            if cause.starts_with("Stack backtrace") {
                break;
            }
            // A message that quotes its cause is not followed by the cause again.
            if !parts.last().is_some_and(|p| p.ends_with(cause)) {
                parts.push(cause.to_string());
            }
        }
        return parts.join(": ");
    }
    lines
        .last()
        .map_or_else(|| "(no message)".into(), |l| (*l).to_string())
}

/// Which folder `path` is: its inode number and creation time (nanoseconds since
/// the epoch), hashed, or the inode alone where the file system keeps no creation
/// time (a deleted folder's inode is often given to the next one at once); `None`
/// where there is neither.
pub fn folder_identity(path: &Path) -> Option<u64> {
    let metadata = std::fs::metadata(path).ok()?;
    let born = metadata
        .created()
        .ok()
        .and_then(|t| t.duration_since(std::time::UNIX_EPOCH).ok())
        .map(|d| d.as_nanos());
    #[cfg(unix)]
    let inode = {
        use std::os::unix::fs::MetadataExt;
        Some(metadata.ino())
    };
    #[cfg(not(unix))]
    let inode: Option<u64> = None;
    match (inode, born) {
        (None, None) => None,
        (inode, born) => Some(xxhash_rust::xxh3::xxh3_64(
            format!("{inode:?} {born:?}").as_bytes(),
        )),
    }
}

/// Whether `record` says item `item` (with these settings) is done: a done record
/// with the item's current settings hash, beside its output — for a shared output,
/// the very folder the item filled.
pub fn counts_as_done(item: &crate::manifest::Item, record: &ItemRecord) -> bool {
    record.status == ItemStatus::Done
        && record.hash == item.settings_hash()
        && item.output.exists()
        && (!item.shared_output || record.output_folder == folder_identity(&item.output))
}

/// The record file of item `id`.
pub fn record_path(results_dir: &Path, id: &str) -> PathBuf {
    results_dir.join(format!("{id}.json"))
}

/// The record of item `id`: `Ok(None)` when there is none, an error when one is
/// there but cannot be read (a damaged record is reported, not silently rerun).
pub fn read_record(results_dir: &Path, id: &str) -> Result<Option<ItemRecord>> {
    let path = record_path(results_dir, id);
    match std::fs::read(&path) {
        Ok(bytes) => serde_json::from_slice(&bytes)
            .map(Some)
            .map_err(|e| BatchError::Io {
                path,
                message: format!("damaged record (delete it to rerun the item): {e}"),
            }),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
        Err(e) => Err(BatchError::io(path, &e)),
    }
}

/// Writes the record of `record.id` atomically.
pub fn write_record(results_dir: &Path, record: &ItemRecord) -> Result<()> {
    std::fs::create_dir_all(results_dir).map_err(|e| BatchError::io(results_dir, &e))?;
    let path = record_path(results_dir, &record.id);
    let text = serde_json::to_string_pretty(record).map_err(|e| BatchError::Io {
        path: path.clone(),
        message: e.to_string(),
    })? + "\n";
    nelf_format::atomic::write_bytes_atomically(&path, text.as_bytes()).map_err(|e| BatchError::io(&path, &e))
}

/// Every file under `dir` (recursively), sorted.
pub fn files_under(dir: &Path) -> Result<Vec<PathBuf>> {
    let mut files = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(folder) = stack.pop() {
        let entries = std::fs::read_dir(&folder).map_err(|e| BatchError::io(&folder, &e))?;
        for entry in entries {
            let path = entry.map_err(|e| BatchError::io(&folder, &e))?.path();
            if path.is_dir() {
                stack.push(path);
            } else {
                files.push(path);
            }
        }
    }
    files.sort();
    Ok(files)
}

/// The entry of `path` (under `dir`) with contents `bytes`.
pub fn output_file(dir: &Path, path: &Path, bytes: &[u8]) -> OutputFile {
    let relative = path.strip_prefix(dir).unwrap_or(path);
    OutputFile {
        path: relative.to_string_lossy().replace('\\', "/"),
        bytes: bytes.len() as u64,
        xxh3: format!("{:016x}", xxhash_rust::xxh3::xxh3_64(bytes)),
    }
}

/// Every file under `dir`, sorted, with sizes and hashes.
pub fn list_outputs(dir: &Path) -> Result<Vec<OutputFile>> {
    files_under(dir)?
        .into_iter()
        .map(|path| {
            let bytes = std::fs::read(&path).map_err(|e| BatchError::io(&path, &e))?;
            Ok(output_file(dir, &path, &bytes))
        })
        .collect()
}

/// The figures of an item's own report: the numeric fields of the `report` of each
/// `*.bake.json` sidecar in `dir` (a bake's file size, rank, voxels, loss …), the
/// row count of a Pareto sweep's `results.json` and the point count of a stability
/// sweep's `stability.json`. Other files are not read.
pub fn read_figures(dir: &Path) -> serde_json::Map<String, serde_json::Value> {
    let mut figures = serde_json::Map::new();
    let Ok(entries) = std::fs::read_dir(dir) else {
        return figures;
    };
    let mut names: Vec<PathBuf> = entries.filter_map(|e| e.ok().map(|e| e.path())).collect();
    names.sort();
    for path in names {
        let name = path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        let count_key = match name.as_str() {
            "results.json" => Some("rows"),
            "stability.json" => Some("points"),
            _ => None,
        };
        if count_key.is_none() && !name.ends_with(".bake.json") {
            continue;
        }
        let Some(json) = std::fs::read(&path)
            .ok()
            .and_then(|b| serde_json::from_slice::<serde_json::Value>(&b).ok())
        else {
            continue;
        };
        if name.ends_with(".bake.json") {
            if let Some(report) = json.get("report").and_then(serde_json::Value::as_object) {
                for (key, value) in report {
                    if value.is_number() || value.is_boolean() {
                        figures.insert(key.clone(), value.clone());
                    }
                }
            }
        } else if let Some(key) = count_key {
            if let Some(rows) = json.get(key).and_then(serde_json::Value::as_array) {
                figures.insert(key.into(), rows.len().into());
            }
        }
    }
    figures
}

#[cfg(test)]
mod tests {
    use super::error_summary;

    #[test]
    fn an_error_chain_reads_as_one_line() {
        let text = "progress\nError: loading the capture in /c\n\nCaused by:\n    0: /c/cameras.json: EOF at line 2\n    1: EOF at line 2\n";
        assert_eq!(
            error_summary(text),
            "loading the capture in /c: /c/cameras.json: EOF at line 2"
        );
        assert_eq!(error_summary("warning\nsegfault\n"), "segfault");
        assert_eq!(error_summary(""), "(no message)");
    }
}
