//! `facelab run SPEC --launcher slurm`: a run as Slurm jobs over the shared cache.
//!
//! The units of work are a cell's stages for one seed. Two job arrays and a final job:
//! - `cells`: one task per sweep cell, with its first seed: the seed-independent stages (the
//!   dataset, the cohorts, the head-neck experiment) and the first seed's (its networks, its
//!   transfers, the inversion, the pose transfer, its real files);
//! - `seeds` (after `cells` succeeded): one task per cell and further seed: that seed's
//!   networks, transfers and real files;
//! - `final` (after both ended, however): the run itself, reading every unit from the cache:
//!   it assembles the tables, figures and manifest, or names the units that are missing.
//!
//! Each task is `facelab task <launch.json> <array>` (the task's index from Slurm), writing
//! into the cache only; units are stored atomically and computed under the cache's unit locks,
//! so tasks, resubmissions and local runs share one cache. A task whose units are all cached
//! is not submitted, so resubmitting after a failure submits only what is missing. The run
//! folder (`run-NNNN.partial` until the final job finishes) holds `logs/`: `launch.json`
//! (the tasks, their units and job ids), each task's log and, once it succeeded, its
//! `.done.json` (host, seconds, job id).

use crate::io::Layout;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use serde::{Deserialize, Serialize};

use crate::cache::{self, Cache, Lookup};
use crate::io::atomic::write_atomic;
use crate::run::cell::{assets, Assets, CellRun, Experiment, Plan, Registry, Sink};
use crate::spec::{self, Cell, LauncherParams, Spec};

use super::folders::{finished_path, new_run_dir, OWNER, PARTIAL};
use super::{RunOptions, UnitState};

/// The record of a submission, `logs/launch.json`.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub(super) struct Launch {
    spec: PathBuf,
    sets: Vec<String>,
    results: PathBuf,
    publish: bool,
    /// Job ids: the two arrays (when submitted) and the final job.
    jobs: Jobs,
    tasks: Vec<Task>,
}

#[derive(Clone, Debug, Default, Serialize, Deserialize)]
struct Jobs {
    cells: Option<String>,
    seeds: Option<String>,
    #[serde(rename = "final")]
    last: Option<String>,
}

/// One array task: a cell with one seed, and the units it makes.
#[derive(Clone, Debug, Serialize, Deserialize)]
struct Task {
    array: String,
    index: usize,
    cell: usize,
    cell_name: String,
    seed: u64,
    /// Unit ids (`stage/key`) the task makes, as planned at submission.
    units: Vec<String>,
}

impl Task {
    fn name(&self) -> String {
        format!("{}-{}", self.array, self.index)
    }

    fn describe(&self) -> String {
        let cell = if self.cell_name.is_empty() {
            String::new()
        } else {
            format!("[{}] ", self.cell_name)
        };
        format!("task {} ({cell}seed {})", self.name(), self.seed)
    }
}

/// What a finished task records, `logs/<array>-<index>.done.json`.
#[derive(Clone, Debug, Serialize, Deserialize)]
struct Done {
    job: String,
    host: String,
    seconds: f64,
}

/// What `launch` submitted.
pub struct Launched {
    /// The run folder (`run-NNNN.partial` until the final job finishes, then `run-NNNN`).
    pub run_dir: PathBuf,
    pub cells_job: Option<String>,
    pub seeds_job: Option<String>,
    pub final_job: String,
    /// Tasks submitted, and tasks left out because the cache holds all their units.
    pub tasks: usize,
    pub skipped: usize,
}

/// A cell's spec as one task computes it: only `seed` (no key hashes the list of seeds; the
/// tables stay, since which ones a spec lists decides keys, e.g. whether the dataset starts
/// from the basis).
fn task_spec(spec: &Spec, seed: u64) -> Spec {
    let mut s = spec.clone();
    s.seeds = vec![seed];
    s
}

/// The experiments a task of `seed` runs: a further seed leaves out those only the first
/// seed's network feeds (the inversion, the head-neck experiment, the pose transfer).
fn task_experiments(cell: &Spec, seed: u64, registry: Registry) -> Vec<&'static dyn Experiment> {
    let first = cell.seeds.first() == Some(&seed);
    registry
        .0
        .iter()
        .copied()
        .filter(|e| first || !e.first_seed_only())
        .collect()
}

