//! The faults a batch must survive without losing anything, with `/bin/sh` standing
//! in for `nelf` (each item is a small shell script writing into `{out}`): killed
//! items, two runs of one index at once, a failing item among good ones, a manifest
//! edited after planning. The same faults with the real `nelf` and a real Slurm
//! cluster are in the root crate's `tests/batch.rs`.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::{Path, PathBuf};

use nelf_batch::manifest::{Item, OUT_PLACEHOLDER, Plan};
use nelf_batch::record::{ItemStatus, read_record};
use nelf_batch::run::{ItemOutcome, RunOptions, run_item, run_task};
use nelf_batch::status::{ItemState, batch_status};

fn sh() -> RunOptions {
    RunOptions {
        program: PathBuf::from("/bin/sh"),
        force: false,
        show_output: false,
    }
}

/// An item running `script` (with `$OUT` set to its folder).
fn item(id: &str, root: &Path, script: &str) -> Item {
    Item::new(
        id.into(),
        "command",
        vec![],
        root.join("out").join(id),
        vec!["-c".into(), format!("OUT='{OUT_PLACEHOLDER}'; {script}")],
    )
}

/// Deterministic output: two files, one of 64 KiB.
const GOOD: &str = r#"echo "$0" > "$OUT/a.txt"; head -c 65536 /dev/zero | tr '\0' x > "$OUT/big.bin""#;

fn files(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut out: Vec<(String, Vec<u8>)> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| {
            let p = e.unwrap().path();
            (
                p.file_name().unwrap().to_string_lossy().into_owned(),
                std::fs::read(&p).unwrap(),
            )
        })
        .collect();
    out.sort();
    out
}

fn leftovers(root: &Path) -> Vec<String> {
    std::fs::read_dir(root.join("out"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.contains(".part-") || n.contains(".old-"))
        .collect()
}

#[test]
fn items_run_once_write_whole_outputs_and_records_and_are_skipped_when_done() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path();
    let items = (0..5).map(|i| item(&format!("i{i}"), root, GOOD)).collect();
    let plan = Plan::new(&root.join("plan.jsonl"), 2, items).unwrap();
    plan.write().unwrap();
    for index in 0..plan.tasks() {
        let outcomes = run_task(&plan, index, &sh()).unwrap();
        assert!(outcomes.iter().all(|o| matches!(o, ItemOutcome::Done(_))));
    }
    let status = batch_status(&plan).unwrap();
    assert!(status.complete(), "{status:?}");
    assert_eq!(status.resubmit, "");
    let record = read_record(&plan.results_dir(), "i3").unwrap().unwrap();
    assert_eq!(record.status, ItemStatus::Done);
    assert_eq!(record.outputs.len(), 2);
    assert_eq!(record.outputs[1].bytes, 65536);
    // Run again: everything is skipped and nothing changes.
    let before = files(&root.join("out/i3"));
    let outcomes = run_task(&plan, 1, &sh()).unwrap();
    assert_eq!(outcomes, vec![ItemOutcome::Skipped, ItemOutcome::Skipped]);
    assert_eq!(files(&root.join("out/i3")), before);
    assert!(leftovers(root).is_empty());
}

#[test]
fn an_item_killed_mid_write_leaves_no_output_and_its_rerun_completes_it() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path();
    let flag = root.join("second-try");
    // The first try writes half its output, then is killed with SIGKILL.
    let killed = format!(
        r#"echo part > "$OUT/a.txt"; if [ ! -e '{flag}' ]; then touch '{flag}'; kill -9 $$; fi; {GOOD}"#,
        flag = flag.display()
    );
    let plan = Plan::new(
        &root.join("plan.jsonl"),
        1,
        vec![item("good", root, GOOD), item("killed", root, &killed)],
    )
    .unwrap();
    plan.write().unwrap();
    run_task(&plan, 0, &sh()).unwrap();
    let good_before = files(&root.join("out/good"));
    let outcome = run_task(&plan, 1, &sh()).unwrap().remove(0);
    let ItemOutcome::Failed(record) = outcome else {
        panic!("{outcome:?}")
    };
    assert_eq!(record.exit_code, None, "killed by a signal");
    assert!(record.error.contains("killed by a signal"), "{}", record.error);
    assert!(
        !root.join("out/killed").exists(),
        "no partial output at the final path"
    );
    assert!(leftovers(root).is_empty(), "{:?}", leftovers(root));
    let status = batch_status(&plan).unwrap();
    assert_eq!((status.done, status.failed), (1, 1));
    assert_eq!(status.resubmit, "1");
    // The rerun completes it; the other item is untouched.
    assert!(matches!(
        run_task(&plan, 1, &sh()).unwrap()[0],
        ItemOutcome::Done(_)
    ));
    assert_eq!(
        files(&root.join("out/killed")),
        good_before,
        "the rerun's output is whole"
    );
    assert_eq!(files(&root.join("out/good")), good_before);
    assert!(batch_status(&plan).unwrap().complete());
}

