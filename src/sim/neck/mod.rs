//! The head-neck system (paper 3.1, A.1-A.2, after Lee & Terzopoulos 2006): a 9-link
//! cervical skeleton driven by 72 Hill-type muscles under two control layers.
//!
//! - `body`: links, discs, reduced-coordinate dynamics (eq. 1-2);
//! - `muscles`: Hill muscles (eq. 3-4) and their layout;
//! - `fit`: the optimization that finds the activations holding a head pose at equilibrium,
//!   and the teacher controller built on it, which teaches the learned voluntary controller;
//! - `simulate`: pose sequences and the closed loop under a voluntary controller;
//! - here: the simulation step, the reflex layer (4 kHz, with the step) and the voluntary
//!   layer's interface (25 Hz).
//!
//! The step is linearly implicit Euler: `(M + h D + h^2 K) du = h tau`, with D and K the
//! damping and stiffness of the discs and muscles (including the reflex's), then
//! `R_j <- R_j exp(h u_j)`. It is stable at 4 kHz for all gains used here and dissipates
//! little: see the energy test.

pub mod body;
mod fit;
pub mod muscles;
mod simulate;

use faer::linalg::solvers::Solve;

pub use crate::sim::pose::HeadPose;
pub use body::{BodyState, Frames, Skeleton, SkeletonParams, DOF, JOINTS, SKULL};
pub use fit::{Fit, Teacher};
pub use muscles::{HillParams, Layer, Muscle, MUSCLES};
pub use simulate::{simulate, PoseSequence, Trajectory};

use crate::sim::geom::{Rot3, V3};

#[derive(Debug, thiserror::Error, PartialEq)]
pub enum NeckError {
    #[error("the neck simulation diverged at t = {time:.4} s (state not finite)")]
    Diverged { time: f64 },
    #[error("the neck's system matrix is not positive definite at t = {time:.4} s")]
    Singular { time: f64 },
    #[error("head pose of frame {frame} is not a number ({what})")]
    NotANumber { frame: usize, what: String },
    #[error("the voluntary controller failed: {0}")]
    Controller(String),
    #[error("no equilibrium: {reason}")]
    Equilibrium { reason: String },
    #[error("no posture reaches head pose {pose:?} (degrees): {reason}")]
    Posture { pose: V3, reason: String },
}

/// Reflex gains (paper 3.1): feedback activation `k_e (e - e*) + k_v (e_dot - e_dot*)` per
/// muscle, e the strain.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct ReflexParams {
    /// Activation per unit strain error. Default 20.
    pub strain_gain: f64,
    /// Activation per unit strain-rate error (s). Default 2: critically damps the step
    /// responses of `experiments/headpose.toml` (0.5 overshoots by up to 30 degrees).
    pub rate_gain: f64,
}

impl Default for ReflexParams {
    fn default() -> Self {
        ReflexParams {
            strain_gain: 20.0,
            rate_gain: 2.0,
        }
    }
}

/// Everything that defines a neck.
#[derive(Clone, Debug, PartialEq)]
pub struct NeckParams {
    pub skeleton: SkeletonParams,
    pub hill: HillParams,
    pub reflex: ReflexParams,
    /// Simulation (and reflex) rate, Hz. Default 4000 (paper 3.1).
    pub simulation_rate: f64,
    /// Voluntary controller rate, Hz. Default 25 (paper 3.1).
    pub voluntary_rate: f64,
    /// Disc and passive muscle damping on (off only to measure energy drift).
    pub damping: bool,
    /// Commanded head range (degrees, one direction) for pitch, yaw, roll: targets beyond it
    /// are clamped. Default (40, 50, 30), inside the summed ranges of motion (68, 77, 61) so
    /// that no joint is driven to its limit.
    pub range_degrees: V3,
    /// Ridge on the activations in the equilibrium fit (rad^2 per unit activation^2): among
    /// the many activations that hold a pose, the one with least effort. Default 1e-4.
    pub effort_weight: f64,
    /// Weight (dimensionless) pulling the fitted posture toward the one that shares the
    /// head's rotation among the joints by their ranges of motion. Default 0.1.
    pub posture_weight: f64,
    /// Voluntary layer: the time (s) in which the strain-rate setpoints would carry the
    /// muscles from the current pose's strains to the target's. Default 0.2.
    pub move_time: f64,
}

