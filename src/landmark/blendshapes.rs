//! The Face Landmarker's blendshape head: 52 ARKit-named scores in [0, 1] from the x, y pixels
//! of 146 of Face Mesh v2's 478 landmarks (`face_blendshapes.tflite`, an MLP-Mixer that
//! centres and scales the points itself). The subset, its order and the names are those of
//! MediaPipe's `face_blendshapes_graph.cc`; the scores come out as the network gives them
//! (`TensorsToClassificationCalculator` with no threshold and no top-k).

use candle_core::{Device, Tensor};

use super::graph::{self, Graph, GraphError};
use super::MESH_V2_POINTS;

const BYTES: &[u8] = include_bytes!("../../assets/landmarker/face_blendshapes.safetensors");

/// The landmarks the head reads, in its input order.
pub const SUBSET: [usize; 146] = [
    0, 1, 4, 5, 6, 7, 8, 10, 13, 14, 17, 21, 33, 37, 39, 40, 46, 52, 53, 54, 55, 58, 61, 63, 65,
    66, 67, 70, 78, 80, 81, 82, 84, 87, 88, 91, 93, 95, 103, 105, 107, 109, 127, 132, 133, 136,
    144, 145, 146, 148, 149, 150, 152, 153, 154, 155, 157, 158, 159, 160, 161, 162, 163, 168, 172,
    173, 176, 178, 181, 185, 191, 195, 197, 234, 246, 249, 251, 263, 267, 269, 270, 276, 282, 283,
    284, 285, 288, 291, 293, 295, 296, 297, 300, 308, 310, 311, 312, 314, 317, 318, 321, 323, 324,
    332, 334, 336, 338, 356, 361, 362, 365, 373, 374, 375, 377, 378, 379, 380, 381, 382, 384, 385,
    386, 387, 388, 389, 390, 397, 398, 400, 402, 405, 409, 415, 454, 466, 468, 469, 470, 471, 472,
    473, 474, 475, 476, 477,
];

/// The 52 scores' names, MediaPipe's own (ARKit's, with `_neutral` first).
pub const BLENDSHAPE_NAMES: [&str; 52] = [
    "_neutral",
    "browDownLeft",
    "browDownRight",
    "browInnerUp",
    "browOuterUpLeft",
    "browOuterUpRight",
    "cheekPuff",
    "cheekSquintLeft",
    "cheekSquintRight",
    "eyeBlinkLeft",
    "eyeBlinkRight",
    "eyeLookDownLeft",
    "eyeLookDownRight",
    "eyeLookInLeft",
    "eyeLookInRight",
    "eyeLookOutLeft",
    "eyeLookOutRight",
    "eyeLookUpLeft",
    "eyeLookUpRight",
    "eyeSquintLeft",
    "eyeSquintRight",
    "eyeWideLeft",
    "eyeWideRight",
    "jawForward",
    "jawLeft",
    "jawOpen",
    "jawRight",
    "mouthClose",
    "mouthDimpleLeft",
    "mouthDimpleRight",
    "mouthFrownLeft",
    "mouthFrownRight",
    "mouthFunnel",
    "mouthLeft",
    "mouthLowerDownLeft",
    "mouthLowerDownRight",
    "mouthPressLeft",
    "mouthPressRight",
    "mouthPucker",
    "mouthRight",
    "mouthRollLower",
    "mouthRollUpper",
    "mouthShrugLower",
    "mouthShrugUpper",
    "mouthSmileLeft",
    "mouthSmileRight",
    "mouthStretchLeft",
    "mouthStretchRight",
    "mouthUpperUpLeft",
    "mouthUpperUpRight",
    "noseSneerLeft",
    "noseSneerRight",
];

/// One face's 52 scores, in [`BLENDSHAPE_NAMES`] order.
pub type Blendshapes = [f64; 52];

/// The index of a blendshape by MediaPipe's name.
pub fn index(name: &str) -> Option<usize> {
    BLENDSHAPE_NAMES.iter().position(|n| *n == name)
}

/// The blendshape network.
pub struct BlendshapeNetwork {
    graph: Graph,
}

impl BlendshapeNetwork {
    pub fn new() -> Result<BlendshapeNetwork, GraphError> {
        Ok(BlendshapeNetwork {
            graph: Graph::from_bytes("face_blendshapes", BYTES)?,
        })
    }

