//! MediaPipe's blendshape scores as files.

use crate::landmark::{Blendshapes, BLENDSHAPE_NAMES};

/// `blendshapes.csv`: a row per frame, `frame,timestamp,success` and MediaPipe's 52 scores
/// under its own names; a frame with no face has `success = 0` and empty scores.
pub fn blendshapes_csv(scores: &[Option<Blendshapes>], fps: f64) -> String {
    let mut text = format!("frame,timestamp,success,{}\n", BLENDSHAPE_NAMES.join(","));
    for (i, s) in scores.iter().enumerate() {
        let timestamp = if fps > 0.0 { i as f64 / fps } else { 0.0 };
        text.push_str(&format!("{},{timestamp:.3},", i + 1));
        match s {
            Some(s) => {
                text.push('1');
                for v in s {
                    text.push_str(&format!(",{v:.6}"));
                }
            }
            None => {
                text.push('0');
                text.push_str(&",".repeat(BLENDSHAPE_NAMES.len()));
            }
        }
        text.push('\n');
    }
    text
}
