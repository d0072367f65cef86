//! Synthetic subjects and the clips they perform (DESIGN 2.4): the reference cohorts that play
//! the roles of KDEF (peak images), CK+ (neutral-to-peak videos) and RAVDESS (talking videos).
//!
//! A subject is the base face with its own geometry (smooth, mirror-symmetric morphs of face
//! width, brow height, nose, jaw and lips), its own muscle strengths and tissue stiffness, and
//! its own way of performing each emotion (the weights W_e perturbed, sometimes with an extra
//! muscle). Everything is drawn from `rng::stream(seed, "cohort/<cohort>/subject/<i>")`, so a
//! subject does not depend on how many others are drawn or on the thread count.
//!
//! Pure: no files. The harness solves each frame on the subject's model and observes it.

use crate::observe::landmarks;
use crate::rng::{stream, Stream};
use crate::sim::controls::{muscle_index, JAW_ROTATION, MUSCLE_COUNT};
use crate::sim::expression::{Expression, ExpressionWeights};
use crate::sim::geom::{smoothstep, V3};
use crate::sim::mesh::Mesh;
use crate::sim::muscles::{MuscleKind, Side, MUSCLE_PAIRS};
use crate::sim::{Activations, FaceModel, FaceParams, ModelError};

/// How subjects differ from the base model. Geometry in metres (the base face is about 15 cm
/// wide); strengths and stiffness as log-normal factors around 1; defaults and their sources
/// in `experiments/base.toml` (`[cohort.subjects]`).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct SubjectParams {
    /// SD of the relative face width change. Default 0.04: bizygomatic breadth varies by
    /// about 4-5% (coefficient of variation) among adults of one sex (Farkas 1994).
    pub face_width_sd: f64,
    /// SD of the brow height shift (m). Default 2 mm.
    pub brow_height_sd: f64,
    /// SD of the nose protrusion change (m). Default 2 mm.
    pub nose_sd: f64,
    /// SD of the chin drop (lower face length change, m). Default 3 mm (lower face height
    /// varies by about 5% of 65 mm).
    pub jaw_length_sd: f64,
    /// SD of the lip thickness change at the red lips (m). Default 1 mm.
    pub lip_thickness_sd: f64,
    /// Median of the whole-face muscle strength (1 = the base model). Default 1: we know of
    /// no measurement that puts real faces above or below the model, so the population is
    /// centred on it; `ablations/cohort_strength.toml` moves it.
    pub strength_median: f64,
    /// Log-SD of the whole-face muscle strength. Default 0.3: people's expressions differ in
    /// amplitude by a factor of about 2 between the weaker and the stronger third.
    pub strength_sd: f64,
    /// Log-SD of each muscle pair's strength around the subject's. Default 0.15.
    pub muscle_strength_sd: f64,
    /// Log-SD of the tissue moduli. Default 0.2 (skin modulus varies 2x across adults).
    pub stiffness_sd: f64,
    /// Log-SD of each expression weight (the subject's own way of posing). Default 0.25.
    pub weight_sd: f64,
    /// Chance that a subject's emotion recruits one extra muscle pair. Default 0.3.
    pub extra_muscle_probability: f64,
    /// Largest weight of such an extra muscle (drawn from U[0.1, this]). Default 0.4.
    pub extra_muscle_weight: f64,
}

impl Default for SubjectParams {
    fn default() -> Self {
        SubjectParams {
            face_width_sd: 0.04,
            brow_height_sd: 2e-3,
            nose_sd: 2e-3,
            jaw_length_sd: 3e-3,
            lip_thickness_sd: 1e-3,
            strength_median: 1.0,
            strength_sd: 0.3,
            muscle_strength_sd: 0.15,
            stiffness_sd: 0.2,
            weight_sd: 0.25,
            extra_muscle_probability: 0.3,
            extra_muscle_weight: 0.4,
        }
    }
}

