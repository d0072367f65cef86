//! The 26 muscle pairs of facial expression: their anatomy table (right side, mirrored to the
//! left), how each is attached to the tissue, and the forces it applies.
//!
//! Linear muscles follow Waters 1987 as used by LTW95 (paper eq. 6): a muscle pulls the fascia
//! nodes near its insertion toward its origin on the skull (or on the mandible, which moves
//! with the jaw), each node with a weight that falls off with distance from the insertion
//! (Waters' cosine fall-off, standing in for LTW95's length and width scalings Theta1, Theta2).
//! Sphincters (orbicularis oris, orbicularis oculi pars orbitalis) pull the fascia nodes in an
//! elliptical zone toward the zone's centre in the face plane. Eyelid muscles drive the lid
//! margins kinematically (see `rig`).
//!
//! Every force here is the gradient of a potential (constant-magnitude pull toward a point,
//! or toward a line in the face plane), so the quasi-static problem is an energy minimisation.
//! Depends only on `sim::geom`, `sim::mesh`, `sim::tissue`.

use super::geom::{norm, sub, V3};
use super::tissue::{Tissue, FASCIA, SKULL};

/// Where a linear muscle's origin sits.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Bone {
    /// The cranium and maxilla: fixed.
    Skull,
    /// The mandible: moves rigidly with the jaw.
    Mandible,
}

/// Which part of a sphincter's ellipse a muscle of the pair covers.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Arc {
    Upper,
    Lower,
    Whole,
}

/// The sphincters' centres are taken from hole contours of the mesh.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Opening {
    Mouth,
    Eye,
}

/// What an eyelid muscle does to the lid margins (see `rig::Lids`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LidAction {
    /// Orbicularis oculi pars palpebralis, pretarsal: closes the lids (blink, AU45).
    Close,
    /// Orbicularis oculi pars palpebralis, preseptal: narrows the eye, mostly by raising the
    /// lower lid (lid tightener, AU07).
    Tighten,
    /// Levator palpebrae superioris: raises the upper lid (AU05).
    Raise,
}

/// How a muscle pair acts, with attachment points given for the subject's right side as
/// vertex indices of the MediaPipe canonical face (`shared/assets` shows every index).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Action {
    Linear {
        /// Vertex over the origin; the origin is the skull-sheet node under it plus `offset`.
        origin: usize,
        /// Offset of the origin from that skull node (m), for origins beyond the mesh (the
        /// galea above the forehead, the platysma's chest fascia below the chin).
        offset: V3,
        bone: Bone,
        /// Vertex over the insertion (fascia sheet).
        insertion: usize,
        /// Radius of the insertion zone (m).
        radius: f64,
    },
    Sphincter {
        opening: Opening,
        arc: Arc,
        /// Semi-axes of the zone ellipse in the face plane, x then y (m).
        semi_axes: [f64; 2],
        /// Elliptical radius below which the weight is zero (0 = the zone is a full ellipse).
        inner: f64,
        /// Weight of the vertical pull relative to the horizontal one.
        vertical: f64,
    },
    Lid(LidAction),
}

/// One row of the anatomy table.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MusclePair {
    /// Anatomical name; the controls are `<name>_left` and `<name>_right`.
    pub name: &'static str,
    /// The OpenFace AU (number) the muscle mainly drives (shared/facs-facts.md (b)).
    pub au: u8,
    /// Peak force at activation 1 (N), spread over the insertion zone. Set so that each AU's
    /// muscles at full activation move its landmark by the published maximal-effort distance
    /// of adult faces (`experiments/au_reach.csv`, `facelab face reach`); unused for lid
    /// muscles, whose effect is an angle.
    pub max_force: f64,
    pub action: Action,
}

// One argument per column of the anatomy table.
#[allow(clippy::too_many_arguments)]
const fn linear(
    name: &'static str,
    au: u8,
    max_force: f64,
    origin: usize,
    offset: V3,
    bone: Bone,
    insertion: usize,
    radius_cm: f64,
) -> MusclePair {
    MusclePair {
        name,
        au,
        max_force,
        action: Action::Linear {
            origin,
            offset,
            bone,
            insertion,
            radius: radius_cm * 1e-2,
        },
    }
}

