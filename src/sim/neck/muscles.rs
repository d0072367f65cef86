//! Hill-type neck muscles (paper A.2, eq. 3-4) and their layout: 36 left/right pairs, 72
//! muscles, as in Lee & Terzopoulos 2006 ("Heads up!", SIGGRAPH), in deep, intermediate and
//! superficial layers.
//!
//! Each muscle is a polyline from its origin through via points to its insertion, every
//! point fixed to a bone; its length is the polyline's. Attachment sites follow Gray's
//! Anatomy (41st ed.) and Kamibayashi & Richmond 1998 (Spine 23:1314) in a simplified bone
//! geometry (`body.rs`); maximum forces follow the physiological cross sections of
//! Kamibayashi & Richmond 1998 and Vasavada et al. 1998 (Spine 23:412) at about 40 N/cm^2.

use super::body::{Frames, DOF, LINKS};
use crate::sim::geom::{dot, norm, scale, sub, V3};

/// Which layer a muscle belongs to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Layer {
    Deep,
    Intermediate,
    Superficial,
}

impl Layer {
    pub fn name(self) -> &'static str {
        match self {
            Layer::Deep => "deep",
            Layer::Intermediate => "intermediate",
            Layer::Superficial => "superficial",
        }
    }
}

/// A point fixed to a bone.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Attachment {
    pub link: usize,
    /// In the link's frame (m).
    pub point: V3,
}

/// Hill model constants shared by all muscles, relative to each muscle's rest length l0 and
/// maximum isometric force F_max.
#[derive(Clone, Debug, PartialEq)]
pub struct HillParams {
    /// l_m / l0: the length below which the contractile element gives no force (eq. 4's
    /// `max(0, k_max (l - l_m))`; k_max follows from F_l(l0) = F_max). Default 0.5.
    pub min_length: f64,
    /// Passive spring k_s / F_max (eq. 3). Default 0.02.
    pub passive_stiffness: f64,
    /// Passive exponent k_c (eq. 3). Default 6: the passive force reaches F_max near 55 %
    /// strain, as in Lee & Terzopoulos 2006.
    pub passive_exponent: f64,
    /// Passive damping k_d / F_max (s, eq. 3). Default 0.05.
    pub passive_damping: f64,
    /// Maximum contraction velocity v_m in rest lengths per second (eq. 4). Default 10
    /// (Zajac 1989).
    pub max_velocity: f64,
}

impl Default for HillParams {
    fn default() -> Self {
        HillParams {
            min_length: 0.5,
            passive_stiffness: 0.02,
            passive_exponent: 6.0,
            passive_damping: 0.05,
            max_velocity: 10.0,
        }
    }
}

#[derive(Clone, Debug, PartialEq)]
pub struct Muscle {
    /// e.g. `sternocleidomastoid_left`.
    pub name: String,
    pub layer: Layer,
    pub path: Vec<Attachment>,
    /// Maximum isometric force F_max (N).
    pub max_force: f64,
    /// Rest length l0 (m): the path length in the neutral posture q = 0.
    pub rest_length: f64,
}

/// Force terms of one muscle at one instant (N).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Force {
    pub passive: f64,
    /// F_l(l) F_v(l_dot): the contractile force at full activation.
    pub contractile: f64,
    /// d(total)/dl and d(total)/dl_dot at the given activation, for the implicit step.
    pub stiffness: f64,
    pub damping: f64,
}

impl Muscle {
    pub fn strain(&self, length: f64) -> f64 {
        (length - self.rest_length) / self.rest_length
    }

    /// Eq. 4's force-length relation: `max(0, k_max (l - l_m))`.
    pub fn force_length(&self, hill: &HillParams, length: f64) -> f64 {
        let l_m = hill.min_length * self.rest_length;
        let k_max = self.max_force / (self.rest_length - l_m);
        (k_max * (length - l_m)).max(0.0)
    }

