//! Photos to face landmarks: MediaPipe's face detector (BlazeFace, short range) and Face Mesh
//! landmark network, run in candle on the CPU with MediaPipe's own weights
//! (`assets/landmarker/`, converted once by `tools/landmarker/convert_mediapipe.py`; Apache-2.0,
//! see `assets/landmarker/NOTICE`). The weights are compiled into the binary: nothing is
//! downloaded or read at run time.
//!
//! The pipeline is MediaPipe's (`face_landmark_front_cpu`): the detector on the letterboxed
//! image -> a rotated square around the face from the two eye keypoints, 1.5x the box -> a
//! 192x192 crop by affine warp -> 468 landmarks -> back to image pixels. In a video the next
//! frame's crop comes from the previous frame's landmarks (eye corners 33 and 263) while the
//! face score holds.
//!
//! Pure computation on RGB pixels: decoding files is `io::photo`'s work.

pub mod detect;
pub mod graph;
pub mod metric;
pub mod warp;

use candle_core::{Device, Tensor};

pub use detect::{Detection, Detector};
pub use graph::{Graph, GraphError};
pub use warp::{RgbFrame, RotatedRect};

const DETECTOR_BYTES: &[u8] =
    include_bytes!("../../assets/landmarker/face_detection_short_range.safetensors");
const MESH_BYTES: &[u8] = include_bytes!("../../assets/landmarker/face_landmark.safetensors");

/// Number of Face Mesh landmarks (the vertices of the canonical face).
pub const MESH_POINTS: usize = 468;

/// The face score below which a tracked face is dropped and the frame detected again.
/// MediaPipe's default is 0.5 (`min_tracking_confidence`), but its landmark network scores a
/// crop of a cup of coffee taken where a face was one frame before at 0.74 (the committed
/// test photos), while real faces score above 0.99; 0.9 keeps a cut away from the face from
/// being tracked into the next shot.
pub const TRACKING_SCORE: f64 = 0.9;

/// Face Mesh: 468 landmarks in image pixels (z scaled like x) and the network's face score.
#[derive(Clone, Debug, PartialEq)]
pub struct FaceMesh {
    pub points: Vec<[f64; 3]>,
    /// Sigmoid of the face-presence output; MediaPipe drops the face below 0.5.
    pub score: f64,
    /// The crop the landmarks were read in.
    pub rect: RotatedRect,
}

/// The face landmark network.
pub struct MeshNetwork {
    graph: Graph,
}

impl MeshNetwork {
    pub fn new() -> Result<MeshNetwork, GraphError> {
        Ok(MeshNetwork {
            graph: Graph::from_bytes("face_landmark", MESH_BYTES)?,
        })
    }

    /// Input side (192).
    pub fn size(&self) -> usize {
        self.graph.input_shape[1]
    }

    /// The 468 landmarks of the face inside `rect` (MediaPipe's ROI: rotated, square).
    pub fn run(&self, frame: &RgbFrame, rect: &RotatedRect) -> Result<FaceMesh, GraphError> {
        let size = self.size();
        let crop = warp::crop(frame, rect, size, warp::Border::Replicate, [0.0, 1.0]);
        let input = chw_tensor(&crop, size)?;
        let out = self.graph.forward(&input)?;
        let raw = to_vec(&out[0])?;
        let score = sigmoid(to_vec(&out[1])?[0] as f64);
        let points = (0..MESH_POINTS)
            .map(|i| {
                let (x, y, z) = (
                    raw[3 * i] as f64,
                    raw[3 * i + 1] as f64,
                    raw[3 * i + 2] as f64,
                );
                rect.to_image([x / size as f64, y / size as f64], z / size as f64)
            })
            .collect();
        Ok(FaceMesh {
            points,
            score,
            rect: *rect,
        })
    }
}

/// Detector and landmark network together, with MediaPipe's thresholds.
pub struct Landmarker {
    pub detector: Detector,
    pub mesh: MeshNetwork,
}

/// One face found in a photo.
#[derive(Clone, Debug)]
pub struct Face {
    pub detection: Detection,
    pub mesh: FaceMesh,
}

impl Landmarker {
    pub fn new() -> Result<Landmarker, GraphError> {
        Ok(Landmarker {
            detector: Detector::new(Graph::from_bytes(
                "face_detection_short_range",
                DETECTOR_BYTES,
            )?),
            mesh: MeshNetwork::new()?,
        })
    }

