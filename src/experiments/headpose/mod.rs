//! The head-neck experiment (`tables = ["headpose"]`, paper 3.1 and 5.3): the learned
//! voluntary controller's (`crate::headneck`) training data and training (cached stages),
//! then tracking of static targets across the range and of pose sequences, the Hill curves
//! (paper Fig. 7), and the face riding on the simulated skull (paper Fig. 4).

use std::path::Path;

use anyhow::{Context, Result};
use rayon::prelude::*;

use crate::cache::Entry;
use crate::experiments::Products;
use crate::headneck::{
    dataset, face_motion, posed_face, sequences, static_targets, Learned, INPUTS, OUTPUTS,
};
use crate::io::rows;
use crate::learn::mlp::{train, Curves, Pairs};
use crate::report::compose::{labelled_grid, png_bytes};
use crate::report::figures::{line_panels, Panel, XySeries, PALETTE};
use crate::report::render::{render, Camera, RenderOptions};
use crate::rng::stream;
use crate::run::cell::{self, CellRun, Experiment, Plan, Trained};
use crate::run::stage::{text, Artifact, Stages, Unit};
use crate::sim::neck::{simulate, BodyState, HeadPose, Neck, PoseSequence, Teacher, Voluntary};
use crate::sim::FaceModel;
use crate::spec::Table;
use std::rc::Rc;

mod report;
pub use report::{markdown, sequences_csv, static_csv};
use report::{Track, Tracks, TrajectoryLine};

/// Bump when the data, training or evaluation change meaning. 5: the teacher's projected
/// gradient restarts its momentum on the proximal-gradient test and always takes its step.
/// 6: the teacher's box QP is solved by projected Newton (a lower objective at the fit's end
/// in 11 of 12 random targets, 6x faster). 7: by the primal-dual active-set method, which
/// meets the 1e-10 stationarity test on every QP of `bench neck`'s fits, where projected
/// Newton stopped at its 200-iteration cap on 51 of 78; the fits take 7 Levenberg-Marquardt
/// steps instead of 19.5, and the data 1 s instead of 59.
const HEADPOSE_VERSION: u32 = 7;
/// Strains are scaled by this in the network's outputs so that they weigh like activations.
/// Samples per second in the trajectories.
const SAMPLE_RATE: f64 = 100.0;

/// The teacher's training pairs and how many of its fits missed their target.
struct Teaching {
    train: Pairs,
    test: Pairs,
    missed: usize,
}

impl Artifact for Teaching {
    fn encode(&self) -> Result<Vec<(String, Vec<u8>)>> {
        Ok(vec![
            ("train_x.f32".into(), f32_bytes(&self.train.x)),
            ("train_y.f32".into(), f32_bytes(&self.train.y)),
            ("test_x.f32".into(), f32_bytes(&self.test.x)),
            ("test_y.f32".into(), f32_bytes(&self.test.y)),
            ("missed.txt".into(), self.missed.to_string().into_bytes()),
        ])
    }
    fn decode(entry: &Entry) -> Result<Self> {
        let read = |name: &str| -> Result<Pairs> {
            Ok(Pairs {
                inputs: INPUTS,
                outputs: OUTPUTS,
                x: f32_from(&entry.read(&format!("{name}_x.f32"))?),
                y: f32_from(&entry.read(&format!("{name}_y.f32"))?),
            })
        };
        Ok(Teaching {
            train: read("train")?,
            test: read("test")?,
            missed: text(entry, "missed.txt")?.trim().parse()?,
        })
    }
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

fn errors(run: &Track) -> Vec<f64> {
    run.pose
        .iter()
        .zip(&run.target)
        .map(|(p, t)| p.error_degrees(*t))
        .collect()
}

fn static_row(controller: &'static str, target: HeadPose, run: &Track, band: f64) -> StaticRow {
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
        final_error: crate::stats::mean_or_zero(&last),
        late_max_error: over(0.5).map(|(e, _)| *e).fold(0.0, f64::max),
        settling_time: match settled_from {
            None => Some(0.0),
            Some(i) if i + 1 < e.len() => Some(run.time[i + 1]),
            Some(_) => None,
        },
        final_pose: *run.pose.last().unwrap_or(&HeadPose::default()),
    }
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
    runs: Vec<(&'static str, String, Track)>,
}

/// What the teacher's training pairs depend on: its targets, poses and split.
#[derive(serde::Serialize)]
struct DataInputs {
    seed: u64,
    fit_targets: usize,
    poses_per_target: usize,
    test_fraction: f64,
    range_degrees: [f64; 3],
}

/// What the voluntary network depends on besides its data.
#[derive(serde::Serialize)]
struct TrainInputs<'a> {
    seed: u64,
    model: &'a crate::learn::params::ModelParams,
    train: &'a crate::learn::params::TrainParams,
}