    /// Eq. 4's force-velocity relation: `max(0, 1 + min(l_dot, 0) / v_m)`.
    pub fn force_velocity(&self, hill: &HillParams, rate: f64) -> f64 {
        let v_m = hill.max_velocity * self.rest_length;
        (1.0 + rate.min(0.0) / v_m).max(0.0)
    }

    /// Eq. 3: `max(0, k_s (exp(k_c e) - 1) + k_d e_dot)`.
    pub fn passive(&self, hill: &HillParams, length: f64, rate: f64, damping: bool) -> f64 {
        let e = self.strain(length);
        let e_dot = rate / self.rest_length;
        let k_s = hill.passive_stiffness * self.max_force;
        let k_d = if damping {
            hill.passive_damping * self.max_force
        } else {
            0.0
        };
        (k_s * ((hill.passive_exponent * e).exp() - 1.0) + k_d * e_dot).max(0.0)
    }

    /// All force terms at activation `a`, with their derivatives for the implicit step.
    pub fn force(&self, hill: &HillParams, a: f64, length: f64, rate: f64, damping: bool) -> Force {
        let passive = self.passive(hill, length, rate, damping);
        let fl = self.force_length(hill, length);
        let fv = self.force_velocity(hill, rate);
        let l0 = self.rest_length;
        let k_s = hill.passive_stiffness * self.max_force;
        let (mut stiffness, mut damping_d) = (0.0, 0.0);
        if passive > 0.0 {
            stiffness += k_s * hill.passive_exponent / l0
                * (hill.passive_exponent * self.strain(length)).exp();
            if damping {
                damping_d += hill.passive_damping * self.max_force / l0;
            }
        }
        if fl > 0.0 {
            stiffness += a * fv * self.max_force / (l0 - hill.min_length * l0);
            if rate < 0.0 && fv > 0.0 {
                damping_d += a * fl / (hill.max_velocity * l0);
            }
        }
        Force {
            passive,
            contractile: fl * fv,
            stiffness,
            damping: damping_d,
        }
    }

    /// Passive elastic energy (J) at `length`: the integral of eq. 3's spring from l0.
    pub fn passive_energy(&self, hill: &HillParams, length: f64) -> f64 {
        let e = self.strain(length);
        if e <= 0.0 {
            return 0.0;
        }
        let k_s = hill.passive_stiffness * self.max_force;
        let k_c = hill.passive_exponent;
        k_s * self.rest_length * (((k_c * e).exp() - 1.0) / k_c - e)
    }
}

/// A muscle's length, its rate and its gradient in q at one instant.
#[derive(Clone, Debug)]
pub struct Geometry {
    pub length: f64,
    pub rate: f64,
    /// dl/dq (the negated moment arms: `P = -G^T` in eq. 1).
    pub gradient: [f64; DOF],
}

/// Length, rate and gradient of `path` in the posture `f`.
pub fn geometry(path: &[Attachment], f: &Frames) -> Geometry {
    let mut g = Geometry {
        length: 0.0,
        rate: 0.0,
        gradient: [0.0; DOF],
    };
    // World positions segment by segment (no allocation: the step calls this per muscle).
    let mut from = f.point(path[0].link, path[0].point);
    for pair in path.windows(2) {
        let (a, b) = (&pair[0], &pair[1]);
        let to = f.point(b.link, b.point);
        let d = sub(to, from);
        let l = norm(d);
        g.length += l;
        let unit = scale(d, 1.0 / l);
        let va = f.point_velocity(a.link, from);
        let vb = f.point_velocity(b.link, to);
        g.rate += dot(unit, sub(vb, va));
        f.add_point_force(b.link, to, unit, &mut g.gradient);
        f.add_point_force(a.link, from, scale(unit, -1.0), &mut g.gradient);
        from = to;
    }
    g
}

/// One pair of the layout, given for the left side (+x).
struct PairSpec {
    name: &'static str,
    layer: Layer,
    max_force: f64,
    path: &'static [(usize, V3)],
}

