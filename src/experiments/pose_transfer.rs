//! Head pose transferred from Table 2's cohorts (Zeng et al. 5.3, Figs. 4-5): each reference
//! frame's head pose (what OpenFace's `pose_Rx, pose_Ry, pose_Rz` would say of the subject)
//! drives the neck through the learned voluntary controller of the head-neck experiment, and
//! the achieved head pose is compared with it.
//!
//! - Images: each pose is a still, held from the upright rest posture until the head settles.
//! - Videos: each clip (one subject, one expression) is followed at the clip's frame rate,
//!   starting from the posture that holds its first pose, as a clip cut from a longer video.
//!
//! The error of a frame is the angle of the rotation between the target and achieved poses.

use anyhow::{bail, Context, Result};
use rayon::prelude::*;

use super::table2::RefFrame;
use crate::cache::{Entry, Lookup};
use crate::cohort::{CohortKind, CohortParams};
use crate::experiments::headpose;
use crate::experiments::table2::planned_cohort;
use crate::experiments::Products;
use crate::io::rows::{self, num, CsvRow};
use crate::learn::Mlp;
use crate::report::table::{Table, TableRow};
use crate::run::cell::{CellRun, Experiment, Plan};
use crate::run::stage::{text, Artifact, Stages, Unit};
use crate::sim::neck::{HeadPose, Neck, PoseSequence};
use crate::transfer::follow;

/// Bump when the evaluation changes meaning.
const POSE_TRANSFER_VERSION: u32 = 1;

/// One cohort's pose transfer: frames, how far the targets turn from upright (mean angle),
/// and the error (mean, RMS, max; degrees).
#[derive(Clone, Debug, PartialEq)]
pub struct PoseRow {
    pub cohort: CohortKind,
    pub frames: usize,
    pub mean_target_deg: f64,
    pub mean_error_deg: f64,
    pub rms_error_deg: f64,
    pub max_error_deg: f64,
}

fn target(f: &RefFrame) -> HeadPose {
    HeadPose {
        pitch: f.pose[0],
        yaw: f.pose[1],
        roll: f.pose[2],
    }
}

/// The units of work: every image alone, every video clip (one subject, one expression) as
/// its run of consecutive frames; indices into `reference`.
fn jobs(reference: &[RefFrame]) -> Vec<Vec<usize>> {
    let mut jobs: Vec<Vec<usize>> = Vec::new();
    for (i, f) in reference.iter().enumerate() {
        let same_clip = |j: &usize| {
            let g = &reference[*j];
            f.cohort.is_video()
                && (g.cohort, g.subject, g.expression) == (f.cohort, f.subject, f.expression)
        };
        match jobs.last_mut() {
            Some(job) if job.last().is_some_and(same_clip) => job.push(i),
            _ => jobs.push(vec![i]),
        }
    }
    jobs
}

/// Per reference frame, the angle between its target pose and the pose the neck reaches.
pub fn errors(
    neck: &Neck,
    mlp: &Mlp,
    cohort: &CohortParams,
    reference: &[RefFrame],
    tick: &(dyn Fn() + Sync),
) -> Result<Vec<f64>> {
    let jobs = jobs(reference);
    let per_job: Vec<Vec<(usize, f64)>> = jobs
        .par_iter()
        .map(|job| -> Result<Vec<(usize, f64)>> {
            let first = &reference[job[0]];
            let targets = PoseSequence {
                fps: cohort.clip(first.cohort).fps,
                poses: job.iter().map(|&i| target(&reference[i])).collect(),
            };
            let (targets, _) = targets.checked(neck).with_context(|| {
                format!(
                    "{} subject {}: head pose",
                    first.cohort.name(),
                    first.subject
                )
            })?;
            let (achieved, _) = follow(neck, mlp, &targets, true).with_context(|| {
                format!(
                    "pose transfer: {} subject {}, {} frame(s)",
                    first.cohort.name(),
                    first.subject,
                    job.len()
                )
            })?;
            tick();
            Ok(job
                .iter()
                .zip(&achieved)
                .map(|(&i, a)| (i, target(&reference[i]).error_degrees(*a)))
                .collect())
        })
        .collect::<Result<_>>()?;
    let mut out = vec![f64::NAN; reference.len()];
    for (i, e) in per_job.into_iter().flatten() {
        out[i] = e;
    }
    Ok(out)
}

