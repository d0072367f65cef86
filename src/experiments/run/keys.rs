//! The inputs a run's stages share (asset and data files by content) and the cache keys of
//! a cell's basis, dataset and training stages.

use crate::cache::{self, Cache, Lookup};
use crate::dataset::reader::Source;
use crate::dataset::{DatasetParams, Family, SolveStart};
use crate::experiments::stage::Unit;
use crate::experiments::table1::Network;
use crate::experiments::{headpose, inversion, pose_transfer, realfaces, table2_stage};
use crate::io::expressions::default_expressions_path;
use crate::io::facs::{data_path, read_facs, FacsMaps, DEFAULT_AU_MUSCLES, DEFAULT_EXPRESSION_AUS};
use crate::io::mesh::default_mesh_path;
use crate::io::observer_fit::read_any_calibration;
use crate::learn::params::{ModelParams, TrainParams};
use crate::observe::Calibration;
use crate::observe::ObserverNoise;
use crate::spec::Cell;
use crate::spec::Spec;
use anyhow::{Context, Result};
use serde::Serialize;
use std::path::Path;

use super::*;

/// The face settings every solve reads: the basis, the dataset and the cohorts hash them.
#[derive(Serialize)]
pub(crate) struct FaceSettings {
    subdivisions: u8,
    tolerance: f64,
    shear_modulus_fraction: f64,
}

impl FaceSettings {
    pub(crate) fn of(d: &DatasetParams) -> FaceSettings {
        FaceSettings {
            subdivisions: d.subdivisions,
            tolerance: d.tolerance,
            shear_modulus_fraction: d.shear_modulus_fraction,
        }
    }
}

/// What the dataset's faces depend on. Not `dataset.test_fraction`: it splits the pairs at
/// training (the train key has it), not the faces.
#[derive(Serialize)]
struct DatasetInputs<'a> {
    face: &'a str,
    data: &'a str,
    settings: FaceSettings,
    pairs_per_expression: usize,
    start: SolveStart,
    family: Family,
    seed: u64,
    observer: ObserverNoise,
    calibration: &'a str,
    source: Source,
}

/// What one network's training depends on (besides the dataset's key).
#[derive(Serialize)]
struct TrainInputs<'a> {
    facs: &'a str,
    seed: u64,
    network: String,
    model: &'a ModelParams,
    train: &'a TrainParams,
    test_fraction: f64,
}

pub(super) fn file_hash(path: &Path) -> Result<String> {
    let bytes = std::fs::read(path).with_context(|| format!("{}: cannot read", path.display()))?;
    Ok(cache::sha256(&bytes))
}

/// The inputs every stage shares: assets and data files, by content.
pub(super) struct Assets {
    pub(super) face: String,
    pub(super) expressions: String,
    pub(super) facs: FacsMaps,
    pub(super) facs_hash: String,
}

impl Assets {
    /// The expression weights' and the spec's observer calibration's hashes.
    pub(super) fn data(&self, spec: &Spec) -> Result<String> {
        Ok(format!(
            "{}{}",
            self.expressions,
            file_hash(&data_path(&spec.calibration))?
        ))
    }
}

/// The spec's observer calibration (`observer.calibration`: gains or a fitted readout).
pub(crate) fn spec_calibration(spec: &Spec) -> Result<Calibration> {
    read_any_calibration(&data_path(&spec.calibration))
        .with_context(|| format!("observer.calibration = \"{}\"", spec.calibration))
}

pub(super) fn assets() -> Result<Assets> {
    let face = file_hash(&default_mesh_path())?;
    let expressions = file_hash(&default_expressions_path())?;
    let ea = data_path(DEFAULT_EXPRESSION_AUS);
    let am = data_path(DEFAULT_AU_MUSCLES);
    let facs = read_facs(&ea, &am)?;
    let facs_hash = format!("{}{}", file_hash(&ea)?, file_hash(&am)?);
    Ok(Assets {
        face,
        expressions,
        facs,
        facs_hash,
    })
}

/// Cache keys of a cell's stages.
pub(super) struct Keys {
    pub(super) basis: Option<String>,
    pub(super) dataset: String,
    /// The faces without detector noise, where the spec's observer adds noise.
    pub(super) clean_dataset: Option<String>,
    /// (seed, network) -> key, in seed then `Network::all()` order.
    pub(super) train: Vec<((u64, Network), String)>,
}

pub(super) fn keys(spec: &Spec, a: &Assets) -> Result<Keys> {
    let needs_basis =
        spec.dataset.start == SolveStart::Predicted || spec.tables.iter().any(|t| t == "inversion");
    let basis = needs_basis.then(|| {
        let face = (a.face.as_str(), FaceSettings::of(&spec.dataset));
        Unit::new("basis", BASIS_VERSION, &face, &[]).key
    });
    // The faces are read without detector noise and cached under the key of the spec with
    // the noise off; a noisy data set is cached under its own key, made from the clean one
    // (`dataset::add_noise`), so a noise sweep solves the faces once.
    let data = a.data(spec)?;
    let dataset_key = |observer: ObserverNoise| {
        let d = &spec.dataset;
        let inputs = DatasetInputs {
            face: &a.face,
            data: &data,
            settings: FaceSettings::of(d),
            pairs_per_expression: d.pairs_per_expression,
            start: d.start,
            family: d.family,
            seed: d.seed,
            observer,
            calibration: &spec.calibration,
            source: spec.observer_source,
        };
        let basis: Vec<&str> = basis.iter().map(String::as_str).collect();
        Unit::new("dataset", DATASET_VERSION, &inputs, &basis).key
    };
    let dataset = dataset_key(spec.observer);
    let clean_dataset = (!spec.observer.is_off()).then(|| dataset_key(ObserverNoise::default()));
    let mut train = Vec::new();
    for &seed in &spec.seeds {
        for network in Network::all() {
            let inputs = TrainInputs {
                facs: &a.facs_hash,
                seed,
                network: network.name(),
                model: &spec.model,
                train: &spec.train,
                test_fraction: spec.dataset.test_fraction,
            };
            let unit = Unit::new("train", TRAIN_VERSION, &inputs, &[&dataset]);
            train.push(((seed, network), unit.key));
        }
    }
    Ok(Keys {
        basis,
        dataset,
        clean_dataset,
        train,
    })
}

