//! Table 2's stages in a run (cohort -> transfer per seed -> renders) and its reports.
//!
//! Stage keys hash, besides the stage name and version:
//! - `cohort`: the face assets, expression and calibration files, `dataset.subdivisions`,
//!   `dataset.tolerance`, `cohort.*`;
//! - `transfer` (per seed): `table2.normalization` and the keys of the cohort, the seed's
//!   unified network, the dataset (its AU range) and the basis;
//! - `renders`: the first seed's transfer key.

use anyhow::{Context, Result};

use crate::cache::Entry;
use crate::cohort::CohortKind;
use crate::dataset::reader::FaceReader;
use crate::dataset::Sample;
use crate::experiments::realfaces;
use crate::experiments::Products;
use crate::io::face::FaceSource;
use crate::learn::Mlp;
use crate::observe::{Calibration, AU_COUNT};
use crate::run::cell::{self, spec_calibration, CellRun, Experiment, Plan, Sweep};
use crate::run::stage::{text, Artifact, Files, Stages, Unit};
use crate::sim::basis::LinearBasis;
use crate::sim::{FaceModel, SolveParams};
use crate::spec::Spec;
use crate::spec::Table;
use crate::transfer::network::{au_mse, range_map, training_range, transfer, Setting, Transferred};
use std::rc::Rc;

mod cohort;
mod renders;
mod report;

pub use cohort::*;

use renders::*;
pub use report::{bars, csv, frames_csv, markdown, sweep_figure, sweep_markdown, tex};

// 2: the expressive face and its recalibrated observer (see BASIS_VERSION in cell/mod.rs).
// 3: video heads sway about their mean pose (cohort.*.head_motion_deg, head_motion_hz).
const COHORT_VERSION: u32 = 3;
const TRANSFER_VERSION: u32 = 2;
// 3: renders show eyeballs, teeth, brows, lips and the head on a neck. 4: the neck runs
// 6.5 cm below the chin onto shoulders. 5: the renderer's own version is in the key
// (`render::RENDER_VERSION`), so what it draws no longer needs a bump here.
const RENDERS_VERSION: u32 = 5;

/// What Table 2 needs from the rest of the cell.
pub struct Inputs<'a> {
    pub spec: &'a Spec,
    pub source: &'a FaceSource,
    /// The face mesh's hash.
    pub face: String,
    /// The expression weights' and observer calibration's hashes (`Assets::data`).
    pub data: String,
    pub dataset_key: &'a str,
    pub basis_key: Option<&'a str>,
    /// Per seed: the unified network's train key and network.
    pub unified: Vec<(u64, String, &'a Mlp)>,
    pub samples: &'a [Sample],
    pub model: &'a FaceModel,
    pub basis: Option<&'a LinearBasis>,
    pub calibration: &'a Calibration,
    /// Whether to render the first seed's transfers (for the figures).
    pub renders: bool,
}

pub struct Table2Result {
    pub cohort_key: String,
    pub rows: Vec<Row>,
    pub reference: Vec<RefFrame>,
    /// The first seed's transfers, per setting, aligned with `reference`.
    pub first: Vec<(Setting, Vec<Transferred>)>,
    /// Renders: (file name, bytes).
    pub renders: Vec<(String, Vec<u8>)>,
}

/// Table 2 in the registry: the cohorts, each seed's transfer, the renders, and the committed
/// real file (`table2.openface`) beside the cohorts.
pub(crate) struct Table2;

