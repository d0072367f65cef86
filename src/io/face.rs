//! Where the face comes from: its mesh, the expression weights and the face's settings, as
//! the command line and a spec's `[dataset]` give them (`Spec::face_source`).

use std::path::PathBuf;

use anyhow::{bail, Context, Result};

use crate::io::expressions::{default_expressions_path, read_expressions};
use crate::io::mesh::{default_mesh_path, read_obj};
use crate::sim::expression::ExpressionWeights;
use crate::sim::{FaceModel, FaceParams, Mesh};

/// Where the face comes from.
#[derive(Clone, Debug, Default)]
pub struct FaceSource {
    /// OBJ mesh; default `assets/face/canonical_face.obj`.
    pub mesh: Option<PathBuf>,
    /// Expression weights; default `experiments/expressions.csv`.
    pub expressions: Option<PathBuf>,
    pub subdivisions: u8,
    /// `TissueParams::shear_modulus_fraction`; default that field's default.
    pub shear_modulus_fraction: Option<f64>,
}

impl FaceSource {
    pub fn model(&self) -> Result<FaceModel> {
        if let Some(f) = self.shear_modulus_fraction {
            if !(f.is_finite() && f >= 0.0) {
                bail!("--shear-modulus-fraction must be a finite number >= 0, got {f}");
            }
        }
        FaceModel::new(&self.mesh()?, self.params()).with_context(|| {
            format!(
                "{}: cannot build the face model",
                self.mesh_path().display()
            )
        })
    }

    fn mesh_path(&self) -> PathBuf {
        self.mesh.clone().unwrap_or_else(default_mesh_path)
    }

    /// The base mesh (before subdivision, m).
    pub fn mesh(&self) -> Result<Mesh> {
        Ok(read_obj(&self.mesh_path())?)
    }

    pub fn params(&self) -> FaceParams {
        let mut params = FaceParams {
            subdivisions: self.subdivisions,
            ..FaceParams::default()
        };
        if let Some(f) = self.shear_modulus_fraction {
            params.tissue.shear_modulus_fraction = f;
        }
        params
    }

    pub fn weights(&self) -> Result<ExpressionWeights> {
        let path = self
            .expressions
            .clone()
            .unwrap_or_else(default_expressions_path);
        Ok(read_expressions(&path)?)
    }
}
