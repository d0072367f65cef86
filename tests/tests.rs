//! Integration tests, one binary (see STYLE.md): `sim` physics, the
//! observer, OpenFace files, the command line and Table 2's transfer.

mod choe;
mod cli;
mod harness;
mod neck;
mod observe;
mod openface;
mod sim;
mod transfer;

use std::sync::OnceLock;

use facelab::sim::FaceModel;

/// The base face model, built once for all tests.
pub fn model() -> &'static FaceModel {
    static MODEL: OnceLock<FaceModel> = OnceLock::new();
    MODEL.get_or_init(|| {
        let mesh = facelab::io::mesh::read_obj(&facelab::io::mesh::default_mesh_path()).unwrap();
        FaceModel::new(&mesh, Default::default()).unwrap()
    })
}

/// The crate root (where `experiments/` and `results/` are).
pub fn root() -> std::path::PathBuf {
    std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// A fresh temporary folder for one test, named by the test module and case.
pub fn temp(module: &str, name: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("facelab-{module}-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Runs the `facelab` binary in the crate root.
pub fn facelab(args: &[&str]) -> std::process::Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_facelab"))
        .args(args)
        .current_dir(root())
        .output()
        .expect("run facelab")
}
