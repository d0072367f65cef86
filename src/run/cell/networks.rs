//! The networks of a cell, which every table but the head-neck experiment reads: the dataset
//! and the training stages through the cache (the data set's starts in `starts`), and each
//! seed's held-out test (Table 1's rows, the record every training run writes). Which
//! networks there are (Zeng et al.'s six per-expression networks and the unified one), their
//! pairs and the split are defined here, below every experiment that reads them.

use crate::cache::Entry;
use crate::dataset::reader::FaceReader;
use crate::dataset::SolveStart;
use crate::dataset::{self, Sample, Starts};
use crate::io::facs::FacsMaps;
use crate::io::rows::{self, num, CsvRow};
use crate::learn::{self, Curves, Mlp, Pairs};
use crate::observe::AU_COUNT;
use crate::rng::stream;
use crate::run::stage::{text, Artifact, Stages, Unit};
use crate::sim::controls::CONTROL_COUNT;
use crate::sim::expression::Expression;
use crate::spec::Spec;
use anyhow::Result;
use std::collections::BTreeMap;

use super::keys::{spec_calibration, Assets, Keys};
use super::starts::{load_basis, load_grid};
use super::{DATASET_VERSION, TRAIN_VERSION};

/// What one network's training depends on (besides the dataset's key).
#[derive(serde::Serialize)]
struct TrainInputs<'a> {
    facs: &'a str,
    seed: u64,
    network: String,
    model: &'a learn::ModelParams,
    train: &'a learn::TrainParams,
    test_fraction: f64,
}

/// Each (seed, network)'s training key, in seed then `Network::all()` order: the FACS tables'
/// hash, the network, the model and training settings and the split, over the dataset's key.
pub(crate) fn train_keys(spec: &Spec, facs: &str, dataset: &str) -> Vec<((u64, Network), String)> {
    let mut train = Vec::new();
    for &seed in &spec.seeds {
        for network in Network::all() {
            let inputs = TrainInputs {
                facs,
                seed,
                network: network.name(),
                model: &spec.model,
                train: &spec.train,
                test_fraction: spec.dataset.test_fraction,
            };
            let unit = Unit::new("train", TRAIN_VERSION, &inputs, &[dataset]);
            train.push(((seed, network), unit.key));
        }
    }
    train
}

/// A line of a training's `curves.csv`: the epoch (from 1) and its train and test MSE.
#[derive(serde::Serialize, serde::Deserialize)]
pub(crate) struct CurveLine {
    pub(crate) epoch: usize,
    #[serde(serialize_with = "num::shortest")]
    pub(crate) train_mse: f64,
    #[serde(serialize_with = "num::shortest")]
    pub(crate) test_mse: f64,
}

impl CsvRow for CurveLine {}

pub(crate) fn curves_csv(curves: &Curves) -> String {
    let lines: Vec<CurveLine> = curves
        .train
        .iter()
        .zip(&curves.test)
        .enumerate()
        .map(|(i, (&train_mse, &test_mse))| CurveLine {
            epoch: i + 1,
            train_mse,
            test_mse,
        })
        .collect();
    rows::to_csv(&lines)
}

pub(crate) fn curves_from(text: &str, name: &str) -> Result<Curves> {
    let mut c = Curves::default();
    for l in rows::from_csv::<CurveLine>(text, name)? {
        c.train.push(l.train_mse);
        c.test.push(l.test_mse);
    }
    Ok(c)
}

/// Samples per cached chunk of the dataset stage (250: 24 chunks of the paper's 6,000).
const DATASET_CHUNK: usize = 250;

/// The training pairs as `dataset.csv`.
struct Samples(Vec<Sample>);

impl Artifact for Samples {
    fn encode(&self) -> Result<Vec<(String, Vec<u8>)>> {
        Ok(vec![(
            "dataset.csv".into(),
            dataset::to_csv(&self.0).into_bytes(),
        )])
    }
    fn decode(entry: &Entry) -> Result<Self> {
        let path = entry.path("dataset.csv").display().to_string();
        Ok(Samples(dataset::from_csv(
            &text(entry, "dataset.csv")?,
            &path,
        )?))
    }
}

/// A trained network and its learning curves.
pub(crate) struct Trained {
    pub(crate) mlp: Mlp,
    pub(crate) curves: Curves,
}

