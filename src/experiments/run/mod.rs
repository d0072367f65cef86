//! `facelab run | status | verify`: a spec's stages, cached by content (DESIGN 2.5).
//!
//! Stages and what their keys hash (besides the stage name and version):
//! - `basis` (only with `dataset.start = "predicted"`): the face assets, `dataset.subdivisions`,
//!   `dataset.tolerance`, `dataset.shear_modulus_fraction`;
//! - `dataset`: the basis key, the face, expression and calibration files, `dataset.*`
//!   except `dataset.test_fraction` (the split happens at training),
//!   `observer.*`;
//! - `train` (per seed and network): the dataset key, `model.*`, `train.*`,
//!   `dataset.test_fraction`, the FACS maps, the seed and the network;
//! - evaluation and reports are cheap and always run.
//!
//! Each run writes `results/<experiment>/run-NNNN/` (one subfolder per sweep cell) with the
//! resolved `spec.toml`, `manifest.json` and CSVs; `results/<experiment>/latest` points at it.
//! Until the manifest is written the folder is `run-NNNN.partial`.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};

use crate::cache::{self, Cache};
use crate::experiments::face::FaceSource;
use crate::experiments::headpose;
use crate::experiments::pose_transfer;
use crate::experiments::realfaces;
use crate::experiments::stage::{Stages, Unit};
use crate::experiments::table1::Row;
use crate::experiments::table2;
use crate::experiments::table2_stage::{self};
use crate::io::atomic::write_atomic;
use crate::spec::{self, Cell};

mod cell;
mod folders;
mod keys;
mod table1_report;

pub(crate) use cell::curves_csv;
pub(crate) use keys::{spec_calibration, FaceSettings};
use {cell::*, folders::*, keys::*, table1_report::*};

/// Code versions: bump when a stage's output for the same inputs changes.
// 2: the expressive face (human range of motion, eyes opened to an adult aperture, lip
// contact) read by its recalibrated observer.
const BASIS_VERSION: u32 = 2;
const DATASET_VERSION: u32 = 2;
const TRAIN_VERSION: u32 = 1;

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
}

pub use super::stage::StageRecord;
pub(crate) use cell::Trained;

#[derive(Clone, Debug)]
pub struct RunSummary {
    pub dir: PathBuf,
    pub stages: Vec<StageRecord>,
    /// Output file (relative to the run folder) -> SHA-256.
    pub outputs: BTreeMap<String, String>,
}

/// The head-neck experiment of one cell: CSVs into the run folder (through `write`), the
/// paper table and figures when the spec is a single cell.
fn headpose_outputs(
    cell: &Cell,
    prefix: &str,
    single: bool,
    out: &Publish,
    cache: &Cache,
    records: &mut Vec<StageRecord>,
    write: &mut dyn FnMut(String, Vec<u8>) -> Result<()>,
) -> Result<Vec<u8>> {
    let spec = &cell.spec;
    let publish = out;
    let out = headpose::stage(spec, &mut Stages::new(cache, &cell.name, records))?;
    write(
        format!("{prefix}headpose_static.csv"),
        headpose::static_csv(&out.static_rows).into_bytes(),
    )?;
    write(
        format!("{prefix}headpose_sequences.csv"),
        headpose::sequences_csv(&out.sequence_rows).into_bytes(),
    )?;
    write(
        format!("{prefix}headpose_trajectories.csv"),
        out.trajectories_csv.clone().into_bytes(),
    )?;
    write(
        format!("{prefix}headpose_curves.csv"),
        curves_csv(&out.curves).into_bytes(),
    )?;
    write(
        format!("{prefix}voluntary.safetensors"),
        out.weights.clone(),
    )?;
    if single {
        let report = &spec.report_prefix;
        publish.table(
            &format!("{report}headpose.md"),
            &headpose::markdown(&out, spec),
        )?;
        let source = FaceSource::of_spec(spec);
        let figures = publish.figures.join(format!("{report}headpose"));
        headpose::figures(&figures, &out, spec, &source.model()?)?;
    }
    Ok(out.weights)
}

