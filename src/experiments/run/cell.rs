//! One sweep cell of a run: the basis, dataset and training stages through the cache, and
//! the evaluation of Table 1 and Table 2 on what they made.

use crate::cache::{Cache, Entry};
use crate::dataset::reader::FaceReader;
use crate::dataset::{self, Sample};
use crate::experiments::face::FaceSource;
use crate::experiments::inversion;
use crate::experiments::realfaces;
use crate::experiments::table1::{self, Network, Row};
use crate::experiments::table2_stage::{self, Table2Result};
use crate::learn::{self, Curves, Mlp};
use crate::observe::AU_NAMES;
use crate::rng::stream;
use crate::sim::basis::LinearBasis;
use crate::sim::geom::V3;
use crate::sim::{FaceModel, SolveParams};
use crate::spec::{Cell, Spec};
use anyhow::{bail, Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use std::collections::BTreeMap;
use std::time::Instant;

use super::*;

pub(super) fn bar(len: u64, message: &str) -> ProgressBar {
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

pub(super) fn basis_bytes(b: &LinearBasis) -> Vec<u8> {
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

pub(super) fn basis_from(bytes: &[u8]) -> Result<LinearBasis> {
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

pub(crate) fn curves_csv(curves: &Curves) -> String {
    let mut out = String::from("epoch,train_mse,test_mse\n");
    for (i, (a, b)) in curves.train.iter().zip(&curves.test).enumerate() {
        out.push_str(&format!("{},{a},{b}\n", i + 1));
    }
    out
}

pub(crate) fn curves_from(text: &str) -> Curves {
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
pub(super) struct CellResult {
    pub(super) rows: Vec<Row>,
    pub(super) table2: Option<Table2Result>,
    pub(super) inversion: Option<inversion::Output>,
    pub(super) realfaces: Option<Vec<realfaces::FileRow>>,
    /// Table 2's committed real file (`table2.openface`) through each seed's network.
    pub(super) table2_real: Option<Vec<realfaces::FileRow>>,
    /// The first seed's unified network (safetensors) and the training AUs' per-AU
    /// statistics, for `facelab transfer --model`.
    pub(super) unified: Vec<u8>,
    pub(super) training_aus: String,
    /// (seed, network) -> curves.
    pub(super) curves: Vec<((u64, Network), Curves)>,
    pub(super) samples: usize,
}

/// The linear basis of the cell's face (cached), when the spec solves from predictions.
pub(super) fn load_basis(
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
pub(super) fn recorder<'a>(
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

pub(super) fn run_cell(
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
    let mut real_rows =
        |files: &[crate::io::realdata::RealInput]| -> Result<Vec<realfaces::FileRow>> {
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
            real_rows(&[crate::io::realdata::committed_input(file)])
                .with_context(|| format!("Table 2's real file {file}"))?,
        ),
        _ => None,
    };
    let realfaces_rows = if spec.tables.iter().any(|t| t == "realfaces") {
        Some(real_rows(&crate::io::realdata::inputs(&spec.realfaces)?)?)
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
pub(super) fn training_aus_csv(samples: &[Sample]) -> String {
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
