//! Quasi-static equilibrium of the face: the free node positions minimising the tissue's
//! elastic energy plus the muscles' potential, for fixed activations.
//!
//! Newton's method on the total energy. Each iteration first tries the exact Hessian; where
//! it is indefinite (compressed springs buckling, prisms past the inflection of their volume
//! energy) it falls back to the positive semi-definite part (compressive geometric terms and
//! the volume's second derivative dropped), then to a diagonal shift. The matrix is assembled
//! in a fill-reducing node order into preallocated slots and factorised by faer's supernodal
//! Cholesky with the symbolic analysis done once per model; a backtracking (Armijo) line
//! search refuses steps that would invert a prism. `facelab bench solve` measures it.
//!
//! Large changes of activation are reached by continuation: the path from the state's own
//! activations to the target is split in halves until each piece converges, so a solve from
//! rest follows the physical loading path and gives the same equilibrium every run. If even
//! the smallest piece fails (`max_halvings`), the rest of the path is followed once more with
//! the exact Hessian shifted toward positive definiteness instead of its semi-definite part:
//! slower per iteration, but it does not circle near buckled equilibria. Solves that converge
//! without it are unchanged by it.

use super::basis::LinearBasis;
use super::controls::Activations;
use super::expression::Expression;
use super::grid::ExpressionGrid;
use super::model::{FaceModel, State};

mod diagnostics;
mod energy;
mod newton;
mod pattern;
mod workspace;

pub use diagnostics::{iteration_cost, residual, softest_mode, IterationCost, SoftMode};
pub use workspace::Workspace;
use {diagnostics::*, energy::*, newton::*, pattern::*};
/// Solver settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SolveParams {
    /// Converged when |gradient| <= tolerance * |gradient at the rest positions| for the same
    /// activations (the force imbalance the solve removes). Default 1e-4: `bench solve`
    /// measures how far a 100x tighter solve moves the landmarks from there: at most 0.25 mm
    /// over its 60 random expressions, against a mean expression motion of 4.9 mm.
    pub tolerance: f64,
    /// Newton iterations allowed per continuation piece. Default 30.
    pub max_iterations: usize,
    /// Equal steps from rest in `solve_from_rest`. Default 4.
    pub continuation_steps: usize,
    /// How many times a piece of the path may be halved before the rest of the path is tried
    /// with the shifted exact Hessian, and then before giving up. Default 6.
    pub max_halvings: usize,
}

impl Default for SolveParams {
    fn default() -> Self {
        SolveParams {
            tolerance: 1e-4,
            max_iterations: 30,
            continuation_steps: 4,
            max_halvings: 6,
        }
    }
}

/// What a successful solve did.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct SolveReport {
    /// Newton iterations over all continuation pieces.
    pub iterations: usize,
    /// Continuation pieces solved.
    pub pieces: usize,
    /// Final relative residual (|g| / |g_rest|).
    pub residual: f64,
}

#[derive(Clone, Debug, thiserror::Error, PartialEq)]
pub enum SolveError {
    #[error("solver did not converge: relative residual {residual:.3e} after {iterations} iterations (tolerance {tolerance:.1e})")]
    NotConverged {
        iterations: usize,
        residual: f64,
        tolerance: f64,
    },
    #[error("non-finite value in the solve at iteration {iteration}")]
    NonFinite { iteration: usize },
    #[error("the activation path could not be followed: the start state has inverted elements")]
    InvalidStart,
    #[error("the model's stiffness pattern cannot be analysed: {0}")]
    Pattern(String),
}

/// Solves for `target` starting from `state` (the equilibrium of `state.activations`), splitting
/// the activation path in halves where a piece fails. On success `state` holds the equilibrium
/// of `target`; on failure it is left at the last equilibrium reached.
pub fn solve(
    model: &FaceModel,
    target: &Activations,
    state: &mut State,
    ws: &mut Workspace,
    params: &SolveParams,
) -> Result<SolveReport, SolveError> {
    let mut report = SolveReport::default();
    let start = state.activations.clone();
    let mut from_pose = model.pose(&start);
    // Path parameter reached so far and the current piece length.
    let mut t = 0.0f64;
    let mut piece = 1.0f64;
    let mut halvings = 0usize;
    let mut curvature = Curvature::SemiDefinite;
    // Iterations spent on pieces that did not converge (for the error).
    let mut failed = 0usize;
    while t < 1.0 {
        let t_next = (t + piece).min(1.0);
        let a = interpolate(&start, target, t_next);
        let to_pose = model.pose(&a);
        let mut trial = state.clone();
        model.carry(&mut trial, &from_pose, &to_pose);
        match newton(model, &to_pose, &mut trial, ws, params, curvature) {
            Ok(r) => {
                report.iterations += r.iterations;
                report.pieces += 1;
                report.residual = r.residual;
                *state = trial;
                from_pose = to_pose;
                t = t_next;
            }
            Err(err) => {
                if let SolveError::NotConverged { iterations, .. } = err {
                    failed += iterations;
                }
                halvings += 1;
                if halvings > params.max_halvings && curvature == Curvature::SemiDefinite {
                    // Follow the rest of the path again with the exact, shifted Hessian.
                    curvature = Curvature::Shifted;
                    halvings = 0;
                    piece = 1.0 - t;
                    continue;
                }
                if halvings > params.max_halvings {
                    return Err(match err {
                        SolveError::NotConverged { residual, .. } => SolveError::NotConverged {
                            iterations: report.iterations + failed,
                            residual,
                            tolerance: params.tolerance,
                        },
                        other => other,
                    });
                }
                piece *= 0.5;
            }
        }
    }
    Ok(report)
}

