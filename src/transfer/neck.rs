//! The head in a transfer: the file's or picture's head pose through the neck under a run's
//! learned voluntary controller.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};

use super::{run_spec, TransferOptions};
use crate::headneck::Learned;
use crate::io::openface::OpenFaceFile;
use crate::learn::Mlp;
use crate::sim::neck::{simulate, BodyState, HeadPose, PoseSequence};

/// The neck's response to a file's head pose, per frame.
pub(super) struct HeadTrack {
    /// The file's pose (clamped into the neck's range).
    pub(super) target: Vec<HeadPose>,
    pub(super) pose: Vec<HeadPose>,
    pub(super) offset: Vec<crate::sim::geom::V3>,
}

/// Drives the neck with the file's rows' `pose_Rx, pose_Ry, pose_Rz` (frames `dt` apart)
/// under a run's learned voluntary controller (`voluntary.safetensors` of `opts.neck`, else
/// of the face's run, whose spec is `spec`) from the upright rest posture.
pub(super) fn drive_neck(
    opts: &TransferOptions,
    spec: &crate::spec::Spec,
    file: &OpenFaceFile,
    dt: f64,
) -> Result<HeadTrack> {
    let rows = &file.rows;
    let (weights, neck) = neck_run(opts, spec)?;
    let bytes = std::fs::read(&weights).map_err(|_| {
        no_neck_controller(
            &weights,
            "the input has head pose (pose_Rx, pose_Ry, pose_Rz)",
        )
    })?;
    let mlp = Mlp::from_safetensors(&bytes).with_context(|| format!("{}", weights.display()))?;
    let targets = PoseSequence {
        fps: 1.0 / dt,
        poses: rows
            .iter()
            .map(|r| {
                let p = r.pose.expect("checked by the caller");
                HeadPose {
                    pitch: p[3],
                    yaw: p[4],
                    roll: p[5],
                }
            })
            .collect(),
    };
    // The reader refuses NaN cells, naming the line; clamped frames are named as the file does.
    let (targets, clamped) = targets
        .checked(&neck)
        .with_context(|| format!("{}: head pose", file.path.display()))?;
    for (i, w) in clamped.iter().take(5) {
        eprintln!(
            "warning: {}: frame {}: {w}",
            file.path.display(),
            rows[*i].frame
        );
    }
    if clamped.len() > 5 {
        eprintln!(
            "warning: {}: {} more frames clamped",
            file.path.display(),
            clamped.len() - 5
        );
    }
    // Sampled at 400 Hz; each frame takes the nearest sample.
    let (pose, offset) = follow(&neck, &mlp, &targets, false)
        .with_context(|| format!("{}: driving the neck", file.path.display()))?;
    Ok(HeadTrack {
        target: targets.poses.clone(),
        pose,
        offset,
    })
}

/// The head under a learned voluntary controller following `targets` (frames `1 / fps`
/// apart): one pose is a still, held until the head settles ([`hold_still`]); more are a clip,
/// simulated from the upright rest posture or, with `settled_start`, from the posture that
/// holds the clip's first pose (a clip cut from a longer video). Returns each frame's pose
/// and skull offset, sampled at 400 Hz, each frame the nearest sample.
pub(crate) fn follow(
    neck: &crate::sim::neck::Neck,
    mlp: &Mlp,
    targets: &PoseSequence,
    settled_start: bool,
) -> Result<(Vec<HeadPose>, Vec<crate::sim::geom::V3>)> {
    let every = 10;
    let first = PoseSequence {
        fps: targets.fps,
        poses: targets.poses.iter().take(1).copied().collect(),
    };
    if targets.poses.len() == 1 {
        let (pose, offset, _) = hold_still(neck, mlp, &first, every)?;
        return Ok((vec![pose], vec![offset]));
    }
    let start = if settled_start {
        hold_still(neck, mlp, &first, every)?.2
    } else {
        BodyState::rest()
    };
    let dt = 1.0 / targets.fps;
    let frames = targets.poses.len();
    let run = simulate(
        neck,
        &mut Learned { mlp },
        targets,
        start,
        frames as f64 * dt,
        every,
    )?;
    let rate = neck.params.simulation_rate / every as f64;
    let pick = |i: usize| ((i as f64 * dt * rate).round() as usize).min(run.time.len() - 1);
    Ok((
        (0..frames).map(|i| run.pose[pick(i)]).collect(),
        (0..frames).map(|i| run.skull_offset[pick(i)]).collect(),
    ))
}

/// How long a still is held per step while the head settles, and when it has settled: the
/// head turns less than [`STILL_SETTLED_DEG`] over one step. At most [`STILL_MAX_STEPS`] steps.
const STILL_STEP_S: f64 = 0.5;
const STILL_SETTLED_DEG: f64 = 0.05;
const STILL_MAX_STEPS: usize = 12;

/// A photo's head pose: the neck holds the one target from the upright rest posture until the
/// head settles (a video frame lasts 1/30 s, far too short to reach a still's pose). Returns
/// the settled pose, skull offset and body state; an error if the head still moves after 6 s.
fn hold_still(
    neck: &crate::sim::neck::Neck,
    mlp: &Mlp,
    target: &PoseSequence,
    every: usize,
) -> Result<(HeadPose, crate::sim::geom::V3, BodyState)> {
    let mut state = BodyState::rest();
    let mut last: Option<HeadPose> = None;
    for _ in 0..STILL_MAX_STEPS {
        let run = simulate(
            neck,
            &mut Learned { mlp },
            target,
            state,
            STILL_STEP_S,
            every,
        )?;
        let (pose, offset) = (
            *run.pose.last().context("an empty neck run")?,
            *run.skull_offset.last().context("an empty neck run")?,
        );
        if last.is_some_and(|p| p.error_degrees(pose) < STILL_SETTLED_DEG) {
            return Ok((pose, offset, run.final_state));
        }
        last = Some(pose);
        state = run.final_state;
    }
    bail!(
        "the head did not settle on the still's pose: it still turns {STILL_SETTLED_DEG} deg or \
         more per {STILL_STEP_S} s after {} s",
        STILL_STEP_S * STILL_MAX_STEPS as f64
    )
}

/// The voluntary controller's weights: `opts.neck`'s run, else the face's.
pub(super) fn neck_weights(opts: &TransferOptions) -> PathBuf {
    opts.neck
        .as_ref()
        .unwrap_or(&opts.model)
        .join("voluntary.safetensors")
}

/// The voluntary controller's weights and the neck it was trained on: `opts.neck`'s run, else
/// the face's (whose spec is `spec`).
fn neck_run(
    opts: &TransferOptions,
    spec: &crate::spec::Spec,
) -> Result<(PathBuf, crate::sim::neck::Neck)> {
    let neck = match &opts.neck {
        Some(dir) => run_spec(&opts.layout, dir)?.headpose.neck(),
        None => spec.headpose.neck(),
    };
    Ok((neck_weights(opts), neck))
}

/// The error for a head pose to follow without a voluntary controller at `weights`; `why` says
/// where the pose comes from.
pub(super) fn no_neck_controller(weights: &Path, why: &str) -> anyhow::Error {
    anyhow::anyhow!(
        "{}: {why}, but the run has no voluntary neck controller (pass --neck with a run of a \
         spec whose tables list \"headpose\", e.g. results/headpose/latest, or pass \
         --ignore-pose)",
        weights.display()
    )
}
