//! The inversion table (issue: Choe et al. 2001 in facelab): on Table 2's cohorts, how well
//! and how fast each way of getting activations from a real face does, all judged the same
//! way (activations -> base model, nonlinear solve from the basis prediction -> observer ->
//! AU MSE against the reference):
//! - `network` / `network_normalized`: the unified network (Table 2's two settings);
//! - `landmarks_pg`: landmark-space optimization (Choe eq. 10) over the linear basis, box
//!   constraints by accelerated projected gradient;
//! - `landmarks_penalty`: Choe's eq. 10 as published, the box as the linear penalty `c D(a)`,
//!   solved to convergence by accelerated proximal gradient (`boxqp::accelerated`);
//! - `aus_basis`: AU-space optimization through the linear basis (projected Gauss-Newton);
//! - `aus_refined`: `aus_basis` corrected by the nonlinear solve (defect correction: the
//!   basis' AU error at the current activations is subtracted from the target, and the
//!   basis fit repeated; the iterate whose nonlinear face is closest is kept, and an iterate
//!   the nonlinear solve cannot reach ends the corrections). The best any
//!   AU -> activation map can do on our model, to within the optimizer: what Table 2's error
//!   owes to the model rather than the network.
//!
//! Every method reads the same detection: the subject's landmarks with detector noise of
//! `inversion.landmark_noise_sd` (IOD units, per coordinate), from which the landmark methods
//! take displacements and the network and AU methods the observer's AUs. Each is scored
//! against the clean face: the observer's reading of the subject's landmarks without noise
//! (AU MSE), and those landmarks (landmark RMS).

use std::time::Instant;

use anyhow::{Context, Result};
use rayon::prelude::*;

use crate::boxqp::{au_fit, Bound};
use crate::cache::Entry;
use crate::cohort::{CohortKind, CohortParams, Subject};
use crate::experiments::table2::planned_cohort;
use crate::experiments::table2::RefFrame;
use crate::experiments::Products;
use crate::learn::{Mlp, Normalization};
use crate::observe::au::AU_MAX;
use crate::observe::{landmarks, Calibration, AU_COUNT, LANDMARK_COUNT};
use crate::rng::stream;
use crate::run::cell::{spec_calibration, CellRun, Experiment, Plan};
use crate::run::stage::{text, Artifact, Stages, Unit};
use crate::sim::expression::ExpressionWeights;
use crate::sim::{solve_from_rest, Activations, FaceParams, Mesh, SolveParams, Workspace};
use crate::spec::InversionParams;
use crate::spec::Table;
use crate::transfer::network::{predict_activations, range_map, training_range};

use crate::observe::model_observer;

mod report;

use crate::transfer::inverter::{activations, flat, rms, Inverter};

pub use report::{csv, markdown, timing_csv, timing_markdown};

/// The methods, in table order.
pub const METHODS: [&str; 6] = [
    "network",
    "network_normalized",
    "landmarks_pg",
    "landmarks_penalty",
    "aus_basis",
    "aus_refined",
];

/// One inverted frame: per method, the transferred AUs, the nonlinear face's landmark error
/// (RMS over the 68 landmarks, IOD units), the optimizer's iterations, its stopping measure
/// at the end and whether it met its test (none for the network), and its time (s, the
/// method alone; `solve_seconds` adds the nonlinear solve that scores it).
#[derive(Clone, Debug, PartialEq)]
pub struct Scored {
    pub aus: [f64; AU_COUNT],
    pub landmark_rms: f64,
    pub iterations: usize,
    /// `(measure, converged)`: for the landmark fits the proximal gradient's norm relative
    /// to `|M^T d|`, for the AU fits the last step's largest activation change.
    pub stop: Option<(f64, bool)>,
    pub seconds: f64,
    pub solve_seconds: f64,
}

