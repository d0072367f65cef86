//! File formats: the face mesh, expression weight tables, the AU calibration, OpenFace CSV.
//! The only place that knows file layouts and column names; every error names the file and
//! line.

pub mod atomic;
pub mod calibration;
pub mod curves;
pub mod expressions;
pub mod facs;
pub mod mesh;
pub mod openface;
pub mod reach;

use std::path::{Path, PathBuf};

/// A data file of the checkout (`rel` from its root): in the working folder if it is there,
/// else beside the crate's sources, so the binary works from any folder of the checkout.
pub fn data_path(rel: &str) -> PathBuf {
    let local = PathBuf::from(rel);
    if local.exists() {
        local
    } else {
        Path::new(env!("CARGO_MANIFEST_DIR")).join(rel)
    }
}
