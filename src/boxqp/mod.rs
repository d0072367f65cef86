//! The bounded least-squares solvers behind activation estimation (Choe, Lee & Ko 2001,
//! eq. 10): the activations whose face best matches observed landmark displacements (or, as an
//! extension, observed AUs), each activation kept in [0, 1]. `transfer::inverter` fits faces
//! with them, the inversion table compares them, and the neck's equilibrium fit solves its QPs
//! with them.
//!
//! Landmark space: the linear muscle basis makes the landmarks an affine function of the
//! activations, `d(a) = M a`, so the problem is a least squares `|M a - d|^2` with the
//! activations held to [0, 1] in one of two ways ([`Bound`]):
//! - `Bound::Box`: the box as a constraint;
//! - `Bound::Penalty(c)`: Choe's eq. 10 as published, `|M a - d|^2 + c sum D(a_i)` with the
//!   linear penalty `D(a) = max(-a, 0) + max(a - 1, 0)`. `D` is exact: once `c` exceeds the
//!   largest `|d/da_i |M a - d|^2|` at the box solution, the penalized minimum is the box
//!   one; below that activations leave the box and are clipped when they drive a face.
//!
//! Both are solved by one method, [`accelerated`]: FISTA (proximal gradient with Nesterov
//! momentum and adaptive restart) with the bound's proximal map, which handles the box and
//! the kinks of `D` exactly. It stops when the norm of the proximal gradient, zero exactly
//! at the minimum, falls below a tolerance; Choe et al. used steepest descent, which on the
//! kinked objective never met that test in 20,000 iterations (facelab before 2026-12).
//! The landmark fits of `transfer::inverter` solve their box QPs by [`projected_newton`],
//! which meets the same test in far fewer iterations than FISTA; the neck's equilibrium fit
//! solves its small, strictly convex box QPs (72 activations, one per Levenberg-Marquardt
//! step) by the primal-dual [`active_set`] method, which meets it in a handful of solves where
//! projected Newton often ran to its iteration cap.
//!
//! AU space (`au_fit`): `min |AU(a) - r|^2` over the box, by projected Gauss-Newton with a
//! forward-difference Jacobian through any face function (the linear basis, or the nonlinear
//! solve for refinement).
//!
//! Pure: no files.

/// `min 0.5 a^T H a - g^T a + c` over `0 <= a <= 1` (H = M^T M, g = M^T d, c = |d|^2 / 2).
#[derive(Clone, Debug, PartialEq)]
pub struct BoxQp {
    pub n: usize,
    /// Row-major n x n.
    pub h: Vec<f64>,
    pub g: Vec<f64>,
    pub c: f64,
}

/// A solver's answer.
#[derive(Clone, Debug, PartialEq)]
pub struct Solution {
    pub a: Vec<f64>,
    pub iterations: usize,
    /// `|M a - d|^2` at `a` (for `au_fit`, its own cost).
    pub residual: f64,
    /// The first-order optimality measure at `a` ([`stationarity`]; for `au_fit`, the last
    /// step's max-norm).
    pub gradient_norm: f64,
    /// Whether the stopping test was met before the iteration cap.
    pub converged: bool,
}

impl BoxQp {
    /// From the columns of M (each of length m) and the target d.
    pub fn least_squares(columns: &[Vec<f64>], d: &[f64]) -> BoxQp {
        let n = columns.len();
        let mut h = vec![0.0; n * n];
        for i in 0..n {
            for j in i..n {
                let v: f64 = columns[i].iter().zip(&columns[j]).map(|(a, b)| a * b).sum();
                h[i * n + j] = v;
                h[j * n + i] = v;
            }
        }
        let g = columns
            .iter()
            .map(|c| c.iter().zip(d).map(|(a, b)| a * b).sum())
            .collect();
        BoxQp {
            n,
            h,
            g,
            c: 0.5 * d.iter().map(|v| v * v).sum::<f64>(),
        }
    }

