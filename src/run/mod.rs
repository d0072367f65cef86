//! The run machinery: `facelab run | status | verify | task`, a spec's stages cached by
//! content (DESIGN 2.5), locally or as Slurm job arrays.
//!
//! A run resolves the spec into cells and runs, in each cell, every experiment of the registry
//! it is handed (`RunOptions::registry`, `experiments::REGISTRY`) that the cell's spec asks
//! for, through the cell's context (`cell`); then a sweep's summary. It names no experiment.
//! The stage framework is `stage`; the networks' stages (the basis, the dataset, the training
//! and each network's test) and what their keys hash are in `cell::networks` and
//! `cell::keys`; each experiment's stages are in its own folder under `experiments`.
//! Evaluation and reports are cheap and always run.
//!
//! Each run writes `results/<experiment>/run-NNNN/` (one subfolder per sweep cell) with the
//! resolved `spec.toml`, `manifest.json` and CSVs; `results/<experiment>/latest` points at it.
//! Until the manifest is written the folder is `run-NNNN.partial`.

use crate::io::Layout;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};

use crate::cache::{self, Cache};
use crate::io::atomic::write_atomic;
use crate::run::cell::{assets, CellRun, Plan, Registry, Sink, Sweep};
use crate::run::stage::{Unit, Verbosity};
use crate::spec;

pub mod cell;
mod committed;
mod folders;
mod slurm;
pub mod stage;

pub use committed::{committed, Committed};
use folders::*;
pub use slurm::{launch, task, wait, Launched};

#[derive(Clone, Debug)]
pub struct RunOptions {
    /// Results folder; the cache lives in `<results>/.cache`, tables and figures in
    /// `<results>/../paper-tables` and `<results>/../figures` (see `publish`).
    pub results: PathBuf,
    pub sets: Vec<String>,
    pub threads: usize,
    /// With `sets`: also write the tables and figures beside the results folder. Without it an
    /// overridden run keeps them in its own run folder and the committed record is untouched.
    pub publish: bool,
    /// The final job of a Slurm run: finish this (`.partial`) run folder, which the launcher
    /// made, once every task's units are in the cache (else name the missing ones).
    pub assemble: Option<PathBuf>,
    /// The experiments a cell may run (`facelab::experiments::REGISTRY`).
    pub registry: Registry,
    /// What the run prints (the command line's `--quiet` / `--verbose`).
    pub verbosity: Verbosity,
    /// Where the checkout's files are (the spec's data files, the face).
    pub layout: Layout,
}

/// Where a spec's run runs: `--launcher` if given, else the spec's `[launcher] kind`.
pub fn launcher_of(
    layout: &Layout,
    spec_path: &Path,
    sets: &[String],
    given: Option<spec::LauncherKind>,
) -> Result<spec::LauncherKind> {
    match given {
        Some(kind) => Ok(kind),
        None => Ok(spec::load(layout, spec_path, sets)?[0].spec.launcher.kind),
    }
}

pub use stage::StageRecord;

#[derive(Clone, Debug)]
pub struct RunSummary {
    pub dir: PathBuf,
    pub stages: Vec<StageRecord>,
    /// Output file (relative to the run folder) -> SHA-256.
    pub outputs: BTreeMap<String, String>,
}

/// A run's folder and its tables and figures, as the experiments write into them.
struct RunSink<'a> {
    dir: &'a Path,
    publish: &'a Publish,
    /// Output file (relative to the run folder) -> SHA-256.
    outputs: BTreeMap<String, String>,
}

impl Sink for RunSink<'_> {
    fn output(&mut self, rel: &str, bytes: Vec<u8>) -> Result<()> {
        write_atomic(&self.dir.join(rel), &bytes)?;
        self.outputs.insert(rel.to_string(), cache::sha256(&bytes));
        Ok(())
    }

    fn measurement(&mut self, rel: &str, bytes: &[u8]) -> Result<()> {
        Ok(write_atomic(&self.dir.join(rel), bytes)?)
    }

    fn table(&self, name: &str, text: &str) -> Result<()> {
        self.publish.table(name, text)
    }

    fn figures(&self) -> &Path {
        &self.publish.figures
    }
}

