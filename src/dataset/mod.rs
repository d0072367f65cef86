//! The dataset stage (DESIGN 3, paper 4.2): for each expression, pairs (AUs, activations)
//! made by the model itself: activations drawn from a family, solve, observe.
//!
//! Families (`dataset.family`):
//! - `paper` (Zeng et al. 4.2, the default): a = w_e * s with s ~ U[0, 1], jaw rotation
//!   ~ U[0, 1], slide and twist neutral. Two numbers per sample.
//! - `broad`: what real faces do besides posing one expression (see [`Family::Broad`]).

/// Where each sample's solve starts.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
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

/// How a sample's activations are drawn (`dataset.family`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Family {
    /// Zeng et al.'s `w_e * s` plus the jaw.
    Paper,
    /// Each sample of expression slot `e` is one of six kinds, drawn with these chances:
    /// - 20% `w_e * s` as in `Paper`;
    /// - 25% a blend: `e` and one or two other expressions, each with its own scale
    ///   ~ U[0, 1], summed and clamped to [0, 1] (surprise with fear, a smile with a frown);
    /// - 15% one AU's muscle group alone (any of the 17, from `au_muscles.csv`) at
    ///   ~ U[0, 1], with the jaw ~ U[0, 0.2] unless the AU is the jaw's;
    /// - 15% left/right asymmetry: `w_e * s` with one side's muscles scaled by ~ U[0, 1];
    /// - 15% speech: `w_e * s` with s ~ U[0, 0.5], the jaw ~ U[0, 0.7], and each lip muscle
    ///   (orbicularis oris, incisivi, depressor labii inferioris, mentalis, risorius,
    ///   depressor anguli oris) with chance 1/2 at ~ U[0, 0.5];
    /// - 10% sparse random: one to four muscle pairs at ~ U[0, 1], each side scaled by
    ///   ~ U[0.5, 1], the jaw ~ U[0, 1] with chance 1/2.
    ///
    /// `Sample::scale` is the slot expression's scale (the AU group's or the strongest
    /// muscle's level where `e` takes no part).
    Broad,
}

impl Family {
    pub const NAMES: [&'static str; 2] = ["paper", "broad"];

    pub fn parse(s: &str) -> Option<Family> {
        match s {
            "paper" => Some(Family::Paper),
            "broad" => Some(Family::Broad),
            _ => None,
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Family::Paper => "paper",
            Family::Broad => "broad",
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
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
    /// How each sample's activations are drawn. Default `Paper`.
    pub family: Family,
    /// Seed of the samples' streams; separate from the training seeds so that every seed
    /// trains on the same, once-simulated pairs. Default 1.
    pub seed: u64,
    /// Intervals along s and along the jaw of a grid of equilibria (`sim::grid`) that a
    /// paper-family data set solved from predictions starts from; 0 (the default) for none:
    /// the linear basis' prediction alone. A grid of 4 makes the faces about 7 times faster
    /// (`bench solve`: 3 Newton iterations a face, against 17), but where the face has two
    /// stable equilibria (joy's and anger's lips) it lands on the other one more often than
    /// the basis' start does (docs/performance.md), so it is not the default.
    pub grid: usize,
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
            family: Family::Paper,
            seed: 1,
            grid: 0,
        }
    }
}

use anyhow::{Context, Result};
use rayon::prelude::*;

pub mod reader;

use crate::io::rows::{self, num, CsvRow};
use crate::observe::{Observer, ObserverNoise, AU_COUNT};
use crate::rng::stream;
use crate::rng::Stream;
use crate::sim::basis::LinearBasis;
use crate::sim::controls::{
    control_index, muscle_index, CONTROL_COUNT, JAW_ROTATION, JAW_SLIDE, JAW_TWIST, MUSCLE_COUNT,
};
use crate::sim::expression::{Expression, ExpressionWeights};
use crate::sim::grid::ExpressionGrid;
use crate::sim::muscles::{Side, MUSCLE_PAIRS};
use crate::sim::solver::{solve_from_grid, solve_predicted};
use crate::sim::{solve_from_rest, Activations, FaceModel, SolveParams, Workspace};
use reader::FaceReader;

/// One training pair.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Sample {
    pub expression: Expression,
    /// Index within its expression.
    pub index: usize,
    /// The expression scale s.
    #[serde(serialize_with = "num::shortest")]
    pub scale: f64,
    #[serde(with = "num::all")]
    pub aus: [f64; AU_COUNT],
    #[serde(with = "num::all")]
    pub activations: [f64; CONTROL_COUNT],
}

