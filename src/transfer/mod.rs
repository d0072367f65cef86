//! `facelab transfer`: real OpenFace AUs -> [normalize] -> a run's unified network ->
//! activations -> the base model -> our observer -> transferred AUs, frame by frame.
//!
//! The run folder (`results/<experiment>/run-NNNN`, default `results/paper/latest`) gives the
//! network (`unified.safetensors`, the first seed's), the training data's per-AU statistics
//! (`training_aus.csv`, what "normalized" maps onto) and the resolved spec (`spec.toml`: face
//! subdivisions and solver tolerance). Only the `AUxx_r` columns of the input are used.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use image::RgbImage;

pub mod fidelity;
mod fit;
pub mod inverter;
mod method;
mod neck;
pub mod network;
mod outputs;
pub mod pictures;

pub(crate) use fit::au_space_fit;
pub use fit::Fitted;
use fit::{aus_by_frame, landmark_fit, openface_fit};
pub use method::TransferMethod;

pub(crate) use neck::follow;
use neck::{drive_neck, neck_weights, no_neck_controller};

use crate::headneck::{face_motion, posed_face};
use crate::io::openface::{read_openface, OpenFaceFile};
use crate::landmark::Blendshapes;
use crate::learn::{Mlp, Normalization, Normalizer};
use crate::observe::{landmarks, model_observer, AU_COUNT, AU_NAMES};
use crate::report::compose::side_by_side;
use crate::report::render::{render, Camera, RenderOptions};
use crate::sim::{solve, solve_from_rest, Activations, SolveParams, Workspace};
use fidelity::{Fidelity, JudgeFrames};
use network::predict_activations;

#[derive(Clone, Debug)]
pub struct TransferOptions {
    /// A run folder with `unified.safetensors`, `training_aus.csv` and `spec.toml`.
    pub model: PathBuf,
    pub normalize: Normalization,
    pub out: PathBuf,
    /// Frames (the file's `frame` numbers) to render; empty: first, middle and last.
    pub render_frames: Vec<i64>,
    /// Keep the head still although the file has pose.
    pub ignore_pose: bool,
    /// A run folder with `voluntary.safetensors` and `spec.toml` (whose `[headpose]` gives the
    /// neck the controller was trained on); `None`: `model`.
    pub neck: Option<PathBuf>,
    /// The input's pictures (photos or video frames with their landmarks drawn), indexed by
    /// the file's `frame` - 1: renders and the GIF then show each beside the model's face.
    pub pictures: Option<Vec<RgbImage>>,
    /// MediaPipe's blendshapes of the input pictures, indexed like `pictures`.
    pub input_blendshapes: Option<Vec<Option<Blendshapes>>>,
    /// Read the transferred face with MediaPipe's blendshapes (`fidelity.csv`, `fidelity.md`).
    pub judge: bool,
    /// Activations per input frame (indexed like `pictures`) found without the network (the
    /// landmark-space fit), each with its face already solved; `None`: the network's, from
    /// the AUs.
    pub fitted: Option<Vec<Option<Fitted>>>,
    /// Where the checkout's files are (the runs' specs name data files relative to it).
    pub layout: crate::io::Layout,
}

#[derive(Clone, Debug, PartialEq)]
pub struct TransferSummary {
    pub rows: usize,
    pub skipped: usize,
    /// Frames whose face did not converge from the previous frame nor from rest: written
    /// with `success = 0` and left out of the scores, each with the solver's reason.
    pub unsolved: Vec<String>,
    pub mse: [f64; AU_COUNT],
    /// RMS and largest angle (degrees) between the file's head pose and the neck's, when the
    /// pose drove the neck.
    pub pose_error: Option<(f64, f64)>,
    /// The AUs normalization passed through on their own reading: their spread across the
    /// file is below `table2::FLAT_SPREAD` (every AU of a single image).
    pub flat: Vec<usize>,
    /// The judge's verdict per reading (with an input picture), or its reading of the
    /// output alone (an OpenFace file).
    pub fidelity: Option<Fidelity>,
    pub written: Vec<PathBuf>,
}

