//! Fitting the observer's readout to OpenFace's AUs on real faces: per AU, a nonnegative
//! least-squares fit (Lawson and Hanson's active-set method) of its intensities on the
//! readout's inputs (`features::inputs`), with a free intercept and a small ridge, stretched
//! so that its readings spread like OpenFace's, and a leave-one-person-out validation of it.
//! Pure: the caller reads the files.
//!
//! Why nonnegative: each input is a part (positive or negative) of what one landmark group
//! does, so a weight says how much of an AU that motion carries. An unconstrained fit on five
//! people learns signs from who happened to do what together (one person frowns while another
//! talks) that do not carry to the next person; the sign constraint is the prior that a motion
//! never counts against an AU.

use faer::linalg::solvers::Solve;

use super::au::{FittedReadout, AU_COUNT};
use super::features::INPUT_COUNT;

/// The ridge added to the Gram matrix, as a fraction of its mean diagonal.
pub const RIDGE: f64 = 1e-3;

#[derive(Debug, thiserror::Error, PartialEq)]
pub enum FitError {
    #[error("no frames to fit")]
    Empty,
    #[error("a value is not finite (frame {frame})")]
    NonFinite { frame: usize },
    #[error("the nonnegative least-squares fit did not converge in {0} steps")]
    NoConvergence(usize),
    #[error("the Gram matrix is not positive definite; the inputs are degenerate")]
    Singular,
    #[error("leave-one-person-out needs at least two people, got {0}")]
    TooFewPeople(usize),
}

/// Minimises `w'Gw / 2 - b'w` over `w >= 0` for a symmetric positive definite `g` (`n x n`,
/// row-major): Lawson and Hanson's NNLS on the normal equations.
pub fn nnls_gram(g: &[f64], b: &[f64]) -> Result<Vec<f64>, FitError> {
    let n = b.len();
    assert_eq!(g.len(), n * n, "Gram matrix is n x n");
    let scale = b.iter().map(|v| v.abs()).fold(0.0, f64::max).max(1e-300);
    let tol = 1e-12 * scale;
    let mut w = vec![0.0; n];
    let mut passive = vec![false; n];
    let max_steps = 10 * n + 10;
    let mut steps = 0;
    loop {
        // The negative gradient; the most promising zero variable joins the passive set.
        let grad: Vec<f64> = (0..n)
            .map(|i| b[i] - (0..n).map(|j| g[i * n + j] * w[j]).sum::<f64>())
            .collect();
        let candidate = (0..n)
            .filter(|&i| !passive[i])
            .max_by(|&a, &c| grad[a].total_cmp(&grad[c]));
        match candidate {
            Some(j) if grad[j] > tol => passive[j] = true,
            _ => return Ok(w),
        }
        loop {
            steps += 1;
            if steps > max_steps {
                return Err(FitError::NoConvergence(max_steps));
            }
            let s = solve_passive(g, b, &passive)?;
            if (0..n).all(|i| !passive[i] || s[i] > 0.0) {
                w = s;
                break;
            }
            // Step from w toward s until the first passive variable reaches zero.
            let alpha = (0..n)
                .filter(|&i| passive[i] && s[i] <= 0.0)
                .map(|i| w[i] / (w[i] - s[i]))
                .fold(f64::INFINITY, f64::min);
            for i in 0..n {
                w[i] += alpha * (s[i] - w[i]);
                if passive[i] && w[i] <= 1e-15 * scale.max(1.0) {
                    passive[i] = false;
                    w[i] = 0.0;
                }
            }
        }
    }
}

/// The unconstrained minimiser over the passive variables (zero elsewhere).
fn solve_passive(g: &[f64], b: &[f64], passive: &[bool]) -> Result<Vec<f64>, FitError> {
    let n = b.len();
    let idx: Vec<usize> = (0..n).filter(|&i| passive[i]).collect();
    let m = idx.len();
    let a = faer::Mat::<f64>::from_fn(m, m, |r, c| g[idx[r] * n + idx[c]]);
    let rhs = faer::Mat::<f64>::from_fn(m, 1, |r, _| b[idx[r]]);
    let llt = a.llt(faer::Side::Lower).map_err(|_| FitError::Singular)?;
    let x = llt.solve(&rhs);
    let mut s = vec![0.0; n];
    for (r, &i) in idx.iter().enumerate() {
        s[i] = x[(r, 0)];
    }
    Ok(s)
}

/// Which inputs each AU's readout may read (`allowed[au][input]`).
pub type Allowed = [[bool; INPUT_COUNT]; AU_COUNT];

/// Every input for every AU.
pub const ALL_INPUTS: Allowed = [[true; INPUT_COUNT]; AU_COUNT];

