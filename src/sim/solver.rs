//! Quasi-static equilibrium of the face: the free node positions minimising the tissue's
//! elastic energy plus the muscles' potential, for fixed activations.
//!
//! Newton's method on the total energy with per-element positive semi-definite Hessians
//! (compressed springs drop their negative geometric term; volume terms use the Gauss-Newton
//! part), factorised by faer's sparse supernodal Cholesky with the symbolic factorisation
//! computed once per model, and a backtracking line search that also refuses steps that
//! would invert a prism. Measured against projective dynamics and L-BFGS in DESIGN 2.1,
//! Newton was the fastest warm-started.
//!
//! Large changes of activation are reached by continuation: the path from the state's own
//! activations to the target is split in halves until each piece converges, so a solve from
//! rest follows the physical loading path and gives the same equilibrium every run.

use faer::linalg::solvers::Solve;
use faer::sparse::linalg::solvers::{Llt, SymbolicLlt};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMat};
use faer::{MatMut, Side};

use super::controls::Activations;
use super::geom::{cross, dot, norm, scale, sub, V3};
use super::model::{FaceModel, Pose, State};
use super::muscles::MuscleKind;
use super::tissue::{prism_volume, PRISM_TETS, PRISM_TET_WEIGHT};

/// Solver settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SolveParams {
    /// Converged when |gradient| <= tolerance * |gradient at the rest positions| for the same
    /// activations (the force imbalance the solve removes). Default 1e-6.
    pub tolerance: f64,
    /// Newton iterations allowed per continuation piece. Default 30.
    pub max_iterations: usize,
    /// Equal steps from rest in `solve_from_rest`. Default 4.
    pub continuation_steps: usize,
    /// How many times a piece of the path may be halved before giving up. Default 6.
    pub max_halvings: usize,
}

