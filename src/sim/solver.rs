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

use std::collections::BTreeMap;

use faer::dyn_stack::{MemBuffer, MemStack, StackReq};
use faer::linalg::cholesky::llt::factor::LltRegularization;
use faer::sparse::linalg::amd;
use faer::sparse::linalg::cholesky::{
    factorize_symbolic_cholesky, CholeskySymbolicParams, LltRef, SymbolicCholesky,
    SymmetricOrdering,
};
use faer::sparse::linalg::SupernodalThreshold;
use faer::sparse::{SparseColMatRef, SymbolicSparseColMat, SymbolicSparseColMatRef};
use faer::{Conj, MatMut, Par, Side};

use super::basis::LinearBasis;
use super::controls::Activations;
use super::geom::{dot, norm, scale, sub, V3};
use super::model::{FaceModel, Pose, State};
use super::muscles::MuscleKind;
use super::tissue::{prism_volume, prism_volume_derivatives};

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

#[derive(Debug, thiserror::Error, PartialEq)]
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
}

const NONE: u32 = u32::MAX;

/// Sparse structure of the Hessian over free degrees of freedom (lower triangle, CSC) and
/// where each element's blocks land in it.
///
/// Free nodes are numbered in an approximate-minimum-degree order of the node graph, so the
/// matrix is assembled already in fill-reducing order: the Cholesky factorisation needs no
/// permutation, and each node's three coordinates stay together in one supernode.
struct Pattern {
    dof: usize,
    /// Free index of each node (in elimination order), or NONE.
    free_index: Vec<u32>,
    symbolic: SymbolicSparseColMat<usize>,
    cholesky: SymbolicCholesky<usize>,
    /// Per free node: slots of its diagonal block (upper entries NONE).
    diag: Vec<[u32; 9]>,
    /// Per spring: slots of the (a, b) off-diagonal block, row = larger free index.
    spring_off: Vec<[u32; 9]>,
    /// Per prism: slots of each (i, j) local pair with i > j where both are free.
    prism_off: Vec<[[u32; 9]; 15]>,
    /// Per ordered pair of distinct lip margin nodes: slots of its (row, column) block.
    lip_off: BTreeMap<(usize, usize), [u32; 9]>,
}

const PRISM_PAIRS: [(usize, usize); 15] = {
    let mut out = [(0, 0); 15];
    let mut k = 0;
    let mut i = 1;
    while i < 6 {
        let mut j = 0;
        while j < i {
            out[k] = (i, j);
            k += 1;
            j += 1;
        }
        i += 1;
    }
    out
};

/// Pairs of nodes coupled by an element.
fn element_links(model: &FaceModel) -> impl Iterator<Item = (usize, usize)> + '_ {
    let springs = model
        .tissue
        .springs
        .iter()
        .map(|s| (s.nodes[0], s.nodes[1]));
    let prisms = model
        .tissue
        .prisms
        .iter()
        .flat_map(|p| PRISM_PAIRS.map(|(i, j)| (p.nodes[i], p.nodes[j])));
    // Every pair of lip margin nodes: a contact couples a vertex with whichever segment of
    // the other lip it has slid over.
    let lip_nodes: Vec<usize> = model.lips.nodes().collect();
    let lips = (0..lip_nodes.len())
        .flat_map(move |i| (0..i).map(move |j| (i, j)))
        .map(move |(i, j)| (lip_nodes[i], lip_nodes[j]));
    springs.chain(prisms).chain(lips)
}

/// An approximate minimum degree order of the free nodes: `order[old] = new`, where `old`
/// numbers the free nodes in node order.
fn node_order(model: &FaceModel, old_index: &[u32], nf: usize) -> Vec<u32> {
    let mut adj: Vec<Vec<usize>> = vec![Vec::new(); nf];
    for (a, b) in element_links(model) {
        let (fa, fb) = (old_index[a], old_index[b]);
        if fa != NONE && fb != NONE && fa != fb {
            adj[fa as usize].push(fb as usize);
            adj[fb as usize].push(fa as usize);
        }
    }
    let mut col_ptr = vec![0usize];
    let mut row_idx = Vec::new();
    for rows in &mut adj {
        rows.sort_unstable();
        rows.dedup();
        row_idx.extend_from_slice(rows);
        col_ptr.push(row_idx.len());
    }
    let nnz = row_idx.len();
    let graph = SymbolicSparseColMat::new_checked(nf, nf, col_ptr, None, row_idx);
    let mut perm = vec![0usize; nf];
    let mut perm_inv = vec![0usize; nf];
    let mut buffer = MemBuffer::new(amd::order_scratch::<usize>(nf, nnz));
    amd::order(
        &mut perm,
        &mut perm_inv,
        graph.as_ref(),
        amd::Control::default(),
        MemStack::new(&mut buffer),
    )
    .expect("AMD ordering of the tissue graph");
    perm_inv.iter().map(|&n| n as u32).collect()
}

