//! `facelab run | status | verify`: a spec's stages, cached by content (DESIGN 2.5).
//!
//! Stages and what their keys hash (besides the stage name and version):
//! - `basis` (only with `dataset.start = "predicted"`): the face assets, `dataset.subdivisions`,
//!   `dataset.tolerance`, `dataset.shear_modulus_fraction`;
//! - `dataset`: the basis key, the face, expression and calibration files, `dataset.*`,
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
use std::time::Instant;

use anyhow::{bail, Context, Result};
use indicatif::{ProgressBar, ProgressStyle};

use super::dataset::{self, Sample, SolveStart};
use super::face::FaceSource;
use super::headpose;
use super::inversion;
use super::pose_transfer;
use super::reader::FaceReader;
use super::realfaces;
use super::table1::{self, Network, Row};
use super::table2;
use super::table2_stage::{self, Table2Result};
use crate::cache::{self, Cache, Entry};
use crate::io::atomic::write_atomic;
use crate::io::expressions::default_expressions_path;
use crate::io::facs::{data_path, read_facs, FacsMaps, DEFAULT_AU_MUSCLES, DEFAULT_EXPRESSION_AUS};
use crate::io::mesh::default_mesh_path;
use crate::io::observer_fit::read_any_calibration;
use crate::learn::{self, Curves, Mlp};
use crate::observe::{Calibration, AU_NAMES};
use crate::rng::stream;
use crate::sim::basis::LinearBasis;
use crate::sim::geom::V3;
use crate::sim::{FaceModel, SolveParams};
use crate::spec::{self, Cell, Spec};
use crate::stats;

/// Code versions: bump when a stage's output for the same inputs changes.
// 2: the expressive face (human range of motion, eyes opened to an adult aperture, lip
// contact) read by its recalibrated observer.
const BASIS_VERSION: u32 = 2;
const DATASET_VERSION: u32 = 2;
const TRAIN_VERSION: u32 = 1;

#[derive(Clone, Debug)]
pub struct RunOptions {
    /// Results folder; the cache lives in `<results>/.cache`, tables and figures in
    /// `<results>/../paper-tables` and `<results>/../figures`.
    pub results: PathBuf,
    pub sets: Vec<String>,
    pub threads: usize,
}

/// What one stage did.
#[derive(Clone, Debug, PartialEq)]
pub struct StageRecord {
    pub cell: String,
    pub stage: String,
    pub key: String,
    pub hit: bool,
    pub seconds: f64,
}

#[derive(Clone, Debug)]
pub struct RunSummary {
    pub dir: PathBuf,
    pub stages: Vec<StageRecord>,
    /// Output file (relative to the run folder) -> SHA-256.
    pub outputs: BTreeMap<String, String>,
}

/// Values under the given dotted prefixes, as canonical `key = value` lines.
pub(super) fn values_text(spec: &Spec, prefixes: &[&str]) -> String {
    prefixed_text(&spec.values, prefixes)
}

fn prefixed_text(values: &BTreeMap<String, toml::Value>, prefixes: &[&str]) -> String {
    values
        .iter()
        .filter(|(k, _)| prefixes.iter().any(|p| k.starts_with(p)))
        .map(|(k, v)| format!("{k} = {v}\n"))
        .collect()
}

fn file_hash(path: &Path) -> Result<String> {
    let bytes = std::fs::read(path).with_context(|| format!("{}: cannot read", path.display()))?;
    Ok(cache::sha256(&bytes))
}

/// The inputs every stage shares: assets and data files, by content.
struct Assets {
    face: String,
    expressions: String,
    facs: FacsMaps,
    facs_hash: String,
}

impl Assets {
    /// The expression weights' and the spec's observer calibration's hashes.
    fn data(&self, spec: &Spec) -> Result<String> {
        Ok(format!(
            "{}{}",
            self.expressions,
            file_hash(&data_path(&spec.calibration))?
        ))
    }
}

/// The spec's observer calibration (`observer.calibration`: gains or a fitted readout).
pub(super) fn spec_calibration(spec: &Spec) -> Result<Calibration> {
    read_any_calibration(&data_path(&spec.calibration))
        .with_context(|| format!("observer.calibration = \"{}\"", spec.calibration))
}

