//! The head-neck system (paper 3.1, A.1-A.2, after Lee & Terzopoulos 2006): a 9-link
//! cervical skeleton driven by 72 Hill-type muscles under two control layers.
//!
//! - `body`: links, discs, reduced-coordinate dynamics (eq. 1-2);
//! - `muscles`: Hill muscles (eq. 3-4) and their layout;
//! - here: the simulation step, the reflex layer (4 kHz, with the step), the voluntary layer's
//!   interface (25 Hz) and the optimization that finds the activations holding a head pose at
//!   equilibrium, which teaches the learned voluntary controller.
//!
//! The step is linearly implicit Euler: `(M + h D + h^2 K) du = h tau`, with D and K the
//! damping and stiffness of the discs and muscles (including the reflex's), then
//! `R_j <- R_j exp(h u_j)`. It is stable at 4 kHz for all gains used here and dissipates
//! little: see the energy test.

pub mod body;
pub mod muscles;

use faer::linalg::solvers::Solve;

pub use crate::observe::pose::HeadPose;
pub use body::{BodyState, Frames, Skeleton, SkeletonParams, DOF, JOINTS, SKULL};
pub use muscles::{HillParams, Layer, Muscle, MUSCLES};

use crate::invert::{projected_gradient, BoxQp};
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
#[derive(Clone, Debug, PartialEq)]
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

/// The fit's residual weights: per N m of unbalanced joint torque and per radian of skull
/// orientation error (the posture prior has `posture_weight`, the effort `effort_weight`).
const FIT_TORQUE_SCALE: f64 = 10.0;
const FIT_ANGLE_SCALE: f64 = 10.0;

/// The activations that hold a head pose, and the strains there (the voluntary setpoints).
#[derive(Clone, Debug, PartialEq)]
pub struct Fit {
    pub activation: Vec<f64>,
    pub angles: [f64; DOF],
    pub strain: Vec<f64>,
    /// Skull orientation error left at the equilibrium (degrees).
    pub error_degrees: f64,
    /// Unbalanced joint torque left (N m): the reflex absorbs it with a small deflection.
    pub torque_residual: f64,
    pub iterations: usize,
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