/// A task's units (ids) and whether the cache holds each.
fn task_units(
    cell: &Cell,
    seed: u64,
    a: &Assets,
    cache: &Cache,
    registry: Registry,
) -> Result<Vec<(String, bool)>> {
    let spec = task_spec(&cell.spec, seed);
    let experiments = task_experiments(&cell.spec, seed, registry);
    let plan = Plan::of(&spec, &cell.name, a, cache, &experiments, false)?;
    Ok(plan
        .into_iter()
        .map(|p| match p.unit {
            Ok(u) => {
                let cached = matches!(cache.inspect(u.stage, &u.key), Lookup::Hit(_));
                (format!("{}/{}", u.stage, u.key), cached)
            }
            Err(_) => (format!("{}/?", p.label), false),
        })
        .collect())
}

/// `sbatch` must be there before anything is written.
fn require_slurm() -> Result<()> {
    match Command::new("sbatch").arg("--version").output() {
        Ok(o) if o.status.success() => Ok(()),
        _ => bail!(
            "Slurm is not installed (or not on PATH): `sbatch --version` failed. Install Slurm's \
             client commands (Debian: slurm-client) or run without --launcher slurm"
        ),
    }
}

/// `sbatch --parsable args...`: the job id.
fn sbatch(args: &[String]) -> Result<String> {
    let out = Command::new("sbatch")
        .arg("--parsable")
        .args(args)
        .output()
        .context("running sbatch")?;
    if !out.status.success() {
        bail!(
            "sbatch {} failed: {}",
            args.join(" "),
            String::from_utf8_lossy(&out.stderr).trim()
        );
    }
    let text = String::from_utf8_lossy(&out.stdout);
    let id = text.trim().split(';').next().unwrap_or("").to_string();
    if id.is_empty() {
        bail!("sbatch printed no job id");
    }
    Ok(id)
}

/// The `sbatch` options of the spec's `[launcher]`.
fn options(l: &LauncherParams) -> Vec<String> {
    let mut o = Vec::new();
    let mut add = |flag: &str, v: &Option<String>| {
        if let Some(v) = v {
            o.push(format!("--{flag}={v}"));
        }
    };
    add("partition", &l.partition);
    add("time", &l.time);
    add("mem", &l.mem);
    add("account", &l.account);
    o.push(format!("--cpus-per-task={}", l.cpus_per_task.unwrap_or(2)));
    o.extend(l.sbatch.iter().cloned());
    o
}

fn absolute(p: &Path) -> Result<PathBuf> {
    std::path::absolute(p).with_context(|| format!("{}: cannot resolve", p.display()))
}

/// A shell word.
fn quote(s: &str) -> String {
    format!("'{}'", s.replace('\'', r"'\''"))
}

/// `stage/key-prefix`, as logs name a unit.
fn short(id: &str) -> &str {
    let end = id.find('/').map_or(id.len(), |p| (p + 13).min(id.len()));
    &id[..end]
}

fn logs(run_dir: &Path) -> PathBuf {
    run_dir.join("logs")
}

fn write_launch(run_dir: &Path, launch: &Launch) -> Result<()> {
    let text = serde_json::to_string_pretty(launch)?;
    Ok(write_atomic(
        &logs(run_dir).join("launch.json"),
        text.as_bytes(),
    )?)
}

fn read_launch(path: &Path) -> Result<Launch> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("{}: cannot read", path.display()))?;
    serde_json::from_str(&text).with_context(|| format!("{}: not a launch record", path.display()))
}