impl Experiment for Table2 {
    fn name(&self) -> &'static str {
        "table2"
    }

    fn table(&self) -> Option<Table> {
        Some(Table::Table2)
    }

    fn plan(&self, plan: &mut Plan) -> Result<()> {
        let spec = plan.spec;
        let cohort = planned_cohort(plan)?;
        let k = plan.keys();
        let transfers: Vec<(u64, Unit)> = k
            .unified()
            .into_iter()
            .map(|(seed, train_key)| {
                let t = transfer_unit(spec, &cohort.key, train_key, &k.dataset, k.basis.as_deref());
                (seed, t)
            })
            .collect();
        let first = transfers.first().map(|(_, t)| t.key.clone());
        plan.add("cohort", cohort);
        for (seed, t) in transfers {
            plan.add(format!("transfer seed {seed}"), t);
        }
        if let (Some(first), true) = (first, plan.publishes) {
            plan.add("renders", renders_unit(&first));
        }
        if let Some(file) = &spec.table2_openface {
            let committed = [crate::io::realdata::committed_input(file)];
            realfaces::plan_files(plan, &format!("realfaces {file}"), &committed)?;
        }
        Ok(())
    }

    fn run(&self, cx: &mut CellRun) -> Result<()> {
        let spec = cx.spec;
        let (n, k, model, basis) = (cx.networks()?, cx.keys()?, cx.model()?, cx.basis()?);
        let calibration = spec_calibration(spec)?;
        let inputs = Inputs {
            spec,
            source: &spec.face_source(),
            face: cx.assets.face.clone(),
            data: cx.assets.data(spec)?,
            dataset_key: &k.dataset,
            basis_key: k.basis.as_deref(),
            unified: n.unified(&k),
            samples: &n.samples,
            model: &model,
            basis: basis.as_ref().as_ref(),
            calibration: &calibration,
            renders: cx.figures("table2").is_some(),
        };
        let t2 = run(&inputs, &mut cx.stages())?;
        // The committed real file through every seed's network, reported beside the cohorts.
        let real = match &spec.table2_openface {
            Some(file) => Some(
                realfaces::through_networks(cx, &[crate::io::realdata::committed_input(file)])
                    .with_context(|| format!("Table 2's real file {file}"))?,
            ),
            None => None,
        };
        cx.output("table2.csv", csv(&t2.rows))?;
        cx.output("reference.csv", reference_csv(&t2.reference))?;
        cx.output("table2_frames.csv", frames_csv(&t2.reference, &t2.first))?;
        if let Some(rows) = &real {
            cx.output("table2_real.csv", realfaces::csv(rows))?;
        }
        let real = real.as_deref().unwrap_or(&[]);
        cx.table("table2.md", &markdown(&t2.rows, spec, &t2.reference, real))?;
        cx.table("table2.tex", &tex(&t2.rows, real, spec.seeds.len()))?;
        if let Some(figures) = cx.figures("table2") {
            for (name, bytes) in &t2.renders {
                crate::io::atomic::write_atomic(&figures.join(name), bytes)?;
            }
            bars(&figures.join("au_mse_bars.png"), &t2.rows)?;
        }
        Products::of(cx).table2 = Some(Rc::new(t2));
        Ok(())
    }

    fn sweep(&self, sweep: &mut Sweep) -> Result<()> {
        let cells: Vec<(String, Vec<Row>)> = Products::each(sweep, |p| p.table2.clone())
            .into_iter()
            .map(|(name, t2)| (name, t2.rows.clone()))
            .collect();
        if cells.is_empty() {
            return Ok(());
        }
        sweep.markdown.push_str(&sweep_markdown(&cells));
        let names: Vec<&str> = cells.iter().map(|(n, _)| n.as_str()).collect();
        let labels = crate::experiments::table1::sweep_labels(&names).1;
        sweep_figure(&sweep.figures(), &cells, &labels)
    }
}

/// The cohorts' unit in a cell's plan (the inversion and the pose transfer key on it too).
pub(crate) fn planned_cohort(plan: &Plan) -> Result<Unit> {
    let (spec, a) = (plan.spec, plan.assets);
    Ok(cohort_unit(spec, &a.face, &a.data(spec)?))
}

/// The reference frames of the cohorts, as `reference.csv`.
struct Reference(Vec<RefFrame>);

impl Artifact for Reference {
    fn encode(&self) -> Result<Vec<(String, Vec<u8>)>> {
        Ok(vec![(
            "reference.csv".into(),
            reference_csv(&self.0).into_bytes(),
        )])
    }
    fn decode(entry: &Entry) -> Result<Self> {
        let path = entry.path("reference.csv").display().to_string();
        Ok(Reference(reference_from_csv(
            &text(entry, "reference.csv")?,
            &path,
        )?))
    }
}

/// One seed's transfers per setting, as `transfers.csv`.
struct Transfers(Vec<(Setting, Vec<Transferred>)>);

