//! The cervical skeleton as articulated rigid bodies (paper A.1, eq. 1-2).
//!
//! Nine links: an immobile base (T1 with the shoulder girdle), the seven cervical vertebrae
//! C7 ... C1 and the skull, chained base -> C7 -> ... -> C1 -> skull. Each of the eight joints is
//! a ball joint with three rotational degrees of freedom (24 in all). The state of joint `j` is
//! the rotation `R_j` of link `j + 1` relative to its parent; its generalized velocity is that
//! link's angular velocity relative to the parent, in the child's axes. The "joint angles" q
//! of eq. 1-2 are the rotation vectors `log R_j` (x = pitch, y = yaw, z = roll axis), so the
//! disc spring of eq. 2 is `tau = -k_s log R_j - k_d u_j` per axis.
//!
//! Frames: metres, +y up, +z anterior (out of the face), +x the subject's left: the face
//! model's frame. At q = 0 every link frame is parallel to the world frame and the neck stands
//! in its neutral, slightly lordotic posture.
//!
//! Dynamics in reduced coordinates: the mass matrix from the link Jacobians and the bias
//! forces (Coriolis, centrifugal, gravity) from a recursive Newton-Euler pass with zero joint
//! acceleration; for 24 degrees of freedom this costs a few microseconds, so a hand-written
//! chain is simpler and faster than a general multibody engine.

use crate::sim::geom::{add, cross, dot, scale, sub, Rot3, V3};

/// Links including the immobile base.
pub const LINKS: usize = 9;
/// Movable links, one joint each.
pub const JOINTS: usize = 8;
/// Generalized coordinates: three rotations per joint.
pub const DOF: usize = 3 * JOINTS;

pub const LINK_NAMES: [&str; LINKS] = ["T1", "C7", "C6", "C5", "C4", "C3", "C2", "C1", "skull"];
/// The joint of link `k` (k >= 1) by the bones it connects.
pub const JOINT_NAMES: [&str; JOINTS] = [
    "T1-C7", "C7-C6", "C6-C5", "C5-C4", "C4-C3", "C3-C2", "C2-C1", "C1-C0",
];

/// Index of the skull link.
pub const SKULL: usize = 8;

/// Range of motion per joint in degrees, one direction, about (x, y, z) = (pitch, yaw, roll):
/// half the flexion-extension, one-sided axial rotation and one-sided lateral bending of
/// White & Panjabi, Clinical Biomechanics of the Spine (2nd ed., 1990), table 2-4 and 2-7
/// (C0-C1 25 / 5 / 5 degrees, C1-C2 20 / 40 / 5, ... C7-T1 9 / 2 / 4).
pub const RANGE_OF_MOTION_DEGREES: [V3; JOINTS] = [
    [4.5, 2.0, 4.0],
    [8.5, 6.0, 7.0],
    [10.0, 7.0, 8.0],
    [10.0, 7.0, 11.0],
    [7.5, 7.0, 11.0],
    [5.0, 3.0, 10.0],
    [10.0, 40.0, 5.0],
    [12.5, 5.0, 5.0],
];

/// One rigid link in its own frame (origin at the joint with its parent).
#[derive(Clone, Debug, PartialEq)]
pub struct Link {
    /// kg.
    pub mass: f64,
    /// Centre of mass (m, link frame).
    pub com: V3,
    /// Principal moments of inertia about the centre of mass along the link axes (kg m^2).
    pub inertia: V3,
    /// This link's joint in the parent's frame (m); unused for the base.
    pub joint: V3,
    /// Height of the vertebra (m): the next joint sits this far above this one.
    pub height: f64,
}

/// Inter-vertebral disc spring of joint `j` (eq. 2), per axis (pitch, yaw, roll).
#[derive(Clone, Debug, PartialEq)]
pub struct Disc {
    /// N m / rad.
    pub stiffness: V3,
    /// N m s / rad.
    pub damping: V3,
    /// Anatomical range, one direction (rad).
    pub range: V3,
    /// Ligament stiffening beta: the torque is `-k q (1 + beta (q / range)^4)`.
    pub stiffening: f64,
}

impl Disc {
    /// Spring torque of axis `a` at angle `q` (N m).
    pub fn spring(&self, a: usize, q: f64) -> f64 {
        let x = q / self.range[a];
        -self.stiffness[a] * q * (1.0 + self.stiffening * x.powi(4))
    }

    /// `-d spring / d q` (N m / rad).
    pub fn tangent(&self, a: usize, q: f64) -> f64 {
        let x = q / self.range[a];
        self.stiffness[a] * (1.0 + 5.0 * self.stiffening * x.powi(4))
    }