impl Default for NeckParams {
    fn default() -> Self {
        NeckParams {
            skeleton: SkeletonParams::default(),
            hill: HillParams::default(),
            reflex: ReflexParams::default(),
            simulation_rate: 4000.0,
            voluntary_rate: 25.0,
            damping: true,
            range_degrees: [40.0, 50.0, 30.0],
            effort_weight: 1e-4,
            posture_weight: 0.1,
            move_time: 0.2,
        }
    }
}

/// The voluntary layer's output for one period: feedforward activations and the setpoints
/// (strain and strain rate) the reflex layer tracks.
#[derive(Clone, Debug, PartialEq)]
pub struct Command {
    pub activation: Vec<f64>,
    pub strain: Vec<f64>,
    pub strain_rate: Vec<f64>,
}

impl Command {
    /// No feedforward and no reflex: the muscles are passive.
    pub fn passive() -> Command {
        Command {
            activation: vec![0.0; MUSCLES],
            strain: vec![0.0; MUSCLES],
            strain_rate: vec![0.0; MUSCLES],
        }
    }
}

/// What the voluntary controller sees.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Observation {
    pub pose: HeadPose,
    /// Skull angular velocity in world axes (rad/s): x pitch, y yaw, z roll.
    pub velocity: V3,
}

/// A voluntary (25 Hz) controller.
pub trait Voluntary {
    fn command(
        &mut self,
        neck: &Neck,
        seen: &Observation,
        target: HeadPose,
    ) -> Result<Command, NeckError>;
}

/// The neck: skeleton, muscles and parameters.
#[derive(Clone, Debug)]
pub struct Neck {
    pub params: NeckParams,
    pub skeleton: Skeleton,
    pub muscles: Vec<Muscle>,
    /// Per joint and axis, the share of the head's rotation (each axis sums to 1 over the
    /// joints): proportional to the range of motion.
    pub shares: [V3; JOINTS],
}

/// One simulation step's report.
#[derive(Clone, Debug)]
pub struct StepReport {
    /// Activations applied (feedforward plus reflex, clamped to [0, 1]).
    pub activation: Vec<f64>,
}

/// Muscle state at an instant, for the reflex and for the equilibrium fit.
#[derive(Clone, Debug)]
pub struct MuscleState {
    pub geometry: Vec<muscles::Geometry>,
}

impl Neck {
    pub fn new(params: NeckParams) -> Neck {
        let skeleton = Skeleton::new(&params.skeleton);
        let rest = skeleton.frames(&BodyState::rest());
        let muscles = muscles::layout(&rest);
        let mut totals = [0.0; 3];
        for rom in &body::RANGE_OF_MOTION_DEGREES {
            for a in 0..3 {
                totals[a] += rom[a];
            }
        }
        let shares = body::RANGE_OF_MOTION_DEGREES
            .map(|rom| [rom[0] / totals[0], rom[1] / totals[1], rom[2] / totals[2]]);
        Neck {
            params,
            skeleton,
            muscles,
            shares,
        }
    }

    pub fn time_step(&self) -> f64 {
        1.0 / self.params.simulation_rate
    }

    /// Simulation steps per voluntary period.
    pub fn steps_per_command(&self) -> usize {
        (self.params.simulation_rate / self.params.voluntary_rate).round() as usize
    }

    pub fn head_pose(&self, f: &Frames) -> HeadPose {
        HeadPose::from_rotation(&f.rotation[SKULL])
    }