/// Submits a spec's run as Slurm jobs (see the module's documentation).
pub fn launch(spec_path: &Path, opts: &RunOptions) -> Result<Launched> {
    require_slurm()?;
    let cells = spec::load(&opts.layout, spec_path, &opts.sets)?;
    let a = assets(&opts.layout)?;
    let results = absolute(&opts.results)?;
    let cache = Cache::new(&results.join(".cache"));
    let launcher = cells[0].spec.launcher.clone();
    let mut tasks = Vec::new();
    let mut skipped = 0;
    for (i, c) in cells.iter().enumerate() {
        for (s, &seed) in c.spec.seeds.iter().enumerate() {
            let units = task_units(c, seed, &a, &cache, opts.registry)?;
            if units.iter().all(|(_, cached)| *cached) {
                skipped += 1;
                continue;
            }
            let array = if s == 0 { "cells" } else { "seeds" };
            let index = tasks.iter().filter(|t: &&Task| t.array == array).count();
            tasks.push(Task {
                array: array.into(),
                index,
                cell: i,
                cell_name: c.name.clone(),
                seed,
                units: units.into_iter().map(|(id, _)| id).collect(),
            });
        }
    }
    let experiment_dir = results.join(&cells[0].spec.experiment);
    let run_dir = new_run_dir(&experiment_dir)?;
    std::fs::create_dir_all(logs(&run_dir))
        .with_context(|| format!("{}: cannot create", logs(&run_dir).display()))?;
    let mut launch = Launch {
        spec: absolute(spec_path)?,
        sets: opts.sets.clone(),
        results: results.clone(),
        publish: opts.publish,
        jobs: Jobs::default(),
        tasks,
    };
    write_launch(&run_dir, &launch)?;
    let binary = std::env::current_exe().context("finding the facelab binary")?;
    let workdir = std::env::current_dir().context("the working folder")?;
    let launch_file = logs(&run_dir).join("launch.json");
    let name = format!("--job-name=facelab-{}", cells[0].spec.experiment);
    let common = |log: String| -> Vec<String> {
        let mut o = vec![
            name.clone(),
            format!("--chdir={}", workdir.display()),
            format!("--output={}", logs(&run_dir).join(log).display()),
        ];
        o.extend(options(&launcher));
        o
    };
    let array_job = |array: &str, after: Option<&String>| -> Result<Option<String>> {
        let n = launch.tasks.iter().filter(|t| t.array == array).count();
        if n == 0 {
            return Ok(None);
        }
        let mut args = common(format!("{array}-%a.log"));
        args.push(format!("--array=0-{}", n - 1));
        if let Some(after) = after {
            args.push(format!("--dependency=afterok:{after}"));
            args.push("--kill-on-invalid-dep=yes".into());
        }
        args.push(format!(
            "--wrap=exec {} task {} {array}",
            quote(&binary.display().to_string()),
            quote(&launch_file.display().to_string())
        ));
        sbatch(&args).map(Some)
    };
    let cells_job = array_job("cells", None)?;
    let seeds_job = array_job("seeds", cells_job.as_ref())?;
    launch.jobs.cells = cells_job.clone();
    launch.jobs.seeds = seeds_job.clone();
    write_launch(&run_dir, &launch)?;
    let mut args = common("final.log".into());
    let after: Vec<&String> = cells_job.iter().chain(&seeds_job).collect();
    if !after.is_empty() {
        let ids: Vec<&str> = after.iter().map(|s| s.as_str()).collect();
        args.push(format!("--dependency=afterany:{}", ids.join(":")));
    }
    let mut command = vec![
        quote(&binary.display().to_string()),
        "run".into(),
        quote(&launch.spec.display().to_string()),
        "--results".into(),
        quote(&results.display().to_string()),
        "--launcher".into(),
        "local".into(),
        "--assemble".into(),
        quote(&run_dir.display().to_string()),
    ];
    for s in &opts.sets {
        command.push("--set".into());
        command.push(quote(s));
    }
    if opts.publish {
        command.push("--publish".into());
    }
    args.push(format!("--wrap=exec {}", command.join(" ")));
    let final_job = sbatch(&args)?;
    launch.jobs.last = Some(final_job.clone());
    write_launch(&run_dir, &launch)?;
    // The run folder belongs to the final job now: no local run takes it for a dead one.
    let owner = run_dir.join(OWNER);
    std::fs::write(&owner, format!("slurm {final_job}\n"))
        .with_context(|| format!("{}: cannot write", owner.display()))?;
    Ok(Launched {
        run_dir: run_dir.clone(),
        cells_job,
        seeds_job,
        final_job,
        tasks: launch.tasks.len(),
        skipped,
    })
}

/// Jobs still in Slurm's queue, by id (`squeue -h -r`: one line per array task, `123_4`),
/// with their state; `None` where `squeue` cannot be run.
fn queue() -> Option<Vec<(String, String)>> {
    let out = Command::new("squeue")
        .args(["-h", "-r", "-o", "%i %T"])
        .output()
        .ok()?;
    out.status.success().then(|| {
        String::from_utf8_lossy(&out.stdout)
            .lines()
            .filter_map(|l| {
                let (id, state) = l.trim().split_once(' ')?;
                Some((id.to_string(), state.to_string()))
            })
            .collect()
    })
}

/// The job id of a task (`array_index`).
fn task_job(launch: &Launch, t: &Task) -> Option<String> {
    let array = match t.array.as_str() {
        "cells" => launch.jobs.cells.as_ref(),
        _ => launch.jobs.seeds.as_ref(),
    }?;
    Some(format!("{array}_{}", t.index))
}

fn done_path(run_dir: &Path, t: &Task) -> PathBuf {
    logs(run_dir).join(format!("{}.done.json", t.name()))
}

