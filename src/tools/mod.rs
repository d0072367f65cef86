//! The work behind the command-line tools that are not experiments: the face (`facelab
//! render`, `gallery`, `face reach`, `face sweep`, `face judge`), the observer (`facelab
//! observe`, its calibration and its fit to OpenFace), Choe's muscle-based editing (`facelab
//! edit`, `retarget`) and the benchmarks (`facelab bench`). The binary's commands are their
//! front ends; the experiments never use them.

pub mod bench;
pub mod edit;
pub mod face;
pub mod observe;
pub mod reach;
