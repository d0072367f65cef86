//! Photos to face landmarks and blendshapes: MediaPipe's face detector (BlazeFace, short
//! range), its Face Mesh landmark networks (v1: 468 points; v2, the Face Landmarker task's:
//! 478 with the irises) and the Face Landmarker's blendshape head (52 ARKit-named scores),
//! run in candle on the CPU with MediaPipe's own weights (`assets/landmarker/`, converted once
//! by `tools/landmarker/convert_mediapipe.py`; Apache-2.0, see `assets/landmarker/NOTICE`).
//! The weights are compiled into the binary: nothing is downloaded or read at run time.
//!
//! The pipeline is MediaPipe's: the detector on the letterboxed image -> a rotated box around
//! the face from the two eye keypoints, 1.5x the detection (v1, `face_landmark_front_cpu`:
//! made square; v2, the Face Landmarker task: as the box is) -> an affine crop (192x192 for
//! v1, 256x256 for v2) -> landmarks -> back to image pixels. In a video the next frame's crop
//! comes from the previous frame's landmarks (eye corners 33 and 263, made square) while the
//! face score holds. The blendshape head reads the x, y pixels of 146 of the 478 points.
//!
//! Pure computation on RGB pixels: decoding files is `io::photo`'s work.

pub mod blendshapes;
pub mod detect;
pub mod graph;
pub mod metric;
pub mod warp;

use candle_core::{Device, Tensor};

pub use blendshapes::{BlendshapeNetwork, Blendshapes, BLENDSHAPE_NAMES};
pub use detect::{Detection, Detector};
pub use graph::{Graph, GraphError};
pub use warp::{RgbFrame, RotatedRect};

const DETECTOR_BYTES: &[u8] =
    include_bytes!("../../assets/landmarker/face_detection_short_range.safetensors");
const MESH_V1_BYTES: &[u8] = include_bytes!("../../assets/landmarker/face_landmark.safetensors");
const MESH_V2_BYTES: &[u8] =
    include_bytes!("../../assets/landmarker/face_landmarks_detector.safetensors");

/// Number of Face Mesh landmarks that are vertices of the canonical face (v1's whole output,
/// v2's first 468).
pub const MESH_POINTS: usize = 468;

/// Face Mesh v2's landmarks: the 468 of the mesh, then the right iris (centre 468 and four
/// points) and the left iris (centre 473 and four points).
pub const MESH_V2_POINTS: usize = 478;

/// Which Face Mesh network, with its crop.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum MeshVersion {
    /// Face Mesh v1 (`face_landmark.tflite`, 192x192, 468 points), as MediaPipe's legacy
    /// FaceMesh solution runs it.
    V1,
    /// Face Mesh v2 (`face_landmarks_detector.tflite` of the Face Landmarker task, 256x256,
    /// 478 points): the points the blendshape head reads.
    #[default]
    V2,
}

impl MeshVersion {
    pub fn name(self) -> &'static str {
        match self {
            MeshVersion::V1 => "mediapipe-face-mesh-v1",
            MeshVersion::V2 => "mediapipe-face-mesh-v2",
        }
    }
}

/// The face score below which a tracked face is dropped and the frame detected again.
/// MediaPipe's default is 0.5 (`min_tracking_confidence`), but its landmark network scores a
/// crop of a cup of coffee taken where a face was one frame before at 0.74 (the committed
/// test photos), while real faces score above 0.99; 0.9 keeps a cut away from the face from
/// being tracked into the next shot.
pub const TRACKING_SCORE: f64 = 0.9;

/// Face Mesh: 468 (v1) or 478 (v2) landmarks in image pixels (z scaled like x) and the
/// network's face score.
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
    pub version: MeshVersion,
}

impl MeshNetwork {
    pub fn new(version: MeshVersion) -> Result<MeshNetwork, GraphError> {
        let graph = match version {
            MeshVersion::V1 => Graph::from_bytes("face_landmark", MESH_V1_BYTES)?,
            MeshVersion::V2 => Graph::from_bytes("face_landmarks_detector", MESH_V2_BYTES)?,
        };
        Ok(MeshNetwork { graph, version })
    }

    /// Input side (192 for v1, 256 for v2).
    pub fn size(&self) -> usize {
        self.graph.input_shape[1]
    }

    /// Number of landmarks (468 for v1, 478 for v2).
    pub fn points(&self) -> usize {
        match self.version {
            MeshVersion::V1 => MESH_POINTS,
            MeshVersion::V2 => MESH_V2_POINTS,
        }
    }

    /// The landmarks of the face inside `rect` (MediaPipe's ROI: rotated).
    pub fn run(&self, frame: &RgbFrame, rect: &RotatedRect) -> Result<FaceMesh, GraphError> {
        let size = self.size();
        let crop = warp::crop(frame, rect, size, warp::Border::Replicate, [0.0, 1.0]);
        let input = chw_tensor(&crop, size)?;
        let out = self.graph.forward(&input)?;
        let raw = to_vec(&out[0])?;
        let score = sigmoid(to_vec(&out[1])?[0] as f64);
        if raw.len() != 3 * self.points() {
            return Err(GraphError::Format {
                name: self.version.name().into(),
                message: format!(
                    "{} landmark values, expected {}",
                    raw.len(),
                    3 * self.points()
                ),
            });
        }
        let points = (0..self.points())
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

/// Detector, landmark network and blendshape head together, with MediaPipe's thresholds.
pub struct Landmarker {
    pub detector: Detector,
    pub mesh: MeshNetwork,
    pub blendshapes: BlendshapeNetwork,
}

/// One face found in a photo.
#[derive(Clone, Debug)]
pub struct Face {
    pub detection: Detection,
    pub mesh: FaceMesh,
}

impl Landmarker {
    /// The default landmarker: Face Mesh v2, as the Face Landmarker task runs it.
    pub fn new() -> Result<Landmarker, GraphError> {
        Landmarker::with(MeshVersion::default())
    }

    pub fn with(version: MeshVersion) -> Result<Landmarker, GraphError> {
        Ok(Landmarker {
            detector: Detector::new(Graph::from_bytes(
                "face_detection_short_range",
                DETECTOR_BYTES,
            )?),
            mesh: MeshNetwork::new(version)?,
            blendshapes: BlendshapeNetwork::new()?,
        })
    }

    /// The blendshape scores of a face, where its landmarks are Face Mesh v2's (v1's 468
    /// points lack the irises the head reads).
    pub fn blendshapes(&self, mesh: &FaceMesh) -> Result<Option<Blendshapes>, GraphError> {
        if mesh.points.len() == MESH_V2_POINTS {
            self.blendshapes.scores(&mesh.points).map(Some)
        } else {
            Ok(None)
        }
    }

    /// Every face the detector finds (largest first) with its landmarks; faces whose mesh score
    /// is below 0.5 are dropped, as MediaPipe drops them.
    pub fn faces(&self, frame: &RgbFrame) -> Result<Vec<Face>, GraphError> {
        let mut faces = Vec::new();
        for detection in self.detector.detect(frame)? {
            let rect = detection.face_rect(self.mesh.version);
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
        let rect = RotatedRect::from_landmarks(&previous.points[..MESH_POINTS]);
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
        check("face_landmark", MESH_V1_BYTES, ["conv2d_21", "conv2d_31"]);
    }

    #[test]
    fn mesh_v2_network_matches_tflite() {
        check(
            "face_landmarks_detector",
            MESH_V2_BYTES,
            ["Identity", "Identity_1"],
        );
    }
}