/// A subject's geometry morph (all zero: the base face).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Morph {
    pub face_width: f64,
    pub brow_height: f64,
    pub nose: f64,
    pub jaw_length: f64,
    pub lip_thickness: f64,
}

/// Where on the face the morphs act, from the base face's landmarks (m).
struct Anchors {
    brow_y: f64,
    nose: V3,
    mouth: V3,
    chin_y: f64,
}

fn anchors(base: &Mesh) -> Anchors {
    let l = landmarks(&base.positions);
    let mean = |idx: std::ops::Range<usize>| {
        let n = idx.len() as f64;
        idx.fold([0.0; 3], |s, i| {
            [s[0] + l[i][0], s[1] + l[i][1], s[2] + l[i][2]]
        })
        .map(|c| c / n)
    };
    Anchors {
        brow_y: mean(17..27)[1],
        nose: l[30],
        mouth: mean(48..68),
        chin_y: l[8][1],
    }
}

fn gauss(d: f64, sigma: f64) -> f64 {
    (-0.5 * (d / sigma).powi(2)).exp()
}

impl Morph {
    /// The displacement of a base-face point. Mirror-symmetric by construction: x enters
    /// through |x| except in the width term, which is odd in x.
    fn displace(&self, a: &Anchors, p: V3) -> V3 {
        let (x, y, _) = (p[0], p[1], p[2]);
        let ax = x.abs();
        let mut d = [self.face_width * x, 0.0, 0.0];
        // Brows and forehead: a soft band around the brow line.
        d[1] += self.brow_height * gauss(y - a.brow_y, 0.012);
        // Nose: protrusion around the tip.
        d[2] += self.nose * gauss(ax, 0.010) * gauss(y - a.nose[1], 0.015);
        // Jaw: everything below the mouth moves down, fully at the chin.
        d[1] -= self.jaw_length * smoothstep((a.mouth[1] - y) / (a.mouth[1] - a.chin_y));
        // Lips: the red lips move apart from the mouth line (smooth through it).
        let v = (y - a.mouth[1]) / 0.008;
        d[1] += self.lip_thickness * v * gauss(ax, 0.025) * (-0.5 * v * v).exp();
        d
    }

    /// The morphed base mesh (same topology).
    pub fn apply(&self, base: &Mesh) -> Result<Mesh, ModelError> {
        let a = anchors(base);
        let positions = base
            .positions
            .iter()
            .map(|&p| {
                let d = self.displace(&a, p);
                [p[0] + d[0], p[1] + d[1], p[2] + d[2]]
            })
            .collect();
        Ok(Mesh::new(positions, base.triangles.clone())?)
    }
}

/// One synthetic person.
#[derive(Clone, Debug)]
pub struct Subject {
    pub index: usize,
    pub morph: Morph,
    /// Whole-face strength factor (1 = the base model).
    pub strength: f64,
    /// Per muscle pair: the factor on its force (includes `strength`).
    pub pair_strength: [f64; MUSCLE_PAIRS.len()],
    /// Factor on the tissue moduli.
    pub stiffness: f64,
    /// The subject's own W_e.
    pub weights: ExpressionWeights,
    pub model: FaceModel,
}

fn lognormal(rng: &mut Stream, sd: f64) -> f64 {
    (sd * rng.normal()).exp()
}

