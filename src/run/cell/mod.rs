//! What an experiment is to the run machinery, and the context a sweep cell runs in.
//!
//! Every table of a run is an [`Experiment`]: its name in a spec's `tables`, the units of work
//! it adds to a cell's plan (what `facelab status` lists and a cluster launcher submits), how
//! it computes on a cell through the cache and writes its outputs, what it writes when the
//! cell is done, and its part of a sweep's summary. A [`Registry`] lists them
//! (`experiments::REGISTRY`, handed to the run); a new experiment is a new folder under
//! `experiments` and one line in that list. Experiments meet in a cell's [`CellRun`]: the spec, the cache,
//! the networks every table but the head-neck experiment reads (computed once, on first use),
//! and [`Products`], where an experiment leaves what a later one reads (Table 2's cohorts for
//! the inversion and the pose transfer, the voluntary neck network for the pose transfer).

use std::any::Any;
use std::path::{Path, PathBuf};
use std::rc::Rc;

use anyhow::Result;

use crate::cache::Cache;
use crate::run::stage::{StageRecord, Stages, Unit, Verbosity};
use crate::sim::basis::LinearBasis;
use crate::sim::FaceModel;
use crate::spec::Spec;

pub(crate) mod keys;
pub(crate) mod networks;
pub(crate) mod starts;

pub(crate) use keys::{assets, keys, spec_calibration, Assets, FaceSettings, Keys};
pub(crate) use networks::{curves_csv, Networks, Trained};

/// Code versions: bump when a stage's output for the same inputs changes.
// 2: the expressive face (human range of motion, eyes opened to an adult aperture, lip
// contact) read by its recalibrated observer.
// Dataset 3: a prediction that fails is retried at 1/2 and 1/4 of the activations and
// continued along the ray from neutral (`solve_predicted`): the same equilibria within the
// solver's tolerance, reached by other iterates, so other bits (and every stage after it).
pub(crate) const BASIS_VERSION: u32 = 2;
pub(crate) const DATASET_VERSION: u32 = 3;
// The grid of the paper family's equilibria the data set starts its solves from
// (`sim::grid`); its key is an input of a paper-family data set's key.
pub(crate) const GRID_VERSION: u32 = 1;
pub(crate) const TRAIN_VERSION: u32 = 1;

/// The experiments a run may hold, in the order a cell runs them
/// (`facelab::experiments::REGISTRY`). The run machinery is handed them and names none.
#[derive(Clone, Copy)]
pub struct Registry(
    pub(crate) &'static [&'static dyn Experiment],
    /// A cell's empty products: the experiments' own typed struct, which the run holds for
    /// them without naming it.
    pub(crate) fn() -> Box<dyn Any>,
);

impl std::fmt::Debug for Registry {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_list()
            .entries(self.0.iter().map(|e| e.name()))
            .finish()
    }
}

/// One table of a run.
pub(crate) trait Experiment: Sync {
    /// Its name (its table's, where it makes one).
    fn name(&self) -> &'static str;

    /// The table of a spec's `tables` it makes, if any.
    fn table(&self) -> Option<crate::spec::Table>;

    /// The tables whose products it reads (each made by an experiment before it in the
    /// registry): by default its table's [`crate::spec::Table::needs`].
    fn reads(&self) -> Vec<crate::spec::Table> {
        self.table().map_or(Vec::new(), |t| t.needs().to_vec())
    }

    /// Whether a cell of `spec` runs it: by default, when `tables` lists its table.
    fn wanted(&self, spec: &Spec) -> bool {
        self.table().is_some_and(|t| spec.tables.contains(&t))
    }

    /// Whether it reads the cell's networks (the dataset and the training stages).
    fn trains(&self) -> bool {
        true
    }

    /// Whether only the first seed feeds it (a cluster's task for a further seed leaves it
    /// out).
    fn first_seed_only(&self) -> bool {
        false
    }