#[test]
fn a_killed_runner_leaves_only_a_staging_folder_that_the_next_run_clears() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path();
    let plan = Plan::new(&root.join("plan.jsonl"), 1, vec![item("x", root, GOOD)]).unwrap();
    // What a runner killed with its item leaves: a staging folder of a process that is
    // gone (pid 2^22 + 1 is above Linux's largest pid).
    let host = nelf_batch::run::host_name();
    let stale = root.join("out").join(format!("x.part-{host}-4194305.0"));
    std::fs::create_dir_all(&stale).unwrap();
    std::fs::write(stale.join("a.txt"), "half").unwrap();
    // Another host's staging folder is not ours to judge.
    let foreign = root.join("out/x.part-elsewhere-1.0");
    std::fs::create_dir_all(&foreign).unwrap();
    assert_eq!(batch_status(&plan).unwrap().staging.len(), 2);
    assert!(matches!(
        run_item(&plan, &plan.items[0], &sh()).unwrap(),
        ItemOutcome::Done(_)
    ));
    assert!(!stale.exists() && foreign.exists());
    assert_eq!(
        std::fs::read_to_string(root.join("out/x/a.txt")).unwrap().trim(),
        "/bin/sh"
    );
}

#[test]
fn two_runs_of_one_index_at_once_both_finish_with_one_whole_output() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path();
    // Slow enough that the two runs overlap.
    let slow = format!("sleep 0.3; {GOOD}");
    let plan = Plan::new(&root.join("plan.jsonl"), 1, vec![item("twice", root, &slow)]).unwrap();
    plan.write().unwrap();
    let outcomes: Vec<ItemOutcome> = std::thread::scope(|s| {
        let a = s.spawn(|| run_task(&plan, 0, &sh()).unwrap().remove(0));
        let b = s.spawn(|| run_task(&plan, 0, &sh()).unwrap().remove(0));
        vec![a.join().unwrap(), b.join().unwrap()]
    });
    let records: Vec<_> = outcomes
        .iter()
        .map(|o| match o {
            ItemOutcome::Done(r) => r.clone(),
            other => panic!("{other:?}"),
        })
        .collect();
    assert_eq!(records[0].outputs, records[1].outputs, "identical outputs");
    let now = nelf_batch::record::list_outputs(&root.join("out/twice")).unwrap();
    assert_eq!(now, records[0].outputs, "the output in place is whole");
    assert!(leftovers(root).is_empty(), "{:?}", leftovers(root));
}

