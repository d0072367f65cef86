//! Activation estimation by optimization (Choe, Lee & Ko 2001, eq. 10): the activations whose
//! face best matches observed landmark displacements (or, as an extension, observed AUs),
//! each activation kept in [0, 1].
//!
//! Landmark space: the linear muscle basis makes the landmarks an affine function of the
//! activations, `d(a) = M a`, so the problem is a box-constrained least squares
//! `min |M a - d|^2, 0 <= a <= 1`. Two solvers:
//! - `projected_gradient`: accelerated projected gradient (FISTA with adaptive restart), the
//!   box handled exactly;
//! - `penalty_descent`: Choe's formulation, the box as a quadratic penalty
//!   `lambda sum (min(a, 0)^2 + max(a - 1, 0)^2)` minimized by plain steepest descent with
//!   exact line search; the result is clipped to the box at the end.
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
    /// `|M a - d|^2` at `a`.
    pub residual: f64,
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

    /// Gradient `H a - g`.
    pub fn gradient(&self, a: &[f64]) -> Vec<f64> {
        self.hv(a)
            .into_iter()
            .zip(&self.g)
            .map(|(h, g)| h - g)
            .collect()
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

/// Norm of the projected gradient (zero exactly at a box-constrained minimum).
pub fn projected_gradient_norm(qp: &BoxQp, a: &[f64]) -> f64 {
    qp.gradient(a)
        .iter()
        .zip(a)
        .map(|(&g, &x)| {
            let p = (x - g).clamp(0.0, 1.0) - x;
            p * p
        })
        .sum::<f64>()
        .sqrt()
}

/// FISTA with adaptive restart from `start`, until the projected gradient norm falls below
/// `tol` (relative to |g|) or `max_iterations`.
pub fn projected_gradient(qp: &BoxQp, start: &[f64], tol: f64, max_iterations: usize) -> Solution {
    let step = 1.0 / qp.lipschitz();
    let scale = qp.g.iter().map(|v| v * v).sum::<f64>().sqrt().max(1e-300);
    let mut a = start.to_vec();
    clamp01(&mut a);
    let mut y = a.clone();
    let mut t = 1.0f64;
    let mut iterations = 0;
    while iterations < max_iterations {
        if projected_gradient_norm(qp, &a) <= tol * scale {
            break;
        }
        iterations += 1;
        let g = qp.gradient(&y);
        let mut next: Vec<f64> = y.iter().zip(&g).map(|(y, g)| y - step * g).collect();
        clamp01(&mut next);
        let t_next = 0.5 * (1.0 + (1.0 + 4.0 * t * t).sqrt());
        // Restart the momentum when it points uphill (O'Donoghue & Candes 2015).
        let uphill: f64 = g
            .iter()
            .zip(next.iter().zip(&a))
            .map(|(g, (n, a))| g * (n - a))
            .sum();
        if uphill > 0.0 {
            t = 1.0;
            y = a.clone();
            continue;
        }
        let beta = (t - 1.0) / t_next;
        y = next
            .iter()
            .zip(&a)
            .map(|(n, a)| n + beta * (n - a))
            .collect();
        a = next;
        t = t_next;
    }
    Solution {
        residual: qp.residual(&a),
        a,
        iterations,
    }
}

/// Choe et al.'s eq. 10: the box as a penalty of weight `lambda`, minimized by steepest
/// descent with exact line search (the objective is piecewise quadratic; the search uses the
/// curvature at the current point), until the gradient norm falls below `tol` (relative) or
/// `max_iterations`; then clipped to the box.
pub fn penalty_descent(
    qp: &BoxQp,
    start: &[f64],
    lambda: f64,
    tol: f64,
    max_iterations: usize,
) -> Solution {
    let scale = qp.g.iter().map(|v| v * v).sum::<f64>().sqrt().max(1e-300);
    let mut a = start.to_vec();
    let mut iterations = 0;
    let outside = |x: f64| !(0.0..=1.0).contains(&x);
    while iterations < max_iterations {
        let mut g = qp.gradient(&a);
        for (gi, &x) in g.iter_mut().zip(&a) {
            if x < 0.0 {
                *gi += 2.0 * lambda * x;
            } else if x > 1.0 {
                *gi += 2.0 * lambda * (x - 1.0);
            }
        }
        let gg: f64 = g.iter().map(|v| v * v).sum();
        if gg.sqrt() <= tol * scale {
            break;
        }
        iterations += 1;
        let hg = qp.hv(&g);
        let mut curvature: f64 = hg.iter().zip(&g).map(|(h, g)| h * g).sum();
        curvature += g
            .iter()
            .zip(&a)
            .filter(|(_, &x)| outside(x))
            .map(|(g, _)| 2.0 * lambda * g * g)
            .sum::<f64>();
        let step = if curvature > 0.0 {
            gg / curvature
        } else {
            1e-3
        };
        for (x, g) in a.iter_mut().zip(&g) {
            *x -= step * g;
        }
    }
    clamp01(&mut a);
    Solution {
        residual: qp.residual(&a),
        a,
        iterations,
    }
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
        if next < current {
            a = b;
            fa = fb;
            current = next;
            damping = (damping * 0.3).max(1e-9);
            if step < tol {
                break;
            }
        } else {
            damping *= 10.0;
            if damping > 1e6 || step < tol {
                break;
            }
        }
    }
    Solution {
        a,
        iterations,
        residual: current,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn blocked_matrix_vector_product_has_the_bits_of_the_row_sums() {
        let mut rng = crate::rng::stream(3, "test/invert/hv");
        for n in [1, 2, 3, 4, 5, 7, 8, 9, 72] {
            let h: Vec<f64> = (0..n * n).map(|_| rng.normal()).collect();
            let mut a: Vec<f64> = (0..n).map(|_| rng.normal()).collect();
            // A first row whose products are all -0.0: the sum's sign must match too.
            a[0] = -0.0;
            let mut h = h;
            for k in 0..n {
                h[k] = if a[k] > 0.0 { -0.0 } else { 0.0 };
            }
            let qp = BoxQp {
                n,
                h: h.clone(),
                g: vec![0.0; n],
                c: 0.0,
            };
            let rows: Vec<u64> = h
                .chunks_exact(n)
                .map(|row| {
                    row.iter()
                        .zip(&a)
                        .map(|(h, x)| h * x)
                        .sum::<f64>()
                        .to_bits()
                })
                .collect();
            let blocked: Vec<u64> = qp.hv(&a).iter().map(|v| v.to_bits()).collect();
            assert_eq!(blocked, rows, "n = {n}");
        }
    }

    /// A small ill-conditioned least squares whose box solution has active bounds.
    fn problem() -> (Vec<Vec<f64>>, Vec<f64>, Vec<f64>) {
        let columns: Vec<Vec<f64>> = (0..6)
            .map(|j| {
                (0..20)
                    .map(|i| ((i * (j + 3)) as f64 * 0.37).sin() + if i == j { 2.0 } else { 0.0 })
                    .collect()
            })
            .collect();
        let truth = vec![0.0, 0.3, 1.0, 0.55, 0.0, 0.8];
        let d: Vec<f64> = (0..20)
            .map(|i| columns.iter().zip(&truth).map(|(c, t)| c[i] * t).sum())
            .collect();
        (columns, d, truth)
    }

    #[test]
    fn projected_gradient_recovers_activations_in_the_box() {
        let (columns, d, truth) = problem();
        let qp = BoxQp::least_squares(&columns, &d);
        let s = projected_gradient(&qp, &[0.5; 6], 1e-10, 10_000);
        for (a, t) in s.a.iter().zip(&truth) {
            assert!((a - t).abs() < 1e-6, "{:?}", s.a);
        }
        assert!(s.a.iter().all(|x| (0.0..=1.0).contains(x)));
    }

    #[test]
    fn targets_outside_the_box_give_bounded_activations() {
        let (columns, d, _) = problem();
        let far: Vec<f64> = d.iter().map(|v| 3.0 * v).collect();
        let qp = BoxQp::least_squares(&columns, &far);
        let s = projected_gradient(&qp, &[0.5; 6], 1e-10, 10_000);
        assert!(s.a.iter().all(|x| (0.0..=1.0).contains(x)));
        assert!(projected_gradient_norm(&qp, &s.a) < 1e-6);
        let p = penalty_descent(&qp, &[0.5; 6], 1e4, 1e-8, 200_000);
        assert!(p.a.iter().all(|x| (0.0..=1.0).contains(x)));
        assert!(p.residual >= s.residual - 1e-9);
    }

    #[test]
    fn au_fit_solves_a_smooth_nonlinear_problem() {
        let truth = [0.2, 0.7, 0.4];
        let mut f = |a: &[f64]| {
            vec![
                a[0] * a[0] + a[1],
                (a[1] * 2.0).sin(),
                a[2] + a[0] * a[2],
                a[1] - a[2],
            ]
        };
        let r = f(&truth);
        let s = au_fit(&mut f, &r, &[0.5; 3], 1e-6, 1e-9, 50);
        for (a, t) in s.a.iter().zip(&truth) {
            assert!((a - t).abs() < 1e-4, "{:?}", s.a);
        }
    }
}