    fn hv(&self, a: &[f64]) -> Vec<f64> {
        let n = self.n;
        let mut out = vec![0.0; n];
        // Four rows at once: four independent sums that the CPU overlaps, each still added
        // left to right from -0.0 as `Iterator::sum` does, so the result is the same bits.
        let mut blocks = self.h.chunks_exact(4 * n);
        let mut outs = out.chunks_exact_mut(4);
        for (rows, o) in (&mut blocks).zip(&mut outs) {
            let (r0, rest) = rows.split_at(n);
            let (r1, rest) = rest.split_at(n);
            let (r2, r3) = rest.split_at(n);
            let mut s = [-0.0f64; 4];
            for (k, &x) in a.iter().enumerate() {
                s[0] += r0[k] * x;
                s[1] += r1[k] * x;
                s[2] += r2[k] * x;
                s[3] += r3[k] * x;
            }
            o.copy_from_slice(&s);
        }
        for (row, o) in blocks
            .remainder()
            .chunks_exact(n)
            .zip(outs.into_remainder())
        {
            *o = row.iter().zip(a).map(|(h, x)| h * x).sum();
        }
        out
    }

    /// `|g| = |M^T d|`, the unit of the solvers' relative stopping tests.
    pub fn gradient_scale(&self) -> f64 {
        self.g.iter().map(|v| v * v).sum::<f64>().sqrt().max(1e-300)
    }

    /// Gradient `H a - g`.
    pub fn gradient(&self, a: &[f64]) -> Vec<f64> {
        self.gradient_from(self.hv(a))
    }

    /// Gradient `H a - g` from `H a` (`ha`), for a solver that also needs `H a` itself.
    fn gradient_from(&self, ha: Vec<f64>) -> Vec<f64> {
        ha.into_iter().zip(&self.g).map(|(h, g)| h - g).collect()
    }

    /// `|M a - d|^2`.
    pub fn residual(&self, a: &[f64]) -> f64 {
        let ha = self.hv(a);
        let quad: f64 = ha.iter().zip(a).map(|(h, x)| h * x).sum();
        let lin: f64 = self.g.iter().zip(a).map(|(g, x)| g * x).sum();
        (quad - 2.0 * lin + 2.0 * self.c).max(0.0)
    }

    /// Largest eigenvalue of H (power iteration), the gradient's Lipschitz constant.
    pub fn lipschitz(&self) -> f64 {
        let mut v = vec![1.0 / (self.n as f64).sqrt(); self.n];
        let mut lambda = 0.0;
        for _ in 0..100 {
            let w = self.hv(&v);
            let norm = w.iter().map(|x| x * x).sum::<f64>().sqrt();
            if norm == 0.0 {
                return 1.0;
            }
            let next = norm;
            v = w.into_iter().map(|x| x / norm).collect();
            if (next - lambda).abs() <= 1e-10 * next {
                lambda = next;
                break;
            }
            lambda = next;
        }
        lambda * 1.01
    }
}

fn clamp01(a: &mut [f64]) {
    for x in a {
        *x = x.clamp(0.0, 1.0);
    }
}

/// How the activations are held to [0, 1].
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Bound {
    /// The box as a constraint.
    Box,
    /// Choe et al.'s linear penalty `c sum D(a_i)` (eq. 10), in the units of `|M a - d|^2`.
    Penalty(f64),
}

impl Bound {
    /// The proximal map of the bound for a gradient step of length `step` (in the units of
    /// [`BoxQp`], whose objective is half of `|M a - d|^2`): the projection onto the box, or
    /// for the penalty a soft threshold toward it (`D`'s slope, `c / 2` there, times `step`).
    fn prox(self, x: f64, step: f64) -> f64 {
        match self {
            Bound::Box => x.clamp(0.0, 1.0),
            Bound::Penalty(c) => {
                let mu = 0.5 * c * step;
                if x < -mu {
                    x + mu
                } else if x < 0.0 {
                    0.0
                } else if x <= 1.0 {
                    x
                } else if x <= 1.0 + mu {
                    1.0
                } else {
                    x - mu
                }
            }
        }
    }

    /// `c sum D(a_i)` (zero for the box, whose iterates never leave it).
    pub fn penalty(self, a: &[f64]) -> f64 {
        match self {
            Bound::Box => 0.0,
            Bound::Penalty(c) => {
                c * a
                    .iter()
                    .map(|&x| (-x).max(0.0) + (x - 1.0).max(0.0))
                    .sum::<f64>()
            }
        }
    }
}

/// Norm of the proximal gradient at unit step, `|prox(a - grad) - a|`: zero exactly at the
/// bound's minimum (for the box, the projected gradient).
pub fn stationarity(qp: &BoxQp, bound: Bound, a: &[f64]) -> f64 {
    stationarity_at(&qp.gradient(a), bound, a)
}

/// [`stationarity`] from the gradient at `a`.
fn stationarity_at(gradient: &[f64], bound: Bound, a: &[f64]) -> f64 {
    gradient
        .iter()
        .zip(a)
        .map(|(&g, &x)| {
            let p = bound.prox(x - g, 1.0) - x;
            p * p
        })
        .sum::<f64>()
        .sqrt()
}