/// One unit of a cell's plan: what it is, and its unit, or why its key cannot be known
/// without running (the pose transfer's key hashes the voluntary network, known once it is
/// cached).
pub struct Planned {
    pub cell: String,
    pub label: String,
    pub unit: Result<Unit, String>,
}

/// Every unit of work of a cell, in the order a run meets them, with their keys computed
/// exactly as the stages compute them (the same functions), reading only the spec, the data
/// files and, for the pose transfer, the cached voluntary network.
pub(crate) fn plan(cell: &Cell, a: &Assets, cache: &Cache) -> Result<Vec<Planned>> {
    let spec = &cell.spec;
    let mut out = Vec::new();
    let mut add = |label: String, unit: Result<Unit, String>| {
        out.push(Planned {
            cell: cell.name.clone(),
            label,
            unit,
        })
    };
    let tables = |t: &str| spec.tables.iter().any(|x| x == t);
    let mut cohort_key = None;
    if spec.tables.iter().any(|t| t != "headpose") {
        let k = keys(spec, a)?;
        if let Some(b) = &k.basis {
            add("basis".into(), Ok(Unit::keyed("basis", b)));
        }
        match &k.clean_dataset {
            Some(clean) => {
                add("dataset (clean)".into(), Ok(Unit::keyed("dataset", clean)));
                add(
                    "dataset_noise".into(),
                    Ok(Unit::keyed("dataset_noise", &k.dataset)),
                );
            }
            None => add("dataset".into(), Ok(Unit::keyed("dataset", &k.dataset))),
        }
        for ((seed, network), key) in &k.train {
            add(
                format!("train {} seed {seed}", network.name()),
                Ok(Unit::keyed("train", key)),
            );
        }
        let unified: Vec<(u64, &str)> = k
            .train
            .iter()
            .filter(|((_, n), _)| *n == Network::Unified)
            .map(|((seed, _), key)| (*seed, key.as_str()))
            .collect();
        // Real OpenFace files through every seed's unified network, labelled per seed.
        let real = |label: &str, files: &[crate::io::realdata::RealInput]| {
            let content = realfaces::content(files)?;
            Ok::<_, anyhow::Error>(
                unified
                    .iter()
                    .map(|(seed, train_key)| {
                        let unit = realfaces::unit(
                            spec,
                            &content,
                            train_key,
                            &k.dataset,
                            k.basis.as_deref(),
                        );
                        (format!("{label} seed {seed}"), unit)
                    })
                    .collect::<Vec<_>>(),
            )
        };
        if tables("table2") {
            let cohort = table2_stage::cohort_unit(spec, &a.face, &a.data(spec)?);
            let mut first = None;
            for (seed, train_key) in &unified {
                let t = table2_stage::transfer_unit(
                    spec,
                    &cohort.key,
                    train_key,
                    &k.dataset,
                    k.basis.as_deref(),
                );
                first.get_or_insert_with(|| t.key.clone());
                add(format!("transfer seed {seed}"), Ok(t));
            }
            if let Some(first) = first {
                add("renders".into(), Ok(table2_stage::renders_unit(&first)));
            }
            if tables("inversion") {
                if let Some((_, train_key)) = unified.first() {
                    let mut inputs = vec![cohort.key.as_str(), train_key, k.dataset.as_str()];
                    inputs.extend(k.basis.as_deref());
                    add("inversion".into(), Ok(inversion::unit(spec, &inputs)));
                }
            }
            if let Some(file) = &spec.table2_openface {
                let committed = [crate::io::realdata::committed_input(file)];
                for (label, unit) in real(&format!("realfaces {file}"), &committed)? {
                    add(label, Ok(unit));
                }
            }
            cohort_key = Some(cohort.key.clone());
            add("cohort".into(), Ok(cohort));
        }
        if tables("realfaces") {
            match crate::io::realdata::inputs(&spec.realfaces) {
                Ok(files) => {
                    for (label, unit) in real("realfaces", &files)? {
                        add(label, Ok(unit));
                    }
                }
                Err(e) => add("realfaces".into(), Err(e.to_string())),
            }
        }
    }
    if tables("headpose") {
        let data = headpose::data_unit(spec);
        let train = headpose::train_unit(spec, &data.key);
        let weights = match cache.inspect(train.stage, &train.key) {
            Lookup::Hit(e) => Some(e.read("weights.safetensors")?),
            _ => None,
        };
        let eval = headpose::eval_unit(spec, &train.key);
        add("headpose_data".into(), Ok(data));
        add("headpose_train".into(), Ok(train));
        add("headpose_eval".into(), Ok(eval));
        if let Some(cohort_key) = &cohort_key {
            add(
                "pose_transfer".into(),
                weights
                    .map(|w| pose_transfer::unit(spec, cohort_key, &w))
                    .ok_or_else(|| "its key needs the voluntary network (headpose_train)".into()),
            );
        }
    }
    Ok(out)
}
