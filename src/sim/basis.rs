//! Linear muscle basis after Choe, Lee & Ko 2001 (their eq. 9, `w = w_init + sum a_i w_i`):
//! the face as the rest face plus a weighted sum of per-control displacement fields, each
//! computed once with the nonlinear solver at that control's full activation. Jaw slide and
//! twist, neutral at 0.5, enter with weight `2 (value - 0.5)` on their field at 1.0.
//!
//! It costs microseconds per face instead of milliseconds, but ignores contact, stiffening
//! and the interaction of muscles; `bench solve` reports how far it is from the nonlinear face.
//! The fields cover every tissue node, not only the surface, so the basis also predicts a
//! start for the nonlinear solve (`solver::solve_predicted`).

use super::controls::{Activations, AUXILIARY, JAW_SLIDE, JAW_TWIST};
use super::geom::V3;
use super::model::FaceModel;
use super::solver::{solve_from_rest, SolveError, SolveParams, Workspace};

#[derive(Clone, Debug)]
pub struct LinearBasis {
    /// Surface vertices (the first `vertex_count` nodes).
    pub vertex_count: usize,
    /// Rest positions of all nodes.
    pub rest: Vec<V3>,
    /// Per control (auxiliary excluded): displacement of every node, flattened xyz.
    pub fields: Vec<Vec<f64>>,
}

/// The coefficient of a control's field for its input value.
fn coefficient(index: usize, value: f64) -> f64 {
    match index {
        JAW_SLIDE | JAW_TWIST => 2.0 * (value - 0.5),
        _ => value,
    }
}

/// Every node's displacement from `rest`, flattened xyz: a field of the basis, or of the
/// grid of equilibria (`sim::grid`).
pub(crate) fn displacement(positions: &[V3], rest: &[V3]) -> Vec<f64> {
    positions
        .iter()
        .zip(rest)
        .flat_map(|(p, r)| [p[0] - r[0], p[1] - r[1], p[2] - r[2]])
        .collect()
}

impl LinearBasis {
    /// Solves the model once per control at full activation (slide, twist at 1.0), the
    /// controls side by side on rayon's threads, each with its own workspace: every solve
    /// starts from rest, so the fields do not depend on the thread count.
    pub fn build(model: &FaceModel, params: &SolveParams) -> Result<LinearBasis, SolveError> {
        use rayon::prelude::*;
        let rest = model.tissue.rest.clone();
        let fields = (0..AUXILIARY)
            .into_par_iter()
            .map_init(
                || Workspace::new(model),
                |ws, index| {
                    let ws = ws.as_mut().map_err(|e| e.clone())?;
                    let mut a = Activations::neutral();
                    a.set_index(index, 1.0).expect("1.0 is in range");
                    let (state, _) = solve_from_rest(model, &a, ws, params)?;
                    Ok(displacement(&state.positions, &rest))
                },
            )
            .collect::<Result<Vec<Vec<f64>>, SolveError>>()?;
        Ok(LinearBasis {
            vertex_count: model.vertex_count(),
            rest,
            fields,
        })
    }

    /// The first `count` node positions for `a`, written into `out`.
    fn combine(&self, a: &Activations, count: usize, out: &mut Vec<V3>) {
        out.clear();
        out.extend_from_slice(&self.rest[..count]);
        let values = a.values();
        for (index, field) in self.fields.iter().enumerate() {
            let c = coefficient(index, values[index]);
            if c != 0.0 {
                for (p, w) in out.iter_mut().zip(field.chunks_exact(3)) {
                    p[0] += c * w[0];
                    p[1] += c * w[1];
                    p[2] += c * w[2];
                }
            }
        }
    }

    /// Surface positions for `a`, written into `out` (resized to the vertex count).
    pub fn evaluate(&self, a: &Activations, out: &mut Vec<V3>) {
        self.combine(a, self.vertex_count, out);
    }

    /// Positions of every node for `a`.
    pub fn predict(&self, a: &Activations) -> Vec<V3> {
        let mut out = Vec::with_capacity(self.rest.len());
        self.combine(a, self.rest.len(), &mut out);
        out
    }
}