/// Norm of the projected gradient (zero exactly at a box-constrained minimum).
pub fn projected_gradient_norm(qp: &BoxQp, a: &[f64]) -> f64 {
    stationarity(qp, Bound::Box, a)
}

/// FISTA with adaptive restart from `start` under `bound`, until the proximal gradient's
/// norm ([`stationarity`]) falls below `tol` (relative to |g|) or `max_iterations`. The
/// answer's `converged` says which; its `residual` is `|M a - d|^2` at the answer.
pub fn accelerated(
    qp: &BoxQp,
    bound: Bound,
    start: &[f64],
    tol: f64,
    max_iterations: usize,
) -> Solution {
    let step = 1.0 / qp.lipschitz();
    let scale = qp.gradient_scale();
    let mut a: Vec<f64> = start.iter().map(|&x| bound.prox(x, 0.0)).collect();
    let mut y = a.clone();
    let mut t = 1.0f64;
    let mut iterations = 0;
    let mut gradient_norm = stationarity(qp, bound, &a);
    while iterations < max_iterations && gradient_norm > tol * scale {
        iterations += 1;
        let g = qp.gradient(&y);
        let next: Vec<f64> = y
            .iter()
            .zip(&g)
            .map(|(y, g)| bound.prox(y - step * g, step))
            .collect();
        // Restart the momentum when the step goes against it (O'Donoghue & Candes 2015,
        // gradient scheme, with the proximal gradient `y - next` in place of the gradient);
        // the step itself is always taken.
        let against: f64 = y
            .iter()
            .zip(next.iter().zip(&a))
            .map(|(y, (n, a))| (y - n) * (n - a))
            .sum();
        if against > 0.0 {
            t = 1.0;
            y = next.clone();
        } else {
            let t_next = 0.5 * (1.0 + (1.0 + 4.0 * t * t).sqrt());
            let beta = (t - 1.0) / t_next;
            y = next
                .iter()
                .zip(&a)
                .map(|(n, a)| n + beta * (n - a))
                .collect();
            t = t_next;
        }
        a = next;
        gradient_norm = stationarity(qp, bound, &a);
    }
    Solution {
        residual: qp.residual(&a),
        converged: gradient_norm <= tol * scale,
        gradient_norm,
        a,
        iterations,
    }
}

/// The box-constrained fit ([`accelerated`] with [`Bound::Box`]).
pub fn projected_gradient(qp: &BoxQp, start: &[f64], tol: f64, max_iterations: usize) -> Solution {
    accelerated(qp, Bound::Box, start, tol, max_iterations)
}