impl TransferSummary {
    pub fn mean(&self) -> f64 {
        self.mse.iter().sum::<f64>() / AU_COUNT as f64
    }
}

/// The training data's per-AU statistics as the normalizer `Normalizer::fit` would give.
fn training_normalizer(path: &Path, kind: Normalization) -> Result<Normalizer> {
    let text = std::fs::read_to_string(path).with_context(|| {
        format!(
            "{}: cannot read (a run of a spec with Table 1 writes it)",
            path.display()
        )
    })?;
    let mut offset = vec![0.0f32; AU_COUNT];
    let mut scale = vec![1.0f32; AU_COUNT];
    let mut seen = [false; AU_COUNT];
    for (i, line) in text.lines().enumerate().skip(1) {
        let cells: Vec<&str> = line.split(',').collect();
        let at = |k: usize| -> Result<f64> {
            cells
                .get(k)
                .with_context(|| format!("{}:{}: too few cells", path.display(), i + 1))?
                .parse()
                .with_context(|| format!("{}:{}: not a number", path.display(), i + 1))
        };
        let k = AU_NAMES
            .iter()
            .position(|a| *a == cells[0])
            .with_context(|| format!("{}:{}: unknown AU `{}`", path.display(), i + 1, cells[0]))?;
        let (lo, hi, mean, sd) = (at(1)?, at(2)?, at(3)?, at(4)?);
        seen[k] = true;
        (offset[k], scale[k]) = match kind {
            Normalization::None => (0.0, 1.0),
            Normalization::MinMax => (
                lo as f32,
                if hi - lo > 1e-12 {
                    (1.0 / (hi - lo)) as f32
                } else {
                    1.0
                },
            ),
            Normalization::ZScore => (
                mean as f32,
                if sd > 1e-12 { (1.0 / sd) as f32 } else { 1.0 },
            ),
        };
    }
    if let Some(k) = seen.iter().position(|s| !s) {
        bail!("{}: no row for {}", path.display(), AU_NAMES[k]);
    }
    Ok(Normalizer { offset, scale })
}

/// The spec a run folder was made with (its `spec.toml`).
fn run_spec(layout: &crate::io::Layout, run: &Path) -> Result<crate::spec::Spec> {
    let path = run.join("spec.toml");
    Ok(crate::spec::load(layout, &path, &[])
        .with_context(|| format!("{}: the run's spec", path.display()))?
        .remove(0)
        .spec)
}

/// The run's unified network (`unified.safetensors`), checked to be the 17 -> 56 one.
fn unified_network(run: &Path) -> Result<Mlp> {
    let weights = run.join("unified.safetensors");
    let bytes = std::fs::read(&weights).with_context(|| {
        format!(
            "{}: cannot read the unified network (run a spec with Table 1 first, e.g. \
             `facelab run experiments/paper.toml`)",
            weights.display()
        )
    })?;
    let mlp = Mlp::from_safetensors(&bytes).with_context(|| format!("{}", weights.display()))?;
    if mlp.inputs != AU_COUNT || mlp.outputs != crate::sim::CONTROL_COUNT {
        bail!(
            "{}: a {} -> {} network, not the unified 17 -> 56",
            weights.display(),
            mlp.inputs,
            mlp.outputs
        );
    }
    Ok(mlp)
}