    pub fn observe(&self, s: &BodyState) -> Observation {
        self.observation(&self.skeleton.frames(s))
    }

    /// What the voluntary controller sees in the posture `f`.
    pub fn observation(&self, f: &Frames) -> Observation {
        Observation {
            pose: self.head_pose(f),
            velocity: f.omega[SKULL],
        }
    }

    /// Clamps a target into the commanded range; the message says what was clamped.
    pub fn clamp_target(&self, target: HeadPose) -> (HeadPose, Option<String>) {
        let d = target.degrees();
        let r = self.params.range_degrees;
        let clamped: V3 = std::array::from_fn(|k| d[k].clamp(-r[k], r[k]));
        if clamped == d {
            return (target, None);
        }
        let names = ["pitch", "yaw", "roll"];
        let what: Vec<String> = (0..3)
            .filter(|&k| clamped[k] != d[k])
            .map(|k| format!("{} {:.1} -> {:.1} deg", names[k], d[k], clamped[k]))
            .collect();
        (
            HeadPose::from_array(clamped.map(f64::to_radians)),
            Some(format!(
                "head pose outside the anatomical range (pitch +-{}, yaw +-{}, roll +-{} deg) clamped: {}",
                r[0],
                r[1],
                r[2],
                what.join(", ")
            )),
        )
    }

    /// Joint angles that put the head at `pose`, the rotation shared among the joints by
    /// their ranges of motion (Newton on the three shared angles).
    pub fn posture(&self, pose: HeadPose) -> Result<BodyState, NeckError> {
        let target = pose.to_array();
        let state_of = |phi: V3| {
            let q: Vec<f64> = (0..DOF)
                .map(|i| self.shares[i / 3][i % 3] * phi[i % 3])
                .collect();
            BodyState::from_angles(&q)
        };
        let pose_of = |phi: V3| {
            let f = self.skeleton.frames(&state_of(phi));
            self.head_pose(&f).to_array()
        };
        let mut phi = pose.rotation().log();
        for _ in 0..30 {
            let now = pose_of(phi);
            let r: V3 = std::array::from_fn(|k| target[k] - now[k]);
            if r.iter().all(|v| v.abs() < 1e-12) {
                return Ok(state_of(phi));
            }
            let h = 1e-7;
            let mut jac = [[0.0; 3]; 3];
            for c in 0..3 {
                let mut p = phi;
                p[c] += h;
                let moved = pose_of(p);
                for rr in 0..3 {
                    jac[rr][c] = (moved[rr] - now[rr]) / h;
                }
            }
            let step = solve3(&jac, r).ok_or_else(|| NeckError::Posture {
                pose: pose.degrees(),
                reason: "singular Jacobian".into(),
            })?;
            for k in 0..3 {
                phi[k] += step[k];
            }
        }
        Err(NeckError::Posture {
            pose: pose.degrees(),
            reason: "Newton did not converge in 30 iterations".into(),
        })
    }

    pub fn muscle_state(&self, f: &Frames) -> MuscleState {
        MuscleState {
            geometry: self
                .muscles
                .iter()
                .map(|m| muscles::geometry(&m.path, f))
                .collect(),
        }
    }

    /// Muscle strains in the range-sharing posture of `pose` (`posture`).
    pub fn shared_strains(&self, pose: HeadPose) -> Result<Vec<f64>, NeckError> {
        let posture = self.posture(pose)?;
        Ok(self.strains(&self.muscle_state(&self.skeleton.frames(&posture))))
    }

    pub fn strains(&self, ms: &MuscleState) -> Vec<f64> {
        self.muscles
            .iter()
            .zip(&ms.geometry)
            .map(|(m, g)| m.strain(g.length))
            .collect()
    }

