//! The head-neck experiment (`tables = ["headpose"]`, paper 3.1 and 5.3): the learned
//! voluntary controller's training data and training (cached stages), then tracking of
//! static targets across the range and of pose sequences, the Hill curves (paper Fig. 7),
//! and the face riding on the simulated skull (paper Fig. 4).
//!
//! Training data: targets drawn uniformly in 1.15 times the evaluated range (within the
//! neck's commanded range); for each, the teacher's
//! equilibrium fit (`Neck::fit`, the activations and strains that hold it); for each target
//! `poses_per_target` current poses and velocities drawn around it, labelled with the
//! teacher's command (`Teacher::command_for`). The network maps (pose, velocity, target) to
//! (activations, strains, strain rates), as the voluntary controller of paper 3.1.

use std::path::Path;
use std::time::Instant;

use anyhow::{Context, Result};
use rayon::prelude::*;

use crate::cache::Cache;
use crate::learn::mlp::{train, Curves, Mlp, Pairs};
use crate::learn::params::{ModelParams, Normalization, TrainParams};
use crate::report::compose::{labelled_grid, png_bytes};
use crate::report::figures::{line_panels, Panel, XySeries, PALETTE};
use crate::report::render::{render, Camera, RenderOptions};
use crate::rng::stream;
use crate::sim::geom::{Rigid, V3};
use crate::sim::neck::{
    simulate, BodyState, Command, HeadPose, Neck, NeckError, NeckParams, Observation, PoseSequence,
    ReflexParams, Teacher, Trajectory, Voluntary, MUSCLES,
};
use crate::sim::{FaceModel, State};

/// Bump when the data, training or evaluation change meaning. 5: the teacher's projected
/// gradient restarts its momentum on the proximal-gradient test and always takes its step.
const HEADPOSE_VERSION: u32 = 5;
/// The spec keys the data stage reads (its targets, poses and split).
const DATA_KEYS: [&str; 7] = [
    "headpose.seed",
    "headpose.fit_targets",
    "headpose.poses_per_target",
    "headpose.test_fraction",
    "headpose.pitch_degrees",
    "headpose.yaw_degrees",
    "headpose.roll_degrees",
];
/// The spec keys the training stage reads (besides its data).
const TRAIN_KEYS: [&str; 6] = [
    "headpose.seed",
    "headpose.layers",
    "headpose.width",
    "headpose.learning_rate",
    "headpose.batch_size",
    "headpose.epochs",
];
/// Strains are scaled by this in the network's outputs so that they weigh like activations.
const STRAIN_SCALE: f64 = 10.0;
const INPUTS: usize = 9;
const OUTPUTS: usize = 3 * MUSCLES;
/// Training targets are drawn in this multiple of the evaluated range.
const TARGET_MARGIN: f64 = 1.15;
/// Samples per second in the trajectories.
const SAMPLE_RATE: f64 = 100.0;

/// `[headpose]` in a spec.
#[derive(Clone, Debug, PartialEq)]
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

fn f32_bytes(v: &[f32]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}

fn f32_from(bytes: &[u8]) -> Vec<f32> {
    bytes
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect()
}

/// One static target's result.
#[derive(Clone, Debug, PartialEq)]
pub struct StaticRow {
    pub controller: &'static str,
    pub target: HeadPose,
    /// Mean error over the last quarter second (degrees).
    pub final_error: f64,
    /// Largest error over the last half second (degrees).
    pub late_max_error: f64,
    /// When the error last entered the band and stayed (s); None if it never settled.
    pub settling_time: Option<f64>,
    pub final_pose: HeadPose,
}

/// One pose sequence's result.
#[derive(Clone, Debug, PartialEq)]
pub struct SequenceRow {
    pub controller: &'static str,
    pub name: String,
    /// RMS and largest error after the first half second (degrees).
    pub rms_error: f64,
    pub max_error: f64,
}

fn errors(run: &Trajectory) -> Vec<f64> {
    run.pose
        .iter()
        .zip(&run.target)
        .map(|(p, t)| p.error_degrees(*t))
        .collect()
}

