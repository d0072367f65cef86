//! The caller-owned scratch memory of a solve: matrix values, factor, gradient, step.

use faer::dyn_stack::{MemBuffer, MemStack, StackReq};
use faer::linalg::cholesky::llt::factor::LltRegularization;
use faer::sparse::linalg::cholesky::LltRef;
use faer::sparse::SparseColMatRef;
use faer::{Conj, MatMut, Par, Side};

use crate::sim::geom::V3;
use crate::sim::model::FaceModel;

use super::*;

/// Scratch memory for solving one model, owned by the caller and reused across solves: no
/// allocation happens inside a Newton iteration.
pub struct Workspace {
    pub(super) pattern: Pattern,
    pub(super) values: Vec<f64>,
    pub(super) factor: Vec<f64>,
    pub(super) stack: MemBuffer,
    pub(super) gradient: Vec<f64>,
    pub(super) step: Vec<f64>,
    pub(super) trial: Vec<V3>,
}

impl Workspace {
    /// The workspace of `model`: its Hessian's pattern in fill-reducing order and the
    /// symbolic Cholesky analysis, done once. An error if the analysis fails (a malformed
    /// model), never a panic.
    pub fn new(model: &FaceModel) -> Result<Workspace, SolveError> {
        let pattern = Pattern::new(model)?;
        let nnz = pattern.symbolic.row_idx().len();
        let dof = pattern.dof;
        let chol = &pattern.cholesky;
        let req = StackReq::any_of(&[
            chol.factorize_numeric_llt_scratch::<f64>(Par::Seq, Default::default()),
            chol.solve_in_place_scratch::<f64>(1, Par::Seq),
        ]);
        Ok(Workspace {
            values: vec![0.0; nnz],
            factor: vec![0.0; chol.len_val()],
            stack: MemBuffer::new(req),
            gradient: vec![0.0; dof],
            step: vec![0.0; dof],
            trial: Vec::new(),
            pattern,
        })
    }

    /// Free degrees of freedom.
    pub fn dof(&self) -> usize {
        self.pattern.dof
    }

    /// Stored entries of the Hessian (lower triangle).
    pub fn hessian_nonzeros(&self) -> usize {
        self.values.len()
    }

    /// Stored entries of its Cholesky factor.
    pub fn factor_nonzeros(&self) -> usize {
        self.factor.len()
    }

    /// Factorises the assembled Hessian into `factor`. Returns false if the matrix is not
    /// positive definite.
    pub(super) fn factorize(&mut self) -> bool {
        let mat = SparseColMatRef::new(self.pattern.matrix_pattern(), &self.values);
        self.pattern
            .cholesky
            .factorize_numeric_llt(
                &mut self.factor,
                mat,
                Side::Lower,
                LltRegularization::default(),
                Par::Seq,
                MemStack::new(&mut self.stack),
                Default::default(),
            )
            .is_ok()
    }

    /// Overwrites `rhs` with `H^-1 rhs` from the last successful `factorize`.
    pub(super) fn solve_factored(&mut self, rhs: &mut [f64]) {
        LltRef::new(&self.pattern.cholesky, &self.factor).solve_in_place_with_conj(
            Conj::No,
            MatMut::from_column_major_slice_mut(rhs, self.pattern.dof, 1),
            Par::Seq,
            MemStack::new(&mut self.stack),
        );
    }

    /// Factorises the assembled Hessian and overwrites `step` with `-H^-1 gradient`.
    /// Returns false if the matrix is not positive definite.
    pub(super) fn newton_step(&mut self) -> bool {
        if !self.factorize() {
            return false;
        }
        let mut step = std::mem::take(&mut self.step);
        for (s, g) in step.iter_mut().zip(&self.gradient) {
            *s = -g;
        }
        self.solve_factored(&mut step);
        self.step = step;
        self.step.iter().all(|v| v.is_finite())
    }

    /// Adds `by` to every diagonal entry of the assembled Hessian.
    pub(super) fn shift_diagonal(&mut self, by: f64) {
        for d in &self.pattern.diag {
            for k in [0, 4, 8] {
                self.values[d[k] as usize] += by;
            }
        }
    }

    /// Inverse iteration on the assembled Hessian: factorises it once, then replaces `v` by
    /// `H^-1 v`, normalised, `iterations` times, so `v` turns toward the eigenvector of the
    /// smallest eigenvalue. Returns false if the matrix is not positive definite.
    pub(super) fn inverse_iteration(&mut self, v: &mut [f64], iterations: usize) -> bool {
        if !self.factorize() {
            return false;
        }
        for _ in 0..iterations {
            self.solve_factored(v);
            let length = dot_slices(v, v).sqrt();
            if !length.is_finite() || length == 0.0 {
                return false;
            }
            v.iter_mut().for_each(|x| *x /= length);
        }
        true
    }

    /// `H v` from the assembled lower-triangle values.
    pub(super) fn hessian_times(&self, v: &[f64]) -> Vec<f64> {
        let sym = self.pattern.symbolic.as_ref();
        let (cp, ri) = (sym.col_ptr(), sym.row_idx());
        let mut out = vec![0.0; v.len()];
        for col in 0..self.pattern.dof {
            for k in cp[col]..cp[col + 1] {
                let (row, h) = (ri[k], self.values[k]);
                out[row] += h * v[col];
                if row != col {
                    out[col] += h * v[row];
                }
            }
        }
        out
    }
}
