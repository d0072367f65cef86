//! Expression displacement mapping (Choe, Lee & Ko 2001, "Facial Expression Editing"): keys
//! (frame, curve, value) on activation curves are met by adding a smooth displacement, a
//! uniform cubic B-spline fitted to the keys' discrepancies. High-frequency detail of the
//! original curve is kept (the displacement is added, not substituted) and the change stays
//! local: among the spline coefficients meeting the keys the smallest (least squares) is
//! chosen, so only basis functions whose support holds a key are nonzero, and a frame farther
//! than two knot spacings from every such knot (four from every key) is left bit for bit as
//! it was.
//!
//! Pure: curves in, curves out.

/// A keyframe constraint.
#[derive(Clone, Debug, PartialEq)]
pub struct Key {
    pub frame: f64,
    /// Index of the curve (column).
    pub curve: usize,
    pub value: f64,
}

#[derive(Debug, thiserror::Error, PartialEq)]
pub enum EditError {
    #[error("knot spacing {0} must be positive")]
    Spacing(f64),
    #[error("key at frame {frame} on curve {curve}: value {value} is outside [0, 1]")]
    Range {
        frame: f64,
        curve: usize,
        value: f64,
    },
    #[error("key at frame {frame} on curve {curve}: no such frame in the curves")]
    Frame { frame: f64, curve: usize },
    #[error("curve {curve} has two keys at frame {frame}")]
    Duplicate { frame: f64, curve: usize },
    #[error("the keys on curve {curve} are too close for knot spacing {spacing} (the fit is singular); use a smaller spacing")]
    Singular { curve: usize, spacing: f64 },
}

/// The uniform cubic B-spline kernel, support (-2, 2).
fn kernel(u: f64) -> f64 {
    let a = u.abs();
    if a < 1.0 {
        (4.0 - 6.0 * a * a + 3.0 * a * a * a) / 6.0
    } else if a < 2.0 {
        (2.0 - a).powi(3) / 6.0
    } else {
        0.0
    }
}

/// The displacement spline of one curve: coefficients on knots `j * spacing`.
#[derive(Clone, Debug, PartialEq)]
pub struct Displacement {
    pub spacing: f64,
    /// (knot index j, coefficient), only the nonzero ones.
    pub coefficients: Vec<(i64, f64)>,
}

impl Displacement {
    pub fn at(&self, t: f64) -> f64 {
        self.coefficients
            .iter()
            .map(|&(j, c)| c * kernel(t / self.spacing - j as f64))
            .sum()
    }

    /// Fits the minimum-norm spline through `(frame, discrepancy)` points.
    pub fn fit(points: &[(f64, f64)], spacing: f64, curve: usize) -> Result<Self, EditError> {
        if points.is_empty() {
            return Ok(Displacement {
                spacing,
                coefficients: Vec::new(),
            });
        }
        // Knots whose support (|t/h - j| < 2) holds a key.
        let mut knots: Vec<i64> = points
            .iter()
            .flat_map(|&(t, _)| {
                let u = t / spacing;
                (u.floor() as i64 - 1)..=(u.ceil() as i64 + 1)
            })
            .filter(|&j| {
                points
                    .iter()
                    .any(|&(t, _)| kernel(t / spacing - j as f64) > 0.0)
            })
            .collect();
        knots.sort_unstable();
        knots.dedup();
        let a: Vec<Vec<f64>> = points
            .iter()
            .map(|&(t, _)| {
                knots
                    .iter()
                    .map(|&j| kernel(t / spacing - j as f64))
                    .collect()
            })
            .collect();
        // (A A^T) y = d, x = A^T y, by Cholesky of the small key-by-key matrix.
        let n = points.len();
        let mut m = vec![vec![0.0; n]; n];
        for i in 0..n {
            for k in 0..n {
                m[i][k] = a[i].iter().zip(&a[k]).map(|(p, q)| p * q).sum();
            }
        }
        let d: Vec<f64> = points.iter().map(|p| p.1).collect();
        let y = cholesky_solve(&mut m, &d).ok_or(EditError::Singular { curve, spacing })?;
        let coefficients = knots
            .iter()
            .enumerate()
            .map(|(c, &j)| (j, (0..n).map(|i| a[i][c] * y[i]).sum()))
            .collect();
        Ok(Displacement {
            spacing,
            coefficients,
        })
    }
}

/// Solves `m y = d` for symmetric positive definite `m` (overwritten); `None` if `m` is
/// singular to working precision.
fn cholesky_solve(m: &mut [Vec<f64>], d: &[f64]) -> Option<Vec<f64>> {
    let n = d.len();
    let scale = (0..n).map(|i| m[i][i]).fold(0.0, f64::max);
    for j in 0..n {
        let mut s = m[j][j];
        for k in 0..j {
            s -= m[j][k] * m[j][k];
        }
        if s <= 1e-12 * scale {
            return None;
        }
        let l = s.sqrt();
        m[j][j] = l;
        for i in j + 1..n {
            let mut s = m[i][j];
            for k in 0..j {
                s -= m[i][k] * m[j][k];
            }
            m[i][j] = s / l;
        }
    }
    let mut y = d.to_vec();
    for i in 0..n {
        for k in 0..i {
            y[i] -= m[i][k] * y[k];
        }
        y[i] /= m[i][i];
    }
    for i in (0..n).rev() {
        for k in i + 1..n {
            y[i] -= m[k][i] * y[k];
        }
        y[i] /= m[i][i];
    }
    Some(y)
}

