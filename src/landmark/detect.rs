//! BlazeFace short range (`face_detection_short_range`): SSD anchors, box and keypoint
//! decoding, weighted non-maximum suppression, as MediaPipe's calculators do them
//! (`SsdAnchorsCalculator`, `TensorsToDetectionsCalculator`, `NonMaxSuppressionCalculator`
//! with the options of `face_detection_short_range.pbtxt`).

use super::graph::{self, Graph, GraphError};
use super::warp::{self, Border, RgbFrame, RotatedRect};
use super::{chw_tensor, sigmoid, MeshVersion};

/// Strides of the four anchor layers; layers with equal strides share one grid.
const STRIDES: [usize; 4] = [8, 16, 16, 16];
const MIN_SCORE: f64 = 0.5;
const SUPPRESSION_IOU: f64 = 0.3;
const SCORE_CLIP: f64 = 100.0;
const KEYPOINTS: usize = 6;

/// A face found by the detector, in image pixels.
#[derive(Clone, Debug, PartialEq)]
pub struct Detection {
    pub score: f64,
    /// xmin, ymin, width, height.
    pub bbox: [f64; 4],
    /// Right eye, left eye, nose tip, mouth, right ear tragion, left ear tragion (the
    /// subject's sides; index 0 is on the image's left).
    pub keypoints: [[f64; 2]; KEYPOINTS],
}

impl Detection {
    pub fn area(&self) -> f64 {
        self.bbox[2] * self.bbox[3]
    }

    /// MediaPipe's landmark crop for this face: Face Mesh v1's square crop
    /// (`face_landmark_front_cpu`), or the Face Landmarker task's 1.5x box for v2.
    pub fn face_rect(&self, version: MeshVersion) -> RotatedRect {
        let [x, y, w, h] = self.bbox;
        let rect = match version {
            MeshVersion::V1 => RotatedRect::face,
            MeshVersion::V2 => RotatedRect::face_box,
        };
        rect(
            [x + w / 2.0, y + h / 2.0],
            w,
            h,
            self.keypoints[0],
            self.keypoints[1],
        )
    }
}

/// The detector network with its anchors.
pub struct Detector {
    graph: Graph,
    /// Anchor centres in the input's normalized coordinates (fixed size 1).
    anchors: Vec<[f64; 2]>,
}

impl Detector {
    pub fn new(graph: Graph) -> Detector {
        let anchors = anchors(graph.input_shape[1]);
        Detector { graph, anchors }
    }

    /// Faces in the frame, strongest first, after suppression.
    pub fn detect(&self, frame: &RgbFrame) -> Result<Vec<Detection>, GraphError> {
        let size = self.graph.input_shape[1];
        let letterbox = RotatedRect::letterbox(frame.width, frame.height);
        let crop = warp::crop(frame, &letterbox, size, Border::Zero, [-1.0, 1.0]);
        let out = self.graph.forward(&chw_tensor(&crop, size)?)?;
        let values = |i: usize| {
            graph::values(&out[i]).map_err(|source| GraphError::Candle {
                name: "face_detection_short_range output".into(),
                cause: source,
            })
        };
        let (boxes, scores) = (values(0)?, values(1)?);
        let coords = boxes.len() / self.anchors.len();
        let n = size as f64;
        // Candidates in the letterbox's normalized coordinates.
        let mut found = Vec::new();
        for (a, anchor) in self.anchors.iter().enumerate() {
            let score = sigmoid((scores[a] as f64).clamp(-SCORE_CLIP, SCORE_CLIP));
            if score < MIN_SCORE {
                continue;
            }
            let r = &boxes[a * coords..(a + 1) * coords];
            let at = |k: usize| r[k] as f64 / n;
            let (cx, cy) = (at(0) + anchor[0], at(1) + anchor[1]);
            let (w, h) = (at(2), at(3));
            let mut keypoints = [[0.0; 2]; KEYPOINTS];
            for (k, kp) in keypoints.iter_mut().enumerate() {
                *kp = [at(4 + 2 * k) + anchor[0], at(5 + 2 * k) + anchor[1]];
            }
            found.push(Detection {
                score,
                bbox: [cx - w / 2.0, cy - h / 2.0, w, h],
                keypoints,
            });
        }
        let to_image = |[u, v]: [f64; 2]| {
            let p = letterbox.to_image([u, v], 0.0);
            [p[0], p[1]]
        };
        Ok(weighted_nms(found)
            .into_iter()
            .map(|d| {
                let [x, y] = to_image([d.bbox[0], d.bbox[1]]);
                Detection {
                    score: d.score,
                    bbox: [
                        x,
                        y,
                        d.bbox[2] * letterbox.width,
                        d.bbox[3] * letterbox.height,
                    ],
                    keypoints: d.keypoints.map(to_image),
                }
            })
            .collect())
    }
}