/// Fits the readout to frames `x` (inputs) and `y` (OpenFace's intensities), each AU on its
/// `allowed` inputs.
pub fn fit_readout(
    x: &[[f64; INPUT_COUNT]],
    y: &[[f64; AU_COUNT]],
    allowed: &Allowed,
) -> Result<FittedReadout, FitError> {
    assert_eq!(x.len(), y.len());
    let rows = x.len();
    if rows == 0 {
        return Err(FitError::Empty);
    }
    if let Some(frame) = (0..rows).find(|&r| x[r].iter().chain(&y[r]).any(|v| !v.is_finite())) {
        return Err(FitError::NonFinite { frame });
    }
    let n = INPUT_COUNT;
    let mean_x: Vec<f64> = (0..n)
        .map(|j| x.iter().map(|r| r[j]).sum::<f64>() / rows as f64)
        .collect();
    let mean_y: [f64; AU_COUNT] =
        std::array::from_fn(|k| y.iter().map(|r| r[k]).sum::<f64>() / rows as f64);
    let mut g = vec![0.0; n * n];
    let mut b = vec![[0.0; AU_COUNT]; n];
    for (xr, yr) in x.iter().zip(y) {
        let xc: Vec<f64> = (0..n).map(|j| xr[j] - mean_x[j]).collect();
        for i in 0..n {
            if xc[i] == 0.0 {
                continue;
            }
            for j in i..n {
                g[i * n + j] += xc[i] * xc[j];
            }
            for k in 0..AU_COUNT {
                b[i][k] += xc[i] * (yr[k] - mean_y[k]);
            }
        }
    }
    for i in 0..n {
        for j in i..n {
            g[i * n + j] /= rows as f64;
            g[j * n + i] = g[i * n + j];
        }
        for v in b[i].iter_mut() {
            *v /= rows as f64;
        }
    }
    let trace = (0..n).map(|i| g[i * n + i]).sum::<f64>() / n as f64;
    for i in 0..n {
        g[i * n + i] += RIDGE * trace.max(1e-300);
    }
    let mut readout = FittedReadout {
        intercept: [0.0; AU_COUNT],
        weights: [[0.0; INPUT_COUNT]; AU_COUNT],
    };
    for k in 0..AU_COUNT {
        let idx: Vec<usize> = (0..n).filter(|&j| allowed[k][j]).collect();
        let m = idx.len();
        let sub_g: Vec<f64> = (0..m * m).map(|e| g[idx[e / m] * n + idx[e % m]]).collect();
        let sub_b: Vec<f64> = idx.iter().map(|&j| b[j][k]).collect();
        let mut w = vec![0.0; n];
        for (&j, v) in idx.iter().zip(nnls_gram(&sub_g, &sub_b)?) {
            w[j] = v;
        }
        // Least squares shrinks its predictions toward the mean by their correlation with the
        // truth; an instrument must span the scale it reads on, so the fitted combination is
        // stretched until its spread over the frames matches OpenFace's (this leaves r as it
        // is and costs some MAE).
        let fitted: Vec<f64> = x
            .iter()
            .map(|r| (0..n).map(|j| w[j] * (r[j] - mean_x[j])).sum::<f64>())
            .collect();
        let sd_fit = crate::stats::rms(&fitted);
        let column: Vec<f64> = y.iter().map(|r| r[k]).collect();
        let (_, sd_y) = crate::stats::mean_sd(&column);
        if sd_fit > 1e-12 {
            let stretch = sd_y / sd_fit;
            w.iter_mut().for_each(|v| *v *= stretch);
        }
        readout.weights[k].copy_from_slice(&w);
        readout.intercept[k] = mean_y[k] - (0..n).map(|j| w[j] * mean_x[j]).sum::<f64>();
    }
    Ok(readout)
}

/// One person's frames for the validation.
#[derive(Clone, Debug)]
pub struct PersonFrames {
    pub person: String,
    pub inputs: Vec<[f64; INPUT_COUNT]>,
    pub aus: Vec<[f64; AU_COUNT]>,
}