#[derive(Clone, Debug, PartialEq)]
pub struct InvertedFrame {
    /// Index into the reference frames.
    pub index: usize,
    /// The observer's reading of the subject's face without detector noise (what each
    /// method is scored against).
    pub truth: [f64; AU_COUNT],
    /// The reading of the noisy detection (the network's and the AU fits' input).
    pub input_aus: [f64; AU_COUNT],
    pub methods: Vec<Scored>,
}

/// Which reference frames are inverted: every image, every `stride`-th video frame.
pub fn selected(reference: &[RefFrame], stride: usize) -> Vec<usize> {
    (0..reference.len())
        .filter(|&i| {
            let f = &reference[i];
            !f.cohort.is_video() || f.frame % stride.max(1) == 0
        })
        .collect()
}

/// Inverts the selected frames with every method.
#[allow(clippy::too_many_arguments)]
pub fn run(
    inverter: &Inverter,
    base_mesh: &Mesh,
    face: FaceParams,
    weights: &ExpressionWeights,
    cohort: &CohortParams,
    calibration: &Calibration,
    reference: &[RefFrame],
    mlp: &Mlp,
    training_aus: &[[f64; AU_COUNT]],
    p: &InversionParams,
    params: &SolveParams,
    tick: &(dyn Fn() + Sync),
) -> Result<Vec<InvertedFrame>> {
    let chosen = selected(reference, p.frame_stride);
    let cx = Inputs {
        inverter,
        base_mesh,
        face,
        weights,
        cohort,
        calibration,
        reference,
        mlp,
        // Normalization maps per cohort, over all of its frames (as Table 2).
        maps: cohort_maps(reference, training_aus),
        p,
        params,
        tick,
    };
    // One job per subject: its model solves its frames, the base model scores the methods.
    let jobs = subject_jobs(reference, &chosen);
    let per_job: Vec<Vec<InvertedFrame>> = jobs
        .par_iter()
        .map(|(kind, s, frames)| invert_subject(&cx, *kind, *s, frames))
        .collect::<Result<_>>()?;
    Ok(per_job.into_iter().flatten().collect())
}

/// A detection of `clean` landmarks: each coordinate with normal noise of `sd` from the
/// stream `name` of `seed` (none at `sd = 0`).
fn detect(
    clean: &[[f64; 3]; LANDMARK_COUNT],
    sd: f64,
    seed: u64,
    name: &str,
) -> [[f64; 3]; LANDMARK_COUNT] {
    let mut rng = stream(seed, name);
    std::array::from_fn(|k| {
        std::array::from_fn(|c| clean[k][c] + if sd > 0.0 { sd * rng.normal() } else { 0.0 })
    })
}

/// What every subject's inversion reads.
struct Inputs<'a> {
    inverter: &'a Inverter<'a>,
    base_mesh: &'a Mesh,
    face: FaceParams,
    weights: &'a ExpressionWeights,
    cohort: &'a CohortParams,
    calibration: &'a Calibration,
    reference: &'a [RefFrame],
    mlp: &'a Mlp,
    maps: Vec<(CohortKind, crate::learn::Normalizer)>,
    p: &'a InversionParams,
    params: &'a SolveParams,
    tick: &'a (dyn Fn() + Sync),
}