fn assets() -> Result<Assets> {
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
struct Keys {
    basis: Option<String>,
    dataset: String,
    /// The faces without detector noise, where the spec's observer adds noise.
    clean_dataset: Option<String>,
    /// (seed, network) -> key, in seed then `Network::all()` order.
    train: Vec<((u64, Network), String)>,
}

fn keys(spec: &Spec, a: &Assets) -> Result<Keys> {
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
    let dataset_key = |values: &BTreeMap<String, toml::Value>| {
        let text = prefixed_text(values, &["dataset.", "observer."]);
        cache::key(
            "dataset",
            DATASET_VERSION,
            &format!("{face}data={data}\n{text}"),
            &basis.iter().map(String::as_str).collect::<Vec<_>>(),
        )
    };
    let dataset = dataset_key(&spec.values);
    let clean_dataset = (!spec.observer.is_off()).then(|| {
        let mut quiet = spec.values.clone();
        for k in ["observer.noise_sd", "observer.gain_spread"] {
            quiet.insert(k.to_string(), toml::Value::Float(0.0));
        }
        dataset_key(&quiet)
    });
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

fn bar(len: u64, message: &str) -> ProgressBar {
    let b = ProgressBar::new(len);
    b.set_style(
        ProgressStyle::with_template(
            "{msg:>10} [{bar:40}] {pos}/{len} {elapsed_precise} eta {eta}",
        )
        .expect("valid template")
        .progress_chars("=> "),
    );
    b.set_message(message.to_string());
    b
}

fn basis_bytes(b: &LinearBasis) -> Vec<u8> {
    let mut out = Vec::new();
    out.extend((b.vertex_count as u64).to_le_bytes());
    out.extend((b.rest.len() as u64).to_le_bytes());
    out.extend((b.fields.len() as u64).to_le_bytes());
    for p in &b.rest {
        for c in p {
            out.extend(c.to_le_bytes());
        }
    }
    for f in &b.fields {
        for v in f {
            out.extend(v.to_le_bytes());
        }
    }
    out
}

fn basis_from(bytes: &[u8]) -> Result<LinearBasis> {
    let mut words = bytes
        .chunks_exact(8)
        .map(|c| <[u8; 8]>::try_from(c).expect("8 bytes"));
    let mut next_u = || -> Result<usize> {
        Ok(u64::from_le_bytes(words.next().context("basis file cut short")?) as usize)
    };
    let (vertex_count, nodes, count) = (next_u()?, next_u()?, next_u()?);
    let floats: Vec<f64> = bytes[24..]
        .chunks_exact(8)
        .map(|c| f64::from_le_bytes(c.try_into().expect("8 bytes")))
        .collect();
    if floats.len() != 3 * nodes * (1 + count) {
        bail!(
            "basis file has {} values, expected {}",
            floats.len(),
            3 * nodes * (1 + count)
        );
    }
    let rest: Vec<V3> = floats[..3 * nodes]
        .chunks_exact(3)
        .map(|c| [c[0], c[1], c[2]])
        .collect();
    let fields = floats[3 * nodes..]
        .chunks_exact(3 * nodes)
        .map(<[f64]>::to_vec)
        .collect();
    Ok(LinearBasis {
        vertex_count,
        rest,
        fields,
    })
}

pub(super) fn curves_csv(curves: &Curves) -> String {
    let mut out = String::from("epoch,train_mse,test_mse\n");
    for (i, (a, b)) in curves.train.iter().zip(&curves.test).enumerate() {
        out.push_str(&format!("{},{a},{b}\n", i + 1));
    }
    out
}

pub(super) fn curves_from(text: &str) -> Curves {
    let mut c = Curves::default();
    for line in text.lines().skip(1) {
        let cells: Vec<f64> = line.split(',').filter_map(|s| s.parse().ok()).collect();
        if cells.len() == 3 {
            c.train.push(cells[1]);
            c.test.push(cells[2]);
        }
    }
    c
}

/// Everything one cell produced.
struct CellResult {
    rows: Vec<Row>,
    table2: Option<Table2Result>,
    inversion: Option<inversion::Output>,
    realfaces: Option<Vec<realfaces::FileRow>>,
    /// Table 2's committed real file (`table2.openface`) through each seed's network.
    table2_real: Option<Vec<realfaces::FileRow>>,
    /// The first seed's unified network (safetensors) and the training AUs' per-AU
    /// statistics, for `facelab transfer --model`.
    unified: Vec<u8>,
    training_aus: String,
    /// (seed, network) -> curves.
    curves: Vec<((u64, Network), Curves)>,
    samples: usize,
}

/// The linear basis of the cell's face (cached), when the spec solves from predictions.
fn load_basis(
    k: &Keys,
    cache: &Cache,
    model: &FaceModel,
    spec: &Spec,
    record: &mut dyn FnMut(&str, &str, bool, Instant),
) -> Result<Option<LinearBasis>> {
    let Some(key) = &k.basis else {
        return Ok(None);
    };
    let t = Instant::now();
    if let Some(e) = cache.get("basis", key)? {
        let b = basis_from(&e.read("basis.bin")?)?;
        record("basis", key, true, t);
        return Ok(Some(b));
    }
    let params = SolveParams {
        tolerance: spec.dataset.tolerance,
        ..SolveParams::default()
    };
    let b = LinearBasis::build(model, &params).context("building the linear basis")?;
    cache.put("basis", key, &[("basis.bin".into(), basis_bytes(&b))])?;
    record("basis", key, false, t);
    Ok(Some(b))
}

/// A stage's record keeper for `cell`: (stage, key, cache hit, start time).
fn recorder<'a>(
    cell: &'a str,
    records: &'a mut Vec<StageRecord>,
) -> impl FnMut(&str, &str, bool, Instant) + 'a {
    move |stage, key, hit, t| {
        records.push(StageRecord {
            cell: cell.into(),
            stage: stage.into(),
            key: key.into(),
            hit,
            seconds: t.elapsed().as_secs_f64(),
        })
    }
}

