//! The learned voluntary controller of the head-neck system (paper 3.1, 5.3): its parameters,
//! the teacher's training pairs, the network as a `Voluntary` controller, the evaluation's
//! static targets and pose sequences, and the face carried by the skull (paper Fig. 4).
//!
//! Training data: targets drawn uniformly in 1.15 times the evaluated range (within the
//! neck's commanded range); for each, the teacher's equilibrium fit (`Neck::fit`, the
//! activations and strains that hold it); for each target `poses_per_target` current poses
//! and velocities drawn around it, labelled with the teacher's command
//! (`Teacher::command_for`). The network maps (pose, velocity, target) to (activations,
//! strains, strain rates), as the voluntary controller of paper 3.1.
//!
//! Pure computation: the harness (`experiments::headpose`) caches, tabulates and draws.

use anyhow::{Context, Result};
use rayon::prelude::*;

use crate::learn::mlp::{Mlp, Pairs};
use crate::learn::params::{ModelParams, Normalization, TrainParams};
use crate::rng::stream;
use crate::sim::geom::{Rigid, V3};
use crate::sim::neck::{
    Command, HeadPose, Neck, NeckError, NeckParams, Observation, PoseSequence, ReflexParams,
    Teacher, Voluntary, MUSCLES,
};
use crate::sim::State;

pub const STRAIN_SCALE: f64 = 10.0;
pub const INPUTS: usize = 9;
pub const OUTPUTS: usize = 3 * MUSCLES;
/// Training targets are drawn in this multiple of the evaluated range.
const TARGET_MARGIN: f64 = 1.15;
/// `[headpose]` in a spec.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct HeadposeParams {
    /// The data's and the network's streams. Default 1.
    pub seed: u64,
    /// Training targets (each one equilibrium fit). Default 400.
    pub fit_targets: usize,
    /// Current poses drawn per target. Default 8.
    pub poses_per_target: usize,
    /// Share of the targets held out for the test MSE. Default 0.2.
    pub test_fraction: f64,
    /// Hidden layers and width of the controller network. Default 4 x 100 (as the face's).
    pub model: ModelParams,
    /// Adam. Default lr 1e-3, batch 64, 1000 epochs, z-score inputs.
    pub train: TrainParams,
    /// Pitch, yaw, roll range of the targets (degrees, one direction). Default (30, 40, 20).
    pub range_degrees: V3,
    /// Simulated seconds per static target. Default 2.
    pub duration: f64,
    /// The band (degrees) a settled head stays in. Default 2.
    pub settle_degrees: f64,
    /// Seconds of each pose sequence. Default 4.
    pub sequence_seconds: f64,
    /// Reflex gains (`headpose.strain_gain`, `headpose.rate_gain`).
    pub reflex: ReflexParams,
}

impl Default for HeadposeParams {
    fn default() -> Self {
        HeadposeParams {
            seed: 1,
            fit_targets: 400,
            poses_per_target: 8,
            test_fraction: 0.2,
            model: ModelParams::default(),
            train: TrainParams {
                learning_rate: 1e-3,
                batch_size: 64,
                epochs: 1000,
                normalization: Normalization::ZScore,
            },
            range_degrees: [30.0, 40.0, 20.0],
            duration: 2.0,
            settle_degrees: 2.0,
            sequence_seconds: 4.0,
            reflex: ReflexParams::default(),
        }
    }
}

impl HeadposeParams {
    pub fn neck(&self) -> Neck {
        Neck::new(NeckParams {
            reflex: self.reflex.clone(),
            ..NeckParams::default()
        })
    }
}

/// The learned voluntary controller: the network's command, activations clamped to [0, 1].
pub struct Learned<'a> {
    pub mlp: &'a Mlp,
}

impl Learned<'_> {
    pub fn input(seen: &Observation, target: HeadPose) -> [f32; INPUTS] {
        let p = seen.pose.to_array();
        let t = target.to_array();
        let mut x = [0f32; INPUTS];
        for k in 0..3 {
            x[k] = p[k] as f32;
            x[3 + k] = seen.velocity[k] as f32;
            x[6 + k] = t[k] as f32;
        }
        x
    }
}

impl Voluntary for Learned<'_> {
    fn command(
        &mut self,
        _neck: &Neck,
        seen: &Observation,
        target: HeadPose,
    ) -> Result<Command, NeckError> {
        let y = self
            .mlp
            .predict(&Learned::input(seen, target))
            .map_err(|e| NeckError::Controller(e.to_string()))?;
        if y.iter().any(|v| !v.is_finite()) {
            return Err(NeckError::Controller(
                "the network's command is not finite".into(),
            ));
        }
        let part = |k: usize, scale: f64| -> Vec<f64> {
            y[k * MUSCLES..(k + 1) * MUSCLES]
                .iter()
                .map(|&v| v as f64 / scale)
                .collect()
        };
        Ok(Command {
            activation: part(0, 1.0)
                .into_iter()
                .map(|a| a.clamp(0.0, 1.0))
                .collect(),
            strain: part(1, STRAIN_SCALE),
            strain_rate: part(2, 1.0),
        })
    }
}

fn uniform_pose(rng: &mut crate::rng::Stream, range: V3) -> HeadPose {
    HeadPose::from_degrees(
        rng.range(-range[0], range[0]),
        rng.range(-range[1], range[1]),
        rng.range(-range[2], range[2]),
    )
}