/// Runs every cell of a spec file.
pub fn run(spec_path: &Path, opts: &RunOptions) -> Result<RunSummary> {
    let cells = spec::load(&opts.layout, spec_path, &opts.sets)?;
    // The real files are outside the repository: say what is missing before computing.
    for cell in &cells {
        if cell.spec.tables.contains(&crate::spec::Table::Realfaces) {
            crate::io::realdata::inputs(&cell.spec.realfaces)
                .with_context(|| format!("{}", spec_path.display()))?;
        }
    }
    let a = assets(&opts.layout)?;
    let cache = Cache::new(&opts.results.join(".cache"));
    cache.remove_stale();
    let experiment = cells[0].spec.experiment.clone();
    let experiment_dir = opts.results.join(&experiment);
    let out_root = opts
        .results
        .parent()
        .map(Path::to_path_buf)
        .unwrap_or_else(|| PathBuf::from("."));
    let git_revision = git(&["rev-parse", "HEAD"]).unwrap_or_else(|| "unknown".into());
    let git_dirty = checkout_dirty(&[
        opts.results.clone(),
        out_root.join("figures"),
        out_root.join("paper-tables"),
    ]);
    let latest_at_start = std::fs::read_link(experiment_dir.join("latest")).ok();
    let run_dir = match &opts.assemble {
        Some(dir) => {
            slurm::check_assembled(dir, &cells, &a, &cache, opts.registry)?;
            dir.clone()
        }
        None => new_run_dir(&experiment_dir)?,
    };
    let publishes = opts.sets.is_empty() || opts.publish;
    let publish = publish_plan(&run_dir, &out_root, publishes, &opts.sets);
    let mut records = Vec::new();
    let mut sink = RunSink {
        dir: &run_dir,
        publish: &publish,
        outputs: BTreeMap::new(),
    };
    let single = cells.len() == 1;
    let mut products: Vec<(String, Box<dyn std::any::Any>)> = Vec::new();
    for c in &cells {
        let prefix = if single {
            String::new()
        } else {
            format!("{}/", sanitize(&c.name))
        };
        sink.output(&format!("{prefix}spec.toml"), c.spec.to_toml().into_bytes())?;
        let mut cx = CellRun::new(
            &c.spec,
            &c.name,
            prefix,
            single,
            &a,
            &cache,
            &mut records,
            &mut sink,
            (opts.registry.1)(),
            opts.verbosity,
        );
        for e in opts.registry.0.iter().filter(|e| e.wanted(&c.spec)) {
            e.run(&mut cx)?;
        }
        // Every experiment then finishes the cell, whether its spec lists it or not (Table 1
        // records the networks of every cell that trained).
        for e in opts.registry.0 {
            e.finish_cell(&mut cx)?;
        }
        products.push((c.name.clone(), cx.products));
    }
    if !single {
        let mut sweep = Sweep::new(&experiment, &products, &mut sink);
        for e in opts.registry.0 {
            e.sweep(&mut sweep)?;
        }
        sweep.finish()?;
    }
    let outputs = sink.outputs;
    let manifest = serde_json::json!({
        "facelab_version": env!("CARGO_PKG_VERSION"),
        // The code: the commit the binary was built from (`build.rs`), wherever it runs.
        "build": {
            "revision": env!("FACELAB_BUILD_REVISION"),
            "dirty": env!("FACELAB_BUILD_DIRTY"),
        },
        // The specs and data: the checkout the run was started in ("unknown" outside one).
        "git_revision": git_revision,
        "git_dirty": git_dirty,
        "spec": spec_path.display().to_string(),
        "sets": opts.sets,
        "experiment": experiment,
        "seeds": cells[0].spec.seeds,
        "threads": opts.threads,
        "launcher": slurm::record(&run_dir),
        "stages": records.iter().map(|r| serde_json::json!({
            "cell": r.cell, "stage": r.stage, "key": r.key, "hit": r.hit, "seconds": r.seconds,
        })).collect::<Vec<_>>(),
        "outputs": outputs,
    });
    write_atomic(
        &run_dir.join("manifest.json"),
        serde_json::to_string_pretty(&manifest)?.as_bytes(),
    )?;
    // One run at a time publishes into a results folder: its tables, figures and `latest`
    // change together, and a run that finishes while another publishes waits, saying so.
    let _lock = PublishLock::acquire(&opts.results)?;
    publish.copy_out()?;
    let run_dir = finish_run_dir(&run_dir)?;
    // Another run of this experiment finished while this one ran: say that this one replaces
    // it as `latest` (and its tables), rather than overwrite it silently.
    let latest_now = std::fs::read_link(experiment_dir.join("latest")).ok();
    if latest_now.is_some() && latest_now != latest_at_start {
        eprintln!(
            "{}: {} finished while this run ran; {} replaces it as latest{}",
            experiment_dir.display(),
            latest_now.unwrap_or_default().display(),
            run_dir.file_name().unwrap_or_default().to_string_lossy(),
            if publishes {
                " and in the published tables and figures"
            } else {
                ""
            }
        );
    }
    point_latest(&experiment_dir, &run_dir)?;
    Ok(RunSummary {
        dir: run_dir,
        stages: records,
        outputs,
    })
}

/// Where a run's tables and figures go. An overridden run is not the committed record: its
/// tables and figures stay in its run folder (and say what was overridden) unless `--publish`
/// asks otherwise. A published run's are staged in its folder and copied out at the end,
/// under the results folder's publish lock, together with `latest`.
fn publish_plan(run_dir: &Path, out_root: &Path, publishes: bool, sets: &[String]) -> Publish {
    if publishes {
        let staging = run_dir.join(STAGING);
        Publish {
            tables: staging.join("paper-tables"),
            figures: staging.join("figures"),
            overrides: sets.to_vec(),
            staged: Some(Staged {
                staging,
                tables: out_root.join("paper-tables"),
                figures: out_root.join("figures"),
            }),
        }
    } else {
        Publish {
            tables: run_dir.join("paper-tables"),
            figures: run_dir.join("figures"),
            overrides: sets.to_vec(),
            staged: None,
        }
    }
}

