//! Table 1 (DESIGN 3, paper 5.2): six per-expression networks against one unified network,
//! by test MSE. Per-expression network e: inputs = e's prototype AUs, outputs = the controls of
//! those AUs (`experiments/expression_aus.csv`, `experiments/au_muscles.csv`), trained and
//! tested on e's pairs only. Unified: 17 AUs -> 56 controls on all pairs; MSE_All over every
//! output of the whole test split, and restricted to each expression's test pairs and outputs
//! so the two can be compared like for like.

use crate::io::facs::FacsMaps;
use crate::learn::{Mlp, Pairs};
use crate::observe::AU_COUNT;
use crate::rng::stream;
use crate::sim::controls::CONTROL_COUNT;
use crate::sim::expression::Expression;
use crate::stats;

use crate::dataset::Sample;

mod report;
pub(crate) use report::{record, sweep_labels, sweep_record, Table1};

/// The paper's column order.
pub const ORDER: [Expression; 6] = [
    Expression::Joy,
    Expression::Sadness,
    Expression::Fear,
    Expression::Anger,
    Expression::Surprise,
    Expression::Disgust,
];

/// Zeng et al. Table 1, in `ORDER`, then MSE_All.
pub const PAPER: [f64; 7] = [
    0.000591, 0.002925, 0.001611, 0.009689, 0.000266, 0.002516, 0.000729,
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

/// Per expression, the paired difference across seeds: each seed's per-expression network's
/// MSE minus its unified network's on the same test pairs and outputs, as mean and 95%
/// interval half-width, and whether the interval excludes zero.
pub fn paired(rows: &[Row]) -> Vec<(f64, f64, bool)> {
    (0..6)
        .map(|k| {
            let d: Vec<f64> = rows
                .iter()
                .map(|r| r.per_expression[k] - r.unified_restricted[k])
                .collect();
            let (m, c) = (stats::mean(&d), stats::ci95(&d));
            (m, c, d.len() > 1 && m.abs() > c)
        })
        .collect()
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paired_difference_is_per_seed_and_says_when_it_excludes_zero() {
        let row = |seed: u64, joy: f64, unified_joy: f64| Row {
            seed,
            per_expression: [joy, 1.0, 1.0, 1.0, 1.0, 1.0],
            all: 0.0,
            unified_restricted: [unified_joy, 1.0, 2.0 + seed as f64, 1.0, 1.0, 1.0],
        };
        // Joy: the per-expression network is 1.0 worse on every seed, a difference the
        // seeds agree on however large the spread of each column.
        let rows = [row(1, 2.0, 1.0), row(2, 11.0, 10.0), row(3, 6.0, 5.0)];
        let p = paired(&rows);
        assert!((p[0].0 - 1.0).abs() < 1e-12 && p[0].1 < 1e-12 && p[0].2);
        // Sadness: no difference, no mark.
        assert_eq!(p[1], (0.0, 0.0, false));
        // Fear: differences -2, -3, -4 (mean -3, interval 2.48).
        assert!((p[2].0 + 3.0).abs() < 1e-12 && p[2].2);
        // One seed: no interval, no claim.
        assert!(!paired(&rows[..1])[0].2);
    }
}
