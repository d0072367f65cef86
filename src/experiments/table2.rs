//! Table 2 (DESIGN 3, paper 5.4): expression transfer from reference cohorts to the base model.
//!
//! Reference AUs R come from our observer on each synthetic subject's face (its own neutral).
//! They go into the unified network either raw ("unnormalized") or mapped per AU, across all
//! images or frames of the cohort, onto the training data's per-AU range ("normalized"). The
//! predicted activations (clamped to [0, 1]; jaw slide and twist neutral, as the paper
//! activates only the jaw rotation) drive the base model; the observer gives transferred AUs T.
//! MSE per AU over all frames of ((R - T) / 5)^2.

use anyhow::{bail, Context, Result};
use rayon::prelude::*;

use crate::cohort::{clips, Clip, CohortKind, CohortParams, Subject};
use crate::learn::{Mlp, Normalization, Normalizer, Pairs};
use crate::observe::au::AU_MAX;
use crate::observe::HeadPose;
use crate::observe::{Calibration, Observer, ObserverNoise, AU_COUNT};
use crate::rng::stream;
use crate::sim::basis::LinearBasis;
use crate::sim::controls::{CONTROL_COUNT, JAW_SLIDE, JAW_TWIST};
use crate::sim::expression::{Expression, ExpressionWeights};
use crate::sim::solver::solve_predicted;
use crate::sim::{
    solve, solve_from_rest, Activations, FaceModel, FaceParams, Mesh, SolveParams, State, Workspace,
};

use crate::dataset::reader::FaceReader;
use crate::io::rows::{self, num, CsvRow};

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

/// Whether reference AUs are mapped onto the training range before the network.
#[derive(
    Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, serde::Serialize, serde::Deserialize,
)]
#[serde(rename_all = "snake_case")]
pub enum Setting {
    Unnormalized,
    Normalized,
}

impl Setting {
    pub const ALL: [Setting; 2] = [Setting::Unnormalized, Setting::Normalized];

    pub fn name(self) -> &'static str {
        match self {
            Setting::Unnormalized => "unnormalized",
            Setting::Normalized => "normalized",
        }
    }

    pub fn parse(s: &str) -> Option<Setting> {
        Setting::ALL.into_iter().find(|k| k.name() == s)
    }
}

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

