//! The real OpenFace files a spec transfers (`[realfaces]`): the list, the folder they live
//! in (never committed: their licences do not let the project carry them) and the check that
//! they are all there.

use std::path::PathBuf;

use super::observer_fit::{read_realdata, ObserverFileError};
use super::DataFile;

/// Why the listed real files cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum RealDataError {
    #[error(transparent)]
    List(#[from] ObserverFileError),
    #[error("{0}")]
    Missing(String),
}

/// `[realfaces]` in a spec.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct RealfacesParams {
    /// The list of files (`file,person,licence`), relative to the repository.
    pub files: DataFile,
    /// The folder the listed paths are relative to, as the spec gives it; `None`: the
    /// layout's (`../shared/realdata`).
    pub data: Option<String>,
    /// That folder, resolved when the spec was loaded.
    #[serde(skip)]
    pub root: PathBuf,
    /// Every n-th used frame of each file is transferred (1: all).
    pub frame_stride: usize,
}

impl RealfacesParams {
    /// `realfaces.files` when a spec does not set it.
    pub const DEFAULT_FILES: &'static str = super::observer_fit::DEFAULT_REALDATA;
}

/// One listed file, found on disk.
#[derive(Clone, Debug)]
pub struct RealInput {
    /// As listed (relative to the data folder).
    pub file: String,
    pub person: String,
    pub path: PathBuf,
}

/// A committed OpenFace file named by a path relative to the repository (Table 2's
/// `table2.openface`), its person named after its folder (`assets/openface/py-feat/x.csv`:
/// "py-feat").
pub fn committed_input(file: &DataFile) -> RealInput {
    let person = std::path::Path::new(&file.name)
        .parent()
        .and_then(|p| p.file_name())
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "real".into());
    RealInput {
        file: file.name.clone(),
        person,
        path: file.path.clone(),
    }
}

/// The listed files, each checked to exist; the error says what is missing and how to give it.
pub fn inputs(p: &RealfacesParams) -> Result<Vec<RealInput>, RealDataError> {
    let list = &p.files.path;
    let root = &p.root;
    let listed = read_realdata(list)?;
    let mut out = Vec::with_capacity(listed.len());
    let mut missing = Vec::new();
    for f in listed {
        let path = root.join(&f.file);
        if !path.is_file() {
            missing.push(f.file.display().to_string());
        }
        out.push(RealInput {
            file: f.file.display().to_string(),
            person: f.person,
            path,
        });
    }
    if !missing.is_empty() {
        return Err(RealDataError::Missing(format!(
            "the real-data table needs the OpenFace files listed in {} under {}, which is not \
             here or lacks {} of them ({}). They are not part of the repository (their \
             licences do not let it carry them): point `realfaces.data` at the folder that \
             holds them, e.g. `--set realfaces.data=\"/path/to/realdata\"`",
            list.display(),
            root.display(),
            missing.len(),
            missing.join(", ")
        )));
    }
    Ok(out)
}
