//! The plan: a JSON-lines manifest of work items, written once by `nelf batch plan`
//! and read by every array task. Line 1 is a header (format version, chunk size, item
//! count); each later line is one [`Item`]: its id, kind, inputs, output path, the
//! `nelf` arguments that make it (`{out}` stands for the folder it writes) and a hash
//! of those settings. Array index `n` runs items `n·chunk … (n+1)·chunk − 1`.
//!
//! The same inputs give the same bytes (no timestamps, paths made absolute), so a plan
//! can be written again and compared. Beside `plan.jsonl` live `plan.results/` (one
//! record per item) and `plan.logs/` (the scheduler's logs).

use std::io::Write;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::error::{BatchError, Result};

/// The manifest format this crate writes and reads.
pub const PLAN_VERSION: u32 = 1;

/// What the placeholder in an item's arguments stands for: the folder the item
/// writes (a staging folder beside its output while it runs).
pub const OUT_PLACEHOLDER: &str = "{out}";

/// The first line of a plan.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct PlanHeader {
    /// Manifest format ([`PLAN_VERSION`]).
    pub nelf_batch: u32,
    /// Items per array index.
    pub chunk: usize,
    /// Items in the plan (checked on reading: a truncated plan is an error).
    pub items: usize,
}

/// One unit of work: idempotent, writing only its own output.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Item {
    /// Unique within the plan; names its record (`plan.results/<id>.json`).
    pub id: String,
    /// What it does: `bake`, `train-data`, `pareto`, `stability`, `command`.
    pub kind: String,
    /// What it reads (for people and for `status`; the arguments say it again).
    pub inputs: Vec<String>,
    /// The folder it writes. Private outputs are made in a staging folder beside it
    /// and renamed into place whole; a shared output (a training dataset that many
    /// items fill) is written in place by the command's own atomic writes.
    pub output: PathBuf,
    /// Whether several items write into `output` (see above).
    #[serde(default)]
    pub shared_output: bool,
    /// The folder the command runs in (where `nelf batch plan` ran: relative
    /// defaults such as `data/envmaps` resolve as they would have there).
    pub workdir: PathBuf,
    /// The command's arguments (after the program name); [`OUT_PLACEHOLDER`] is
    /// replaced by the folder to write.
    pub args: Vec<String>,
    /// [`Item::settings_hash`] when the plan was written (the run compares the hash of
    /// the line as it is now with the one its done record holds).
    pub hash: String,
}

/// The settings that decide an item's output, hashed.
#[derive(Serialize)]
struct Settings<'a> {
    kind: &'a str,
    inputs: &'a [String],
    output: &'a Path,
    shared_output: bool,
    workdir: &'a Path,
    args: &'a [String],
}

impl Item {
    /// Makes an item, run in the current folder, and its hash.
    pub fn new(id: String, kind: &str, inputs: Vec<String>, output: PathBuf, args: Vec<String>) -> Self {
        let mut item = Self {
            id,
            kind: kind.into(),
            inputs,
            output,
            shared_output: false,
            workdir: std::env::current_dir().unwrap_or_default(),
            args,
            hash: String::new(),
        };
        item.hash = item.settings_hash();
        item
    }

    /// A 128-bit xxh3 of the settings (kind, inputs, output, folder, arguments) as hex: equal
    /// hashes mean the same command writing the same place.
    pub fn settings_hash(&self) -> String {
        let settings = Settings {
            kind: &self.kind,
            inputs: &self.inputs,
            output: &self.output,
            shared_output: self.shared_output,
            workdir: &self.workdir,
            args: &self.args,
        };
        // Serializing these plain fields cannot fail; an empty string would only
        // make every hash equal, which the tests would catch.
        let bytes = serde_json::to_vec(&settings).unwrap_or_default();
        format!("{:032x}", xxhash_rust::xxh3::xxh3_128(&bytes))
    }

    /// The arguments with [`OUT_PLACEHOLDER`] replaced by `folder`.
    pub fn args_writing_to(&self, folder: &Path) -> Vec<String> {
        let folder = folder.to_string_lossy();
        self.args
            .iter()
            .map(|a| a.replace(OUT_PLACEHOLDER, &folder))
            .collect()
    }
}

/// A plan read from (or to be written to) a manifest.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Plan {
    /// The manifest's path (absolute).
    pub path: PathBuf,
    /// Items per array index.
    pub chunk: usize,
    /// The items, in manifest order.
    pub items: Vec<Item>,
}

/// Whether `id` can name a file on every system we run on.
fn id_is_safe(id: &str) -> bool {
    !id.is_empty()
        && id.len() <= 120
        && !id.starts_with('.')
        && id
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.'))
}