/// The teacher's training pairs: only what the data reads, so retraining never re-fits.
pub fn data_unit(spec: &crate::spec::Spec) -> Unit {
    let h = &spec.headpose;
    let inputs = DataInputs {
        seed: h.seed,
        fit_targets: h.fit_targets,
        poses_per_target: h.poses_per_target,
        test_fraction: h.test_fraction,
        range_degrees: h.range_degrees,
    };
    Unit::new("headpose_data", HEADPOSE_VERSION, &inputs, &[])
}

/// The tracking runs of the network trained under `train_key`: the neck, the targets' range,
/// durations and sequences (`headpose.*`).
pub fn eval_unit(spec: &crate::spec::Spec, train_key: &str) -> Unit {
    Unit::new(
        "headpose_eval",
        HEADPOSE_VERSION,
        &spec.headpose,
        &[train_key],
    )
}

/// The voluntary network, trained on the data of `data_key`.
pub fn train_unit(spec: &crate::spec::Spec, data_key: &str) -> Unit {
    let h = &spec.headpose;
    let inputs = TrainInputs {
        seed: h.seed,
        model: &h.model,
        train: &h.train,
    };
    Unit::new("headpose_train", HEADPOSE_VERSION, &inputs, &[data_key])
}

/// The head-neck experiment in the registry: its three cached stages, its CSVs and the
/// voluntary network in the run folder, its table and figures.
pub(crate) struct Headpose;

/// The voluntary neck network of a cell (safetensors), for the pose transfer.
pub(crate) struct VoluntaryWeights(pub(crate) Vec<u8>);

impl Experiment for Headpose {
    fn name(&self) -> &'static str {
        "headpose"
    }

    fn table(&self) -> Option<Table> {
        Some(Table::Headpose)
    }

    fn first_seed_only(&self) -> bool {
        true
    }

    fn trains(&self) -> bool {
        false
    }

    fn plan(&self, plan: &mut Plan) -> Result<()> {
        let data = data_unit(plan.spec);
        let train = train_unit(plan.spec, &data.key);
        let eval = eval_unit(plan.spec, &train.key);
        plan.add("headpose_data", data);
        plan.add("headpose_train", train);
        plan.add("headpose_eval", eval);
        Ok(())
    }

    fn run(&self, cx: &mut CellRun) -> Result<()> {
        let spec = cx.spec;
        let out = stage(spec, &mut cx.stages())?;
        cx.output("headpose_static.csv", static_csv(&out.static_rows))?;
        cx.output("headpose_sequences.csv", sequences_csv(&out.sequence_rows))?;
        cx.output("headpose_trajectories.csv", out.trajectories_csv.clone())?;
        cx.output("headpose_curves.csv", cell::curves_csv(&out.curves))?;
        cx.output("voluntary.safetensors", out.weights.clone())?;
        cx.table("headpose.md", &markdown(&out, spec))?;
        if let Some(dir) = cx.figures("headpose") {
            figures(&dir, &out, spec, &*cx.model()?)?;
        }
        Products::of(cx).voluntary = Some(Rc::new(VoluntaryWeights(out.weights)));
        Ok(())
    }
}