    /// The units of work it adds to a cell's plan, in the order a run meets them, with keys
    /// computed by the same functions its stages use.
    fn plan(&self, plan: &mut Plan) -> Result<()>;

    /// Computes it on a cell through the cache and writes its outputs: CSVs into the run
    /// folder, and, for a single-cell spec, its tables and figures.
    fn run(&self, cx: &mut CellRun) -> Result<()>;

    /// What it writes after every wanted experiment of a cell ran, whether the cell's spec
    /// lists it or not (Table 1 records the networks of every cell that trained).
    fn finish_cell(&self, _cx: &mut CellRun) -> Result<()> {
        Ok(())
    }

    /// Its part of a sweep's summary, from every cell's products (after all cells ran; every
    /// registered experiment, in registry order, whether the spec lists it or not).
    fn sweep(&self, _sweep: &mut Sweep) -> Result<()> {
        Ok(())
    }
}

/// Where a run writes; the run implements it over its folder and its publishing.
pub(crate) trait Sink {
    /// A compared output, `rel` to the run folder, hashed into the manifest.
    fn output(&mut self, rel: &str, bytes: Vec<u8>) -> Result<()>;
    /// A measurement of this machine (timings), `rel` to the run folder, outside the compared
    /// outputs.
    fn measurement(&mut self, rel: &str, bytes: &[u8]) -> Result<()>;
    /// A paper table (Markdown or LaTeX) named `name` in the tables folder.
    fn table(&self, name: &str, text: &str) -> Result<()>;
    /// The figures folder.
    fn figures(&self) -> &Path;
}

/// One sweep cell of a run, as its experiments see it.
pub(crate) struct CellRun<'a> {
    pub(crate) spec: &'a Spec,
    pub(crate) assets: &'a Assets,
    /// What its experiments hand each other (the registry's typed struct).
    pub(crate) products: Box<dyn Any>,
    cell: &'a str,
    /// The cell's folder in the run folder: empty for a single-cell spec, `name/` in a sweep.
    prefix: String,
    single: bool,
    cache: &'a Cache,
    records: &'a mut Vec<StageRecord>,
    sink: &'a mut dyn Sink,
    verbosity: Verbosity,
    keys: Option<Rc<Keys>>,
    networks: Option<Rc<Networks>>,
    model: Option<Rc<FaceModel>>,
    basis: Option<Rc<Option<LinearBasis>>>,
}

