//! The built-in landmarker against the real MediaPipe (0.10.14) on the committed test photos
//! (`tests/data/landmarker/photos/`, SOURCES.md there; references made by
//! `tools/landmarker/reference.py`).

use std::path::PathBuf;

use facelab::io::photo::read_rgb;
use facelab::landmark::Landmarker;

use crate::root;

fn data() -> PathBuf {
    root().join("tests/data/landmarker")
}

fn rows(path: PathBuf) -> Vec<Vec<f64>> {
    std::fs::read_to_string(&path)
        .unwrap()
        .lines()
        .skip(1)
        .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
        .collect()
}

/// Per photo: mean and max landmark distance over the inter-ocular distance (outer eye
/// corners 33 and 263 of the reference), and the detector box's largest edge offset over the
/// reference box's size.
fn compare(stem: &str, landmarker: &Landmarker) -> Option<(f64, f64, f64)> {
    let frame = read_rgb(&data().join(format!("photos/{stem}.png"))).unwrap();
    let faces = landmarker.faces(&frame).unwrap();
    let want = rows(data().join(format!("reference/{stem}.landmarks.csv")));
    let boxes = rows(data().join(format!("reference/{stem}.detection.csv")));
    if want.is_empty() {
        assert!(
            faces.is_empty(),
            "{stem}: MediaPipe finds no face, facelab found {}",
            faces.len()
        );
        assert!(boxes.is_empty());
        return None;
    }
    assert!(
        !faces.is_empty(),
        "{stem}: MediaPipe finds a face, facelab none"
    );
    let face = &faces[0];
    let d = |a: [f64; 2], b: [f64; 2]| ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)).sqrt();
    let iod = d([want[33][1], want[33][2]], [want[263][1], want[263][2]]);
    let dist: Vec<f64> = (0..468)
        .map(|i| {
            let p = face.mesh.points[i];
            d([p[0], p[1]], [want[i][1], want[i][2]]) / iod
        })
        .collect();
    let mean = dist.iter().sum::<f64>() / dist.len() as f64;
    let max = dist.iter().cloned().fold(0.0, f64::max);
    let r = &boxes[0];
    let size = r[4].max(r[5]);
    let b = face.detection.bbox;
    let edges = [
        b[0] - r[2],
        b[1] - r[3],
        b[0] + b[2] - (r[2] + r[4]),
        b[1] + b[3] - (r[3] + r[5]),
    ];
    let box_err = edges.iter().map(|e| e.abs()).fold(0.0, f64::max) / size;
    Some((mean, max, box_err))
}

#[test]
fn landmarks_match_mediapipe_on_every_test_photo() {
    let landmarker = Landmarker::new().unwrap();
    let mut faces = 0;
    for stem in [
        "astronaut",
        "coffee",
        "render_joy",
        "render_mouth_open",
        "render_rest",
    ] {
        if let Some((mean, max, box_err)) = compare(stem, &landmarker) {
            eprintln!(
                "{stem}: mean {:.4} max {:.4} of the inter-ocular distance, box {:.4}",
                mean, max, box_err
            );
            assert!(
                mean <= 0.01,
                "{stem}: mean landmark distance {mean:.4} of the inter-ocular distance"
            );
            assert!(
                max <= 0.03,
                "{stem}: max landmark distance {max:.4} of the inter-ocular distance"
            );
            assert!(
                box_err <= 0.05,
                "{stem}: detector box off by {box_err:.4} of its size"
            );
            faces += 1;
        }
    }
    assert_eq!(faces, 4);
}
