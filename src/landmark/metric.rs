//! From image landmarks to the model's frame: a similarity fit (rotation, uniform scale,
//! translation; Umeyama) of Face Mesh's 468 points onto the model's rest surface, whose first
//! 468 vertices are the same canonical mesh.
//!
//! The fit uses only points that expressions barely move (the observer's `STABLE` landmarks,
//! outer face and eye corners, plus the nasal bridge, iBUG 27 and 28), so a smile or an open
//! mouth does not pull the scale or the pose. Image points come in MediaPipe's convention
//! (x right, y down in pixels, z scaled like x, smaller toward the camera) and are turned to
//! the model's (+y up, +z out of the face) before the fit. The rotation that maps the image
//! face onto the model is the inverse of the head's turn, so the head pose is that of `R^T`.

use crate::observe::au::STABLE;
use crate::observe::landmarks::landmark_vertices;
use crate::observe::pose::{align, HeadPose};
use crate::sim::geom::{dot, sub, Rot3, V3};

/// iBUG landmarks on the nasal bridge, rigid with the skull.
const BRIDGE: [usize; 2] = [27, 28];

/// A face in the model's frame.
#[derive(Clone, Debug, PartialEq)]
pub struct MetricFace {
    /// The 468 points in model units (cm), head turn removed.
    pub points: Vec<V3>,
    /// The head's rotation in OpenFace's convention.
    pub pose: HeadPose,
    /// Model units per image pixel.
    pub scale: f64,
    /// RMS residual of the fitted points (model units).
    pub residual: f64,
}

/// The canonical vertices the fit uses.
pub fn fit_vertices() -> Vec<usize> {
    let map = landmark_vertices();
    let mut v: Vec<usize> = STABLE
        .iter()
        .chain(&BRIDGE)
        .flat_map(|&i| map[i].iter().copied())
        .collect();
    v.sort_unstable();
    v.dedup();
    v
}

/// Fits `image` (468 MediaPipe points) onto `rest` (at least 468 model vertices).
pub fn fit(image: &[[f64; 3]], rest: &[V3]) -> MetricFace {
    let cam: Vec<V3> = image.iter().map(|p| [p[0], -p[1], -p[2]]).collect();
    let idx = fit_vertices();
    let from: Vec<V3> = idx.iter().map(|&i| cam[i]).collect();
    let to: Vec<V3> = idx.iter().map(|&i| rest[i]).collect();
    let (s, r, t) = similarity(&from, &to);
    let map = |p: V3| {
        let q = r.apply(p);
        [s * q[0] + t[0], s * q[1] + t[1], s * q[2] + t[2]]
    };
    let points: Vec<V3> = cam.iter().map(|&p| map(p)).collect();
    let residual = (idx
        .iter()
        .map(|&i| {
            let d = sub(points[i], rest[i]);
            dot(d, d)
        })
        .sum::<f64>()
        / idx.len() as f64)
        .sqrt();
    MetricFace {
        points,
        pose: HeadPose::from_rotation(&r.transpose()),
        scale: s,
        residual,
    }
}

/// The similarity `x -> s R x + t` that best maps `from` onto `to` in least squares: Kabsch's
/// rotation (invariant to scale) and then the optimal scale for it.
pub fn similarity(from: &[V3], to: &[V3]) -> (f64, Rot3, V3) {
    let n = from.len() as f64;
    let mean = |ps: &[V3]| {
        ps.iter().fold([0.0; 3], |m, p| {
            [m[0] + p[0] / n, m[1] + p[1] / n, m[2] + p[2] / n]
        })
    };
    let (cf, ct) = (mean(from), mean(to));
    let (r, _) = align(from, to);
    let (mut num, mut den) = (0.0, 0.0);
    for (f, g) in from.iter().zip(to) {
        let a = r.apply(sub(*f, cf));
        num += dot(a, sub(*g, ct));
        den += dot(a, a);
    }
    let s = if den > 0.0 { num / den } else { 1.0 };
    let rc = r.apply(cf);
    (
        s,
        r,
        [ct[0] - s * rc[0], ct[1] - s * rc[1], ct[2] - s * rc[2]],
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_turned_scaled_face_comes_back_with_its_pose() {
        // A stand-in "face": 468 scattered points.
        let rest: Vec<V3> = (0..468)
            .map(|i| {
                let f = i as f64;
                [
                    (0.7 * f).sin() * 6.0,
                    (1.3 * f).cos() * 8.0,
                    (0.2 * f).sin() * 3.0,
                ]
            })
            .collect();
        let pose = HeadPose {
            pitch: 0.2,
            yaw: -0.3,
            roll: 0.1,
        };
        let turn = pose.rotation();
        // The image: head turned, 12 px per model unit, shifted, in MediaPipe's axes.
        let image: Vec<[f64; 3]> = rest
            .iter()
            .map(|&p| {
                let q = turn.apply(p);
                [12.0 * q[0] + 300.0, -12.0 * q[1] + 200.0, -12.0 * q[2]]
            })
            .collect();
        let face = fit(&image, &rest);
        assert!((face.scale - 1.0 / 12.0).abs() < 1e-12);
        assert!(face.residual < 1e-9);
        for (a, b) in face.points.iter().zip(&rest) {
            assert!(sub(*a, *b).iter().all(|d| d.abs() < 1e-9));
        }
        let got = face.pose;
        assert!(
            (got.pitch - 0.2).abs() < 1e-9
                && (got.yaw + 0.3).abs() < 1e-9
                && (got.roll - 0.1).abs() < 1e-9
        );
    }
}
