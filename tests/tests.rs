//! Integration tests, one binary (see STYLE.md): `sim` physics, the
//! observer, OpenFace files, the command line and Table 2's transfer.

mod choe;
mod cli;
mod harness;
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
