//! The biomechanical face: mesh, layered tissue, muscles, jaw and lids, the quasi-static
//! solver and the linear muscle basis (DESIGN 2.1).
//!
//! No file I/O and no harness types: everything here takes and returns plain data.

pub mod basis;
pub mod controls;
pub mod expression;
pub mod geom;
pub mod grid;
pub mod lips;
pub mod mesh;
pub mod model;
pub mod muscles;
pub mod neck;
pub mod pose;
pub mod rig;
pub mod solver;
pub mod tissue;
pub mod validity;

pub use controls::{control_index, control_names, Activations, ControlError, CONTROL_COUNT};
pub use mesh::{Mesh, MeshError};
pub use model::{FaceModel, FaceParams, ModelError, State};
pub use solver::{solve, solve_from_rest, SolveError, SolveParams, SolveReport, Workspace};
