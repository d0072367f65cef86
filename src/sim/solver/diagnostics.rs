//! Measurements of the solver: the cost of one iteration, the softest mode of the Hessian
//! and the full-space residual.

use crate::sim::model::{FaceModel, State};

use super::*;

/// Where the time of one Newton iteration goes, measured at a state (`facelab bench solve`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct IterationCost {
    /// Gradient and Hessian assembly (s).
    pub assemble: f64,
    /// Numeric Cholesky factorisation and the two triangular solves (s).
    pub factorize: f64,
    /// One energy evaluation, which each line-search trial makes (s).
    pub energy: f64,
}

/// Times the parts of a Newton iteration at `state` for its own activations, each the mean
/// of `repeats` runs. The positive semi-definite Hessian is factorised, so the factorisation
/// runs to completion as it does in every iteration that takes a step.
pub fn iteration_cost(
    model: &FaceModel,
    state: &State,
    ws: &mut Workspace,
    repeats: usize,
) -> IterationCost {
    let repeats = repeats.max(1);
    let pose = model.pose(&state.activations);
    let x = &state.positions;
    let mean = |t: std::time::Instant| t.elapsed().as_secs_f64() / repeats as f64;
    let t = std::time::Instant::now();
    for _ in 0..repeats {
        assemble(model, &pose, x, ws, true, false);
    }
    let assemble_s = mean(t);
    let values = ws.values.clone();
    let t = std::time::Instant::now();
    for _ in 0..repeats {
        ws.values.copy_from_slice(&values);
        std::hint::black_box(ws.newton_step());
    }
    let factorize = mean(t);
    let t = std::time::Instant::now();
    for _ in 0..repeats {
        std::hint::black_box(energy(model, &pose, x));
    }
    IterationCost {
        assemble: assemble_s,
        factorize,
        energy: mean(t),
    }
}

/// The softest way the face can deform at a state: the smallest eigenvalue of the Hessian
/// of its energy, and where the eigenvector lives (`facelab bench solve`).
///
/// At a stable equilibrium the exact Hessian is positive definite; a negative smallest
/// eigenvalue says the solve stopped at a saddle, where the face could lower its energy by
/// moving along the mode. A mode carried by one vertex column is a mesh-scale instability
/// (the surface node tilting over the node beneath it), not a deformation of the face.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SoftMode {
    /// Smallest eigenvalue of the Hessian over the free coordinates (N/m); negative where the
    /// state is a saddle of the energy.
    pub stiffness: f64,
    /// The surface vertex whose column of nodes (all four sheets) carries most of the mode.
    pub vertex: usize,
    /// Share of the mode's squared length carried by that vertex's column and its mirror
    /// image's, in [0, 1]: near 1 for a mode local to one spot of a symmetric face.
    pub vertex_share: f64,
    /// `|H v - stiffness v| / |stiffness|` for the unit vector found: how far the inverse
    /// iteration is from an eigenvector.
    pub eigen_residual: f64,
}

/// The softest mode of the exact Hessian (`exact`) or of its positive semi-definite part at
/// `state`, for its own activations, by `iterations` steps of inverse iteration. Where the
/// Hessian is indefinite the iteration runs on it shifted by the smallest power of ten that
/// makes it positive definite, and the stiffness found is negative. `None` only if no shift
/// up to 1e12 N/m does.
pub fn softest_mode(
    model: &FaceModel,
    state: &State,
    ws: &mut Workspace,
    exact: bool,
    iterations: usize,
) -> Option<SoftMode> {
    let pose = model.pose(&state.activations);
    assemble(model, &pose, &state.positions, ws, true, exact);
    let (stiffness, v, eigen_residual) = lowest_eigenpair(ws, iterations)?;
    let n = model.vertex_count();
    let mut column = vec![0.0; n];
    for (node, &f) in ws.pattern.free_index.iter().enumerate() {
        if f != NONE {
            let f = 3 * f as usize;
            column[node % n] += dot_slices(&v[f..f + 3], &v[f..f + 3]);
        }
    }
    let vertex = (0..n)
        .max_by(|&a, &b| column[a].total_cmp(&column[b]))
        .expect("a face has vertices");
    let mirror = model.mirror[vertex];
    let vertex_share = if mirror == vertex {
        column[vertex]
    } else {
        column[vertex] + column[mirror]
    };
    Some(SoftMode {
        stiffness,
        vertex,
        vertex_share,
        eigen_residual,
    })
}

/// The smallest eigenvalue of the assembled Hessian, its unit eigenvector and the relative
/// residual `|H v - lambda v| / |lambda|`, by inverse iteration, shifted where the Hessian is
/// indefinite (see `softest_mode`). Leaves the Hessian as it was, shift included.
pub(super) fn lowest_eigenpair(
    ws: &mut Workspace,
    iterations: usize,
) -> Option<(f64, Vec<f64>, f64)> {
    // A fixed start with no symmetry, so that no eigenvector is missed by being orthogonal.
    let start: Vec<f64> = (0..ws.dof())
        .map(|i| 1.0 + (i as f64 * 0.618_034).fract())
        .collect();
    let mut v = start.clone();
    let mut shift = 0.0;
    while !ws.inverse_iteration(&mut v, iterations) {
        let next: f64 = if shift == 0.0 { 1e-3 } else { shift * 10.0 };
        if next > 1e12 {
            return None;
        }
        ws.shift_diagonal(next - shift);
        shift = next;
        v.clone_from(&start);
    }
    let hv = ws.hessian_times(&v);
    let shifted = dot_slices(&hv, &v);
    let stiffness = shifted - shift;
    let residual = hv
        .iter()
        .zip(&v)
        .map(|(h, x)| (h - shifted * x).powi(2))
        .sum::<f64>()
        .sqrt()
        / stiffness.abs();
    Some((stiffness, v, residual))
}

pub(super) fn dot_slices(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// The relative residual of `state` for its own activations (for checking a returned state).
pub fn residual(model: &FaceModel, state: &State, ws: &mut Workspace) -> f64 {
    let pose = model.pose(&state.activations);
    let rest = rest_under(model, &pose);
    assemble(model, &pose, &rest, ws, false, false);
    let scale_norm = gradient_norm(ws);
    assemble(model, &pose, &state.positions, ws, false, false);
    if scale_norm == 0.0 {
        gradient_norm(ws)
    } else {
        gradient_norm(ws) / scale_norm
    }
}
