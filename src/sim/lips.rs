//! Contact between the lips: the upper lip's margin may touch the lower one's but not pass
//! below it (and the lower not above the upper). Each margin vertex is compared with the
//! opposite margin's segment beneath (or above) it in the face plane, wherever the lips have
//! slid to, so a lip pulled sideways (a jaw twist, one half of the sphincter) still meets
//! the part of the other lip it is over. The penalty `E = k/2 min(0, gap)^2` acts on the
//! height gap; its gradient and Hessian are exact (the Hessian's curvature term, which
//! comes from the segment's slope, is kept only where the solver asks for the full one).
//! Depends on `geom`, `rig`.

use super::geom::V3;
use super::rig::split_contour;

/// The lips' inner margins (surface sheet nodes), each ordered by its rest abscissa, the
/// corners left out: there the margins meet by construction.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct LipMargins {
    pub upper: Vec<usize>,
    pub lower: Vec<usize>,
}

/// One margin vertex in contact with a segment of the opposite margin: its nodes `[v, a, b]`,
/// the signed gap (negative: overlap) and the gap's derivatives over the local coordinates
/// `[x_v, y_v, x_a, y_a, x_b, y_b]` (z plays no part).
#[derive(Clone, Debug, PartialEq)]
pub struct LipContact {
    pub nodes: [usize; 3],
    pub gap: f64,
    pub grad: [f64; 6],
    pub hess: [[f64; 6]; 6],
}

/// The gap of `v` above (sign +1) or below (sign -1) the segment `a`-`b` at its abscissa, with
/// derivatives; None if `v` is not over the segment or the segment is vertical.
///
/// With `u = x_v - x_a`, `dx = x_b - x_a`, `dy = y_b - y_a`: `gap = s (y_v - y_a - u dy / dx)`.
fn segment_gap(x: &[V3], [v, a, b]: [usize; 3], sign: f64) -> Option<LipContact> {
    let (xv, xa, xb) = (x[v][0], x[a][0], x[b][0]);
    let (lo, hi) = (xa.min(xb), xa.max(xb));
    let dx = xb - xa;
    if xv < lo || xv > hi || dx.abs() < 1e-6 {
        return None;
    }
    let (u, dy) = (xv - xa, x[b][1] - x[a][1]);
    let h = u * dy / dx;
    let q = x[v][1] - x[a][1] - h;
    // Derivatives of h in p = (u, dy, dx), and of p in the local coordinates.
    let dh = [dy / dx, u / dx, -u * dy / (dx * dx)];
    let hh = [
        [0.0, 1.0 / dx, -dy / (dx * dx)],
        [1.0 / dx, 0.0, -u / (dx * dx)],
        [
            -dy / (dx * dx),
            -u / (dx * dx),
            2.0 * u * dy / (dx * dx * dx),
        ],
    ];
    let dp: [[f64; 6]; 3] = [
        [1.0, 0.0, -1.0, 0.0, 0.0, 0.0],
        [0.0, 0.0, 0.0, -1.0, 0.0, 1.0],
        [0.0, 0.0, -1.0, 0.0, 1.0, 0.0],
    ];
    let mut grad = [0.0, 1.0, 0.0, -1.0, 0.0, 0.0];
    for k in 0..3 {
        for (g, d) in grad.iter_mut().zip(dp[k]) {
            *g -= dh[k] * d;
        }
    }
    let mut hess = [[0.0; 6]; 6];
    for i in 0..3 {
        for j in 0..3 {
            for r in 0..6 {
                for c in 0..6 {
                    hess[r][c] -= hh[i][j] * dp[i][r] * dp[j][c];
                }
            }
        }
    }
    Some(LipContact {
        nodes: [v, a, b],
        gap: sign * q,
        grad: grad.map(|g| sign * g),
        hess: hess.map(|row| row.map(|h| sign * h)),
    })
}

impl LipMargins {
    /// The margins of the mouth contour at rest positions `p`.
    pub fn new(mouth: &[usize], p: &[V3]) -> LipMargins {
        let (_, _, mut upper, mut lower) = split_contour(mouth, p);
        let by_x = |a: &usize, b: &usize| p[*a][0].total_cmp(&p[*b][0]).then(a.cmp(b));
        upper.sort_by(by_x);
        lower.sort_by(by_x);
        LipMargins { upper, lower }
    }

    /// Every node of both margins.
    pub fn nodes(&self) -> impl Iterator<Item = usize> + '_ {
        self.upper.iter().chain(&self.lower).copied()
    }

    /// The contacts with overlap (gap < 0) at positions `x`: each vertex of one margin
    /// against the first segment of the other that lies under (or over) it.
    pub fn active(&self, x: &[V3]) -> Vec<LipContact> {
        let mut out = Vec::new();
        for (own, other, sign) in [
            (&self.upper, &self.lower, 1.0),
            (&self.lower, &self.upper, -1.0),
        ] {
            for &v in own {
                let hit = other
                    .windows(2)
                    .find_map(|w| segment_gap(x, [v, w[0], w[1]], sign));
                if let Some(c) = hit.filter(|c| c.gap < 0.0) {
                    out.push(c);
                }
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The gap's gradient and Hessian against central differences of the gap itself.
    #[test]
    fn segment_gap_derivatives_match_finite_differences() {
        let x0: Vec<V3> = vec![
            [0.3e-3, -1.0e-3, 0.0],
            [-2e-3, 0.5e-3, 0.0],
            [3e-3, 1.5e-3, 0.0],
        ];
        for sign in [1.0, -1.0] {
            let c = segment_gap(&x0, [0, 1, 2], sign).unwrap();
            let coords = [(0, 0), (0, 1), (1, 0), (1, 1), (2, 0), (2, 1)];
            let gap_at = |k: usize, t: f64| {
                let mut x = x0.clone();
                x[coords[k].0][coords[k].1] += t;
                segment_gap(&x, [0, 1, 2], sign).unwrap()
            };
            let h = 1e-8;
            for k in 0..6 {
                let (p, m) = (gap_at(k, h), gap_at(k, -h));
                let fd = (p.gap - m.gap) / (2.0 * h);
                assert!(
                    (fd - c.grad[k]).abs() < 1e-6,
                    "d gap / d{k}: {fd} vs {}",
                    c.grad[k]
                );
                for r in 0..6 {
                    let fd2 = (p.grad[r] - m.grad[r]) / (2.0 * h);
                    assert!(
                        (fd2 - c.hess[r][k]).abs() < 1e-3 * (1.0 + c.hess[r][k].abs()),
                        "d2 gap / d{r} d{k}: {fd2} vs {}",
                        c.hess[r][k]
                    );
                }
            }
        }
    }

    #[test]
    fn a_vertex_beside_the_segment_or_above_it_has_no_contact() {
        let x: Vec<V3> = vec![[5e-3, -1e-3, 0.0], [-2e-3, 0.0, 0.0], [3e-3, 0.0, 0.0]];
        assert!(segment_gap(&x, [0, 1, 2], 1.0).is_none());
        let margins = LipMargins {
            upper: vec![0],
            lower: vec![1, 2],
        };
        let above: Vec<V3> = vec![[0.0, 1e-3, 0.0], [-2e-3, 0.0, 0.0], [3e-3, 0.0, 0.0]];
        assert!(margins.active(&above).is_empty());
        let below: Vec<V3> = vec![[0.0, -1e-3, 0.0], [-2e-3, 0.0, 0.0], [3e-3, 0.0, 0.0]];
        let contacts = margins.active(&below);
        assert_eq!(contacts.len(), 1);
        assert!((contacts[0].gap + 1e-3).abs() < 1e-12);
    }
}