/// `start + t (target - start)`, element-wise.
fn interpolate(start: &Activations, target: &Activations, t: f64) -> Activations {
    if t >= 1.0 {
        return target.clone();
    }
    let mut values = *start.values();
    for (v, &b) in values.iter_mut().zip(target.values()) {
        *v += t * (b - *v);
    }
    Activations::from_values(&values).expect("a convex combination stays in [0, 1]")
}

/// Solves for `target` from the rest face in `params.continuation_steps` equal steps.
pub fn solve_from_rest(
    model: &FaceModel,
    target: &Activations,
    ws: &mut Workspace,
    params: &SolveParams,
) -> Result<(State, SolveReport), SolveError> {
    let mut state = model.rest_state();
    let mut total = SolveReport::default();
    let steps = params.continuation_steps.max(1);
    for k in 1..=steps {
        let a = target.scaled_from_neutral(k as f64 / steps as f64);
        let r = solve(model, &a, &mut state, ws, params)?;
        total.iterations += r.iterations;
        total.pieces += r.pieces;
        total.residual = r.residual;
    }
    Ok((state, total))
}

/// Solves for `target` from the linear basis' prediction of its equilibrium, which is what
/// makes sampling many random faces cheap. Where the prediction of `target` inverts a prism or
/// Newton does not converge from it, the prediction of `target` scaled toward neutral (by
/// 1/2, then 1/4) is tried instead, and its equilibrium continued to `target` along the same
/// straight path from neutral that [`solve_from_rest`] follows; if none of them converges,
/// falls back to `solve_from_rest`. The report's iterations include the failed attempts.
pub fn solve_predicted(
    model: &FaceModel,
    basis: &LinearBasis,
    target: &Activations,
    ws: &mut Workspace,
    params: &SolveParams,
) -> Result<(State, SolveReport), SolveError> {
    let mut spent = 0;
    for level in 0..PREDICTION_LEVELS {
        let t = 0.5f64.powi(level as i32);
        let a = if level == 0 {
            target.clone()
        } else {
            target.scaled_from_neutral(t)
        };
        let positions = basis.predict(&a);
        let (mut state, mut report) = match solve_from_guess(model, a, positions, ws, params) {
            Ok(solved) => solved,
            Err(SolveError::NotConverged { iterations, .. }) => {
                spent += iterations;
                continue;
            }
            Err(_) => continue,
        };
        if level > 0 {
            match solve(model, target, &mut state, ws, params) {
                Ok(rest_of_path) => {
                    report.iterations += rest_of_path.iterations;
                    report.pieces += rest_of_path.pieces;
                    report.residual = rest_of_path.residual;
                }
                Err(SolveError::NotConverged { iterations, .. }) => {
                    spent += report.iterations + iterations;
                    break;
                }
                Err(_) => {
                    spent += report.iterations;
                    break;
                }
            }
        }
        report.iterations += spent;
        return Ok((state, report));
    }
    let (state, mut report) = solve_from_rest(model, target, ws, params)?;
    report.iterations += spent;
    Ok((state, report))
}

/// Newton's method for `target` from `guess` (every node's position; the fixed nodes are put
/// where `target`'s pose holds them), with no continuation: for a guess near the equilibrium,
/// such as the linear basis' or the grid's prediction.
pub fn solve_from_guess(
    model: &FaceModel,
    target: Activations,
    mut guess: Vec<crate::sim::geom::V3>,
    ws: &mut Workspace,
    params: &SolveParams,
) -> Result<(State, SolveReport), SolveError> {
    let pose = model.pose(&target);
    for (node, p) in guess.iter_mut().enumerate() {
        if !model.free[node] {
            *p = pose.fixed[node];
        }
    }
    let mut state = State {
        positions: guess,
        activations: target,
    };
    let report = newton(
        model,
        &pose,
        &mut state,
        ws,
        params,
        Curvature::SemiDefinite,
    )?;
    Ok((state, report))
}

/// Solves a paper-family face (`w_e s` plus the jaw, `target`) from the grid's prediction of
/// its equilibrium; where Newton does not converge from there, by continuation from the
/// nearest grid face; where that fails too (or the grid lacks `e`), as [`solve_predicted`]
/// does with `basis`, or from rest without one. The report's iterations include the failed
/// attempts.
pub fn solve_from_grid(
    model: &FaceModel,
    grid: &ExpressionGrid,
    basis: Option<&LinearBasis>,
    (e, s, jaw): (Expression, f64, f64),
    target: &Activations,
    ws: &mut Workspace,
    params: &SolveParams,
) -> Result<(State, SolveReport), SolveError> {
    let mut spent = 0;
    if let Some(guess) = grid.predict(e, s, jaw) {
        match solve_from_guess(model, target.clone(), guess, ws, params) {
            Ok(solved) => return Ok(solved),
            Err(SolveError::NotConverged { iterations, .. }) => spent += iterations,
            Err(_) => {}
        }
    }
    // The grid face nearest to the target, continued to it: a short path.
    if let Some(mut state) = grid.nearest(e, s, jaw) {
        match solve(model, target, &mut state, ws, params) {
            Ok(mut report) => {
                report.iterations += spent;
                return Ok((state, report));
            }
            Err(SolveError::NotConverged { iterations, .. }) => spent += iterations,
            Err(_) => {}
        }
    }
    let (state, mut report) = match basis {
        Some(b) => solve_predicted(model, b, target, ws, params)?,
        None => solve_from_rest(model, target, ws, params)?,
    };
    report.iterations += spent;
    Ok((state, report))
}

/// How many predictions `solve_predicted` tries: the target's, then at 1/2 and 1/4 of it.
const PREDICTION_LEVELS: usize = 3;

#[cfg(test)]
mod tests;
