//! File formats: the face mesh, expression weight tables. The only place that knows file
//! layouts and column names; every error names the file and line.

pub mod expressions;
pub mod mesh;
