//! The 17 OpenFace intensity AUs read off 3D landmarks, the way a FACS coder reads a face:
//! each AU is a geometric change from the subject's own neutral face, in the neutral face's
//! frame, divided by the inter-ocular distance (IOD, between the eye centres), times a gain
//! that maps it onto OpenFace's 0..5 scale, clamped to [0, 5].
//!
//! Before measuring, the current landmarks are aligned rigidly onto the neutral ones over
//! points that facial muscles barely move (see `STABLE`), so a head rotation changes the pose
//! but not the AUs.
//!
//! The measures (landmark numbers are 0-based iBUG; "rise" is +y, "out" is away from the
//! midline, "back" is -z; L/R averaged):
//!
//! | AU | measure |
//! |---|---|
//! | AU01 inner brow raiser | rise of the inner brow (20, 21, 22, 23) |
//! | AU02 outer brow raiser | rise of the outer brow (17, 18, 25, 26) |
//! | AU04 brow lowerer | fall of the brow (19-24) plus the narrowing of the gap 21-22 |
//! | AU05 upper lid raiser | rise of the upper lid (37, 38, 43, 44) |
//! | AU06 cheek raiser | rise of the lower lid (40, 41, 46, 47) plus half the fall of the outer brow (17, 18, 25, 26), which the orbital part pulls toward the eye |
//! | AU07 lid tightener | rise of the lower lid (40, 41, 46, 47) above its eye corners |
//! | AU09 nose wrinkler | rise of the nostril wings (31, 35) |
//! | AU10 upper lip raiser | rise of the upper lip (50, 51, 52) |
//! | AU12 lip corner puller | rise of the mouth corners (48, 54) plus half their outward pull |
//! | AU14 dimpler | backward pull of the mouth corners relative to the lips beside them (upper 49, 53 and lower 55, 59, averaged), but never more than the corners' own backward motion, less half their vertical motion: corners pulled down or up, or by the opening jaw, slide back over the curved face without a dimple, and lips pushed forward (mentalis, levator labii at full human range in disgust) leave corners that stay put without one |
//! | AU15 lip corner depressor | fall of the corners below the mid-line of the lips (62, 66) |
//! | AU17 chin raiser | lengthening of lower lip to chin (57-8): mentalis pushes the lower lip up off the chin |
//! | AU20 lip stretcher | outward pull of the corners beyond their rise |
//! | AU23 lip tightener | narrowing of the upper lip (49-53), which the jaw does not stretch; the model's sphincter bunches the red lips rather than thinning them |
//! | AU25 lips part | opening of the inner lips (62-66) |
//! | AU26 jaw drop | lengthening of nose tip to chin (30-8) |
//! | AU45 blink | closing of the eye aperture, as a fraction of the neutral aperture |
//!
//! Gains are data: `experiments/au_calibration.csv` (read by `io::calibration`) says for each
//! AU which activations it was calibrated on and what they should read; `facelab observe
//! --calibrate` recomputes the gains from the model.

use crate::rng::Stream;
use crate::sim::geom::{norm, sub, Rot3, V3};

use super::features::{features, inputs, FEATURE_COUNT, INPUT_COUNT};
use super::landmarks::LANDMARK_COUNT;
use super::pose::{align, HeadPose};

/// OpenFace's intensity AUs, in its column order.
pub const AU_NAMES: [&str; 17] = [
    "AU01", "AU02", "AU04", "AU05", "AU06", "AU07", "AU09", "AU10", "AU12", "AU14", "AU15", "AU17",
    "AU20", "AU23", "AU25", "AU26", "AU45",
];
pub const AU_COUNT: usize = AU_NAMES.len();

/// The index of an AU by name (`AU12`) or number (`12`).
pub fn au_index(name: &str) -> Option<usize> {
    let digits = name.trim().trim_start_matches("AU").trim_end_matches("_r");
    let n: u32 = digits.parse().ok()?;
    AU_NAMES
        .iter()
        .position(|a| a[2..].parse::<u32>().ok() == Some(n))
}

/// Landmarks that facial muscles move least: the face outline at the temples (0, 16) and the
/// eye corners (36, 39, 42, 45). On the model no control moves them at all; the nose bridge
/// (27-30), often used, rises up to 1.5 mm with orbicularis oculi and levator labii.
pub const STABLE: [usize; 6] = [0, 16, 36, 39, 42, 45];

/// Highest intensity on OpenFace's scale.
pub const AU_MAX: f64 = 5.0;