    /// Spring energy (J), zero at q = 0.
    pub fn energy(&self, a: usize, q: f64) -> f64 {
        let x = q / self.range[a];
        self.stiffness[a] * q * q * (0.5 + self.stiffening * x.powi(4) / 6.0)
    }
}

/// Skeleton parameters; `Skeleton::new` derives the links and discs from them.
#[derive(Clone, Debug, PartialEq)]
pub struct SkeletonParams {
    /// Head mass (kg). Default 4.5 (adult head, Yoganandan et al. 2009, 4.0-5.0 kg).
    pub head_mass: f64,
    /// Head centre of mass relative to the occipital condyles (m). Default (0, 0.035, 0.015):
    /// about 3.5 cm above and 1.5 cm anterior (Yoganandan et al. 2009).
    pub head_com: V3,
    /// Head principal moments about its centre of mass (kg m^2): pitch, yaw, roll axes.
    /// Default (0.022, 0.015, 0.020) (Yoganandan et al. 2009).
    pub head_inertia: V3,
    /// Vertebra mass (kg), bone with the soft tissue that moves with it. Default 0.2.
    pub vertebra_mass: f64,
    /// Disc torque (N m) at which each joint reaches its range of motion: the disc stiffness
    /// of axis `k` is `range_torque / range_k`, so stiffer joints are the ones that move
    /// less. Default 2.5 (cervical segments reach their range at 1.5-3 N m in vitro,
    /// Wheeldon et al. 2006).
    pub range_torque: f64,
    /// Ligament stiffening beta (eq. 2 extended): the disc torque is
    /// `-k q (1 + beta (q / range)^4)`, linear near neutral and stiffening toward the range
    /// as the ligaments tighten, so that the passive neck, which buckles under the head's
    /// weight with linear springs (the ligamentous cervical spine alone buckles near 10 N,
    /// Panjabi et al. 1998), sags but stays within its range. Default 4: `(1 + beta)
    /// range_torque` = 12.5 N m at the range.
    pub ligament_stiffening: f64,
    /// Disc damping (N m s / rad) per axis. Default 0.05.
    pub disc_damping: f64,
    /// Gravity (m/s^2) along -y. Default 9.81.
    pub gravity: f64,
}

impl Default for SkeletonParams {
    fn default() -> Self {
        SkeletonParams {
            head_mass: 4.5,
            head_com: [0.0, 0.035, 0.015],
            head_inertia: [0.022, 0.015, 0.020],
            vertebra_mass: 0.2,
            range_torque: 2.5,
            ligament_stiffening: 4.0,
            disc_damping: 0.05,
            gravity: 9.81,
        }
    }
}

/// Vertebra heights (m) of C7 ... C1 (body plus disc; C2 with the dens).
const HEIGHTS: [f64; 7] = [0.018, 0.017, 0.017, 0.017, 0.017, 0.030, 0.015];
/// Anterior offset (m) of each joint from the one below: the cervical lordosis.
const LORDOSIS: [f64; JOINTS] = [0.0, 0.004, 0.003, 0.002, 0.0, -0.002, -0.004, -0.006];

#[derive(Clone, Debug, PartialEq)]
pub struct Skeleton {
    pub links: Vec<Link>,
    pub discs: Vec<Disc>,
    pub gravity: V3,
}

/// Joint rotations and velocities: the simulation state.
#[derive(Clone, Debug, PartialEq)]
pub struct BodyState {
    pub rotations: [Rot3; JOINTS],
    /// Relative angular velocity of each link in its own axes (rad/s), 3 per joint.
    pub velocity: [f64; DOF],
}

impl BodyState {
    pub fn rest() -> BodyState {
        BodyState {
            rotations: [Rot3::IDENTITY; JOINTS],
            velocity: [0.0; DOF],
        }
    }

    /// From joint rotation vectors (24, rad), at rest.
    pub fn from_angles(q: &[f64]) -> BodyState {
        let mut s = BodyState::rest();
        for (j, r) in s.rotations.iter_mut().enumerate() {
            *r = Rot3::exp([q[3 * j], q[3 * j + 1], q[3 * j + 2]]);
        }
        s
    }

    /// The joint angles q: rotation vectors, 3 per joint.
    pub fn angles(&self) -> [f64; DOF] {
        let mut q = [0.0; DOF];
        for (j, r) in self.rotations.iter().enumerate() {
            q[3 * j..3 * j + 3].copy_from_slice(&r.log());
        }
        q
    }
}

