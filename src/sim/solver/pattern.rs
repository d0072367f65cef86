//! The Hessian's sparsity pattern over the free nodes in fill-reducing order, with the slot
//! each element's blocks land in, and the symbolic Cholesky analysis done once per model.

use std::collections::BTreeMap;

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::sparse::linalg::amd;
use faer::sparse::linalg::cholesky::{
    factorize_symbolic_cholesky, CholeskySymbolicParams, SymbolicCholesky, SymmetricOrdering,
};
use faer::sparse::linalg::SupernodalThreshold;
use faer::sparse::{SymbolicSparseColMat, SymbolicSparseColMatRef};
use faer::Side;

use super::SolveError;
use crate::sim::model::FaceModel;

pub(super) const NONE: u32 = u32::MAX;

/// Sparse structure of the Hessian over free degrees of freedom (lower triangle, CSC) and
/// where each element's blocks land in it.
///
/// Free nodes are numbered in an approximate-minimum-degree order of the node graph, so the
/// matrix is assembled already in fill-reducing order: the Cholesky factorisation needs no
/// permutation, and each node's three coordinates stay together in one supernode.
pub(super) struct Pattern {
    pub(super) dof: usize,
    /// Free index of each node (in elimination order), or NONE.
    pub(super) free_index: Vec<u32>,
    pub(super) symbolic: SymbolicSparseColMat<usize>,
    pub(super) cholesky: SymbolicCholesky<usize>,
    /// Per free node: slots of its diagonal block (upper entries NONE).
    pub(super) diag: Vec<[u32; 9]>,
    /// Per spring: slots of the (a, b) off-diagonal block, row = larger free index.
    pub(super) spring_off: Vec<[u32; 9]>,
    /// Per prism: slots of each (i, j) local pair with i > j where both are free.
    pub(super) prism_off: Vec<[[u32; 9]; 15]>,
    /// Per ordered pair of distinct lip margin nodes: slots of its (row, column) block.
    pub(super) lip_off: BTreeMap<(usize, usize), [u32; 9]>,
}

pub(super) const PRISM_PAIRS: [(usize, usize); 15] = {
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
pub(super) fn element_links(model: &FaceModel) -> impl Iterator<Item = (usize, usize)> + '_ {
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
pub(super) fn node_order(
    model: &FaceModel,
    old_index: &[u32],
    nf: usize,
) -> Result<Vec<u32>, SolveError> {
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
    .map_err(|e| SolveError::Pattern(format!("AMD ordering of the tissue graph: {e:?}")))?;
    Ok(perm_inv.iter().map(|&n| n as u32).collect())
}

impl Pattern {
    pub(super) fn new(model: &FaceModel) -> Result<Pattern, SolveError> {
        let mut free_index = vec![NONE; model.node_count()];
        let mut count = 0u32;
        for (node, &f) in model.free.iter().enumerate() {
            if f {
                free_index[node] = count;
                count += 1;
            }
        }
        let nf = count as usize;
        let order = node_order(model, &free_index, nf)?;
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
        .map_err(|e| {
            SolveError::Pattern(format!("symbolic Cholesky of the tissue pattern: {e:?}"))
        })?;
        Ok(Pattern {
            dof,
            free_index,
            symbolic,
            cholesky,
            diag,
            spring_off,
            prism_off,
            lip_off,
        })
    }

    pub(super) fn matrix_pattern(&self) -> SymbolicSparseColMatRef<'_, usize> {
        self.symbolic.as_ref()
    }
}