/// Transfers a file's frames (an OpenFace file's rows, or a picture's from the landmarker:
/// `OpenFaceFile::from_rows`) and writes `transferred.csv`, `activations.csv`, `mse.csv`,
/// renders of the chosen frames and, for more than one frame, `transfer.gif`. The network is
/// read only where the activations are not `opts.fitted`.
pub fn transfer_frames(file: &OpenFaceFile, opts: &TransferOptions) -> Result<TransferSummary> {
    let run = &opts.model;
    let spec = run_spec(&opts.layout, run)?;
    let name = file.path.display();
    if file.rows.is_empty() {
        bail!("{name}: no row with success = 1 ({} skipped)", file.skipped);
    }
    let reference: Vec<[f64; AU_COUNT]> = file.rows.iter().map(|r| r.aus).collect();
    let flat = network::flat_aus(opts.normalize, &reference);
    let map = match opts.normalize {
        Normalization::None => None,
        kind => {
            let target = training_normalizer(&run.join("training_aus.csv"), kind)?;
            Some(network::range_map(kind, &reference, &target))
        }
    };
    let (acts, mut presolved) = frame_activations(file, opts, map.as_ref(), &reference)?;

    let source = spec.face_source();
    let model = source.model()?;
    let observer = model_observer(&model, crate::run::cell::spec_calibration(&spec)?)?;
    let params = SolveParams {
        tolerance: spec.dataset.tolerance,
        ..SolveParams::default()
    };
    let n = file.rows.len();
    let wanted = frames_to_render(file, opts)?;
    let dt = match (file.rows[0].timestamp, file.rows[n - 1].timestamp) {
        (Some(a), Some(b)) if b > a && n > 1 => (b - a) / (n - 1) as f64,
        _ => 1.0 / 30.0,
    };
    let head = if !opts.ignore_pose && file.rows.iter().all(|r| r.pose.is_some()) {
        Some(drive_neck(opts, &spec, file, dt)?)
    } else {
        None
    };
    let gif_every = n.div_ceil(300).max(1);
    // A moving head needs the wider frame.
    let camera = match head {
        Some(_) => Camera::head_motion(),
        None => Camera::frontal(),
    };
    let still = RenderOptions {
        camera,
        ..RenderOptions::default()
    };
    let cell = RenderOptions {
        width: 240,
        height: 280,
        camera,
        ..RenderOptions::default()
    };
    let mut judged = opts.judge.then(|| JudgeFrames::new(n, still)).transpose()?;
    // What a solved frame gives: its AUs as the observer reads them, the judge's readings, a
    // still and a GIF frame where asked. A function of the frame's face alone, so the frames
    // of a block are made side by side (rayon) and kept in order.
    let made = |i: usize, state: &crate::sim::State| -> Result<Made> {
        let aus = observer
            .observe(&landmarks(state.surface(model.vertex_count())))?
            .aus;
        let frame = file.rows[i].frame;
        let posed;
        let state = match &head {
            Some(h) => {
                let motion = face_motion(h.pose[i], h.offset[i]);
                posed = posed_face(state, &motion);
                &posed
            }
            None => state,
        };
        let picture = opts
            .pictures
            .as_ref()
            .and_then(|p| p.get(usize::try_from(frame - 1).ok()?));
        let beside = |face: RgbImage| match picture {
            Some(p) => side_by_side(p, &face),
            None => face,
        };
        let reading = match &judged {
            Some(j) => Some(j.reading(&model, state, i)?),
            None => None,
        };
        let still = wanted
            .contains(&frame)
            .then(|| (frame, beside(render(&model, state, &still))));
        let gif = (n > 1 && i % gif_every == 0).then(|| beside(render(&model, state, &cell)));
        Ok(Made {
            aus,
            reading,
            still,
            gif,
        })
    };
    let mut transferred = Vec::with_capacity(n);
    let mut stills: Vec<(i64, RgbImage)> = Vec::new();
    let mut frames: Vec<RgbImage> = Vec::new();
    let mut solved = vec![true; n];
    let mut readings = Vec::new();
    // The solved frames not yet made, at most a block of them.
    let mut pending: Vec<(usize, Option<crate::sim::State>)> = Vec::new();
    let mut flush = |pending: &mut Vec<(usize, Option<crate::sim::State>)>| -> Result<()> {
        use rayon::prelude::*;
        let block: Vec<Option<Made>> = pending
            .par_iter()
            .map(|(i, state)| state.as_ref().map(|s| made(*i, s)).transpose())
            .collect::<Result<_>>()?;
        for ((i, _), frame) in pending.drain(..).zip(block) {
            let Some(frame) = frame else {
                solved[i] = false;
                transferred.push([0.0; AU_COUNT]);
                continue;
            };
            transferred.push(frame.aus);
            readings.extend(frame.reading.map(|r| (i, r)));
            stills.extend(frame.still);
            frames.extend(frame.gif);
        }
        Ok(())
    };
    let mut ws = Workspace::new(&model)?;
    let failures = solve_clip_tolerant(
        &acts,
        |i, a, previous: Option<&crate::sim::State>, ws| match previous {
            _ if presolved[i].is_some() => Ok(presolved[i].take().expect("checked")),
            Some(p) => {
                let mut s = p.clone();
                solve(&model, a, &mut s, ws, &params)?;
                Ok(s)
            }
            None => Ok(solve_from_rest(&model, a, ws, &params)?.0),
        },
        &mut ws,
        |i, state| {
            pending.push((i, state.cloned()));
            if pending.len() == MADE_BLOCK {
                flush(&mut pending)?;
            }
            Ok(())
        },
    )
    .with_context(|| format!("{name}: transferring"))?;
    flush(&mut pending).with_context(|| format!("{name}: transferring"))?;
    if let Some(j) = judged.as_mut() {
        for (i, reading) in readings {
            j.store(i, reading);
        }
    }
    let unsolved: Vec<String> = failures
        .iter()
        .map(|(i, why)| format!("frame {}: {why}", file.rows[*i].frame))
        .collect();
    if unsolved.len() == n {
        bail!(
            "{name}: the face converged in none of the {n} frames (first: {})",
            unsolved[0]
        );
    }

    let outputs = outputs::write(outputs::Made {
        file,
        opts,
        reference: &reference,
        acts: &acts,
        transferred: &transferred,
        solved: &solved,
        head: head.as_ref(),
        dt,
        gif_every,
        frames: &frames,
        stills: &stills,
        judged,
    })?;
    Ok(TransferSummary {
        rows: n,
        skipped: file.skipped,
        unsolved,
        mse: outputs.mse,
        pose_error: outputs.pose_error,
        flat,
        fidelity: outputs.fidelity,
        written: outputs.written,
    })
}