/// `expression,index,scale,AU01..AU45,<56 control names>`; numbers in Rust's shortest
/// round-trip form, so reading gives back the same bits.
impl CsvRow for Sample {
    fn header() -> Vec<String> {
        rows::wide(&["expression", "index", "scale"])
    }
}

/// Where a data set's solves start besides rest: the grid of the paper family's equilibria
/// (its faces), the linear basis' prediction (any face, and where the grid's start fails).
#[derive(Clone, Copy, Default)]
pub struct Starts<'a> {
    pub basis: Option<&'a LinearBasis>,
    pub grid: Option<&'a ExpressionGrid>,
}

/// Generates `params.pairs_per_expression` pairs per expression, read without detector noise
/// (see [`add_noise`]). Each sample draws from its own stream (`dataset/<expression>/<index>`),
/// so the result does not depend on how rayon splits the work. `au_controls` (per AU, the
/// controls of its muscle group, as `FacsMaps::au_controls`) serves the broad family's
/// single-AU samples.
#[allow(clippy::too_many_arguments)]
pub fn generate(
    model: &FaceModel,
    weights: &ExpressionWeights,
    reader: &FaceReader,
    observer: &Observer,
    starts: Starts,
    au_controls: &[Vec<usize>],
    params: &DatasetParams,
    seed: u64,
    jobs: &[(Expression, usize)],
    workspaces: &WorkspacePool,
    tick: &(dyn Fn() + Sync),
) -> Result<Vec<Sample>> {
    let solve = SolveParams {
        tolerance: params.tolerance,
        ..SolveParams::default()
    };
    jobs.par_iter()
        .map_init(
            || workspaces.take(model),
            |ws, &(e, index)| -> Result<Sample> {
                let ws = ws.get()?;
                let mut rng = stream(seed, &format!("dataset/{e}/{index}"));
                let (scale, a) = draw(params.family, weights, au_controls, e, &mut rng);
                let jaw = a.get(JAW_ROTATION);
                let paper = (e, scale, jaw);
                let state = match (params.start, starts.grid, starts.basis) {
                    (SolveStart::Predicted, Some(g), b) if params.family == Family::Paper => {
                        solve_from_grid(model, g, b, paper, &a, ws, &solve)
                    }
                    (SolveStart::Predicted, _, Some(b)) => {
                        solve_predicted(model, b, &a, ws, &solve)
                    }
                    _ => solve_from_rest(model, &a, ws, &solve),
                }
                .map(|(s, _)| s)
                .with_context(|| {
                    format!("dataset sample {e}/{index} (s = {scale:.4}, jaw = {jaw:.4})")
                })?;
                let aus = observer.observe(&reader.read(model, &state, None)?)?.aus;
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

/// Workspaces kept across calls of [`generate`]: a data set made in chunks analyses the
/// model's stiffness pattern once per worker, not once per chunk and split. A workspace is
/// scratch memory, so which one a sample gets does not change its result.
#[derive(Default)]
pub struct WorkspacePool(std::sync::Mutex<Vec<Workspace>>);

impl WorkspacePool {
    fn take(&self, model: &FaceModel) -> Pooled<'_> {
        let kept = self.0.lock().unwrap_or_else(|e| e.into_inner()).pop();
        Pooled {
            ws: Some(kept.map_or_else(|| Workspace::new(model), Ok)),
            pool: self,
        }
    }
}

/// A workspace borrowed from a pool, returned to it when dropped (`ws` is `Some` until then).
struct Pooled<'a> {
    ws: Option<Result<Workspace, crate::sim::SolveError>>,
    pool: &'a WorkspacePool,
}

impl Pooled<'_> {
    fn get(&mut self) -> Result<&mut Workspace, crate::sim::SolveError> {
        match self.ws.as_mut().expect("present until dropped") {
            Ok(ws) => Ok(ws),
            Err(e) => Err(e.clone()),
        }
    }
}