    /// The static generalized force (N m) at joint angles `q` (exponential coordinates)
    /// under activations `a`: discs, gravity, passive and contractile muscle forces at rest
    /// (eq. 1 with zero velocity). Also the skull's orientation and the muscle geometry.
    fn static_force(&self, q: &[f64; DOF], a: &[f64]) -> ([f64; DOF], Rot3, MuscleState) {
        let s = BodyState::from_angles(q);
        let f = self.skeleton.frames(&s);
        let c = self.skeleton.bias(&s, &f);
        let disc = self.skeleton.disc_torque(&s, false);
        let mut g: [f64; DOF] = std::array::from_fn(|i| disc[i] - c[i]);
        let ms = self.muscle_state(&f);
        let hill = &self.params.hill;
        for ((m, geo), &ak) in self.muscles.iter().zip(&ms.geometry).zip(a) {
            let tension =
                m.passive(hill, geo.length, 0.0, false) + ak * m.force_length(hill, geo.length);
            for i in 0..DOF {
                g[i] -= tension * geo.gradient[i];
            }
        }
        (g, f.rotation[SKULL], ms)
    }

    /// `K = -dG/dq` (row-major) by forward differences at `q` where the force is `g`, and
    /// with `reference` the Jacobian of `log(reference R_skull)` (3 x DOF, row-major).
    fn stiffness(
        &self,
        q: &[f64; DOF],
        a: &[f64],
        g: &[f64; DOF],
        reference: &Rot3,
        e0: V3,
    ) -> (Vec<f64>, Vec<f64>) {
        const H: f64 = 1e-7;
        let mut k = vec![0.0; DOF * DOF];
        let mut jh = vec![0.0; 3 * DOF];
        for c in 0..DOF {
            let mut p = *q;
            p[c] += H;
            let (gp, head, _) = self.static_force(&p, a);
            for r in 0..DOF {
                k[r * DOF + c] = -(gp[r] - g[r]) / H;
            }
            let e = reference.mul(&head).log();
            for row in 0..3 {
                jh[row * DOF + c] = (e[row] - e0[row]) / H;
            }
        }
        (k, jh)
    }

