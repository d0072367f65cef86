//! The observer's features: what a face does, measured from the subject's own neutral face,
//! that a fitted readout (`au::FittedReadout`) maps onto OpenFace's AU scale.
//!
//! Two kinds, all in the neutral face's frame and inter-ocular distance (IOD) units:
//! - the 17 hand-made AU measures of `au.rs` (`m_AU01` .. `m_AU45`), each designed for one AU;
//! - the change of 50 landmark distances (`d_19_37` is the distance between iBUG landmarks
//!   19 and 37), chosen by what the facial muscles do: brow to eye (AU01/02/04), the lids
//!   (AU05/07/45), the eye corners, the nose (AU09/10), the lips' widths, heights and
//!   thicknesses (AU10/12/14/20/23/25), mouth corners to eye corners, nose and chin
//!   (AU12/15/20), and lip to chin and nose to chin (AU17/26). A distance does not change
//!   with the head's rotation, so these are robust to an imperfect alignment.
//!
//! A readout sees each feature's positive and negative part as two inputs (`d_48_54+`,
//! `d_48_54-`), so a nonnegative fit can use a lengthening and a shortening differently.

use crate::sim::geom::{norm, sub, V3};

use super::au::{measures, AU_COUNT, AU_NAMES};
use super::landmarks::LANDMARK_COUNT;

/// Landmark pairs whose distance changes are features (0-based iBUG).
pub const PAIRS: [(usize, usize); 50] = [
    // brow to eye, and the gap between the brows
    (19, 37),
    (24, 44),
    (21, 39),
    (22, 42),
    (17, 36),
    (26, 45),
    (21, 22),
    (20, 38),
    (23, 43),
    // the lids' gaps and the eyes' widths
    (37, 41),
    (38, 40),
    (43, 47),
    (44, 46),
    (36, 39),
    (42, 45),
    // nose: alar width, nose to upper lip, ala to corner, bridge length
    (31, 35),
    (33, 51),
    (31, 48),
    (35, 54),
    (27, 33),
    // the mouth: width, height, inner opening, lip thicknesses, inner width
    (48, 54),
    (51, 57),
    (62, 66),
    (50, 61),
    (52, 63),
    (58, 65),
    (56, 67),
    (49, 59),
    (53, 55),
    (60, 64),
    // mouth corners to eye corners, nose and chin; chin and jaw
    (48, 36),
    (54, 45),
    (48, 33),
    (54, 33),
    (48, 8),
    (54, 8),
    (57, 8),
    (30, 8),
    (33, 8),
    (51, 33),
    (48, 57),
    (54, 57),
    (48, 51),
    (54, 51),
    // the red lips' widths and the inner lower lip to its outer midpoint
    (50, 52),
    (49, 53),
    (55, 59),
    (56, 58),
    (66, 57),
    (62, 51),
];

pub const FEATURE_COUNT: usize = AU_COUNT + PAIRS.len();
/// Each feature's positive and negative part.
pub const INPUT_COUNT: usize = 2 * FEATURE_COUNT;

/// Feature names in `features` order.
pub fn feature_names() -> Vec<String> {
    AU_NAMES
        .iter()
        .map(|a| format!("m_{a}"))
        .chain(PAIRS.iter().map(|(a, b)| format!("d_{a}_{b}")))
        .collect()
}

/// Input names in `inputs` order: every feature's `+` part, then every `-` part.
pub fn input_names() -> Vec<String> {
    let f = feature_names();
    f.iter()
        .map(|n| format!("{n}+"))
        .chain(f.iter().map(|n| format!("{n}-")))
        .collect()
}

/// The features of current landmarks `c` against neutral `n` (both aligned, face frame, IOD
/// units).
pub fn features(
    n: &[V3; LANDMARK_COUNT],
    c: &[V3; LANDMARK_COUNT],
    neutral_aperture: f64,
) -> [f64; FEATURE_COUNT] {
    let m = measures(n, c, neutral_aperture);
    let mut out = [0.0; FEATURE_COUNT];
    out[..AU_COUNT].copy_from_slice(&m);
    for (slot, &(a, b)) in out[AU_COUNT..].iter_mut().zip(PAIRS.iter()) {
        *slot = norm(sub(c[a], c[b])) - norm(sub(n[a], n[b]));
    }
    out
}

/// The readout's inputs: positive parts, then negative parts.
pub fn inputs(features: &[f64; FEATURE_COUNT]) -> [f64; INPUT_COUNT] {
    std::array::from_fn(|i| {
        if i < FEATURE_COUNT {
            features[i].max(0.0)
        } else {
            (-features[i - FEATURE_COUNT]).max(0.0)
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_are_unique_and_counted() {
        let names = input_names();
        assert_eq!(names.len(), INPUT_COUNT);
        let set: std::collections::BTreeSet<_> = names.iter().collect();
        assert_eq!(set.len(), INPUT_COUNT);
        for (a, b) in PAIRS {
            assert!(a < LANDMARK_COUNT && b < LANDMARK_COUNT && a != b);
        }
    }

    #[test]
    fn a_face_at_rest_has_no_features_and_parts_split_the_sign() {
        let n: [V3; LANDMARK_COUNT] =
            std::array::from_fn(|i| [(i as f64).sin(), (i as f64).cos(), 0.1 * i as f64]);
        let open = super::super::au::aperture(&n);
        let f = features(&n, &n, open);
        assert!(f.iter().all(|v| v.abs() < 1e-12));
        let mut c = n;
        c[54][0] += 0.1; // the left corner moves out: the mouth widens
        let f = features(&n, &c, open);
        let x = inputs(&f);
        let k = AU_COUNT + PAIRS.iter().position(|&p| p == (48, 54)).unwrap();
        assert!(f[k] > 0.0);
        assert_eq!(x[k], f[k]);
        assert_eq!(x[FEATURE_COUNT + k], 0.0);
    }
}