/// World placement and motion of every link for one state.
#[derive(Clone, Debug)]
pub struct Frames {
    /// Link orientation in the world.
    pub rotation: [Rot3; LINKS],
    /// Link origin (its joint) in the world (m).
    pub origin: [V3; LINKS],
    /// Centre of mass in the world (m).
    pub com: [V3; LINKS],
    /// Angular velocity in the world (rad/s).
    pub omega: [V3; LINKS],
    /// Velocity of the link origin (m/s).
    pub velocity: [V3; LINKS],
}

impl Frames {
    /// A point given in `link`'s frame, in the world.
    #[inline]
    pub fn point(&self, link: usize, local: V3) -> V3 {
        add(self.origin[link], self.rotation[link].apply(local))
    }

    /// Velocity of the world point `x` carried by `link`.
    #[inline]
    pub fn point_velocity(&self, link: usize, x: V3) -> V3 {
        add(
            self.velocity[link],
            cross(self.omega[link], sub(x, self.origin[link])),
        )
    }

    /// Adds `J^T g` to `out`: the generalized force of the world force `g` applied at the
    /// point `x` carried by `link` (equivalently the gradient of `g . x` in q).
    pub fn add_point_force(&self, link: usize, x: V3, g: V3, out: &mut [f64]) {
        for k in 1..=link {
            let torque = cross(sub(x, self.origin[k]), g);
            let local = self.rotation[k].apply_transpose(torque);
            for a in 0..3 {
                out[3 * (k - 1) + a] += local[a];
            }
        }
    }
}

fn outer(a: V3, b: V3) -> [[f64; 3]; 3] {
    let mut m = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            m[i][j] = a[i] * b[j];
        }
    }
    m
}

/// `W diag(d) W^T`: a principal inertia in world axes.
fn rotate_inertia(w: &Rot3, d: V3) -> [[f64; 3]; 3] {
    let m = &w.0;
    let mut out = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            out[i][j] = (0..3).map(|k| m[i][k] * d[k] * m[j][k]).sum();
        }
    }
    out
}

fn mat_vec(m: &[[f64; 3]; 3], v: V3) -> V3 {
    [dot(m[0], v), dot(m[1], v), dot(m[2], v)]
}

impl Skeleton {
    pub fn new(p: &SkeletonParams) -> Skeleton {
        let mut links = Vec::with_capacity(LINKS);
        // The base never moves; its mass does not enter the dynamics.
        links.push(Link {
            mass: 0.0,
            com: [0.0; 3],
            inertia: [0.0; 3],
            joint: [0.0; 3],
            height: 0.0,
        });
        let mut below_height = 0.0;
        for (k, &h) in HEIGHTS.iter().enumerate() {
            // A vertebra as a block 6 cm wide (transverse processes) and 5 cm deep (body to
            // spinous process), centred on its canal.
            let (w, d, m) = (0.06, 0.05, p.vertebra_mass);
            links.push(Link {
                mass: m,
                com: [0.0, 0.5 * h, -0.01],
                inertia: [
                    m / 12.0 * (h * h + d * d),
                    m / 12.0 * (w * w + d * d),
                    m / 12.0 * (w * w + h * h),
                ],
                joint: [0.0, below_height, LORDOSIS[k]],
                height: h,
            });
            below_height = h;
        }
        links.push(Link {
            mass: p.head_mass,
            com: p.head_com,
            inertia: p.head_inertia,
            joint: [0.0, below_height, LORDOSIS[JOINTS - 1]],
            height: 0.0,
        });
        let discs = RANGE_OF_MOTION_DEGREES
            .iter()
            .map(|rom| {
                let range = rom.map(f64::to_radians);
                Disc {
                    stiffness: range.map(|r| p.range_torque / r),
                    damping: [p.disc_damping; 3],
                    stiffening: p.ligament_stiffening,
                    range,
                }
            })
            .collect();
        Skeleton {
            links,
            discs,
            gravity: [0.0, -p.gravity, 0.0],
        }
    }