impl Artifact for Trained {
    fn encode(&self) -> Result<Vec<(String, Vec<u8>)>> {
        Ok(vec![
            ("weights.safetensors".into(), self.mlp.to_safetensors()?),
            ("curves.csv".into(), curves_csv(&self.curves).into_bytes()),
        ])
    }
    fn decode(entry: &Entry) -> Result<Self> {
        Ok(Trained {
            mlp: Mlp::from_safetensors(&entry.read("weights.safetensors")?)?,
            curves: curves_from(
                &text(entry, "curves.csv")?,
                &entry.path("curves.csv").display().to_string(),
            )?,
        })
    }
}

/// A cell's data set and trained networks, and each seed's Table 1 row.
pub(crate) struct Networks {
    pub(crate) samples: Vec<Sample>,
    /// (seed, network) -> the trained network.
    pub(crate) nets: BTreeMap<(u64, Network), Mlp>,
    /// (seed, network) -> curves, in seed then `Network::all()` order.
    pub(crate) curves: Vec<((u64, Network), Curves)>,
    /// Table 1's row of each seed: every network on its held-out test pairs.
    pub(crate) rows: Vec<Row>,
}

impl Networks {
    /// Every seed's unified network with its training key, in seed order.
    pub(crate) fn unified<'a>(&'a self, k: &Keys) -> Vec<(u64, String, &'a Mlp)> {
        k.train
            .iter()
            .filter(|((_, n), _)| *n == Network::Unified)
            .map(|((seed, n), key)| (*seed, key.clone(), &self.nets[&(*seed, *n)]))
            .collect()
    }

    /// The AUs of the training pairs (what Table 2 normalizes onto).
    pub(crate) fn training_aus(&self) -> Vec<[f64; crate::observe::AU_COUNT]> {
        self.samples.iter().map(|s| s.aus).collect()
    }
}

/// The data set's faces without the detector's noise, solved in cached chunks.
fn clean_dataset(
    spec: &Spec,
    a: &Assets,
    k: &Keys,
    source: &crate::io::face::FaceSource,
    stages: &mut Stages,
) -> Result<Samples> {
    let clean_key = k.clean_dataset.as_ref().unwrap_or(&k.dataset);
    stages.get_or_compute(&Unit::keyed("dataset", clean_key), |stages| {
        let model = source.model()?;
        let reader = FaceReader::new(spec.observer_source)?;
        let observer = reader.observer(&model, spec_calibration(spec)?)?;
        let basis = match spec.dataset.start {
            SolveStart::Predicted => load_basis(k, stages, &model, spec)?,
            SolveStart::Rest => None,
        };
        let jobs = dataset::jobs(&spec.dataset);
        let weights = source.weights()?;
        let grid = load_grid(k, stages, &model, &weights, spec)?;
        let progress = stages.bar(jobs.len() as u64, "dataset");
        let tick = || progress.inc(1);
        // Cached in chunks, so a killed run loses at most one chunk of solving; every
        // sample has its own stream, so the chunks join to the same bytes.
        let mut samples = Vec::with_capacity(jobs.len());
        let workspaces = dataset::WorkspacePool::default();
        for (i, chunk) in jobs.chunks(DATASET_CHUNK).enumerate() {
            let unit = Unit::new(
                "dataset_chunk",
                DATASET_VERSION,
                &(i, DATASET_CHUNK),
                &[clean_key],
            );
            let before = progress.position();
            let Samples(part) = stages.get_or_compute(&unit, |_| {
                Ok(Samples(dataset::generate(
                    &model,
                    &weights,
                    &reader,
                    &observer,
                    Starts {
                        basis: basis.as_ref(),
                        grid: grid.as_ref(),
                    },
                    &a.facs.au_controls,
                    &spec.dataset,
                    spec.dataset.seed,
                    chunk,
                    &workspaces,
                    &tick,
                )?))
            })?;
            // A cached chunk did not tick.
            let ticked = progress.position() - before;
            progress.inc(part.len() as u64 - ticked);
            samples.extend(part);
        }
        progress.finish_and_clear();
        Ok(Samples(samples))
    })
}

