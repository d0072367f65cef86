//! Linear muscle basis after Choe, Lee & Ko 2001 (their eq. 4): the surface as the rest
//! surface plus a weighted sum of per-control displacement fields, each computed once with the
//! nonlinear solver at that control's full activation. Jaw slide and twist, neutral at 0.5,
//! enter with weight `2 (value - 0.5)` on their field at 1.0.
//!
//! It costs microseconds per face instead of milliseconds, but ignores contact, stiffening
//! and the interaction of muscles; `bench solve` reports how far it is from the nonlinear face.

use super::controls::{Activations, AUXILIARY, CONTROL_COUNT, JAW_SLIDE, JAW_TWIST};
use super::geom::V3;
use super::model::FaceModel;
use super::solver::{solve_from_rest, SolveError, SolveParams, Workspace};

#[derive(Clone, Debug)]
pub struct LinearBasis {
    pub rest: Vec<V3>,
    /// Per control (auxiliary excluded): surface displacement field, flattened xyz.
    pub fields: Vec<Vec<f64>>,
}

/// The coefficient of a control's field for its input value.
fn coefficient(index: usize, value: f64) -> f64 {
    match index {
        JAW_SLIDE | JAW_TWIST => 2.0 * (value - 0.5),
        _ => value,
    }
}

impl LinearBasis {
    /// Solves the model once per control at full activation (slide, twist at 1.0).
    pub fn build(model: &FaceModel, params: &SolveParams) -> Result<LinearBasis, SolveError> {
        let n = model.vertex_count();
        let rest: Vec<V3> = model.tissue.rest[..n].to_vec();
        let mut ws = Workspace::new(model);
        let mut fields = Vec::with_capacity(AUXILIARY);
        for index in 0..AUXILIARY {
            let mut a = Activations::neutral();
            a.set_index(index, 1.0).expect("1.0 is in range");
            let (state, _) = solve_from_rest(model, &a, &mut ws, params)?;
            let field = (0..n)
                .flat_map(|v| {
                    let (p, r) = (state.positions[v], rest[v]);
                    [p[0] - r[0], p[1] - r[1], p[2] - r[2]]
                })
                .collect();
            fields.push(field);
        }
        Ok(LinearBasis { rest, fields })
    }

    /// Surface positions for `a`, written into `out` (resized to the vertex count).
    pub fn evaluate(&self, a: &Activations, out: &mut Vec<V3>) {
        let n = self.rest.len();
        let mut flat: Vec<f64> = Vec::with_capacity(3 * n);
        flat.extend(self.rest.iter().flatten());
        let values = a.values();
        for (index, field) in self.fields.iter().enumerate() {
            let c = coefficient(index, values[index]);
            if c != 0.0 {
                for (x, w) in flat.iter_mut().zip(field) {
                    *x += c * w;
                }
            }
        }
        out.clear();
        out.extend(flat.chunks_exact(3).map(|c| [c[0], c[1], c[2]]));
        debug_assert!(self.fields.len() < CONTROL_COUNT);
    }
}
