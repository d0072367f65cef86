//! The tissue and muscle energy, its gradient and its Hessian (exact or positive
//! semi-definite part), assembled into the pattern's slots.

use crate::sim::geom::{dot, norm, scale, sub, V3};
use crate::sim::model::{FaceModel, Pose};
use crate::sim::muscles::MuscleKind;
use crate::sim::tissue::{prism_volume, prism_volume_derivatives};

use super::*;

/// Adds a symmetric 3x3 block `k` (row-major) to the slots.
#[inline]
pub(super) fn add_block(values: &mut [f64], slots: &[u32; 9], k: &[[f64; 3]; 3], sign: f64) {
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
pub(super) fn outer(a: V3, b: V3, s: f64) -> [[f64; 3]; 3] {
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
pub(super) fn iso_plus_outer(c1: f64, u: V3, c2: f64) -> [[f64; 3]; 3] {
    let mut m = outer(u, u, c2);
    for (i, row) in m.iter_mut().enumerate() {
        row[i] += c1;
    }
    m
}

/// Spring energy, force magnitude dE/dl and tangent stiffness d2E/dl2 at length `l`.
#[inline]
pub(super) fn spring_law(
    s: &crate::sim::tissue::Spring,
    l: f64,
    strain: f64,
    factor: f64,
) -> (f64, f64, f64) {
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
pub(super) const VOLUME_BARRIER: f64 = 0.2;

/// `[e]_x s`, the matrix of `v -> s e x v`.
#[inline]
pub(super) fn skew(e: V3, s: f64) -> [[f64; 3]; 3] {
    [
        [0.0, -s * e[2], s * e[1]],
        [s * e[2], 0.0, -s * e[0]],
        [-s * e[1], s * e[0], 0.0],
    ]
}

/// Shear modulus of prism `p` (Pa): its slab's Young's modulus times
/// `TissueParams::shear_modulus_fraction / 3`.
pub(super) fn shear_modulus(model: &FaceModel, p: &crate::sim::tissue::Prism) -> f64 {
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
pub(super) fn gram_forces(p: &crate::sim::tissue::Prism, x: &[V3]) -> ([V3; 6], [V3; 6]) {
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
pub(super) fn energy(model: &FaceModel, pose: &Pose, x: &[V3]) -> f64 {
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
pub(super) fn assemble(
    model: &FaceModel,
    pose: &Pose,
    x: &[V3],
    ws: &mut Workspace,
    hessian: bool,
    full: bool,
) {
    let mut acc = Sums {
        pat: &ws.pattern,
        g: &mut ws.gradient,
        h: &mut ws.values,
    };
    acc.g.fill(0.0);
    if hessian {
        acc.h.fill(0.0);
    }
    // In this order, so every sum adds its terms as it always has.
    springs(model, x, &mut acc, hessian, full);
    prisms(model, x, &mut acc, hessian, full);
    contacts(model, pose, x, &mut acc, hessian, full);
    muscles(model, pose, x, &mut acc, hessian);
}

/// The gradient and the Hessian's values being summed, addressed by node.
struct Sums<'a> {
    pat: &'a Pattern,
    g: &'a mut [f64],
    h: &'a mut [f64],
}

impl Sums<'_> {
    /// Adds `sign v` to a free node's gradient.
    #[inline]
    fn grad(&mut self, node: usize, v: V3, sign: f64) {
        let f = self.pat.free_index[node];
        if f != NONE {
            let f = 3 * f as usize;
            self.g[f] += sign * v[0];
            self.g[f + 1] += sign * v[1];
            self.g[f + 2] += sign * v[2];
        }
    }

    /// Adds `k` to a free node's diagonal block.
    #[inline]
    fn diag(&mut self, node: usize, k: &[[f64; 3]; 3]) {
        let f = self.pat.free_index[node];
        if f != NONE {
            add_block(self.h, &self.pat.diag[f as usize], k, 1.0);
        }
    }
}

/// The tissue's springs (the layers' edges).
fn springs(model: &FaceModel, x: &[V3], acc: &mut Sums, hessian: bool, full: bool) {
    let tp = &model.params.tissue;
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
        acc.grad(a, fv, -1.0);
        acc.grad(b, fv, 1.0);
        if hessian {
            // kt u u^T + max(f/l, 0) (I - u u^T): the compressive geometric term is dropped
            // so the block stays positive semi-definite.
            let geo = if full {
                force / l
            } else {
                (force / l).max(0.0)
            };
            let k = iso_plus_outer(geo, u, kt - geo);
            acc.diag(a, &k);
            acc.diag(b, &k);
            add_block(acc.h, &acc.pat.spring_off[si], &k, -1.0);
        }
    }
}

/// The prisms' volume and shear terms.
fn prisms(model: &FaceModel, x: &[V3], acc: &mut Sums, hessian: bool, full: bool) {
    let tp = &model.params.tissue;
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
                acc.grad(node, f, mu);
            }
            if hessian {
                for a in 0..6 {
                    acc.diag(
                        p.nodes[a],
                        &iso_plus_outer(mu * p.gram[a][a], [0.0; 3], 0.0),
                    );
                }
                for (slots, &(a, b)) in acc.pat.prism_off[pi].iter().zip(&PRISM_PAIRS) {
                    let k = iso_plus_outer(mu * p.gram[a][b], [0.0; 3], 0.0);
                    add_block(acc.h, slots, &k, 1.0);
                }
            }
        }
        for k in 0..6 {
            acc.grad(p.nodes[k], dv[k], coef);
        }
        if hessian {
            // c grad V grad V^T, plus (full) coef hess V; hess V has zero diagonal blocks.
            for k in 0..6 {
                acc.diag(p.nodes[k], &outer(dv[k], dv[k], c));
            }
            for (slots, &(a, b)) in acc.pat.prism_off[pi].iter().zip(&PRISM_PAIRS) {
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
                    add_block(acc.h, slots, &k, 1.0);
                }
            }
        }
    }
}