/// The cell's dataset (its clean faces, then the detector's noise, cached apart so that a
/// noise sweep solves the faces once) and every (seed, network) trained on it.
pub(crate) fn networks(spec: &Spec, a: &Assets, k: &Keys, stages: &mut Stages) -> Result<Networks> {
    let source = spec.face_source();
    // Dataset (and the basis it starts from): the clean faces, then the detector's noise,
    // cached apart so that a noise sweep solves the faces once.
    let clean = |stages: &mut Stages| clean_dataset(spec, a, k, &source, stages);
    let Samples(samples) = if k.clean_dataset.is_some() {
        stages.get_or_compute(&Unit::keyed("dataset_noise", &k.dataset), |stages| {
            let Samples(clean) = clean(stages)?;
            Ok(Samples(dataset::add_noise(
                &clean,
                &source.weights()?,
                &a.facs.au_controls,
                &spec.dataset,
                &spec.observer,
                spec.dataset.seed,
            )))
        })?
    } else {
        clean(stages)?
    };

    // Training: every (seed, network).
    // The networks are independent: the missing ones train in parallel, each candle operation
    // on one thread as the command line sets it (a small MLP trains fastest on one thread),
    // with the same bytes as one by one.
    let progress = stages.bar(k.train.len() as u64, "train");
    let units: Vec<Unit> = k
        .train
        .iter()
        .map(|(_, key)| Unit::keyed("train", key))
        .collect();
    // One batched model per network kind: its seeds share every shape and step count, and
    // each network's bytes are its own whatever shares its batch (`learn::batch`).
    let mut groups: Vec<Vec<usize>> = Vec::new();
    for kind in Network::all() {
        let members: Vec<usize> = (0..k.train.len())
            .filter(|&i| k.train[i].0 .1 == kind)
            .collect();
        if !members.is_empty() {
            groups.push(members);
        }
    }
    let trained = stages.get_or_compute_groups(&units, &groups, |members| {
        let sets: Vec<(Pairs, Pairs)> = members
            .iter()
            .map(|&i| {
                let (seed, network) = k.train[i].0;
                let split = split(&samples, spec.dataset.test_fraction, seed);
                network_pairs(network, &samples, &split, &a.facs)
            })
            .collect();
        let mut streams: Vec<_> = members
            .iter()
            .map(|&i| {
                let (seed, network) = k.train[i].0;
                stream(seed, &format!("train/{}", network.name()))
            })
            .collect();
        let mut sources: Vec<_> = streams.iter_mut().map(|r| move || r.uniform()).collect();
        let mut jobs: Vec<learn::Job> = sets
            .iter()
            .zip(sources.iter_mut())
            .map(|((train, test), uniform)| learn::Job {
                train,
                test,
                uniform,
            })
            .collect();
        let trained = learn::train_batch(&mut jobs, &spec.model, &spec.train).map_err(|e| {
            let what = match e.index {
                Some(i) => {
                    let (seed, network) = k.train[members[i]].0;
                    format!("training the {} network, seed {seed}", network.name())
                }
                None => format!("training the {} networks", k.train[members[0]].0 .1.name()),
            };
            anyhow::Error::new(e.error).context(what)
        })?;
        progress.inc(members.len() as u64);
        Ok(trained
            .into_iter()
            .map(|(mlp, curves)| Trained { mlp, curves })
            .collect())
    })?;
    progress.finish_and_clear();
    let mut nets: BTreeMap<(u64, Network), Mlp> = BTreeMap::new();
    let mut curves = Vec::new();
    for (((seed, network), _), t) in k.train.iter().zip(trained) {
        nets.insert((*seed, *network), t.mlp);
        curves.push(((*seed, *network), t.curves));
    }

    let mut rows = Vec::new();
    for &seed in &spec.seeds {
        let split = split(&samples, spec.dataset.test_fraction, seed);
        let seed_nets: Vec<&Mlp> = Network::all().iter().map(|n| &nets[&(seed, *n)]).collect();
        rows.push(evaluate(seed, &seed_nets, &samples, &split, &a.facs)?);
    }
    Ok(Networks {
        samples,
        nets,
        curves,
        rows,
    })
}

/// The paper's column order.
pub const ORDER: [Expression; 6] = [
    Expression::Joy,
    Expression::Sadness,
    Expression::Fear,
    Expression::Anger,
    Expression::Surprise,
    Expression::Disgust,
];

/// Which network.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum Network {
    Unified,
    Expression(Expression),
}

impl Network {
    pub fn all() -> Vec<Network> {
        std::iter::once(Network::Unified)
            .chain(ORDER.iter().map(|&e| Network::Expression(e)))
            .collect()
    }

    pub fn name(self) -> String {
        match self {
            Network::Unified => "unified".into(),
            Network::Expression(e) => e.to_string(),
        }
    }

    /// Input AU indices and output control indices.
    pub fn io(self, facs: &FacsMaps) -> (Vec<usize>, Vec<usize>) {
        match self {
            Network::Unified => ((0..AU_COUNT).collect(), (0..CONTROL_COUNT).collect()),
            Network::Expression(e) => (
                facs.expression_aus[e as usize].clone(),
                facs.expression_controls(e),
            ),
        }
    }
}