impl Subject {
    /// Draws subject `index` of a cohort from its stream.
    pub fn draw(
        base: &Mesh,
        face: FaceParams,
        weights: &ExpressionWeights,
        p: &SubjectParams,
        seed: u64,
        label: &str,
        index: usize,
    ) -> Result<Subject, ModelError> {
        let mut rng = stream(seed, &format!("cohort/{label}/subject/{index}"));
        let morph = Morph {
            face_width: p.face_width_sd * rng.normal(),
            brow_height: p.brow_height_sd * rng.normal(),
            nose: p.nose_sd * rng.normal(),
            jaw_length: p.jaw_length_sd * rng.normal(),
            lip_thickness: p.lip_thickness_sd * rng.normal(),
        };
        let strength = p.strength_median * lognormal(&mut rng, p.strength_sd);
        let mut pair_strength = [0.0; MUSCLE_PAIRS.len()];
        for s in &mut pair_strength {
            *s = strength * lognormal(&mut rng, p.muscle_strength_sd);
        }
        let stiffness = lognormal(&mut rng, p.stiffness_sd);
        let mut own = ExpressionWeights::default();
        for e in Expression::ALL {
            let w = weights.weights(e);
            for pair in 0..MUSCLE_PAIRS.len() {
                let shared = lognormal(&mut rng, p.weight_sd);
                for side in [Side::Right, Side::Left] {
                    let c = muscle_index(pair, side);
                    let asym = lognormal(&mut rng, 0.2 * p.weight_sd);
                    own.set(e, c, (w[c] * shared * asym).clamp(0.0, 1.0));
                }
            }
            let jaw = w[JAW_ROTATION] * lognormal(&mut rng, p.weight_sd);
            own.set(e, JAW_ROTATION, jaw.clamp(0.0, 1.0));
            if rng.uniform() < p.extra_muscle_probability {
                let unused: Vec<usize> = (0..MUSCLE_PAIRS.len())
                    .filter(|&pair| w[muscle_index(pair, Side::Right)] == 0.0)
                    .collect();
                if !unused.is_empty() {
                    let pair = unused[rng.index(unused.len())];
                    let extra = rng.range(0.1, p.extra_muscle_weight.max(0.1));
                    for side in [Side::Right, Side::Left] {
                        own.set(e, muscle_index(pair, side), extra);
                    }
                }
            }
        }
        let mut params = face;
        let t = &mut params.tissue;
        t.epidermis_modulus *= stiffness;
        t.dermal_fatty_modulus *= stiffness;
        t.muscle_layer_modulus *= stiffness;
        t.volume_modulus *= stiffness;
        let mut model = FaceModel::new(&morph.apply(base)?, params)?;
        for m in &mut model.muscles {
            for (_, f) in &mut m.nodes {
                *f *= pair_strength[m.pair];
            }
        }
        Ok(Subject {
            index,
            morph,
            strength,
            pair_strength,
            stiffness,
            weights: own,
            model,
        })
    }

    /// The subject performing `e` at intensity `s`, with the jaw rotation given separately when
    /// `jaw` is `Some` (speech). Lid muscles (which act kinematically) take the strength as a
    /// factor on their activation.
    pub fn perform(&self, e: Option<Expression>, s: f64, jaw: Option<f64>) -> Activations {
        let mut a = match e {
            Some(e) => self.weights.activations(e, s),
            None => Activations::neutral(),
        };
        for m in 0..MUSCLE_COUNT {
            let muscle = &self.model.muscles[m];
            if matches!(muscle.kind, MuscleKind::Lid(_)) {
                let v = (a.get(m) * self.pair_strength[muscle.pair]).clamp(0.0, 1.0);
                a.set_index(m, v).expect("clamped");
            }
        }
        if let Some(j) = jaw {
            let v = (a.get(JAW_ROTATION) + j).clamp(0.0, 1.0);
            a.set_index(JAW_ROTATION, v).expect("clamped");
        }
        a
    }
}