/// One subject's frames: drawn, solved and inverted by every method.
fn invert_subject(
    cx: &Inputs,
    kind: CohortKind,
    s: usize,
    frames: &[usize],
) -> Result<Vec<InvertedFrame>> {
    let subject = Subject::draw(
        cx.base_mesh,
        cx.face,
        cx.weights,
        &cx.cohort.subjects,
        cx.cohort.seed,
        kind.name(),
        s,
    )?;
    let subject_observer = model_observer(&subject.model, cx.calibration.clone())?;
    let mut sws = Workspace::new(&subject.model)?;
    let mut ws = Workspace::new(cx.inverter.model)?;
    let mut surface = Vec::new();
    let mut out = Vec::new();
    for &i in frames {
        let f = &cx.reference[i];
        let a = Activations::from_values(&f.activations)?;
        let (state, _) = solve_from_rest(&subject.model, &a, &mut sws, cx.params)
            .with_context(|| format!("inversion: reference frame {i}"))?;
        let clean = landmarks(state.surface(subject.model.vertex_count()));
        // One detection, with its noise, for every method; scored against the clean
        // face.
        let detected = detect(
            &clean,
            cx.p.landmark_noise_sd * subject_observer.iod(),
            cx.cohort.seed,
            &format!("inversion/detector/{}/{}/{}", kind.name(), s, f.frame),
        );
        let truth = subject_observer.observe(&clean)?.aus;
        let d_clean = flat(&subject_observer.displacements(&clean)?);
        let d = flat(&subject_observer.displacements(&detected)?);
        let r = subject_observer.observe(&detected)?.aus;
        let mut methods = Vec::new();
        let score = |name: &str,
                     a: &Activations,
                     iterations: usize,
                     stop: Option<(f64, bool)>,
                     seconds: f64,
                     ws: &mut Workspace|
         -> Result<Scored> {
            let t = Instant::now();
            let (aus, disp) = cx.inverter.solve(a, ws, cx.params).with_context(|| {
                format!(
                    "inversion: {} of reference frame {i} ({} subject {}, {:?} frame {})",
                    name,
                    f.cohort.name(),
                    f.subject,
                    f.expression,
                    f.frame
                )
            })?;
            Ok(Scored {
                aus,
                landmark_rms: rms(&disp, &d_clean),
                iterations,
                stop,
                seconds,
                solve_seconds: t.elapsed().as_secs_f64(),
            })
        };
        // The network, both settings.
        for map in [None, cx.maps.iter().find(|m| m.0 == kind).map(|m| &m.1)] {
            let t = Instant::now();
            let a = predict_activations(cx.mlp, map, &[r])?.remove(0);
            let name = METHODS[methods.len()];
            methods.push(score(
                name,
                &a,
                1,
                None,
                t.elapsed().as_secs_f64(),
                &mut ws,
            )?);
        }
        // Landmark space: the box, then Choe's linear penalty.
        for (name, bound) in [
            ("landmarks_pg", Bound::Box),
            ("landmarks_penalty", Bound::Penalty(cx.p.penalty)),
        ] {
            let t = Instant::now();
            let (fit, relative) = cx.inverter.landmarks(&d, bound);
            let seconds = t.elapsed().as_secs_f64();
            methods.push(score(
                name,
                &activations(&fit.a),
                fit.iterations,
                Some((relative, fit.converged)),
                seconds,
                &mut ws,
            )?);
        }
        // AU space through the basis, then corrected by the nonlinear face.
        let t = Instant::now();
        let start = vec![0.0; cx.inverter.columns.len()];
        let mut f = |x: &[f64]| cx.inverter.basis_aus(x, &mut surface);
        let fit = au_fit(&mut f, &r, &start, 1e-4, 1e-4, 30);
        let basis_seconds = t.elapsed().as_secs_f64();
        methods.push(score(
            "aus_basis",
            &activations(&fit.a),
            fit.iterations,
            Some((fit.gradient_norm, fit.converged)),
            basis_seconds,
            &mut ws,
        )?);
        // Defect correction, keeping the iterate whose nonlinear face is closest.
        let t = Instant::now();
        let (x, iterations, stop) = corrected(
            cx.inverter,
            &fit,
            &r,
            cx.p.refinements,
            &mut ws,
            &mut surface,
            cx.params,
        );
        let seconds = basis_seconds + t.elapsed().as_secs_f64();
        methods.push(score(
            "aus_refined",
            &activations(&x),
            iterations,
            Some(stop),
            seconds,
            &mut ws,
        )?);
        out.push(InvertedFrame {
            index: i,
            truth,
            input_aus: r,
            methods,
        });
        (cx.tick)();
    }
    Ok(out)
}