    /// Positions and velocities of all links.
    pub fn frames(&self, s: &BodyState) -> Frames {
        let mut f = Frames {
            rotation: [Rot3::IDENTITY; LINKS],
            origin: [[0.0; 3]; LINKS],
            com: [[0.0; 3]; LINKS],
            omega: [[0.0; 3]; LINKS],
            velocity: [[0.0; 3]; LINKS],
        };
        for i in 1..LINKS {
            let p = i - 1;
            let d = f.rotation[p].apply(self.links[i].joint);
            f.rotation[i] = f.rotation[p].mul(&s.rotations[p]);
            f.origin[i] = add(f.origin[p], d);
            let u = [
                s.velocity[3 * p],
                s.velocity[3 * p + 1],
                s.velocity[3 * p + 2],
            ];
            f.omega[i] = add(f.omega[p], f.rotation[i].apply(u));
            f.velocity[i] = add(f.velocity[p], cross(f.omega[p], d));
            f.com[i] = f.point(i, self.links[i].com);
        }
        f
    }

    /// The joint-space mass matrix M(q), row-major DOF x DOF.
    pub fn mass_matrix(&self, f: &Frames) -> Vec<f64> {
        let mut m = vec![0.0; DOF * DOF];
        for i in 1..LINKS {
            let link = &self.links[i];
            let inertia = rotate_inertia(&f.rotation[i], link.inertia);
            for k in 1..=i {
                let dk = sub(f.com[i], f.origin[k]);
                for j in 1..=k {
                    let dj = sub(f.com[i], f.origin[j]);
                    // m ((dj . dk) I - dk dj^T) + I_world, in world axes.
                    let mut block = outer(dk, dj);
                    let dd = dot(dj, dk);
                    for a in 0..3 {
                        for b in 0..3 {
                            block[a][b] = link.mass * (if a == b { dd } else { 0.0 } - block[a][b])
                                + inertia[a][b];
                        }
                    }
                    // W_j^T block W_k.
                    let wj = &f.rotation[j].0;
                    let wk = &f.rotation[k].0;
                    for a in 0..3 {
                        for b in 0..3 {
                            let mut v = 0.0;
                            for c in 0..3 {
                                for e in 0..3 {
                                    v += wj[c][a] * block[c][e] * wk[e][b];
                                }
                            }
                            let (r, col) = (3 * (j - 1) + a, 3 * (k - 1) + b);
                            m[r * DOF + col] += v;
                            if j != k {
                                m[col * DOF + r] += v;
                            }
                        }
                    }
                }
            }
        }
        m
    }

    /// The bias forces C(q, qdot) of eq. 1: Coriolis, centrifugal and gravity, as the joint
    /// torques needed for zero joint acceleration (recursive Newton-Euler).
    pub fn bias(&self, s: &BodyState, f: &Frames) -> [f64; DOF] {
        let mut alpha = [[0.0; 3]; LINKS];
        let mut accel = [[0.0; 3]; LINKS];
        let mut force = [[0.0; 3]; LINKS];
        let mut moment = [[0.0; 3]; LINKS];
        for i in 1..LINKS {
            let p = i - 1;
            let d = sub(f.origin[i], f.origin[p]);
            let u = [
                s.velocity[3 * p],
                s.velocity[3 * p + 1],
                s.velocity[3 * p + 2],
            ];
            let wu = f.rotation[i].apply(u);
            alpha[i] = add(alpha[p], cross(f.omega[p], wu));
            accel[i] = add(
                accel[p],
                add(cross(alpha[p], d), cross(f.omega[p], cross(f.omega[p], d))),
            );
            let e = sub(f.com[i], f.origin[i]);
            let w = f.omega[i];
            let a_com = add(accel[i], add(cross(alpha[i], e), cross(w, cross(w, e))));
            let link = &self.links[i];
            force[i] = scale(sub(a_com, self.gravity), link.mass);
            let inertia = rotate_inertia(&f.rotation[i], link.inertia);
            moment[i] = add(mat_vec(&inertia, alpha[i]), cross(w, mat_vec(&inertia, w)));
        }
        // Accumulate from the skull down: total force of the subtree and its moment about
        // each joint.
        let mut c = [0.0; DOF];
        let mut total_force = [0.0; 3];
        let mut total_moment = [0.0; 3];
        for i in (1..LINKS).rev() {
            if i + 1 < LINKS {
                // Move the moment of the subtree above from joint i+1 to joint i.
                let lever = sub(f.origin[i + 1], f.origin[i]);
                total_moment = add(total_moment, cross(lever, total_force));
            }
            let e = sub(f.com[i], f.origin[i]);
            total_moment = add(total_moment, add(cross(e, force[i]), moment[i]));
            total_force = add(total_force, force[i]);
            let local = f.rotation[i].apply_transpose(total_moment);
            c[3 * (i - 1)..3 * i].copy_from_slice(&local);
        }
        c
    }