/// Runs every cell of a spec file.
pub fn run(spec_path: &Path, opts: &RunOptions) -> Result<RunSummary> {
    let cells = spec::load(spec_path, &opts.sets)?;
    // The real files are outside the repository: say what is missing before computing.
    for cell in &cells {
        if cell.spec.tables.iter().any(|t| t == "realfaces") {
            crate::io::realdata::inputs(&cell.spec.realfaces)
                .with_context(|| format!("{}", spec_path.display()))?;
        }
    }
    let a = assets()?;
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
    let run_dir = new_run_dir(&experiment_dir)?;
    // An overridden run is not the committed record: its tables and figures stay in its run
    // folder (and say what was overridden) unless `--publish` asks otherwise.
    // A published run's tables and figures are staged in its folder and copied out at the end,
    // under the results folder's publish lock, together with `latest`.
    let publishes = opts.sets.is_empty() || opts.publish;
    let publish = if publishes {
        let staging = run_dir.join(STAGING);
        Publish {
            tables: staging.join("paper-tables"),
            figures: staging.join("figures"),
            overrides: opts.sets.clone(),
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
            overrides: opts.sets.clone(),
            staged: None,
        }
    };
    let mut records = Vec::new();
    let mut outputs: BTreeMap<String, String> = BTreeMap::new();
    let write =
        |rel: String, bytes: Vec<u8>, outputs: &mut BTreeMap<String, String>| -> Result<()> {
            let path = run_dir.join(&rel);
            write_atomic(&path, &bytes)?;
            outputs.insert(rel, cache::sha256(&bytes));
            Ok(())
        };
    let mut sweep_rows: Vec<(String, Vec<Row>)> = Vec::new();
    let mut sweep_table2: Vec<(String, Vec<table2::Row>)> = Vec::new();
    let mut sweep_realfaces: Vec<(String, Vec<realfaces::FileRow>)> = Vec::new();
    for cell in &cells {
        let prefix = if cells.len() > 1 {
            format!("{}/", sanitize(&cell.name))
        } else {
            String::new()
        };
        write(
            format!("{prefix}spec.toml"),
            cell.spec.to_toml().into_bytes(),
            &mut outputs,
        )?;
        let mut voluntary = None;
        if cell.spec.tables.iter().any(|t| t == "headpose") {
            voluntary = Some(headpose_outputs(
                cell,
                &prefix,
                cells.len() == 1,
                &publish,
                &cache,
                &mut records,
                &mut |rel, bytes| write(rel, bytes, &mut outputs),
            )?);
        }
        if cell.spec.tables.iter().all(|t| t == "headpose") {
            continue;
        }
        let result = run_cell(cell, &a, &cache, &mut records)?;
        write(
            format!("{prefix}table1.csv"),
            table1_csv(&result.rows).into_bytes(),
            &mut outputs,
        )?;
        write(
            format!("{prefix}curves.csv"),
            all_curves_csv(&result.curves).into_bytes(),
            &mut outputs,
        )?;
        if cells.len() == 1 {
            // A spec that trains only for its own table (e.g. the real-data table) keeps its
            // Table 1 in the run folder.
            if cell.spec.tables.iter().any(|t| t == "table1") {
                let report = &cell.spec.report_prefix;
                let md = table1_markdown(&result.rows, &cell.spec, result.samples);
                publish.table(&format!("{report}table1.md"), &md)?;
                publish.table(&format!("{report}table1.tex"), &table1_tex(&result.rows))?;
                let figures = publish.figures.join(format!("{report}table1"));
                table1_figures(&figures, &result)?;
            }
            write(
                "unified.safetensors".into(),
                result.unified.clone(),
                &mut outputs,
            )?;
            write(
                "training_aus.csv".into(),
                result.training_aus.clone().into_bytes(),
                &mut outputs,
            )?;
        }
        if let Some(iv) = &result.inversion {
            write(
                format!("{prefix}inversion.csv"),
                iv.csv.clone().into_bytes(),
                &mut outputs,
            )?;
            // Timings are measurements, not results: outside the compared outputs.
            for (name, text) in [
                ("inversion.csv", &iv.timing),
                ("inversion.md", &iv.timing_markdown),
            ] {
                let path = run_dir.join(&prefix).join("timings").join(name);
                write_atomic(&path, text.as_bytes())?;
            }
            if cells.len() == 1 {
                publish.table(
                    &format!("{}methods.md", cell.spec.report_prefix),
                    &iv.markdown,
                )?;
            }
        }
        if let Some(t2) = &result.table2 {
            write(
                format!("{prefix}table2.csv"),
                table2_stage::csv(&t2.rows).into_bytes(),
                &mut outputs,
            )?;
            write(
                format!("{prefix}reference.csv"),
                table2::reference_csv(&t2.reference).into_bytes(),
                &mut outputs,
            )?;
            write(
                format!("{prefix}table2_frames.csv"),
                table2_stage::frames_csv(&t2.reference, &t2.first).into_bytes(),
                &mut outputs,
            )?;
            let real = result.table2_real.as_deref().unwrap_or(&[]);
            if let Some(rows) = &result.table2_real {
                write(
                    format!("{prefix}table2_real.csv"),
                    realfaces::csv(rows).into_bytes(),
                    &mut outputs,
                )?;
            }
            if cells.len() == 1 {
                let report = &cell.spec.report_prefix;
                publish.table(
                    &format!("{report}table2.md"),
                    &table2_stage::markdown(&t2.rows, &cell.spec, &t2.reference, real),
                )?;
                publish.table(
                    &format!("{report}table2.tex"),
                    &table2_stage::tex(&t2.rows, real, cell.spec.seeds.len()),
                )?;
                let figures = publish.figures.join(format!("{report}table2"));
                for (name, bytes) in &t2.renders {
                    write_atomic(&figures.join(name), bytes)?;
                }
                table2_stage::bars(&figures.join("au_mse_bars.png"), &t2.rows)?;
            }
            // Head pose from the cohorts, where the spec has the head-neck controller.
            if let Some(weights) = &voluntary {
                let rows = pose_transfer::stage(
                    &cell.spec,
                    &mut Stages::new(&cache, &cell.name, &mut records),
                    &t2.cohort_key,
                    weights,
                    &t2.reference,
                )?;
                write(
                    format!("{prefix}table2_pose.csv"),
                    pose_transfer::csv(&rows).into_bytes(),
                    &mut outputs,
                )?;
                if cells.len() == 1 {
                    let md = pose_transfer::markdown(&rows);
                    publish.table(&format!("{}table2_pose.md", cell.spec.report_prefix), &md)?;
                }
            }
        }
        if let Some(rf) = &result.realfaces {
            write(
                format!("{prefix}realfaces.csv"),
                realfaces::csv(rf).into_bytes(),
                &mut outputs,
            )?;
            if cells.len() == 1 {
                publish.table(
                    &format!("{}realfaces.md", cell.spec.report_prefix),
                    &realfaces::markdown(rf, &cell.spec),
                )?;
            }
        }
        if let Some(rf) = result.realfaces {
            sweep_realfaces.push((cell.name.clone(), rf));
        }
        if let Some(t2) = result.table2 {
            sweep_table2.push((cell.name.clone(), t2.rows));
        }
        sweep_rows.push((cell.name.clone(), result.rows));
    }
    if cells.len() > 1 {
        let mut md = sweep_markdown(&experiment, &sweep_rows);
        if !sweep_table2.is_empty() {
            md.push_str(&table2_stage::sweep_markdown(&sweep_table2));
        }
        if !sweep_realfaces.is_empty() {
            md.push_str(&realfaces::sweep_markdown(&sweep_realfaces));
        }
        write(
            format!("{experiment}.csv"),
            sweep_csv(&sweep_rows).into_bytes(),
            &mut outputs,
        )?;
        publish.table(&format!("{experiment}.md"), &md)?;
        let dir = publish.figures.join(&experiment);
        sweep_figure(&dir, &sweep_rows)?;
        if !sweep_table2.is_empty() {
            let names: Vec<&str> = sweep_table2.iter().map(|(n, _)| n.as_str()).collect();
            table2_stage::sweep_figure(&dir, &sweep_table2, &sweep_labels(&names).1)?;
        }
    }
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

/// A unit's state in the cache, as `facelab status` reports it.
#[derive(Clone, Debug, PartialEq)]
pub enum UnitState {
    Cached,
    Missing,
    Damaged(String),
    /// The key is not known until an earlier stage is cached (the reason).
    Waiting(String),
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
pub fn status(spec_path: &Path, sets: &[String], results: &Path) -> Result<Vec<StatusLine>> {
    let cells = spec::load(spec_path, sets)?;
    let a = assets()?;
    let cache = Cache::new(&results.join(".cache"));
    let mut out = Vec::new();
    for cell in &cells {
        for p in plan(cell, &a, &cache)? {
            let state = match &p.unit {
                Ok(u) => match cache.inspect(u.stage, &u.key) {
                    crate::cache::Lookup::Hit(_) => UnitState::Cached,
                    crate::cache::Lookup::Missing => UnitState::Missing,
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

pub fn verify(run_dir: &Path, threads: usize) -> Result<Vec<String>> {
    let manifest_path = run_dir.join("manifest.json");
    let manifest: serde_json::Value = serde_json::from_slice(
        &std::fs::read(&manifest_path)
            .with_context(|| format!("{}: cannot read", manifest_path.display()))?,
    )
    .with_context(|| format!("{}: not a run manifest", manifest_path.display()))?;
    let outputs = manifest["outputs"]
        .as_object()
        .with_context(|| format!("{}: no outputs", manifest_path.display()))?;
    // The recorded, resolved spec of each cell: the run's own `spec.toml`, or one per sweep
    // cell folder. Rerunning what was recorded (not the spec path as typed then, which may
    // have changed since) is what makes this a check of the run.
    let mut cells: Vec<String> = outputs
        .keys()
        .filter_map(|name| name.strip_suffix("spec.toml"))
        .map(str::to_string)
        .collect();
    cells.sort();
    if cells.is_empty() {
        bail!("{}: the run recorded no spec.toml", run_dir.display());
    }
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