/// Training pairs: (train, test, fits that missed by more than 0.5 degrees).
pub fn dataset(
    neck: &Neck,
    p: &HeadposeParams,
    tick: &(dyn Fn() + Sync),
) -> Result<(Pairs, Pairs, usize)> {
    // Targets reach a little beyond the evaluated range (within the neck's commanded range)
    // so that its corners are inside the data rather than on its edge.
    let limit = neck.params.range_degrees;
    let wide: V3 = std::array::from_fn(|k| (TARGET_MARGIN * p.range_degrees[k]).min(limit[k]));
    let mut rng = stream(p.seed, "headpose/targets");
    let targets: Vec<HeadPose> = (0..p.fit_targets)
        .map(|_| uniform_pose(&mut rng, wide))
        .collect();
    let rows: Vec<(Vec<f32>, Vec<f32>, bool)> = targets
        .par_iter()
        .enumerate()
        .map(|(i, &target)| -> Result<(Vec<f32>, Vec<f32>, bool)> {
            let fit = neck
                .fit(target)
                .with_context(|| format!("fitting target {:?} (degrees)", target.degrees()))?;
            let mut rng = stream(p.seed, &format!("headpose/poses/{i}"));
            let (mut x, mut y) = (Vec::new(), Vec::new());
            for _ in 0..p.poses_per_target {
                let pose = uniform_pose(&mut rng, wide);
                let velocity = [0.5 * rng.normal(), 0.5 * rng.normal(), 0.5 * rng.normal()];
                let seen = Observation { pose, velocity };
                let c = Teacher::command_for(neck, pose, target, &fit)?;
                x.extend(Learned::input(&seen, target));
                y.extend(c.activation.iter().map(|&v| v as f32));
                y.extend(c.strain.iter().map(|&v| (v * STRAIN_SCALE) as f32));
                y.extend(c.strain_rate.iter().map(|&v| v as f32));
            }
            tick();
            Ok((x, y, fit.error_degrees > 0.5))
        })
        .collect::<Result<_>>()?;
    let n_test = ((p.fit_targets as f64 * p.test_fraction).round() as usize).min(p.fit_targets - 1);
    let mut train = Pairs {
        inputs: INPUTS,
        outputs: OUTPUTS,
        ..Pairs::default()
    };
    let mut test = train.clone();
    let mut missed = 0;
    for (i, (x, y, miss)) in rows.into_iter().enumerate() {
        missed += miss as usize;
        let into = if i >= p.fit_targets - n_test {
            &mut test
        } else {
            &mut train
        };
        into.x.extend(x);
        into.y.extend(y);
    }
    Ok((train, test, missed))
}

/// The grid of static targets: each axis at -range, 0, +range (27 targets).
pub fn static_targets(range: V3) -> Vec<HeadPose> {
    let mut out = Vec::new();
    for i in [-1.0, 0.0, 1.0] {
        for j in [-1.0, 0.0, 1.0] {
            for k in [-1.0, 0.0, 1.0] {
                out.push(HeadPose::from_degrees(
                    i * range[0],
                    j * range[1],
                    k * range[2],
                ));
            }
        }
    }
    out
}

/// The pose sequences (30 fps): a nod, a head shake and a look around.
pub fn sequences(range: V3, seconds: f64) -> Vec<(String, PoseSequence)> {
    let fps = 30.0;
    let n = (seconds * fps).round() as usize + 1;
    let make = |f: &dyn Fn(f64) -> V3| PoseSequence {
        fps,
        poses: (0..n)
            .map(|i| {
                let d = f(i as f64 / fps);
                HeadPose::from_degrees(d[0], d[1], d[2])
            })
            .collect(),
    };
    let tau = std::f64::consts::TAU;
    vec![
        (
            "nod".into(),
            make(&|t| [0.7 * range[0] * (tau * 0.5 * t).sin(), 0.0, 0.0]),
        ),
        (
            "shake".into(),
            make(&|t| [0.0, 0.7 * range[1] * (tau * 0.5 * t).sin(), 0.0]),
        ),
        (
            "look_around".into(),
            make(&|t| {
                [
                    0.5 * range[0] * (tau * 0.25 * t).sin(),
                    0.7 * range[1] * (tau * 0.25 * t).cos(),
                    0.5 * range[2] * (tau * 0.5 * t).sin(),
                ]
            }),
        ),
    ]
}

/// The face carried by the skull: the skull's rotation about the occipital condyles and the
/// condyles' displacement, in the face's frame (metres, +y up, +z out of the face; the neck's
/// frame has the same axes).
pub fn face_motion(pose: HeadPose, skull_offset: V3) -> Rigid {
    Rigid {
        rotation: pose.rotation(),
        pivot: CONDYLES,
        translation: skull_offset,
    }
}

/// The occipital condyles (the skull's joint) in the face's frame (m): on the midline about
/// 3 cm below and 6 cm behind the face mesh's origin, behind the jaw's hinge
/// (`sim::rig`, (0, 0.003, -0.026)), an anthropometric estimate.
pub const CONDYLES: V3 = [0.0, -0.03, -0.06];

/// The face at rest moved rigidly with the skull.
pub fn posed_face(rest: &State, motion: &Rigid) -> State {
    State {
        positions: rest.positions.iter().map(|&x| motion.apply(x)).collect(),
        activations: rest.activations.clone(),
    }
}