/// Contact with the skull, and between the lips.
fn contacts(model: &FaceModel, pose: &Pose, x: &[V3], acc: &mut Sums, hessian: bool, full: bool) {
    let tp = &model.params.tissue;
    for (c, &(anchor, normal)) in model.contacts.iter().zip(&pose.skull) {
        let gap = dot(sub(x[c.node], anchor), normal) - c.clearance;
        if gap < 0.0 {
            acc.grad(c.node, normal, tp.skull_contact_stiffness * gap);
            if hessian {
                acc.diag(c.node, &outer(normal, normal, tp.skull_contact_stiffness));
            }
        }
    }
    // Lip contact: k gap grad(gap), and k (grad grad^T + gap hess) (the curvature term only
    // for the full Hessian; without it the block stays positive semi-definite).
    let k = tp.lip_contact_stiffness;
    for c in model.lips.active(x) {
        for (i, &node) in c.nodes.iter().enumerate() {
            acc.grad(node, [c.grad[2 * i], c.grad[2 * i + 1], 0.0], k * c.gap);
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
                        acc.diag(c.nodes[i], &block);
                    } else if let Some(slots) = acc.pat.lip_off.get(&(c.nodes[i], c.nodes[j])) {
                        // Each unordered pair's block is stored once (the lower triangle);
                        // the (i, j) and (j, i) loops each add their half of it.
                        add_block(acc.h, slots, &block, 0.5);
                    }
                }
            }
        }
    }
}

/// The muscles' pulls toward their targets.
fn muscles(model: &FaceModel, pose: &Pose, x: &[V3], acc: &mut Sums, hessian: bool) {
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
                    acc.grad(node, dd, mag / rho);
                    if hessian {
                        let mut k = outer(dd, dd, -mag / rho.powi(3));
                        k[0][0] += mag / rho;
                        k[1][1] += mag * k2 / rho;
                        acc.diag(node, &k);
                    }
                }
                _ => {
                    let r = norm(d);
                    if r < 1e-12 {
                        continue;
                    }
                    let u = scale(d, 1.0 / r);
                    acc.grad(node, u, mag);
                    if hessian {
                        acc.diag(node, &iso_plus_outer(mag / r, u, -mag / r));
                    }
                }
            }
        }
    }
}
