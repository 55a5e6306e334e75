//! Building plans: the items of the batch kinds `nelf batch plan` knows — bakes of
//! many captures or meshes (paths, globs, or a CSV list), shards of heads of
//! `nelf train data`, and the points of `nelf eval pareto` (one grid resolution per
//! item: one bake serves its ranks and encodings) and `nelf eval stability` (one axis
//! per item). Every path is made absolute: every node reads the same shared file
//! system at the same path.

use std::path::{Path, PathBuf};

use crate::error::{BatchError, Result};
use crate::manifest::{Item, OUT_PLACEHOLDER, sanitize_id};

fn absolute(path: &Path) -> Result<PathBuf> {
    std::path::absolute(path).map_err(|e| BatchError::io(path, &e))
}

/// Expands each input that holds a glob pattern (`*`, `?`, `[`) that the shell did
/// not expand; other inputs are kept as they are (a missing one fails its own item
/// with the command's error, not the plan). Sorted within each pattern.
pub fn expand_inputs(inputs: &[String]) -> Result<Vec<PathBuf>> {
    let mut out = Vec::new();
    for input in inputs {
        if input.contains(['*', '?', '[']) {
            let matches = glob::glob(input).map_err(|e| BatchError::Settings(format!("{input:?}: {e}")))?;
            let mut found: Vec<PathBuf> = matches.filter_map(std::result::Result::ok).collect();
            if found.is_empty() {
                return Err(BatchError::Settings(format!("{input:?} matches nothing")));
            }
            found.sort();
            out.extend(found);
        } else {
            out.push(PathBuf::from(input));
        }
    }
    Ok(out)
}

/// Reads a list of inputs: one per line, the path in the first comma-separated
/// column and an optional id in the second; `#` comments, blank lines and a header
/// line whose first column is `input` or `path` are skipped.
pub fn read_list(path: &Path) -> Result<Vec<(PathBuf, Option<String>)>> {
    let text = std::fs::read_to_string(path).map_err(|e| BatchError::io(path, &e))?;
    let mut out = Vec::new();
    for (number, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let mut columns = line.split(',').map(str::trim);
        let first = columns.next().unwrap_or_default();
        if number == 0 && matches!(first.to_ascii_lowercase().as_str(), "input" | "path") {
            continue;
        }
        if first.is_empty() {
            return Err(BatchError::PlanLine {
                path: path.to_path_buf(),
                line: number + 1,
                message: "no input path in the first column".into(),
            });
        }
        let id = columns.next().filter(|c| !c.is_empty()).map(str::to_string);
        out.push((PathBuf::from(first), id));
    }
    Ok(out)
}

/// Whether `path` names a mesh file (baked with `nelf bake mesh`) rather than a
/// capture folder.
fn is_mesh(path: &Path) -> bool {
    path.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| matches!(e.to_ascii_lowercase().as_str(), "obj" | "off" | "ply"))
}

/// Ids from stems, made unique with `-2`, `-3` … in input order.
fn unique_ids(stems: impl Iterator<Item = String>) -> Vec<String> {
    let mut seen = std::collections::HashMap::<String, usize>::new();
    stems
        .map(|stem| {
            let count = seen.entry(stem.clone()).or_insert(0);
            *count += 1;
            if *count == 1 {
                stem
            } else {
                format!("{stem}-{count}")
            }
        })
        .collect()
}

/// One bake per input: `bake capture DIR` or `bake mesh FILE`, writing
/// `<out>/<id>/asset.nelf` (and its `asset.bake.json`), with `extra` arguments
/// appended (bake options: `--resolution 96`, `--source photos`, …).
pub fn bake_items(inputs: &[(PathBuf, Option<String>)], out: &Path, extra: &[String]) -> Result<Vec<Item>> {
    if inputs.is_empty() {
        return Err(BatchError::Settings("no inputs to bake".into()));
    }
    let out = absolute(out)?;
    let ids = unique_ids(inputs.iter().map(|(path, id)| {
        id.as_deref().map_or_else(
            || {
                sanitize_id(
                    &path
                        .file_stem()
                        .map_or_else(String::new, |s| s.to_string_lossy().into_owned()),
                )
            },
            sanitize_id,
        )
    }));
    inputs
        .iter()
        .zip(ids)
        .map(|((path, _), id)| {
            let input = absolute(path)?;
            let input_text = input.to_string_lossy().into_owned();
            let what = if is_mesh(&input) { "mesh" } else { "capture" };
            let mut args = vec![
                "bake".to_string(),
                what.into(),
                input_text.clone(),
                "--out".into(),
                format!("{OUT_PLACEHOLDER}/asset.nelf"),
                "--quiet".into(),
            ];
            args.extend(extra.iter().cloned());
            Ok(Item::new(
                id.clone(),
                "bake",
                vec![input_text],
                out.join(&id),
                args,
            ))
        })
        .collect()
}

