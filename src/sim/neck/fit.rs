//! The equilibrium fit (the activations and strains that hold a head pose at rest, a box
//! QP solved by the primal-dual active-set method) and the teacher voluntary controller built
//! on it.

use super::*;
use crate::boxqp::{active_set, BoxQp};

/// The fit's residual weights: per N m of unbalanced joint torque and per radian of skull
/// orientation error (the posture prior has `posture_weight`, the effort `effort_weight`).
const FIT_TORQUE_SCALE: f64 = 10.0;
const FIT_ANGLE_SCALE: f64 = 10.0;
/// Levenberg-Marquardt steps allowed per fit.
const MAX_STEPS: usize = 80;

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
    /// Levenberg-Marquardt steps taken.
    pub iterations: usize,
    /// Whether the fit stopped at its gain test (a step that lowers the objective by less
    /// than 1e-7 of it) rather than at its 80-step cap or an unaccepted step at full damping.
    pub converged: bool,
}

impl Neck {
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
        let mut converged = false;
        while iterations < MAX_STEPS && !converged {
            iterations += 1;
            let (k, jh) = self.stiffness(&q, &a, &g, &goal, e);
            // Linearized residual M_a a' + M_q dq - d.
            let (m_a, m_q) = self.linearized(&ms, &k, &jh, w_p);
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
            let proposal = active_set(&qp, &a, 1e-10, 200).a;
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
                    converged = gain < 1e-7 * phi;
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
        }
        let error = r[DOF..DOF + 3].iter().map(|v| v * v).sum::<f64>().sqrt() / FIT_ANGLE_SCALE;
        let torque = g.iter().map(|v| v * v).sum::<f64>().sqrt();
        Ok(Fit {
            activation: a,
            angles: q,
            strain: self.strains(&ms),
            error_degrees: error.to_degrees(),
            torque_residual: torque,
            iterations,
            converged,
        })
    }

    /// The fit's residual linearized at the current posture: its rows (`2 DOF + 3`: scaled
    /// torques, head angle, posture prior) against the activations (`M_a`, row-major over
    /// the muscles) and against the joint angles (`M_q`, from the stiffness `k` and the head
    /// angle's Jacobian `jh`).
    fn linearized(
        &self,
        ms: &MuscleState,
        k: &[f64],
        jh: &[f64],
        w_p: f64,
    ) -> (Vec<f64>, Vec<f64>) {
        const ROWS: usize = 2 * DOF + 3;
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
        (m_a, m_q)
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