fn run_cell(
    cell: &Cell,
    a: &Assets,
    cache: &Cache,
    records: &mut Vec<StageRecord>,
) -> Result<CellResult> {
    let spec = &cell.spec;
    let k = keys(spec, a)?;
    let mut record = recorder(&cell.name, records);
    let source = FaceSource::of_spec(spec);

    // Dataset (and the basis it starts from): the clean faces, then the detector's noise.
    let t = Instant::now();
    let read = |e: &Entry| -> Result<Vec<Sample>> {
        let text = String::from_utf8(e.read("dataset.csv")?)?;
        dataset::from_csv(&text, &e.path("dataset.csv").display().to_string())
    };
    let cached = cache.get("dataset", &k.dataset)?;
    let samples: Vec<Sample> = if let Some(e) = cached {
        let s = read(&e)?;
        record("dataset", &k.dataset, true, t);
        s
    } else {
        let clean_key = k.clean_dataset.as_ref().unwrap_or(&k.dataset);
        let clean = match cache.get("dataset", clean_key)? {
            Some(e) => {
                let s = read(&e)?;
                record("dataset", clean_key, true, t);
                s
            }
            None => {
                let model = source.model()?;
                let reader = FaceReader::new(spec.observer_source)?;
                let observer = reader.observer(&model, spec_calibration(spec)?)?;
                let basis = load_basis(&k, cache, &model, spec, &mut record)?;
                let total = spec.dataset.pairs_per_expression * 6;
                let progress = bar(total as u64, "dataset");
                let tick = || progress.inc(1);
                let s = dataset::generate(
                    &model,
                    &source.weights()?,
                    &reader,
                    &observer,
                    basis.as_ref(),
                    &a.facs.au_controls,
                    &spec.dataset,
                    spec.dataset.seed,
                    &tick,
                )?;
                progress.finish_and_clear();
                cache.put(
                    "dataset",
                    clean_key,
                    &[("dataset.csv".into(), dataset::to_csv(&s).into_bytes())],
                )?;
                record("dataset", clean_key, false, t);
                s
            }
        };
        if k.clean_dataset.is_some() {
            let t = Instant::now();
            let noisy = dataset::add_noise(
                &clean,
                &source.weights()?,
                &a.facs.au_controls,
                &spec.dataset,
                &spec.observer,
                spec.dataset.seed,
            );
            cache.put(
                "dataset",
                &k.dataset,
                &[("dataset.csv".into(), dataset::to_csv(&noisy).into_bytes())],
            )?;
            record("dataset_noise", &k.dataset, false, t);
            noisy
        } else {
            clean
        }
    };

    // Training: every (seed, network).
    let progress = bar(k.train.len() as u64, "train");
    let mut nets: BTreeMap<(u64, Network), Mlp> = BTreeMap::new();
    let mut curves = Vec::new();
    for ((seed, network), key) in &k.train {
        let t = Instant::now();
        let split = table1::split(&samples, spec.dataset.test_fraction, *seed);
        let entry: Entry = match cache.get("train", key)? {
            Some(e) => {
                record("train", key, true, t);
                e
            }
            None => {
                let (train_pairs, test_pairs) =
                    table1::network_pairs(*network, &samples, &split, &a.facs);
                let mut rng = stream(*seed, &format!("train/{}", network.name()));
                let mut uniform = || rng.uniform();
                let (mlp, c) = learn::train(
                    &train_pairs,
                    &test_pairs,
                    &spec.model,
                    &spec.train,
                    &mut uniform,
                )
                .with_context(|| format!("training the {} network, seed {seed}", network.name()))?;
                let e = cache.put(
                    "train",
                    key,
                    &[
                        ("weights.safetensors".into(), mlp.to_safetensors()?),
                        ("curves.csv".into(), curves_csv(&c).into_bytes()),
                    ],
                )?;
                record("train", key, false, t);
                e
            }
        };
        nets.insert(
            (*seed, *network),
            Mlp::from_safetensors(&entry.read("weights.safetensors")?)?,
        );
        curves.push((
            (*seed, *network),
            curves_from(&String::from_utf8(entry.read("curves.csv")?)?),
        ));
        progress.inc(1);
    }
    progress.finish_and_clear();

    let wants_table2 = spec.tables.iter().any(|t| t == "table2");
    let calibration = spec_calibration(spec)?;
    let mut inversion_out = None;
    let table2 = if wants_table2 {
        let model = source.model()?;
        let basis = load_basis(&k, cache, &model, spec, &mut record)?;
        let unified = k
            .train
            .iter()
            .filter(|((_, n), _)| *n == Network::Unified)
            .map(|((seed, n), key)| (*seed, key.clone(), &nets[&(*seed, *n)]))
            .collect();
        let inputs = table2_stage::Inputs {
            spec,
            source: &source,
            assets: format!("face={}\ndata={}\n", a.face, a.data(spec)?),
            dataset_key: &k.dataset,
            basis_key: k.basis.as_deref(),
            unified,
            samples: &samples,
            model: &model,
            basis: basis.as_ref(),
            calibration: &calibration,
        };
        let t2 = table2_stage::run(&inputs, cache, &mut record, &bar)?;
        if spec.tables.iter().any(|t| t == "inversion") {
            let basis = basis.as_ref().expect("inversion always has a basis key");
            let inverter = inversion::Inverter::new(&model, basis, &calibration)?;
            let (seed, train_key, mlp) = &inputs.unified[0];
            let mut keys = vec![
                t2.cohort_key.as_str(),
                train_key.as_str(),
                k.dataset.as_str(),
            ];
            keys.extend(k.basis.as_deref());
            let training: Vec<_> = samples.iter().map(|s| s.aus).collect();
            inversion_out = Some(
                inversion::stage(
                    spec,
                    &source,
                    cache,
                    &mut record,
                    &bar,
                    &keys,
                    &inverter,
                    &calibration,
                    &t2.reference,
                    mlp,
                    &training,
                )
                .with_context(|| format!("the inversion table (network of seed {seed})"))?,
            );
        }
        Some(t2)
    } else {
        None
    };
    // Real OpenFace files through every seed's unified network: the real-data table's files,
    // and the committed file Table 2 reports beside its cohorts.
    let mut real_rows = |files: &[realfaces::RealInput]| -> Result<Vec<realfaces::FileRow>> {
        let model = source.model()?;
        let basis = load_basis(&k, cache, &model, spec, &mut record)?;
        let reader = FaceReader::new(spec.observer_source)?;
        let observer = reader.observer(&model, calibration.clone())?;
        let training: Vec<_> = samples.iter().map(|s| s.aus).collect();
        let inputs = realfaces::Inputs {
            spec,
            files,
            dataset_key: &k.dataset,
            basis_key: k.basis.as_deref(),
            unified: k
                .train
                .iter()
                .filter(|((_, n), _)| *n == Network::Unified)
                .map(|((seed, n), key)| (*seed, key.clone(), &nets[&(*seed, *n)]))
                .collect(),
            training_aus: &training,
            model: &model,
            basis: basis.as_ref(),
            reader: &reader,
            observer: &observer,
        };
        realfaces::run(&inputs, cache, &mut record, &bar)
    };
    let table2_real = match (&table2, &spec.table2_openface) {
        (Some(_), Some(file)) => Some(
            real_rows(&[realfaces::committed_input(file)])
                .with_context(|| format!("Table 2's real file {file}"))?,
        ),
        _ => None,
    };
    let realfaces_rows = if spec.tables.iter().any(|t| t == "realfaces") {
        Some(real_rows(&realfaces::inputs(&spec.realfaces)?)?)
    } else {
        None
    };
    let unified = nets[&(spec.seeds[0], Network::Unified)].to_safetensors()?;
    let mut rows = Vec::new();
    for &seed in &spec.seeds {
        let split = table1::split(&samples, spec.dataset.test_fraction, seed);
        let seed_nets: Vec<Mlp> = Network::all()
            .into_iter()
            .map(|n| nets.remove(&(seed, n)).expect("trained above"))
            .collect();
        rows.push(table1::evaluate(
            seed, &seed_nets, &samples, &split, &a.facs,
        )?);
    }
    Ok(CellResult {
        rows,
        table2,
        inversion: inversion_out,
        realfaces: realfaces_rows,
        table2_real,
        unified,
        training_aus: training_aus_csv(&samples),
        curves,
        samples: samples.len(),
    })
}