/// For each person, the intensities predicted for their frames by a readout fitted on
/// everyone else (clamped to [0, 5], as the observer reads them).
pub fn leave_one_person_out(
    people: &[PersonFrames],
    allowed: &Allowed,
) -> Result<Vec<Vec<[f64; AU_COUNT]>>, FitError> {
    if people.len() < 2 {
        return Err(FitError::TooFewPeople(people.len()));
    }
    people
        .iter()
        .enumerate()
        .map(|(held, p)| {
            let (mut x, mut y) = (Vec::new(), Vec::new());
            for (i, q) in people.iter().enumerate() {
                if i != held {
                    x.extend_from_slice(&q.inputs);
                    y.extend_from_slice(&q.aus);
                }
            }
            let readout = fit_readout(&x, &y, allowed)?;
            Ok(p.inputs.iter().map(|r| readout.read(r)).collect())
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The exact minimiser by trying every active set (small n only).
    fn brute_force(g: &[f64], b: &[f64]) -> Vec<f64> {
        let n = b.len();
        let objective = |w: &[f64]| {
            let mut v = 0.0;
            for i in 0..n {
                v -= b[i] * w[i];
                for j in 0..n {
                    v += 0.5 * w[i] * g[i * n + j] * w[j];
                }
            }
            v
        };
        let mut best = (0.0, vec![0.0; n]);
        for mask in 1..(1u32 << n) {
            let passive: Vec<bool> = (0..n).map(|i| mask & (1 << i) != 0).collect();
            let s = solve_passive(g, b, &passive).unwrap();
            if s.iter().all(|&v| v >= 0.0) && objective(&s) < best.0 {
                best = (objective(&s), s);
            }
        }
        best.1
    }

    #[test]
    fn nnls_matches_the_exhaustive_minimiser() {
        // G = A'A for a fixed A, b = A'y with a y that makes some weights want to be negative.
        let a = [
            [1.0, 0.2, 0.0, 0.5],
            [0.3, 1.0, 0.4, 0.0],
            [0.0, 0.6, 1.0, 0.2],
            [0.5, 0.0, 0.3, 1.0],
            [0.2, 0.1, 0.9, 0.4],
        ];
        for y in [
            [1.0, -2.0, 0.5, 3.0, -1.0],
            [-1.0, -1.0, -1.0, -1.0, -1.0],
            [2.0, 1.0, 0.0, 1.0, 2.0],
        ] {
            let n = 4;
            let mut g = vec![0.0; n * n];
            let mut b = vec![0.0; n];
            for (row, yr) in a.iter().zip(y) {
                for i in 0..n {
                    b[i] += row[i] * yr;
                    for j in 0..n {
                        g[i * n + j] += row[i] * row[j];
                    }
                }
            }
            let w = nnls_gram(&g, &b).unwrap();
            let exact = brute_force(&g, &b);
            for (p, q) in w.iter().zip(&exact) {
                assert!((p - q).abs() < 1e-10, "{w:?} vs {exact:?}");
            }
            assert!(w.iter().all(|&v| v >= 0.0));
        }
    }

    #[test]
    fn the_fit_recovers_nonnegative_weights_and_refuses_bad_input() {
        // Frames whose AU00 is 0.5 + 2 x input 3 + 1 x input 70, exactly.
        let mut rng = crate::rng::stream(1, "test/fit");
        let mut x = Vec::new();
        let mut y = Vec::new();
        for _ in 0..600 {
            let mut xr = [0.0; INPUT_COUNT];
            for v in xr.iter_mut() {
                *v = rng.uniform();
            }
            let mut yr = [0.0; AU_COUNT];
            yr[0] = 0.5 + 2.0 * xr[3] + xr[70];
            x.push(xr);
            y.push(yr);
        }
        let readout = fit_readout(&x, &y, &ALL_INPUTS).unwrap();
        let mut only_three = [[false; INPUT_COUNT]; AU_COUNT];
        only_three[0][3] = true;
        let narrow = fit_readout(&x, &y, &only_three).unwrap();
        assert!(narrow.weights[0]
            .iter()
            .enumerate()
            .all(|(j, &w)| j == 3 || w == 0.0));
        assert!(narrow.weights[0][3] > 1.0);
        let pred = readout.read(&x[5]);
        assert!(
            (pred[0] - y[5][0]).abs() < 0.02,
            "{} vs {}",
            pred[0],
            y[5][0]
        );
        assert!(readout.weights.iter().flatten().all(|&w| w >= 0.0));
        assert!((readout.weights[0][3] - 2.0).abs() < 0.05);
        assert!(pred[1].abs() < 1e-9);

        assert_eq!(fit_readout(&[], &[], &ALL_INPUTS), Err(FitError::Empty));
        x[7][2] = f64::NAN;
        assert_eq!(
            fit_readout(&x, &y, &ALL_INPUTS),
            Err(FitError::NonFinite { frame: 7 })
        );
        let one = PersonFrames {
            person: "a".into(),
            inputs: vec![],
            aus: vec![],
        };
        assert_eq!(
            leave_one_person_out(&[one], &ALL_INPUTS),
            Err(FitError::TooFewPeople(1))
        );
    }
}