    /// The activations that hold the head at `target` at equilibrium, with the posture and
    /// the muscle strains there: Gauss-Newton (Levenberg-Marquardt damped) on
    /// `s_G^2 |G(q, a)|^2 + s_h^2 |e_head(q)|^2 + w_p^2 |q - q_shared|^2 + lambda |a|^2` over the
    /// joint angles q and a in [0, 1]^72 jointly, with G the static generalized force (zero at
    /// equilibrium), `e_head` the skull's orientation error and `q_shared` the posture that
    /// shares the rotation among the joints by range of motion (`posture`). Each step
    /// eliminates the posture step and solves a box QP in the activations. Many activations
    /// hold a pose; the ridge picks the least effort. The posture is a free unknown, so the
    /// fit never has to follow the passive neck's folding equilibrium branches; the
    /// equilibrium need not be passively stable, since the reflex stiffens it.
    pub fn fit(&self, target: HeadPose) -> Result<Fit, NeckError> {
        let prior = self.posture(target)?.angles();
        let w_p = self.params.posture_weight;
        let lambda = self.params.effort_weight;
        let goal = target.rotation().transpose();
        let mut a = vec![0.0; MUSCLES];
        let mut q = prior;
        const ROWS: usize = 2 * DOF + 3;
        // The scaled residual [s_G G; s_h e; w_p (q - prior)] and the objective.
        let evaluate = |q: &[f64; DOF], a: &[f64]| {
            let (g, head, ms) = self.static_force(q, a);
            let e = goal.mul(&head).log();
            let mut r = Vec::with_capacity(ROWS);
            r.extend(g.iter().map(|v| FIT_TORQUE_SCALE * v));
            r.extend(e.iter().map(|v| FIT_ANGLE_SCALE * v));
            r.extend((0..DOF).map(|i| w_p * (q[i] - prior[i])));
            let phi = r.iter().map(|v| v * v).sum::<f64>()
                + lambda * a.iter().map(|v| v * v).sum::<f64>();
            (r, g, e, ms, phi)
        };
        let (mut r, mut g, mut e, mut ms, mut phi) = evaluate(&q, &a);
        let mut iterations = 0;
        // Levenberg-Marquardt damping, raised when a step fails.
        let mut mu = 0.0f64;
        while iterations < 80 {
            iterations += 1;
            let (k, jh) = self.stiffness(&q, &a, &g, &goal, e);
            // Linearized residual M_a a' + M_q dq - d.
            let hill = &self.params.hill;
            let mut m_a = vec![0.0; ROWS * MUSCLES];
            for (c, (m, geo)) in self.muscles.iter().zip(&ms.geometry).enumerate() {
                let fl = m.force_length(hill, geo.length);
                for i in 0..DOF {
                    m_a[i * MUSCLES + c] = -FIT_TORQUE_SCALE * fl * geo.gradient[i];
                }
            }
            let mut m_q = vec![0.0; ROWS * DOF];
            for i in 0..DOF {
                for j in 0..DOF {
                    m_q[i * DOF + j] = -FIT_TORQUE_SCALE * k[i * DOF + j];
                }
                m_q[(DOF + 3 + i) * DOF + i] = w_p;
            }
            for row in 0..3 {
                for j in 0..DOF {
                    m_q[(DOF + row) * DOF + j] = FIT_ANGLE_SCALE * jh[row * DOF + j];
                }
            }
            // d = M_a a - r (the residual at a' = a, dq = 0 is r).
            let d: Vec<f64> = (0..ROWS)
                .map(|row| {
                    (0..MUSCLES)
                        .map(|c| m_a[row * MUSCLES + c] * a[c])
                        .sum::<f64>()
                        - r[row]
                })
                .collect();
            // Eliminate dq = N^-1 M_q^T (d - M_a a'), N = M_q^T M_q + mu I: the residual becomes
            // P (M_a a' - d) with P = I - M_q N^-1 M_q^T.
            let mut n = vec![0.0; DOF * DOF];
            for i in 0..DOF {
                for j in 0..DOF {
                    n[i * DOF + j] = (0..ROWS)
                        .map(|row| m_q[row * DOF + i] * m_q[row * DOF + j])
                        .sum();
                }
                n[i * DOF + i] += mu;
            }
            let m_qt: Vec<f64> = (0..DOF * ROWS)
                .map(|x| m_q[(x % ROWS) * DOF + x / ROWS])
                .collect();
            let n_inv_mqt =
                solve_dense(&n, DOF, &m_qt, ROWS).ok_or_else(|| NeckError::Equilibrium {
                    reason: "singular posture system".into(),
                })?;
            // The posture step that best absorbs a residual v: N^-1 M_q^T v.
            let posture_step = |v: &[f64]| -> Vec<f64> {
                (0..DOF)
                    .map(|i| {
                        (0..ROWS)
                            .map(|row| n_inv_mqt[i * ROWS + row] * v[row])
                            .sum()
                    })
                    .collect()
            };
            let project = |v: &[f64]| -> Vec<f64> {
                let y = posture_step(v);
                (0..ROWS)
                    .map(|row| v[row] - (0..DOF).map(|i| m_q[row * DOF + i] * y[i]).sum::<f64>())
                    .collect()
            };
            let columns: Vec<Vec<f64>> = (0..MUSCLES)
                .map(|c| {
                    project(
                        &(0..ROWS)
                            .map(|row| m_a[row * MUSCLES + c])
                            .collect::<Vec<_>>(),
                    )
                })
                .collect();
            let mut qp = BoxQp::least_squares(&columns, &project(&d));
            for i in 0..qp.n {
                qp.h[i * qp.n + i] += lambda + mu;
                qp.g[i] += mu * a[i];
            }
            let proposal = projected_gradient(&qp, &a, 1e-10, 5000).a;
            let rest: Vec<f64> = (0..ROWS)
                .map(|row| {
                    d[row]
                        - (0..MUSCLES)
                            .map(|c| m_a[row * MUSCLES + c] * proposal[c])
                            .sum::<f64>()
                })
                .collect();
            let dq = posture_step(&rest);
            let mut accepted = false;
            let mut t = 1.0;
            while t > 0.1 {
                let qt: [f64; DOF] = std::array::from_fn(|i| q[i] + t * dq[i]);
                let at: Vec<f64> = a
                    .iter()
                    .zip(&proposal)
                    .map(|(x, p)| x + t * (p - x))
                    .collect();
                let (rt, gt, et, mst, phit) = evaluate(&qt, &at);
                if phit < phi {
                    let gain = phi - phit;
                    (q, a, r, g, e, ms, phi) = (qt, at, rt, gt, et, mst, phit);
                    accepted = true;
                    if gain < 1e-7 * phi {
                        iterations = usize::MAX - 1;
                    }
                    break;
                }
                t *= 0.5;
            }
            if !accepted {
                mu = (mu * 10.0).max(1e-4);
                if mu > 1e4 {
                    break;
                }
            } else if mu > 0.0 {
                mu = if mu < 1e-6 { 0.0 } else { mu / 10.0 };
            }
            if iterations == usize::MAX - 1 {
                break;
            }
        }
        let error = r[DOF..DOF + 3].iter().map(|v| v * v).sum::<f64>().sqrt() / FIT_ANGLE_SCALE;
        let torque = g.iter().map(|v| v * v).sum::<f64>().sqrt();
        Ok(Fit {
            activation: a,
            angles: q,
            strain: self.strains(&ms),
            error_degrees: error.to_degrees(),
            torque_residual: torque,
            iterations: iterations.min(80),
        })
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

/// The teacher voluntary controller: feedforward activations and strain setpoints of the
/// equilibrium that holds the target (`Neck::fit`), and strain-rate setpoints that would carry
/// the strains from the current pose's to the target's in `move_time`. Exact but slow (one fit
/// per new target); the learned controller imitates it. Every fit starts cold, so the command
/// is a function of what the controller sees and its target alone.
#[derive(Clone, Debug, Default)]
pub struct Teacher {
    last: Option<(HeadPose, Fit)>,
}

impl Teacher {
    /// The command for a controller that sees `pose` and aims at `target`, with `fit` the
    /// target's equilibrium.
    pub fn command_for(
        neck: &Neck,
        pose: HeadPose,
        target: HeadPose,
        fit: &Fit,
    ) -> Result<Command, NeckError> {
        let (from, to) = (neck.shared_strains(pose)?, neck.shared_strains(target)?);
        let time = neck.params.move_time;
        Ok(Command {
            activation: fit.activation.clone(),
            strain: fit.strain.clone(),
            strain_rate: to
                .iter()
                .zip(&from)
                .map(|(e, e0)| (e - e0) / time)
                .collect(),
        })
    }
}

impl Voluntary for Teacher {
    fn command(
        &mut self,
        neck: &Neck,
        seen: &Observation,
        target: HeadPose,
    ) -> Result<Command, NeckError> {
        let fit = match self.last.take() {
            Some((t, fit)) if t == target => fit,
            _ => neck.fit(target)?,
        };
        let command = Teacher::command_for(neck, seen.pose, target, &fit)?;
        self.last = Some((target, fit));
        Ok(command)
    }
}

/// Target head poses at a frame rate (e.g. an OpenFace sequence); the last frame holds.
#[derive(Clone, Debug, PartialEq)]
pub struct PoseSequence {
    pub fps: f64,
    pub poses: Vec<HeadPose>,
}

impl PoseSequence {
    /// One pose held.
    pub fn hold(pose: HeadPose) -> PoseSequence {
        PoseSequence {
            fps: 1.0,
            poses: vec![pose],
        }
    }

    pub fn at(&self, time: f64) -> HeadPose {
        let k = (time * self.fps + 1e-9).floor().max(0.0) as usize;
        self.poses[k.min(self.poses.len() - 1)]
    }

    /// The sequence with every pose inside the neck's commanded range, and for each clamped
    /// frame (0-based) what was clamped; a NaN pose is an error naming its frame.
    pub fn checked(&self, neck: &Neck) -> Result<(PoseSequence, Vec<(usize, String)>), NeckError> {
        let mut warnings = Vec::new();
        let mut poses = Vec::with_capacity(self.poses.len());
        for (frame, p) in self.poses.iter().enumerate() {
            let names = ["pitch", "yaw", "roll"];
            if let Some(k) = (0..3).find(|&k| !p.to_array()[k].is_finite()) {
                return Err(NeckError::NotANumber {
                    frame,
                    what: names[k].into(),
                });
            }
            let (clamped, warning) = neck.clamp_target(*p);
            if let Some(w) = warning {
                warnings.push((frame, w));
            }
            poses.push(clamped);
        }
        Ok((
            PoseSequence {
                fps: self.fps,
                poses,
            },
            warnings,
        ))
    }
}

/// A simulated run: the head pose sampled every `every` steps.
#[derive(Clone, Debug, PartialEq)]
pub struct Trajectory {
    pub time: Vec<f64>,
    pub target: Vec<HeadPose>,
    pub pose: Vec<HeadPose>,
    /// Mean applied activation over the muscles at each sample.
    pub effort: Vec<f64>,
    /// The skull joint's displacement from its rest position at each sample (m).
    pub skull_offset: Vec<V3>,
    /// One per clamped target frame.
    pub warnings: Vec<String>,
    pub final_state: BodyState,
}

/// Simulates `duration` seconds from `start` toward `targets` (checked and clamped first),
/// the voluntary controller called every `1 / voluntary_rate` s, the reflex every step;
/// samples every `every` steps.
pub fn simulate(
    neck: &Neck,
    controller: &mut dyn Voluntary,
    targets: &PoseSequence,
    start: BodyState,
    duration: f64,
    every: usize,
) -> Result<Trajectory, NeckError> {
    let (targets, clamped) = targets.checked(neck)?;
    let warnings = clamped
        .into_iter()
        .map(|(frame, w)| format!("frame {frame}: {w}"))
        .collect();
    let h = neck.time_step();
    let steps = (duration / h).round() as usize;
    let per_command = neck.steps_per_command();
    let mut s = start;
    let mut out = Trajectory {
        time: Vec::new(),
        target: Vec::new(),
        pose: Vec::new(),
        effort: Vec::new(),
        skull_offset: Vec::new(),
        warnings,
        final_state: BodyState::rest(),
    };
    let rest = neck.skeleton.frames(&BodyState::rest()).origin[SKULL];
    let mut command = Command::passive();
    for n in 0..steps {
        let t = n as f64 * h;
        if n % per_command == 0 {
            let seen = neck.observe(&s);
            command = controller.command(neck, &seen, targets.at(t))?;
        }
        let report = neck.step(&mut s, &command, true, t)?;
        if (n + 1) % every == 0 {
            let f = neck.skeleton.frames(&s);
            let seen = neck.observation(&f);
            out.skull_offset
                .push(std::array::from_fn(|k| f.origin[SKULL][k] - rest[k]));
            out.time.push(t + h);
            out.target.push(targets.at(t + h));
            out.pose.push(seen.pose);
            out.effort
                .push(report.activation.iter().sum::<f64>() / MUSCLES as f64);
        }
    }
    out.final_state = s;
    Ok(out)
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
mod tests {
    use super::*;
    use rayon::prelude::*;

    fn passive_run(neck: &Neck, seconds: f64, command: &Command) -> BodyState {
        let mut s = BodyState::rest();
        let steps = (seconds * neck.params.simulation_rate) as usize;
        for n in 0..steps {
            neck.step(&mut s, command, false, n as f64 * neck.time_step())
                .unwrap();
        }
        s
    }

    #[test]
    fn passive_head_sags_but_stays_within_the_range_of_motion() {
        let neck = Neck::new(NeckParams::default());
        let s = passive_run(&neck, 3.0, &Command::passive());
        let pose = neck.observe(&s).pose.degrees();
        assert!(pose[0] > 10.0, "the head should sag forward: {pose:?}");
        let q = s.angles();
        for (j, rom) in body::RANGE_OF_MOTION_DEGREES.iter().enumerate() {
            for a in 0..3 {
                let angle = q[3 * j + a].to_degrees().abs();
                assert!(
                    angle < rom[a],
                    "joint {j} axis {a}: {angle} deg beyond {}",
                    rom[a]
                );
            }
        }
        // It has (nearly) come to rest: only a slow creep against the ligaments is left.
        assert!(
            s.velocity.iter().all(|v| v.abs() < 0.02),
            "{:?}",
            s.velocity
        );
    }

    #[test]
    fn symmetric_activations_give_no_yaw_or_roll() {
        let neck = Neck::new(NeckParams::default());
        let mut command = Command::passive();
        for (k, a) in command.activation.iter_mut().enumerate() {
            *a = 0.05 + 0.3 * ((k / 2) % 5) as f64 / 4.0;
        }
        let s = passive_run(&neck, 0.5, &command);
        let pose = neck.observe(&s).pose;
        assert!(pose.yaw.abs() < 1e-9 && pose.roll.abs() < 1e-9, "{pose:?}");
        assert!(
            pose.pitch.abs() > 1e-3,
            "the activations should move the head: {pose:?}"
        );
    }

    #[test]
    fn energy_drifts_little_without_damping() {
        let neck = Neck::new(NeckParams {
            damping: false,
            ..NeckParams::default()
        });
        let mut s = BodyState::rest();
        let e0 = neck.energy(&s);
        let (mut lo, mut hi) = (e0, e0);
        for n in 0..4000 {
            neck.step(&mut s, &Command::passive(), false, n as f64 / 4000.0)
                .unwrap();
            let e = neck.energy(&s);
            lo = lo.min(e);
            hi = hi.max(e);
        }
        // The head falls about 35 degrees and swings: about 0.5 J goes between gravity,
        // springs and motion; the total may wander by a few percent of that.
        assert!(hi - lo < 0.02, "energy wandered {lo} .. {hi} J");
        assert!(
            neck.observe(&s).pose.pitch.abs() > 0.05,
            "the head should have moved"
        );
    }

    #[test]
    fn static_targets_in_the_range_are_reached_within_2_degrees_and_held() {
        let neck = Neck::new(NeckParams::default());
        let targets = [
            [30.0, 0.0, 0.0],
            [-30.0, 0.0, 0.0],
            [0.0, 40.0, 0.0],
            [0.0, -40.0, 0.0],
            [0.0, 0.0, 20.0],
            [0.0, 0.0, -20.0],
            [30.0, 40.0, 20.0],
            [-30.0, -40.0, -20.0],
        ];
        let errors: Vec<(V3, f64)> = targets
            .par_iter()
            .map(|d| {
                let target = HeadPose::from_degrees(d[0], d[1], d[2]);
                let run = simulate(
                    &neck,
                    &mut Teacher::default(),
                    &PoseSequence::hold(target),
                    BodyState::rest(),
                    2.0,
                    40,
                )
                .unwrap();
                let worst = run
                    .time
                    .iter()
                    .zip(&run.pose)
                    .filter(|(t, _)| **t >= 1.5)
                    .map(|(_, p)| p.error_degrees(target))
                    .fold(0.0, f64::max);
                (*d, worst)
            })
            .collect();
        for (d, worst) in errors {
            assert!(
                worst < 2.0,
                "target {d:?}: {worst:.2} deg off over the last 0.5 s"
            );
        }
    }

    #[test]
    fn same_inputs_give_bit_identical_trajectories() {
        let neck = Neck::new(NeckParams::default());
        let targets = PoseSequence {
            fps: 10.0,
            poses: (0..4)
                .map(|k| HeadPose::from_degrees(5.0 * k as f64, -8.0 * k as f64, 3.0))
                .collect(),
        };
        let run = || {
            simulate(
                &neck,
                &mut Teacher::default(),
                &targets,
                BodyState::rest(),
                0.4,
                8,
            )
            .unwrap()
        };
        let (a, b) = (run(), run());
        let bits = |t: &Trajectory| -> Vec<u64> {
            t.pose
                .iter()
                .flat_map(|p| p.to_array().map(f64::to_bits))
                .chain(t.final_state.velocity.iter().map(|v| v.to_bits()))
                .collect()
        };
        assert_eq!(bits(&a), bits(&b));
    }

    #[test]
    fn targets_beyond_the_range_are_clamped_with_a_warning_and_nan_is_an_error() {
        let neck = Neck::new(NeckParams::default());
        let seq = PoseSequence {
            fps: 30.0,
            poses: vec![HeadPose::default(), HeadPose::from_degrees(10.0, 80.0, 0.0)],
        };
        let (clamped, warnings) = seq.checked(&neck).unwrap();
        assert_eq!(warnings.len(), 1);
        assert!(
            warnings[0].0 == 1 && warnings[0].1.contains("yaw 80.0 -> 50.0"),
            "{warnings:?}"
        );
        assert!((clamped.poses[1].degrees()[1] - 50.0).abs() < 1e-9);
        let bad = PoseSequence {
            fps: 30.0,
            poses: vec![
                HeadPose::default(),
                HeadPose::default(),
                HeadPose::from_degrees(0.0, 0.0, f64::NAN),
            ],
        };
        let err = simulate(
            &neck,
            &mut Teacher::default(),
            &bad,
            BodyState::rest(),
            0.1,
            10,
        )
        .unwrap_err();
        assert_eq!(
            err.to_string(),
            "head pose of frame 2 is not a number (roll)"
        );
    }

    #[test]
    fn fit_holds_the_target_at_equilibrium() {
        let neck = Neck::new(NeckParams::default());
        let target = HeadPose::from_degrees(-20.0, 25.0, 10.0);
        let fit = neck.fit(target).unwrap();
        assert!(fit.error_degrees < 0.1, "{fit:?}");
        assert!(fit.activation.iter().all(|a| (0.0..=1.0).contains(a)));
        // Released at the fitted posture with the fitted activations, it stays.
        let mut s = BodyState::from_angles(&fit.angles);
        let command = Command {
            activation: fit.activation.clone(),
            strain: fit.strain.clone(),
            strain_rate: vec![0.0; MUSCLES],
        };
        for n in 0..2000 {
            neck.step(&mut s, &command, true, n as f64 / 4000.0)
                .unwrap();
        }
        let err = neck.observe(&s).pose.error_degrees(target);
        assert!(err < 0.2, "drifted {err} deg");
    }
}