/// A unit's state in the cache, as `facelab status` reports it.
#[derive(Clone, Debug, PartialEq)]
pub enum UnitState {
    Cached,
    Missing,
    Damaged(String),
    /// The key is not known until an earlier stage is cached (the reason).
    Waiting(String),
    /// Not cached; a submitted Slurm task will make it (which task and job).
    Queued(String),
    Running(String),
    /// Not cached, and the Slurm task that was to make it ended without finishing.
    Failed(String),
}

/// One line of `facelab status`.
#[derive(Clone, Debug)]
pub struct StatusLine {
    pub cell: String,
    pub label: String,
    pub unit: Option<Unit>,
    pub state: UnitState,
}

/// `facelab status`: every unit of work of every cell and whether the cache holds it. Reads
/// only: nothing is computed, removed or written.
pub fn status(
    layout: &Layout,
    spec_path: &Path,
    sets: &[String],
    results: &Path,
    registry: Registry,
) -> Result<Vec<StatusLine>> {
    let cells = spec::load(layout, spec_path, sets)?;
    let a = assets(layout)?;
    let cache = Cache::new(&results.join(".cache"));
    let slurm = slurm::unit_states(results, &cells[0].spec.experiment);
    let mut out = Vec::new();
    for cell in &cells {
        let plan = Plan::of(
            &cell.spec,
            &cell.name,
            &a,
            &cache,
            registry.0,
            cells.len() == 1,
        )?;
        for p in plan {
            let state = match &p.unit {
                Ok(u) => match cache.inspect(u.stage, &u.key) {
                    crate::cache::Lookup::Hit(_) => UnitState::Cached,
                    crate::cache::Lookup::Missing => {
                        let id = format!("{}/{}", u.stage, u.key);
                        slurm
                            .iter()
                            .find(|(unit, _)| *unit == id)
                            .map_or(UnitState::Missing, |(_, s)| s.clone())
                    }
                    crate::cache::Lookup::Damaged { reason, .. } => UnitState::Damaged(reason),
                },
                Err(why) => UnitState::Waiting(why.clone()),
            };
            out.push(StatusLine {
                cell: p.cell,
                label: p.label,
                unit: p.unit.ok(),
                state,
            });
        }
    }
    Ok(out)
}

/// A finished run as its folder records it: its manifest, and the folder prefix of each cell's
/// recorded, resolved `spec.toml` (empty for the run's own, `name/` per sweep cell), sorted.
pub(super) fn recorded(run_dir: &Path) -> Result<(serde_json::Value, Vec<String>)> {
    let path = run_dir.join("manifest.json");
    let manifest: serde_json::Value = serde_json::from_slice(
        &std::fs::read(&path).with_context(|| format!("{}: cannot read", path.display()))?,
    )
    .with_context(|| format!("{}: not a run manifest", path.display()))?;
    let mut cells: Vec<String> = manifest["outputs"]
        .as_object()
        .with_context(|| format!("{}: no outputs", path.display()))?
        .keys()
        .filter_map(|name| name.strip_suffix("spec.toml"))
        .map(str::to_string)
        .collect();
    cells.sort();
    if cells.is_empty() {
        bail!("{}: the run recorded no spec.toml", run_dir.display());
    }
    Ok((manifest, cells))
}

pub fn verify(
    layout: &Layout,
    run_dir: &Path,
    threads: usize,
    registry: Registry,
    verbosity: Verbosity,
) -> Result<Vec<String>> {
    // Rerunning each cell's recorded spec (not the spec path as typed then, which may have
    // changed since) is what makes this a check of the run.
    let (manifest, cells) = recorded(run_dir)?;
    let outputs = manifest["outputs"]
        .as_object()
        .expect("recorded() checked the outputs");
    let tmp = std::env::temp_dir().join(format!("facelab-verify-{}", std::process::id()));
    let mut differ = Vec::new();
    for prefix in &cells {
        let _ = std::fs::remove_dir_all(&tmp);
        let summary = run(
            &run_dir.join(prefix).join("spec.toml"),
            &RunOptions {
                results: tmp.join("results"),
                sets: Vec::new(),
                threads,
                publish: false,
                assemble: None,
                registry,
                verbosity,
                layout: layout.clone(),
            },
        );
        let summary = match summary {
            Ok(s) => s,
            Err(e) => {
                let _ = std::fs::remove_dir_all(&tmp);
                return Err(e);
            }
        };
        for (name, hash) in outputs {
            let Some(own) = name.strip_prefix(prefix.as_str()) else {
                continue;
            };
            // Timings are measurements of this machine, not results (runs before `timings/`
            // listed `inversion_timing.csv`); a sweep's summary (`<experiment>.csv` beside the
            // cells) is made from the cells' CSVs.
            if !own.ends_with(".csv") || own.ends_with("_timing.csv") || own.contains('/') {
                continue;
            }
            if summary.outputs.get(own).map(String::as_str) != hash.as_str() {
                differ.push(name.clone());
            }
        }
    }
    let _ = std::fs::remove_dir_all(&tmp);
    Ok(differ)
}