impl Artifact for Transfers {
    fn encode(&self) -> Result<Vec<(String, Vec<u8>)>> {
        Ok(vec![(
            "transfers.csv".into(),
            transfers_csv(&self.0).into_bytes(),
        )])
    }
    fn decode(entry: &Entry) -> Result<Self> {
        let path = entry.path("transfers.csv").display().to_string();
        Ok(Transfers(transfers_from_csv(
            &text(entry, "transfers.csv")?,
            &path,
        )?))
    }
}

/// What the cohorts depend on.
#[derive(serde::Serialize)]
struct CohortInputs<'a> {
    face: &'a str,
    data: &'a str,
    cohort: &'a crate::cohort::CohortParams,
    source: crate::dataset::reader::Source,
    #[serde(skip_serializing_if = "Option::is_none")]
    renderer: Option<u32>,
    settings: cell::FaceSettings,
}

/// The cohorts' unit: the face mesh's and the data files' hashes, `cohort.*`,
/// `observer.source` and the face settings.
pub fn cohort_unit(spec: &Spec, face: &str, data: &str) -> Unit {
    let inputs = CohortInputs {
        face,
        data,
        cohort: &spec.cohort,
        source: spec.observer_source,
        renderer: spec.observer_source.renderer(),
        settings: cell::FaceSettings::of(&spec.dataset),
    };
    Unit::new("cohort", COHORT_VERSION, &inputs, &[])
}

/// What a transfer reads of the spec besides its inputs' keys: `table2.*`.
#[derive(serde::Serialize)]
struct TransferInputs<'a> {
    normalization: crate::learn::params::Normalization,
    openface: Option<&'a str>,
}

/// One seed's transfer: `table2.*`, the cohorts, the seed's unified network, the dataset (its
/// AU range) and the basis.
pub fn transfer_unit(
    spec: &Spec,
    cohort_key: &str,
    train_key: &str,
    dataset_key: &str,
    basis_key: Option<&str>,
) -> Unit {
    let mut inputs = vec![cohort_key, train_key, dataset_key];
    inputs.extend(basis_key);
    Unit::new(
        "transfer",
        TRANSFER_VERSION,
        &TransferInputs {
            normalization: spec.table2_normalization,
            openface: spec.table2_openface.as_ref().map(|f| f.name.as_str()),
        },
        &inputs,
    )
}

/// The renders of the first seed's transfers.
pub fn renders_unit(first_transfer_key: &str) -> Unit {
    Unit::new(
        "renders",
        RENDERS_VERSION,
        &crate::report::render::RENDER_VERSION,
        &[first_transfer_key],
    )
}