// Link indices (body.rs): 0 T1 (base), 1 C7, 2 C6, 3 C5, 4 C4, 5 C3, 6 C2, 7 C1, 8 skull.
const T1: usize = 0;
const C7: usize = 1;
const C6: usize = 2;
const C5: usize = 3;
const C4: usize = 4;
const C3: usize = 5;
const C2: usize = 6;
const C1: usize = 7;
const SKULL: usize = 8;

// Landmarks on a cervical vertebra (link frame: origin at the joint below, y up).
// Transverse process tip, anterior tubercle, articular pillar, lamina and spinous process.
const fn transverse(h: f64) -> V3 {
    [0.025, 0.5 * h, -0.008]
}
const fn anterior_tubercle(h: f64) -> V3 {
    [0.018, 0.5 * h, 0.006]
}
const fn articular(h: f64) -> V3 {
    [0.020, 0.6 * h, -0.016]
}
const fn lamina(h: f64) -> V3 {
    [0.010, 0.6 * h, -0.028]
}
const fn spinous(h: f64) -> V3 {
    [0.003, 0.3 * h, -0.045]
}
const fn body(h: f64) -> V3 {
    [0.006, 0.5 * h, 0.012]
}

const H7: f64 = 0.018;
const H6: f64 = 0.017;
const H5: f64 = 0.017;
const H4: f64 = 0.017;
const H3: f64 = 0.017;
const H2: f64 = 0.030;
const H1: f64 = 0.015;

// Base (T1 and the shoulder girdle), relative to the top of the T1 body.
const MANUBRIUM: V3 = [0.02, -0.035, 0.10];
const ACROMION: V3 = [0.15, -0.01, -0.01];
const SCAPULA_SUPERIOR_ANGLE: V3 = [0.08, -0.05, -0.06];
const RIB1_ANTERIOR: V3 = [0.04, -0.02, 0.04];
const RIB1_MIDDLE: V3 = [0.05, -0.02, 0.01];
const RIB2_POSTERIOR: V3 = [0.06, -0.04, -0.01];
const T1_TRANSVERSE: V3 = [0.03, 0.0, -0.01];
const T2_TRANSVERSE: V3 = [0.03, -0.022, -0.015];
const T3_TRANSVERSE: V3 = [0.03, -0.044, -0.02];
const T3_SPINOUS: V3 = [0.004, -0.05, -0.065];
const T3_BODY: V3 = [0.008, -0.044, 0.015];

// Skull, relative to the occipital condyles.
const MASTOID: V3 = [0.05, 0.015, -0.005];
const MASTOID_POSTERIOR: V3 = [0.045, 0.015, -0.02];
const SUPERIOR_NUCHAL_LATERAL: V3 = [0.04, 0.03, -0.055];
const SUPERIOR_NUCHAL_MEDIAL: V3 = [0.015, 0.03, -0.06];
const INFERIOR_NUCHAL_LATERAL: V3 = [0.025, 0.015, -0.045];
const INFERIOR_NUCHAL_MEDIAL: V3 = [0.01, 0.015, -0.045];
const OCCIPUT_LATERAL: V3 = [0.035, 0.015, -0.035];
const BASIOCCIPUT: V3 = [0.01, 0.005, 0.02];
const BASIOCCIPUT_MEDIAL: V3 = [0.006, 0.005, 0.015];
const JUGULAR_PROCESS: V3 = [0.035, 0.005, 0.0];

const C1_TRANSVERSE: V3 = [0.04, 0.5 * H1, -0.005];
const C1_POSTERIOR_TUBERCLE: V3 = [0.004, 0.5 * H1, -0.035];
const C1_ANTERIOR: V3 = [0.012, 0.6 * H1, 0.012];

