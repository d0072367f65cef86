//! The outside judge: MediaPipe's blendshapes read a person's picture and the face facelab
//! made of it, so a transfer is measured by a reader facelab did not write (its own observer
//! reads both sides of a transfer and so cannot tell a missed expression from a kept one).
//!
//! A face is read two ways. `render`: the face is rendered and the rendered picture goes
//! through the landmarker and the blendshape head, as a camera would see it. `mesh`: the
//! face's own vertices are projected into that picture instead (the first 468 are Face Mesh's
//! points; the irises come from the eyeballs), so the reading does not depend on the
//! landmarker finding the rendered face. Scores are compared in groups: the left and right
//! scores of one movement averaged ([`GROUPS`]).

use anyhow::{Context, Result};

use crate::landmark::{
    blendshapes, Blendshapes, Landmarker, RgbFrame, MESH_POINTS, MESH_V2_POINTS,
};
use crate::report::head::iris_points;
use crate::report::render::{project, render, RenderOptions};
use crate::sim::geom::V3;
use crate::sim::{FaceModel, State};
use crate::stats::mean_or_zero;

/// The blendshape groups the judge compares: a name and the MediaPipe scores averaged.
pub const GROUPS: [(&str, &[&str]); 18] = [
    ("smile", &["mouthSmileLeft", "mouthSmileRight"]),
    ("frown", &["mouthFrownLeft", "mouthFrownRight"]),
    ("brow down", &["browDownLeft", "browDownRight"]),
    ("inner brow up", &["browInnerUp"]),
    ("outer brow up", &["browOuterUpLeft", "browOuterUpRight"]),
    ("eye blink", &["eyeBlinkLeft", "eyeBlinkRight"]),
    ("eye squint", &["eyeSquintLeft", "eyeSquintRight"]),
    ("eye wide", &["eyeWideLeft", "eyeWideRight"]),
    ("cheek squint", &["cheekSquintLeft", "cheekSquintRight"]),
    ("nose sneer", &["noseSneerLeft", "noseSneerRight"]),
    ("upper lip up", &["mouthUpperUpLeft", "mouthUpperUpRight"]),
    (
        "lower lip down",
        &["mouthLowerDownLeft", "mouthLowerDownRight"],
    ),
    ("jaw open", &["jawOpen"]),
    ("mouth press", &["mouthPressLeft", "mouthPressRight"]),
    ("mouth pucker", &["mouthPucker"]),
    ("mouth funnel", &["mouthFunnel"]),
    ("mouth stretch", &["mouthStretchLeft", "mouthStretchRight"]),
    ("mouth shrug", &["mouthShrugLower", "mouthShrugUpper"]),
];

/// Short column labels of the groups, in [`GROUPS`] order, for tables and heat maps.
pub const GROUP_LABELS: [&str; GROUPS.len()] = [
    "smile", "frown", "brDown", "inUp", "outUp", "blink", "squint", "wide", "cheek", "sneer",
    "ulUp", "llDown", "jaw", "press", "pucker", "funnel", "stretch", "shrug",
];

/// A group counts as shown at or above this score, and as absent below [`ABSENT`].
pub const SHOWN: f64 = 0.3;
pub const ABSENT: f64 = 0.1;

/// One face's group scores, in [`GROUPS`] order.
pub type Groups = [f64; GROUPS.len()];

/// The group scores of one face, in [`GROUPS`] order.
pub fn groups(scores: &Blendshapes) -> Groups {
    std::array::from_fn(|g| {
        let names = GROUPS[g].1;
        names
            .iter()
            .map(|n| scores[blendshapes::index(n).expect("a MediaPipe blendshape name")])
            .sum::<f64>()
            / names.len() as f64
    })
}

/// How a face was read.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Reading {
    Render,
    Mesh,
}

impl Reading {
    pub fn name(self) -> &'static str {
        match self {
            Reading::Render => "render",
            Reading::Mesh => "mesh",
        }
    }
}

