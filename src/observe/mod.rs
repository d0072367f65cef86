//! Observing a face like OpenFace does: the 68 iBUG landmarks on the simulated surface
//! (DESIGN 2.2). Pure; uses only `sim` types.

pub mod landmarks;

pub use landmarks::{landmarks, LANDMARK_COUNT};