/// Solved frames made into AUs, readings and pictures at a time (side by side): enough to
/// keep both cores busy, few enough faces held at once for a long file.
const MADE_BLOCK: usize = 64;

/// What one solved frame of a transfer gives (`transfer_frames`).
struct Made {
    aus: [f64; AU_COUNT],
    reading: Option<fidelity::FrameReading>,
    still: Option<(i64, RgbImage)>,
    gif: Option<RgbImage>,
}

/// Each frame's activations and, where a fit already solved it, its face: `opts.fitted`'s,
/// or the run's unified network's on the frames' AUs (after `map`).
fn frame_activations(
    file: &OpenFaceFile,
    opts: &TransferOptions,
    map: Option<&Normalizer>,
    reference: &[[f64; AU_COUNT]],
) -> Result<(Vec<Activations>, Vec<Option<crate::sim::State>>)> {
    Ok(match &opts.fitted {
        Some(fitted) => {
            let rows = file
                .rows
                .iter()
                .map(|r| {
                    usize::try_from(r.frame - 1)
                        .ok()
                        .and_then(|k| fitted.get(k).cloned().flatten())
                        .with_context(|| format!("frame {}: no fitted activations", r.frame))
                })
                .collect::<Result<Vec<_>>>()?;
            rows.into_iter().map(|f| (f.activations, f.state)).unzip()
        }
        None => {
            let acts = predict_activations(&unified_network(&opts.model)?, map, reference)?;
            let none = vec![None; acts.len()];
            (acts, none)
        }
    })
}