impl Drop for Pooled<'_> {
    fn drop(&mut self) {
        if let Some(Ok(ws)) = self.ws.take() {
            self.pool
                .0
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .push(ws);
        }
    }
}

/// Every sample of a data set, in its order: each expression's `pairs_per_expression`
/// indices. A sample depends only on its own `(expression, index)` stream, so any run of
/// consecutive jobs can be generated on its own (the harness caches them in chunks).
pub fn jobs(params: &DatasetParams) -> Vec<(Expression, usize)> {
    Expression::ALL
        .iter()
        .flat_map(|&e| (0..params.pairs_per_expression).map(move |i| (e, i)))
        .collect()
}

/// One sample's scale and activations from its stream.
fn draw(
    family: Family,
    weights: &ExpressionWeights,
    au_controls: &[Vec<usize>],
    e: Expression,
    rng: &mut Stream,
) -> (f64, Activations) {
    match family {
        Family::Paper => {
            let scale = rng.uniform();
            let jaw = rng.uniform();
            (scale, weights.sample(e, scale, jaw))
        }
        Family::Broad => broad_sample(weights, au_controls, e, rng),
    }
}

/// The detector's error on clean samples (`observer.noise_sd`, `observer.gain_spread`;
/// DESIGN 2.2): one set of gain factors for the data set (`dataset/observer-gains`) and fresh
/// noise per reading, drawn from each sample's own stream where its activations' draws end.
/// The faces are the same whatever the noise, so a noise sweep solves them once; the result
/// is the same bits as reading with noise while generating. Returns the samples unchanged
/// when the noise is off.
pub fn add_noise(
    samples: &[Sample],
    weights: &ExpressionWeights,
    au_controls: &[Vec<usize>],
    params: &DatasetParams,
    noise: &ObserverNoise,
    seed: u64,
) -> Vec<Sample> {
    if noise.is_off() {
        return samples.to_vec();
    }
    let gains = noise.subject_gains(&mut stream(seed, "dataset/observer-gains"));
    samples
        .iter()
        .map(|s| {
            let mut rng = stream(seed, &format!("dataset/{}/{}", s.expression, s.index));
            // Past the activations' draws, to where the reading's noise was drawn.
            let _ = draw(params.family, weights, au_controls, s.expression, &mut rng);
            let mut out = s.clone();
            noise.apply(&mut out.aus, &gains, &mut rng);
            out
        })
        .collect()
}

/// The lip muscles speech moves (the broad family's speech-like samples).
const SPEECH_MUSCLES: [&str; 8] = [
    "orbicularis_oris_upper",
    "orbicularis_oris_lower",
    "incisivus_labii_superioris",
    "incisivus_labii_inferioris",
    "depressor_labii_inferioris",
    "mentalis",
    "risorius",
    "depressor_anguli_oris",
];