fn log_path(run_dir: &Path, t: &Task) -> PathBuf {
    logs(run_dir).join(format!("{}.log", t.name()))
}

/// Blocks until a submission's final job ended; fails naming each task that did not finish
/// (with its job and log) and the final job's log.
pub fn wait(launched: &Launched) -> Result<()> {
    let launch = read_launch(&logs(&launched.run_dir).join("launch.json"))?;
    let started = Instant::now();
    eprintln!(
        "waiting for Slurm: {} task(s), final job {}",
        launched.tasks, launched.final_job
    );
    loop {
        let Some(q) = queue() else {
            bail!("squeue failed while waiting for job {}", launched.final_job);
        };
        if !q.iter().any(|(id, _)| *id == launched.final_job) {
            break;
        }
        std::thread::sleep(Duration::from_secs(2));
    }
    // The final job renames the run folder when it finished.
    if finished_path(&launched.run_dir)?
        .join("manifest.json")
        .exists()
    {
        eprintln!(
            "Slurm jobs finished in {}",
            crate::run::stage::duration(started.elapsed().as_secs_f64())
        );
        return Ok(());
    }
    let mut failed: Vec<String> = launch
        .tasks
        .iter()
        .filter(|t| !done_path(&launched.run_dir, t).exists())
        .map(|t| {
            format!(
                "{} failed (job {}), log {}",
                t.describe(),
                task_job(&launch, t).unwrap_or_default(),
                log_path(&launched.run_dir, t).display()
            )
        })
        .collect();
    failed.push(format!(
        "the final job {} did not finish the run, log {}",
        launched.final_job,
        logs(&launched.run_dir).join("final.log").display()
    ));
    bail!("the Slurm run failed:\n  {}", failed.join("\n  "))
}

/// A task, as Slurm runs it: the cell's units for one seed into the cache, nothing else.
pub fn task(
    layout: &Layout,
    launch_file: &Path,
    array: &str,
    index: Option<usize>,
    registry: Registry,
    verbosity: crate::run::stage::Verbosity,
) -> Result<()> {
    let started = Instant::now();
    let launch = read_launch(launch_file)?;
    let index = match index {
        Some(i) => i,
        None => std::env::var("SLURM_ARRAY_TASK_ID")
            .ok()
            .and_then(|v| v.parse().ok())
            .context("no task index: give --index or run as a Slurm array task")?,
    };
    let t = launch
        .tasks
        .iter()
        .find(|t| t.array == array && t.index == index)
        .with_context(|| format!("{}: no task {array}-{index}", launch_file.display()))?;
    let cells = spec::load(layout, &launch.spec, &launch.sets)?;
    let c: &Cell = cells
        .get(t.cell)
        .with_context(|| format!("{}: no cell {}", launch.spec.display(), t.cell))?;
    let spec = task_spec(&c.spec, t.seed);
    let experiments = task_experiments(&c.spec, t.seed, registry);
    let a = assets(layout)?;
    let cache = Cache::new(&launch.results.join(".cache"));
    let mut records = Vec::new();
    let mut sink = Discard;
    let mut cx = CellRun::new(
        &spec,
        &c.name,
        String::new(),
        false,
        &a,
        &cache,
        &mut records,
        &mut sink,
        (registry.1)(),
        verbosity,
    );
    for e in experiments.iter().filter(|e| e.wanted(&spec)) {
        e.run(&mut cx)?;
    }
    let run_dir = launch_file
        .parent()
        .and_then(Path::parent)
        .context("launch.json outside a run folder")?;
    let job = match (
        std::env::var("SLURM_ARRAY_JOB_ID"),
        std::env::var("SLURM_ARRAY_TASK_ID"),
    ) {
        (Ok(j), Ok(i)) => format!("{j}_{i}"),
        _ => std::env::var("SLURM_JOB_ID").unwrap_or_else(|_| "-".into()),
    };
    let done = Done {
        job,
        host: cache::host(),
        seconds: started.elapsed().as_secs_f64(),
    };
    let computed = records.iter().filter(|r| !r.hit).count();
    write_atomic(
        &done_path(run_dir, t),
        serde_json::to_string_pretty(&done)?.as_bytes(),
    )?;
    eprintln!(
        "{}: {} units, {computed} computed, in {}",
        t.describe(),
        records.len(),
        crate::run::stage::duration(done.seconds)
    );
    Ok(())
}

/// A task writes nothing but cache entries.
struct Discard;