/// Dataset and training (cached), then the evaluation.
pub fn stage(spec: &crate::spec::Spec, stages: &mut Stages) -> Result<Output> {
    let p = &spec.headpose;
    let neck = p.neck();
    let data = data_unit(spec);
    let Teaching {
        train: train_pairs,
        test: test_pairs,
        missed,
    } = stages.get_or_compute(&data, |stages| {
        let progress = stages.bar(p.fit_targets as u64, "neck equilibrium fits");
        let tick = || progress.inc(1);
        let (train, test, missed) = dataset(&neck, p, &tick)?;
        progress.finish_and_clear();
        Ok(Teaching {
            train,
            test,
            missed,
        })
    })?;
    let training = train_unit(spec, &data.key);
    let Trained { mlp, curves } = stages.get_or_compute(&training, |_| {
        let mut rng = stream(p.seed, "headpose/network");
        let mut uniform = || rng.uniform();
        let (mlp, curves) = train(&train_pairs, &test_pairs, &p.model, &p.train, &mut uniform)
            .context("training the voluntary controller")?;
        Ok(Trained { mlp, curves })
    })?;

    // Static targets, both controllers; sequences with the learned one: cached, since the
    // 54 runs at 4 kHz are most of a rerun's time.
    let targets = static_targets(p.range_degrees);
    let jobs: Vec<(&'static str, usize)> = ["teacher", "learned"]
        .into_iter()
        .flat_map(|c| (0..targets.len()).map(move |i| (c, i)))
        .collect();
    let seqs = sequences(p.range_degrees, p.sequence_seconds);
    let evaluation = eval_unit(spec, &training.key);
    let Tracks(all) = stages.get_or_compute(&evaluation, |stages| {
        let every = (neck.params.simulation_rate / SAMPLE_RATE).round() as usize;
        let progress = stages.bar((jobs.len() + seqs.len()) as u64, "head pose tracking");
        let mut runs: Vec<(&'static str, String, Track)> = jobs
            .par_iter()
            .map(|&(c, i)| -> Result<(&'static str, String, Track)> {
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
                    Track::of(run),
                ))
            })
            .collect::<Result<_>>()?;
        let seq_runs: Vec<(&'static str, String, Track)> = seqs
            .par_iter()
            .map(|(name, seq)| -> Result<(&'static str, String, Track)> {
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
                progress.inc(1);
                Ok(("learned", name.clone(), Track::of(run)))
            })
            .collect::<Result<_>>()?;
        progress.finish_and_clear();
        runs.extend(seq_runs);
        Ok(Tracks(runs))
    })?;
    if all.len() != jobs.len() + seqs.len() {
        anyhow::bail!(
            "the cached tracking runs ({}) are not the {} this spec makes",
            all.len(),
            jobs.len() + seqs.len()
        );
    }
    let (runs, seq_runs) = all.split_at(jobs.len());
    let static_rows = runs
        .iter()
        .zip(&jobs)
        .map(|((c, _, run), &(_, i))| static_row(c, targets[i], run, p.settle_degrees))
        .collect();
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
                rms_error: crate::stats::rms(&e),
                max_error: e.iter().copied().fold(0.0, f64::max),
            }
        })
        .collect();
    let mut lines = Vec::new();
    for (c, case, run) in &all {
        for ((&time, target), pose) in run.time.iter().zip(&run.target).zip(&run.pose) {
            let (a, b) = (target.degrees(), pose.degrees());
            lines.push(TrajectoryLine {
                controller: c.to_string(),
                case: case.clone(),
                time,
                target_pitch: a[0],
                target_yaw: a[1],
                target_roll: a[2],
                pose_pitch: b[0],
                pose_yaw: b[1],
                pose_roll: b[2],
            });
        }
    }
    let csv = rows::to_csv(&lines);
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

fn degrees_series(run: &Track, axis: usize, pose: bool) -> Vec<(f64, f64)> {
    run.time
        .iter()
        .zip(if pose { &run.pose } else { &run.target })
        .map(|(t, p)| (*t, p.degrees()[axis]))
        .collect()
}

/// Target (dashed) against achieved angles over time, one panel per axis.
fn tracking_figure(path: &Path, title: &str, runs: &[(&str, &Track)]) -> Result<()> {
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
        let runs: Vec<(&str, &Track)> = cases
            .iter()
            .filter_map(|case| find(c, case).map(|t| (case.trim_start_matches("static "), t)))
            .collect();
        tracking_figure(
            &dir.join(format!("static_{c}.png")),
            &format!("Static targets, {c} controller (pitch yaw roll, deg)"),
            &runs,
        )?;
    }
    let seq: Vec<(&str, &Track)> = out
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
    crate::io::atomic::write_atomic(&dir.join("face_poses.png"), &png_bytes(&grid)?)?;
    Ok(())
}
