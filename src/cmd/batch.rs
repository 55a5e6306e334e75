//! `nelf batch …`: many captures, training heads and sweeps as one batch of
//! idempotent items, run by index on Slurm, a Kubernetes Indexed Job, a farm queue
//! or this machine (`nelf_batch`; README.md "Batches on a cluster").

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use nelf_batch::Plan;
use nelf_batch::run::{ItemOutcome, RunOptions};

/// Options of `nelf batch`.
#[derive(Debug, clap::Args)]
pub struct BatchArgs {
    #[command(subcommand)]
    pub command: BatchCommand,
}

/// Batch subcommands.
#[derive(Debug, clap::Subcommand)]
pub enum BatchCommand {
    /// Write a plan (a JSON-lines manifest of work items).
    #[command(subcommand)]
    Plan(PlanCommand),
    /// Run one array index of a plan (from --index, `SLURM_ARRAY_TASK_ID` or `JOB_COMPLETION_INDEX`).
    Run(RunArgs),
    /// Run a whole plan on this machine, -j indices at a time.
    Local(LocalArgs),
    /// Write (and with --submit, submit) the plan's Slurm job array script.
    Slurm(SlurmArgs),
    /// Done / failed / missing items and the indices to submit again.
    Status(StatusArgs),
    /// Merge the items' records into CSV and JSON beside the plan.
    Collect(CollectArgs),
    /// One command per line for farm queues and GNU parallel.
    Commands(CommandsArgs),
}

/// Where a plan goes and how items group into array tasks.
#[derive(Debug, clap::Args)]
pub struct PlanOutput {
    /// The plan to write (default: `plan.jsonl` in the output folder).
    #[arg(long)]
    pub plan: Option<PathBuf>,
    /// Items per array index: keeps an array under Slurm's `MaxArraySize` and each task
    /// above a minute.
    #[arg(long, default_value_t = 1)]
    pub chunk: usize,
}

/// What to plan.
#[derive(Debug, clap::Subcommand)]
pub enum PlanCommand {
    /// Bakes of many capture folders or meshes (.obj/.off/.ply): paths or quoted globs;
    /// each writes `<out>/<id>/asset.nelf`. Bake options go after `--`.
    Bake {
        /// Capture folders or mesh files (globs the shell left are expanded).
        inputs: Vec<String>,
        /// A list of inputs instead (or as well): `path[,id]` per line.
        #[arg(long)]
        list: Option<PathBuf>,
        /// Folder of the outputs.
        #[arg(short, long)]
        out: PathBuf,
        #[command(flatten)]
        plan: PlanOutput,
        /// Options of `nelf bake` for every item.
        #[arg(last = true)]
        extra: Vec<String>,
    },
    /// `nelf train data` in shards of heads, all filling one dataset folder.
    TrainData {
        /// The dataset folder.
        #[arg(short, long)]
        out: PathBuf,
        /// Training heads.
        #[arg(long, default_value_t = 200)]
        heads: u32,
        /// Validation heads.
        #[arg(long, default_value_t = 8)]
        val_heads: u32,
        /// Heads per item.
        #[arg(long, default_value_t = 8)]
        shard: u32,
        #[command(flatten)]
        plan: PlanOutput,
        /// Options of `nelf train data` for every item (`--size 64`, `--seed 3`).
        #[arg(last = true)]
        extra: Vec<String>,
    },
    /// `nelf eval pareto`, one grid resolution per item (`<out>/r<res>/`).
    Pareto {
        /// What to evaluate (capture, mesh, `head:SEED`).
        input: String,
        #[arg(short, long)]
        out: PathBuf,
        /// Grid resolutions.
        #[arg(long, value_delimiter = ',', default_value = "64,96,128,192")]
        resolutions: Vec<u32>,
        #[command(flatten)]
        plan: PlanOutput,
        /// Options of `nelf eval pareto` for every item (`--quick`, `--ranks 2,8`).
        #[arg(last = true)]
        extra: Vec<String>,
    },
    /// `nelf eval stability`, one axis per item (`<out>/<axis>/`).
    Stability {
        /// What to evaluate (capture, mesh, `head:SEED`).
        input: String,
        #[arg(short, long)]
        out: PathBuf,
        /// Axes (default: every axis of `nelf eval stability`).
        #[arg(long, value_delimiter = ',')]
        axes: Vec<String>,
        #[command(flatten)]
        plan: PlanOutput,
        /// Options of `nelf eval stability` for every item (`--quick`).
        #[arg(last = true)]
        extra: Vec<String>,
    },
}

