//! The inputs a run's stages share (asset and data files by content) and the cache keys of
//! a cell's basis, dataset and training stages.

use crate::cache::{self};
use crate::dataset::SolveStart;
use crate::experiments::table1::Network;
use crate::io::expressions::default_expressions_path;
use crate::io::facs::{data_path, read_facs, FacsMaps, DEFAULT_AU_MUSCLES, DEFAULT_EXPRESSION_AUS};
use crate::io::mesh::default_mesh_path;
use crate::io::observer_fit::read_any_calibration;
use crate::observe::Calibration;
use crate::spec::Spec;
use anyhow::{Context, Result};
use std::path::Path;

use super::*;

/// Values under the given dotted prefixes, as canonical `key = value` lines.
pub(crate) fn values_text(spec: &Spec, prefixes: &[&str]) -> String {
    spec.values_text(prefixes, &[], &[])
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
    let face = format!("face={}\n", a.face);
    let needs_basis =
        spec.dataset.start == SolveStart::Predicted || spec.tables.iter().any(|t| t == "inversion");
    let basis = needs_basis.then(|| {
        let v = format!(
            "{face}dataset.subdivisions = {}\ndataset.tolerance = {}\n\
             dataset.shear_modulus_fraction = {}\n",
            spec.dataset.subdivisions, spec.dataset.tolerance, spec.dataset.shear_modulus_fraction
        );
        cache::key("basis", BASIS_VERSION, &v, &[])
    });
    // The faces are read without detector noise and cached under the key of the spec with
    // the noise off; a noisy data set is cached under its own key, made from the clean one
    // (`dataset::add_noise`), so a noise sweep solves the faces once.
    let data = a.data(spec)?;
    // `dataset.test_fraction` splits the pairs at training (its key), not the faces.
    let dataset_key = |zeroed: &[&str]| {
        let text = spec.values_text(
            &["dataset.", "observer."],
            &["dataset.test_fraction"],
            zeroed,
        );
        cache::key(
            "dataset",
            DATASET_VERSION,
            &format!("{face}data={data}\n{text}"),
            &basis.iter().map(String::as_str).collect::<Vec<_>>(),
        )
    };
    let dataset = dataset_key(&[]);
    let clean_dataset = (!spec.observer.is_off())
        .then(|| dataset_key(&["observer.noise_sd", "observer.gain_spread"]));
    let mut train = Vec::new();
    for &seed in &spec.seeds {
        for network in Network::all() {
            let v = format!(
                "facs={}\nseed={seed}\nnetwork={}\n{}{}",
                a.facs_hash,
                network.name(),
                values_text(spec, &["model.", "train."]),
                values_text(spec, &["dataset.test_fraction"]),
            );
            train.push((
                (seed, network),
                cache::key("train", TRAIN_VERSION, &v, &[&dataset]),
            ));
        }
    }
    Ok(Keys {
        basis,
        dataset,
        clean_dataset,
        train,
    })
}