/// What a cohort's clips are like. Field defaults and their reasons are in
/// `experiments/base.toml` (`[cohort.images]`, `[cohort.onset_videos]`, `[cohort.talking_videos]`).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct ClipParams {
    pub subjects: usize,
    /// Frames per clip (1 for images).
    pub frames: usize,
    /// Peak intensity s ~ U[peak_min, peak_max] per clip.
    pub peak_min: f64,
    pub peak_max: f64,
    /// SD of the head rotation per axis (degrees); drawn per clip: an image's pose, a
    /// video's mean pose.
    pub head_rotation_sd: f64,
    /// Videos: the head sways about its mean pose, on each axis a sinusoid of amplitude
    /// ~ U[0.5, 1] x this (degrees) at `head_motion_hz` with its own phase. 0 holds it still.
    pub head_motion_deg: f64,
    /// Videos: the sway's frequency (Hz).
    pub head_motion_hz: f64,
    /// Frames per second (videos).
    pub fps: f64,
    /// Speech: syllables per second (0 for no speech).
    pub syllable_rate: f64,
    /// Speech: peak jaw rotation added by a syllable (control units).
    pub jaw_amplitude: f64,
    /// Frames from neutral to the held intensity (talking videos; onset videos ramp over
    /// the whole clip).
    pub ramp_frames: usize,
}

/// The three cohorts.
#[derive(
    Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, serde::Serialize, serde::Deserialize,
)]
#[serde(rename_all = "snake_case")]
pub enum CohortKind {
    Images,
    OnsetVideos,
    TalkingVideos,
}

impl CohortKind {
    pub const ALL: [CohortKind; 3] = [
        CohortKind::Images,
        CohortKind::OnsetVideos,
        CohortKind::TalkingVideos,
    ];

    pub fn name(self) -> &'static str {
        match self {
            CohortKind::Images => "images",
            CohortKind::OnsetVideos => "onset_videos",
            CohortKind::TalkingVideos => "talking_videos",
        }
    }

    pub fn parse(s: &str) -> Option<CohortKind> {
        CohortKind::ALL.into_iter().find(|k| k.name() == s)
    }

    pub fn is_video(self) -> bool {
        self != CohortKind::Images
    }
}

/// The cohorts of Table 2: their seed, the detector noise on reference AUs, how subjects
/// differ, and each cohort's clips. Defaults in `experiments/base.toml` with their reasons.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct CohortParams {
    /// Seed of the subjects and clips (one population for every training seed). Default 1.
    pub seed: u64,
    /// SD of the detector noise added to each reference AU (AU units). Default 0.1.
    pub noise_sd: f64,
    pub subjects: SubjectParams,
    pub images: ClipParams,
    pub onset_videos: ClipParams,
    pub talking_videos: ClipParams,
}

impl CohortParams {
    pub fn clip(&self, kind: CohortKind) -> &ClipParams {
        match kind {
            CohortKind::Images => &self.images,
            CohortKind::OnsetVideos => &self.onset_videos,
            CohortKind::TalkingVideos => &self.talking_videos,
        }
    }
}

impl Default for CohortParams {
    fn default() -> Self {
        let still = ClipParams {
            subjects: 10,
            frames: 1,
            peak_min: 0.6,
            peak_max: 1.0,
            head_rotation_sd: 5.0,
            head_motion_deg: 0.0,
            head_motion_hz: 0.5,
            fps: 30.0,
            syllable_rate: 0.0,
            jaw_amplitude: 0.0,
            ramp_frames: 1,
        };
        CohortParams {
            seed: 1,
            noise_sd: 0.1,
            subjects: SubjectParams::default(),
            images: still,
            onset_videos: ClipParams {
                subjects: 6,
                frames: 10,
                head_rotation_sd: 3.0,
                head_motion_deg: 3.0,
                ..still
            },
            talking_videos: ClipParams {
                subjects: 4,
                frames: 24,
                peak_min: 0.2,
                peak_max: 0.5,
                head_rotation_sd: 3.0,
                head_motion_deg: 3.0,
                syllable_rate: 4.5,
                jaw_amplitude: 0.2,
                ramp_frames: 6,
                ..still
            },
        }
    }
}

/// One frame a subject performs: its activations and head rotation (pitch, yaw, roll, rad).
#[derive(Clone, Debug, PartialEq)]
pub struct Frame {
    pub activations: Activations,
    pub head: [f64; 3],
}

