//! The 68 iBUG landmarks on the MediaPipe canonical mesh, from
//! `assets/face/ibug68_to_mediapipe468.csv` (copied from `shared/assets`, which documents how
//! each point was matched). Points listed with two vertices are their mean. The table is
//! compiled into the binary so observing a face needs no file access.

use std::sync::OnceLock;

use super::au::{Calibration, ObserveError, Observer};
use crate::sim::geom::V3;
use crate::sim::FaceModel;

pub const LANDMARK_COUNT: usize = 68;

const TABLE: &str = include_str!("../../assets/face/ibug68_to_mediapipe468.csv");

/// Per landmark (0-based iBUG order), the canonical-mesh vertices it averages.
pub fn landmark_vertices() -> &'static [Vec<usize>; LANDMARK_COUNT] {
    static MAP: OnceLock<[Vec<usize>; LANDMARK_COUNT]> = OnceLock::new();
    MAP.get_or_init(|| {
        let mut out: [Vec<usize>; LANDMARK_COUNT] = std::array::from_fn(|_| Vec::new());
        let mut reader = csv::Reader::from_reader(TABLE.as_bytes());
        for record in reader.records() {
            let record = record.expect("embedded landmark table is valid CSV");
            let index: usize = record[1].parse().expect("0-based index column");
            out[index] = record[3]
                .split(';')
                .map(|v| v.trim().parse().expect("vertex index"))
                .collect();
        }
        assert!(out.iter().all(|v| !v.is_empty()), "all 68 landmarks mapped");
        out
    })
}

/// The 68 landmarks of a surface whose first 468 vertices are the canonical mesh's (true at
/// every subdivision level, which appends vertices).
pub fn landmarks(surface: &[V3]) -> [V3; LANDMARK_COUNT] {
    let map = landmark_vertices();
    std::array::from_fn(|i| {
        let vs = &map[i];
        let mut p = [0.0; 3];
        for &v in vs {
            for k in 0..3 {
                p[k] += surface[v][k];
            }
        }
        p.map(|c| c / vs.len() as f64)
    })
}

/// The observer of the base model: its rest landmarks are the neutral face.
pub fn model_observer(
    model: &FaceModel,
    calibration: Calibration,
) -> Result<Observer, ObserveError> {
    let rest = model.rest_state();
    Observer::new(&landmarks(rest.surface(model.vertex_count())), calibration)
}

/// OpenFace's camera frame (+y down, +z away from the camera) to ours (+y up, +z toward it).
pub fn from_camera(p: &[V3; LANDMARK_COUNT]) -> [V3; LANDMARK_COUNT] {
    p.map(|q| [q[0], -q[1], -q[2]])
}

/// The per-landmark, per-coordinate median of `faces`.
pub fn median_face(faces: &[[V3; LANDMARK_COUNT]]) -> [V3; LANDMARK_COUNT] {
    std::array::from_fn(|i| {
        std::array::from_fn(|k| {
            let mut v: Vec<f64> = faces.iter().map(|f| f[i][k]).collect();
            crate::stats::median(&mut v)
        })
    })
}