impl Pattern {
    fn new(model: &FaceModel) -> Pattern {
        let mut free_index = vec![NONE; model.node_count()];
        let mut count = 0u32;
        for (node, &f) in model.free.iter().enumerate() {
            if f {
                free_index[node] = count;
                count += 1;
            }
        }
        let nf = count as usize;
        let order = node_order(model, &free_index, nf);
        for f in free_index.iter_mut().filter(|f| **f != NONE) {
            *f = order[*f as usize];
        }
        let dof = 3 * nf;
        // Node adjacency (lower: row node >= column node).
        let mut adj: Vec<Vec<u32>> = (0..nf as u32).map(|f| vec![f]).collect();
        for (a, b) in element_links(model) {
            let (fa, fb) = (free_index[a], free_index[b]);
            if fa != NONE && fb != NONE && fa != fb {
                adj[fa.min(fb) as usize].push(fa.max(fb));
            }
        }
        for a in &mut adj {
            a.sort_unstable();
            a.dedup();
        }
        // CSC: column 3*lo + dj holds rows 3*hi + di for hi in adj[lo], lower part only.
        let mut col_ptr = Vec::with_capacity(dof + 1);
        let mut row_idx = Vec::new();
        col_ptr.push(0usize);
        for (lo, rows) in adj.iter().enumerate() {
            for dj in 0..3 {
                let col = 3 * lo + dj;
                for &hi in rows {
                    for di in 0..3 {
                        let row = 3 * hi as usize + di;
                        if row >= col {
                            row_idx.push(row);
                        }
                    }
                }
                col_ptr.push(row_idx.len());
            }
        }
        let slot = |row: usize, col: usize| -> u32 {
            let start = col_ptr[col];
            let rows = &row_idx[start..col_ptr[col + 1]];
            (start + rows.binary_search(&row).expect("entry in pattern")) as u32
        };
        let block = |hi: u32, lo: u32| -> [u32; 9] {
            let mut out = [NONE; 9];
            for di in 0..3 {
                for dj in 0..3 {
                    let (row, col) = (3 * hi as usize + di, 3 * lo as usize + dj);
                    if row >= col {
                        out[3 * di + dj] = slot(row, col);
                    }
                }
            }
            out
        };
        let diag = (0..nf as u32).map(|f| block(f, f)).collect();
        let pair_block = |a: usize, b: usize| -> [u32; 9] {
            let (fa, fb) = (free_index[a], free_index[b]);
            if fa == NONE || fb == NONE {
                return [NONE; 9];
            }
            // Block (a, b) of the element; stored transposed when a's index is smaller.
            if fa > fb {
                block(fa, fb)
            } else {
                let t = block(fb, fa);
                [t[0], t[3], t[6], t[1], t[4], t[7], t[2], t[5], t[8]]
            }
        };
        let spring_off = model
            .tissue
            .springs
            .iter()
            .map(|s| pair_block(s.nodes[0], s.nodes[1]))
            .collect();
        let prism_off = model
            .tissue
            .prisms
            .iter()
            .map(|p| PRISM_PAIRS.map(|(i, j)| pair_block(p.nodes[i], p.nodes[j])))
            .collect();
        let mut lip_off = BTreeMap::new();
        for a in model.lips.nodes() {
            for b in model.lips.nodes().filter(|&b| b != a) {
                lip_off.insert((a, b), pair_block(a, b));
            }
        }
        // The symbolic analysis without a permutation reads the upper triangle: the same
        // pattern transposed. The numeric factorisation then takes the lower values as they are.
        let mut upper_ptr = vec![0usize; dof + 1];
        for &row in &row_idx {
            upper_ptr[row + 1] += 1;
        }
        for c in 0..dof {
            upper_ptr[c + 1] += upper_ptr[c];
        }
        let mut upper_idx = vec![0usize; row_idx.len()];
        let mut next = upper_ptr.clone();
        for col in 0..dof {
            for &row in &row_idx[col_ptr[col]..col_ptr[col + 1]] {
                upper_idx[next[row]] = col;
                next[row] += 1;
            }
        }
        let upper = SymbolicSparseColMat::new_checked(dof, dof, upper_ptr, None, upper_idx);
        let symbolic = SymbolicSparseColMat::new_checked(dof, dof, col_ptr, None, row_idx);
        let cholesky = factorize_symbolic_cholesky(
            upper.as_ref(),
            Side::Upper,
            SymmetricOrdering::Identity,
            CholeskySymbolicParams {
                supernodal_flop_ratio_threshold: SupernodalThreshold::FORCE_SUPERNODAL,
                ..Default::default()
            },
        )
        .expect("symbolic Cholesky of the tissue pattern");
        Pattern {
            dof,
            free_index,
            symbolic,
            cholesky,
            diag,
            spring_off,
            prism_off,
            lip_off,
        }
    }

    fn matrix_pattern(&self) -> SymbolicSparseColMatRef<'_, usize> {
        self.symbolic.as_ref()
    }
}

/// Scratch memory for solving one model, owned by the caller and reused across solves: no
/// allocation happens inside a Newton iteration.
pub struct Workspace {
    pattern: Pattern,
    values: Vec<f64>,
    factor: Vec<f64>,
    stack: MemBuffer,
    gradient: Vec<f64>,
    step: Vec<f64>,
    trial: Vec<V3>,
}