/// The edit of one set of curves.
#[derive(Clone, Debug, PartialEq)]
pub struct Edited {
    /// `values[frame][curve]`, clamped to [0, 1].
    pub values: Vec<Vec<f64>>,
    /// Per edited curve: its displacement.
    pub displacements: Vec<(usize, Displacement)>,
}

/// Applies `keys` to `curves` (`curves[frame_index][curve]`, frame numbers in `frames`).
pub fn edit(
    frames: &[f64],
    curves: &[Vec<f64>],
    keys: &[Key],
    spacing: f64,
) -> Result<Edited, EditError> {
    if !(spacing > 0.0 && spacing.is_finite()) {
        return Err(EditError::Spacing(spacing));
    }
    let mut by_curve: std::collections::BTreeMap<usize, Vec<(f64, f64)>> = Default::default();
    for k in keys {
        if !(0.0..=1.0).contains(&k.value) {
            return Err(EditError::Range {
                frame: k.frame,
                curve: k.curve,
                value: k.value,
            });
        }
        let i = frames
            .iter()
            .position(|&f| f == k.frame)
            .ok_or(EditError::Frame {
                frame: k.frame,
                curve: k.curve,
            })?;
        let points = by_curve.entry(k.curve).or_default();
        if points.iter().any(|p| p.0 == k.frame) {
            return Err(EditError::Duplicate {
                frame: k.frame,
                curve: k.curve,
            });
        }
        points.push((k.frame, k.value - curves[i][k.curve]));
    }
    let mut values = curves.to_vec();
    let mut displacements = Vec::new();
    for (curve, points) in by_curve {
        let d = Displacement::fit(&points, spacing, curve)?;
        for (row, &t) in values.iter_mut().zip(frames) {
            let delta = d.at(t);
            if delta != 0.0 {
                row[curve] = (row[curve] + delta).clamp(0.0, 1.0);
            }
        }
        displacements.push((curve, d));
    }
    Ok(Edited {
        values,
        displacements,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn wiggly(n: usize) -> (Vec<f64>, Vec<Vec<f64>>) {
        let frames: Vec<f64> = (0..n).map(|f| f as f64).collect();
        let curves = frames
            .iter()
            .map(|&t| vec![0.3 + 0.1 * (0.9 * t).sin(), 0.5 + 0.05 * (2.3 * t).cos()])
            .collect();
        (frames, curves)
    }

    #[test]
    fn no_keys_is_the_identity() {
        let (frames, curves) = wiggly(50);
        let e = edit(&frames, &curves, &[], 8.0).unwrap();
        assert_eq!(e.values, curves);
    }

    #[test]
    fn keys_are_met_and_far_frames_untouched() {
        let (frames, curves) = wiggly(120);
        let keys = [
            Key {
                frame: 40.0,
                curve: 0,
                value: 0.9,
            },
            Key {
                frame: 47.0,
                curve: 0,
                value: 0.1,
            },
            Key {
                frame: 90.0,
                curve: 1,
                value: 0.2,
            },
        ];
        for spacing in [3.0, 8.0, 16.0] {
            let e = edit(&frames, &curves, &keys, spacing).unwrap();
            for k in &keys {
                let got = e.values[k.frame as usize][k.curve];
                assert!(
                    (got - k.value).abs() < 1e-6,
                    "h {spacing}: {got} vs {}",
                    k.value
                );
            }
            for (i, &t) in frames.iter().enumerate() {
                for c in 0..2 {
                    let near = keys
                        .iter()
                        .any(|k| k.curve == c && (k.frame - t).abs() < 4.0 * spacing);
                    if !near {
                        assert_eq!(e.values[i][c], curves[i][c], "frame {t} curve {c}");
                    }
                }
            }
        }
    }

    #[test]
    fn bad_keys_are_errors() {
        let (frames, curves) = wiggly(20);
        let key = |frame: f64, value: f64| Key {
            frame,
            curve: 0,
            value,
        };
        assert!(matches!(
            edit(&frames, &curves, &[key(3.0, 1.5)], 4.0),
            Err(EditError::Range { .. })
        ));
        assert!(matches!(
            edit(&frames, &curves, &[key(30.0, 0.5)], 4.0),
            Err(EditError::Frame { .. })
        ));
        assert!(matches!(
            edit(&frames, &curves, &[key(3.0, 0.5), key(3.0, 0.6)], 4.0),
            Err(EditError::Duplicate { .. })
        ));
        assert!(matches!(
            edit(&frames, &curves, &[key(3.0, 0.5)], 0.0),
            Err(EditError::Spacing(_))
        ));
    }
}