/// Options of `nelf batch run`.
#[derive(Debug, clap::Args)]
pub struct RunArgs {
    /// The plan.
    pub plan: PathBuf,
    /// The array index (default: `SLURM_ARRAY_TASK_ID`, then `JOB_COMPLETION_INDEX`).
    #[arg(long)]
    pub index: Option<usize>,
    /// Run items even when their done record matches.
    #[arg(long)]
    pub force: bool,
    /// Pass the items' standard output through.
    #[arg(long)]
    pub show_output: bool,
}

/// Options of `nelf batch local`.
#[derive(Debug, clap::Args)]
pub struct LocalArgs {
    /// The plan.
    pub plan: PathBuf,
    /// Indices run at once.
    #[arg(short, long, default_value_t = 1)]
    pub jobs: usize,
    /// No progress bar.
    #[arg(long)]
    pub quiet: bool,
}

/// Options of `nelf batch slurm`.
#[derive(Debug, clap::Args)]
pub struct SlurmArgs {
    /// The plan.
    pub plan: PathBuf,
    /// CPUs per array task.
    #[arg(long, default_value_t = 2)]
    pub cpus: u32,
    /// Memory per array task.
    #[arg(long, default_value = "8G")]
    pub mem: String,
    /// Time limit per item, minutes (a task gets this × the chunk).
    #[arg(long, default_value_t = 30)]
    pub minutes_per_item: u32,
    /// Array tasks running at once (0: as many as Slurm gives).
    #[arg(long, default_value_t = 0)]
    pub max_parallel: usize,
    /// Slurm partition (default: the cluster's default).
    #[arg(long)]
    pub partition: Option<String>,
    /// Only these indices (`0-3,7`, as `nelf batch status` prints them).
    #[arg(long)]
    pub indices: Option<String>,
    /// More `#SBATCH` options (repeatable: `--sbatch=--account=lab`).
    #[arg(long = "sbatch", allow_hyphen_values = true)]
    pub extra: Vec<String>,
    /// The `nelf` every node runs (default: this one; it must be on the shared file system).
    #[arg(long)]
    pub nelf: Option<PathBuf>,
    /// Submit the script with sbatch.
    #[arg(long)]
    pub submit: bool,
    /// With --submit: wait for the array to end, then print the status.
    #[arg(long, requires = "submit")]
    pub wait: bool,
}

/// Options of `nelf batch status`.
#[derive(Debug, clap::Args)]
pub struct StatusArgs {
    /// The plan.
    pub plan: PathBuf,
    /// Print JSON.
    #[arg(long)]
    pub json: bool,
    /// Exit non-zero unless every item is done.
    #[arg(long)]
    pub check: bool,
}

/// Options of `nelf batch collect`.
#[derive(Debug, clap::Args)]
pub struct CollectArgs {
    /// The plan.
    pub plan: PathBuf,
    /// Folder for results.csv and results.json (default: beside the plan,
    /// `plan.results.csv`, `plan.results.json`).
    #[arg(long)]
    pub out: Option<PathBuf>,
}

/// Options of `nelf batch commands`.
#[derive(Debug, clap::Args)]
pub struct CommandsArgs {
    /// The plan.
    pub plan: PathBuf,
    /// Print each item's own command writing straight to its output (no staging,
    /// no record) instead of `nelf batch run PLAN --index N`.
    #[arg(long)]
    pub direct: bool,
    /// The `nelf` the commands name (default: this one).
    #[arg(long)]
    pub nelf: Option<PathBuf>,
}

fn read_plan(path: &Path) -> anyhow::Result<Plan> {
    Plan::read(path).with_context(|| format!("reading the plan {}", path.display()))
}

fn this_nelf(given: Option<&Path>) -> anyhow::Result<PathBuf> {
    match given {
        Some(path) => Ok(std::path::absolute(path)?),
        None => std::env::current_exe().context("finding this nelf binary"),
    }
}

pub fn run(args: &BatchArgs) -> anyhow::Result<()> {
    match &args.command {
        BatchCommand::Plan(command) => plan(command),
        BatchCommand::Run(run) => run_index(run),
        BatchCommand::Local(local) => run_local(local),
        BatchCommand::Slurm(slurm) => write_slurm(slurm),
        BatchCommand::Status(status) => print_status(status),
        BatchCommand::Collect(collect) => {
            let plan = read_plan(&collect.plan)?;
            let done = nelf_batch::collect::collect(&plan, collect.out.as_deref())
                .with_context(|| format!("collecting the results of {}", plan.path.display()))?;
            println!(
                "{} done, {} failed, {} not done: {} and {}",
                done.done,
                done.failed,
                done.other,
                done.csv.display(),
                done.json.display()
            );
            merge_sweeps(&plan, collect.out.as_deref())
        }
        BatchCommand::Commands(commands) => {
            let plan = read_plan(&commands.plan)?;
            let nelf = this_nelf(commands.nelf.as_deref())?;
            let lines = if commands.direct {
                nelf_batch::direct_commands(&plan, &nelf)
            } else {
                nelf_batch::task_commands(&plan, &nelf)
            };
            print_out(&(lines.join("\n") + "\n"))
        }
    }
}