/// One sample of the broad family for expression slot `e` (see [`Family::Broad`]): its
/// scale and activations.
pub fn broad_sample(
    weights: &ExpressionWeights,
    au_controls: &[Vec<usize>],
    e: Expression,
    rng: &mut Stream,
) -> (f64, Activations) {
    let mut v = [0.0; CONTROL_COUNT];
    let add = |v: &mut [f64; CONTROL_COUNT], ex: Expression, s: f64| {
        for (x, w) in v.iter_mut().zip(weights.weights(ex)) {
            *x += w * s;
        }
    };
    let kind = rng.uniform();
    let scale;
    if kind < 0.20 {
        // Zeng et al.'s own samples.
        scale = rng.uniform();
        add(&mut v, e, scale);
        v[JAW_ROTATION] = rng.uniform();
    } else if kind < 0.45 {
        // A blend of `e` with one or two other expressions, each at its own scale.
        scale = rng.uniform();
        add(&mut v, e, scale);
        let mut others: Vec<Expression> = Expression::ALL
            .iter()
            .copied()
            .filter(|&x| x != e)
            .collect();
        for _ in 0..1 + rng.index(2) {
            let other = others.remove(rng.index(others.len()));
            add(&mut v, other, rng.uniform());
        }
        v[JAW_ROTATION] = rng.uniform();
    } else if kind < 0.60 {
        // One AU's muscle group alone.
        let au = rng.index(au_controls.len());
        scale = rng.uniform();
        for &c in &au_controls[au] {
            v[c] = scale;
        }
        if !au_controls[au].contains(&JAW_ROTATION) {
            v[JAW_ROTATION] = rng.range(0.0, 0.2);
        }
    } else if kind < 0.75 {
        // Left/right asymmetry: one side weaker.
        scale = rng.uniform();
        add(&mut v, e, scale);
        let weak = if rng.uniform() < 0.5 {
            Side::Left
        } else {
            Side::Right
        };
        let factor = rng.uniform();
        for pair in 0..MUSCLE_PAIRS.len() {
            v[muscle_index(pair, weak)] *= factor;
        }
        v[JAW_ROTATION] = rng.uniform();
    } else if kind < 0.90 {
        // Speech: a faint expression, the jaw and the lips moving.
        scale = rng.range(0.0, 0.5);
        add(&mut v, e, scale);
        v[JAW_ROTATION] = rng.range(0.0, 0.7);
        for name in SPEECH_MUSCLES {
            if rng.uniform() < 0.5 {
                let level = rng.range(0.0, 0.5);
                for side in ["left", "right"] {
                    let c = control_index(&format!("{name}_{side}")).expect("a model muscle");
                    v[c] += level;
                }
            }
        }
    } else {
        // Sparse random activations.
        let mut top: f64 = 0.0;
        for _ in 0..1 + rng.index(4) {
            let pair = rng.index(MUSCLE_PAIRS.len());
            let level = rng.uniform();
            for side in [Side::Left, Side::Right] {
                let x = level * rng.range(0.5, 1.0);
                v[muscle_index(pair, side)] = x;
                top = top.max(x);
            }
        }
        scale = top;
        if rng.uniform() < 0.5 {
            v[JAW_ROTATION] = rng.uniform();
        }
    }
    for x in &mut v[..MUSCLE_COUNT + 1] {
        *x = x.clamp(0.0, 1.0);
    }
    v[JAW_SLIDE] = 0.5;
    v[JAW_TWIST] = 0.5;
    (
        scale,
        Activations::from_values(&v).expect("clamped to [0, 1]"),
    )
}

pub fn to_csv(samples: &[Sample]) -> String {
    rows::to_csv(samples)
}