impl Workspace {
    pub fn new(model: &FaceModel) -> Workspace {
        let pattern = Pattern::new(model);
        let nnz = pattern.symbolic.row_idx().len();
        let dof = pattern.dof;
        let chol = &pattern.cholesky;
        let req = StackReq::any_of(&[
            chol.factorize_numeric_llt_scratch::<f64>(Par::Seq, Default::default()),
            chol.solve_in_place_scratch::<f64>(1, Par::Seq),
        ]);
        Workspace {
            values: vec![0.0; nnz],
            factor: vec![0.0; chol.len_val()],
            stack: MemBuffer::new(req),
            gradient: vec![0.0; dof],
            step: vec![0.0; dof],
            trial: Vec::new(),
            pattern,
        }
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
    fn factorize(&mut self) -> bool {
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
    fn solve_factored(&mut self, rhs: &mut [f64]) {
        LltRef::new(&self.pattern.cholesky, &self.factor).solve_in_place_with_conj(
            Conj::No,
            MatMut::from_column_major_slice_mut(rhs, self.pattern.dof, 1),
            Par::Seq,
            MemStack::new(&mut self.stack),
        );
    }

    /// Factorises the assembled Hessian and overwrites `step` with `-H^-1 gradient`.
    /// Returns false if the matrix is not positive definite.
    fn newton_step(&mut self) -> bool {
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
    fn shift_diagonal(&mut self, by: f64) {
        for d in &self.pattern.diag {
            for k in [0, 4, 8] {
                self.values[d[k] as usize] += by;
            }
        }
    }

    /// Inverse iteration on the assembled Hessian: factorises it once, then replaces `v` by
    /// `H^-1 v`, normalised, `iterations` times, so `v` turns toward the eigenvector of the
    /// smallest eigenvalue. Returns false if the matrix is not positive definite.
    fn inverse_iteration(&mut self, v: &mut [f64], iterations: usize) -> bool {
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
    fn hessian_times(&self, v: &[f64]) -> Vec<f64> {
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

/// Adds a symmetric 3x3 block `k` (row-major) to the slots.
#[inline]
fn add_block(values: &mut [f64], slots: &[u32; 9], k: &[[f64; 3]; 3], sign: f64) {
    for di in 0..3 {
        for dj in 0..3 {
            let s = slots[3 * di + dj];
            if s != NONE {
                values[s as usize] += sign * k[di][dj];
            }
        }
    }
}

#[inline]
fn outer(a: V3, b: V3, s: f64) -> [[f64; 3]; 3] {
    let mut m = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            m[i][j] = s * a[i] * b[j];
        }
    }
    m
}

/// `c1 * I + c2 * u u^T`.
#[inline]
fn iso_plus_outer(c1: f64, u: V3, c2: f64) -> [[f64; 3]; 3] {
    let mut m = outer(u, u, c2);
    for (i, row) in m.iter_mut().enumerate() {
        row[i] += c1;
    }
    m
}

/// Spring energy, force magnitude dE/dl and tangent stiffness d2E/dl2 at length `l`.
#[inline]
fn spring_law(s: &super::tissue::Spring, l: f64, strain: f64, factor: f64) -> (f64, f64, f64) {
    let e = l - s.rest;
    let knee = strain * s.rest;
    if s.biphasic && e > knee {
        let extra = e - knee;
        let energy =
            0.5 * s.k * knee * knee + s.k * knee * extra + 0.5 * s.k * factor * extra * extra;
        (energy, s.k * knee + s.k * factor * extra, s.k * factor)
    } else {
        (0.5 * s.k * e * e, s.k * e, s.k)
    }
}

/// Weight of the logarithmic barrier in the volume energy: it grows without bound as a
/// prism's volume goes to zero, so Newton steps see inversion coming instead of being cut
/// short by the line search.
const VOLUME_BARRIER: f64 = 0.2;

/// `[e]_x s`, the matrix of `v -> s e x v`.
#[inline]
fn skew(e: V3, s: f64) -> [[f64; 3]; 3] {
    [
        [0.0, -s * e[2], s * e[1]],
        [s * e[2], 0.0, -s * e[0]],
        [-s * e[1], s * e[0], 0.0],
    ]
}

/// Shear modulus of prism `p` (Pa): its slab's Young's modulus times
/// `TissueParams::shear_modulus_fraction / 3`.
fn shear_modulus(model: &FaceModel, p: &super::tissue::Prism) -> f64 {
    let tp = &model.params.tissue;
    let e = [
        tp.epidermis_modulus,
        tp.dermal_fatty_modulus,
        tp.muscle_layer_modulus,
    ][p.nodes[0] / model.vertex_count()];
    tp.shear_modulus_fraction * e / 3.0
}

/// The prism's node positions relative to its first node, `r`, and the Gram term's force on
/// each node, `S r` (per coordinate): `x^T S x / 2 = sum_a r_a . (S r)_a / 2`. Relative
/// positions are exact (rows of S sum to zero) and keep the sums free of cancellation.
fn gram_forces(p: &super::tissue::Prism, x: &[V3]) -> ([V3; 6], [V3; 6]) {
    let origin = x[p.nodes[0]];
    let r = p.nodes.map(|i| sub(x[i], origin));
    let forces = p.gram.map(|row| {
        let mut f = [0.0; 3];
        for (s, rb) in row.iter().zip(&r) {
            for d in 0..3 {
                f[d] += s * rb[d];
            }
        }
        f
    });
    (r, forces)
}

/// Total energy at `x` (J), or infinity if a prism is inverted (signed volume <= 0). A prism
/// of the thin muscle layer may shear so far that one of its tetrahedra turns over while the
/// prism keeps its volume: that is the fascia sliding over the skull, not an inversion.
fn energy(model: &FaceModel, pose: &Pose, x: &[V3]) -> f64 {
    let tp = &model.params.tissue;
    let mut e = 0.0;
    for s in &model.tissue.springs {
        let l = norm(sub(x[s.nodes[1]], x[s.nodes[0]]));
        e += spring_law(
            s,
            l,
            tp.epidermis_stiffening_strain,
            tp.epidermis_stiffening_factor,
        )
        .0;
    }
    for p in &model.tissue.prisms {
        let volume = prism_volume(&p.nodes.map(|i| x[i]));
        if volume <= 0.0 {
            return f64::INFINITY;
        }
        let j = volume / p.rest_volume;
        e += tp.volume_modulus
            * p.rest_volume
            * (0.5 * (j - 1.0).powi(2) + VOLUME_BARRIER * (j - 1.0 - j.ln()));
        let mu = shear_modulus(model, p);
        if mu > 0.0 {
            let (r, forces) = gram_forces(p, x);
            let distortion: f64 = r.iter().zip(&forces).map(|(ra, fa)| dot(*ra, *fa)).sum();
            e += mu * (0.5 * distortion - p.rest_volume * j.ln());
        }
    }
    for (c, &(anchor, normal)) in model.contacts.iter().zip(&pose.skull) {
        let gap = dot(sub(x[c.node], anchor), normal) - c.clearance;
        if gap < 0.0 {
            e += 0.5 * tp.skull_contact_stiffness * gap * gap;
        }
    }
    for c in model.lips.active(x) {
        e += 0.5 * tp.lip_contact_stiffness * c.gap * c.gap;
    }
    let act = pose.activations.values();
    for (i, m) in model.muscles.iter().enumerate() {
        let a = act[i];
        if a == 0.0 {
            continue;
        }
        let target = pose.targets[i];
        for &(node, f) in &m.nodes {
            let d = sub(x[node], target);
            let r = match m.kind {
                MuscleKind::Sphincter { vertical, core, .. } => {
                    (d[0] * d[0] + (vertical * d[1]).powi(2) + core * core).sqrt() - core
                }
                _ => norm(d),
            };
            e += a * f * r;
        }
    }
    e
}

/// Gradient over free dofs, and (when `hessian`) the Hessian values.
fn assemble(
    model: &FaceModel,
    pose: &Pose,
    x: &[V3],
    ws: &mut Workspace,
    hessian: bool,
    full: bool,
) {
    let tp = &model.params.tissue;
    let pat = &ws.pattern;
    let g = &mut ws.gradient;
    let h = &mut ws.values;
    g.fill(0.0);
    if hessian {
        h.fill(0.0);
    }
    let add_grad = |g: &mut [f64], node: usize, v: V3, sign: f64| {
        let f = pat.free_index[node];
        if f != NONE {
            let f = 3 * f as usize;
            g[f] += sign * v[0];
            g[f + 1] += sign * v[1];
            g[f + 2] += sign * v[2];
        }
    };
    let add_diag = |h: &mut [f64], node: usize, k: &[[f64; 3]; 3]| {
        let f = pat.free_index[node];
        if f != NONE {
            add_block(h, &pat.diag[f as usize], k, 1.0);
        }
    };
    for (si, s) in model.tissue.springs.iter().enumerate() {
        let [a, b] = s.nodes;
        let d = sub(x[b], x[a]);
        let l = norm(d);
        let u = scale(d, 1.0 / l);
        let (_, force, kt) = spring_law(
            s,
            l,
            tp.epidermis_stiffening_strain,
            tp.epidermis_stiffening_factor,
        );
        let fv = scale(u, force);
        add_grad(g, a, fv, -1.0);
        add_grad(g, b, fv, 1.0);
        if hessian {
            // kt u u^T + max(f/l, 0) (I - u u^T): the compressive geometric term is dropped
            // so the block stays positive semi-definite.
            let geo = if full {
                force / l
            } else {
                (force / l).max(0.0)
            };
            let k = iso_plus_outer(geo, u, kt - geo);
            add_diag(h, a, &k);
            add_diag(h, b, &k);
            add_block(h, &pat.spring_off[si], &k, -1.0);
        }
    }
    for (pi, p) in model.tissue.prisms.iter().enumerate() {
        let (v, dv, hv) = prism_volume_derivatives(&p.nodes.map(|i| x[i]));
        // psi(J) = kappa V0 (0.5 (J - 1)^2 + b (J - 1 - ln J)), J = V / V0:
        // grad = kappa (J - 1 + b (1 - 1/J)) grad V,
        // hess = kappa (1 + b / J^2) / V0 grad V grad V^T + kappa (J - 1 + b (1 - 1/J)) hess V.
        let j = v / p.rest_volume;
        let mut coef = tp.volume_modulus * (j - 1.0 + VOLUME_BARRIER * (1.0 - 1.0 / j));
        let mut c = tp.volume_modulus * (1.0 + VOLUME_BARRIER / (j * j)) / p.rest_volume;
        let mu = shear_modulus(model, p);
        if mu > 0.0 {
            // mu (x^T S x / 2 - V0 ln J): grad = mu S x - (mu / J) grad V,
            // hess = mu S (x) I + mu / (V0 J^2) grad V grad V^T - (mu / J) hess V.
            coef -= mu / j;
            c += mu / (p.rest_volume * j * j);
            for (&node, f) in p.nodes.iter().zip(gram_forces(p, x).1) {
                add_grad(g, node, f, mu);
            }
            if hessian {
                for a in 0..6 {
                    add_diag(
                        h,
                        p.nodes[a],
                        &iso_plus_outer(mu * p.gram[a][a], [0.0; 3], 0.0),
                    );
                }
                for (slots, &(a, b)) in pat.prism_off[pi].iter().zip(&PRISM_PAIRS) {
                    let k = iso_plus_outer(mu * p.gram[a][b], [0.0; 3], 0.0);
                    add_block(h, slots, &k, 1.0);
                }
            }
        }
        for k in 0..6 {
            add_grad(g, p.nodes[k], dv[k], coef);
        }
        if hessian {
            // c grad V grad V^T, plus (full) coef hess V; hess V has zero diagonal blocks.
            for k in 0..6 {
                add_diag(h, p.nodes[k], &outer(dv[k], dv[k], c));
            }
            for (slots, &(a, b)) in pat.prism_off[pi].iter().zip(&PRISM_PAIRS) {
                if slots[0] != NONE {
                    let mut k = outer(dv[a], dv[b], c);
                    if full {
                        let second = skew(hv[a][b], coef);
                        for r in 0..3 {
                            for s in 0..3 {
                                k[r][s] += second[r][s];
                            }
                        }
                    }
                    add_block(h, slots, &k, 1.0);
                }
            }
        }
    }
    for (c, &(anchor, normal)) in model.contacts.iter().zip(&pose.skull) {
        let gap = dot(sub(x[c.node], anchor), normal) - c.clearance;
        if gap < 0.0 {
            add_grad(g, c.node, normal, tp.skull_contact_stiffness * gap);
            if hessian {
                add_diag(
                    h,
                    c.node,
                    &outer(normal, normal, tp.skull_contact_stiffness),
                );
            }
        }
    }
    // Lip contact: k gap grad(gap), and k (grad grad^T + gap hess) (the curvature term only
    // for the full Hessian; without it the block stays positive semi-definite).
    let k = tp.lip_contact_stiffness;
    for c in model.lips.active(x) {
        for (i, &node) in c.nodes.iter().enumerate() {
            add_grad(g, node, [c.grad[2 * i], c.grad[2 * i + 1], 0.0], k * c.gap);
        }
        if hessian {
            let local = |r: usize, s: usize| {
                let curvature = if full { c.gap * c.hess[r][s] } else { 0.0 };
                k * (c.grad[r] * c.grad[s] + curvature)
            };
            for i in 0..3 {
                for j in 0..3 {
                    let mut block = [[0.0; 3]; 3];
                    for r in 0..2 {
                        for s in 0..2 {
                            block[r][s] = local(2 * i + r, 2 * j + s);
                        }
                    }
                    if i == j {
                        add_diag(h, c.nodes[i], &block);
                    } else if let Some(slots) = pat.lip_off.get(&(c.nodes[i], c.nodes[j])) {
                        // Each unordered pair's block is stored once (the lower triangle);
                        // the (i, j) and (j, i) loops each add their half of it.
                        add_block(h, slots, &block, 0.5);
                    }
                }
            }
        }
    }
    let act = pose.activations.values();
    for (i, m) in model.muscles.iter().enumerate() {
        let a = act[i];
        if a == 0.0 {
            continue;
        }
        let target = pose.targets[i];
        for &(node, f) in &m.nodes {
            let d = sub(x[node], target);
            let mag = a * f;
            match m.kind {
                MuscleKind::Sphincter { vertical, core, .. } => {
                    // U = mag (rho - c), rho = sqrt(d^T D d + c^2), D = diag(1, k^2, 0):
                    // grad = mag D d / rho, hess = mag (D / rho - (D d)(D d)^T / rho^3).
                    let k2 = vertical * vertical;
                    let dd = [d[0], k2 * d[1], 0.0];
                    let rho = (d[0] * d[0] + k2 * d[1] * d[1] + core * core).sqrt();
                    add_grad(g, node, dd, mag / rho);
                    if hessian {
                        let mut k = outer(dd, dd, -mag / rho.powi(3));
                        k[0][0] += mag / rho;
                        k[1][1] += mag * k2 / rho;
                        add_diag(h, node, &k);
                    }
                }
                _ => {
                    let r = norm(d);
                    if r < 1e-12 {
                        continue;
                    }
                    let u = scale(d, 1.0 / r);
                    add_grad(g, node, u, mag);
                    if hessian {
                        add_diag(h, node, &iso_plus_outer(mag / r, u, -mag / r));
                    }
                }
            }
        }
    }
}

/// The rest positions with the fixed nodes where `pose` puts them: the reference state whose
/// force imbalance scales the residual.
fn rest_under(model: &FaceModel, pose: &Pose) -> Vec<V3> {
    let mut rest = model.tissue.rest.clone();
    for (node, p) in rest.iter_mut().enumerate() {
        if !model.free[node] {
            *p = pose.fixed[node];
        }
    }
    rest
}

fn gradient_norm(ws: &Workspace) -> f64 {
    ws.gradient.iter().map(|v| v * v).sum::<f64>().sqrt()
}

/// Force imbalance (N) below which a pose counts as unloaded.
const NO_LOAD: f64 = 1e-9;

/// What a Newton iteration does where the exact Hessian is indefinite.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Curvature {
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
fn newton(
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

/// Solves for `target` from the linear basis' prediction of its equilibrium: one Newton solve
/// at the target, with no continuation, which is what makes sampling many random faces cheap.
/// If the prediction inverts an element or Newton does not converge from it, falls back to
/// `solve_from_rest`; the report's iterations include the failed attempt.
pub fn solve_predicted(
    model: &FaceModel,
    basis: &LinearBasis,
    target: &Activations,
    ws: &mut Workspace,
    params: &SolveParams,
) -> Result<(State, SolveReport), SolveError> {
    let pose = model.pose(target);
    let mut positions = basis.predict(target);
    for (node, p) in positions.iter_mut().enumerate() {
        if !model.free[node] {
            *p = pose.fixed[node];
        }
    }
    let mut state = State {
        positions,
        activations: target.clone(),
    };
    let spent = match newton(
        model,
        &pose,
        &mut state,
        ws,
        params,
        Curvature::SemiDefinite,
    ) {
        Ok(report) => return Ok((state, report)),
        Err(SolveError::NotConverged { iterations, .. }) => iterations,
        Err(_) => 0,
    };
    let (state, mut report) = solve_from_rest(model, target, ws, params)?;
    report.iterations += spent;
    Ok((state, report))
}

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
fn lowest_eigenpair(ws: &mut Workspace, iterations: usize) -> Option<(f64, Vec<f64>, f64)> {
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

fn dot_slices(a: &[f64], b: &[f64]) -> f64 {
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::mesh::{default_mesh_path, read_obj};
    use crate::rng::stream;
    use crate::sim::model::FaceParams;

    fn model() -> FaceModel {
        let mesh = read_obj(&default_mesh_path()).unwrap();
        FaceModel::new(&mesh, FaceParams::default()).unwrap()
    }

    /// LTW95's springs without the prisms' shear term.
    fn springs_only_model() -> FaceModel {
        let mesh = read_obj(&default_mesh_path()).unwrap();
        let mut params = FaceParams::default();
        params.tissue.shear_modulus_fraction = 0.0;
        FaceModel::new(&mesh, params).unwrap()
    }

    #[test]
    fn softest_mode_is_an_eigenpair_below_every_rayleigh_quotient() {
        let m = model();
        let mut a = Activations::neutral();
        for (name, v) in [
            ("zygomaticus_major_left", 0.9),
            ("zygomaticus_major_right", 0.9),
            ("jaw_rotation", 0.3),
        ] {
            a.set(name, v).unwrap();
        }
        let mut ws = Workspace::new(&m);
        let (state, _) = solve_from_rest(&m, &a, &mut ws, &SolveParams::default()).unwrap();
        let mut rng = stream(3, "test/softest_mode");
        for exact in [true, false] {
            let mode = softest_mode(&m, &state, &mut ws, exact, 200).expect("a finite Hessian");
            assert!(mode.stiffness > 0.0, "{mode:?}");
            assert!(mode.eigen_residual < 1e-2, "{mode:?}");
            assert!((0.0..=1.0 + 1e-12).contains(&mode.vertex_share), "{mode:?}");
            assert!(m.free[mode.vertex], "{mode:?}");
            // The smallest eigenvalue bounds the Rayleigh quotient of every direction.
            for _ in 0..20 {
                let v: Vec<f64> = (0..ws.dof()).map(|_| rng.normal()).collect();
                let q = dot_slices(&ws.hessian_times(&v), &v) / dot_slices(&v, &v);
                assert!(
                    mode.stiffness <= q,
                    "{} > Rayleigh quotient {q}",
                    mode.stiffness
                );
            }
        }
    }

    #[test]
    fn a_negative_softest_mode_is_negative_curvature_of_the_energy() {
        // Every free node drawn 2% toward the face's centre compresses the springs; their
        // geometric stiffness then makes the exact Hessian indefinite (without the prisms'
        // shear term, which holds the compressed columns upright).
        let m = springs_only_model();
        let mut state = m.rest_state();
        let count = state.positions.len() as f64;
        let centre = state.positions.iter().fold([0.0; 3], |c, p| {
            [
                c[0] + p[0] / count,
                c[1] + p[1] / count,
                c[2] + p[2] / count,
            ]
        });
        for (node, p) in state.positions.iter_mut().enumerate() {
            if m.free[node] {
                *p = [0, 1, 2].map(|c| centre[c] + 0.98 * (p[c] - centre[c]));
            }
        }
        let pose = m.pose(&state.activations);
        let mut ws = Workspace::new(&m);
        assemble(&m, &pose, &state.positions, &mut ws, true, true);
        let (lambda, v, residual) = lowest_eigenpair(&mut ws, 80).expect("a finite Hessian");
        assert!(lambda < 0.0, "smallest eigenvalue {lambda}");
        assert!(residual < 1e-2, "eigen residual {residual}");
        let mode = softest_mode(&m, &state, &mut ws, true, 80).unwrap();
        assert_eq!(mode.stiffness, lambda);
        // The energy's second difference along the mode is its eigenvalue.
        let along = |t: f64| {
            let mut y = state.positions.clone();
            for (node, p) in y.iter_mut().enumerate() {
                let f = ws.pattern.free_index[node];
                if f != NONE {
                    for c in 0..3 {
                        p[c] += t * v[3 * f as usize + c];
                    }
                }
            }
            energy(&m, &pose, &y)
        };
        let t = 1e-6;
        let curvature = (along(t) - 2.0 * along(0.0) + along(-t)) / (t * t);
        assert!(
            (curvature - lambda).abs() <= 1e-3 * lambda.abs(),
            "energy curvature {curvature} against eigenvalue {lambda}"
        );
    }

    #[test]
    fn gradient_and_hessian_match_finite_differences() {
        check_derivatives(&model(), false);
    }

    #[test]
    fn gradient_and_hessian_match_finite_differences_without_prism_shear() {
        check_derivatives(&springs_only_model(), false);
    }

    #[test]
    fn gradient_and_hessian_match_finite_differences_with_the_lips_in_contact() {
        check_derivatives(&model(), true);
    }

    #[test]
    fn lip_contact_keeps_the_lips_from_passing_through_each_other() {
        // Zygomaticus major and levator anguli oris with the lower half of orbicularis oris
        // drive the lower lip up behind the upper one near the corners; without contact it
        // passes 2.4 mm through.
        let a = crossing_activations();
        let with = model();
        let without = no_lip_contact_model();
        let gap = |m: &FaceModel| {
            let mut ws = Workspace::new(m);
            let (s, _) = solve_from_rest(m, &a, &mut ws, &SolveParams::default()).unwrap();
            crate::sim::validity::defects(m, &s).min_lip_gap
        };
        let (open, contact) = (gap(&without), gap(&with));
        assert!(
            open < -1e-3,
            "without contact the lips overlap {:.2} mm",
            open * 1e3
        );
        assert!(
            contact > -crate::sim::validity::CROSSING_TOLERANCE,
            "with contact they overlap {:.2} mm",
            contact * 1e3
        );
    }

    fn crossing_activations() -> Activations {
        let mut a = Activations::neutral();
        for name in [
            "zygomaticus_major_left",
            "zygomaticus_major_right",
            "levator_anguli_oris_left",
            "levator_anguli_oris_right",
            "orbicularis_oris_lower_left",
            "orbicularis_oris_lower_right",
        ] {
            a.set(name, 1.0).unwrap();
        }
        a
    }

    fn no_lip_contact_model() -> FaceModel {
        let mesh = read_obj(&default_mesh_path()).unwrap();
        let mut params = FaceParams::default();
        params.tissue.lip_contact_stiffness = 0.0;
        FaceModel::new(&mesh, params).unwrap()
    }

    #[test]
    fn prism_shear_leaves_the_rest_face_unstressed_and_stiffens_it() {
        let (plain, sheared) = (springs_only_model(), model());
        let a = Activations::neutral();
        let pose = sheared.pose(&a);
        let rest = rest_under(&sheared, &pose);
        let mut ws = Workspace::new(&sheared);
        assemble(&sheared, &pose, &rest, &mut ws, false, false);
        // A single muscle at 1e-3 pulls with ~1e-3 N; the rest face must be far below that.
        assert!(
            gradient_norm(&ws) < 1e-12,
            "rest force {:e} N",
            gradient_norm(&ws)
        );
        // Sliding the surface sheet over the dermis (10 um, upward along the surface) costs
        // far more with the shear term: the crossing springs barely resist it. The thinned
        // lips stay put.
        let n = sheared.vertex_count();
        let mut slid = rest.clone();
        let tissue = &sheared.tissue;
        for (v, p) in slid[..n].iter_mut().enumerate() {
            if tissue.thickness_scale[v] < 1.0 {
                continue;
            }
            let normal = tissue.normals[v];
            let up = sub([0.0, 1.0, 0.0], scale(normal, normal[1]));
            let along = scale(up, 1e-5 / norm(up));
            *p = [p[0] + along[0], p[1] + along[1], p[2] + along[2]];
        }
        let cost = |m: &FaceModel| energy(m, &pose, &slid) - energy(m, &pose, &rest);
        assert!(
            cost(&sheared) > 5.0 * cost(&plain),
            "{} J against {} J",
            cost(&sheared),
            cost(&plain)
        );
    }

    /// With `lips_crossed`, the derivatives are taken at the equilibrium of the model without
    /// lip contact for activations that push the lips through each other, so the contact
    /// term is active.
    fn check_derivatives(m: &FaceModel, lips_crossed: bool) {
        let mut a = Activations::neutral();
        for (name, v) in [
            ("zygomaticus_major_left", 0.8),
            ("orbicularis_oris_upper_left", 0.5),
            ("orbicularis_oculi_orbital_right", 0.5),
            ("frontalis_medial_right", 0.6),
            ("jaw_rotation", 0.27),
        ] {
            a.set(name, v).unwrap();
        }
        if lips_crossed {
            a = crossing_activations();
        }
        let pose = m.pose(&a);
        let mut ws = Workspace::new(m);
        let mut rng = stream(7, "test/derivatives");
        let mut x = rest_under(m, &pose);
        if lips_crossed {
            let open = no_lip_contact_model();
            let mut ws = Workspace::new(&open);
            x = solve_from_rest(&open, &a, &mut ws, &SolveParams::default())
                .unwrap()
                .0
                .positions;
            let active = m.lips.active(&x);
            assert!(active.len() >= 2, "{} contacts", active.len());
            assert!(active.iter().all(|c| c.gap < -1e-3));
        }
        // Off equilibrium, so the gradient is large against the difference's error; less so
        // on the crossed lips, whose thin prisms would invert.
        let noise = if lips_crossed { 2e-6 } else { 2e-5 };
        for (node, p) in x.iter_mut().enumerate() {
            if m.free[node] {
                for c in p.iter_mut() {
                    *c += noise * rng.normal();
                }
            }
        }
        let dir: Vec<f64> = (0..ws.dof()).map(|_| rng.normal()).collect();
        let free_index = ws.pattern.free_index.clone();
        let moved = |t: f64| {
            let mut y = x.clone();
            for (node, p) in y.iter_mut().enumerate() {
                let f = free_index[node];
                if f != NONE {
                    for c in 0..3 {
                        p[c] += t * dir[3 * f as usize + c];
                    }
                }
            }
            y
        };
        // With crossed lips only the contact term is checked: the model without it is
        // subtracted, so the stiff tissue terms' difference error on the deformed lips does
        // not hide it.
        let reference = lips_crossed.then(no_lip_contact_model);
        let mut ws_ref = reference.as_ref().map(Workspace::new);
        let energy_of = |y: &[V3]| {
            energy(m, &pose, y) - reference.as_ref().map_or(0.0, |r| energy(r, &pose, y))
        };
        let mut gradient_of =
            |y: &[V3], ws: &mut Workspace, hessian: bool| -> (Vec<f64>, Vec<f64>) {
                assemble(m, &pose, y, ws, hessian, true);
                let (mut g, mut hv) = (ws.gradient.clone(), ws.hessian_times(&dir));
                if let (Some(r), Some(w)) = (reference.as_ref(), ws_ref.as_mut()) {
                    assemble(r, &pose, y, w, hessian, true);
                    let hr = w.hessian_times(&dir);
                    for i in 0..g.len() {
                        g[i] -= w.gradient[i];
                        hv[i] -= hr[i];
                    }
                }
                (g, hv)
            };
        let h = 1e-7;
        // The contact gap is a ratio over 5 mm segments: its third derivative makes the
        // central difference's own error about 3e-6 of the contact's directional derivative
        // at the best step (measured 2e-8 of 7.4e-3 at 1e-7, 1.3e-6 at 1e-6, 6e-8 at 1e-8).
        let tolerance = if lips_crossed { 1e-5 } else { 1e-6 };
        let (g0, hv) = gradient_of(&x, &mut ws, true);
        let analytic: f64 = g0.iter().zip(&dir).map(|(g, d)| g * d).sum();
        let numeric = (energy_of(&moved(h)) - energy_of(&moved(-h))) / (2.0 * h);
        assert!(
            analytic.abs() > 1e-3,
            "the checked terms are active: {analytic}"
        );
        assert!(
            (analytic - numeric).abs() <= tolerance * analytic.abs().max(1e-9),
            "directional derivative {analytic} vs finite difference {numeric}"
        );
        let (gp, _) = gradient_of(&moved(h), &mut ws, false);
        let (gm, _) = gradient_of(&moved(-h), &mut ws, false);
        let mut err = 0.0f64;
        let mut size = 0.0f64;
        for i in 0..hv.len() {
            let fd = (gp[i] - gm[i]) / (2.0 * h);
            err = err.max((fd - hv[i]).abs());
            size = size.max(fd.abs());
        }
        assert!(
            err <= 1e-5 * size,
            "Hessian-vector product off by {err} of {size}"
        );
    }
}