/// Per expression (`Expression::ALL` order): sample indices of the train and test splits.
#[derive(Clone, Debug, PartialEq)]
pub struct Split {
    pub train: Vec<Vec<usize>>,
    pub test: Vec<Vec<usize>>,
}

/// Shuffles each expression's samples with `split/<expression>` of `seed` and holds out the
/// last `test_fraction` (at least one pair).
pub fn split(samples: &[Sample], test_fraction: f64, seed: u64) -> Split {
    let mut train = Vec::new();
    let mut test = Vec::new();
    for e in Expression::ALL {
        let mut idx: Vec<usize> = (0..samples.len())
            .filter(|&i| samples[i].expression == e)
            .collect();
        let mut rng = stream(seed, &format!("split/{e}"));
        for i in (1..idx.len()).rev() {
            idx.swap(i, rng.index(i + 1));
        }
        let n_test = ((idx.len() as f64 * test_fraction).round() as usize).clamp(1, idx.len() - 1);
        let cut = idx.len() - n_test;
        test.push(idx[cut..].to_vec());
        train.push(idx[..cut].to_vec());
    }
    Split { train, test }
}

/// Pairs of the chosen samples, AUs `inputs` -> controls `outputs`.
pub fn pairs(samples: &[Sample], idx: &[usize], inputs: &[usize], outputs: &[usize]) -> Pairs {
    let mut p = Pairs {
        inputs: inputs.len(),
        outputs: outputs.len(),
        x: Vec::with_capacity(idx.len() * inputs.len()),
        y: Vec::with_capacity(idx.len() * outputs.len()),
    };
    for &i in idx {
        p.x.extend(inputs.iter().map(|&k| samples[i].aus[k] as f32));
        p.y.extend(outputs.iter().map(|&k| samples[i].activations[k] as f32));
    }
    p
}

/// The train and test pairs of a network.
pub fn network_pairs(
    network: Network,
    samples: &[Sample],
    split: &Split,
    facs: &FacsMaps,
) -> (Pairs, Pairs) {
    let (inputs, outputs) = network.io(facs);
    let pick = |sets: &Vec<Vec<usize>>| -> Vec<usize> {
        match network {
            Network::Unified => sets.iter().flatten().copied().collect(),
            Network::Expression(e) => sets[e as usize].clone(),
        }
    };
    (
        pairs(samples, &pick(&split.train), &inputs, &outputs),
        pairs(samples, &pick(&split.test), &inputs, &outputs),
    )
}

/// One seed's row of Table 1.
#[derive(Clone, Debug, PartialEq)]
pub struct Row {
    pub seed: u64,
    /// Per-expression networks, `ORDER`.
    pub per_expression: [f64; 6],
    /// MSE_All of the unified network.
    pub all: f64,
    /// The unified network on each expression's test pairs and that expression's outputs.
    pub unified_restricted: [f64; 6],
}

/// Evaluates trained networks (`nets` in `Network::all()` order) on the test split.
pub fn evaluate(
    seed: u64,
    nets: &[&Mlp],
    samples: &[Sample],
    split: &Split,
    facs: &FacsMaps,
) -> Result<Row, crate::learn::LearnError> {
    let networks = Network::all();
    let mut per_expression = [0.0; 6];
    let mut unified_restricted = [0.0; 6];
    let unified = &nets[0];
    let (_, all_test) = network_pairs(Network::Unified, samples, split, facs);
    let all = unified.mse(&all_test)?;
    for (k, &e) in ORDER.iter().enumerate() {
        let n = networks
            .iter()
            .position(|&x| x == Network::Expression(e))
            .expect("every expression has a network");
        let (_, test) = network_pairs(networks[n], samples, split, facs);
        per_expression[k] = nets[n].mse(&test)?;
        // Unified predictions on e's test pairs, scored on e's outputs only.
        let (_, outputs) = networks[n].io(facs);
        let full = pairs(
            samples,
            &split.test[e as usize],
            &(0..AU_COUNT).collect::<Vec<_>>(),
            &(0..CONTROL_COUNT).collect::<Vec<_>>(),
        );
        let predicted = unified.predict(&full.x)?;
        let m = full.len();
        let mut sum = 0.0;
        for i in 0..m {
            for &o in &outputs {
                let d = predicted[i * CONTROL_COUNT + o] - full.y[i * CONTROL_COUNT + o];
                sum += (d as f64).powi(2);
            }
        }
        unified_restricted[k] = sum / (m * outputs.len()) as f64;
    }
    Ok(Row {
        seed,
        per_expression,
        all,
        unified_restricted,
    })
}
