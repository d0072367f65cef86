//! Newton's method on the total energy with the Hessian fallbacks and the Armijo line search.

use crate::sim::geom::V3;
use crate::sim::model::{FaceModel, Pose, State};

use super::*;

/// The rest positions with the fixed nodes where `pose` puts them: the reference state whose
/// force imbalance scales the residual.
pub(super) fn rest_under(model: &FaceModel, pose: &Pose) -> Vec<V3> {
    let mut rest = model.tissue.rest.clone();
    for (node, p) in rest.iter_mut().enumerate() {
        if !model.free[node] {
            *p = pose.fixed[node];
        }
    }
    rest
}

pub(super) fn gradient_norm(ws: &Workspace) -> f64 {
    ws.gradient.iter().map(|v| v * v).sum::<f64>().sqrt()
}

/// Force imbalance (N) below which a pose counts as unloaded.
pub(super) const NO_LOAD: f64 = 1e-9;

/// What a Newton iteration does where the exact Hessian is indefinite.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Curvature {
    /// Drop the compressive springs' geometric terms and the volume's second derivative (the
    /// positive semi-definite part), then shift the diagonal if that is still singular. Cheap
    /// and usually enough, but near a buckled equilibrium the stiffness it drops is the very
    /// softness of the buckling mode, and the iteration can circle just above tolerance.
    SemiDefinite,
    /// Keep the exact Hessian and add the smallest power-of-ten multiple of the identity that
    /// makes it positive definite (Levenberg), starting a tenth below the last shift.
    Shifted,
}

/// Newton iterations at fixed `pose` from the positions in `state`.
pub(super) fn newton(
    model: &FaceModel,
    pose: &Pose,
    state: &mut State,
    ws: &mut Workspace,
    params: &SolveParams,
    curvature: Curvature,
) -> Result<SolveReport, SolveError> {
    // Scale: the force imbalance of the rest positions under this pose.
    let rest = rest_under(model, pose);
    assemble(model, pose, &rest, ws, false, false);
    let scale_norm = gradient_norm(ws);
    if !scale_norm.is_finite() {
        return Err(SolveError::NonFinite { iteration: 0 });
    }
    // No load (neutral activations): the rest positions are the equilibrium. The floor is
    // far below any activation's force (a muscle at 1e-6 pulls with ~1e-6 N) and above the
    // round-off of an unloaded assembly (~1e-16 N), which no Newton step can reduce.
    if scale_norm <= NO_LOAD {
        state.positions = rest;
        return Ok(SolveReport::default());
    }
    let x = &mut state.positions;
    let mut e0 = energy(model, pose, x);
    if !e0.is_finite() {
        return Err(SolveError::InvalidStart);
    }
    let mut residual = f64::INFINITY;
    let mut last_shift = 0.0f64;
    let mut done = 0;
    for iteration in 0..=params.max_iterations {
        done = iteration;
        assemble(model, pose, x, ws, true, true);
        residual = gradient_norm(ws) / scale_norm;
        if !residual.is_finite() {
            return Err(SolveError::NonFinite { iteration });
        }
        if residual <= params.tolerance {
            return Ok(SolveReport {
                iterations: iteration,
                pieces: 1,
                residual,
            });
        }
        if iteration == params.max_iterations {
            break;
        }
        // Solve H s = -g with the full Hessian. Where it is indefinite (compressed springs,
        // a prism past its volume's inflection), fall back as `curvature` says.
        let mut full = true;
        let mut shift = 0.0;
        while !ws.newton_step() {
            if full && curvature == Curvature::SemiDefinite {
                full = false;
                assemble(model, pose, x, ws, true, false);
                continue;
            }
            let next = match curvature {
                Curvature::SemiDefinite if shift == 0.0 => 1e-3,
                Curvature::SemiDefinite => shift * 100.0,
                Curvature::Shifted if shift == 0.0 => (last_shift * 0.1).max(1e-3),
                Curvature::Shifted => shift * 10.0,
            };
            if next > 1e12 {
                return Err(SolveError::NonFinite { iteration });
            }
            ws.shift_diagonal(next - shift);
            shift = next;
        }
        last_shift = shift;
        let slope = dot_slices(&ws.step, &ws.gradient);
        // Backtracking (Armijo) line search on the energy.
        let mut alpha = 1.0;
        let mut accepted = false;
        for _ in 0..30 {
            ws.trial.clone_from(x);
            for (node, p) in ws.trial.iter_mut().enumerate() {
                let f = ws.pattern.free_index[node];
                if f != NONE {
                    let f = 3 * f as usize;
                    p[0] += alpha * ws.step[f];
                    p[1] += alpha * ws.step[f + 1];
                    p[2] += alpha * ws.step[f + 2];
                }
            }
            let e = energy(model, pose, &ws.trial);
            if e <= e0 + 1e-4 * alpha * slope {
                std::mem::swap(x, &mut ws.trial);
                e0 = e;
                accepted = true;
                break;
            }
            alpha *= 0.5;
        }
        if !accepted {
            break;
        }
    }
    // Iterations whose step was taken: a failed line search ends the attempt early.
    Err(SolveError::NotConverged {
        iterations: done,
        residual,
        tolerance: params.tolerance,
    })
}