/// One image or video: a subject performing one emotion.
#[derive(Clone, Debug, PartialEq)]
pub struct Clip {
    pub kind: CohortKind,
    pub subject: usize,
    /// `None`: the neutral image.
    pub expression: Option<Expression>,
    pub peak: f64,
    pub frames: Vec<Frame>,
}

/// The clips of `subject` in cohort `kind`: one per emotion (images also a neutral one, first),
/// drawn from `cohort/<kind>/clip/<subject>/<emotion>`.
pub fn clips(subject: &Subject, kind: CohortKind, p: &ClipParams, seed: u64) -> Vec<Clip> {
    let neutral = (kind == CohortKind::Images).then_some(None);
    neutral
        .into_iter()
        .chain(Expression::ALL.iter().map(|&e| Some(e)))
        .map(|e| {
            let name = e.map_or("neutral", |e| e.name());
            let mut rng = stream(
                seed,
                &format!("cohort/{}/clip/{}/{name}", kind.name(), subject.index),
            );
            let peak = rng.range(p.peak_min, p.peak_max);
            let sd = p.head_rotation_sd.to_radians();
            let head = [sd * rng.normal(), sd * rng.normal(), sd * rng.normal()];
            let phase = rng.uniform();
            // The sway, drawn after the draws above so that they stay what they were.
            let sway: Vec<(f64, f64)> = if kind.is_video() && p.head_motion_deg > 0.0 {
                (0..3)
                    .map(|_| {
                        let amplitude = p.head_motion_deg.to_radians() * rng.range(0.5, 1.0);
                        (amplitude, rng.range(0.0, std::f64::consts::TAU))
                    })
                    .collect()
            } else {
                Vec::new()
            };
            let n = p.frames.max(1);
            let frames = (0..n)
                .map(|f| {
                    let (s, jaw) = match kind {
                        CohortKind::Images => (peak, None),
                        CohortKind::OnsetVideos => {
                            let t = if n > 1 {
                                f as f64 / (n - 1) as f64
                            } else {
                                1.0
                            };
                            (peak * smoothstep(t), None)
                        }
                        CohortKind::TalkingVideos => {
                            let ramp = p.ramp_frames.max(1) as f64;
                            let s = peak * smoothstep(f as f64 / ramp);
                            // Syllables: the jaw opens and closes at the syllable rate.
                            let t = f as f64 / p.fps + phase / p.syllable_rate.max(1e-9);
                            let open = (std::f64::consts::PI * p.syllable_rate * t).sin().powi(2);
                            (s, Some(p.jaw_amplitude * open))
                        }
                    };
                    let t = f as f64 / p.fps;
                    let mut head = head;
                    for (h, (amplitude, phase)) in head.iter_mut().zip(&sway) {
                        *h += amplitude
                            * (std::f64::consts::TAU * p.head_motion_hz * t + phase).sin();
                    }
                    Frame {
                        activations: subject.perform(e, s, jaw),
                        head,
                    }
                })
                .collect();
            Clip {
                kind,
                subject: subject.index,
                expression: e,
                peak,
                frames,
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn morph_is_mirror_symmetric() {
        let a = Anchors {
            brow_y: 0.03,
            nose: [0.0, 0.0, 0.02],
            mouth: [0.0, -0.03, 0.0],
            chin_y: -0.07,
        };
        let m = Morph {
            face_width: 0.05,
            brow_height: 0.002,
            nose: 0.002,
            jaw_length: 0.003,
            lip_thickness: 0.001,
        };
        for p in [
            [0.013, -0.031, 0.01],
            [0.04, 0.02, -0.01],
            [0.002, -0.06, 0.0],
        ] {
            let d = m.displace(&a, p);
            let e = m.displace(&a, [-p[0], p[1], p[2]]);
            assert_eq!(d[0], -e[0]);
            assert_eq!(d[1], e[1]);
            assert_eq!(d[2], e[2]);
        }
    }
}