/// For a plan of `nelf eval pareto` or `stability` parts: the report one machine's
/// sweep writes, from the parts that are done, in `<plan folder>/report/` (or the
/// collect folder's).
fn merge_sweeps(plan: &Plan, out: Option<&Path>) -> anyhow::Result<()> {
    let Some(kind) = plan.items.first().map(|i| i.kind.clone()) else {
        return Ok(());
    };
    if kind != "pareto" && kind != "stability" {
        return Ok(());
    }
    let mut parts = Vec::new();
    for item in &plan.items {
        if item.kind != kind {
            bail!(
                "{}: a sweep plan mixes {kind} and {} items",
                plan.path.display(),
                item.kind
            );
        }
        if nelf_batch::run::is_done(plan, item)? {
            parts.push(item.output.clone());
        }
    }
    if parts.is_empty() {
        println!("no {kind} part is done yet: no report");
        return Ok(());
    }
    let dir = out
        .map(Path::to_path_buf)
        .or_else(|| plan.path.parent().map(|p| p.join("report")))
        .context("the plan has no folder")?;
    if kind == "pareto" {
        nelf_eval::merge::merge_pareto(&parts, &dir)
            .with_context(|| format!("merging {} Pareto parts into {}", parts.len(), dir.display()))?;
    } else {
        nelf_eval::merge::merge_stability(&parts, &dir)
            .with_context(|| format!("merging {} stability parts into {}", parts.len(), dir.display()))?;
    }
    println!(
        "{kind} report of {} of {} parts: {}",
        parts.len(),
        plan.items.len(),
        dir.join("report.html").display()
    );
    Ok(())
}

fn plan(command: &PlanCommand) -> anyhow::Result<()> {
    let (items, out, output) = match command {
        PlanCommand::Bake {
            inputs,
            list,
            out,
            plan,
            extra,
        } => {
            let mut all: Vec<(PathBuf, Option<String>)> = nelf_batch::plan::expand_inputs(inputs)?
                .into_iter()
                .map(|p| (p, None))
                .collect();
            if let Some(list) = list {
                all.extend(
                    nelf_batch::plan::read_list(list)
                        .with_context(|| format!("reading the list {}", list.display()))?,
                );
            }
            (nelf_batch::plan::bake_items(&all, out, extra)?, out, plan)
        }
        PlanCommand::TrainData {
            out,
            heads,
            val_heads,
            shard,
            plan,
            extra,
        } => (
            nelf_batch::plan::train_data_items(out, *heads, *val_heads, *shard, extra)?,
            out,
            plan,
        ),
        PlanCommand::Pareto {
            input,
            out,
            resolutions,
            plan,
            extra,
        } => (
            nelf_batch::plan::pareto_items(input, out, resolutions, extra)?,
            out,
            plan,
        ),
        PlanCommand::Stability {
            input,
            out,
            axes,
            plan,
            extra,
        } => {
            let known = nelf_eval::stability::AXES;
            if let Some(bad) = axes.iter().find(|a| !known.contains(&a.as_str())) {
                bail!("--axes: unknown axis {bad:?} (known: {})", known.join(", "));
            }
            let axes: Vec<String> = if axes.is_empty() {
                known.iter().map(|a| (*a).to_string()).collect()
            } else {
                axes.clone()
            };
            (
                nelf_batch::plan::stability_items(input, out, &axes, extra)?,
                out,
                plan,
            )
        }
    };
    let path = output.plan.clone().unwrap_or_else(|| out.join("plan.jsonl"));
    let plan = Plan::new(&path, output.chunk, items)?;
    plan.write()?;
    println!(
        "{}: {} items in {} array indices (0-{}) of up to {}",
        plan.path.display(),
        plan.items.len(),
        plan.tasks(),
        plan.tasks() - 1,
        plan.chunk
    );
    Ok(())
}