#[test]
fn a_failing_item_records_its_error_and_the_others_finish() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path();
    let bad = r#"echo "capture /data/bad: cameras.json line 3: not JSON" >&2; exit 3"#;
    let plan = Plan::new(
        &root.join("plan.jsonl"),
        3,
        vec![
            item("a", root, GOOD),
            item("bad", root, bad),
            item("c", root, GOOD),
        ],
    )
    .unwrap();
    plan.write().unwrap();
    let outcomes = run_task(&plan, 0, &sh()).unwrap();
    assert!(matches!(outcomes[0], ItemOutcome::Done(_)) && matches!(outcomes[2], ItemOutcome::Done(_)));
    let ItemOutcome::Failed(record) = &outcomes[1] else {
        panic!()
    };
    assert_eq!(record.exit_code, Some(3));
    assert!(record.error.contains("cameras.json line 3"));
    assert!(!root.join("out/bad").exists());
    let status = batch_status(&plan).unwrap();
    assert_eq!(
        status.failures,
        vec![(
            "bad".to_string(),
            "capture /data/bad: cameras.json line 3: not JSON".to_string()
        )]
    );
    let collected = nelf_batch::collect::collect(&plan, None).unwrap();
    assert_eq!((collected.done, collected.failed), (2, 1));
    let csv = std::fs::read_to_string(collected.csv).unwrap();
    assert!(
        csv.lines()
            .any(|l| l.starts_with("bad,command,failed,") && l.contains("not JSON")),
        "{csv}"
    );
}

#[test]
fn an_edited_item_runs_again_and_the_others_are_kept() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path();
    let plan = Plan::new(
        &root.join("plan.jsonl"),
        1,
        vec![item("a", root, GOOD), item("b", root, GOOD)],
    )
    .unwrap();
    plan.write().unwrap();
    for index in 0..2 {
        run_task(&plan, index, &sh()).unwrap();
    }
    // Edit item b's settings in the manifest by hand (its stored hash is left stale).
    let text = std::fs::read_to_string(&plan.path).unwrap();
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    let b = lines[2].replace(r#"big.bin\""]"#, r#"big.bin\"; echo v2 > \"$OUT/v2.txt\""]"#);
    assert_ne!(b, lines[2]);
    lines[2] = b;
    std::fs::write(&plan.path, lines.join("\n") + "\n").unwrap();
    let plan = Plan::read(&plan.path).unwrap();
    let status = batch_status(&plan).unwrap();
    assert_eq!(status.states[1], ("b".to_string(), ItemState::Changed));
    assert_eq!(status.resubmit, "1");
    let a_before = files(&root.join("out/a"));
    assert_eq!(run_task(&plan, 0, &sh()).unwrap(), vec![ItemOutcome::Skipped]);
    assert!(matches!(
        run_task(&plan, 1, &sh()).unwrap()[0],
        ItemOutcome::Done(_)
    ));
    assert!(
        root.join("out/b/v2.txt").exists(),
        "the old output was replaced whole"
    );
    assert_eq!(files(&root.join("out/a")), a_before);
    assert!(leftovers(root).is_empty());
    assert!(batch_status(&plan).unwrap().complete());
}

#[test]
fn a_shard_of_a_shared_folder_is_done_only_in_the_folder_it_filled() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path();
    let shared = root.join("dataset");
    let shard = |id: &str| {
        let mut item = Item::new(
            id.into(),
            "command",
            vec![],
            shared.clone(),
            vec![
                "-c".into(),
                format!("echo {id} > '{}/{id}.txt'", shared.display()),
            ],
        );
        item.shared_output = true;
        item.hash = item.settings_hash();
        item
    };
    let plan = Plan::new(&root.join("plan.jsonl"), 1, vec![shard("s0"), shard("s1")]).unwrap();
    assert!(matches!(
        run_task(&plan, 0, &sh()).unwrap()[0],
        ItemOutcome::Done(_)
    ));
    assert_eq!(run_task(&plan, 0, &sh()).unwrap(), vec![ItemOutcome::Skipped]);
    // The dataset is deleted; the other shard makes the folder again.
    std::fs::remove_dir_all(&shared).unwrap();
    assert!(matches!(
        run_task(&plan, 1, &sh()).unwrap()[0],
        ItemOutcome::Done(_)
    ));
    let status = batch_status(&plan).unwrap();
    assert_eq!(status.states[0], ("s0".to_string(), ItemState::Changed));
    assert_eq!(status.resubmit, "0");
    assert!(matches!(
        run_task(&plan, 0, &sh()).unwrap()[0],
        ItemOutcome::Done(_)
    ));
    assert!(shared.join("s0.txt").is_file() && shared.join("s1.txt").is_file());
    assert!(batch_status(&plan).unwrap().complete());
}