    /// One step of `h = 1 / simulation_rate` under `command`, with the reflex adding
    /// `k_e (e - e*) + k_v (e_dot - e_dot*)` when `reflex` is on.
    pub fn step(
        &self,
        s: &mut BodyState,
        command: &Command,
        reflex: bool,
        time: f64,
    ) -> Result<StepReport, NeckError> {
        let h = self.time_step();
        let hill = &self.params.hill;
        let damping = self.params.damping;
        let f = self.skeleton.frames(s);
        let mut system = self.skeleton.mass_matrix(&f);
        let bias = self.skeleton.bias(s, &f);
        let disc = self.skeleton.disc_torque(s, damping);
        let mut tau: Vec<f64> = (0..DOF).map(|i| disc[i] - bias[i]).collect();
        for (j, d) in self.skeleton.discs.iter().enumerate() {
            let q = s.rotations[j].log();
            for a in 0..3 {
                let i = 3 * j + a;
                let damp = if damping { d.damping[a] } else { 0.0 };
                system[i * DOF + i] += h * damp + h * h * d.tangent(a, q[a]);
            }
        }
        let (k_e, k_v) = (self.params.reflex.strain_gain, self.params.reflex.rate_gain);
        let mut applied = Vec::with_capacity(MUSCLES);
        for (k, m) in self.muscles.iter().enumerate() {
            let g = muscles::geometry(&m.path, &f);
            let l0 = m.rest_length;
            let mut a = command.activation[k];
            let (mut da_dl, mut da_dv) = (0.0, 0.0);
            if reflex {
                let e = m.strain(g.length);
                let e_dot = g.rate / l0;
                a += k_e * (e - command.strain[k]) + k_v * (e_dot - command.strain_rate[k]);
                da_dl = k_e / l0;
                da_dv = k_v / l0;
            }
            if !(0.0..=1.0).contains(&a) {
                a = a.clamp(0.0, 1.0);
                da_dl = 0.0;
                da_dv = 0.0;
            }
            let force = m.force(hill, a, g.length, g.rate, damping);
            let total = force.passive + a * force.contractile;
            let stiffness = force.stiffness + force.contractile * da_dl;
            let damping_d = force.damping + force.contractile * da_dv;
            let weight = h * damping_d + h * h * stiffness;
            // The joints the muscle spans (no allocation: this runs 72 times a step).
            let mut nz = [0usize; DOF];
            let mut count = 0;
            for (i, &v) in g.gradient.iter().enumerate() {
                if v != 0.0 {
                    nz[count] = i;
                    count += 1;
                }
            }
            let nz = &nz[..count];
            for &r in nz {
                tau[r] -= total * g.gradient[r];
                if weight != 0.0 {
                    let wr = weight * g.gradient[r];
                    for &c in nz {
                        system[r * DOF + c] += wr * g.gradient[c];
                    }
                }
            }
            applied.push(a);
        }
        let a = faer::Mat::<f64>::from_fn(DOF, DOF, |r, c| system[r * DOF + c]);
        let llt = a
            .llt(faer::Side::Lower)
            .map_err(|_| NeckError::Singular { time })?;
        let mut rhs = faer::Mat::<f64>::from_fn(DOF, 1, |r, _| h * tau[r]);
        llt.solve_in_place(rhs.as_mut());
        for i in 0..DOF {
            s.velocity[i] += rhs[(i, 0)];
        }
        if s.velocity.iter().any(|v| !v.is_finite()) {
            return Err(NeckError::Diverged { time });
        }
        for j in 0..JOINTS {
            let u = [
                s.velocity[3 * j],
                s.velocity[3 * j + 1],
                s.velocity[3 * j + 2],
            ];
            s.rotations[j] = s.rotations[j].mul(&Rot3::exp(u.map(|v| v * h)));
        }
        Ok(StepReport {
            activation: applied,
        })
    }

    /// Total mechanical energy (J): kinetic, gravity, discs and passive muscle springs.
    pub fn energy(&self, s: &BodyState) -> f64 {
        let f = self.skeleton.frames(s);
        let muscles: f64 = self
            .muscles
            .iter()
            .map(|m| m.passive_energy(&self.params.hill, muscles::geometry(&m.path, &f).length))
            .sum();
        self.skeleton.energy(s, &f) + muscles
    }
}

/// Solves `A X = B` for `A` n x n and `B` n x m, both row-major (LU with partial pivoting).
fn solve_dense(a: &[f64], n: usize, b: &[f64], m: usize) -> Option<Vec<f64>> {
    let mat = faer::Mat::<f64>::from_fn(n, n, |r, c| a[r * n + c]);
    let lu = mat.partial_piv_lu();
    let mut rhs = faer::Mat::<f64>::from_fn(n, m, |r, c| b[r * m + c]);
    lu.solve_in_place(rhs.as_mut());
    let out: Vec<f64> = (0..n * m).map(|i| rhs[(i / m, i % m)]).collect();
    out.iter().all(|v| v.is_finite()).then_some(out)
}

fn solve3(m: &[[f64; 3]; 3], b: V3) -> Option<V3> {
    let det = m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
        - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
        + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
    if det.abs() < 1e-300 {
        return None;
    }
    let col = |c: usize| -> f64 {
        let mut mm = *m;
        for r in 0..3 {
            mm[r][c] = b[r];
        }
        mm[0][0] * (mm[1][1] * mm[2][2] - mm[1][2] * mm[2][1])
            - mm[0][1] * (mm[1][0] * mm[2][2] - mm[1][2] * mm[2][0])
            + mm[0][2] * (mm[1][0] * mm[2][1] - mm[1][1] * mm[2][0])
    };
    Some([col(0) / det, col(1) / det, col(2) / det])
}

#[cfg(test)]
mod tests;