/// The frames to render: `opts.render_frames`, each checked to be a used row, or the first,
/// middle and last.
fn frames_to_render(file: &OpenFaceFile, opts: &TransferOptions) -> Result<Vec<i64>> {
    let (n, name) = (file.rows.len(), file.path.display());
    let wanted: Vec<i64> = if opts.render_frames.is_empty() {
        let mut v = vec![
            file.rows[0].frame,
            file.rows[n / 2].frame,
            file.rows[n - 1].frame,
        ];
        v.dedup();
        v
    } else {
        opts.render_frames.clone()
    };
    for f in &wanted {
        if !file.rows.iter().any(|r| r.frame == *f) {
            bail!("{name}: no used row with frame {f} to render");
        }
    }
    Ok(wanted)
}

/// Solves a clip frame by frame, each from the previous solved frame
/// (`solve(i, a, Some(prev))`) and, where that fails, again from rest (`solve(i, a, None)`,
/// the continuation from neutral);
/// a frame that fails both is handed to `each` as `None` and the next frame starts from the
/// last solved one. Returns the failed frames with the solver's reason, so that one hard
/// frame does not sink a file.
pub fn solve_clip_tolerant<S: Clone>(
    frames: &[Activations],
    mut solve: impl FnMut(usize, &Activations, Option<&S>, &mut Workspace) -> Result<S>,
    ws: &mut Workspace,
    mut each: impl FnMut(usize, Option<&S>) -> Result<()>,
) -> Result<Vec<(usize, String)>> {
    let mut last: Option<S> = None;
    let mut failures = Vec::new();
    for (i, a) in frames.iter().enumerate() {
        let warm = last.as_ref().map(|p| solve(i, a, Some(p), ws));
        let result = match warm {
            Some(Ok(s)) => Ok(s),
            Some(Err(first)) => {
                solve(i, a, None, ws).map_err(|e| format!("{first:#}; from rest: {e:#}"))
            }
            None => solve(i, a, None, ws).map_err(|e| format!("{e:#}")),
        };
        match result {
            Ok(s) => {
                each(i, Some(&s))?;
                last = Some(s);
            }
            Err(why) => {
                each(i, None)?;
                failures.push((i, why));
            }
        }
    }
    Ok(failures)
}