impl Default for SolveParams {
    fn default() -> Self {
        SolveParams {
            tolerance: 1e-6,
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
struct Pattern {
    dof: usize,
    /// Free index of each node, or NONE.
    free_index: Vec<u32>,
    symbolic: SymbolicSparseColMat<usize>,
    llt: SymbolicLlt<usize>,
    /// Per free node: slots of its diagonal block (upper entries NONE).
    diag: Vec<[u32; 9]>,
    /// Per spring: slots of the (a, b) off-diagonal block, row = larger free index.
    spring_off: Vec<[u32; 9]>,
    /// Per prism: slots of each (i, j) local pair with i > j where both are free.
    prism_off: Vec<[[u32; 9]; 15]>,
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
        let dof = 3 * nf;
        // Node adjacency (lower: row node >= column node).
        let mut adj: Vec<Vec<u32>> = (0..nf as u32).map(|f| vec![f]).collect();
        let mut link = |a: usize, b: usize| {
            let (fa, fb) = (free_index[a], free_index[b]);
            if fa != NONE && fb != NONE && fa != fb {
                let (hi, lo) = (fa.max(fb), fa.min(fb));
                adj[lo as usize].push(hi);
            }
        };
        for s in &model.tissue.springs {
            link(s.nodes[0], s.nodes[1]);
        }
        for p in &model.tissue.prisms {
            for &(i, j) in &PRISM_PAIRS {
                link(p.nodes[i], p.nodes[j]);
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
        let symbolic = SymbolicSparseColMat::new_checked(dof, dof, col_ptr, None, row_idx);
        let llt = SymbolicLlt::try_new(symbolic.as_ref(), Side::Lower)
            .expect("symbolic Cholesky of the tissue pattern");
        Pattern {
            dof,
            free_index,
            symbolic,
            llt,
            diag,
            spring_off,
            prism_off,
        }
    }
}

/// Scratch memory for solving one model, owned by the caller and reused across solves.
pub struct Workspace {
    pattern: Pattern,
    values: Vec<f64>,
    gradient: Vec<f64>,
    step: Vec<f64>,
    trial: Vec<V3>,
}

impl Workspace {
    pub fn new(model: &FaceModel) -> Workspace {
        let pattern = Pattern::new(model);
        let nnz = pattern.symbolic.row_idx().len();
        let dof = pattern.dof;
        Workspace {
            pattern,
            values: vec![0.0; nnz],
            gradient: vec![0.0; dof],
            step: vec![0.0; dof],
            trial: Vec::new(),
        }
    }

    /// Free degrees of freedom.
    pub fn dof(&self) -> usize {
        self.pattern.dof
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

/// Gradient of a prism's volume with respect to its six nodes.
fn prism_volume_gradient(p: &[V3; 6]) -> (f64, [V3; 6]) {
    let mut g = [[0.0; 3]; 6];
    let mut volume = 0.0;
    for t in &PRISM_TETS {
        let [a, b, c, d] = t.map(|i| p[i]);
        let (ba, ca, da) = (sub(b, a), sub(c, a), sub(d, a));
        let w = PRISM_TET_WEIGHT / 6.0;
        volume += w * dot(cross(ba, ca), da);
        let gb = scale(cross(ca, da), w);
        let gc = scale(cross(da, ba), w);
        let gd = scale(cross(ba, ca), w);
        let ga = scale(
            [
                gb[0] + gc[0] + gd[0],
                gb[1] + gc[1] + gd[1],
                gb[2] + gc[2] + gd[2],
            ],
            -1.0,
        );
        for (k, gk) in [(t[0], ga), (t[1], gb), (t[2], gc), (t[3], gd)] {
            g[k] = [g[k][0] + gk[0], g[k][1] + gk[1], g[k][2] + gk[2]];
        }
    }
    (volume, g)
}

/// Weight of the logarithmic barrier in the volume energy: it grows without bound as a
/// prism's volume goes to zero, so Newton steps see inversion coming instead of being cut
/// short by the line search.
const VOLUME_BARRIER: f64 = 0.2;

/// `[e]_x`, the matrix of `v -> e x v`.
fn skew(e: V3, s: f64) -> [[f64; 3]; 3] {
    [
        [0.0, -s * e[2], s * e[1]],
        [s * e[2], 0.0, -s * e[0]],
        [-s * e[1], s * e[0], 0.0],
    ]
}

/// Second derivatives of a prism's volume: `h[i][j]` is d2V / dx_i dx_j (3x3).
/// For a tetrahedron V = det[p1-p0, p2-p0, p3-p0] / 6: d2V/dp1dp2 = -[p3-p0]_x / 6,
/// d2V/dp1dp3 = [p2-p0]_x / 6, d2V/dp2dp3 = -[p1-p0]_x / 6, transposes below the diagonal,
/// and the p0 rows and columns minus the sums of the others (translation invariance).
fn prism_volume_hessian(p: &[V3; 6]) -> [[[[f64; 3]; 3]; 6]; 6] {
    let mut h = [[[[0.0; 3]; 3]; 6]; 6];
    for t in &PRISM_TETS {
        let e = [1, 2, 3].map(|k| sub(p[t[k]], p[t[0]]));
        let mut local = [[[[0.0; 3]; 3]; 4]; 4];
        let s = PRISM_TET_WEIGHT / 6.0;
        local[1][2] = skew(e[2], -s);
        local[1][3] = skew(e[1], s);
        local[2][3] = skew(e[0], -s);
        for (i, j) in [(1, 2), (1, 3), (2, 3)] {
            let m = local[i][j];
            local[j][i] = [
                [m[0][0], m[1][0], m[2][0]],
                [m[0][1], m[1][1], m[2][1]],
                [m[0][2], m[1][2], m[2][2]],
            ];
        }
        for j in 1..4 {
            for r in 0..3 {
                for c in 0..3 {
                    let col: f64 = (1..4).map(|i| local[i][j][r][c]).sum();
                    local[0][j][r][c] = -col;
                    local[j][0][c][r] = -col;
                }
            }
        }
        for r in 0..3 {
            for c in 0..3 {
                local[0][0][r][c] = -(1..4).map(|j| local[0][j][r][c]).sum::<f64>();
            }
        }
        for a in 0..4 {
            for b in 0..4 {
                for r in 0..3 {
                    for c in 0..3 {
                        h[t[a]][t[b]][r][c] += local[a][b][r][c];
                    }
                }
            }
        }
    }
    h
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
    }
    for (c, &(anchor, normal)) in model.contacts.iter().zip(&pose.skull) {
        let gap = dot(sub(x[c.node], anchor), normal) - c.clearance;
        if gap < 0.0 {
            e += 0.5 * tp.skull_contact_stiffness * gap * gap;
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
        let q = p.nodes.map(|i| x[i]);
        let (_, dv) = prism_volume_gradient(&q);
        // The volume itself as `prism_volume` sums it, bit for bit as at rest.
        let v = prism_volume(&q);
        // psi(J) = kappa V0 (0.5 (J - 1)^2 + b (J - 1 - ln J)), J = V / V0:
        // grad = kappa (J - 1 + b (1 - 1/J)) grad V,
        // hess = kappa (1 + b / J^2) / V0 grad V grad V^T + kappa (J - 1 + b (1 - 1/J)) hess V.
        let j = v / p.rest_volume;
        let coef = tp.volume_modulus * (j - 1.0 + VOLUME_BARRIER * (1.0 - 1.0 / j));
        let c = tp.volume_modulus * (1.0 + VOLUME_BARRIER / (j * j)) / p.rest_volume;
        for k in 0..6 {
            add_grad(g, p.nodes[k], dv[k], coef);
        }
        if hessian {
            // c grad V grad V^T, plus (full) c (V - V0) hess V.
            let second = if full {
                Some(prism_volume_hessian(&q))
            } else {
                None
            };
            let block = |i: usize, j: usize| {
                let mut k = outer(dv[i], dv[j], c);
                if let Some(hv) = &second {
                    for r in 0..3 {
                        for s in 0..3 {
                            k[r][s] += coef * hv[i][j][r][s];
                        }
                    }
                }
                k
            };
            for k in 0..6 {
                add_diag(h, p.nodes[k], &block(k, k));
            }
            for (slots, &(i, j)) in pat.prism_off[pi].iter().zip(&PRISM_PAIRS) {
                if slots[0] != NONE {
                    add_block(h, slots, &block(i, j), 1.0);
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

/// Newton iterations at fixed `pose` from the positions in `state`.
fn newton(
    model: &FaceModel,
    pose: &Pose,
    state: &mut State,
    ws: &mut Workspace,
    params: &SolveParams,
) -> Result<SolveReport, SolveError> {
    // Scale: the force imbalance of the rest positions under this pose.
    let rest = rest_under(model, pose);
    assemble(model, pose, &rest, ws, false, false);
    let scale_norm = gradient_norm(ws);
    if !scale_norm.is_finite() {
        return Err(SolveError::NonFinite { iteration: 0 });
    }
    if scale_norm == 0.0 {
        state.positions = rest;
        return Ok(SolveReport::default());
    }
    let x = &mut state.positions;
    let mut e0 = energy(model, pose, x);
    if !e0.is_finite() {
        return Err(SolveError::InvalidStart);
    }
    let mut residual = f64::INFINITY;
    for iteration in 0..=params.max_iterations {
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
        // Solve H s = -g; on a (rare) failed factorisation, shift the diagonal and retry.
        let mut shift = 0.0;
        let llt = loop {
            if shift > 0.0 {
                for d in &ws.pattern.diag {
                    for k in [0, 4, 8] {
                        ws.values[d[k] as usize] += shift;
                    }
                }
            }
            let mat = SparseColMatRef::new(ws.pattern.symbolic.as_ref(), &ws.values);
            match Llt::try_new_with_symbolic(ws.pattern.llt.clone(), mat, Side::Lower) {
                Ok(llt) => break llt,
                Err(_) if shift < 1e12 => shift = if shift == 0.0 { 1e-3 } else { shift * 100.0 },
                Err(_) => return Err(SolveError::NonFinite { iteration }),
            }
        };
        for (s, g) in ws.step.iter_mut().zip(&ws.gradient) {
            *s = -g;
        }
        llt.solve_in_place(MatMut::from_column_major_slice_mut(
            &mut ws.step,
            ws.pattern.dof,
            1,
        ));
        let slope: f64 = ws.step.iter().zip(&ws.gradient).map(|(s, g)| s * g).sum();
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
    Err(SolveError::NotConverged {
        iterations: params.max_iterations,
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
    while t < 1.0 {
        let t_next = (t + piece).min(1.0);
        let a = interpolate(&start, target, t_next);
        let to_pose = model.pose(&a);
        let mut trial = state.clone();
        model.carry(&mut trial, &from_pose, &to_pose);
        match newton(model, &to_pose, &mut trial, ws, params) {
            Ok(r) => {
                report.iterations += r.iterations;
                report.pieces += 1;
                report.residual = r.residual;
                *state = trial;
                from_pose = to_pose;
                t = t_next;
            }
            Err(err) => {
                halvings += 1;
                if halvings > params.max_halvings {
                    return Err(match err {
                        SolveError::NotConverged { residual, .. } => SolveError::NotConverged {
                            iterations: report.iterations + params.max_iterations,
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