/// The box QP by projected Newton (Bertsekas 1982): each iteration fixes the variables at a
/// bound whose gradient pushes outward (within `min(EPSILON, stationarity)` of the bound),
/// takes the Newton step of the others (Cholesky of H on them) and a scaled gradient step of
/// the fixed ones, and searches along the projection arc (Armijo). For the small, strictly
/// convex QPs of the landmark fits it meets the same stationarity test as
/// [`projected_gradient`] in far fewer iterations than FISTA's thousands (on the neck's fit,
/// whose QPs have many activations near their bounds, it binds a few per iteration under
/// many step halvings and often ran to its cap: [`active_set`] solves those). An H that is
/// not positive definite on the free set falls back to the scaled gradient step.
pub fn projected_newton(qp: &BoxQp, start: &[f64], tol: f64, max_iterations: usize) -> Solution {
    use faer::linalg::solvers::Solve;
    const EPSILON: f64 = 1e-3;
    const ARMIJO: f64 = 1e-4;
    let n = qp.n;
    let scale = qp.gradient_scale();
    // The objective and the gradient at a point share its `H a`, computed once per point
    // (the gradient through `BoxQp::gradient_from`, so the same bits as `gradient`).
    let objective = |a: &[f64], ha: &[f64]| -> f64 {
        a.iter()
            .zip(ha)
            .zip(&qp.g)
            .map(|((x, h), g)| x * (0.5 * h - g))
            .sum()
    };
    let mut a: Vec<f64> = start.iter().map(|x| x.clamp(0.0, 1.0)).collect();
    let ha = qp.hv(&a);
    let mut f = objective(&a, &ha);
    let mut g = qp.gradient_from(ha);
    let mut iterations = 0;
    let mut gradient_norm = stationarity_at(&g, Bound::Box, &a);
    while iterations < max_iterations && gradient_norm > tol * scale {
        iterations += 1;
        let eps = EPSILON.min(gradient_norm);
        let binding: Vec<bool> = (0..n)
            .map(|i| (a[i] <= eps && g[i] > 0.0) || (a[i] >= 1.0 - eps && g[i] < 0.0))
            .collect();
        let free: Vec<usize> = (0..n).filter(|&i| !binding[i]).collect();
        let diagonal = |i: usize| qp.h[i * n + i].max(1e-300);
        let mut step: Vec<f64> = (0..n).map(|i| -g[i] / diagonal(i)).collect();
        if !free.is_empty() {
            let m = free.len();
            let h = faer::Mat::<f64>::from_fn(m, m, |r, c| qp.h[free[r] * n + free[c]]);
            if let Ok(llt) = h.llt(faer::Side::Lower) {
                let mut rhs = faer::Mat::<f64>::from_fn(m, 1, |r, _| -g[free[r]]);
                llt.solve_in_place(rhs.as_mut());
                for (r, &i) in free.iter().enumerate() {
                    step[i] = rhs[(r, 0)];
                }
            }
        }
        // Armijo along the arc a(t) = P(a + t step).
        let mut t = 1.0;
        let mut accepted = false;
        for _ in 0..60 {
            let trial: Vec<f64> = a
                .iter()
                .zip(&step)
                .map(|(x, d)| (x + t * d).clamp(0.0, 1.0))
                .collect();
            let decrease: f64 = (0..n)
                .map(|i| {
                    if binding[i] {
                        g[i] * (a[i] - trial[i])
                    } else {
                        -t * g[i] * step[i]
                    }
                })
                .sum();
            let ht = qp.hv(&trial);
            let ft = objective(&trial, &ht);
            // `decrease` >= 0: the free step is a Newton step of a positive definite block
            // (or a scaled gradient step), and the bound ones move against the gradient.
            if f - ft >= ARMIJO * decrease {
                accepted = true;
                a = trial;
                f = ft;
                g = qp.gradient_from(ht);
                break;
            }
            t *= 0.5;
        }
        gradient_norm = stationarity_at(&g, Bound::Box, &a);
        if !accepted {
            break;
        }
    }
    Solution {
        residual: qp.residual(&a),
        converged: gradient_norm <= tol * scale,
        gradient_norm,
        a,
        iterations,
    }
}

/// The box QP by the primal-dual active-set method (Hintermüller, Ito & Kunisch 2002, a
/// semismooth Newton method on the optimality conditions). From a point `a` and its gradient
/// `r = H a - g`, a variable with `a_i - r_i / H_ii` below 0 is fixed at 0, one above 1 at 1,
/// and the others solve `H a = g` exactly on their block (Cholesky) with the fixed ones held;
/// this repeats until the sets no longer change, where the minimum's conditions hold: the free
/// variables inside the box with zero gradient, the fixed ones pushed outward. Each iteration
/// moves every variable that changes set at once, where [`projected_newton`] frees or binds a
/// few per iteration under a line search, so a strictly convex QP of the neck's fit takes a
/// handful of solves of its free block. The method can cycle where H is far from diagonally
/// dominant: after `max_iterations`, or a free block that is not positive definite, or an
/// answer that misses `tol` in rounding, [`projected_newton`] continues from its point, and the
/// answer counts both methods' iterations.
pub fn active_set(qp: &BoxQp, start: &[f64], tol: f64, max_iterations: usize) -> Solution {
    use faer::linalg::solvers::Solve;
    #[derive(Clone, Copy, PartialEq, Eq)]
    enum Set {
        Free,
        Lower,
        Upper,
    }
    let n = qp.n;
    let scale = qp.gradient_scale();
    let mut a = start.to_vec();
    clamp01(&mut a);
    let mut r = qp.gradient(&a);
    let mut sets: Vec<Set> = Vec::new();
    let mut iterations = 0;
    let mut settled = false;
    while iterations < max_iterations {
        let next: Vec<Set> = (0..n)
            .map(|i| {
                let x = a[i] - r[i] / qp.h[i * n + i].max(1e-300);
                if x < 0.0 {
                    Set::Lower
                } else if x > 1.0 {
                    Set::Upper
                } else {
                    Set::Free
                }
            })
            .collect();
        if next == sets {
            settled = true;
            break;
        }
        sets = next;
        iterations += 1;
        let free: Vec<usize> = (0..n).filter(|&i| sets[i] == Set::Free).collect();
        for i in 0..n {
            match sets[i] {
                Set::Lower => a[i] = 0.0,
                Set::Upper => a[i] = 1.0,
                Set::Free => {}
            }
        }
        if !free.is_empty() {
            let m = free.len();
            let h = faer::Mat::<f64>::from_fn(m, m, |row, col| qp.h[free[row] * n + free[col]]);
            let Ok(llt) = h.llt(faer::Side::Lower) else {
                break;
            };
            let mut rhs = faer::Mat::<f64>::from_fn(m, 1, |row, _| {
                let i = free[row];
                qp.g[i]
                    - (0..n)
                        .filter(|&j| sets[j] == Set::Upper)
                        .map(|j| qp.h[i * n + j])
                        .sum::<f64>()
            });
            llt.solve_in_place(rhs.as_mut());
            for (row, &i) in free.iter().enumerate() {
                a[i] = rhs[(row, 0)];
            }
        }
        r = qp.gradient(&a);
    }
    // Settled sets leave the free variables in the box up to rounding.
    if a.iter().any(|x| !(0.0..=1.0).contains(x)) {
        clamp01(&mut a);
        r = qp.gradient(&a);
    }
    let gradient_norm = stationarity_at(&r, Bound::Box, &a);
    if settled && gradient_norm <= tol * scale {
        return Solution {
            residual: qp.residual(&a),
            converged: true,
            gradient_norm,
            a,
            iterations,
        };
    }
    let mut rest = projected_newton(qp, &a, tol, max_iterations);
    rest.iterations += iterations;
    rest
}