/// The per-cohort summary of `errors`.
pub fn summarize(reference: &[RefFrame], errors: &[f64]) -> Vec<PoseRow> {
    CohortKind::ALL
        .iter()
        .filter_map(|&kind| {
            let idx: Vec<usize> = (0..reference.len())
                .filter(|&i| reference[i].cohort == kind)
                .collect();
            if idx.is_empty() {
                return None;
            }
            let e: Vec<f64> = idx.iter().map(|&i| errors[i]).collect();
            let upright = HeadPose::default();
            let turn: Vec<f64> = idx
                .iter()
                .map(|&i| upright.error_degrees(target(&reference[i])))
                .collect();
            Some(PoseRow {
                cohort: kind,
                frames: idx.len(),
                mean_target_deg: crate::stats::mean(&turn),
                mean_error_deg: crate::stats::mean(&e),
                rms_error_deg: crate::stats::mean(&e.iter().map(|x| x * x).collect::<Vec<_>>())
                    .sqrt(),
                max_error_deg: e.iter().copied().fold(0.0, f64::max),
            })
        })
        .collect()
}

/// A row's cells: the cohort's name, then its numbers with `digits` decimals.
fn cells(r: &PoseRow, digits: usize) -> [String; 6] {
    let n = |x: f64| format!("{x:.digits$}");
    [
        r.cohort.name().to_string(),
        r.frames.to_string(),
        n(r.mean_target_deg),
        n(r.mean_error_deg),
        n(r.rms_error_deg),
        n(r.max_error_deg),
    ]
}

/// A line of `table2_pose.csv`.
#[derive(serde::Serialize, serde::Deserialize)]
struct PoseLine {
    cohort: CohortKind,
    frames: usize,
    #[serde(serialize_with = "num::fixed::<4, _>")]
    mean_target_deg: f64,
    #[serde(serialize_with = "num::fixed::<4, _>")]
    mean_error_deg: f64,
    #[serde(serialize_with = "num::fixed::<4, _>")]
    rms_error_deg: f64,
    #[serde(serialize_with = "num::fixed::<4, _>")]
    max_error_deg: f64,
}

impl CsvRow for PoseLine {}

/// `cohort,frames,mean_target_deg,mean_error_deg,rms_error_deg,max_error_deg`.
pub fn csv(rows: &[PoseRow]) -> String {
    let lines: Vec<PoseLine> = rows
        .iter()
        .map(|r| PoseLine {
            cohort: r.cohort,
            frames: r.frames,
            mean_target_deg: r.mean_target_deg,
            mean_error_deg: r.mean_error_deg,
            rms_error_deg: r.rms_error_deg,
            max_error_deg: r.max_error_deg,
        })
        .collect();
    rows::to_csv(&lines)
}

/// The pose table beside Table 2.
pub fn markdown(rows: &[PoseRow]) -> String {
    let mut out = String::from(
        "# Table 2, head pose: transferred through the voluntary controller and the neck\n\n\
         Each reference frame's head pose (the subject's pose_Rx, pose_Ry, pose_Rz) drives the \
         simulated neck through the learned voluntary controller of the head-neck experiment \
         (`voluntary.safetensors`). Images: each pose a still, held from upright rest until \
         the head settles (it turns less than 0.05 deg in 0.5 s). Videos: each clip followed \
         at its frame rate from the posture that holds its first pose. Error: the angle of the \
         rotation from the target to the achieved pose (deg); target: the angle from upright.\n\n",
    );
    let mut t = Table::labelled(&[
        "cohort",
        "frames",
        "mean target turn (deg)",
        "mean error (deg)",
        "RMS error (deg)",
        "max error (deg)",
    ]);
    for r in rows {
        let mut c = cells(r, 2);
        c[0] = c[0].replace('_', " ");
        t.push(TableRow::new(c.into()));
    }
    out.push_str(&t.markdown());
    out
}

/// A line of `errors.csv`.
#[derive(serde::Serialize, serde::Deserialize)]
struct ErrorLine {
    #[serde(serialize_with = "num::shortest")]
    error_deg: f64,
}

impl CsvRow for ErrorLine {}