/// SSD anchor centres for the short-range model: per stride group, a grid of
/// `input / stride` cells with two anchors per layer at each cell centre.
fn anchors(input: usize) -> Vec<[f64; 2]> {
    let mut out = Vec::new();
    let mut layer = 0;
    while layer < STRIDES.len() {
        let stride = STRIDES[layer];
        let mut per_cell = 0;
        while layer < STRIDES.len() && STRIDES[layer] == stride {
            per_cell += 2; // aspect ratio 1 and the interpolated scale
            layer += 1;
        }
        let cells = input.div_ceil(stride);
        for y in 0..cells {
            for x in 0..cells {
                let c = [
                    (x as f64 + 0.5) / cells as f64,
                    (y as f64 + 0.5) / cells as f64,
                ];
                out.extend(std::iter::repeat_n(c, per_cell));
            }
        }
    }
    out
}

fn iou(a: &[f64; 4], b: &[f64; 4]) -> f64 {
    let x0 = a[0].max(b[0]);
    let y0 = a[1].max(b[1]);
    let x1 = (a[0] + a[2]).min(b[0] + b[2]);
    let y1 = (a[1] + a[3]).min(b[1] + b[3]);
    let inter = (x1 - x0).max(0.0) * (y1 - y0).max(0.0);
    let union = a[2] * a[3] + b[2] * b[3] - inter;
    if union > 0.0 {
        inter / union
    } else {
        0.0
    }
}

/// MediaPipe's weighted NMS: the strongest remaining box and every box overlapping it by more
/// than the threshold are averaged, weighted by score, into one detection with the strongest
/// box's score.
fn weighted_nms(mut found: Vec<Detection>) -> Vec<Detection> {
    // Stable sort: equal scores keep anchor order, as std::stable_sort does in MediaPipe.
    found.sort_by(|a, b| b.score.total_cmp(&a.score));
    let mut out = Vec::new();
    while !found.is_empty() {
        let top = found[0].clone();
        let (group, rest): (Vec<Detection>, Vec<Detection>) = found
            .into_iter()
            .partition(|d| iou(&d.bbox, &top.bbox) > SUPPRESSION_IOU);
        found = rest;
        // The top box overlaps itself fully, so `group` always holds it.
        let total: f64 = group.iter().map(|d| d.score).sum();
        let mut corners = [0.0; 4];
        let mut keypoints = [[0.0; 2]; KEYPOINTS];
        for d in &group {
            let w = d.score;
            let [x, y, bw, bh] = d.bbox;
            for (c, v) in corners.iter_mut().zip([x, y, x + bw, y + bh]) {
                *c += v * w;
            }
            for (k, kp) in keypoints.iter_mut().enumerate() {
                kp[0] += d.keypoints[k][0] * w;
                kp[1] += d.keypoints[k][1] * w;
            }
        }
        let c = corners.map(|v| v / total);
        out.push(Detection {
            score: top.score,
            bbox: [c[0], c[1], c[2] - c[0], c[3] - c[1]],
            keypoints: keypoints.map(|[x, y]| [x / total, y / total]),
        });
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn anchors_number_896_on_two_grids() {
        let a = anchors(128);
        assert_eq!(a.len(), 896);
        assert_eq!(a[0], [0.5 / 16.0, 0.5 / 16.0]);
        assert_eq!(a[1], a[0]);
        assert_eq!(a[512], [0.5 / 8.0, 0.5 / 8.0]);
        assert_eq!(a[517], a[512]);
        assert_ne!(a[518], a[512]);
    }

    #[test]
    fn nms_averages_overlapping_boxes_by_score() {
        let d = |score, x| Detection {
            score,
            bbox: [x, 0.0, 1.0, 1.0],
            keypoints: [[x, 0.0]; KEYPOINTS],
        };
        let out = weighted_nms(vec![d(0.6, 0.2), d(0.9, 0.0), d(0.7, 5.0)]);
        assert_eq!(out.len(), 2);
        assert_eq!(out[0].score, 0.9);
        let want = 0.6 * 0.2 / 1.5;
        assert!(
            (out[0].bbox[0] - want).abs() < 1e-12 && (out[0].keypoints[3][0] - want).abs() < 1e-12
        );
        assert_eq!(out[1].bbox[0], 5.0);
    }
}
