//! Where the face comes from: its mesh, the expression weights and the face's settings, as
//! the command line and a spec's `[dataset]` give them (`Spec::face_source`).

use std::path::PathBuf;

use anyhow::{bail, Context, Result};

use crate::io::expressions::read_expressions;
use crate::io::mesh::read_obj;
use crate::io::Layout;
use crate::sim::expression::ExpressionWeights;
use crate::sim::{FaceModel, FaceParams, Mesh};

/// Where the face comes from.
#[derive(Clone, Debug)]
pub struct FaceSource {
    /// OBJ mesh (the layout's: `assets/face/canonical_face.obj`).
    pub mesh: PathBuf,
    /// Expression weights (the layout's: `experiments/expressions.csv`).
    pub expressions: PathBuf,
    pub subdivisions: u8,
    /// `TissueParams::shear_modulus_fraction`; default that field's default.
    pub shear_modulus_fraction: Option<f64>,
}

impl FaceSource {
    /// The committed face of a layout, at its default settings.
    pub fn of(layout: &Layout) -> FaceSource {
        FaceSource {
            mesh: layout.mesh(),
            expressions: layout.expressions(),
            subdivisions: 0,
            shear_modulus_fraction: None,
        }
    }

    pub fn model(&self) -> Result<FaceModel> {
        if let Some(f) = self.shear_modulus_fraction {
            if !(f.is_finite() && f >= 0.0) {
                bail!("--shear-modulus-fraction must be a finite number >= 0, got {f}");
            }
        }
        FaceModel::new(&self.mesh()?, self.params())
            .with_context(|| format!("{}: cannot build the face model", self.mesh.display()))
    }

    /// The base mesh (before subdivision, m).
    pub fn mesh(&self) -> Result<Mesh> {
        Ok(read_obj(&self.mesh)?)
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
        Ok(read_expressions(&self.expressions)?)
    }
}