/// Per cohort, the min-max map of its frames' AUs onto the training data's range (Table 2's
/// normalized setting).
fn cohort_maps(
    reference: &[RefFrame],
    training_aus: &[[f64; AU_COUNT]],
) -> Vec<(CohortKind, crate::learn::Normalizer)> {
    let target = training_range(Normalization::MinMax, training_aus);
    CohortKind::ALL
        .iter()
        .map(|&k| {
            let all: Vec<[f64; AU_COUNT]> = reference
                .iter()
                .filter(|f| f.cohort == k)
                .map(|f| f.aus)
                .collect();
            (k, range_map(Normalization::MinMax, &all, &target))
        })
        .collect()
}

/// The chosen frames grouped by subject, in order: (cohort, subject, frame indices).
fn subject_jobs(reference: &[RefFrame], chosen: &[usize]) -> Vec<(CohortKind, usize, Vec<usize>)> {
    let mut jobs: Vec<(CohortKind, usize, Vec<usize>)> = Vec::new();
    for &i in chosen {
        let f = &reference[i];
        match jobs.last_mut() {
            Some((k, s, v)) if *k == f.cohort && *s == f.subject => v.push(i),
            _ => jobs.push((f.cohort, f.subject, vec![i])),
        }
    }
    jobs
}

/// The table's `aus_refined`: the basis fit `fit` of the AUs `r`, corrected `refinements`
/// times through the nonlinear face (each correction solved at full tolerance from the
/// basis prediction), keeping the iterate whose face reads closest; with the iterations and
/// the last stop.
#[allow(clippy::too_many_arguments)]
fn corrected(
    inverter: &Inverter,
    fit: &crate::boxqp::Solution,
    r: &[f64; AU_COUNT],
    refinements: usize,
    ws: &mut Workspace,
    surface: &mut Vec<crate::sim::geom::V3>,
    params: &SolveParams,
) -> (Vec<f64>, usize, (f64, bool)) {
    let mut x = fit.a.clone();
    let mut iterations = fit.iterations;
    let mut stop = (fit.gradient_norm, fit.converged);
    let cost =
        |aus: &[f64; AU_COUNT]| -> f64 { aus.iter().zip(r).map(|(a, b)| (a - b).powi(2)).sum() };
    let mut best: Option<(f64, Vec<f64>)> = None;
    for step in 0..=refinements {
        // A correction can ask for activations the nonlinear face cannot reach
        // (the solve does not converge): keep the best iterate so far.
        let Ok((nl, _)) = inverter.solve(&activations(&x), ws, params) else {
            break;
        };
        let c = cost(&nl);
        if best.as_ref().is_none_or(|b| c < b.0) {
            best = Some((c, x.clone()));
        }
        if step == refinements {
            break;
        }
        let bl = inverter.basis_aus(&x, surface);
        let target: Vec<f64> = (0..AU_COUNT).map(|k| r[k] - (nl[k] - bl[k])).collect();
        let mut f = |x: &[f64]| inverter.basis_aus(x, surface);
        let next = au_fit(&mut f, &target, &x, 1e-4, 1e-4, 30);
        iterations += next.iterations;
        stop = (next.gradient_norm, next.converged);
        x = next.a;
    }
    let x = best.map_or(fit.a.clone(), |b| b.1);
    (x, iterations, stop)
}

/// Per cohort and method: AU MSE (mean over 17, AUs / 5, against the clean reading),
/// landmark RMS, iterations, the stopping measure and the share of frames that met their
/// test (methods that iterate), and milliseconds per frame (method alone, and with the
/// scoring solve). `input_noise` is the RMS of the detected reading minus the clean one over
/// the cohort's frames and AUs: the AU noise the landmark noise makes.
#[derive(Clone, Debug, PartialEq)]
pub struct Summary {
    pub cohort: CohortKind,
    pub method: &'static str,
    pub frames: usize,
    pub au_mse: f64,
    pub landmark_rms: f64,
    pub iterations: f64,
    /// Mean stopping measure and the share converged, where the method iterates.
    pub stop: Option<(f64, f64)>,
    pub input_noise: f64,
    pub ms: f64,
    pub ms_with_solve: f64,
}