/// `nelf train data` in shards of `shard` head ids (validation heads included),
/// every shard writing into the same dataset folder `out` (each head is written
/// whole by the command itself, so the shards share it safely).
pub fn train_data_items(
    out: &Path,
    heads: u32,
    val_heads: u32,
    shard: u32,
    extra: &[String],
) -> Result<Vec<Item>> {
    if shard == 0 {
        return Err(BatchError::Settings("--shard must be at least 1 head".into()));
    }
    let total = heads + val_heads;
    if total == 0 {
        return Err(BatchError::Settings("no heads to write".into()));
    }
    let out = absolute(out)?;
    let out_text = out.to_string_lossy().into_owned();
    Ok((0..total)
        .step_by(shard as usize)
        .map(|first| {
            let last = (first + shard).min(total) - 1;
            let mut args = vec![
                "train".to_string(),
                "data".into(),
                "--out".into(),
                out_text.clone(),
                "--heads".into(),
                heads.to_string(),
                "--val-heads".into(),
                val_heads.to_string(),
                "--only-heads".into(),
                format!("{first}-{last}"),
                "--quiet".into(),
            ];
            args.extend(extra.iter().cloned());
            let mut item = Item::new(
                format!("heads-{first:05}-{last:05}"),
                "train-data",
                vec![],
                out.clone(),
                args,
            );
            item.shared_output = true;
            item.hash = item.settings_hash();
            item
        })
        .collect())
}

/// An evaluation input as the command takes it: a path made absolute, `head:SEED`
/// kept.
fn eval_input(input: &str) -> Result<String> {
    if input.starts_with("head:") {
        Ok(input.to_string())
    } else {
        Ok(absolute(Path::new(input))?.to_string_lossy().into_owned())
    }
}

/// `nelf eval pareto` one grid resolution per item, into `<out>/r<resolution>/`.
pub fn pareto_items(input: &str, out: &Path, resolutions: &[u32], extra: &[String]) -> Result<Vec<Item>> {
    if resolutions.is_empty() {
        return Err(BatchError::Settings(
            "no resolutions to sweep (--resolutions)".into(),
        ));
    }
    let out = absolute(out)?;
    let input = eval_input(input)?;
    Ok(resolutions
        .iter()
        .map(|r| {
            let mut args = vec![
                "eval".to_string(),
                "pareto".into(),
                input.clone(),
                "--resolutions".into(),
                r.to_string(),
                "--out".into(),
                OUT_PLACEHOLDER.into(),
                "--quiet".into(),
            ];
            args.extend(extra.iter().cloned());
            Item::new(
                format!("r{r}"),
                "pareto",
                vec![input.clone()],
                out.join(format!("r{r}")),
                args,
            )
        })
        .collect())
}

/// `nelf eval stability` one axis per item, into `<out>/<axis>/`.
pub fn stability_items(input: &str, out: &Path, axes: &[String], extra: &[String]) -> Result<Vec<Item>> {
    if axes.is_empty() {
        return Err(BatchError::Settings("no axes to sweep (--axes)".into()));
    }
    let out = absolute(out)?;
    let input = eval_input(input)?;
    Ok(axes
        .iter()
        .map(|axis| {
            let id = sanitize_id(axis);
            let mut args = vec![
                "eval".to_string(),
                "stability".into(),
                input.clone(),
                "--axes".into(),
                axis.clone(),
                "--out".into(),
                OUT_PLACEHOLDER.into(),
                "--quiet".into(),
            ];
            args.extend(extra.iter().cloned());
            Item::new(id.clone(), "stability", vec![input.clone()], out.join(&id), args)
        })
        .collect())
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;

    #[test]
    fn bakes_get_unique_ids_and_meshes_bake_as_meshes() {
        let inputs = vec![
            (PathBuf::from("/c/a"), None),
            (PathBuf::from("/d/a"), None),
            (PathBuf::from("/m/head.obj"), Some("scan one".into())),
        ];
        let items = bake_items(&inputs, Path::new("/out"), &["--resolution".into(), "48".into()]).unwrap();
        let ids: Vec<&str> = items.iter().map(|i| i.id.as_str()).collect();
        assert_eq!(ids, ["a", "a-2", "scan_one"]);
        assert_eq!(items[2].args[..3], ["bake", "mesh", "/m/head.obj"]);
        assert_eq!(items[0].args.last().unwrap(), "48");
        assert_eq!(items[1].output, Path::new("/out/a-2"));
    }

    #[test]
    fn shards_cover_every_head_once() {
        let items = train_data_items(Path::new("/data"), 10, 3, 4, &[]).unwrap();
        let ranges: Vec<&str> = items
            .iter()
            .map(|i| i.args[i.args.iter().position(|a| a == "--only-heads").unwrap() + 1].as_str())
            .collect();
        assert_eq!(ranges, ["0-3", "4-7", "8-11", "12-12"]);
        assert!(
            items
                .iter()
                .all(|i| i.shared_output && i.hash == i.settings_hash())
        );
    }

    #[test]
    fn a_list_skips_its_header_and_comments_and_names_a_bad_line() {
        let dir = tempfile::tempdir().unwrap();
        let list = dir.path().join("list.csv");
        std::fs::write(&list, "input,id\n# a comment\n/c/one,first\n/c/two\n\n").unwrap();
        let read = read_list(&list).unwrap();
        assert_eq!(
            read,
            vec![
                (PathBuf::from("/c/one"), Some("first".into())),
                (PathBuf::from("/c/two"), None)
            ]
        );
        std::fs::write(&list, "/c/one\n,x\n").unwrap();
        assert!(read_list(&list).unwrap_err().to_string().contains("line 2"));
    }
}
