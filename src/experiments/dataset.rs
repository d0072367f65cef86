//! The dataset stage (DESIGN 3, paper 4.2): for each expression, pairs (AUs, activations)
//! made by the model itself: a = w_e * s with s ~ U[0, 1], jaw rotation ~ U[0, 1], slide and
//! twist neutral; solve; observe.

/// Where each sample's solve starts.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SolveStart {
    /// The linear basis' prediction of the equilibrium (one Newton solve; falls back to
    /// `Rest` if it fails).
    Predicted,
    /// The rest face, by continuation.
    Rest,
}

impl SolveStart {
    pub const NAMES: [&'static str; 2] = ["predicted", "rest"];

    pub fn parse(s: &str) -> Option<SolveStart> {
        match s {
            "predicted" => Some(SolveStart::Predicted),
            "rest" => Some(SolveStart::Rest),
            _ => None,
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            SolveStart::Predicted => "predicted",
            SolveStart::Rest => "rest",
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DatasetParams {
    /// Pairs per expression. Default 1000 (paper 4.2).
    pub pairs_per_expression: usize,
    /// Share of each expression's pairs held out for testing, in (0, 1). Default 0.2.
    pub test_fraction: f64,
    /// Face mesh subdivision levels (0, 1 or 2). Default 0.
    pub subdivisions: u8,
    /// Solver convergence tolerance (relative residual). Default `SolveParams` default.
    pub tolerance: f64,
    /// Shear modulus of the tissue prisms as a fraction of E / 3
    /// (`TissueParams::shear_modulus_fraction`). Default 1.
    pub shear_modulus_fraction: f64,
    pub start: SolveStart,
    /// Seed of the samples' streams; separate from the training seeds so that every seed
    /// trains on the same, once-simulated pairs. Default 1.
    pub seed: u64,
}

impl Default for DatasetParams {
    fn default() -> Self {
        DatasetParams {
            pairs_per_expression: 1000,
            test_fraction: 0.2,
            subdivisions: 0,
            tolerance: crate::sim::SolveParams::default().tolerance,
            shear_modulus_fraction: crate::sim::tissue::TissueParams::default()
                .shear_modulus_fraction,
            start: SolveStart::Predicted,
            seed: 1,
        }
    }
}

use anyhow::{bail, Context, Result};
use rayon::prelude::*;

use crate::observe::{landmarks, Observer, ObserverNoise, AU_COUNT, AU_NAMES};
use crate::rng::stream;
use crate::sim::basis::LinearBasis;
use crate::sim::controls::{control_names, CONTROL_COUNT};
use crate::sim::expression::{Expression, ExpressionWeights};
use crate::sim::solver::solve_predicted;
use crate::sim::{solve_from_rest, FaceModel, SolveParams, Workspace};

/// One training pair.
#[derive(Clone, Debug, PartialEq)]
pub struct Sample {
    pub expression: Expression,
    /// Index within its expression.
    pub index: usize,
    /// The expression scale s.
    pub scale: f64,
    pub aus: [f64; AU_COUNT],
    pub activations: [f64; CONTROL_COUNT],
}

/// Generates `params.pairs_per_expression` pairs per expression. Each sample draws from its
/// own stream (`dataset/<expression>/<index>`), so the result does not depend on how rayon
/// splits the work.
#[allow(clippy::too_many_arguments)]
pub fn generate(
    model: &FaceModel,
    weights: &ExpressionWeights,
    observer: &Observer,
    basis: Option<&LinearBasis>,
    params: &DatasetParams,
    noise: &ObserverNoise,
    seed: u64,
    tick: &(dyn Fn() + Sync),
) -> Result<Vec<Sample>> {
    let solve = SolveParams {
        tolerance: params.tolerance,
        ..SolveParams::default()
    };
    let gains = noise.subject_gains(&mut stream(seed, "dataset/observer-gains"));
    let jobs: Vec<(Expression, usize)> = Expression::ALL
        .iter()
        .flat_map(|&e| (0..params.pairs_per_expression).map(move |i| (e, i)))
        .collect();
    jobs.par_iter()
        .map_init(
            || Workspace::new(model),
            |ws, &(e, index)| -> Result<Sample> {
                let mut rng = stream(seed, &format!("dataset/{e}/{index}"));
                let scale = rng.uniform();
                let jaw = rng.uniform();
                let a = weights.sample(e, scale, jaw);
                let state = match (params.start, basis) {
                    (SolveStart::Predicted, Some(b)) => solve_predicted(model, b, &a, ws, &solve),
                    _ => solve_from_rest(model, &a, ws, &solve),
                }
                .map(|(s, _)| s)
                .with_context(|| {
                    format!("dataset sample {e}/{index} (s = {scale:.4}, jaw = {jaw:.4})")
                })?;
                let mut aus = observer
                    .observe(&landmarks(state.surface(model.vertex_count())))?
                    .aus;
                if !noise.is_off() {
                    noise.apply(&mut aus, &gains, &mut rng);
                }
                tick();
                Ok(Sample {
                    expression: e,
                    index,
                    scale,
                    aus,
                    activations: *a.values(),
                })
            },
        )
        .collect()
}

/// `expression,index,scale,AU01..AU45,<56 control names>`; numbers in Rust's shortest
/// round-trip form, so reading gives back the same bits.
pub fn to_csv(samples: &[Sample]) -> String {
    let mut out = String::from("expression,index,scale");
    for a in AU_NAMES {
        out.push(',');
        out.push_str(a);
    }
    for c in control_names() {
        out.push(',');
        out.push_str(c);
    }
    out.push('\n');
    for s in samples {
        out.push_str(&format!("{},{},{}", s.expression, s.index, s.scale));
        for v in s.aus.iter().chain(&s.activations) {
            out.push_str(&format!(",{v}"));
        }
        out.push('\n');
    }
    out
}

pub fn from_csv(text: &str, name: &str) -> Result<Vec<Sample>> {
    let mut lines = text.lines();
    let header = lines.next().unwrap_or_default();
    let expected = 3 + AU_COUNT + CONTROL_COUNT;
    if header.split(',').count() != expected {
        bail!(
            "{name}: header has {} columns, expected {expected}",
            header.split(',').count()
        );
    }
    lines
        .enumerate()
        .map(|(i, line)| {
            let cells: Vec<&str> = line.split(',').collect();
            if cells.len() != expected {
                bail!(
                    "{name}:{}: {} cells, expected {expected}",
                    i + 2,
                    cells.len()
                );
            }
            let num = |k: usize| -> Result<f64> {
                cells[k]
                    .parse()
                    .with_context(|| format!("{name}:{}: `{}` is not a number", i + 2, cells[k]))
            };
            Ok(Sample {
                expression: cells[0]
                    .parse()
                    .map_err(|e| anyhow::anyhow!("{name}:{}: {e}", i + 2))?,
                index: num(1)? as usize,
                scale: num(2)?,
                aus: std::array::from_fn(|k| num(3 + k).unwrap_or(f64::NAN)),
                activations: std::array::from_fn(|k| num(3 + AU_COUNT + k).unwrap_or(f64::NAN)),
            })
        })
        .collect()
}