#[allow(clippy::too_many_arguments)]
const fn sphincter(
    name: &'static str,
    au: u8,
    max_force: f64,
    opening: Opening,
    arc: Arc,
    semi_axes_cm: [f64; 2],
    inner: f64,
    vertical: f64,
) -> MusclePair {
    MusclePair {
        name,
        au,
        max_force,
        action: Action::Sphincter {
            opening,
            arc,
            semi_axes: [semi_axes_cm[0] * 1e-2, semi_axes_cm[1] * 1e-2],
            inner,
            vertical,
        },
    }
}

const fn lid(name: &'static str, au: u8, action: LidAction) -> MusclePair {
    MusclePair {
        name,
        au,
        max_force: 0.0,
        action: Action::Lid(action),
    }
}

const NONE: V3 = [0.0, 0.0, 0.0];

/// The 26 pairs. Attachment sites follow standard anatomy atlases (origins on bone, insertions
/// in the skin/modiolus); the paper names the frontalis, corrugator, levator labii, orbicularis
/// oculi, mentalis and orbicularis oris groups.
pub const MUSCLE_PAIRS: [MusclePair; 26] = [
    // Forehead: frontalis in three bellies, origin in the galea aponeurotica above the mesh.
    linear(
        "frontalis_medial",
        1,
        17.9,
        109,
        [0.0, 0.025, -0.01],
        Bone::Skull,
        107,
        1.4,
    ),
    linear(
        "frontalis_intermediate",
        2,
        45.0,
        67,
        [0.0, 0.025, -0.01],
        Bone::Skull,
        66,
        1.3,
    ),
    linear(
        "frontalis_lateral",
        2,
        56.0,
        103,
        [0.0, 0.025, -0.01],
        Bone::Skull,
        63,
        1.4,
    ),
    // Glabella: brow lowerers.
    linear(
        "corrugator_supercilii",
        4,
        23.8,
        193,
        NONE,
        Bone::Skull,
        65,
        1.2,
    ),
    linear(
        "depressor_supercilii",
        4,
        8.75,
        122,
        NONE,
        Bone::Skull,
        55,
        0.9,
    ),
    linear(
        "procerus",
        4,
        7.0,
        6,
        [-0.003, 0.0, 0.0],
        Bone::Skull,
        8,
        0.9,
    ),
    // Eye.
    sphincter(
        "orbicularis_oculi_orbital",
        6,
        27.0,
        Opening::Eye,
        Arc::Whole,
        [2.8, 2.4],
        0.6,
        1.0,
    ),
    lid("orbicularis_oculi_preseptal", 7, LidAction::Tighten),
    lid("orbicularis_oculi_pretarsal", 45, LidAction::Close),
    lid("levator_palpebrae_superioris", 5, LidAction::Raise),
    // Nose and upper lip.
    linear(
        "levator_labii_superioris_alaeque_nasi",
        9,
        19.5,
        188,
        NONE,
        Bone::Skull,
        129,
        0.9,
    ),
    linear("nasalis", 9, 9.75, 203, NONE, Bone::Skull, 126, 0.7),
    // 46 N: the widened smile (below) stretches the parted lips thinner, and at 39 N the open
    // smile of AU25's reach row parted the inner lips 7.8 mm, under the published 8-16.
    linear(
        "levator_labii_superioris",
        10,
        46.0,
        100,
        NONE,
        Bone::Skull,
        39,
        0.9,
    ),
    linear(
        "zygomaticus_minor",
        10,
        15.0,
        118,
        NONE,
        Bone::Skull,
        40,
        0.8,
    ),
    // Mouth corner (modiolus). Zygomaticus major runs from the zygomatic bone, 2 cm lateral
    // and 0.5 cm below the skull under vertex 123, to the modiolus 6.5 mm lateral of the
    // corner (vertex 57), spread over 2 cm of it: with levator anguli oris the corners go up
    // and out and widen the mouth by 22.6 mm (46% of its 49 mm), where real maximal smiles put
    // it: in OpenFace's 3D landmarks of about 60 people, posed smiles widen the mouth by
    // 34-37% of neutral and the one strong smiler of shared/realdata by 48-51%
    // (`experiments/au_reach.csv` rows AU12 and AU12_width). At 28 N, 1 cm lateral and 1.4 cm
    // it widened by 28%, less than a typical smile, and the fitted readout read AU12 2.0; a
    // narrower zone at the force needed folds the skin at the insertion.
    linear(
        "zygomaticus_major",
        12,
        60.0,
        123,
        [-0.02, -0.005, 0.0],
        Bone::Skull,
        57,
        2.0,
    ),
    linear(
        "levator_anguli_oris",
        12,
        5.0,
        36,
        NONE,
        Bone::Skull,
        61,
        0.9,
    ),
    linear("buccinator", 14, 18.0, 215, NONE, Bone::Skull, 61, 0.9),
    linear("risorius", 20, 12.0, 58, NONE, Bone::Skull, 61, 0.9),
    linear(
        "platysma",
        20,
        6.0,
        136,
        [0.0, -0.03, -0.01],
        Bone::Skull,
        57,
        1.3,
    ),
    linear(
        "depressor_anguli_oris",
        15,
        11.8,
        150,
        NONE,
        Bone::Mandible,
        61,
        0.9,
    ),
    // Lower lip and chin.
    linear(
        "depressor_labii_inferioris",
        25,
        10.5,
        32,
        NONE,
        Bone::Mandible,
        181,
        0.8,
    ),
    linear(
        "mentalis",
        17,
        14.0,
        18,
        [-0.004, 0.0, 0.0],
        Bone::Mandible,
        208,
        1.0,
    ),
    linear(
        "incisivus_labii_superioris",
        23,
        6.0,
        165,
        NONE,
        Bone::Skull,
        185,
        0.7,
    ),
    linear(
        "incisivus_labii_inferioris",
        23,
        6.0,
        194,
        NONE,
        Bone::Mandible,
        43,
        0.7,
    ),
    sphincter(
        "orbicularis_oris_upper",
        23,
        20.7,
        Opening::Mouth,
        Arc::Upper,
        [3.0, 1.6],
        0.0,
        0.5,
    ),
    sphincter(
        "orbicularis_oris_lower",
        23,
        20.7,
        Opening::Mouth,
        Arc::Lower,
        [3.0, 1.6],
        0.0,
        0.5,
    ),
];

