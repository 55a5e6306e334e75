//! Batches that outgrow one machine. A plan (`manifest`) lists idempotent work
//! items, each a `nelf` command writing its own output folder; any engine that hands
//! out array indices runs them (`run`: Slurm's `SLURM_ARRAY_TASK_ID`, a Kubernetes
//! Indexed Job's `JOB_COMPLETION_INDEX`, a farm queue's command line, or `local` on
//! this machine). Outputs appear whole or not at all (staging folder + rename on the
//! shared file system), each item leaves a record (`record`), and `status` and
//! `collect` read the records. `slurm` writes and submits the job array.
//!
//! No locks and no server: the only shared state is files, written atomically, and
//! the items' commands are deterministic, so a duplicated or repeated run is harmless.

pub mod collect;
pub mod error;
pub mod local;
pub mod manifest;
pub mod plan;
pub mod record;
pub mod run;
pub mod slurm;
pub mod status;

pub use error::{BatchError, Result};
pub use manifest::{Item, Plan};

/// `text` quoted for a POSIX shell (as it is when it needs no quotes).
pub fn shell_quote(text: &str) -> String {
    // try_quote refuses only a NUL byte, which no path or argument can hold.
    shlex::try_quote(text).map_or_else(
        |_| format!("'{}'", text.replace('\'', "'\\''")),
        std::borrow::Cow::into_owned,
    )
}

/// A shell-quoted command line of `program` and `args`.
pub fn command_line(program: &std::path::Path, args: &[String]) -> String {
    std::iter::once(shell_quote(&program.to_string_lossy()))
        .chain(args.iter().map(|a| shell_quote(a)))
        .collect::<Vec<_>>()
        .join(" ")
}

/// One command per array index (`nelf batch run PLAN --index N`), for farm queues
/// and GNU parallel that take a text file of commands.
pub fn task_commands(plan: &Plan, program: &std::path::Path) -> Vec<String> {
    (0..plan.tasks())
        .map(|index| {
            command_line(
                program,
                &[
                    "batch".into(),
                    "run".into(),
                    plan.path.to_string_lossy().into_owned(),
                    "--index".into(),
                    index.to_string(),
                ],
            )
        })
        .collect()
}

/// Each item's own command writing straight to its output (no staging, no record),
/// run in the item's folder: what the batch runs, one by one.
pub fn direct_commands(plan: &Plan, program: &std::path::Path) -> Vec<String> {
    plan.items
        .iter()
        .map(|item| {
            let command = command_line(program, &item.args_writing_to(&item.output));
            if item.workdir.as_os_str().is_empty() {
                command
            } else {
                format!("cd {} && {command}", command_line(&item.workdir, &[]))
            }
        })
        .collect()
}