/// Each frame's pose error (degrees), as `errors.csv`.
struct Errors(Vec<f64>);

impl Artifact for Errors {
    fn encode(&self) -> Result<Vec<(String, Vec<u8>)>> {
        let lines: Vec<ErrorLine> = self
            .0
            .iter()
            .map(|&error_deg| ErrorLine { error_deg })
            .collect();
        Ok(vec![(
            "errors.csv".into(),
            rows::to_csv(&lines).into_bytes(),
        )])
    }
    fn decode(entry: &Entry) -> Result<Self> {
        let name = entry.path("errors.csv").display().to_string();
        let lines: Vec<ErrorLine> = rows::from_csv(&text(entry, "errors.csv")?, &name)?;
        Ok(Errors(lines.into_iter().map(|l| l.error_deg).collect()))
    }
}

/// The head pose of Table 2's cohorts in the registry: run where the spec lists both
/// "table2" and "headpose" (both run before it).
pub(crate) struct PoseTransfer;

impl Experiment for PoseTransfer {
    fn name(&self) -> &'static str {
        "pose_transfer"
    }

    fn table(&self) -> Option<crate::spec::Table> {
        None
    }

    fn first_seed_only(&self) -> bool {
        true
    }

    fn reads(&self) -> Vec<crate::spec::Table> {
        vec![crate::spec::Table::Table2, crate::spec::Table::Headpose]
    }

    /// Whenever a spec lists both tables it reads.
    fn wanted(&self, spec: &crate::spec::Spec) -> bool {
        self.reads().iter().all(|t| spec.tables.contains(t))
    }

    fn plan(&self, plan: &mut Plan) -> Result<()> {
        let spec = plan.spec;
        let cohort = planned_cohort(plan)?;
        let train = headpose::train_unit(spec, &headpose::data_unit(spec).key);
        match plan.cache.inspect(train.stage, &train.key) {
            Lookup::Hit(e) => {
                let u = unit(spec, &cohort.key, &e.read("weights.safetensors")?);
                plan.add("pose_transfer", u);
            }
            _ => plan.waiting(
                "pose_transfer",
                "its key needs the voluntary network (headpose_train)",
            ),
        }
        Ok(())
    }

    fn run(&self, cx: &mut CellRun) -> Result<()> {
        let (t2, weights) = (
            Products::of(cx).table2.clone(),
            Products::of(cx).voluntary.clone(),
        );
        let (Some(t2), Some(weights)) = (t2, weights) else {
            bail!("the pose transfer needs Table 2's cohorts and the voluntary network");
        };
        let spec = cx.spec;
        let rows = stage(
            spec,
            &mut cx.stages(),
            &t2.cohort_key,
            &weights.0,
            &t2.reference,
        )?;
        cx.output("table2_pose.csv", csv(&rows))?;
        cx.table("table2_pose.md", &markdown(&rows))
    }
}

/// The stage's unit: `headpose.*`, the cohorts' key and the controller's bytes.
pub fn unit(spec: &crate::spec::Spec, cohort_key: &str, voluntary: &[u8]) -> Unit {
    let controller = crate::cache::sha256(voluntary);
    Unit::new(
        "pose_transfer",
        POSE_TRANSFER_VERSION,
        &spec.headpose,
        &[cohort_key, &controller],
    )
}

/// The cached stage: its key is the cohort's key, the controller's bytes and the neck's
/// parameters (`headpose.*`).
#[allow(clippy::too_many_arguments)]
pub fn stage(
    spec: &crate::spec::Spec,
    stages: &mut Stages,
    cohort_key: &str,
    voluntary: &[u8],
    reference: &[RefFrame],
) -> Result<Vec<PoseRow>> {
    let unit = unit(spec, cohort_key, voluntary);
    let Errors(errors) = stages.get_or_compute(&unit, |stages| {
        let mlp = Mlp::from_safetensors(voluntary)?;
        let neck = spec.headpose.neck();
        let progress = stages.bar(jobs(reference).len() as u64, "pose");
        let tick = || progress.inc(1);
        let errors = errors(&neck, &mlp, &spec.cohort, reference, &tick)?;
        progress.finish_and_clear();
        Ok(Errors(errors))
    })?;
    Ok(summarize(reference, &errors))
}