/// The landmarker and blendshape head, ready to read pictures and faces.
pub struct Judge {
    landmarker: Landmarker,
}

impl Judge {
    pub fn new() -> Result<Judge> {
        Ok(Judge {
            landmarker: Landmarker::new().context("the landmarker's networks")?,
        })
    }

    /// Its landmarker (Face Mesh v2 and the blendshape head), for pictures read frame by
    /// frame.
    pub fn landmarker(&self) -> &Landmarker {
        &self.landmarker
    }

    /// The scores of the largest face in a picture, `None` where there is none.
    pub fn picture(&self, frame: &RgbFrame) -> Result<Option<Blendshapes>> {
        let faces = self.landmarker.faces(frame)?;
        match faces.first() {
            Some(face) => Ok(self.landmarker.blendshapes(&face.mesh)?),
            None => Ok(None),
        }
    }

    /// Reads `state` of `model` as it looks through `options`' camera.
    pub fn face(
        &self,
        model: &FaceModel,
        state: &State,
        options: &RenderOptions,
        reading: Reading,
    ) -> Result<Option<Blendshapes>> {
        match reading {
            Reading::Render => {
                let image = render(model, state, options);
                let (w, h) = (image.width() as usize, image.height() as usize);
                self.picture(&RgbFrame::new(w, h, image.into_raw()))
            }
            Reading::Mesh => {
                let points = mesh_points(model, state);
                let pixels = project(options, &points);
                Ok(Some(self.landmarker.blendshapes.scores(&pixels)?))
            }
        }
    }
}

/// Face Mesh v2's 478 points on the model: its first 468 surface vertices (the canonical
/// face's topology) and the irises.
pub fn mesh_points(model: &FaceModel, state: &State) -> Vec<V3> {
    let surface = state.surface(model.vertex_count());
    let mut points: Vec<V3> = surface[..MESH_POINTS].to_vec();
    points.extend(iris_points(model, state));
    debug_assert_eq!(points.len(), MESH_V2_POINTS);
    points
}

/// Pearson's r of two series; `None` when either is constant or shorter than 3. Unlike
/// `stats::pearson` it treats a variance below 1e-12 as none: a group read the same on every
/// frame can leave a rounding residue instead of zero, and its r would be noise.
pub fn pearson(a: &[f64], b: &[f64]) -> Option<f64> {
    let n = a.len().min(b.len());
    if n < 3 {
        return None;
    }
    let mean = |v: &[f64]| v[..n].iter().sum::<f64>() / n as f64;
    let (ma, mb) = (mean(a), mean(b));
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    for i in 0..n {
        let (x, y) = (a[i] - ma, b[i] - mb);
        sab += x * y;
        saa += x * x;
        sbb += y * y;
    }
    (saa > 1e-12 && sbb > 1e-12).then(|| sab / (saa * sbb).sqrt())
}

/// Per group over frames where both sides were read: the mean in and out, the mean absolute
/// difference and, for three frames or more, Pearson's r.
#[derive(Clone, Debug, PartialEq)]
pub struct GroupAgreement {
    pub group: &'static str,
    pub frames: usize,
    pub mean_in: f64,
    pub mean_out: f64,
    pub mean_abs_diff: f64,
    pub r: Option<f64>,
}

/// Compares the input's scores with the output's, frame by frame (`None` where a side has
/// no face).
pub fn agreement(
    input: &[Option<Blendshapes>],
    output: &[Option<Blendshapes>],
) -> Vec<GroupAgreement> {
    let group = |s: &Option<Blendshapes>| s.as_ref().map(groups);
    let input: Vec<Option<Groups>> = input.iter().map(group).collect();
    let output: Vec<Option<Groups>> = output.iter().map(group).collect();
    group_agreement(&input, &output)
}