impl Sink for Discard {
    fn output(&mut self, _rel: &str, _bytes: Vec<u8>) -> Result<()> {
        Ok(())
    }
    fn measurement(&mut self, _rel: &str, _bytes: &[u8]) -> Result<()> {
        Ok(())
    }
    fn table(&self, _name: &str, _text: &str) -> Result<()> {
        Ok(())
    }
    fn figures(&self) -> &Path {
        Path::new("")
    }
}

/// The final job's check before it assembles: every task's units are in the cache, or the
/// missing ones are named with the task that should have made them and its log.
pub(super) fn check_assembled(
    run_dir: &Path,
    cells: &[Cell],
    a: &Assets,
    cache: &Cache,
    registry: Registry,
) -> Result<()> {
    let launch = read_launch(&logs(run_dir).join("launch.json"))?;
    let mut missing = Vec::new();
    let mut named = std::collections::BTreeSet::new();
    for c in cells {
        for &seed in &c.spec.seeds {
            // A unit several of a cell's tasks plan (its dataset) is named once, with the
            // first task that plans it.
            for (id, cached) in task_units(c, seed, a, cache, registry)? {
                if cached || !named.insert((c.name.clone(), id.clone())) {
                    continue;
                }
                let by = launch
                    .tasks
                    .iter()
                    .find(|t| t.cell_name == c.name && t.seed == seed)
                    .map_or(String::new(), |t| {
                        format!(
                            ", made by {} (log {})",
                            t.describe(),
                            log_path(run_dir, t).display()
                        )
                    });
                let cell = if c.name.is_empty() {
                    String::new()
                } else {
                    format!("[{}] ", c.name)
                };
                missing.push(format!("{cell}{}{by}", short(&id)));
            }
        }
    }
    if !missing.is_empty() {
        bail!(
            "{} unit(s) missing from the cache after the Slurm tasks:\n  {}",
            missing.len(),
            missing.join("\n  ")
        );
    }
    Ok(())
}

/// The manifest's record of how the run ran: the launcher, its jobs and each task's host and
/// seconds.
pub(super) fn record(run_dir: &Path) -> serde_json::Value {
    let Ok(launch) = read_launch(&logs(run_dir).join("launch.json")) else {
        return serde_json::json!({ "kind": "local" });
    };
    let tasks: Vec<serde_json::Value> = launch
        .tasks
        .iter()
        .map(|t| {
            let done: Option<Done> = std::fs::read_to_string(done_path(run_dir, t))
                .ok()
                .and_then(|s| serde_json::from_str(&s).ok());
            serde_json::json!({
                "task": t.name(),
                "cell": t.cell_name,
                "seed": t.seed,
                "job": done.as_ref().map(|d| d.job.clone()),
                "host": done.as_ref().map(|d| d.host.clone()),
                "seconds": done.as_ref().map(|d| d.seconds),
            })
        })
        .collect();
    serde_json::json!({
        "kind": "slurm",
        "jobs": {
            "cells": launch.jobs.cells,
            "seeds": launch.jobs.seeds,
            "final": std::env::var("SLURM_JOB_ID").ok().or(launch.jobs.last),
        },
        "tasks": tasks,
    })
}

/// For `facelab status`: the state of each unit a submitted, unfinished Slurm run of
/// `experiment` plans to make and the cache does not hold yet: queued, running, or failed
/// (its task ended without finishing), by unit id.
pub(super) fn unit_states(results: &Path, experiment: &str) -> Vec<(String, UnitState)> {
    let dir = results.join(experiment);
    let Ok(entries) = std::fs::read_dir(&dir) else {
        return Vec::new();
    };
    let q = queue().unwrap_or_default();
    let mut out = Vec::new();
    for run_dir in entries.filter_map(|e| e.ok().map(|e| e.path())) {
        if !run_dir.to_string_lossy().ends_with(PARTIAL) {
            continue;
        }
        let Ok(launch) = read_launch(&logs(&run_dir).join("launch.json")) else {
            continue;
        };
        for t in &launch.tasks {
            let job = task_job(&launch, t).unwrap_or_default();
            let state = match q.iter().find(|(id, _)| *id == job).map(|(_, s)| s.as_str()) {
                Some("PENDING") => UnitState::Queued(format!("{}, job {job}", t.describe())),
                Some(_) => UnitState::Running(format!("{}, job {job}", t.describe())),
                None if done_path(&run_dir, t).exists() => continue,
                None => UnitState::Failed(format!(
                    "{} ended without finishing, log {}",
                    t.describe(),
                    log_path(&run_dir, t).display()
                )),
            };
            for u in &t.units {
                out.push((u.clone(), state.clone()));
            }
        }
    }
    out
}