/// Solves a clip frame by frame (the first from rest, each next from the previous frame's
/// equilibrium), calling `each` with every frame's state.
pub fn solve_clip(
    model: &FaceModel,
    frames: &[Activations],
    first: impl Fn(&Activations, &mut Workspace) -> Result<State>,
    ws: &mut Workspace,
    params: &SolveParams,
    mut each: impl FnMut(usize, &State) -> Result<()>,
) -> Result<()> {
    let mut state: Option<State> = None;
    for (f, a) in frames.iter().enumerate() {
        match state.as_mut() {
            None => state = Some(first(a, ws).with_context(|| format!("frame {f}"))?),
            Some(s) => {
                solve(model, a, s, ws, params).with_context(|| format!("frame {f}"))?;
            }
        }
        each(f, state.as_ref().expect("solved"))?;
    }
    Ok(())
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

fn pairs_of(rows: &[[f64; AU_COUNT]]) -> Pairs {
    Pairs {
        inputs: AU_COUNT,
        outputs: 0,
        x: rows.iter().flatten().map(|&v| v as f32).collect(),
        y: Vec::new(),
    }
}

/// Below this spread (range for min-max, SD for z-score; AU intensity on the 0-5 scale) an AU
/// carries no range to normalize: a single image, or an AU that barely moves in a clip.
pub const FLAT_SPREAD: f64 = 0.1;

/// The AUs whose spread across `input` is below [`FLAT_SPREAD`] (all of them for one row).
pub fn flat_aus(kind: Normalization, input: &[[f64; AU_COUNT]]) -> Vec<usize> {
    if kind == Normalization::None {
        return Vec::new();
    }
    (0..AU_COUNT)
        .filter(|&k| {
            let column: Vec<f64> = input.iter().map(|r| r[k]).collect();
            let (_, spread) = kind.offset_spread(&column);
            spread.is_nan() || spread < FLAT_SPREAD
        })
        .collect()
}

/// The per-AU affine map that takes `input`'s range (min-max) or mean and SD (z-score) onto
/// `target`'s: `x -> (x - offset) * scale`. The identity when the two agree, and for every
/// AU of [`flat_aus`]: a range that is not there cannot be stretched, so a single image or a
/// still AU keeps its own reading (on the observer's scale, which the training data share)
/// instead of landing on the training minimum, a neutral face.
pub fn range_map(
    kind: Normalization,
    input: &[[f64; AU_COUNT]],
    target: &Normalizer,
) -> Normalizer {
    let mut map = Normalizer::fit(kind, &pairs_of(input)).onto(target);
    for k in flat_aus(kind, input) {
        map.offset[k] = 0.0;
        map.scale[k] = 1.0;
    }
    map
}

/// The training data's per-AU statistics as a normalizer of `kind`.
pub fn training_range(kind: Normalization, training_aus: &[[f64; AU_COUNT]]) -> Normalizer {
    Normalizer::fit(kind, &pairs_of(training_aus))
}

/// Network outputs as activations the base model accepts: each clamped to [0, 1], jaw slide
/// and twist neutral.
pub fn to_activations(out: &[f32]) -> Activations {
    let mut values: [f64; CONTROL_COUNT] = std::array::from_fn(|k| (out[k] as f64).clamp(0.0, 1.0));
    values[JAW_SLIDE] = 0.5;
    values[JAW_TWIST] = 0.5;
    Activations::from_values(&values).expect("clamped")
}

/// The unified network's activations for rows of reference AUs (after `map`, if any).
pub fn predict_activations(
    mlp: &Mlp,
    map: Option<&Normalizer>,
    rows: &[[f64; AU_COUNT]],
) -> Result<Vec<Activations>> {
    let inputs: Vec<f32> = rows.iter().flatten().map(|&v| v as f32).collect();
    let inputs = match map {
        Some(m) => m.apply(&inputs),
        None => inputs,
    };
    if inputs.iter().any(|v| !v.is_finite()) {
        bail!("reference AUs contain NaN or infinite values");
    }
    let out = mlp
        .predict(&inputs)
        .context("running the unified network")?;
    Ok(out
        .chunks_exact(CONTROL_COUNT)
        .map(to_activations)
        .collect())
}

/// One transferred frame.
#[derive(Clone, Debug, PartialEq)]
pub struct Transferred {
    pub activations: [f64; CONTROL_COUNT],
    pub aus: [f64; AU_COUNT],
}

/// Transfers clips of input AUs (each a sequence of frames) onto the base model: the network
/// (after `map`, if any), then a solve per frame (the first from the basis prediction or rest,
/// each next warm from the previous one), then the observer. Clips run in parallel; frames in
/// order. Calls `tick` per clip.
#[allow(clippy::too_many_arguments)]
pub fn transfer(
    model: &FaceModel,
    basis: Option<&LinearBasis>,
    reader: &FaceReader,
    observer: &Observer,
    mlp: &Mlp,
    map: Option<&Normalizer>,
    clips: &[Vec<[f64; AU_COUNT]>],
    params: &SolveParams,
    tick: &(dyn Fn() + Sync),
) -> Result<Vec<Vec<Transferred>>> {
    let rows: Vec<[f64; AU_COUNT]> = clips.iter().flatten().copied().collect();
    let mut acts = predict_activations(mlp, map, &rows)?.into_iter();
    let jobs: Vec<Vec<Activations>> = clips
        .iter()
        .map(|c| acts.by_ref().take(c.len()).collect())
        .collect();
    jobs.par_iter()
        .enumerate()
        .map_init(
            || Workspace::new(model),
            |ws, (ci, acts)| -> Result<Vec<Transferred>> {
                let ws = ws.as_mut().map_err(|e| e.clone())?;
                let mut frames = Vec::with_capacity(acts.len());
                solve_clip(
                    model,
                    acts,
                    |a, ws| {
                        Ok(match basis {
                            Some(b) => solve_predicted(model, b, a, ws, params)?.0,
                            None => solve_from_rest(model, a, ws, params)?.0,
                        })
                    },
                    ws,
                    params,
                    |_, state| {
                        let o = observer.observe(&reader.read(model, state, None)?)?;
                        frames.push(Transferred {
                            activations: *state.activations.values(),
                            aus: o.aus,
                        });
                        Ok(())
                    },
                )
                .with_context(|| format!("transferring clip {ci}"))?;
                tick();
                Ok(frames)
            },
        )
        .collect()
}

/// Per-AU MSE of (reference - transferred) / 5 over all frames.
pub fn au_mse(reference: &[[f64; AU_COUNT]], transferred: &[[f64; AU_COUNT]]) -> [f64; AU_COUNT] {
    std::array::from_fn(|k| {
        let d: Vec<f64> = reference
            .iter()
            .zip(transferred)
            .map(|(r, t)| (r[k] - t[k]) / AU_MAX)
            .collect();
        crate::stats::mean_square(&d)
    })
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn range_map_is_the_identity_when_ranges_match() {
        let a: Vec<[f64; AU_COUNT]> = (0..5)
            .map(|i| std::array::from_fn(|k| (i * (k + 1)) as f64 * 0.1))
            .collect();
        // Same ranges, different samples inside them.
        let mut b = a.clone();
        b.swap(1, 3);
        b[2] = std::array::from_fn(|k| a[2][k] * 0.5 + a[3][k] * 0.5);
        for kind in [Normalization::MinMax] {
            let m = range_map(kind, &b, &training_range(kind, &a));
            for (o, s) in m.offset.iter().zip(&m.scale) {
                assert!(o.abs() < 1e-6, "offset {o}");
                assert!((s - 1.0).abs() < 1e-6, "scale {s}");
            }
        }
        let z = range_map(
            Normalization::ZScore,
            &a,
            &training_range(Normalization::ZScore, &a),
        );
        let x: Vec<f32> = a.iter().flatten().map(|&v| v as f32).collect();
        for (u, v) in z.apply(&x).iter().zip(&x) {
            assert!((u - v).abs() < 1e-5);
        }
    }

    #[test]
    fn range_map_takes_one_range_onto_another() {
        let input: Vec<[f64; AU_COUNT]> = vec![[1.0; AU_COUNT], [2.0; AU_COUNT]];
        let target: Vec<[f64; AU_COUNT]> = vec![[0.0; AU_COUNT], [4.0; AU_COUNT]];
        let m = range_map(
            Normalization::MinMax,
            &input,
            &training_range(Normalization::MinMax, &target),
        );
        let y = m.apply(&[1.5; AU_COUNT]);
        assert!(y.iter().all(|v| (v - 2.0).abs() < 1e-6), "{y:?}");
    }

    #[test]
    fn a_single_row_or_a_still_au_keeps_its_reading() {
        let target = training_range(Normalization::MinMax, &[[0.0; AU_COUNT], [4.0; AU_COUNT]]);
        let mut smile = [0.0; AU_COUNT];
        smile[8] = 3.0;
        for kind in [Normalization::MinMax, Normalization::ZScore] {
            assert_eq!(flat_aus(kind, &[smile]).len(), AU_COUNT);
            let m = range_map(kind, &[smile], &target);
            let x: Vec<f32> = smile.iter().map(|&v| v as f32).collect();
            assert_eq!(m.apply(&x), x, "{kind:?}");
        }
        // In a clip, only the AU that does not move passes through.
        let mut faint = smile;
        faint[8] = 1.0;
        let clip = vec![smile, faint];
        let flat = flat_aus(Normalization::MinMax, &clip);
        assert_eq!(flat.len(), AU_COUNT - 1);
        assert!(!flat.contains(&8));
        assert!(flat_aus(Normalization::None, &[smile]).is_empty());
    }

    #[test]
    fn mse_is_on_the_unit_scale() {
        let r = vec![[5.0; AU_COUNT], [0.0; AU_COUNT]];
        let t = vec![[0.0; AU_COUNT], [0.0; AU_COUNT]];
        assert!(au_mse(&r, &t).iter().all(|&m| m == 0.5));
    }
}