const PAIRS: [PairSpec; 36] = [
    // Superficial.
    PairSpec {
        name: "sternocleidomastoid",
        layer: Layer::Superficial,
        max_force: 120.0,
        path: &[(T1, MANUBRIUM), (SKULL, MASTOID)],
    },
    PairSpec {
        name: "trapezius",
        layer: Layer::Superficial,
        max_force: 80.0,
        path: &[
            (T1, ACROMION),
            (C5, [0.03, 0.5 * H5, -0.06]),
            (SKULL, SUPERIOR_NUCHAL_LATERAL),
        ],
    },
    PairSpec {
        name: "splenius_capitis",
        layer: Layer::Superficial,
        max_force: 60.0,
        path: &[
            (T1, T3_SPINOUS),
            (C4, [0.018, 0.5 * H4, -0.05]),
            (SKULL, MASTOID_POSTERIOR),
        ],
    },
    PairSpec {
        name: "levator_scapulae",
        layer: Layer::Superficial,
        max_force: 50.0,
        path: &[(T1, SCAPULA_SUPERIOR_ANGLE), (C1, C1_TRANSVERSE)],
    },
    // Intermediate.
    PairSpec {
        name: "semispinalis_capitis",
        layer: Layer::Intermediate,
        max_force: 100.0,
        path: &[
            (T1, T3_TRANSVERSE),
            (C4, lamina(H4)),
            (SKULL, SUPERIOR_NUCHAL_MEDIAL),
        ],
    },
    PairSpec {
        name: "longissimus_capitis",
        layer: Layer::Intermediate,
        max_force: 40.0,
        path: &[
            (T1, T3_TRANSVERSE),
            (C4, articular(H4)),
            (SKULL, MASTOID_POSTERIOR),
        ],
    },
    PairSpec {
        name: "splenius_cervicis",
        layer: Layer::Intermediate,
        max_force: 30.0,
        path: &[
            (T1, T3_SPINOUS),
            (C4, [0.02, 0.5 * H4, -0.04]),
            (C2, transverse(H2)),
        ],
    },
    PairSpec {
        name: "semispinalis_cervicis",
        layer: Layer::Intermediate,
        max_force: 60.0,
        path: &[(T1, T2_TRANSVERSE), (C2, spinous(H2))],
    },
    PairSpec {
        name: "longissimus_cervicis",
        layer: Layer::Intermediate,
        max_force: 30.0,
        path: &[(T1, T3_TRANSVERSE), (C3, transverse(H3))],
    },
    PairSpec {
        name: "scalenus_anterior",
        layer: Layer::Intermediate,
        max_force: 40.0,
        path: &[(T1, RIB1_ANTERIOR), (C4, anterior_tubercle(H4))],
    },
    PairSpec {
        name: "scalenus_medius",
        layer: Layer::Intermediate,
        max_force: 40.0,
        path: &[(T1, RIB1_MIDDLE), (C2, transverse(H2))],
    },
    PairSpec {
        name: "scalenus_posterior",
        layer: Layer::Intermediate,
        max_force: 30.0,
        path: &[(T1, RIB2_POSTERIOR), (C5, transverse(H5))],
    },
    PairSpec {
        name: "longus_capitis",
        layer: Layer::Intermediate,
        max_force: 30.0,
        path: &[
            (C5, anterior_tubercle(H5)),
            (C2, body(H2)),
            (SKULL, BASIOCCIPUT),
        ],
    },
    // Deep: suboccipital.
    PairSpec {
        name: "rectus_capitis_posterior_major",
        layer: Layer::Deep,
        max_force: 20.0,
        path: &[(C2, spinous(H2)), (SKULL, INFERIOR_NUCHAL_LATERAL)],
    },
    PairSpec {
        name: "rectus_capitis_posterior_minor",
        layer: Layer::Deep,
        max_force: 10.0,
        path: &[(C1, C1_POSTERIOR_TUBERCLE), (SKULL, INFERIOR_NUCHAL_MEDIAL)],
    },
    PairSpec {
        name: "obliquus_capitis_superior",
        layer: Layer::Deep,
        max_force: 15.0,
        path: &[(C1, C1_TRANSVERSE), (SKULL, OCCIPUT_LATERAL)],
    },
    PairSpec {
        name: "obliquus_capitis_inferior",
        layer: Layer::Deep,
        max_force: 25.0,
        path: &[(C2, spinous(H2)), (C1, C1_TRANSVERSE)],
    },
    PairSpec {
        name: "rectus_capitis_anterior",
        layer: Layer::Deep,
        max_force: 10.0,
        path: &[(C1, C1_ANTERIOR), (SKULL, BASIOCCIPUT_MEDIAL)],
    },
    PairSpec {
        name: "rectus_capitis_lateralis",
        layer: Layer::Deep,
        max_force: 10.0,
        path: &[(C1, C1_TRANSVERSE), (SKULL, JUGULAR_PROCESS)],
    },
    // Deep: multifidus, each spanning two segments (transverse/articular -> spinous).
    PairSpec {
        name: "multifidus_t1_c6",
        layer: Layer::Deep,
        max_force: 20.0,
        path: &[(T1, T1_TRANSVERSE), (C6, spinous(H6))],
    },
    PairSpec {
        name: "multifidus_c7_c5",
        layer: Layer::Deep,
        max_force: 20.0,
        path: &[(C7, articular(H7)), (C5, spinous(H5))],
    },
    PairSpec {
        name: "multifidus_c6_c4",
        layer: Layer::Deep,
        max_force: 20.0,
        path: &[(C6, articular(H6)), (C4, spinous(H4))],
    },
    PairSpec {
        name: "multifidus_c5_c3",
        layer: Layer::Deep,
        max_force: 20.0,
        path: &[(C5, articular(H5)), (C3, spinous(H3))],
    },
    PairSpec {
        name: "multifidus_c4_c2",
        layer: Layer::Deep,
        max_force: 20.0,
        path: &[(C4, articular(H4)), (C2, spinous(H2))],
    },
    // Deep: longus colli, inferior oblique, vertical and superior oblique parts.
    PairSpec {
        name: "longus_colli_inferior",
        layer: Layer::Deep,
        max_force: 20.0,
        path: &[(T1, T3_BODY), (C5, anterior_tubercle(H5))],
    },
    PairSpec {
        name: "longus_colli_vertical",
        layer: Layer::Deep,
        max_force: 25.0,
        path: &[(T1, T3_BODY), (C5, body(H5)), (C2, body(H2))],
    },
    PairSpec {
        name: "longus_colli_superior",
        layer: Layer::Deep,
        max_force: 20.0,
        path: &[(C5, anterior_tubercle(H5)), (C1, C1_ANTERIOR)],
    },
    // Deep: intertransversarii, one per segment.
    PairSpec {
        name: "intertransversarius_t1_c7",
        layer: Layer::Deep,
        max_force: 8.0,
        path: &[(T1, T1_TRANSVERSE), (C7, transverse(H7))],
    },
    PairSpec {
        name: "intertransversarius_c7_c6",
        layer: Layer::Deep,
        max_force: 8.0,
        path: &[(C7, transverse(H7)), (C6, transverse(H6))],
    },
    PairSpec {
        name: "intertransversarius_c6_c5",
        layer: Layer::Deep,
        max_force: 8.0,
        path: &[(C6, transverse(H6)), (C5, transverse(H5))],
    },
    PairSpec {
        name: "intertransversarius_c5_c4",
        layer: Layer::Deep,
        max_force: 8.0,
        path: &[(C5, transverse(H5)), (C4, transverse(H4))],
    },
    PairSpec {
        name: "intertransversarius_c4_c3",
        layer: Layer::Deep,
        max_force: 8.0,
        path: &[(C4, transverse(H4)), (C3, transverse(H3))],
    },
    PairSpec {
        name: "intertransversarius_c3_c2",
        layer: Layer::Deep,
        max_force: 8.0,
        path: &[(C3, transverse(H3)), (C2, transverse(H2))],
    },
    // Deep: rotatores, transverse process to the lamina one segment up.
    PairSpec {
        name: "rotatores_c6_c5",
        layer: Layer::Deep,
        max_force: 8.0,
        path: &[(C6, transverse(H6)), (C5, lamina(H5))],
    },
    PairSpec {
        name: "rotatores_c4_c3",
        layer: Layer::Deep,
        max_force: 8.0,
        path: &[(C4, transverse(H4)), (C3, lamina(H3))],
    },
    PairSpec {
        name: "rotatores_c3_c2",
        layer: Layer::Deep,
        max_force: 8.0,
        path: &[(C3, transverse(H3)), (C2, lamina(H2))],
    },
];

