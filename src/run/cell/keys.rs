//! The inputs a run's stages share (asset and data files by content) and the cache keys of
//! a cell's basis and dataset stages; its training keys are made where its networks are
//! defined (`networks::train_keys`).

use super::networks::{train_keys, Network};
use crate::cache;
use crate::dataset::reader::Source;
use crate::dataset::{DatasetParams, Family, SolveStart};
use crate::io::facs::{read_facs, FacsMaps};
use crate::io::observer_fit::read_any_calibration;
use crate::io::Layout;
use crate::observe::Calibration;
use crate::observe::ObserverNoise;
use crate::run::stage::Unit;
use crate::spec::Spec;
use anyhow::{Context, Result};
use serde::Serialize;
use std::path::Path;

use super::{BASIS_VERSION, DATASET_VERSION, GRID_VERSION};

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
    #[serde(skip_serializing_if = "Option::is_none")]
    renderer: Option<u32>,
}

pub(crate) fn file_hash(path: &Path) -> Result<String> {
    let bytes = std::fs::read(path).with_context(|| format!("{}: cannot read", path.display()))?;
    Ok(cache::sha256(&bytes))
}

/// The inputs every stage shares: assets and data files, by content.
pub(crate) struct Assets {
    pub(crate) face: String,
    pub(crate) expressions: String,
    pub(crate) facs: FacsMaps,
    pub(crate) facs_hash: String,
}

impl Assets {
    /// The expression weights' and the spec's observer calibration's hashes.
    pub(crate) fn data(&self, spec: &Spec) -> Result<String> {
        Ok(format!(
            "{}{}",
            self.expressions,
            file_hash(&spec.calibration.path)?
        ))
    }
}

/// The spec's observer calibration (`observer.calibration`: gains or a fitted readout).
pub(crate) fn spec_calibration(spec: &Spec) -> Result<Calibration> {
    read_any_calibration(&spec.calibration.path)
        .with_context(|| format!("observer.calibration = \"{}\"", spec.calibration))
}

/// The face's code version, hashed with the mesh into the face every stage solves (the basis,
/// the dataset and the cohorts, and through them every stage after them). Bump it when the
/// muscles, the tissue or the solver move the equilibria. What the renderer draws has its own
/// version (`render::RENDER_VERSION`), keyed only where a result reads a render.
// 1: zygomaticus major widens a maximal smile by 46% (from 28%), levator labii superioris at
// 46 N; the eyes look out of the middle of their lid openings; the neck's front lies 5.5 cm
// behind the chin.
pub(crate) const FACE_VERSION: u32 = 1;

/// The checkout's face, expression weights and FACS tables, by content.
pub(crate) fn assets(layout: &Layout) -> Result<Assets> {
    let face = format!("{}/face-{FACE_VERSION}", file_hash(&layout.mesh())?);
    let expressions = file_hash(&layout.expressions())?;
    let (ea, am) = layout.facs();
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
pub(crate) struct Keys {
    pub(crate) basis: Option<String>,
    /// The grid of equilibria a paper-family data set solved from predictions starts from.
    pub(crate) grid: Option<String>,
    pub(crate) dataset: String,
    /// The faces without detector noise, where the spec's observer adds noise.
    pub(crate) clean_dataset: Option<String>,
    /// (seed, network) -> key, in seed then `Network::all()` order.
    pub(crate) train: Vec<((u64, Network), String)>,
}

impl Keys {
    /// Every seed's unified network's training key, in seed order.
    pub(crate) fn unified(&self) -> Vec<(u64, &str)> {
        self.train
            .iter()
            .filter(|((_, n), _)| *n == Network::Unified)
            .map(|((seed, _), key)| (*seed, key.as_str()))
            .collect()
    }
}

pub(crate) fn keys(spec: &Spec, a: &Assets) -> Result<Keys> {
    let needs_basis = spec.dataset.start == SolveStart::Predicted
        || spec.tables.contains(&crate::spec::Table::Inversion);
    let basis = needs_basis.then(|| {
        let face = (a.face.as_str(), FaceSettings::of(&spec.dataset));
        Unit::new("basis", BASIS_VERSION, &face, &[]).key
    });
    // A paper-family data set starts from the grid's interpolated equilibria (the basis
    // where they fail); other families, and `dataset.grid = 0`, from the basis alone, so
    // their keys stay what they were before the grid.
    let d = &spec.dataset;
    let grid =
        (d.start == SolveStart::Predicted && d.family == Family::Paper && d.grid > 0).then(|| {
            let inputs = (
                a.face.as_str(),
                FaceSettings::of(d),
                a.expressions.as_str(),
                d.grid,
            );
            Unit::new("grid", GRID_VERSION, &inputs, &[]).key
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
            calibration: &spec.calibration.name,
            source: spec.observer_source,
            renderer: spec.observer_source.renderer(),
        };
        // The data set reads the basis only to start its solves from its predictions; from
        // rest its faces are the same whether or not another table builds a basis.
        let starts: Vec<&str> = basis
            .iter()
            .filter(|_| d.start == SolveStart::Predicted)
            .chain(&grid)
            .map(String::as_str)
            .collect();
        Unit::new("dataset", DATASET_VERSION, &inputs, &starts).key
    };
    let dataset = dataset_key(spec.observer);
    let clean_dataset = (!spec.observer.is_off()).then(|| dataset_key(ObserverNoise::default()));
    let train = train_keys(spec, &a.facs_hash, &dataset);
    Ok(Keys {
        basis,
        grid,
        dataset,
        clean_dataset,
        train,
    })
}