    /// Every face the detector finds (largest first) with its landmarks; faces whose mesh score
    /// is below 0.5 are dropped, as MediaPipe drops them.
    pub fn faces(&self, frame: &RgbFrame) -> Result<Vec<Face>, GraphError> {
        let mut faces = Vec::new();
        for detection in self.detector.detect(frame)? {
            let rect = detection.face_rect();
            let mesh = self.mesh.run(frame, &rect)?;
            if mesh.score >= 0.5 {
                faces.push(Face { detection, mesh });
            }
        }
        faces.sort_by(|a, b| b.detection.area().total_cmp(&a.detection.area()));
        Ok(faces)
    }

    /// The next video frame's landmarks from the previous frame's (MediaPipe's tracking): the
    /// crop follows the eye corners; `None` when the face score drops below
    /// [`TRACKING_SCORE`], so the caller detects again.
    pub fn track(
        &self,
        frame: &RgbFrame,
        previous: &FaceMesh,
    ) -> Result<Option<FaceMesh>, GraphError> {
        let rect = RotatedRect::from_landmarks(&previous.points);
        let mesh = self.mesh.run(frame, &rect)?;
        Ok((mesh.score >= TRACKING_SCORE).then_some(mesh))
    }
}

pub(crate) fn sigmoid(x: f64) -> f64 {
    1.0 / (1.0 + (-x).exp())
}

/// A [1, 3, size, size] tensor from an interleaved RGB float crop.
fn chw_tensor(crop: &[f32], size: usize) -> Result<Tensor, GraphError> {
    let candle = |source| GraphError::Candle {
        name: "input".into(),
        cause: source,
    };
    Tensor::from_slice(crop, (1, size, size, 3), &Device::Cpu)
        .and_then(|t| t.permute((0, 3, 1, 2))?.contiguous())
        .map_err(candle)
}

fn to_vec(t: &Tensor) -> Result<Vec<f32>, GraphError> {
    graph::values(t).map_err(|source| GraphError::Candle {
        name: "output".into(),
        cause: source,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::BTreeMap;

    /// The input pattern `tools/landmarker/reference.py` gave TFLite's interpreter.
    fn pattern(size: usize) -> Tensor {
        let mut v = Vec::with_capacity(size * size * 3);
        for h in 0..size {
            for w in 0..size {
                for c in 0..3 {
                    let (h, w, c) = (h as f64, w as f64, c as f64);
                    v.push(((0.37 * h + 0.11 * w + 1.3 * c).sin() * (0.05 * (h - w)).cos()) as f32);
                }
            }
        }
        chw_tensor(&v, size).unwrap()
    }

    fn reference(name: &str) -> BTreeMap<String, Vec<f64>> {
        let path = format!(
            "{}/tests/data/landmarker/reference/network_{name}.csv",
            env!("CARGO_MANIFEST_DIR")
        );
        let mut out: BTreeMap<String, Vec<f64>> = BTreeMap::new();
        for line in std::fs::read_to_string(path).unwrap().lines().skip(1) {
            let f: Vec<&str> = line.split(',').collect();
            out.entry(f[0].to_string())
                .or_default()
                .push(f[2].parse().unwrap());
        }
        out
    }

    /// Each network, run on a fixed input by our interpreter, against TFLite's own outputs.
    fn check(name: &str, bytes: &[u8], names: [&str; 2]) {
        let graph = Graph::from_bytes(name, bytes).unwrap();
        let out = graph.forward(&pattern(graph.input_shape[1])).unwrap();
        let want = reference(name);
        for (t, key) in out.iter().zip(names) {
            let got = graph::values(t).unwrap();
            let want = &want[key];
            assert_eq!(got.len(), want.len(), "{key}");
            let scale = want.iter().fold(0f64, |m, v| m.max(v.abs()));
            let worst = got
                .iter()
                .zip(want)
                .map(|(g, w)| (*g as f64 - w).abs())
                .fold(0f64, f64::max);
            assert!(
                worst <= 1e-3 * scale.max(1.0),
                "{name} {key}: max |diff| {worst} (scale {scale})"
            );
        }
    }

    #[test]
    fn detector_network_matches_tflite() {
        check(
            "face_detection_short_range",
            DETECTOR_BYTES,
            ["regressors", "classificators"],
        );
    }

    #[test]
    fn mesh_network_matches_tflite() {
        check("face_landmark", MESH_BYTES, ["conv2d_21", "conv2d_31"]);
    }
}