fn run_index(args: &RunArgs) -> anyhow::Result<()> {
    let plan = read_plan(&args.plan)?;
    let index = nelf_batch::run::resolve_index(args.index, |name| std::env::var(name).ok())?;
    let options = RunOptions {
        program: this_nelf(None)?,
        force: args.force,
        show_output: args.show_output,
    };
    let items = plan.task_items(index)?.len();
    eprintln!(
        "nelf batch: index {index} of {} ({items} items) on {}",
        plan.path.display(),
        nelf_batch::run::host_name()
    );
    let outcomes = nelf_batch::run::run_task(&plan, index, &options)?;
    let mut failed = Vec::new();
    for (item, outcome) in plan.task_items(index)?.iter().zip(&outcomes) {
        match outcome {
            ItemOutcome::Skipped => println!("{}: already done", item.id),
            ItemOutcome::Done(r) => println!("{}: done in {:.1} s", item.id, r.secs),
            ItemOutcome::Failed(r) => {
                println!(
                    "{}: FAILED: {}",
                    item.id,
                    nelf_batch::record::error_summary(&r.error)
                );
                failed.push(item.id.clone());
            }
        }
    }
    if !failed.is_empty() {
        bail!(
            "{} of {items} items of index {index} failed ({}); their records are in {}",
            failed.len(),
            failed.join(", "),
            plan.results_dir().display()
        );
    }
    Ok(())
}

fn run_local(args: &LocalArgs) -> anyhow::Result<()> {
    let plan = read_plan(&args.plan)?;
    let options = RunOptions {
        program: this_nelf(None)?,
        force: false,
        show_output: false,
    };
    let bar = if args.quiet {
        indicatif::ProgressBar::hidden()
    } else {
        indicatif::ProgressBar::new(0)
    };
    let report = nelf_batch::local::run_local(&plan, args.jobs, &options, &bar)?;
    println!(
        "{} done, {} already done, {} failed in {:.1} s ({} at a time)",
        report.done, report.skipped, report.failed, report.secs, args.jobs
    );
    if report.failed > 0 {
        for error in &report.errors {
            println!("  {error}");
        }
        bail!(
            "{} items failed; `nelf batch status {}` lists them",
            report.failed,
            plan.path.display()
        );
    }
    Ok(())
}

fn write_slurm(args: &SlurmArgs) -> anyhow::Result<()> {
    let plan = read_plan(&args.plan)?;
    let options = nelf_batch::slurm::SlurmOptions {
        program: this_nelf(args.nelf.as_deref())?,
        cpus: args.cpus,
        mem: args.mem.clone(),
        minutes_per_item: args.minutes_per_item,
        max_parallel: args.max_parallel,
        partition: args.partition.clone(),
        indices: args
            .indices
            .as_deref()
            .map(nelf_batch::manifest::parse_ranges)
            .transpose()?,
        extra: args.extra.clone(),
    };
    let script = nelf_batch::slurm::write_script(&plan, &options)?;
    println!("sbatch script: {}", script.display());
    if args.submit {
        let job = nelf_batch::slurm::submit(&script)?;
        println!("submitted job {job}; logs in {}", plan.logs_dir().display());
        if args.wait {
            nelf_batch::slurm::wait_for(&job, std::time::Duration::from_secs(1))?;
            print_status(&StatusArgs {
                plan: plan.path.clone(),
                json: false,
                check: false,
            })?;
        }
    }
    Ok(())
}

/// Writes `text` to standard output; a reader that went away (`| head`) ends the
/// output quietly instead of a panic.
fn print_out(text: &str) -> anyhow::Result<()> {
    use std::io::Write as _;
    let mut out = std::io::stdout().lock();
    match out.write_all(text.as_bytes()).and_then(|()| out.flush()) {
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => Ok(()),
        other => Ok(other.context("writing to standard output")?),
    }
}

fn print_status(args: &StatusArgs) -> anyhow::Result<()> {
    use std::fmt::Write as _;
    let plan = read_plan(&args.plan)?;
    let status = nelf_batch::status::batch_status(&plan)?;
    let mut text = String::new();
    if args.json {
        text = serde_json::to_string_pretty(&status)? + "\n";
    } else {
        let _ = writeln!(
            text,
            "{}: {} items in {} indices: {} done, {} failed, {} changed since they ran, {} missing",
            plan.path.display(),
            status.items,
            status.tasks,
            status.done,
            status.failed,
            status.changed,
            status.missing
        );
        for (id, error) in &status.failures {
            let _ = writeln!(text, "  failed {id}: {error}");
        }
        for staging in &status.staging {
            let _ = writeln!(
                text,
                "  staging (running, or killed on another host): {}",
                staging.display()
            );
        }
        if status.resubmit.is_empty() {
            text.push_str("all done\n");
        } else {
            let _ = writeln!(text, "to run again: --indices {}", status.resubmit);
        }
    }
    print_out(&text)?;
    if args.check && !status.complete() {
        bail!(
            "{} of {} items are not done",
            status.items - status.done,
            status.items
        );
    }
    Ok(())
}