/// Turns a file stem into a safe id part (other characters become `_`).
pub fn sanitize_id(text: &str) -> String {
    let cleaned: String = text
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.') {
                c
            } else {
                '_'
            }
        })
        .take(80)
        .collect();
    let cleaned = cleaned.trim_start_matches('.').to_string();
    if cleaned.is_empty() {
        "item".into()
    } else {
        cleaned
    }
}

impl Plan {
    /// A plan of `items` at `path`, checked: a chunk of at least 1, at least one item,
    /// unique ids that name files.
    pub fn new(path: &Path, chunk: usize, items: Vec<Item>) -> Result<Self> {
        let path = std::path::absolute(path).map_err(|e| BatchError::io(path, &e))?;
        let plan = Self { path, chunk, items };
        plan.check()?;
        Ok(plan)
    }

    fn check(&self) -> Result<()> {
        if self.chunk == 0 {
            return Err(BatchError::Settings("--chunk must be at least 1".into()));
        }
        if self.items.is_empty() {
            return Err(BatchError::Settings(format!(
                "{}: the plan has no items",
                self.path.display()
            )));
        }
        let mut seen = std::collections::HashSet::new();
        for item in &self.items {
            if !id_is_safe(&item.id) {
                return Err(BatchError::Settings(format!(
                    "item id {:?} cannot name a file (letters, digits, - _ . only)",
                    item.id
                )));
            }
            if !seen.insert(item.id.as_str()) {
                return Err(BatchError::Settings(format!(
                    "item id {:?} appears twice",
                    item.id
                )));
            }
        }
        Ok(())
    }

    /// Array indices (tasks): ⌈items / chunk⌉.
    pub fn tasks(&self) -> usize {
        self.items.len().div_ceil(self.chunk)
    }

    /// The items of array index `index`.
    pub fn task_items(&self, index: usize) -> Result<&[Item]> {
        if index >= self.tasks() {
            return Err(BatchError::Index(format!(
                "index {index} is outside the plan {} (indices 0–{}: {} items in chunks of {})",
                self.path.display(),
                self.tasks() - 1,
                self.items.len(),
                self.chunk
            )));
        }
        let start = index * self.chunk;
        Ok(&self.items[start..(start + self.chunk).min(self.items.len())])
    }

    /// The array index that runs item number `item` (manifest order).
    pub fn task_of(&self, item: usize) -> usize {
        item / self.chunk
    }

    /// `plan.results/`: one record per item.
    pub fn results_dir(&self) -> PathBuf {
        self.path.with_extension("results")
    }

    /// `plan.logs/`: the scheduler's logs.
    pub fn logs_dir(&self) -> PathBuf {
        self.path.with_extension("logs")
    }

    /// Writes the manifest atomically.
    pub fn write(&self) -> Result<()> {
        if let Some(parent) = self.path.parent() {
            std::fs::create_dir_all(parent).map_err(|e| BatchError::io(parent, &e))?;
        }
        let header = PlanHeader {
            nelf_batch: PLAN_VERSION,
            chunk: self.chunk,
            items: self.items.len(),
        };
        nelf_format::atomic::write_atomically(&self.path, |w| {
            serde_json::to_writer(&mut *w, &header)?;
            w.write_all(b"\n")?;
            for item in &self.items {
                serde_json::to_writer(&mut *w, item)?;
                w.write_all(b"\n")?;
            }
            Ok(())
        })
        .map_err(|e| BatchError::io(&self.path, &e))
    }

    /// Reads a manifest; a line that is not what `nelf batch plan` writes is an error
    /// naming the file and the line.
    pub fn read(path: &Path) -> Result<Self> {
        let path = std::path::absolute(path).map_err(|e| BatchError::io(path, &e))?;
        let text = std::fs::read_to_string(&path).map_err(|e| BatchError::io(&path, &e))?;
        let bad = |line: usize, message: String| BatchError::PlanLine {
            path: path.clone(),
            line,
            message,
        };
        let mut lines = text.lines().enumerate().filter(|(_, l)| !l.trim().is_empty());
        let Some((_, first)) = lines.next() else {
            return Err(bad(1, "empty: not a plan written by `nelf batch plan`".into()));
        };
        let header: PlanHeader = serde_json::from_str(first).map_err(|e| {
            bad(
                1,
                format!("not a plan header (written by `nelf batch plan`): {e}"),
            )
        })?;
        if header.nelf_batch != PLAN_VERSION {
            return Err(bad(
                1,
                format!(
                    "plan format {} (this nelf reads format {PLAN_VERSION})",
                    header.nelf_batch
                ),
            ));
        }
        let mut items = Vec::with_capacity(header.items);
        for (number, line) in lines {
            let item: Item =
                serde_json::from_str(line).map_err(|e| bad(number + 1, format!("not a plan item: {e}")))?;
            items.push(item);
        }
        if items.len() != header.items {
            return Err(bad(
                1,
                format!(
                    "the header says {} items but the file holds {} (truncated or edited by hand?)",
                    header.items,
                    items.len()
                ),
            ));
        }
        let plan = Self {
            path: path.clone(),
            chunk: header.chunk,
            items,
        };
        plan.check().map_err(|e| bad(1, e.to_string()))?;
        Ok(plan)
    }
}

