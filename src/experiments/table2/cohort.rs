//! Table 2 (DESIGN 3, paper 5.4): expression transfer from reference cohorts to the base model.
//! This file makes the cohorts' reference frames; the network's path they take is
//! `crate::transfer::network`.
//!
//! Reference AUs R come from our observer on each synthetic subject's face (its own neutral).
//! They go into the unified network either raw ("unnormalized") or mapped per AU, across all
//! images or frames of the cohort, onto the training data's per-AU range ("normalized"). The
//! predicted activations (clamped to [0, 1]; jaw slide and twist neutral, as the paper
//! activates only the jaw rotation) drive the base model; the observer gives transferred AUs T.
//! MSE per AU over all frames of ((R - T) / 5)^2.

use anyhow::{Context, Result};
use rayon::prelude::*;

use crate::cohort::{clips, Clip, CohortKind, CohortParams, Subject};
use crate::observe::HeadPose;
use crate::observe::{Calibration, Observer, ObserverNoise, AU_COUNT};
use crate::rng::stream;
use crate::sim::controls::CONTROL_COUNT;
use crate::sim::expression::{Expression, ExpressionWeights};
use crate::sim::{solve_from_rest, Activations, FaceParams, Mesh, SolveParams, Workspace};

use crate::dataset::reader::FaceReader;
use crate::io::rows::{self, num, CsvRow};
use crate::transfer::network::{solve_clip, Setting, Transferred};

/// The paper's 8 AUs of Table 2 (indices into `AU_NAMES`).
pub const PAPER_AUS: [&str; 8] = [
    "AU01", "AU04", "AU06", "AU09", "AU12", "AU15", "AU20", "AU25",
];

/// Zeng et al. Table 2: (row, the 8 AUs' MSE, mean over 17).
pub const PAPER: [(&str, [f64; 8], f64); 4] = [
    (
        "KDEF (unnormalized)",
        [0.191, 0.088, 0.186, 0.133, 0.011, 0.155, 0.129, 0.092],
        0.157,
    ),
    (
        "KDEF (normalized)",
        [0.118, 0.064, 0.186, 0.068, 0.028, 0.109, 0.146, 0.052],
        0.129,
    ),
    (
        "RAVDESS (video)",
        [0.012, 0.222, 0.107, 0.044, 0.083, 0.016, 0.077, 0.036],
        0.086,
    ),
    (
        "CK (video)",
        [0.038, 0.054, 0.059, 0.015, 0.008, 0.023, 0.057, 0.034],
        0.048,
    ),
];

/// One reference image or video frame.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RefFrame {
    pub cohort: CohortKind,
    pub subject: usize,
    /// `None`: a neutral image.
    #[serde(with = "neutral")]
    pub expression: Option<Expression>,
    pub frame: usize,
    /// Observed head pose (OpenFace pose_Rx, Ry, Rz; rad).
    #[serde(with = "num::all")]
    pub pose: [f64; 3],
    #[serde(with = "num::all")]
    pub aus: [f64; AU_COUNT],
    /// The subject's activations (its own muscles).
    #[serde(with = "num::all")]
    pub activations: [f64; CONTROL_COUNT],
}

/// `cohort,subject,expression,frame,pose_Rx,pose_Ry,pose_Rz,AU01..AU45,<56 controls>`;
/// numbers in Rust's shortest round-trip form.
impl CsvRow for RefFrame {
    fn header() -> Vec<String> {
        rows::wide(&[
            "cohort",
            "subject",
            "expression",
            "frame",
            "pose_Rx",
            "pose_Ry",
            "pose_Rz",
        ])
    }
}

/// A frame's expression, "neutral" for none.
pub(crate) mod neutral {
    use super::Expression;
    use serde::{Deserialize, Deserializer, Serializer};

    pub fn serialize<S: Serializer>(e: &Option<Expression>, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(e.map_or("neutral", |e| e.name()))
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Option<Expression>, D::Error> {
        let name = String::deserialize(d)?;
        match name.as_str() {
            "neutral" => Ok(None),
            s => s.parse().map(Some).map_err(serde::de::Error::custom),
        }
    }
}

/// One line of a seed's transfers: the setting, the frame's index into the reference, its
/// AUs and activations.
#[derive(serde::Serialize, serde::Deserialize)]
struct TransferLine {
    setting: Setting,
    index: usize,
    #[serde(with = "num::all")]
    aus: [f64; AU_COUNT],
    #[serde(with = "num::all")]
    activations: [f64; CONTROL_COUNT],
}

impl CsvRow for TransferLine {
    fn header() -> Vec<String> {
        rows::wide(&["setting", "index"])
    }
}

fn expression_name(e: Option<Expression>) -> &'static str {
    e.map_or("neutral", |e| e.name())
}

/// The subjects of one cohort.
pub fn subjects(
    base: &Mesh,
    face: FaceParams,
    weights: &ExpressionWeights,
    p: &CohortParams,
    kind: CohortKind,
) -> Result<Vec<Subject>> {
    (0..p.clip(kind).subjects)
        .into_par_iter()
        .map(|i| {
            Subject::draw(base, face, weights, &p.subjects, p.seed, kind.name(), i)
                .with_context(|| format!("cohort {}: subject {i}", kind.name()))
        })
        .collect()
}