pub fn summarize(frames: &[InvertedFrame], reference: &[RefFrame]) -> Vec<Summary> {
    let mut out = Vec::new();
    for kind in CohortKind::ALL {
        let mine: Vec<&InvertedFrame> = frames
            .iter()
            .filter(|f| reference[f.index].cohort == kind)
            .collect();
        if mine.is_empty() {
            continue;
        }
        let mean = |g: &dyn Fn(&InvertedFrame) -> f64| {
            let v: Vec<f64> = mine.iter().map(|f| g(f)).collect();
            crate::stats::mean(&v)
        };
        let input_noise = mean(&|f| {
            let d: Vec<f64> = (0..AU_COUNT).map(|k| f.input_aus[k] - f.truth[k]).collect();
            crate::stats::mean_square(&d)
        })
        .sqrt();
        for (m, &method) in METHODS.iter().enumerate() {
            let stop = mine[0].methods[m].stop.map(|_| {
                let of = |f: &InvertedFrame| f.methods[m].stop.unwrap_or((f64::NAN, false));
                (
                    mean(&|f| of(f).0),
                    mean(&|f| if of(f).1 { 1.0 } else { 0.0 }),
                )
            });
            out.push(Summary {
                cohort: kind,
                method,
                frames: mine.len(),
                au_mse: mean(&|f| {
                    let t = f.methods[m].aus;
                    let d: Vec<f64> = (0..AU_COUNT)
                        .map(|k| (f.truth[k] - t[k]) / AU_MAX)
                        .collect();
                    crate::stats::mean_square(&d)
                }),
                landmark_rms: mean(&|f| f.methods[m].landmark_rms),
                iterations: mean(&|f| f.methods[m].iterations as f64),
                stop,
                input_noise,
                ms: mean(&|f| 1e3 * f.methods[m].seconds),
                ms_with_solve: mean(&|f| 1e3 * (f.methods[m].seconds + f.methods[m].solve_seconds)),
            });
        }
    }
    out
}

/// What the inversion stage leaves: the table's CSV and Markdown, and the timings' CSV and
/// Markdown.
pub struct Output {
    pub csv: String,
    pub timing: String,
    pub markdown: String,
    pub timing_markdown: String,
}

impl Artifact for Output {
    fn encode(&self) -> Result<Vec<(String, Vec<u8>)>> {
        Ok(vec![
            ("inversion.csv".into(), self.csv.clone().into_bytes()),
            (
                "inversion_timing.csv".into(),
                self.timing.clone().into_bytes(),
            ),
            ("inversion.md".into(), self.markdown.clone().into_bytes()),
            (
                "inversion_timing.md".into(),
                self.timing_markdown.clone().into_bytes(),
            ),
        ])
    }
    fn decode(entry: &Entry) -> Result<Self> {
        Ok(Output {
            csv: text(entry, "inversion.csv")?,
            timing: text(entry, "inversion_timing.csv")?,
            markdown: text(entry, "inversion.md")?,
            timing_markdown: text(entry, "inversion_timing.md")?,
        })
    }
}

// 3: the expressive face (see BASIS_VERSION in cell/mod.rs). 4: one noisy detection for every
// method, scored against the clean face; Choe's linear penalty solved to convergence.
// 5: the caption's ordinal ("every 3rd video frame"; the markdown is cached with the stage).
// 6: the times per frame leave the table for the run's `timings/`.
const INVERSION_VERSION: u32 = 6;

/// The inversion table in the registry: on Table 2's cohorts (the spec must list "table2",
/// which runs first), with the first seed's unified network.
pub(crate) struct Inversion;

