//! Small fixed-size vector and rotation algebra for the simulator.
//!
//! Positions are `[f64; 3]` in metres. Nothing here allocates; nothing here knows about faces.

/// A point or direction in metres.
pub type V3 = [f64; 3];

#[inline]
pub fn add(a: V3, b: V3) -> V3 {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

#[inline]
pub fn sub(a: V3, b: V3) -> V3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

#[inline]
pub fn scale(a: V3, s: f64) -> V3 {
    [a[0] * s, a[1] * s, a[2] * s]
}

#[inline]
pub fn dot(a: V3, b: V3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

#[inline]
pub fn cross(a: V3, b: V3) -> V3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

#[inline]
pub fn norm(a: V3) -> f64 {
    dot(a, a).sqrt()
}

/// `a / |a|`, or zero for a zero vector.
#[inline]
pub fn normalize(a: V3) -> V3 {
    let n = norm(a);
    if n > 0.0 {
        scale(a, 1.0 / n)
    } else {
        [0.0; 3]
    }
}

#[inline]
pub fn lerp(a: V3, b: V3, t: f64) -> V3 {
    add(a, scale(sub(b, a), t))
}

/// Smoothstep of `t` clamped to [0, 1]: 0 below, 1 above, with zero slope at both ends.
pub fn smoothstep(t: f64) -> f64 {
    let t = t.clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// Signed volume of the tetrahedron (a, b, c, d): positive when (b-a, c-a, d-a) is right-handed.
#[inline]
pub fn tet_volume(a: V3, b: V3, c: V3, d: V3) -> f64 {
    dot(cross(sub(b, a), sub(c, a)), sub(d, a)) / 6.0
}

/// A 3x3 rotation matrix, row-major.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Rot3(pub [[f64; 3]; 3]);

impl Rot3 {
    pub const IDENTITY: Rot3 = Rot3([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]);

    /// Rotation by `angle` radians about the unit `axis` (Rodrigues' formula).
    pub fn about_axis(axis: V3, angle: f64) -> Rot3 {
        let [x, y, z] = normalize(axis);
        let (s, c) = angle.sin_cos();
        let t = 1.0 - c;
        Rot3([
            [t * x * x + c, t * x * y - s * z, t * x * z + s * y],
            [t * x * y + s * z, t * y * y + c, t * y * z - s * x],
            [t * x * z - s * y, t * y * z + s * x, t * z * z + c],
        ])
    }

    #[inline]
    pub fn apply(&self, v: V3) -> V3 {
        let m = &self.0;
        [dot(m[0], v), dot(m[1], v), dot(m[2], v)]
    }

    /// Rotation by the rotation vector `v` (axis times angle, radians): the exponential map.
    pub fn exp(v: V3) -> Rot3 {
        let angle = norm(v);
        if angle < 1e-300 {
            return Rot3::IDENTITY;
        }
        Rot3::about_axis(v, angle)
    }

    /// The rotation vector of `self` (the logarithm map), for angles below pi.
    pub fn log(&self) -> V3 {
        let m = &self.0;
        let skew = [m[2][1] - m[1][2], m[0][2] - m[2][0], m[1][0] - m[0][1]];
        let cos = ((m[0][0] + m[1][1] + m[2][2] - 1.0) * 0.5).clamp(-1.0, 1.0);
        let sin = 0.5 * norm(skew);
        let angle = sin.atan2(cos);
        // angle / sin(angle), with its series near zero.
        let factor = if angle < 1e-4 {
            1.0 + angle * angle / 6.0
        } else {
            angle / sin
        };
        scale(skew, 0.5 * factor)
    }

    pub fn transpose(&self) -> Rot3 {
        let m = &self.0;
        Rot3([
            [m[0][0], m[1][0], m[2][0]],
            [m[0][1], m[1][1], m[2][1]],
            [m[0][2], m[1][2], m[2][2]],
        ])
    }

    /// `self^T v`.
    #[inline]
    pub fn apply_transpose(&self, v: V3) -> V3 {
        let m = &self.0;
        [
            m[0][0] * v[0] + m[1][0] * v[1] + m[2][0] * v[2],
            m[0][1] * v[0] + m[1][1] * v[1] + m[2][1] * v[2],
            m[0][2] * v[0] + m[1][2] * v[1] + m[2][2] * v[2],
        ]
    }

    pub fn mul(&self, other: &Rot3) -> Rot3 {
        let mut out = [[0.0; 3]; 3];
        for (i, row) in out.iter_mut().enumerate() {
            for (j, cell) in row.iter_mut().enumerate() {
                *cell = (0..3).map(|k| self.0[i][k] * other.0[k][j]).sum();
            }
        }
        Rot3(out)
    }
}

/// A rigid motion x -> R (x - pivot) + pivot + t.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Rigid {
    pub rotation: Rot3,
    pub pivot: V3,
    pub translation: V3,
}

impl Rigid {
    pub const IDENTITY: Rigid = Rigid {
        rotation: Rot3::IDENTITY,
        pivot: [0.0; 3],
        translation: [0.0; 3],
    };

    /// The moved point, computed as `x + displacement(x)` so the identity motion returns `x`
    /// bit for bit.
    #[inline]
    pub fn apply(&self, x: V3) -> V3 {
        add(x, self.displacement(x))
    }

    /// `R (x - pivot) - (x - pivot) + t`: exactly zero for the identity.
    #[inline]
    pub fn displacement(&self, x: V3) -> V3 {
        let r = sub(x, self.pivot);
        add(sub(self.rotation.apply(r), r), self.translation)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rotation_about_z_turns_x_into_y() {
        let r = Rot3::about_axis([0.0, 0.0, 1.0], std::f64::consts::FRAC_PI_2);
        let v = r.apply([1.0, 0.0, 0.0]);
        assert!((v[0]).abs() < 1e-15 && (v[1] - 1.0).abs() < 1e-15);
    }

    #[test]
    fn log_inverts_exp() {
        for v in [[0.3, -0.2, 0.1], [1e-7, 2e-7, -1e-7], [0.0, 2.5, 0.0]] {
            let back = Rot3::exp(v).log();
            for k in 0..3 {
                assert!((back[k] - v[k]).abs() < 1e-12, "{v:?} -> {back:?}");
            }
        }
    }

    #[test]
    fn unit_tet_has_volume_one_sixth() {
        let v = tet_volume([0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]);
        assert!((v - 1.0 / 6.0).abs() < 1e-15);
    }
}