/// [`agreement`] of faces already read as groups.
pub fn group_agreement(input: &[Option<Groups>], output: &[Option<Groups>]) -> Vec<GroupAgreement> {
    let pairs: Vec<(Groups, Groups)> = input
        .iter()
        .zip(output)
        .filter_map(|(a, b)| Some(((*a)?, (*b)?)))
        .collect();
    GROUPS
        .iter()
        .enumerate()
        .map(|(g, (name, _))| {
            let a: Vec<f64> = pairs.iter().map(|p| p.0[g]).collect();
            let b: Vec<f64> = pairs.iter().map(|p| p.1[g]).collect();
            let diff: Vec<f64> = a.iter().zip(&b).map(|(x, y)| (x - y).abs()).collect();
            GroupAgreement {
                group: name,
                frames: a.len(),
                mean_in: mean_or_zero(&a),
                mean_out: mean_or_zero(&b),
                mean_abs_diff: mean_or_zero(&diff),
                r: pearson(&a, &b),
            }
        })
        .collect()
}

/// The verdict on one comparison: of the groups the input shows (mean >= [`SHOWN`]), how
/// many the output keeps within 0.1, and how many groups the output shows that the input
/// does not (mean < [`ABSENT`]).
#[derive(Clone, Debug, PartialEq)]
pub struct Verdict {
    pub shown: usize,
    pub kept: usize,
    pub added: usize,
    /// Mean absolute difference over the shown groups.
    pub shown_diff: f64,
}

pub fn verdict(groups: &[GroupAgreement]) -> Verdict {
    let shown: Vec<&GroupAgreement> = groups.iter().filter(|g| g.mean_in >= SHOWN).collect();
    let kept = shown.iter().filter(|g| g.mean_abs_diff <= 0.1).count();
    let added = groups
        .iter()
        .filter(|g| g.mean_in < ABSENT && g.mean_out >= SHOWN)
        .count();
    let shown_diff = if shown.is_empty() {
        0.0
    } else {
        shown.iter().map(|g| g.mean_abs_diff).sum::<f64>() / shown.len() as f64
    };
    Verdict {
        shown: shown.len(),
        kept,
        added,
        shown_diff,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scores(pairs: &[(&str, f64)]) -> Blendshapes {
        let mut s = [0.0; 52];
        for (n, v) in pairs {
            s[blendshapes::index(n).unwrap()] = *v;
        }
        s
    }

    #[test]
    fn groups_average_left_and_right() {
        let g = groups(&scores(&[
            ("mouthSmileLeft", 0.8),
            ("mouthSmileRight", 0.6),
            ("jawOpen", 0.5),
        ]));
        assert!((g[0] - 0.7).abs() < 1e-12);
        assert_eq!(g[12], 0.5);
        for (name, members) in GROUPS {
            for m in members {
                assert!(blendshapes::index(m).is_some(), "{name}: {m}");
            }
        }
    }

    /// A smile that comes out as an open mouth: the smile is shown and lost, the jaw added.
    #[test]
    fn a_lost_smile_and_an_added_jaw_are_counted() {
        let input = vec![Some(scores(&[
            ("mouthSmileLeft", 0.8),
            ("mouthSmileRight", 0.8),
        ]))];
        let output = vec![Some(scores(&[("jawOpen", 0.6)]))];
        let a = agreement(&input, &output);
        let v = verdict(&a);
        assert_eq!((v.shown, v.kept, v.added), (1, 0, 1));
        assert!((v.shown_diff - 0.8).abs() < 1e-12);
        let same = verdict(&agreement(&input, &input));
        assert_eq!((same.shown, same.kept, same.added), (1, 1, 0));
        assert_eq!(a[0].r, None);
        assert!(agreement(&input, &[None]).iter().all(|g| g.frames == 0));
    }

    #[test]
    fn pearson_of_a_series_and_its_scaled_copy_is_one() {
        let a = [0.1, 0.4, 0.2, 0.9];
        let b: Vec<f64> = a.iter().map(|x| 2.0 * x + 1.0).collect();
        assert!((pearson(&a, &b).unwrap() - 1.0).abs() < 1e-12);
        assert_eq!(pearson(&a, &[1.0; 4]), None);
    }
}