/// How the observer turns what it measures into intensities.
#[derive(Clone, Debug, PartialEq)]
pub enum Calibration {
    /// Per-AU gains anchored on the model: intensity = gain x the AU's own measure (IOD units,
    /// or a fraction for AU45), `experiments/au_calibration.csv`.
    Gains([f64; AU_COUNT]),
    /// A readout fitted to OpenFace's AUs on real faces (`facelab observe --fit`).
    Fitted(Box<FittedReadout>),
}

/// Intensity of AU k = `intercept[k] + weights[k] . inputs` (the positive and negative parts of
/// `features::features`), clamped to [0, 5]; weights are nonnegative.
#[derive(Clone, Debug, PartialEq)]
pub struct FittedReadout {
    pub intercept: [f64; AU_COUNT],
    pub weights: [[f64; INPUT_COUNT]; AU_COUNT],
}

impl FittedReadout {
    /// The clamped intensities for these inputs.
    pub fn read(&self, inputs: &[f64; INPUT_COUNT]) -> [f64; AU_COUNT] {
        std::array::from_fn(|k| {
            let v = self.intercept[k]
                + self.weights[k]
                    .iter()
                    .zip(inputs)
                    .map(|(w, x)| w * x)
                    .sum::<f64>();
            v.clamp(0.0, AU_MAX)
        })
    }
}

/// Detector error stand-in (DESIGN 2.2): each AU's gain is scaled by a per-subject factor
/// `1 + gain_spread * N(0, 1)` (kept positive) and Gaussian noise of `noise_sd` (AU units) is
/// added to every reading, before clamping. Off when both are 0.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct ObserverNoise {
    pub noise_sd: f64,
    pub gain_spread: f64,
}

impl ObserverNoise {
    pub fn is_off(&self) -> bool {
        self.noise_sd == 0.0 && self.gain_spread == 0.0
    }

    /// Per-AU gain factors for one subject.
    pub fn subject_gains(&self, rng: &mut Stream) -> [f64; AU_COUNT] {
        std::array::from_fn(|_| (1.0 + self.gain_spread * rng.normal()).max(0.05))
    }

    /// Applies the subject's gain factors and fresh reading noise to clean intensities.
    pub fn apply(&self, aus: &mut [f64; AU_COUNT], gains: &[f64; AU_COUNT], rng: &mut Stream) {
        for (a, g) in aus.iter_mut().zip(gains) {
            let noise = if self.noise_sd > 0.0 {
                self.noise_sd * rng.normal()
            } else {
                0.0
            };
            *a = (*a * g + noise).clamp(0.0, AU_MAX);
        }
    }
}

/// What the observer reads off one face.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Observation {
    /// Intensities on 0..5, in `AU_NAMES` order.
    pub aus: [f64; AU_COUNT],
    /// Head rotation relative to the neutral face.
    pub pose: HeadPose,
}

/// Mouth and eye indices used by several measures.
const CORNERS: [usize; 2] = [48, 54];
const RIGHT_EYE: [usize; 6] = [36, 37, 38, 39, 40, 41];
const LEFT_EYE: [usize; 6] = [42, 43, 44, 45, 46, 47];
/// Upper/lower lid pairs whose vertical gaps make the eye aperture.
const LID_PAIRS: [(usize, usize); 4] = [(37, 41), (38, 40), (43, 47), (44, 46)];

/// An observer for one subject: its neutral landmarks in their own face frame.
#[derive(Clone, Debug)]
pub struct Observer {
    calibration: Calibration,
    neutral: [V3; LANDMARK_COUNT],
    /// Neutral landmarks in the face frame, divided by the IOD.
    frame_neutral: [V3; LANDMARK_COUNT],
    /// Face frame: rows are the face's x (toward its left), y (up), z (out) axes.
    axes: Rot3,
    origin: V3,
    iod: f64,
    aperture: f64,
}

fn mean_of(p: &[V3; LANDMARK_COUNT], idx: &[usize]) -> V3 {
    let mut m = [0.0; 3];
    for &i in idx {
        for k in 0..3 {
            m[k] += p[i][k] / idx.len() as f64;
        }
    }
    m
}

/// Mean vertical gap of the lid pairs (in whatever units `p` has).
pub(crate) fn aperture(p: &[V3; LANDMARK_COUNT]) -> f64 {
    LID_PAIRS
        .iter()
        .map(|&(u, l)| p[u][1] - p[l][1])
        .sum::<f64>()
        / LID_PAIRS.len() as f64
}

#[derive(Debug, thiserror::Error, PartialEq)]
pub enum ObserveError {
    #[error("the neutral landmarks are degenerate (inter-ocular distance {0:e})")]
    Degenerate(f64),
    #[error("landmark {0} is not finite")]
    NonFinite(usize),
}