/// `facelab transfer PATH`: an OpenFace CSV's rows go straight to [`transfer_frames`]
/// (normalization `normalize`, default min-max); a photo, folder, GIF or video first goes
/// through the built-in landmarker ([`pictures::landmark_files`]), whose frames carry AUs read
/// by the run's own observer (its spec's calibration), so they are on the training data's
/// scale and need no normalization (default `none`); its `openface.csv` and pictures are
/// written beside the outputs once the transfer succeeds. Returns the landmarker's summary
/// for image inputs.
pub fn transfer_path(
    input: &Path,
    opts: &TransferOptions,
    normalize: Option<Normalization>,
    neutral: Option<pictures::PhotoNeutral>,
    method: Option<TransferMethod>,
) -> Result<(TransferSummary, Option<pictures::LandmarkOutput>)> {
    use pictures::{input_kind, landmark_files, write_files, InputKind};
    let fits = method.is_none_or(|m| m != TransferMethod::Network);
    if fits && normalize.is_some_and(|n| n != Normalization::None) {
        bail!(
            "--normalize maps the AUs onto the network's training range: it needs --method \
             network (the fits, the default, match the AUs as they are)"
        );
    }
    if input_kind(input)? == InputKind::OpenFace {
        let file = read_openface(input)?;
        let fitted = match TransferMethod::for_input(input, method)? {
            TransferMethod::Network => None,
            TransferMethod::Landmarks => Some(openface_fit(&file, &opts.layout, &opts.model)?),
            TransferMethod::Aus => {
                let spec = run_spec(&opts.layout, &opts.model)?;
                let model = spec.face_source().model()?;
                let calibration = crate::run::cell::spec_calibration(&spec)?;
                Some(au_space_fit(
                    &spec,
                    &model,
                    &calibration,
                    &aus_by_frame(&file),
                )?)
            }
        };
        // The network reads a file's AUs min-max normalized unless told otherwise; the fits
        // match them as they are.
        let default = match fitted {
            None => Normalization::MinMax,
            Some(_) => Normalization::None,
        };
        let opts = TransferOptions {
            normalize: normalize.unwrap_or(default),
            fitted,
            ..opts.clone()
        };
        return Ok((transfer_frames(&file, &opts)?, None));
    }
    let spec = run_spec(&opts.layout, &opts.model)?;
    // Pictures always have a head pose: without a controller, say so before any work.
    if !opts.ignore_pose {
        let weights = neck_weights(opts);
        if !weights.is_file() {
            return Err(no_neck_controller(
                &weights,
                "a picture's head pose drives the neck",
            ));
        }
    }
    let model = spec.face_source().model()?;
    let calibration = crate::run::cell::spec_calibration(&spec)?;
    let mut landmarked = landmark_files(input, &opts.out, &model, calibration.clone(), neutral)?;
    let fitted = match TransferMethod::for_input(input, method)? {
        TransferMethod::Network => None,
        TransferMethod::Landmarks => Some(landmark_fit(
            &spec,
            &model,
            &calibration,
            &landmarked.displacements,
        )?),
        TransferMethod::Aus => Some(au_space_fit(
            &spec,
            &model,
            &calibration,
            &aus_by_frame(&landmarked.frames),
        )?),
    };
    let opts = TransferOptions {
        fitted,
        normalize: normalize.unwrap_or(Normalization::None),
        pictures: Some(landmarked.pictures.clone()),
        input_blendshapes: Some(landmarked.blendshapes.clone()),
        ..opts.clone()
    };
    let mut summary = transfer_frames(&landmarked.frames, &opts)?;
    landmarked.written = write_files(&opts.out, &landmarked.files)?;
    let mut written = landmarked.written.clone();
    written.append(&mut summary.written);
    summary.written = written;
    Ok((summary, Some(landmarked)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::face::FaceSource;

    /// A clip whose frame 1 fails from the previous frame but solves from rest, and whose
    /// frame 2 fails both ways: frame 2 alone is lost, named with both reasons, and frame 3
    /// starts from frame 1's state.
    #[test]
    fn a_frame_that_fails_twice_is_skipped_and_the_clip_goes_on() {
        let model = FaceSource::of(&crate::io::Layout::here()).model().unwrap();
        let mut ws = Workspace::new(&model).unwrap();
        let frames = vec![Activations::neutral(); 4];
        let mut starts = Vec::new();
        let mut seen = Vec::new();
        let failures = solve_clip_tolerant(
            &frames,
            |_, _, previous: Option<&usize>, _| {
                let i = starts.len();
                starts.push(previous.copied());
                // Calls: 0 rest; 1 warm (fails), 1 rest; 2 warm (fails), 2 rest (fails); 3 warm.
                match (i, previous) {
                    (1, Some(_)) => anyhow::bail!("no convergence from frame 0"),
                    (3, Some(_)) => anyhow::bail!("relative residual 8.8e-4 after 232 iterations"),
                    (4, None) => anyhow::bail!("no convergence from rest"),
                    _ => Ok(i),
                }
            },
            &mut ws,
            |i, s| {
                seen.push((i, s.copied()));
                Ok(())
            },
        )
        .unwrap();
        assert_eq!(
            seen,
            vec![(0, Some(0)), (1, Some(2)), (2, None), (3, Some(5))]
        );
        assert_eq!(starts, vec![None, Some(0), None, Some(2), None, Some(2)]);
        assert_eq!(failures.len(), 1);
        assert_eq!(failures[0].0, 2);
        assert!(
            failures[0].1.contains("232 iterations") && failures[0].1.contains("from rest"),
            "{}",
            failures[0].1
        );
    }
}