/// Number of neck muscles.
pub const MUSCLES: usize = 2 * PAIRS.len();

/// The 72 muscles, left then right of each pair (index `2 p` and `2 p + 1`), with rest
/// lengths measured in the neutral posture `rest`.
pub fn layout(rest: &Frames) -> Vec<Muscle> {
    debug_assert!(PAIRS
        .iter()
        .all(|p| p.path.iter().all(|&(link, _)| link < LINKS)));
    let mut out = Vec::with_capacity(MUSCLES);
    for pair in &PAIRS {
        for (side, sign) in [("left", 1.0), ("right", -1.0)] {
            let path: Vec<Attachment> = pair
                .path
                .iter()
                .map(|&(link, p)| Attachment {
                    link,
                    point: [sign * p[0], p[1], p[2]],
                })
                .collect();
            let rest_length = geometry(&path, rest).length;
            out.push(Muscle {
                name: format!("{}_{side}", pair.name),
                layer: pair.layer,
                path,
                max_force: pair.max_force,
                rest_length,
            });
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::super::body::{BodyState, Skeleton, SkeletonParams};
    use super::*;

    #[test]
    fn length_gradient_matches_finite_differences() {
        let sk = Skeleton::new(&SkeletonParams::default());
        let muscles = layout(&sk.frames(&BodyState::rest()));
        assert_eq!(muscles.len(), 72);
        let q: Vec<f64> = (0..DOF)
            .map(|i| 0.03 * ((i * 5 % 7) as f64 - 3.0))
            .collect();
        let s = BodyState::from_angles(&q);
        let f = sk.frames(&s);
        let h = 1e-6;
        for m in [&muscles[0], &muscles[9], &muscles[40], &muscles[71]] {
            let g = geometry(&m.path, &f);
            for j in 0..8 {
                for a in 0..3 {
                    let mut axis = [0.0; 3];
                    axis[a] = h;
                    let mut plus = s.clone();
                    plus.rotations[j] = s.rotations[j].mul(&crate::sim::geom::Rot3::exp(axis));
                    axis[a] = -h;
                    let mut minus = s.clone();
                    minus.rotations[j] = s.rotations[j].mul(&crate::sim::geom::Rot3::exp(axis));
                    let lp = geometry(&m.path, &sk.frames(&plus)).length;
                    let lm = geometry(&m.path, &sk.frames(&minus)).length;
                    let numeric = (lp - lm) / (2.0 * h);
                    assert!(
                        (numeric - g.gradient[3 * j + a]).abs() < 1e-7,
                        "{} joint {j} axis {a}",
                        m.name
                    );
                }
            }
        }
    }

    #[test]
    fn hill_relations_match_eq_4() {
        let sk = Skeleton::new(&SkeletonParams::default());
        let m = &layout(&sk.frames(&BodyState::rest()))[0];
        let hill = HillParams::default();
        let l0 = m.rest_length;
        assert!((m.force_length(&hill, l0) - m.max_force).abs() < 1e-9);
        assert_eq!(m.force_length(&hill, 0.4 * l0), 0.0);
        assert_eq!(m.force_velocity(&hill, 0.5), 1.0);
        assert!((m.force_velocity(&hill, -5.0 * l0) - 0.5).abs() < 1e-12);
        assert_eq!(m.passive(&hill, 0.9 * l0, 0.0, true), 0.0);
        assert!(m.passive(&hill, 1.2 * l0, 0.0, true) > 0.0);
    }
}