impl<'a> CellRun<'a> {
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn new(
        spec: &'a Spec,
        cell: &'a str,
        prefix: String,
        single: bool,
        assets: &'a Assets,
        cache: &'a Cache,
        records: &'a mut Vec<StageRecord>,
        sink: &'a mut dyn Sink,
        products: Box<dyn Any>,
        verbosity: Verbosity,
    ) -> CellRun<'a> {
        CellRun {
            spec,
            assets,
            products,
            cell,
            prefix,
            single,
            cache,
            records,
            sink,
            verbosity,
            keys: None,
            networks: None,
            model: None,
            basis: None,
        }
    }

    /// The cell's stages: the cache, with every unit recorded for the manifest.
    pub(crate) fn stages(&mut self) -> Stages<'_> {
        Stages::new(self.cache, self.cell, self.records, self.verbosity)
    }

    /// The keys of the cell's basis, dataset and training stages.
    pub(crate) fn keys(&mut self) -> Result<Rc<Keys>> {
        let (spec, assets) = (self.spec, self.assets);
        once(&mut self.keys, || keys(spec, assets))
    }

    /// The cell's data set and trained networks, computed (through the cache) on first use.
    pub(crate) fn networks(&mut self) -> Result<Rc<Networks>> {
        let k = self.keys()?;
        let (spec, assets) = (self.spec, self.assets);
        let mut stages = Stages::new(self.cache, self.cell, self.records, self.verbosity);
        once(&mut self.networks, || {
            networks::networks(spec, assets, &k, &mut stages)
        })
    }

    /// The networks, if an experiment of the cell asked for them.
    pub(crate) fn trained(&self) -> Option<Rc<Networks>> {
        self.networks.clone()
    }

    /// The cell's face model.
    pub(crate) fn model(&mut self) -> Result<Rc<FaceModel>> {
        let spec = self.spec;
        once(&mut self.model, || spec.face_source().model())
    }

    /// The linear basis of the cell's face (cached), when the spec solves from predictions
    /// or inverts.
    pub(crate) fn basis(&mut self) -> Result<Rc<Option<LinearBasis>>> {
        let (k, model, spec) = (self.keys()?, self.model()?, self.spec);
        let mut stages = Stages::new(self.cache, self.cell, self.records, self.verbosity);
        once(&mut self.basis, || {
            starts::load_basis(&k, &mut stages, &model, spec)
        })
    }

    /// Whether the cell is the whole spec: only then does it write tables and figures (a
    /// sweep's summary is its table).
    pub(crate) fn publishes(&self) -> bool {
        self.single
    }

    /// Writes `name` into the cell's folder of the run (a compared output).
    pub(crate) fn output(&mut self, name: &str, bytes: impl Into<Vec<u8>>) -> Result<()> {
        let rel = format!("{}{name}", self.prefix);
        self.sink.output(&rel, bytes.into())
    }

    /// Writes a measurement `name` into the cell's `timings/` folder (not a compared output).
    pub(crate) fn measurement(&mut self, name: &str, text: &str) -> Result<()> {
        let rel = format!("{}timings/{name}", self.prefix);
        self.sink.measurement(&rel, text.as_bytes())
    }

    /// Writes the paper table `name` (under the spec's report prefix) for a single-cell spec.
    pub(crate) fn table(&self, name: &str, text: &str) -> Result<()> {
        if !self.single {
            return Ok(());
        }
        self.sink
            .table(&format!("{}{name}", self.spec.report_prefix), text)
    }

    /// The figures folder `name` (under the spec's report prefix) for a single-cell spec.
    pub(crate) fn figures(&self, name: &str) -> Option<PathBuf> {
        self.single.then(|| {
            self.sink
                .figures()
                .join(format!("{}{name}", self.spec.report_prefix))
        })
    }
}

/// What `slot` holds, made by `make` and kept there on first use.
fn once<T>(slot: &mut Option<Rc<T>>, make: impl FnOnce() -> Result<T>) -> Result<Rc<T>> {
    if let Some(v) = slot {
        return Ok(v.clone());
    }
    let v = Rc::new(make()?);
    *slot = Some(v.clone());
    Ok(v)
}

/// A sweep's summary, written after all its cells ran.
pub(crate) struct Sweep<'a> {
    /// The spec's experiment name: the summary's file names.
    pub(crate) experiment: &'a str,
    /// Every cell's name and products, in the spec's order.
    pub(crate) cells: &'a [(String, Box<dyn Any>)],
    /// The summary's Markdown, each experiment appending its part.
    pub(crate) markdown: String,
    sink: &'a mut dyn Sink,
}

impl<'a> Sweep<'a> {
    pub(crate) fn new(
        experiment: &'a str,
        cells: &'a [(String, Box<dyn Any>)],
        sink: &'a mut dyn Sink,
    ) -> Sweep<'a> {
        Sweep {
            experiment,
            cells,
            markdown: String::new(),
            sink,
        }
    }

    /// Every cell's name and products, as the registry's type `P`.
    pub(crate) fn products<P: Any>(&self) -> Vec<(&str, &P)> {
        self.cells
            .iter()
            .map(|(name, p)| {
                let p = p
                    .downcast_ref()
                    .expect("a cell's products are the registry's type");
                (name.as_str(), p)
            })
            .collect()
    }

    /// Writes `rel` into the run folder (a compared output).
    pub(crate) fn output(&mut self, rel: &str, bytes: impl Into<Vec<u8>>) -> Result<()> {
        self.sink.output(rel, bytes.into())
    }

    /// The summary's figures folder.
    pub(crate) fn figures(&self) -> PathBuf {
        self.sink.figures().join(self.experiment)
    }

    /// Writes the summary's Markdown as the table `<experiment>.md`.
    pub(crate) fn finish(self) -> Result<()> {
        self.sink
            .table(&format!("{}.md", self.experiment), &self.markdown)
    }
}

