//! The face frame: rigid alignment of landmark sets (Kabsch). The head pose type and its
//! Euler convention live in `sim::pose` (re-exported here).
//! Coordinates are the model's (+x toward the subject's left, +y up, +z out of the face).

use crate::sim::geom::{sub, Rot3, V3};
pub use crate::sim::pose::HeadPose;

/// The rigid motion `x -> r x + t` that best maps `from[i]` onto `to[i]` (least squares over
/// the chosen points; Kabsch with the reflection fix).
pub fn align(from: &[V3], to: &[V3]) -> (Rot3, V3) {
    let n = from.len() as f64;
    let mean = |ps: &[V3]| {
        let mut m = [0.0; 3];
        for p in ps {
            for k in 0..3 {
                m[k] += p[k] / n;
            }
        }
        m
    };
    let (cf, ct) = (mean(from), mean(to));
    // Cross-covariance H = sum (to - ct)(from - cf)^T; R = U diag(1, 1, det) V^T.
    let mut h = faer::Mat::<f64>::zeros(3, 3);
    for (f, t) in from.iter().zip(to) {
        let (a, b) = (sub(*t, ct), sub(*f, cf));
        for i in 0..3 {
            for j in 0..3 {
                h[(i, j)] += a[i] * b[j];
            }
        }
    }
    let svd = h.svd().expect("SVD of a 3x3 matrix");
    let (u, v) = (svd.U(), svd.V());
    let det = |m: faer::MatRef<f64>| {
        m[(0, 0)] * (m[(1, 1)] * m[(2, 2)] - m[(1, 2)] * m[(2, 1)])
            - m[(0, 1)] * (m[(1, 0)] * m[(2, 2)] - m[(1, 2)] * m[(2, 0)])
            + m[(0, 2)] * (m[(1, 0)] * m[(2, 1)] - m[(1, 1)] * m[(2, 0)])
    };
    let d = if det(u) * det(v) < 0.0 { -1.0 } else { 1.0 };
    let mut r = [[0.0; 3]; 3];
    for (i, row) in r.iter_mut().enumerate() {
        for (j, x) in row.iter_mut().enumerate() {
            *x = u[(i, 0)] * v[(j, 0)] + u[(i, 1)] * v[(j, 1)] + d * u[(i, 2)] * v[(j, 2)];
        }
    }
    let r = Rot3(r);
    let rc = r.apply(cf);
    (r, [ct[0] - rc[0], ct[1] - rc[1], ct[2] - rc[2]])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn alignment_recovers_a_rigid_motion() {
        let pts: Vec<V3> = (0..7)
            .map(|i| {
                let f = i as f64;
                [f.sin(), (2.0 * f).cos(), 0.3 * f]
            })
            .collect();
        let r = Rot3::about_axis([0.3, 1.0, -0.2], 0.7);
        let moved: Vec<V3> = pts
            .iter()
            .map(|p| {
                let q = r.apply(*p);
                [q[0] + 1.0, q[1] - 2.0, q[2] + 0.5]
            })
            .collect();
        let (found, t) = align(&pts, &moved);
        for i in 0..3 {
            for j in 0..3 {
                assert!((found.0[i][j] - r.0[i][j]).abs() < 1e-10);
            }
        }
        assert!((t[0] - 1.0).abs() < 1e-10 && (t[1] + 2.0).abs() < 1e-10);
    }
}