pub fn from_csv(text: &str, name: &str) -> Result<Vec<Sample>> {
    Ok(rows::from_csv(text, name)?)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::expressions::read_expressions;
    use crate::io::facs::read_facs;

    fn draws(e: Expression, n: usize) -> Vec<(f64, Activations)> {
        let layout = crate::io::Layout::here();
        let weights = read_expressions(&layout.expressions()).unwrap();
        let (expression_aus, au_muscles) = layout.facs();
        let facs = read_facs(&expression_aus, &au_muscles).unwrap();
        (0..n)
            .map(|i| {
                let mut rng = stream(7, &format!("dataset/{e}/{i}"));
                broad_sample(&weights, &facs.au_controls, e, &mut rng)
            })
            .collect()
    }

    #[test]
    fn detector_noise_is_per_sample_reproducible_and_of_its_stated_size() {
        let layout = crate::io::Layout::here();
        let weights = read_expressions(&layout.expressions()).unwrap();
        let (expression_aus, au_muscles) = layout.facs();
        let facs = read_facs(&expression_aus, &au_muscles).unwrap();
        let params = DatasetParams {
            family: Family::Broad,
            ..DatasetParams::default()
        };
        let seed = 5;
        let clean: Vec<Sample> = Expression::ALL
            .iter()
            .flat_map(|&e| (0..200).map(move |i| (e, i)))
            .map(|(e, index)| {
                let mut rng = stream(seed, &format!("dataset/{e}/{index}"));
                let (scale, a) = draw(params.family, &weights, &facs.au_controls, e, &mut rng);
                Sample {
                    expression: e,
                    index,
                    scale,
                    aus: [2.5; AU_COUNT],
                    activations: *a.values(),
                }
            })
            .collect();
        let noise = ObserverNoise {
            noise_sd: 0.2,
            gain_spread: 0.0,
        };
        let add = |s: &[Sample], n: &ObserverNoise| {
            add_noise(s, &weights, &facs.au_controls, &params, n, seed)
        };
        assert_eq!(
            add(&clean, &ObserverNoise::default()),
            clean,
            "off: unchanged"
        );
        let noisy = add(&clean, &noise);
        // Each sample's noise comes from its own stream: the order of the input is irrelevant.
        let mut reversed = clean.clone();
        reversed.reverse();
        let mut again = add(&reversed, &noise);
        again.reverse();
        assert_eq!(again, noisy);
        // The noise is where generating with noise drew it: after the activations' draws.
        let s = &clean[7];
        let mut rng = stream(seed, &format!("dataset/{}/{}", s.expression, s.index));
        let _ = draw(
            params.family,
            &weights,
            &facs.au_controls,
            s.expression,
            &mut rng,
        );
        let mut aus = s.aus;
        noise.apply(&mut aus, &[1.0; AU_COUNT], &mut rng);
        assert_eq!(aus, noisy[7].aus);
        // Its size: zero mean, sd 0.2 (2.5 +/- 0.2 is never clamped).
        let d: Vec<f64> = noisy
            .iter()
            .zip(&clean)
            .flat_map(|(n, c)| (0..AU_COUNT).map(move |k| n.aus[k] - c.aus[k]))
            .collect();
        let (mean, sd) = crate::stats::mean_sd(&d);
        assert!(
            mean.abs() < 0.01 && (sd - 0.2).abs() < 0.01,
            "mean {mean}, sd {sd}"
        );
        for (n, c) in noisy.iter().zip(&clean) {
            assert_eq!((n.scale, n.activations), (c.scale, c.activations));
        }
    }

    #[test]
    fn broad_samples_are_valid_reproducible_and_go_beyond_the_paper_family() {
        let weights = read_expressions(&crate::io::Layout::here().expressions()).unwrap();
        let e = Expression::Joy;
        let a = draws(e, 400);
        assert_eq!(a, draws(e, 400), "the same streams give the same samples");
        let w = weights.weights(e);
        let (mut asymmetric, mut off_family, mut silent_slot) = (0, 0, 0);
        for (scale, act) in &a {
            let v = act.values();
            assert!((0.0..=1.0).contains(scale));
            assert!(v.iter().all(|x| (0.0..=1.0).contains(x)));
            assert_eq!((v[JAW_SLIDE], v[JAW_TWIST]), (0.5, 0.5));
            if (0..MUSCLE_PAIRS.len()).any(|p| {
                (v[muscle_index(p, Side::Left)] - v[muscle_index(p, Side::Right)]).abs() > 0.05
            }) {
                asymmetric += 1;
            }
            // Not w_e * s for any s: some muscle outside joy's weights is active.
            if (0..MUSCLE_COUNT).any(|c| w[c] == 0.0 && v[c] > 0.01) {
                off_family += 1;
            }
            if (0..MUSCLE_COUNT).all(|c| w[c] == 0.0 || v[c] < 1e-12) {
                silent_slot += 1;
            }
        }
        // Asymmetric and sparse kinds: about 25%; blends, speech, single AUs and sparse
        // activations leave the family: about 65%.
        assert!(
            (60..=140).contains(&asymmetric),
            "{asymmetric} asymmetric of 400"
        );
        assert!(
            (200..=320).contains(&off_family),
            "{off_family} off the family of 400"
        );
        assert!(
            silent_slot > 20,
            "single AUs and sparse draws without joy: {silent_slot}"
        );
    }
}