/// Subject's side. Left is +x.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Side {
    Left,
    Right,
}

impl Side {
    pub fn suffix(self) -> &'static str {
        match self {
            Side::Left => "left",
            Side::Right => "right",
        }
    }
}

/// A muscle attached to a particular model: its pull on fascia nodes.
#[derive(Clone, Debug, PartialEq)]
pub struct Muscle {
    pub pair: usize,
    pub side: Side,
    pub kind: MuscleKind,
    /// (node, force per unit activation in N); forces sum to the pair's `max_force`.
    pub nodes: Vec<(usize, f64)>,
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub enum MuscleKind {
    /// Pulls each node toward `origin` (rest position; moved by the jaw if on the mandible).
    Linear {
        origin: V3,
        bone: Bone,
        insertion: V3,
    },
    /// Pulls each node toward `centre` in the x-y (face) plane with the smoothed potential
    /// `f (sqrt(dx^2 + (k dy)^2 + c^2) - c)`: `k` weakens the vertical pull (lips close without
    /// crossing), the core `c` makes the pull fade at the centre instead of a cone tip.
    Sphincter {
        centre: V3,
        vertical: f64,
        core: f64,
    },
    /// Acts through the lid rig; no nodes.
    Lid(LidAction),
}

impl Muscle {
    pub fn name(&self) -> String {
        format!("{}_{}", MUSCLE_PAIRS[self.pair].name, self.side.suffix())
    }
}

/// Radius over which a sphincter's pull fades at its centre (m).
const SPHINCTER_CORE: f64 = 0.006;

/// Fall-off of a muscle's pull with normalised distance `r` in [0, 1] from the insertion
/// (Waters 1987's raised cosine).
fn falloff(r: f64) -> f64 {
    if r >= 1.0 {
        0.0
    } else {
        0.5 * (1.0 + (std::f64::consts::PI * r).cos())
    }
}

/// Attaches one muscle of a pair. `vertex` maps the table's right-side vertex index to this
/// side's (the mirror map for the left); `flip` is -1 for the left side's x offsets.
/// `centres` gives the sphincter centres of the mouth and of this side's eye (rest, m);
/// `free` says which nodes are free (forces on fixed nodes do nothing and are dropped).
pub fn attach(
    pair: usize,
    side: Side,
    tissue: &Tissue,
    vertex: impl Fn(usize) -> usize,
    centres: (V3, V3),
    free: &[bool],
) -> Muscle {
    let def = &MUSCLE_PAIRS[pair];
    let n = tissue.vertex_count;
    let flip = if side == Side::Left { -1.0 } else { 1.0 };
    let fascia = |v: usize| tissue.rest[FASCIA * n + v];
    let mut weights: Vec<(usize, f64)> = Vec::new();
    let kind = match def.action {
        Action::Linear {
            origin,
            offset,
            bone,
            insertion,
            radius,
        } => {
            let o = tissue.rest[SKULL * n + vertex(origin)];
            let origin_point = [o[0] + flip * offset[0], o[1] + offset[1], o[2] + offset[2]];
            let ins = fascia(vertex(insertion));
            for v in 0..n {
                let w = falloff(norm(sub(fascia(v), ins)) / radius);
                if w > 0.0 {
                    weights.push((FASCIA * n + v, w));
                }
            }
            MuscleKind::Linear {
                origin: origin_point,
                bone,
                insertion: ins,
            }
        }
        Action::Sphincter {
            opening,
            arc,
            semi_axes,
            inner,
            vertical,
        } => {
            let centre = match opening {
                Opening::Mouth => centres.0,
                Opening::Eye => centres.1,
            };
            for v in 0..n {
                let p = fascia(v);
                let (dx, dy) = (p[0] - centre[0], p[1] - centre[1]);
                let r = ((dx / semi_axes[0]).powi(2) + (dy / semi_axes[1]).powi(2)).sqrt();
                if r >= 1.0 || r < inner {
                    continue;
                }
                // A bump across the band [inner, 1]; a full ellipse peaks at its centre.
                let mut w = if inner > 0.0 {
                    (std::f64::consts::PI * (r - inner) / (1.0 - inner)).sin()
                } else {
                    falloff(r)
                };
                // Halves split at the centre line; nodes on a split line go half to each.
                let side_share = if opening == Opening::Mouth {
                    let x = p[0] - centre[0];
                    let own = if side == Side::Right {
                        x < 0.0
                    } else {
                        x > 0.0
                    };
                    if x.abs() < 1e-9 {
                        0.5
                    } else if own {
                        1.0
                    } else {
                        0.0
                    }
                } else {
                    1.0
                };
                let arc_share = match arc {
                    Arc::Whole => 1.0,
                    Arc::Upper | Arc::Lower => {
                        let up = arc == Arc::Upper;
                        if dy.abs() < 1e-9 {
                            0.5
                        } else if (dy > 0.0) == up {
                            1.0
                        } else {
                            0.0
                        }
                    }
                };
                w *= side_share * arc_share;
                if w > 0.0 {
                    weights.push((FASCIA * n + v, w));
                }
            }
            MuscleKind::Sphincter {
                centre,
                vertical,
                core: SPHINCTER_CORE,
            }
        }
        Action::Lid(action) => MuscleKind::Lid(action),
    };
    weights.retain(|&(node, _)| free[node]);
    let total: f64 = weights.iter().map(|&(_, w)| w).sum();
    let nodes = if total > 0.0 {
        weights
            .into_iter()
            .map(|(node, w)| (node, def.max_force * w / total))
            .collect()
    } else {
        Vec::new()
    };
    Muscle {
        pair,
        side,
        kind,
        nodes,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn twenty_six_pairs_with_unique_names() {
        let mut names: Vec<_> = MUSCLE_PAIRS.iter().map(|m| m.name).collect();
        names.sort_unstable();
        names.dedup();
        assert_eq!(names.len(), 26);
    }

    #[test]
    fn every_pair_drives_an_openface_au() {
        const OPENFACE: [u8; 17] = [1, 2, 4, 5, 6, 7, 9, 10, 12, 14, 15, 17, 20, 23, 25, 26, 45];
        for m in &MUSCLE_PAIRS {
            assert!(OPENFACE.contains(&m.au), "{} tagged AU{}", m.name, m.au);
        }
    }
}