/// A subject's clip, solved and observed: the reference frames.
pub fn observe_clip(
    subject: &Subject,
    reader: &FaceReader,
    observer: &Observer,
    clip: &Clip,
    cohort: &CohortParams,
    params: &SolveParams,
    ws: &mut Workspace,
) -> Result<Vec<RefFrame>> {
    let (noise_sd, seed, kind) = (cohort.noise_sd, cohort.seed, clip.kind);
    let model = &subject.model;
    let activations: Vec<Activations> = clip.frames.iter().map(|f| f.activations.clone()).collect();
    let noise = ObserverNoise {
        noise_sd,
        gain_spread: 0.0,
    };
    let mut out = Vec::with_capacity(clip.frames.len());
    let name = expression_name(clip.expression);
    solve_clip(
        model,
        &activations,
        |a, ws| Ok(solve_from_rest(model, a, ws, params)?.0),
        ws,
        params,
        |f, state| {
            let head = clip.frames[f].head;
            let r = HeadPose {
                pitch: head[0],
                yaw: head[1],
                roll: head[2],
            }
            .rotation();
            let o = observer.observe(&reader.read(model, state, Some(&r))?)?;
            let mut aus = o.aus;
            if noise_sd > 0.0 {
                let label = format!("cohort/{}/noise/{}/{name}/{f}", kind.name(), clip.subject);
                noise.apply(&mut aus, &[1.0; AU_COUNT], &mut stream(seed, &label));
            }
            out.push(RefFrame {
                cohort: kind,
                subject: clip.subject,
                expression: clip.expression,
                frame: f,
                pose: [o.pose.pitch, o.pose.yaw, o.pose.roll],
                aus,
                activations: *state.activations.values(),
            });
            Ok(())
        },
    )
    .with_context(|| format!("cohort {}, subject {}, {name}", kind.name(), clip.subject))?;
    Ok(out)
}

/// Every cohort's reference frames, in cohort, subject, clip and frame order.
#[allow(clippy::too_many_arguments)]
pub fn reference(
    base: &Mesh,
    face: FaceParams,
    weights: &ExpressionWeights,
    calibration: &Calibration,
    reader: &FaceReader,
    p: &CohortParams,
    kinds: &[CohortKind],
    params: &SolveParams,
    tick: &(dyn Fn() + Sync),
) -> Result<Vec<RefFrame>> {
    let jobs: Vec<(CohortKind, usize)> = kinds
        .iter()
        .flat_map(|&k| (0..p.clip(k).subjects).map(move |i| (k, i)))
        .collect();
    let per_job: Vec<Vec<RefFrame>> = jobs
        .par_iter()
        .map(|&(kind, i)| -> Result<Vec<RefFrame>> {
            let subject = Subject::draw(base, face, weights, &p.subjects, p.seed, kind.name(), i)
                .with_context(|| format!("cohort {}: subject {i}", kind.name()))?;
            let observer = reader.observer(&subject.model, calibration.clone())?;
            let mut ws = Workspace::new(&subject.model)?;
            let mut frames = Vec::new();
            for clip in clips(&subject, kind, p.clip(kind), p.seed) {
                frames.extend(observe_clip(
                    &subject, reader, &observer, &clip, p, params, &mut ws,
                )?);
                tick();
            }
            Ok(frames)
        })
        .collect::<Result<_>>()?;
    Ok(per_job.into_iter().flatten().collect())
}

/// Number of clips `reference` solves (for a progress bar).
pub fn clip_count(p: &CohortParams, kinds: &[CohortKind]) -> usize {
    kinds
        .iter()
        .map(|&k| p.clip(k).subjects * if k.is_video() { 6 } else { 7 })
        .sum()
}

/// Splits frames into clips: runs of the same cohort, subject and expression.
pub fn clip_ranges(frames: &[RefFrame]) -> Vec<std::ops::Range<usize>> {
    let mut out = Vec::new();
    let mut start = 0;
    for i in 1..=frames.len() {
        let cut = i == frames.len() || {
            let (a, b) = (&frames[i - 1], &frames[i]);
            (a.cohort, a.subject, a.expression) != (b.cohort, b.subject, b.expression)
        };
        if cut {
            out.push(start..i);
            start = i;
        }
    }
    out
}

/// One Table 2 row: a cohort in a setting, for one seed.
#[derive(Clone, Debug, PartialEq)]
pub struct Row {
    pub seed: u64,
    pub cohort: CohortKind,
    pub setting: Setting,
    pub mse: [f64; AU_COUNT],
}

impl Row {
    pub fn mean(&self) -> f64 {
        crate::stats::mean(&self.mse)
    }
}

pub fn reference_csv(frames: &[RefFrame]) -> String {
    rows::to_csv(frames)
}

pub fn reference_from_csv(text: &str, name: &str) -> Result<Vec<RefFrame>> {
    Ok(rows::from_csv(text, name)?)
}

/// One seed's transfers: `setting,<frame index into the reference>,AU01..AU45,<56 controls>`.
pub fn transfers_csv(t: &[(Setting, Vec<Transferred>)]) -> String {
    let lines: Vec<TransferLine> = t
        .iter()
        .flat_map(|(setting, frames)| {
            frames.iter().enumerate().map(|(index, f)| TransferLine {
                setting: *setting,
                index,
                aus: f.aus,
                activations: f.activations,
            })
        })
        .collect();
    rows::to_csv(&lines)
}

pub fn transfers_from_csv(text: &str, name: &str) -> Result<Vec<(Setting, Vec<Transferred>)>> {
    let mut out: Vec<(Setting, Vec<Transferred>)> = Vec::new();
    for l in rows::from_csv::<TransferLine>(text, name)? {
        let frame = Transferred {
            aus: l.aus,
            activations: l.activations,
        };
        match out.last_mut() {
            Some((s, v)) if *s == l.setting => v.push(frame),
            _ => out.push((l.setting, vec![frame])),
        }
    }
    Ok(out)
}