pub fn run(inp: &Inputs, stages: &mut Stages) -> Result<Table2Result> {
    let spec = inp.spec;
    let params = SolveParams {
        tolerance: spec.dataset.tolerance,
        ..SolveParams::default()
    };

    // Cohort: the reference frames.
    let cohort = cohort_unit(spec, &inp.face, &inp.data);
    let cohort_key = cohort.key.clone();
    let reader = FaceReader::new(spec.observer_source)?;
    let Reference(reference_frames) = stages.get_or_compute(&cohort, |stages| {
        let kinds = CohortKind::ALL;
        let progress = stages.bar(clip_count(&spec.cohort, &kinds) as u64, "cohort");
        let tick = || progress.inc(1);
        // Cached per cohort, so a killed run loses at most one cohort's solving; every
        // subject has its own stream, so the parts join to the same bytes.
        let mut frames = Vec::new();
        for kind in kinds {
            let unit = Unit::new("cohort_part", COHORT_VERSION, kind.name(), &[&cohort_key]);
            let before = progress.position();
            let Reference(part) = stages.get_or_compute(&unit, |_| {
                Ok(Reference(reference(
                    &inp.source.mesh()?,
                    inp.source.params(),
                    &inp.source.weights()?,
                    inp.calibration,
                    &reader,
                    &spec.cohort,
                    &[kind],
                    &params,
                    &tick,
                )?))
            })?;
            // A cached part did not tick.
            let count = clip_count(&spec.cohort, &[kind]) as u64;
            progress.inc(count.saturating_sub(progress.position() - before));
            frames.extend(part);
        }
        progress.finish_and_clear();
        Ok(Reference(frames))
    })?;

    let observer = reader.observer(inp.model, inp.calibration.clone())?;
    let training: Vec<[f64; AU_COUNT]> = inp.samples.iter().map(|s| s.aus).collect();
    let target = training_range(spec.table2_normalization, &training);
    let clips = clip_ranges(&reference_frames);

    // Transfer, per seed.
    let mut rows = Vec::new();
    let mut first = None;
    let mut first_key = String::new();
    for (seed, train_key, mlp) in &inp.unified {
        let unit = transfer_unit(spec, &cohort_key, train_key, inp.dataset_key, inp.basis_key);
        let key = unit.key.clone();
        let Transfers(transfers) = stages.get_or_compute(&unit, |stages| {
            let progress = stages.bar(2 * clips.len() as u64, &format!("transfer {seed}"));
            let tick = || progress.inc(1);
            let mut out = Vec::new();
            for setting in Setting::ALL {
                let mut frames: Vec<Transferred> = Vec::with_capacity(reference_frames.len());
                for kind in CohortKind::ALL {
                    // Cached per setting and cohort, so a killed run loses at most one part;
                    // each clip is transferred on its own, so the parts join to the same bytes.
                    let part = Unit::new(
                        "transfer_part",
                        TRANSFER_VERSION,
                        &(setting.name(), kind.name()),
                        &[&key],
                    );
                    let count = clips
                        .iter()
                        .filter(|r| reference_frames[r.start].cohort == kind)
                        .count() as u64;
                    let before = progress.position();
                    let Transfers(done) = stages.get_or_compute(&part, |_| {
                        let mine: Vec<&std::ops::Range<usize>> = clips
                            .iter()
                            .filter(|r| reference_frames[r.start].cohort == kind)
                            .collect();
                        let aus: Vec<Vec<[f64; AU_COUNT]>> = mine
                            .iter()
                            .map(|r| {
                                reference_frames[(*r).clone()]
                                    .iter()
                                    .map(|f| f.aus)
                                    .collect()
                            })
                            .collect();
                        let all: Vec<[f64; AU_COUNT]> = aus.iter().flatten().copied().collect();
                        let map = (setting == Setting::Normalized)
                            .then(|| range_map(spec.table2_normalization, &all, &target));
                        let t = transfer(
                            inp.model,
                            inp.basis,
                            &reader,
                            &observer,
                            mlp,
                            map.as_ref(),
                            &aus,
                            &params,
                            &tick,
                        )
                        .with_context(|| {
                            format!("Table 2, seed {seed}: {} {}", kind.name(), setting.name())
                        })?;
                        Ok(Transfers(vec![(
                            setting,
                            t.into_iter().flatten().collect(),
                        )]))
                    })?;
                    // A cached part did not tick.
                    progress.inc(count.saturating_sub(progress.position() - before));
                    frames.extend(done.into_iter().flat_map(|(_, f)| f));
                }
                out.push((setting, frames));
            }
            progress.finish_and_clear();
            Ok(Transfers(out))
        })?;
        rows.extend(seed_rows(*seed, &reference_frames, &transfers));
        if first.is_none() {
            first = Some(transfers);
            first_key = key;
        }
    }
    let first = first.context("Table 2 needs at least one seed")?;

    // Renders of the first seed, for the figures.
    let renders = if inp.renders {
        let Files(r) = stages.get_or_compute(&renders_unit(&first_key), |_| {
            Ok(Files(renders(inp, &reference_frames, &first, &params)?))
        })?;
        r
    } else {
        Vec::new()
    };
    Ok(Table2Result {
        cohort_key,
        rows,
        reference: reference_frames,
        first,
        renders,
    })
}

/// One seed's Table 2 rows: per setting and cohort, the AU MSE of its transfers against the
/// reference frames.
fn seed_rows(
    seed: u64,
    reference: &[RefFrame],
    transfers: &[(Setting, Vec<Transferred>)],
) -> Vec<Row> {
    let mut rows = Vec::new();
    for (setting, frames) in transfers {
        for kind in CohortKind::ALL {
            let idx: Vec<usize> = (0..reference.len())
                .filter(|&i| reference[i].cohort == kind)
                .collect();
            let r: Vec<_> = idx.iter().map(|&i| reference[i].aus).collect();
            let t: Vec<_> = idx.iter().map(|&i| frames[i].aus).collect();
            rows.push(Row {
                seed,
                cohort: kind,
                setting: *setting,
                mse: au_mse(&r, &t),
            });
        }
    }
    rows
}