impl Observer {
    /// An observer for a subject with these neutral landmarks (any units, any head pose).
    pub fn new(
        neutral: &[V3; LANDMARK_COUNT],
        calibration: Calibration,
    ) -> Result<Observer, ObserveError> {
        if let Some(i) = neutral
            .iter()
            .position(|p| p.iter().any(|c| !c.is_finite()))
        {
            return Err(ObserveError::NonFinite(i));
        }
        let right = mean_of(neutral, &RIGHT_EYE);
        let left = mean_of(neutral, &LEFT_EYE);
        let iod = norm(sub(left, right));
        if iod.is_nan() || iod <= 1e-12 {
            return Err(ObserveError::Degenerate(iod));
        }
        // x from the right eye to the left; y from the chin toward the eyes, made orthogonal.
        let x = crate::sim::geom::normalize(sub(left, right));
        let eyes = crate::sim::geom::lerp(left, right, 0.5);
        let up = sub(eyes, neutral[8]);
        let y = crate::sim::geom::normalize(sub(up, crate::sim::geom::scale(x, dot3(up, x))));
        let z = crate::sim::geom::cross(x, y);
        let axes = Rot3([x, y, z]);
        let origin = mean_of(neutral, &STABLE);
        let mut observer = Observer {
            calibration,
            neutral: *neutral,
            frame_neutral: [[0.0; 3]; LANDMARK_COUNT],
            axes,
            origin,
            iod,
            aperture: 0.0,
        };
        observer.frame_neutral = observer.to_frame(neutral);
        observer.aperture = aperture(&observer.frame_neutral);
        Ok(observer)
    }

    pub fn calibration(&self) -> &Calibration {
        &self.calibration
    }

    /// The neutral face's inter-ocular distance (the units of the landmarks it was made
    /// from): the unit of `displacements`.
    pub fn iod(&self) -> f64 {
        self.iod
    }

    /// Landmarks already aligned with the neutral face, in face-frame IOD units.
    fn to_frame(&self, p: &[V3; LANDMARK_COUNT]) -> [V3; LANDMARK_COUNT] {
        std::array::from_fn(|i| {
            let q = self.axes.apply(sub(p[i], self.origin));
            [q[0] / self.iod, q[1] / self.iod, q[2] / self.iod]
        })
    }

    /// The raw geometric measures (before gains) and the head pose of `current`.
    pub fn measure(
        &self,
        current: &[V3; LANDMARK_COUNT],
    ) -> Result<([f64; AU_COUNT], HeadPose), ObserveError> {
        let (c, r) = self.aligned(current)?;
        // Head rotation relative to the neutral face, about the camera's (model's) axes.
        let pose = HeadPose::from_rotation(&r);
        Ok((measures(&self.frame_neutral, &c, self.aperture), pose))
    }

    /// `current` with the head motion undone, in the neutral face's frame (IOD units), and
    /// the head rotation.
    fn aligned(
        &self,
        current: &[V3; LANDMARK_COUNT],
    ) -> Result<([V3; LANDMARK_COUNT], Rot3), ObserveError> {
        if let Some(i) = current
            .iter()
            .position(|p| p.iter().any(|c| !c.is_finite()))
        {
            return Err(ObserveError::NonFinite(i));
        }
        let stable_now: Vec<V3> = STABLE.iter().map(|&i| current[i]).collect();
        let stable_neutral: Vec<V3> = STABLE.iter().map(|&i| self.neutral[i]).collect();
        // current ~ r neutral + t: undo it, then measure in the neutral frame.
        let (r, t) = align(&stable_neutral, &stable_now);
        let back: [V3; LANDMARK_COUNT] = std::array::from_fn(|i| {
            let d = sub(current[i], t);
            transpose_apply(&r, d)
        });
        Ok((self.to_frame(&back), r))
    }

    /// Landmark displacements from the neutral face with the head motion undone, in the
    /// neutral face's frame and IOD units: comparable across faces of different size (the
    /// marker displacements of Choe et al.'s eq. 10).
    pub fn displacements(
        &self,
        current: &[V3; LANDMARK_COUNT],
    ) -> Result<[V3; LANDMARK_COUNT], ObserveError> {
        let (c, _) = self.aligned(current)?;
        Ok(std::array::from_fn(|i| sub(c[i], self.frame_neutral[i])))
    }

    /// The features (`features::features`) of `current` and its head pose.
    pub fn features(
        &self,
        current: &[V3; LANDMARK_COUNT],
    ) -> Result<([f64; FEATURE_COUNT], HeadPose), ObserveError> {
        let (c, r) = self.aligned(current)?;
        Ok((
            features(&self.frame_neutral, &c, self.aperture),
            HeadPose::from_rotation(&r),
        ))
    }

