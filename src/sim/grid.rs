//! Equilibria on a grid of the paper family's parameters, interpolated into starts for the
//! nonlinear solve.
//!
//! The paper's samples (Zeng et al. 4.2) are `a = w_e s` plus the jaw's rotation: per
//! expression a face of two parameters, `(s, jaw)` in `[0, 1]^2`. Their equilibria are smooth
//! in both, so a few faces solved from rest on a regular grid, interpolated by cubic
//! polynomials along each axis, predict any sample's equilibrium to a fraction of a
//! millimetre, where the linear basis is off by millimetres. Newton's method then finishes in
//! a few iterations near a stable equilibrium, where the exact Hessian factors at once
//! (`solver::solve_from_grid`). Each grid face is solved from rest, so the grid is a function
//! of the model, the weights and the tolerance alone.

use super::basis::displacement;
use super::controls::Activations;
use super::expression::{Expression, ExpressionWeights};
use super::geom::V3;
use super::model::{FaceModel, State};
use super::solver::{solve_from_rest, SolveError, SolveParams, Workspace};

/// The paper family's equilibria on a `(steps + 1) x (steps + 1)` grid per expression.
#[derive(Clone, Debug)]
pub struct ExpressionGrid {
    /// Intervals along each axis (s and the jaw).
    pub steps: usize,
    /// The expressions it holds, in the order of `fields`.
    pub expressions: Vec<Expression>,
    /// Rest positions of all nodes.
    pub rest: Vec<V3>,
    /// Per expression, per grid face (`i_s * (steps + 1) +
    /// i_jaw`): the displacement of every node, flattened xyz.
    pub fields: Vec<Vec<Vec<f64>>>,
    /// The activations of each grid face, aligned with `fields`.
    pub activations: Vec<Vec<Activations>>,
}

/// The grid faces' parameters, `(expression, s, jaw)`, in the order `fields` keeps them.
pub fn grid_points(expressions: &[Expression], steps: usize) -> Vec<(Expression, f64, f64)> {
    let at = |i: usize| i as f64 / steps as f64;
    expressions
        .iter()
        .flat_map(|&e| (0..=steps).flat_map(move |i| (0..=steps).map(move |k| (e, at(i), at(k)))))
        .collect()
}

impl ExpressionGrid {
    /// Solves every grid face of `expressions` from rest, side by side on rayon's threads
    /// with a workspace each: every face is its own solve, so the grid does not depend on the
    /// thread count.
    pub fn build(
        model: &FaceModel,
        weights: &ExpressionWeights,
        expressions: &[Expression],
        steps: usize,
        params: &SolveParams,
    ) -> Result<ExpressionGrid, SolveError> {
        use rayon::prelude::*;
        assert!(
            steps >= 3,
            "cubic interpolation needs 4 grid faces per axis"
        );
        let rest = model.tissue.rest.clone();
        let points = grid_points(expressions, steps);
        let flat = points
            .par_iter()
            .map_init(
                || Workspace::new(model),
                |ws, &(e, s, jaw)| {
                    let ws = ws.as_mut().map_err(|e| e.clone())?;
                    let (state, _) =
                        solve_from_rest(model, &weights.sample(e, s, jaw), ws, params)?;
                    Ok(displacement(&state.positions, &rest))
                },
            )
            .collect::<Result<Vec<Vec<f64>>, SolveError>>()?;
        let per = (steps + 1) * (steps + 1);
        let mut fields = Vec::with_capacity(expressions.len());
        let mut flat = flat.into_iter();
        let mut activations = Vec::with_capacity(expressions.len());
        for k in 0..expressions.len() {
            fields.push(flat.by_ref().take(per).collect());
            activations.push(
                points[k * per..(k + 1) * per]
                    .iter()
                    .map(|&(e, s, jaw)| weights.sample(e, s, jaw))
                    .collect(),
            );
        }
        Ok(ExpressionGrid {
            steps,
            expressions: expressions.to_vec(),
            rest,
            fields,
            activations,
        })
    }

    /// Every node's position for expression `e` at `(s, jaw)` (each clamped to [0, 1]):
    /// tensor-product cubic interpolation through the 4 x 4 nearest grid faces. None if the
    /// grid does not hold `e`.
    pub fn predict(&self, e: Expression, s: f64, jaw: f64) -> Option<Vec<V3>> {
        let field = &self.fields[self.index(e)?];
        let (ws, wj) = (cubic(s, self.steps), cubic(jaw, self.steps));
        let mut out = self.rest.clone();
        for &(i, a) in &ws {
            for &(k, b) in &wj {
                let w = a * b;
                let d = &field[i * (self.steps + 1) + k];
                for (p, d) in out.iter_mut().zip(d.chunks_exact(3)) {
                    p[0] += w * d[0];
                    p[1] += w * d[1];
                    p[2] += w * d[2];
                }
            }
        }
        Some(out)
    }

    fn index(&self, e: Expression) -> Option<usize> {
        self.expressions.iter().position(|&x| x == e)
    }
}

impl ExpressionGrid {
    /// The grid face nearest to `(s, jaw)` of expression `e`: its equilibrium, from which a
    /// short continuation reaches any face of its cell.
    pub fn nearest(&self, e: Expression, s: f64, jaw: f64) -> Option<State> {
        let at = |t: f64| (t.clamp(0.0, 1.0) * self.steps as f64).round() as usize;
        let index = at(s) * (self.steps + 1) + at(jaw);
        let x = self.index(e)?;
        Some(State {
            positions: self
                .rest
                .iter()
                .zip(self.fields[x][index].chunks_exact(3))
                .map(|(r, d)| [r[0] + d[0], r[1] + d[1], r[2] + d[2]])
                .collect(),
            activations: self.activations[x][index].clone(),
        })
    }
}

/// Lagrange weights at `t` in [0, 1] of the 4 grid nodes (of `steps + 1`) nearest to it, the
/// stencil shifted inward at the ends.
fn cubic(t: f64, steps: usize) -> [(usize, f64); 4] {
    let x = t.clamp(0.0, 1.0) * steps as f64;
    let first = (x.floor() as usize).saturating_sub(1).min(steps - 3);
    std::array::from_fn(|j| {
        let node = first + j;
        let w = (0..4)
            .filter(|&m| m != j)
            .map(|m| {
                let other = (first + m) as f64;
                (x - other) / (node as f64 - other)
            })
            .product();
        (node, w)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cubic_weights_reproduce_cubics_and_sum_to_one() {
        for steps in [3, 4, 6] {
            for k in 0..=40 {
                let t = k as f64 / 40.0;
                let w = cubic(t, steps);
                let sum: f64 = w.iter().map(|(_, w)| w).sum();
                assert!((sum - 1.0).abs() < 1e-12, "steps {steps}, t {t}: sum {sum}");
                let f = |x: f64| 2.0 - x + 3.0 * x * x - 0.5 * x * x * x;
                let at: f64 = w.iter().map(|&(i, w)| w * f(i as f64 / steps as f64)).sum();
                assert!(
                    (at - f(t)).abs() < 1e-12,
                    "steps {steps}, t {t}: {at} vs {}",
                    f(t)
                );
                // At a grid node the weight is that node's alone.
                if (t * steps as f64).fract() == 0.0 {
                    let node = (t * steps as f64) as usize;
                    for (i, w) in w {
                        let want = if i == node { 1.0 } else { 0.0 };
                        assert!((w - want).abs() < 1e-12);
                    }
                }
            }
        }
    }
}