/// One unit of a cell's plan: what it is, and its unit, or why its key cannot be known
/// without running (the pose transfer's key hashes the voluntary network, known once it is
/// cached).
pub struct Planned {
    pub cell: String,
    pub label: String,
    pub unit: Result<Unit, String>,
}

/// A cell's plan as its experiments add to it.
pub(crate) struct Plan<'a> {
    pub(crate) spec: &'a Spec,
    pub(crate) assets: &'a Assets,
    pub(crate) cache: &'a Cache,
    /// Whether the run writes tables and figures (a single-cell spec): their own units
    /// (Table 2's renders) are planned only then.
    pub(crate) publishes: bool,
    cell: &'a str,
    keys: Option<Keys>,
    pub(crate) units: Vec<Planned>,
}

impl<'a> Plan<'a> {
    /// The units of every experiment `experiments` of `spec` runs, in the order a run meets
    /// them: the networks first when any experiment reads them.
    pub(crate) fn of(
        spec: &'a Spec,
        cell: &'a str,
        assets: &'a Assets,
        cache: &'a Cache,
        experiments: &[&dyn Experiment],
        publishes: bool,
    ) -> Result<Vec<Planned>> {
        let wanted: Vec<&dyn Experiment> = experiments
            .iter()
            .copied()
            .filter(|e| e.wanted(spec))
            .collect();
        let keys = if wanted.iter().any(|e| e.trains()) {
            Some(keys(spec, assets)?)
        } else {
            None
        };
        let mut plan = Plan {
            spec,
            assets,
            cache,
            publishes,
            cell,
            keys,
            units: Vec::new(),
        };
        if let Some(k) = plan.keys.take() {
            if let Some(b) = &k.basis {
                plan.add("basis", Unit::keyed("basis", b));
            }
            if let Some(g) = &k.grid {
                plan.add("grid", Unit::keyed("grid", g));
            }
            match &k.clean_dataset {
                Some(clean) => {
                    plan.add("dataset (clean)", Unit::keyed("dataset", clean));
                    plan.add("dataset_noise", Unit::keyed("dataset_noise", &k.dataset));
                }
                None => plan.add("dataset", Unit::keyed("dataset", &k.dataset)),
            }
            for ((seed, network), key) in &k.train {
                plan.add(
                    format!("train {} seed {seed}", network.name()),
                    Unit::keyed("train", key),
                );
            }
            plan.keys = Some(k);
        }
        for e in wanted {
            e.plan(&mut plan)?;
        }
        Ok(plan.units)
    }

    /// The keys of the cell's basis, dataset and training stages (the plan of an experiment
    /// that reads the networks).
    pub(crate) fn keys(&self) -> &Keys {
        self.keys
            .as_ref()
            .expect("the plan has the networks' keys when an experiment trains")
    }

    /// Adds a unit labelled `label`.
    pub(crate) fn add(&mut self, label: impl Into<String>, unit: Unit) {
        self.push(label, Ok(unit));
    }

    /// Adds a unit whose key is not known yet, and why.
    pub(crate) fn waiting(&mut self, label: impl Into<String>, why: impl Into<String>) {
        self.push(label, Err(why.into()));
    }

    fn push(&mut self, label: impl Into<String>, unit: Result<Unit, String>) {
        self.units.push(Planned {
            cell: self.cell.to_string(),
            label: label.into(),
            unit,
        });
    }
}