    /// Intensities (0..5) and head pose of `current`.
    pub fn observe(&self, current: &[V3; LANDMARK_COUNT]) -> Result<Observation, ObserveError> {
        match &self.calibration {
            Calibration::Gains(gains) => {
                let (raw, pose) = self.measure(current)?;
                let aus = std::array::from_fn(|k| (gains[k] * raw[k].max(0.0)).clamp(0.0, AU_MAX));
                Ok(Observation { aus, pose })
            }
            Calibration::Fitted(readout) => {
                let (f, pose) = self.features(current)?;
                Ok(Observation {
                    aus: readout.read(&inputs(&f)),
                    pose,
                })
            }
        }
    }
}

fn dot3(a: V3, b: V3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn transpose_apply(r: &Rot3, v: V3) -> V3 {
    let m = r.0;
    std::array::from_fn(|j| m[0][j] * v[0] + m[1][j] * v[1] + m[2][j] * v[2])
}

/// The 17 measures from neutral `n` and current `c` landmarks (face frame, IOD units).
pub(crate) fn measures(
    n: &[V3; LANDMARK_COUNT],
    c: &[V3; LANDMARK_COUNT],
    neutral_aperture: f64,
) -> [f64; AU_COUNT] {
    let dy = |idx: &[usize]| idx.iter().map(|&i| c[i][1] - n[i][1]).sum::<f64>() / idx.len() as f64;
    // Outward motion: +x on the subject's left (x > 0), -x on the right.
    let out = |idx: &[usize]| {
        idx.iter()
            .map(|&i| (c[i][0] - n[i][0]) * n[i][0].signum())
            .sum::<f64>()
            / idx.len() as f64
    };
    let back =
        |idx: &[usize]| idx.iter().map(|&i| n[i][2] - c[i][2]).sum::<f64>() / idx.len() as f64;
    let dist = |p: &[V3; LANDMARK_COUNT], a: usize, b: usize| norm(sub(p[a], p[b]));
    let pos = |v: f64| v.max(0.0);

    let brow_gap = c[22][0] - c[21][0] - (n[22][0] - n[21][0]);
    let corner_rise = dy(&CORNERS);
    let corner_out = out(&CORNERS);
    let mid = dy(&[62, 66]);
    let eye_corners = dy(&[36, 39, 42, 45]);
    let open = aperture(c);
    [
        dy(&[20, 21, 22, 23]),
        dy(&[17, 18, 25, 26]),
        pos(-dy(&[19, 20, 21, 22, 23, 24])) + pos(-brow_gap),
        dy(&[37, 38, 43, 44]),
        pos(dy(&[40, 41, 46, 47])) + 0.5 * pos(-dy(&[17, 18, 25, 26])),
        dy(&[40, 41, 46, 47]) - eye_corners,
        dy(&[31, 35]),
        dy(&[50, 51, 52]),
        pos(corner_rise) + 0.5 * pos(corner_out),
        back(&CORNERS).min(back(&CORNERS) - 0.5 * (back(&[49, 53]) + back(&[55, 59])))
            - 0.5 * corner_rise.abs(),
        -(corner_rise - mid),
        dist(c, 57, 8) - dist(n, 57, 8),
        corner_out - pos(corner_rise),
        dist(n, 49, 53) - dist(c, 49, 53),
        dist(c, 62, 66) - dist(n, 62, 66),
        dist(c, 30, 8) - dist(n, 30, 8),
        if neutral_aperture > 0.0 {
            1.0 - open / neutral_aperture
        } else {
            0.0
        },
    ]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::stream;

    #[test]
    fn noise_is_seeded_and_off_by_default() {
        let clean: [f64; AU_COUNT] = std::array::from_fn(|k| 0.2 * k as f64);
        let off = ObserverNoise::default();
        assert!(off.is_off());
        let mut same = clean;
        let gains = off.subject_gains(&mut stream(1, "t"));
        off.apply(&mut same, &gains, &mut stream(1, "t"));
        assert_eq!(same, clean);

        let on = ObserverNoise {
            noise_sd: 0.2,
            gain_spread: 0.1,
        };
        let run = |seed| {
            let mut rng = stream(seed, "observer/noise");
            let gains = on.subject_gains(&mut rng);
            let mut aus = clean;
            on.apply(&mut aus, &gains, &mut rng);
            aus
        };
        assert_eq!(run(3), run(3));
        assert_ne!(run(3), run(4));
        assert!(run(3).iter().all(|a| (0.0..=AU_MAX).contains(a)));
    }
}