    /// The scores of a face from its 478 Face Mesh v2 landmarks in image pixels (z unused).
    pub fn scores(&self, points: &[[f64; 3]]) -> Result<Blendshapes, GraphError> {
        if points.len() != MESH_V2_POINTS {
            return Err(GraphError::Format {
                name: "face_blendshapes".into(),
                message: format!(
                    "needs the {MESH_V2_POINTS} landmarks of Face Mesh v2, got {}",
                    points.len()
                ),
            });
        }
        let xy: Vec<f32> = SUBSET
            .iter()
            .flat_map(|&i| [points[i][0] as f32, points[i][1] as f32])
            .collect();
        let candle = |cause| GraphError::Candle {
            name: "face_blendshapes".into(),
            cause,
        };
        let input = Tensor::from_vec(xy, (1, SUBSET.len(), 2), &Device::Cpu).map_err(candle)?;
        let out = self.graph.forward(&input)?;
        let v = graph::values(&out[0]).map_err(candle)?;
        let mut scores = [0.0; 52];
        if v.len() != scores.len() {
            return Err(GraphError::Format {
                name: "face_blendshapes".into(),
                message: format!("{} scores, expected 52", v.len()),
            });
        }
        for (s, x) in scores.iter_mut().zip(v) {
            *s = x as f64;
        }
        Ok(scores)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The network on the fixed points of `tools/landmarker/reference_landmarker.py`, against
    /// TFLite's own outputs.
    #[test]
    fn network_matches_tflite() {
        let xy: Vec<f32> = (0..SUBSET.len())
            .flat_map(|i| {
                let i = i as f64;
                [
                    (200.0 + 80.0 * (0.7 * i).sin() * (0.6 + 0.4 * (0.13 * i).cos())) as f32,
                    (240.0 + 100.0 * (0.7 * i).cos() * (0.6 + 0.4 * (0.29 * i).sin())) as f32,
                ]
            })
            .collect();
        let net = BlendshapeNetwork::new().unwrap();
        let input = Tensor::from_vec(xy, (1, SUBSET.len(), 2), &Device::Cpu).unwrap();
        let got = graph::values(&net.graph.forward(&input).unwrap()[0]).unwrap();
        let path = format!(
            "{}/tests/data/landmarker/reference/network_face_blendshapes.csv",
            env!("CARGO_MANIFEST_DIR")
        );
        let want: Vec<f64> = std::fs::read_to_string(path)
            .unwrap()
            .lines()
            .skip(1)
            .map(|l| l.rsplit(',').next().unwrap().parse().unwrap())
            .collect();
        assert_eq!(got.len(), want.len());
        for (k, (g, w)) in got.iter().zip(&want).enumerate() {
            assert!(
                (*g as f64 - w).abs() <= 1e-4,
                "{}: {g} vs TFLite's {w}",
                BLENDSHAPE_NAMES[k]
            );
        }
    }

    #[test]
    fn subset_is_sorted_and_ends_with_the_irises() {
        assert!(SUBSET.windows(2).all(|w| w[0] < w[1]));
        assert_eq!(&SUBSET[136..], &(468..478).collect::<Vec<_>>()[..]);
        assert_eq!(index("jawOpen"), Some(25));
        assert_eq!(index("noseSneerRight"), Some(51));
    }

    /// The head's scores depend on the shape of the points only: it centres them and divides
    /// by their mean distance from the centre, so a moved, scaled copy scores the same.
    #[test]
    fn scores_are_invariant_to_translation_and_scale() {
        let net = BlendshapeNetwork::new().unwrap();
        let points: Vec<[f64; 3]> = (0..MESH_V2_POINTS)
            .map(|i| {
                let t = i as f64 * 0.37;
                [100.0 + 40.0 * t.sin(), 120.0 + 50.0 * (1.3 * t).cos(), 0.0]
            })
            .collect();
        let moved: Vec<[f64; 3]> = points
            .iter()
            .map(|p| [2.5 * p[0] + 31.0, 2.5 * p[1] - 7.0, p[2]])
            .collect();
        let (a, b) = (net.scores(&points).unwrap(), net.scores(&moved).unwrap());
        for (x, y) in a.iter().zip(&b) {
            assert!((0.0..=1.0).contains(x));
            assert!((x - y).abs() < 1e-4, "{x} vs {y}");
        }
        assert!(net.scores(&points[..468]).is_err());
    }
}