/// Array indices as Slurm's `--array` writes them: `0-3,7,9-10`.
pub fn format_ranges(indices: &[usize]) -> String {
    let mut sorted = indices.to_vec();
    sorted.sort_unstable();
    sorted.dedup();
    let mut parts = Vec::new();
    let mut i = 0;
    while i < sorted.len() {
        let start = sorted[i];
        let mut end = start;
        while i + 1 < sorted.len() && sorted[i + 1] == end + 1 {
            i += 1;
            end = sorted[i];
        }
        parts.push(if start == end {
            start.to_string()
        } else {
            format!("{start}-{end}")
        });
        i += 1;
    }
    parts.join(",")
}

/// Parses `0-3,7,9-10` (the inverse of [`format_ranges`]).
pub fn parse_ranges(text: &str) -> Result<Vec<usize>> {
    let bad = || BatchError::Index(format!("{text:?} is not a list of indices like 0-3,7"));
    let mut out = Vec::new();
    for part in text.split(',').map(str::trim).filter(|p| !p.is_empty()) {
        match part.split_once('-') {
            Some((a, b)) => {
                let a: usize = a.trim().parse().map_err(|_| bad())?;
                let b: usize = b.trim().parse().map_err(|_| bad())?;
                if b < a {
                    return Err(bad());
                }
                out.extend(a..=b);
            }
            None => out.push(part.parse().map_err(|_| bad())?),
        }
    }
    if out.is_empty() {
        return Err(bad());
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;

    fn items(n: usize) -> Vec<Item> {
        (0..n)
            .map(|i| {
                Item::new(
                    format!("i{i}"),
                    "command",
                    vec![],
                    PathBuf::from(format!("/o/{i}")),
                    vec!["-c".into(), format!("echo {i} > {OUT_PLACEHOLDER}/x")],
                )
            })
            .collect()
    }

    #[test]
    fn a_plan_round_trips_and_chunks_cover_every_item_once() {
        let dir = tempfile::tempdir().unwrap();
        let plan = Plan::new(&dir.path().join("p.jsonl"), 3, items(10)).unwrap();
        plan.write().unwrap();
        let back = Plan::read(&plan.path).unwrap();
        assert_eq!(back, plan);
        assert_eq!(plan.tasks(), 4);
        let ids: Vec<&str> = (0..plan.tasks())
            .flat_map(|t| plan.task_items(t).unwrap().iter().map(|i| i.id.as_str()))
            .collect();
        assert_eq!(ids, plan.items.iter().map(|i| i.id.as_str()).collect::<Vec<_>>());
        assert!(plan.task_items(4).is_err());
        assert_eq!(plan.task_of(9), 3);
        // The same plan gives the same bytes.
        let first = std::fs::read(&plan.path).unwrap();
        plan.write().unwrap();
        assert_eq!(std::fs::read(&plan.path).unwrap(), first);
    }

    #[test]
    fn a_damaged_line_is_named_and_a_changed_setting_changes_the_hash() {
        let dir = tempfile::tempdir().unwrap();
        let plan = Plan::new(&dir.path().join("p.jsonl"), 1, items(3)).unwrap();
        plan.write().unwrap();
        let text = std::fs::read_to_string(&plan.path).unwrap();
        let mut lines: Vec<&str> = text.lines().collect();
        lines[2] = "{\"id\": \"i1\", \"kind\": ";
        std::fs::write(&plan.path, lines.join("\n")).unwrap();
        let error = Plan::read(&plan.path).unwrap_err().to_string();
        assert!(error.contains("line 3") && error.contains("p.jsonl"), "{error}");

        let mut item = items(1).remove(0);
        let before = item.settings_hash();
        assert_eq!(before, item.hash);
        item.args.push("--quick".into());
        assert_ne!(item.settings_hash(), before);

        let duplicate = vec![items(1).remove(0), items(1).remove(0)];
        assert!(Plan::new(&dir.path().join("d.jsonl"), 1, duplicate).is_err());
    }

    #[test]
    fn index_ranges_round_trip() {
        assert_eq!(format_ranges(&[7, 0, 1, 2, 3, 9, 10]), "0-3,7,9-10");
        assert_eq!(parse_ranges("0-3,7,9-10").unwrap(), vec![0, 1, 2, 3, 7, 9, 10]);
        assert!(parse_ranges("3-1").is_err());
        assert!(parse_ranges("x").is_err());
    }
}
