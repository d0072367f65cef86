//! File formats: the face mesh, expression weight tables, the AU calibration, OpenFace CSV.
//! The only place that knows file layouts and column names; every error names the file and
//! line.

pub mod atomic;
pub mod calibration;
pub mod expressions;
pub mod facs;
pub mod mesh;
pub mod openface;