/// Per AU: min, max, mean and SD over all training pairs (what Table 2 normalizes onto).
fn training_aus_csv(samples: &[Sample]) -> String {
    let mut out = String::from("au,min,max,mean,sd\n");
    let n = samples.len().max(1) as f64;
    for (k, name) in AU_NAMES.iter().enumerate() {
        let v: Vec<f64> = samples.iter().map(|s| s.aus[k]).collect();
        let mean = v.iter().sum::<f64>() / n;
        let sd = (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n).sqrt();
        let lo = v.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        out.push_str(&format!("{name},{lo},{hi},{mean},{sd}\n"));
    }
    out
}

fn fmt(v: f64) -> String {
    format!("{v:.6e}")
}

/// `seed,joy,...,disgust,all,unified_joy,...` rows, then `mean` and `ci95`.
fn table1_csv(rows: &[Row]) -> String {
    let names: Vec<String> = table1::ORDER.iter().map(|e| e.to_string()).collect();
    let mut out = format!(
        "seed,{},all,{}\n",
        names.join(","),
        names
            .iter()
            .map(|n| format!("unified_{n}"))
            .collect::<Vec<_>>()
            .join(",")
    );
    let line = |label: String, v: &[f64]| {
        format!(
            "{label},{}\n",
            v.iter().map(|x| fmt(*x)).collect::<Vec<_>>().join(",")
        )
    };
    let flat: Vec<Vec<f64>> = rows
        .iter()
        .map(|r| {
            r.per_expression
                .iter()
                .chain(std::iter::once(&r.all))
                .chain(&r.unified_restricted)
                .copied()
                .collect()
        })
        .collect();
    for (r, v) in rows.iter().zip(&flat) {
        out.push_str(&line(r.seed.to_string(), v));
    }
    let column = |j: usize| flat.iter().map(|v| v[j]).collect::<Vec<_>>();
    let means: Vec<f64> = (0..13).map(|j| stats::mean(&column(j))).collect();
    let cis: Vec<f64> = (0..13).map(|j| stats::ci95(&column(j))).collect();
    out.push_str(&line("mean".into(), &means));
    out.push_str(&line("ci95".into(), &cis));
    out
}

fn summary(rows: &[Row]) -> (Vec<f64>, Vec<f64>, Vec<f64>, Vec<f64>) {
    let col = |f: &dyn Fn(&Row) -> f64| rows.iter().map(f).collect::<Vec<_>>();
    let mut mean = Vec::new();
    let mut ci = Vec::new();
    let mut umean = Vec::new();
    let mut uci = Vec::new();
    for k in 0..6 {
        let v = col(&|r| r.per_expression[k]);
        mean.push(stats::mean(&v));
        ci.push(stats::ci95(&v));
        let u = col(&|r| r.unified_restricted[k]);
        umean.push(stats::mean(&u));
        uci.push(stats::ci95(&u));
    }
    let all = col(&|r| r.all);
    mean.push(stats::mean(&all));
    ci.push(stats::ci95(&all));
    (mean, ci, umean, uci)
}

