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

/// Random strictly convex 72-variable QPs (the neck fit's size) whose minima sit partly on
/// the bounds: eight least squares of 40 rows, with 0.05 on the diagonal.
fn random_qps() -> Vec<BoxQp> {
    let mut rng = crate::rng::stream(5, "test/invert/newton");
    (0..8)
        .map(|_| {
            let (n, m) = (72, 40);
            let columns: Vec<Vec<f64>> = (0..n)
                .map(|_| (0..m).map(|_| rng.normal()).collect())
                .collect();
            let d: Vec<f64> = (0..m).map(|_| 3.0 * rng.normal()).collect();
            let mut qp = BoxQp::least_squares(&columns, &d);
            for i in 0..n {
                qp.h[i * n + i] += 0.05;
            }
            qp
        })
        .collect()
}

/// The largest difference between two answers' activations.
fn largest_difference(x: &[f64], y: &[f64]) -> f64 {
    x.iter()
        .zip(y)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max)
}

/// The random QPs: projected Newton meets FISTA's stationarity test at the same minimum, in
/// far fewer iterations.
#[test]
fn projected_newton_finds_the_minimum_projected_gradient_finds() {
    for (trial, qp) in random_qps().into_iter().enumerate() {
        let n = qp.n;
        let fista = projected_gradient(&qp, &[0.0; 72], 1e-10, 200_000);
        let newton = projected_newton(&qp, &[0.0; 72], 1e-10, 100);
        assert!(fista.converged && newton.converged, "trial {trial}");
        let bound = newton.a.iter().filter(|&&x| x == 0.0 || x == 1.0).count();
        assert!(bound > 0 && bound < n, "trial {trial}: {bound} at a bound");
        let apart = largest_difference(&fista.a, &newton.a);
        assert!(apart < 1e-6, "trial {trial}: {apart:.2e} apart");
        assert!(
            10 * newton.iterations < fista.iterations,
            "trial {trial}: Newton {} iterations, FISTA {}",
            newton.iterations,
            fista.iterations
        );
    }
}

/// The random QPs: the active-set method (with projected Newton after it where its
/// sets have not settled in 50 iterations) meets the test at projected Newton's minimum,
/// from the box's corner and from its middle, and stays in the box.
#[test]
fn active_set_finds_the_minimum_projected_newton_finds() {
    for (trial, qp) in random_qps().into_iter().enumerate() {
        let newton = projected_newton(&qp, &[0.0; 72], 1e-10, 200);
        for start in [0.0, 0.5] {
            let sets = active_set(&qp, &[start; 72], 1e-10, 50);
            assert!(newton.converged && sets.converged, "trial {trial}");
            let apart = largest_difference(&sets.a, &newton.a);
            assert!(apart < 1e-8, "trial {trial}: {apart:.2e} apart");
            assert!(sets.a.iter().all(|x| (0.0..=1.0).contains(x)));
        }
    }
}

/// Where the sets do not settle within the cap, projected Newton finishes from there.
#[test]
fn active_set_hands_an_unsettled_point_to_projected_newton() {
    let (columns, d, truth) = problem();
    let qp = BoxQp::least_squares(&columns, &d);
    let s = active_set(&qp, &[0.5; 6], 1e-10, 1);
    assert!(s.converged, "{s:?}");
    for (a, t) in s.a.iter().zip(&truth) {
        assert!((a - t).abs() < 1e-6, "{:?}", s.a);
    }
}

#[test]
fn targets_outside_the_box_give_bounded_activations() {
    let (columns, d, _) = problem();
    let far: Vec<f64> = d.iter().map(|v| 3.0 * v).collect();
    let qp = BoxQp::least_squares(&columns, &far);
    let s = projected_gradient(&qp, &[0.5; 6], 1e-10, 10_000);
    assert!(s.a.iter().all(|x| (0.0..=1.0).contains(x)));
    assert!(projected_gradient_norm(&qp, &s.a) < 1e-6);
    assert!(s.converged);
}

/// The largest `|d/da_i |M a - d|^2|` at `a`: the penalty weight above which Choe's
/// linear penalty is exact there.
fn exactness_threshold(qp: &BoxQp, a: &[f64]) -> f64 {
    qp.gradient(a)
        .iter()
        .map(|g| 2.0 * g.abs())
        .fold(0.0, f64::max)
}

#[test]
fn choes_linear_penalty_converges_to_the_box_solution_above_its_exactness_threshold() {
    let (columns, d, _) = problem();
    // A target outside the box, so that the bounds are active and the penalty matters.
    let far: Vec<f64> = d.iter().map(|v| 3.0 * v).collect();
    let qp = BoxQp::least_squares(&columns, &far);
    let boxed = projected_gradient(&qp, &[0.0; 6], 1e-12, 100_000);
    assert!(boxed.converged);
    let threshold = exactness_threshold(&qp, &boxed.a);
    assert!(threshold > 1.0, "bounds active: {threshold}");
    let exact = accelerated(
        &qp,
        Bound::Penalty(2.0 * threshold),
        &[0.0; 6],
        1e-12,
        100_000,
    );
    assert!(exact.converged, "{} iterations", exact.iterations);
    assert!(exact.iterations < 100_000);
    for (p, b) in exact.a.iter().zip(&boxed.a) {
        assert!((p - b).abs() < 1e-8, "{:?} vs {:?}", exact.a, boxed.a);
    }
    // Below it the minimum leaves the box, and it is a minimum: its proximal gradient
    // vanishes and no nearby point (in any coordinate) is lower.
    let bound = Bound::Penalty(0.25 * threshold);
    let soft = accelerated(&qp, bound, &[0.0; 6], 1e-12, 100_000);
    assert!(soft.converged);
    assert!(
        soft.a.iter().any(|x| !(0.0..=1.0).contains(x)),
        "{:?}",
        soft.a
    );
    let objective = |a: &[f64]| qp.residual(a) + bound.penalty(a);
    let best = objective(&soft.a);
    for i in 0..6 {
        for h in [-1e-4, 1e-4] {
            let mut b = soft.a.clone();
            b[i] += h;
            assert!(objective(&b) >= best - 1e-12, "coordinate {i}, step {h}");
        }
    }
    assert_eq!(stationarity(&qp, bound, &soft.a), soft.gradient_norm);
}

#[test]
fn the_penalty_prox_is_a_soft_threshold_toward_the_box() {
    let b = Bound::Penalty(4.0);
    // mu = c / 2 * step = 1 at step 0.5.
    let cases = [
        (-3.0, -2.0),
        (-0.5, 0.0),
        (0.3, 0.3),
        (1.5, 1.0),
        (2.5, 1.5),
    ];
    for (x, want) in cases {
        assert_eq!(b.prox(x, 0.5), want, "prox({x})");
    }
    assert_eq!(b.penalty(&[-0.5, 0.5, 1.25]), 4.0 * 0.75);
    assert_eq!(Bound::Box.prox(-0.5, 0.5), 0.0);
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