impl Experiment for Inversion {
    fn name(&self) -> &'static str {
        "inversion"
    }

    fn table(&self) -> Option<Table> {
        Some(Table::Inversion)
    }

    fn first_seed_only(&self) -> bool {
        true
    }

    fn plan(&self, plan: &mut Plan) -> Result<()> {
        let spec = plan.spec;
        let cohort = planned_cohort(plan)?;
        let k = plan.keys();
        let Some((_, train_key)) = k.unified().first().copied() else {
            return Ok(());
        };
        let mut inputs = vec![cohort.key.as_str(), train_key, k.dataset.as_str()];
        inputs.extend(k.basis.as_deref());
        let u = unit(spec, &inputs);
        plan.add("inversion", u);
        Ok(())
    }

    fn run(&self, cx: &mut CellRun) -> Result<()> {
        let spec = cx.spec;
        let t2 = Products::of(cx)
            .table2
            .clone()
            .context("the inversion table runs on Table 2's cohorts: list \"table2\" first")?;
        let (n, k, model, basis) = (cx.networks()?, cx.keys()?, cx.model()?, cx.basis()?);
        let basis = basis
            .as_ref()
            .as_ref()
            .context("inversion always has a basis key")?;
        let calibration = spec_calibration(spec)?;
        let inverter = Inverter::new(&model, basis, &calibration)?;
        let (seed, train_key, mlp) = n.unified(&k).into_iter().next().context("no seed")?;
        let mut keys = vec![
            t2.cohort_key.as_str(),
            train_key.as_str(),
            k.dataset.as_str(),
        ];
        keys.extend(k.basis.as_deref());
        let source = spec.face_source();
        let out = stage(
            spec,
            &source,
            &mut cx.stages(),
            &keys,
            &inverter,
            &calibration,
            &t2.reference,
            mlp,
            &n.training_aus(),
        )
        .with_context(|| format!("the inversion table (network of seed {seed})"))?;
        cx.output("inversion.csv", out.csv)?;
        // Timings are measurements, not results: outside the compared outputs.
        cx.measurement("inversion.csv", &out.timing)?;
        cx.measurement("inversion.md", &out.timing_markdown)?;
        cx.table("methods.md", &out.markdown)
    }
}

/// The inversion's unit: `inversion.*` and its inputs' keys (the cohort, the first seed's
/// unified network, the dataset and the basis).
pub fn unit(spec: &crate::spec::Spec, inputs: &[&str]) -> Unit {
    Unit::new("inversion", INVERSION_VERSION, &spec.inversion, inputs)
}

/// The cached inversion stage. Its key hashes `inversion.*` and the keys of the cohort, the
/// first seed's unified network, the dataset (normalization range) and the basis.
#[allow(clippy::too_many_arguments)]
pub fn stage(
    spec: &crate::spec::Spec,
    source: &crate::io::face::FaceSource,
    stages: &mut Stages,
    inputs: &[&str],
    inverter: &Inverter,
    calibration: &Calibration,
    reference: &[RefFrame],
    mlp: &Mlp,
    training_aus: &[[f64; AU_COUNT]],
) -> Result<Output> {
    stages.get_or_compute(&unit(spec, inputs), |stages| {
        let p = &spec.inversion;
        let progress = stages.bar(
            selected(reference, p.frame_stride).len() as u64,
            "inversion",
        );
        let tick = || progress.inc(1);
        let params = SolveParams {
            tolerance: spec.dataset.tolerance,
            ..SolveParams::default()
        };
        let frames = run(
            inverter,
            &source.mesh()?,
            source.params(),
            &source.weights()?,
            &spec.cohort,
            calibration,
            reference,
            mlp,
            training_aus,
            p,
            &params,
            &tick,
        )?;
        progress.finish_and_clear();
        let rows = summarize(&frames, reference);
        Ok(Output {
            csv: csv(&rows),
            timing: timing_csv(&rows),
            markdown: markdown(&rows, p, spec.seeds[0]),
            timing_markdown: timing_markdown(&rows),
        })
    })
}

#[cfg(test)]
mod tests;