fn paired_cell((m, c, excludes_zero): (f64, f64, bool), dagger: &str) -> String {
    format!(
        "{m:+.1e} ± {c:.1e}{}",
        if excludes_zero { dagger } else { "" }
    )
}

fn table1_markdown(rows: &[Row], spec: &Spec, samples: usize) -> String {
    let (mean, ci, umean, uci) = summary(rows);
    let heads: Vec<String> = table1::ORDER
        .iter()
        .map(|e| format!("MSE_{}", capitalize(e.name())))
        .chain(std::iter::once("MSE_All".into()))
        .collect();
    let mut out =
        String::from("# Table 1: per-expression networks vs one unified network (test MSE)\n\n");
    out.push_str(&format!(
        "facelab: {} seeds ({}), {} pairs ({} per expression, {:.0}% held out), network {} x {} ReLU, Adam lr {}, batch {}, {} epochs, normalization {}. Mean ± 95% interval over seeds.\n\n",
        rows.len(),
        spec.seeds.iter().map(|s| s.to_string()).collect::<Vec<_>>().join(", "),
        samples,
        spec.dataset.pairs_per_expression,
        spec.dataset.test_fraction * 100.0,
        spec.model.layers,
        spec.model.width,
        spec.train.learning_rate,
        spec.train.batch_size,
        spec.train.epochs,
        spec.train.normalization.name(),
    ));
    out.push_str(&format!("| | {} |\n", heads.join(" | ")));
    out.push_str(&format!("|---|{}\n", "---|".repeat(7)));
    out.push_str(&format!(
        "| Zeng et al. | {} |\n",
        table1::PAPER
            .iter()
            .map(|v| format!("{v:.6}"))
            .collect::<Vec<_>>()
            .join(" | ")
    ));
    out.push_str(&format!(
        "| facelab | {} |\n",
        mean.iter()
            .zip(&ci)
            .map(|(m, c)| format!("{m:.2e} ± {c:.1e}"))
            .collect::<Vec<_>>()
            .join(" | ")
    ));
    out.push_str(&format!(
        "| facelab / paper | {} |\n",
        mean.iter()
            .zip(&table1::PAPER)
            .map(|(m, p)| format!("{:.2e}", m / p))
            .collect::<Vec<_>>()
            .join(" | ")
    ));
    out.push_str(&format!(
        "| unified network, same pairs and outputs | {} | {:.2e} ± {:.1e} |\n",
        umean
            .iter()
            .zip(&uci)
            .map(|(m, c)| format!("{m:.2e} ± {c:.1e}"))
            .collect::<Vec<_>>()
            .join(" | "),
        mean[6],
        ci[6]
    ));
    out.push_str(&format!(
        "| per-expression - unified, paired over seeds | {} | |\n",
        table1::paired(rows)
            .into_iter()
            .map(|p| paired_cell(p, " †"))
            .collect::<Vec<_>>()
            .join(" | ")
    ));
    out.push_str(
        "\nThe unified row scores the unified network on each expression's test pairs and only that expression's network outputs, the like-for-like comparison with the facelab row. The paired row is, per seed, the per-expression network's MSE minus the unified network's on those pairs, as mean ± 95% interval over seeds; † marks an interval that excludes 0 (negative: the per-expression network is better, positive: the unified one). The seeds vary the networks' initialization and batch order only; the dataset is the same for every seed.\n",
    );
    out
}

fn table1_tex(rows: &[Row]) -> String {
    let (mean, ci, umean, uci) = summary(rows);
    let mut out = String::from(
        "\\begin{tabular}{lrrrrrrr}\n\\hline\n & Joy & Sadness & Fear & Anger & Surprise & Disgust & All \\\\\n\\hline\n",
    );
    out.push_str(&format!(
        "Zeng et al. & {} \\\\\n",
        table1::PAPER
            .iter()
            .map(|v| format!("{v:.6}"))
            .collect::<Vec<_>>()
            .join(" & ")
    ));
    out.push_str(&format!(
        "facelab & {} \\\\\n",
        mean.iter()
            .zip(&ci)
            .map(|(m, c)| format!("{m:.2e} $\\pm$ {c:.1e}"))
            .collect::<Vec<_>>()
            .join(" & ")
    ));
    out.push_str(&format!(
        "unified, same outputs & {} & \\\\\n",
        umean
            .iter()
            .zip(&uci)
            .map(|(m, c)| format!("{m:.2e} $\\pm$ {c:.1e}"))
            .collect::<Vec<_>>()
            .join(" & ")
    ));
    out.push_str(&format!(
        "per-expression $-$ unified (paired) & {} & \\\\\n",
        table1::paired(rows)
            .into_iter()
            .map(|p| paired_cell(p, "$^\\dagger$").replace('±', "$\\pm$"))
            .collect::<Vec<_>>()
            .join(" & ")
    ));
    out.push_str("\\hline\n\\end{tabular}\n");
    out
}

fn capitalize(s: &str) -> String {
    let mut c = s.chars();
    c.next()
        .map(|f| f.to_uppercase().collect::<String>() + c.as_str())
        .unwrap_or_default()
}

fn sanitize(name: &str) -> String {
    name.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || "-_.=".contains(c) {
                c
            } else {
                '_'
            }
        })
        .collect()
}

fn git(args: &[&str]) -> Option<String> {
    let out = std::process::Command::new("git").args(args).output().ok()?;
    out.status
        .success()
        .then(|| String::from_utf8_lossy(&out.stdout).trim().to_string())
}