/// Projected Gauss-Newton for `min |f(a) - r|^2` over the box, with `f` evaluated by the
/// caller (any face: linear basis or nonlinear solve) and its Jacobian by forward differences
/// of size `h` (one-sided toward the box interior). Stops when the step is below `tol`
/// (max-norm) or after `max_iterations`. Returns the activations and the iterations.
pub fn au_fit(
    f: &mut dyn FnMut(&[f64]) -> Vec<f64>,
    r: &[f64],
    start: &[f64],
    h: f64,
    tol: f64,
    max_iterations: usize,
) -> Solution {
    let n = start.len();
    let mut a = start.to_vec();
    clamp01(&mut a);
    let mut fa = f(&a);
    let cost = |fa: &[f64]| fa.iter().zip(r).map(|(x, y)| (x - y).powi(2)).sum::<f64>();
    let mut current = cost(&fa);
    let mut iterations = 0;
    let mut damping = 1e-6;
    let mut last_step = f64::INFINITY;
    let mut converged = false;
    while iterations < max_iterations {
        iterations += 1;
        let columns: Vec<Vec<f64>> = (0..n)
            .map(|j| {
                let mut b = a.clone();
                let dh = if b[j] + h <= 1.0 { h } else { -h };
                b[j] += dh;
                f(&b).iter().zip(&fa).map(|(x, y)| (x - y) / dh).collect()
            })
            .collect();
        let residual: Vec<f64> = r.iter().zip(&fa).map(|(r, f)| r - f).collect();
        // Step s: min |J s - residual|^2 + damping |s|^2 with a + s in the box.
        let mut qp = BoxQp::least_squares(&columns, &residual);
        let trace = (0..n).map(|i| qp.h[i * n + i]).sum::<f64>() / n as f64;
        for i in 0..n {
            qp.h[i * n + i] += damping * trace.max(1e-12);
        }
        // Shift to absolute activations: s = b - a, b in [0, 1].
        let ha = qp.hv(&a);
        let shifted = BoxQp {
            n,
            g: qp.g.iter().zip(&ha).map(|(g, h)| g + h).collect(),
            h: qp.h.clone(),
            c: 0.0,
        };
        let b = projected_gradient(&shifted, &a, 1e-8, 500).a;
        let fb = f(&b);
        let next = cost(&fb);
        let step = b
            .iter()
            .zip(&a)
            .map(|(x, y)| (x - y).abs())
            .fold(0.0, f64::max);
        last_step = step;
        if next < current {
            a = b;
            fa = fb;
            current = next;
            damping = (damping * 0.3).max(1e-9);
            if step < tol {
                converged = true;
                break;
            }
        } else {
            damping *= 10.0;
            if damping > 1e6 || step < tol {
                converged = step < tol;
                break;
            }
        }
    }
    Solution {
        a,
        iterations,
        residual: current,
        gradient_norm: last_step,
        converged,
    }
}

#[cfg(test)]
mod tests;
