//! Head pose in OpenFace's Euler angles: the quantity the observer reads from landmarks and
//! the neck's controllers take as a target. Defined here, beside the rotations it converts,
//! so that `sim` needs nothing from `observe`.
//!
//! Coordinates are the model's: +x toward the subject's left, +y up, +z out of the face, so a
//! camera in front sees +x on the image's right. OpenFace's camera frame has +y down and +z
//! into the scene, a half turn about x from ours (`C = diag(1, -1, -1)`); a head rotation `R`
//! in our frame is `C R C` in OpenFace's. OpenFace composes `R = Rx(pitch) Ry(yaw) Rz(roll)`
//! (its `Euler2RotationMatrix`), so `yaw = asin(R02)`, `pitch = atan2(-R12, R22)`,
//! `roll = atan2(-R01, R00)`. Positive pitch turns the face down.

use crate::sim::geom::{Rot3, V3};

/// Head rotation in OpenFace's convention (`pose_Rx`, `pose_Ry`, `pose_Rz`), radians.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct HeadPose {
    pub pitch: f64,
    pub yaw: f64,
    pub roll: f64,
}

impl HeadPose {
    pub fn from_degrees(pitch: f64, yaw: f64, roll: f64) -> HeadPose {
        HeadPose::from_array([pitch, yaw, roll].map(f64::to_radians))
    }

    /// `[pitch, yaw, roll]` (rad).
    pub fn to_array(self) -> V3 {
        [self.pitch, self.yaw, self.roll]
    }

    pub fn from_array(a: V3) -> HeadPose {
        HeadPose {
            pitch: a[0],
            yaw: a[1],
            roll: a[2],
        }
    }

    /// `[pitch, yaw, roll]` (degrees).
    pub fn degrees(self) -> V3 {
        self.to_array().map(f64::to_degrees)
    }

    /// The angle (degrees) of the rotation between two poses.
    pub fn error_degrees(self, other: HeadPose) -> f64 {
        let r = self.rotation().transpose().mul(&other.rotation());
        let v = r.log();
        (v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
            .sqrt()
            .to_degrees()
    }

    /// The pose of a head turned by `r` (model frame) from the frontal neutral face.
    pub fn from_rotation(r: &Rot3) -> HeadPose {
        let m = r.0;
        // C R C flips the signs of the entries that mix x with y or z.
        let c = [
            [m[0][0], -m[0][1], -m[0][2]],
            [-m[1][0], m[1][1], m[1][2]],
            [-m[2][0], m[2][1], m[2][2]],
        ];
        HeadPose {
            pitch: (-c[1][2]).atan2(c[2][2]),
            yaw: c[0][2].clamp(-1.0, 1.0).asin(),
            roll: (-c[0][1]).atan2(c[0][0]),
        }
    }

    /// The model-frame rotation of this pose (inverse of `from_rotation`).
    pub fn rotation(&self) -> Rot3 {
        let (s1, c1) = self.pitch.sin_cos();
        let (s2, c2) = self.yaw.sin_cos();
        let (s3, c3) = self.roll.sin_cos();
        let c = [
            [c2 * c3, -c2 * s3, s2],
            [c1 * s3 + c3 * s1 * s2, c1 * c3 - s1 * s2 * s3, -c2 * s1],
            [s1 * s3 - c1 * c3 * s2, c3 * s1 + c1 * s2 * s3, c1 * c2],
        ];
        Rot3([
            [c[0][0], -c[0][1], -c[0][2]],
            [-c[1][0], c[1][1], c[1][2]],
            [-c[2][0], c[2][1], c[2][2]],
        ])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn euler_angles_round_trip_and_pitch_down_is_positive() {
        let pose = HeadPose {
            pitch: 0.3,
            yaw: -0.5,
            roll: 0.2,
        };
        let back = HeadPose::from_rotation(&pose.rotation());
        assert!((back.pitch - 0.3).abs() < 1e-12);
        assert!((back.yaw + 0.5).abs() < 1e-12);
        assert!((back.roll - 0.2).abs() < 1e-12);
        // Turning about +x by a positive angle brings the forehead (+y) forward (+z): the
        // face looks down, which OpenFace reports as positive pitch.
        let down = Rot3::about_axis([1.0, 0.0, 0.0], 0.2);
        let p = HeadPose::from_rotation(&down);
        assert!((p.pitch - 0.2).abs() < 1e-12 && p.yaw.abs() < 1e-12);
    }
}