/// Whether the checkout differs from its commit, outputs aside: what runs write (`outputs`,
/// where they lie inside the checkout) is not a change to what produced them, so a run after
/// another in the same checkout still counts as clean.
fn checkout_dirty(outputs: &[PathBuf]) -> Option<bool> {
    let top = PathBuf::from(git(&["rev-parse", "--show-toplevel"])?);
    let mut args: Vec<String> = ["status", "--porcelain", "--", ":/"]
        .map(String::from)
        .into();
    for path in outputs {
        let Ok(abs) = std::path::absolute(path) else {
            continue;
        };
        if let Ok(rel) = abs.strip_prefix(&top) {
            if !rel.as_os_str().is_empty() {
                args.push(format!(":(top,exclude){}", rel.display()));
            }
        }
    }
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    git(&args).map(|s| !s.is_empty())
}

/// A new run folder, `run-NNNN.partial` until `finish_run_dir` names it `run-NNNN`: a run that
/// fails or is killed leaves no folder that looks finished. Concurrent runs each get their own
/// number.
fn new_run_dir(experiment_dir: &Path) -> Result<PathBuf> {
    std::fs::create_dir_all(experiment_dir)
        .with_context(|| format!("{}: cannot create", experiment_dir.display()))?;
    let mut n = std::fs::read_dir(experiment_dir)?
        .filter_map(|e| e.ok())
        .filter_map(|e| {
            let name = e.file_name();
            let name = name.to_str()?.strip_prefix("run-")?;
            name.strip_suffix(PARTIAL)
                .unwrap_or(name)
                .parse::<u32>()
                .ok()
        })
        .max()
        .unwrap_or(0);
    loop {
        n += 1;
        if experiment_dir.join(format!("run-{n:04}")).exists() {
            continue;
        }
        let dir = experiment_dir.join(format!("run-{n:04}{PARTIAL}"));
        match std::fs::create_dir(&dir) {
            Ok(()) => return Ok(dir),
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => continue,
            Err(e) => return Err(e).with_context(|| format!("{}: cannot create", dir.display())),
        }
    }
}

/// Suffix of a run folder whose run has not finished.
const PARTIAL: &str = ".partial";

/// Renames a finished run's folder to `run-NNNN` and returns the new path.
fn finish_run_dir(partial: &Path) -> Result<PathBuf> {
    let name = partial
        .file_name()
        .and_then(|n| n.to_str())
        .and_then(|n| n.strip_suffix(PARTIAL))
        .context("a partial run folder's name ends in .partial")?;
    let done = partial.with_file_name(name);
    std::fs::rename(partial, &done)
        .with_context(|| format!("{}: cannot rename to {name}", partial.display()))?;
    Ok(done)
}

fn point_latest(experiment_dir: &Path, run: &Path) -> Result<()> {
    let name = run.file_name().context("run folder has a name")?;
    let tmp = experiment_dir.join(format!(".latest-{}", std::process::id()));
    let _ = std::fs::remove_file(&tmp);
    #[cfg(unix)]
    std::os::unix::fs::symlink(name, &tmp)?;
    #[cfg(not(unix))]
    std::fs::write(&tmp, name.to_string_lossy().as_bytes())?;
    std::fs::rename(&tmp, experiment_dir.join("latest"))?;
    Ok(())
}

/// Writes `paper-tables/<report prefix><name>`.
fn paper_table(out_root: &Path, spec: &Spec, name: &str, text: &str) -> Result<()> {
    let path = out_root
        .join("paper-tables")
        .join(format!("{}{name}", spec.report_prefix));
    write_atomic(&path, text.as_bytes())
        .with_context(|| format!("{}: cannot write", path.display()))
}