fn static_row(
    controller: &'static str,
    target: HeadPose,
    run: &Trajectory,
    band: f64,
) -> StaticRow {
    let e = errors(run);
    let end = *run.time.last().unwrap_or(&0.0);
    let over = |from: f64| {
        e.iter()
            .zip(&run.time)
            .filter(move |(_, t)| **t > end - from + 1e-9)
    };
    let last: Vec<f64> = over(0.25).map(|(e, _)| *e).collect();
    let settled_from = e.iter().rposition(|v| *v >= band);
    StaticRow {
        controller,
        target,
        final_error: last.iter().sum::<f64>() / last.len().max(1) as f64,
        late_max_error: over(0.5).map(|(e, _)| *e).fold(0.0, f64::max),
        settling_time: match settled_from {
            None => Some(0.0),
            Some(i) if i + 1 < e.len() => Some(run.time[i + 1]),
            Some(_) => None,
        },
        final_pose: *run.pose.last().unwrap_or(&HeadPose::default()),
    }
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

/// Everything the stage makes.
pub struct Output {
    pub static_rows: Vec<StaticRow>,
    pub sequence_rows: Vec<SequenceRow>,
    /// `controller,case,time,target_pitch,...,pose_roll` (degrees).
    pub trajectories_csv: String,
    pub curves: Curves,
    pub pairs: (usize, usize),
    pub missed_fits: usize,
    /// The voluntary network (safetensors).
    pub weights: Vec<u8>,
    /// Kept for the figures.
    runs: Vec<(&'static str, String, Trajectory)>,
}

/// Dataset and training (cached), then the evaluation.
pub fn stage(
    spec: &crate::spec::Spec,
    cache: &Cache,
    record: &mut dyn FnMut(&str, &str, bool, Instant),
    bar: &dyn Fn(u64, &str) -> indicatif::ProgressBar,
) -> Result<Output> {
    let p = &spec.headpose;
    let neck = p.neck();
    // Each stage hashes only the keys it reads: retraining never re-fits.
    let data_values = super::run::values_text(spec, &DATA_KEYS);
    let data_key = crate::cache::key("headpose_data", HEADPOSE_VERSION, &data_values, &[]);
    let t = Instant::now();
    let (train_pairs, test_pairs, missed) = match cache.get("headpose_data", &data_key)? {
        Some(e) => {
            let read = |name: &str, inputs: usize, outputs: usize| -> Result<Pairs> {
                Ok(Pairs {
                    inputs,
                    outputs,
                    x: f32_from(&e.read(&format!("{name}_x.f32"))?),
                    y: f32_from(&e.read(&format!("{name}_y.f32"))?),
                })
            };
            let missed = String::from_utf8(e.read("missed.txt")?)?.trim().parse()?;
            record("headpose_data", &data_key, true, t);
            (
                read("train", INPUTS, OUTPUTS)?,
                read("test", INPUTS, OUTPUTS)?,
                missed,
            )
        }
        None => {
            let progress = bar(p.fit_targets as u64, "neck equilibrium fits");
            let tick = || progress.inc(1);
            let (train, test, missed) = dataset(&neck, p, &tick)?;
            progress.finish_and_clear();
            cache.put(
                "headpose_data",
                &data_key,
                &[
                    ("train_x.f32".into(), f32_bytes(&train.x)),
                    ("train_y.f32".into(), f32_bytes(&train.y)),
                    ("test_x.f32".into(), f32_bytes(&test.x)),
                    ("test_y.f32".into(), f32_bytes(&test.y)),
                    ("missed.txt".into(), missed.to_string().into_bytes()),
                ],
            )?;
            record("headpose_data", &data_key, false, t);
            (train, test, missed)
        }
    };
    let train_values = super::run::values_text(spec, &TRAIN_KEYS);
    let train_key = crate::cache::key(
        "headpose_train",
        HEADPOSE_VERSION,
        &train_values,
        &[&data_key],
    );
    let t = Instant::now();
    let (mlp, curves) = match cache.get("headpose_train", &train_key)? {
        Some(e) => {
            record("headpose_train", &train_key, true, t);
            (
                Mlp::from_safetensors(&e.read("weights.safetensors")?)?,
                super::run::curves_from(&String::from_utf8(e.read("curves.csv")?)?),
            )
        }
        None => {
            let mut rng = stream(p.seed, "headpose/network");
            let mut uniform = || rng.uniform();
            let (mlp, curves) = train(&train_pairs, &test_pairs, &p.model, &p.train, &mut uniform)
                .context("training the voluntary controller")?;
            cache.put(
                "headpose_train",
                &train_key,
                &[
                    ("weights.safetensors".into(), mlp.to_safetensors()?),
                    (
                        "curves.csv".into(),
                        super::run::curves_csv(&curves).into_bytes(),
                    ),
                ],
            )?;
            record("headpose_train", &train_key, false, t);
            (mlp, curves)
        }
    };

    // Static targets, both controllers; sequences with the learned one.
    let targets = static_targets(p.range_degrees);
    let every = (neck.params.simulation_rate / SAMPLE_RATE).round() as usize;
    let progress = bar(2 * targets.len() as u64, "head pose tracking");
    let jobs: Vec<(&'static str, usize)> = ["teacher", "learned"]
        .into_iter()
        .flat_map(|c| (0..targets.len()).map(move |i| (c, i)))
        .collect();
    let runs: Vec<(&'static str, String, Trajectory)> = jobs
        .par_iter()
        .map(|&(c, i)| -> Result<(&'static str, String, Trajectory)> {
            let target = targets[i];
            let mut controller: Box<dyn Voluntary + '_> = match c {
                "teacher" => Box::new(Teacher::default()),
                _ => Box::new(Learned { mlp: &mlp }),
            };
            let run = simulate(
                &neck,
                controller.as_mut(),
                &PoseSequence::hold(target),
                BodyState::rest(),
                p.duration,
                every,
            )
            .with_context(|| format!("{c} controller, target {:?} deg", target.degrees()))?;
            progress.inc(1);
            let d = target.degrees();
            Ok((
                c,
                format!("static {:.0} {:.0} {:.0}", d[0], d[1], d[2]),
                run,
            ))
        })
        .collect::<Result<_>>()?;
    progress.finish_and_clear();
    let static_rows = runs
        .iter()
        .zip(&jobs)
        .map(|((c, _, run), &(_, i))| static_row(c, targets[i], run, p.settle_degrees))
        .collect();
    let seqs = sequences(p.range_degrees, p.sequence_seconds);
    let seq_runs: Vec<(&'static str, String, Trajectory)> = seqs
        .par_iter()
        .map(
            |(name, seq)| -> Result<(&'static str, String, Trajectory)> {
                let mut learned = Learned { mlp: &mlp };
                let run = simulate(
                    &neck,
                    &mut learned,
                    seq,
                    BodyState::rest(),
                    p.sequence_seconds,
                    every,
                )
                .with_context(|| format!("learned controller, sequence {name}"))?;
                Ok(("learned", name.clone(), run))
            },
        )
        .collect::<Result<_>>()?;
    let sequence_rows = seq_runs
        .iter()
        .map(|(c, name, run)| {
            let e: Vec<f64> = errors(run)
                .into_iter()
                .zip(&run.time)
                .filter(|(_, t)| **t >= 0.5)
                .map(|(e, _)| e)
                .collect();
            SequenceRow {
                controller: c,
                name: name.clone(),
                rms_error: (e.iter().map(|v| v * v).sum::<f64>() / e.len().max(1) as f64).sqrt(),
                max_error: e.iter().copied().fold(0.0, f64::max),
            }
        })
        .collect();
    let mut all = runs;
    all.extend(seq_runs);
    let mut csv = String::from(
        "controller,case,time,target_pitch,target_yaw,target_roll,pose_pitch,pose_yaw,pose_roll\n",
    );
    for (c, case, run) in &all {
        for ((t, target), pose) in run.time.iter().zip(&run.target).zip(&run.pose) {
            let (a, b) = (target.degrees(), pose.degrees());
            csv.push_str(&format!(
                "{c},{case},{t:.3},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4}\n",
                a[0], a[1], a[2], b[0], b[1], b[2]
            ));
        }
    }
    Ok(Output {
        static_rows,
        sequence_rows,
        trajectories_csv: csv,
        curves,
        pairs: (train_pairs.len(), test_pairs.len()),
        missed_fits: missed,
        weights: mlp.to_safetensors()?,
        runs: all,
    })
}

fn opt(v: Option<f64>) -> String {
    v.map_or("never".into(), |v| format!("{v:.2}"))
}

pub fn static_csv(rows: &[StaticRow]) -> String {
    let mut out = String::from(
        "controller,target_pitch,target_yaw,target_roll,final_error_deg,late_max_error_deg,settling_time_s,final_pitch,final_yaw,final_roll\n",
    );
    for r in rows {
        let (t, f) = (r.target.degrees(), r.final_pose.degrees());
        out.push_str(&format!(
            "{},{:.0},{:.0},{:.0},{:.4},{:.4},{},{:.4},{:.4},{:.4}\n",
            r.controller,
            t[0],
            t[1],
            t[2],
            r.final_error,
            r.late_max_error,
            r.settling_time.map_or("".into(), |v| format!("{v:.3}")),
            f[0],
            f[1],
            f[2]
        ));
    }
    out
}

pub fn sequences_csv(rows: &[SequenceRow]) -> String {
    let mut out = String::from("controller,sequence,rms_error_deg,max_error_deg\n");
    for r in rows {
        out.push_str(&format!(
            "{},{},{:.4},{:.4}\n",
            r.controller, r.name, r.rms_error, r.max_error
        ));
    }
    out
}

/// `paper-tables/headpose.md`.
pub fn markdown(out: &Output, spec: &crate::spec::Spec) -> String {
    let p = &spec.headpose;
    let mut md = String::from("# Head pose control (paper 3.1, 5.3)\n\n");
    md.push_str(&format!(
        "Static targets: every combination of pitch {{-{0}, 0, {0}}}, yaw {{-{1}, 0, {1}}}, roll \
         {{-{2}, 0, {2}}} degrees, each simulated {3} s from the upright rest posture at 4 kHz with \
         the voluntary controller at 25 Hz and the reflex at every step. Final error: mean angle \
         between achieved and target skull orientation over the last 0.25 s. Settling time: when the \
         error last entered the {4}-degree band.\n\n",
        p.range_degrees[0], p.range_degrees[1], p.range_degrees[2], p.duration, p.settle_degrees
    ));
    md.push_str("| controller | targets | within band at the end | mean final error (deg) | max final error (deg) | mean settling time (s) | max settling time (s) |\n|---|---|---|---|---|---|---|\n");
    for c in ["teacher", "learned"] {
        let rows: Vec<&StaticRow> = out
            .static_rows
            .iter()
            .filter(|r| r.controller == c)
            .collect();
        let n = rows.len().max(1) as f64;
        let within = rows
            .iter()
            .filter(|r| r.late_max_error < p.settle_degrees)
            .count();
        let settled: Vec<f64> = rows.iter().filter_map(|r| r.settling_time).collect();
        let all_settled = settled.len() == rows.len();
        md.push_str(&format!(
            "| {c} | {} | {within} | {:.2} | {:.2} | {:.2} | {} |\n",
            rows.len(),
            rows.iter().map(|r| r.final_error).sum::<f64>() / n,
            rows.iter().map(|r| r.final_error).fold(0.0, f64::max),
            settled.iter().sum::<f64>() / settled.len().max(1) as f64,
            if all_settled {
                format!("{:.2}", settled.iter().copied().fold(0.0, f64::max))
            } else {
                "never (some)".into()
            },
        ));
    }
    md.push_str("\nPer target (learned controller):\n\n| pitch | yaw | roll | final error (deg) | settling time (s) |\n|---|---|---|---|---|\n");
    for r in out.static_rows.iter().filter(|r| r.controller == "learned") {
        let t = r.target.degrees();
        md.push_str(&format!(
            "| {:.0} | {:.0} | {:.0} | {:.2} | {} |\n",
            t[0],
            t[1],
            t[2],
            r.final_error,
            opt(r.settling_time)
        ));
    }
    md.push_str("\nPose sequences (30 fps targets, learned controller; errors after the first 0.5 s):\n\n| sequence | RMS error (deg) | max error (deg) |\n|---|---|---|\n");
    for r in &out.sequence_rows {
        md.push_str(&format!(
            "| {} | {:.2} | {:.2} |\n",
            r.name, r.rms_error, r.max_error
        ));
    }
    let last = |v: &[f64]| v.last().copied().unwrap_or(f64::NAN);
    md.push_str(&format!(
        "\nVoluntary network: {INPUTS} inputs (pose, angular velocity, target) -> {} x {} ReLU -> {OUTPUTS} \
         outputs (72 activations, 72 strains x {STRAIN_SCALE}, 72 strain rates), Adam lr {}, {} epochs; \
         {} training and {} test pairs from {} equilibrium fits ({} missed by more than 0.5 deg); \
         final train MSE {:.2e}, test MSE {:.2e}.\n",
        p.model.layers,
        p.model.width,
        p.train.learning_rate,
        p.train.epochs,
        out.pairs.0,
        out.pairs.1,
        p.fit_targets,
        out.missed_fits,
        last(&out.curves.train),
        last(&out.curves.test),
    ));
    md.push_str(&format!(
        "\nSeeds: headpose.seed = {}. Reproduce: `cargo run --release -- run experiments/headpose.toml`.\n",
        p.seed
    ));
    md
}

fn degrees_series(run: &Trajectory, axis: usize, pose: bool) -> Vec<(f64, f64)> {
    run.time
        .iter()
        .zip(if pose { &run.pose } else { &run.target })
        .map(|(t, p)| (*t, p.degrees()[axis]))
        .collect()
}

/// Target (dashed) against achieved angles over time, one panel per axis.
fn tracking_figure(path: &Path, title: &str, runs: &[(&str, &Trajectory)]) -> Result<()> {
    let axes = ["pitch", "yaw", "roll"];
    let panels: Vec<Panel> = (0..3)
        .map(|a| Panel {
            title: axes[a].into(),
            x_label: "time (s)".into(),
            y_label: "angle (deg)".into(),
            series: runs
                .iter()
                .enumerate()
                .flat_map(|(i, (label, run))| {
                    let color = PALETTE[(i + 1) % PALETTE.len()];
                    [
                        XySeries {
                            label: format!("{label} target"),
                            points: degrees_series(run, a, false),
                            color,
                            dashed: true,
                        },
                        XySeries {
                            label: format!("{label} achieved"),
                            points: degrees_series(run, a, true),
                            color,
                            dashed: false,
                        },
                    ]
                })
                .collect(),
        })
        .collect();
    line_panels(path, title, &panels)
}

/// Paper Fig. 7: the Hill force-length (active at a = 1, passive, total) and force-velocity
/// relations of eq. 3-4, normalized by F_max and l0.
fn hill_figure(path: &Path, neck: &Neck) -> Result<()> {
    let m = &neck.muscles[0];
    let hill = &neck.params.hill;
    let l0 = m.rest_length;
    let lengths: Vec<f64> = (0..=120).map(|i| 0.4 + i as f64 * 0.01).collect();
    let f = |v: f64| v / m.max_force;
    let active: Vec<(f64, f64)> = lengths
        .iter()
        .map(|&r| (r, f(m.force_length(hill, r * l0))))
        .collect();
    let passive: Vec<(f64, f64)> = lengths
        .iter()
        .map(|&r| (r, f(m.passive(hill, r * l0, 0.0, false))))
        .collect();
    let total: Vec<(f64, f64)> = active
        .iter()
        .zip(&passive)
        .map(|(a, p)| (a.0, a.1 + p.1))
        .collect();
    let rates: Vec<(f64, f64)> = (0..=100)
        .map(|i| {
            let v = -1.2 + i as f64 * 0.02;
            (v, m.force_velocity(hill, v * hill.max_velocity * l0))
        })
        .collect();
    let s = |label: &str, points: Vec<(f64, f64)>, k: usize, dashed: bool| XySeries {
        label: label.into(),
        points,
        color: PALETTE[k],
        dashed,
    };
    line_panels(
        path,
        "Hill-type neck muscle (eq. 3-4)",
        &[
            Panel {
                title: "force-length".into(),
                x_label: "length l / l0".into(),
                y_label: "force / F_max".into(),
                series: vec![
                    s("contractile (a = 1)", active, 5, false),
                    s("passive", passive, 1, true),
                    s("total", total, 0, false),
                ],
            },
            Panel {
                title: "force-velocity".into(),
                x_label: "lengthening rate / (v_max l0)".into(),
                y_label: "F_v".into(),
                series: vec![s("F_v", rates, 5, false)],
            },
        ],
    )
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

/// Figures into `dir`.
pub fn figures(
    dir: &Path,
    out: &Output,
    spec: &crate::spec::Spec,
    model: &FaceModel,
) -> Result<()> {
    let p = &spec.headpose;
    let neck = p.neck();
    hill_figure(&dir.join("hill_curves.png"), &neck)?;
    let find = |c: &str, case: &str| {
        out.runs
            .iter()
            .find(|r| r.0 == c && r.1 == case)
            .map(|r| &r.2)
    };
    let r = p.range_degrees;
    let cases = [
        format!("static {:.0} 0 0", r[0]),
        format!("static 0 {:.0} 0", -r[1]),
        format!("static {:.0} {:.0} {:.0}", -r[0], r[1], r[2]),
    ];
    for c in ["teacher", "learned"] {
        let runs: Vec<(&str, &Trajectory)> = cases
            .iter()
            .filter_map(|case| find(c, case).map(|t| (case.trim_start_matches("static "), t)))
            .collect();
        tracking_figure(
            &dir.join(format!("static_{c}.png")),
            &format!("Static targets, {c} controller (pitch yaw roll, deg)"),
            &runs,
        )?;
    }
    let seq: Vec<(&str, &Trajectory)> = out
        .runs
        .iter()
        .filter(|r| !r.1.starts_with("static"))
        .map(|r| (r.1.as_str(), &r.2))
        .collect();
    tracking_figure(
        &dir.join("sequences.png"),
        "Pose sequences, learned controller",
        &seq,
    )?;
    // Paper Fig. 4: the face at the head poses the learned controller reached.
    let rest = model.rest_state();
    let shown = [
        "static 0 0 0".to_string(),
        format!("static 0 {:.0} 0", r[1]),
        format!("static 0 {:.0} 0", -r[1]),
        format!("static {:.0} 0 0", r[0]),
        format!("static {:.0} 0 0", -r[0]),
        format!("static 0 0 {:.0}", r[2]),
    ];
    let options = RenderOptions {
        width: 300,
        height: 350,
        camera: Camera::head_motion(),
        ..RenderOptions::default()
    };
    let mut cells = Vec::new();
    let mut labels = Vec::new();
    for case in &shown {
        if let Some(run) = find("learned", case) {
            let (pose, offset) = (run.pose.last(), run.skull_offset.last());
            let motion = face_motion(
                pose.copied().unwrap_or_default(),
                offset.copied().unwrap_or_default(),
            );
            let state = posed_face(&rest, &motion);
            cells.push(render(model, &state, &options));
            let d = run.pose.last().copied().unwrap_or_default().degrees();
            // `+ 0.0` turns a rounded -0 into 0, so a label never reads "-0".
            let deg = |x: f64| x.round() + 0.0;
            labels.push(format!(
                "{:.0} / {:.0} / {:.0}",
                deg(d[0]),
                deg(d[1]),
                deg(d[2])
            ));
        }
    }
    let grid = labelled_grid(
        "The face on the simulated skull (achieved pitch / yaw / roll, deg)",
        &[cells],
        &[String::new()],
        &labels,
    )?;
    crate::io::atomic::write_atomic(&dir.join("face_poses.png"), &png_bytes(&grid)?)
        .with_context(|| format!("{}: cannot write", dir.join("face_poses.png").display()))?;
    Ok(())
}