    /// Disc spring and damper torques (eq. 2), with the per-axis stiffness and damping.
    pub fn disc_torque(&self, s: &BodyState, damping: bool) -> [f64; DOF] {
        let mut tau = [0.0; DOF];
        for (j, disc) in self.discs.iter().enumerate() {
            let q = s.rotations[j].log();
            for a in 0..3 {
                let v = s.velocity[3 * j + a];
                tau[3 * j + a] =
                    disc.spring(a, q[a]) - if damping { disc.damping[a] * v } else { 0.0 };
            }
        }
        tau
    }

    /// Kinetic energy plus gravitational and disc potential energy (J); the potential is zero
    /// at q = 0 with the base origin as the height datum.
    pub fn energy(&self, s: &BodyState, f: &Frames) -> f64 {
        let m = self.mass_matrix(f);
        let u = &s.velocity;
        let kinetic: f64 = (0..DOF)
            .map(|r| u[r] * (0..DOF).map(|c| m[r * DOF + c] * u[c]).sum::<f64>())
            .sum::<f64>()
            * 0.5;
        let gravity: f64 = (1..LINKS)
            .map(|i| -self.links[i].mass * dot(self.gravity, f.com[i]))
            .sum();
        let springs: f64 = self
            .discs
            .iter()
            .enumerate()
            .map(|(j, d)| {
                let q = s.rotations[j].log();
                (0..3).map(|a| d.energy(a, q[a])).sum::<f64>()
            })
            .sum();
        kinetic + gravity + springs
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mass_matrix_is_symmetric_positive_definite_and_matches_kinetic_energy() {
        let sk = Skeleton::new(&SkeletonParams::default());
        let q: Vec<f64> = (0..DOF)
            .map(|i| 0.05 * ((i * 7 % 5) as f64 - 2.0))
            .collect();
        let mut s = BodyState::from_angles(&q);
        for (i, v) in s.velocity.iter_mut().enumerate() {
            *v = 0.3 * ((i * 3 % 7) as f64 - 3.0);
        }
        let f = sk.frames(&s);
        let m = sk.mass_matrix(&f);
        for r in 0..DOF {
            for c in 0..DOF {
                assert!((m[r * DOF + c] - m[c * DOF + r]).abs() < 1e-12);
            }
            assert!(m[r * DOF + r] > 0.0);
        }
        // Kinetic energy from the link velocities equals 1/2 u^T M u.
        let mut direct = 0.0;
        for i in 1..LINKS {
            let l = &sk.links[i];
            let v = f.point_velocity(i, f.com[i]);
            let inertia = rotate_inertia(&f.rotation[i], l.inertia);
            direct +=
                0.5 * l.mass * dot(v, v) + 0.5 * dot(f.omega[i], mat_vec(&inertia, f.omega[i]));
        }
        let u = &s.velocity;
        let from_m: f64 = (0..DOF)
            .map(|r| u[r] * (0..DOF).map(|c| m[r * DOF + c] * u[c]).sum::<f64>())
            .sum::<f64>()
            * 0.5;
        assert!(
            (direct - from_m).abs() < 1e-12 * direct.max(1.0),
            "{direct} vs {from_m}"
        );
    }

    #[test]
    fn static_bias_is_the_gradient_of_gravitational_energy() {
        let sk = Skeleton::new(&SkeletonParams::default());
        let q: Vec<f64> = (0..DOF)
            .map(|i| 0.04 * ((i * 5 % 7) as f64 - 3.0))
            .collect();
        let s = BodyState::from_angles(&q);
        let f = sk.frames(&s);
        let c = sk.bias(&s, &f);
        let potential = |st: &BodyState| {
            let f = sk.frames(st);
            (1..LINKS)
                .map(|i| -sk.links[i].mass * dot(sk.gravity, f.com[i]))
                .sum::<f64>()
        };
        // Rotate joint j about its own axis a by a small angle: dV/dtheta = C.
        let h = 1e-6;
        for j in 0..JOINTS {
            for a in 0..3 {
                let mut axis = [0.0; 3];
                axis[a] = h;
                let mut plus = s.clone();
                plus.rotations[j] = s.rotations[j].mul(&Rot3::exp(axis));
                axis[a] = -h;
                let mut minus = s.clone();
                minus.rotations[j] = s.rotations[j].mul(&Rot3::exp(axis));
                let numeric = (potential(&plus) - potential(&minus)) / (2.0 * h);
                let got = c[3 * j + a];
                assert!(
                    (numeric - got).abs() < 1e-6,
                    "joint {j} axis {a}: {numeric} vs {got}"
                );
            }
        }
    }
}
