//! The base face mesh as a Wavefront OBJ subset: `v x y z` lines in centimetres and
//! `f a b c` triangles (1-based, `a/b/c` texture or normal suffixes ignored).

use std::path::{Path, PathBuf};

use crate::sim::{Mesh, MeshError};

/// The committed base mesh, relative to the crate root.
pub const DEFAULT_MESH: &str = "assets/face/canonical_face.obj";

#[derive(Debug, thiserror::Error)]
pub enum MeshFileError {
    #[error("{path}: {cause}")]
    Read {
        path: PathBuf,
        cause: std::io::Error,
    },
    #[error("{path}:{line}: {message}")]
    Parse {
        path: PathBuf,
        line: usize,
        message: String,
    },
    #[error("{path}: {cause}")]
    Invalid { path: PathBuf, cause: MeshError },
}

/// Reads an OBJ face mesh and converts centimetres to metres.
pub fn read_obj(path: &Path) -> Result<Mesh, MeshFileError> {
    let text = std::fs::read_to_string(path).map_err(|cause| MeshFileError::Read {
        path: path.to_path_buf(),
        cause,
    })?;
    parse_obj(&text).map_err(|e| match e {
        ObjError::Parse { line, message } => MeshFileError::Parse {
            path: path.to_path_buf(),
            line,
            message,
        },
        ObjError::Mesh(cause) => MeshFileError::Invalid {
            path: path.to_path_buf(),
            cause,
        },
    })
}

enum ObjError {
    Parse { line: usize, message: String },
    Mesh(MeshError),
}

fn parse_obj(text: &str) -> Result<Mesh, ObjError> {
    let mut positions = Vec::new();
    let mut triangles = Vec::new();
    for (i, raw) in text.lines().enumerate() {
        let line = i + 1;
        let err = |message: String| ObjError::Parse { line, message };
        let mut parts = raw.split_whitespace();
        match parts.next() {
            Some("v") => {
                let coords: Vec<&str> = parts.collect();
                if coords.len() < 3 {
                    return Err(err(format!(
                        "vertex needs 3 coordinates, found {}",
                        coords.len()
                    )));
                }
                let mut p = [0.0; 3];
                for (k, c) in coords[..3].iter().enumerate() {
                    let v: f64 = c
                        .parse()
                        .map_err(|_| err(format!("`{c}` is not a number")))?;
                    if !v.is_finite() {
                        return Err(err(format!("`{c}` is not finite")));
                    }
                    p[k] = v * 1e-2;
                }
                positions.push(p);
            }
            Some("f") => {
                let idx: Vec<&str> = parts.collect();
                if idx.len() != 3 {
                    return Err(err(format!(
                        "face must be a triangle, found {} corners",
                        idx.len()
                    )));
                }
                let mut t = [0usize; 3];
                for (k, c) in idx.iter().enumerate() {
                    let head = c.split('/').next().unwrap_or("");
                    let v: usize = head
                        .parse()
                        .map_err(|_| err(format!("`{c}` is not a vertex index")))?;
                    if v == 0 {
                        return Err(err("vertex indices are 1-based; found 0".to_string()));
                    }
                    t[k] = v - 1;
                }
                triangles.push(t);
            }
            _ => {}
        }
    }
    Mesh::new(positions, triangles).map_err(ObjError::Mesh)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn malformed_coordinate_names_the_line() {
        let text = "v 0 0 0\nv 1 x 0\n";
        match parse_obj(text) {
            Err(ObjError::Parse { line, message }) => {
                assert_eq!(line, 2);
                assert!(message.contains("`x`"));
            }
            _ => panic!("expected a parse error"),
        }
    }
}
