//! Observing a face like OpenFace does (DESIGN 2.2): the 68 iBUG landmarks on the simulated
//! surface, head pose, and the 17 intensity AUs. Pure; uses only `sim` types.

pub mod au;
pub mod features;
pub mod fit;
pub mod landmarks;
pub mod pose;

pub use au::{Calibration, Observation, Observer, ObserverNoise, AU_COUNT, AU_NAMES};
pub use landmarks::{from_camera, landmarks, median_face, model_observer, LANDMARK_COUNT};
pub use pose::HeadPose;