/// The head-neck experiment of one cell: CSVs into the run folder (through `write`), the
/// paper table and figures when the spec is a single cell.
fn headpose_outputs(
    cell: &Cell,
    prefix: &str,
    single: bool,
    out_root: &Path,
    cache: &Cache,
    records: &mut Vec<StageRecord>,
    write: &mut dyn FnMut(String, Vec<u8>) -> Result<()>,
) -> Result<Vec<u8>> {
    let spec = &cell.spec;
    let mut record = recorder(&cell.name, records);
    let out = headpose::stage(spec, cache, &mut record, &bar)?;
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
        write_atomic(
            &out_root
                .join("paper-tables")
                .join(format!("{report}headpose.md")),
            headpose::markdown(&out, spec).as_bytes(),
        )?;
        let source = FaceSource::of_spec(spec);
        let figures = out_root.join("figures").join(format!("{report}headpose"));
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
            realfaces::inputs(&cell.spec.realfaces)
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
    let run_dir = new_run_dir(&experiment_dir)?;
    let mut records = Vec::new();
    let mut outputs: BTreeMap<String, String> = BTreeMap::new();
    let write =
        |rel: String, bytes: Vec<u8>, outputs: &mut BTreeMap<String, String>| -> Result<()> {
            let path = run_dir.join(&rel);
            write_atomic(&path, &bytes)
                .with_context(|| format!("{}: cannot write", path.display()))?;
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
            spec::to_toml(&cell.spec.values).into_bytes(),
            &mut outputs,
        )?;
        let mut voluntary = None;
        if cell.spec.tables.iter().any(|t| t == "headpose") {
            voluntary = Some(headpose_outputs(
                cell,
                &prefix,
                cells.len() == 1,
                &out_root,
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
        let mut curves = String::from("seed,network,epoch,train_mse,test_mse\n");
        for ((seed, network), c) in &result.curves {
            for (i, (tr, te)) in c.train.iter().zip(&c.test).enumerate() {
                curves.push_str(&format!("{seed},{},{},{tr},{te}\n", network.name(), i + 1));
            }
        }
        write(
            format!("{prefix}curves.csv"),
            curves.into_bytes(),
            &mut outputs,
        )?;
        if cells.len() == 1 {
            // A spec that trains only for its own table (e.g. the real-data table) keeps its
            // Table 1 in the run folder.
            if cell.spec.tables.iter().any(|t| t == "table1") {
                let report = &cell.spec.report_prefix;
                let tables = out_root.join("paper-tables");
                let md = table1_markdown(&result.rows, &cell.spec, result.samples);
                write_atomic(&tables.join(format!("{report}table1.md")), md.as_bytes())?;
                write_atomic(
                    &tables.join(format!("{report}table1.tex")),
                    table1_tex(&result.rows).as_bytes(),
                )?;
                let figures = out_root.join("figures").join(format!("{report}table1"));
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
            write(
                format!("{prefix}inversion_timing.csv"),
                iv.timing.clone().into_bytes(),
                &mut outputs,
            )?;
            if cells.len() == 1 {
                paper_table(&out_root, &cell.spec, "inversion.md", &iv.markdown)?;
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
                let tables = out_root.join("paper-tables");
                write_atomic(
                    &tables.join(format!("{report}table2.md")),
                    table2_stage::markdown(&t2.rows, &cell.spec, &t2.reference, real).as_bytes(),
                )?;
                write_atomic(
                    &tables.join(format!("{report}table2.tex")),
                    table2_stage::tex(&t2.rows, real).as_bytes(),
                )?;
                let figures = out_root.join("figures").join(format!("{report}table2"));
                for (name, bytes) in &t2.renders {
                    write_atomic(&figures.join(name), bytes)?;
                }
                table2_stage::bars(&figures.join("au_mse_bars.png"), &t2.rows)?;
            }
            // Head pose from the cohorts, where the spec has the head-neck controller.
            if let Some(weights) = &voluntary {
                let mut record = recorder(&cell.name, &mut records);
                let rows = pose_transfer::stage(
                    &cell.spec,
                    &cache,
                    &mut record,
                    &bar,
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
                    paper_table(&out_root, &cell.spec, "table2_pose.md", &md)?;
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
                write_atomic(
                    &out_root
                        .join("paper-tables")
                        .join(format!("{}realfaces.md", cell.spec.report_prefix)),
                    realfaces::markdown(rf, &cell.spec).as_bytes(),
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
        write_atomic(
            &out_root
                .join("paper-tables")
                .join(format!("{experiment}.md")),
            md.as_bytes(),
        )?;
        let dir = out_root.join("figures").join(&experiment);
        sweep_figure(&dir, &sweep_rows)?;
        if !sweep_table2.is_empty() {
            let names: Vec<&str> = sweep_table2.iter().map(|(n, _)| n.as_str()).collect();
            table2_stage::sweep_figure(&dir, &sweep_table2, &sweep_labels(&names).1)?;
        }
    }
    let manifest = serde_json::json!({
        "facelab_version": env!("CARGO_PKG_VERSION"),
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
    let run_dir = finish_run_dir(&run_dir)?;
    point_latest(&experiment_dir, &run_dir)?;
    Ok(RunSummary {
        dir: run_dir,
        stages: records,
        outputs,
    })
}

fn table1_figures(dir: &Path, result: &CellResult) -> Result<()> {
    use crate::report::figures::{grouped_bars, log_curves, Series, PALETTE};
    let first_seed = result.curves.first().map(|((s, _), _)| *s).unwrap_or(1);
    let mut series = Vec::new();
    for (i, ((seed, network), c)) in result.curves.iter().enumerate() {
        if *seed != first_seed {
            continue;
        }
        let color = PALETTE[i % PALETTE.len()];
        series.push(Series {
            label: format!("{} test", network.name()),
            values: c.test.clone(),
            color,
            dashed: false,
        });
        if *network == Network::Unified {
            series.push(Series {
                label: "unified train".into(),
                values: c.train.clone(),
                color,
                dashed: true,
            });
        }
    }
    log_curves(
        &dir.join("loss_curves.png"),
        &format!("Training curves (seed {first_seed})"),
        "MSE",
        &series,
    )?;
    let (mean, _, _, _) = summary(&result.rows);
    let cats: Vec<String> = table1::ORDER
        .iter()
        .map(|e| capitalize(e.name()))
        .chain(std::iter::once("All".into()))
        .collect();
    grouped_bars(
        &dir.join("table1_bars.png"),
        "Table 1: test MSE",
        "MSE",
        &cats,
        &[
            ("Zeng et al.".into(), PALETTE[5], table1::PAPER.to_vec()),
            ("facelab (mean over seeds)".into(), PALETTE[1], mean),
        ],
    )
}

/// Bars of MSE_All and the mean per-expression MSE for each cell, labelled by its values.
/// A sweep's swept keys (`a / b`) and each cell's values (`1/2`), from cell names `a=1,b=2`.
fn sweep_labels(names: &[&str]) -> (String, Vec<String>) {
    let part = |name: &str, value: bool| -> String {
        name.split(',')
            .map(|kv| {
                kv.split_once('=')
                    .map_or(kv, |(k, v)| if value { v } else { k })
                    .to_string()
            })
            .collect::<Vec<_>>()
            .join(if value { "/" } else { " / " })
    };
    let keys = names.first().map(|n| part(n, false)).unwrap_or_default();
    (keys, names.iter().map(|n| part(n, true)).collect())
}

fn sweep_figure(dir: &Path, rows: &[(String, Vec<Row>)]) -> Result<()> {
    use crate::report::figures::{grouped_bars, PALETTE};
    let names: Vec<&str> = rows.iter().map(|(n, _)| n.as_str()).collect();
    let (keys, labels) = sweep_labels(&names);
    let all: Vec<f64> = rows
        .iter()
        .map(|(_, r)| stats::mean(&r.iter().map(|x| x.all).collect::<Vec<_>>()))
        .collect();
    let per: Vec<f64> = rows
        .iter()
        .map(|(_, r)| {
            stats::mean(
                &r.iter()
                    .map(|x| stats::mean(&x.per_expression))
                    .collect::<Vec<_>>(),
            )
        })
        .collect();
    grouped_bars(
        &dir.join("sweep.png"),
        &format!("Test MSE by {keys}"),
        "MSE (mean over seeds)",
        &labels,
        &[
            ("unified, MSE_All".into(), PALETTE[0], all),
            ("per-expression networks, mean".into(), PALETTE[1], per),
        ],
    )
}

fn sweep_csv(rows: &[(String, Vec<Row>)]) -> String {
    let mut out = String::from("cell,mse_all_mean,mse_all_ci95,mse_per_expression_mean\n");
    for (name, r) in rows {
        let all: Vec<f64> = r.iter().map(|x| x.all).collect();
        let per: Vec<f64> = r.iter().map(|x| stats::mean(&x.per_expression)).collect();
        out.push_str(&format!(
            "\"{name}\",{},{},{}\n",
            fmt(stats::mean(&all)),
            fmt(stats::ci95(&all)),
            fmt(stats::mean(&per))
        ));
    }
    out
}

fn sweep_markdown(experiment: &str, rows: &[(String, Vec<Row>)]) -> String {
    let mut out = format!(
        "# {experiment}: Table 1 over a sweep\n\n| cell | MSE_All (unified) | mean of per-expression MSEs |\n|---|---|---|\n"
    );
    for (name, r) in rows {
        let all: Vec<f64> = r.iter().map(|x| x.all).collect();
        let per: Vec<f64> = r.iter().map(|x| stats::mean(&x.per_expression)).collect();
        out.push_str(&format!(
            "| {name} | {:.2e} ± {:.1e} | {:.2e} ± {:.1e} |\n",
            stats::mean(&all),
            stats::ci95(&all),
            stats::mean(&per),
            stats::ci95(&per)
        ));
    }
    out
}

/// `facelab status`: which stages of each cell are cached.
pub fn status(
    spec_path: &Path,
    sets: &[String],
    results: &Path,
) -> Result<Vec<(String, String, bool)>> {
    let cells = spec::load(spec_path, sets)?;
    let a = assets()?;
    let cache = Cache::new(&results.join(".cache"));
    let mut out = Vec::new();
    for cell in &cells {
        let k = keys(&cell.spec, &a)?;
        let label = |s: &str| {
            if cell.name.is_empty() {
                s.to_string()
            } else {
                format!("{} [{}]", s, cell.name)
            }
        };
        if let Some(b) = &k.basis {
            out.push((label("basis"), b.clone(), cache.has("basis", b)));
        }
        out.push((
            label("dataset"),
            k.dataset.clone(),
            cache.has("dataset", &k.dataset),
        ));
        for ((seed, network), key) in &k.train {
            out.push((
                label(&format!("train {} seed {seed}", network.name())),
                key.clone(),
                cache.has("train", key),
            ));
        }
    }
    Ok(out)
}

/// `facelab verify`: reruns a run's resolved specs from scratch in a temporary folder and
/// compares the hashes of every CSV. Returns the files that differ.
pub fn verify(run_dir: &Path, threads: usize) -> Result<Vec<String>> {
    let manifest: serde_json::Value = serde_json::from_slice(
        &std::fs::read(run_dir.join("manifest.json"))
            .with_context(|| format!("{}: no manifest.json", run_dir.display()))?,
    )?;
    let outputs = manifest["outputs"]
        .as_object()
        .context("manifest has no outputs")?;
    let spec_file = PathBuf::from(manifest["spec"].as_str().context("manifest has no spec")?);
    let sets: Vec<String> = manifest["sets"]
        .as_array()
        .map(|a| {
            a.iter()
                .filter_map(|s| s.as_str().map(String::from))
                .collect()
        })
        .unwrap_or_default();
    let tmp = std::env::temp_dir().join(format!("facelab-verify-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&tmp);
    let summary = run(
        &spec_file,
        &RunOptions {
            results: tmp.join("results"),
            sets,
            threads,
        },
    )?;
    let mut differ = Vec::new();
    for (name, hash) in outputs {
        // Timings are measurements of this machine, not results.
        if !name.ends_with(".csv") || name.ends_with("_timing.csv") {
            continue;
        }
        if summary.outputs.get(name).map(String::as_str) != hash.as_str() {
            differ.push(name.clone());
        }
    }
    let _ = std::fs::remove_dir_all(&tmp);
    Ok(differ)
}
