//! Pose sequences and the closed-loop simulation of the neck under a voluntary controller.

use super::*;
use crate::sim::geom::V3;

/// Target head poses at a frame rate (e.g. an OpenFace sequence); the last frame holds.
#[derive(Clone, Debug, PartialEq)]
pub struct PoseSequence {
    pub fps: f64,
    pub poses: Vec<HeadPose>,
}

impl PoseSequence {
    /// One pose held.
    pub fn hold(pose: HeadPose) -> PoseSequence {
        PoseSequence {
            fps: 1.0,
            poses: vec![pose],
        }
    }

    pub fn at(&self, time: f64) -> HeadPose {
        let k = (time * self.fps + 1e-9).floor().max(0.0) as usize;
        self.poses[k.min(self.poses.len() - 1)]
    }

    /// The sequence with every pose inside the neck's commanded range, and for each clamped
    /// frame (0-based) what was clamped; a NaN pose is an error naming its frame.
    pub fn checked(&self, neck: &Neck) -> Result<(PoseSequence, Vec<(usize, String)>), NeckError> {
        let mut warnings = Vec::new();
        let mut poses = Vec::with_capacity(self.poses.len());
        for (frame, p) in self.poses.iter().enumerate() {
            let names = ["pitch", "yaw", "roll"];
            if let Some(k) = (0..3).find(|&k| !p.to_array()[k].is_finite()) {
                return Err(NeckError::NotANumber {
                    frame,
                    what: names[k].into(),
                });
            }
            let (clamped, warning) = neck.clamp_target(*p);
            if let Some(w) = warning {
                warnings.push((frame, w));
            }
            poses.push(clamped);
        }
        Ok((
            PoseSequence {
                fps: self.fps,
                poses,
            },
            warnings,
        ))
    }
}

/// A simulated run: the head pose sampled every `every` steps.
#[derive(Clone, Debug, PartialEq)]
pub struct Trajectory {
    pub time: Vec<f64>,
    pub target: Vec<HeadPose>,
    pub pose: Vec<HeadPose>,
    /// Mean applied activation over the muscles at each sample.
    pub effort: Vec<f64>,
    /// The skull joint's displacement from its rest position at each sample (m).
    pub skull_offset: Vec<V3>,
    /// One per clamped target frame.
    pub warnings: Vec<String>,
    pub final_state: BodyState,
}

/// Simulates `duration` seconds from `start` toward `targets` (checked and clamped first),
/// the voluntary controller called every `1 / voluntary_rate` s, the reflex every step;
/// samples every `every` steps.
pub fn simulate(
    neck: &Neck,
    controller: &mut dyn Voluntary,
    targets: &PoseSequence,
    start: BodyState,
    duration: f64,
    every: usize,
) -> Result<Trajectory, NeckError> {
    let (targets, clamped) = targets.checked(neck)?;
    let warnings = clamped
        .into_iter()
        .map(|(frame, w)| format!("frame {frame}: {w}"))
        .collect();
    let h = neck.time_step();
    let steps = (duration / h).round() as usize;
    let per_command = neck.steps_per_command();
    let mut s = start;
    let mut out = Trajectory {
        time: Vec::new(),
        target: Vec::new(),
        pose: Vec::new(),
        effort: Vec::new(),
        skull_offset: Vec::new(),
        warnings,
        final_state: BodyState::rest(),
    };
    let rest = neck.skeleton.frames(&BodyState::rest()).origin[SKULL];
    let mut command = Command::passive();
    for n in 0..steps {
        let t = n as f64 * h;
        if n % per_command == 0 {
            let seen = neck.observe(&s);
            command = controller.command(neck, &seen, targets.at(t))?;
        }
        let report = neck.step(&mut s, &command, true, t)?;
        if (n + 1) % every == 0 {
            let f = neck.skeleton.frames(&s);
            let seen = neck.observation(&f);
            out.skull_offset
                .push(std::array::from_fn(|k| f.origin[SKULL][k] - rest[k]));
            out.time.push(t + h);
            out.target.push(targets.at(t + h));
            out.pose.push(seen.pose);
            out.effort
                .push(report.activation.iter().sum::<f64>() / MUSCLES as f64);
        }
    }
    out.final_state = s;
    Ok(out)
}
