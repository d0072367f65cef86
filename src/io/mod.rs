//! File formats: the face mesh, expression weight tables, the AU calibration, OpenFace CSV.
//! The only place that knows file layouts and column names; every error names the file and
//! line.

pub mod atomic;
pub mod blendshapes;
pub mod calibration;
pub mod curves;
pub mod embedded;
pub mod expressions;
pub mod face;
pub mod facs;
pub mod mesh;
pub mod observer_fit;
pub mod openface;
pub mod photo;
pub mod reach;
pub mod realdata;
pub mod rows;

use std::path::{Path, PathBuf};

static DATA_ROOT: std::sync::OnceLock<PathBuf> = std::sync::OnceLock::new();

/// Whether `dir` is a facelab checkout (or a copy of its data): it holds `experiments/` and
/// `assets/face/`.
fn is_root(dir: &Path) -> bool {
    dir.join("experiments").is_dir() && dir.join("assets/face").is_dir()
}

/// The first of `start` and its ancestors that is a checkout (`experiments/` and
/// `assets/face/`).
pub fn find_root(start: &Path) -> Option<PathBuf> {
    let start = std::path::absolute(start).ok()?;
    start
        .ancestors()
        .find(|d| is_root(d))
        .map(Path::to_path_buf)
}

/// Sets the checkout the data files are read from when the working folder is not in one
/// (the command line passes the spec's folder). The first call wins.
pub fn set_data_root(dir: &Path) {
    if let Some(root) = find_root(dir) {
        let _ = DATA_ROOT.set(root);
    }
}

/// The checkout data files resolve against: the working folder's (walking up), else the one
/// `set_data_root` found.
pub fn data_root() -> Option<PathBuf> {
    std::env::current_dir()
        .ok()
        .and_then(|d| find_root(&d))
        .or_else(|| DATA_ROOT.get().cloned())
}

/// A data file or folder of the checkout (`rel` from its root, or absolute): as given if it
/// exists from the working folder, else under `data_root()`, else the copy compiled into the
/// binary ([`embedded`], written out once to the user's cache folder). The binary reads
/// nothing from where it was built, so an installed copy works from any folder. When the file
/// is nowhere the path is returned as given, and the error that reads it names it.
pub fn data_path(rel: &str) -> PathBuf {
    let local = PathBuf::from(rel);
    if local.exists() || local.is_absolute() {
        return local;
    }
    if let Some(root) = data_root().filter(|root| root.join(rel).exists()) {
        return root.join(rel);
    }
    match embedded::materialize(rel) {
        Some(Ok(path)) => path,
        Some(Err(e)) => {
            eprintln!("warning: the built-in copy of {rel} could not be written out: {e}");
            local
        }
        None => local,
    }
}

/// A data file read whole: its header, then each record with its line number.
pub(crate) type CsvRows = (Vec<String>, Vec<(u64, csv::StringRecord)>);

/// A data file's rows: its header and each record with its line, `#` lines skipped. The
/// files of `experiments/` all read this way; each checks its own header and cells.
pub(crate) fn commented_csv(path: &Path) -> Result<CsvRows, csv::Error> {
    let mut reader = csv::ReaderBuilder::new()
        .comment(Some(b'#'))
        .from_path(path)?;
    let header = reader.headers()?.iter().map(str::to_string).collect();
    let mut rows = Vec::new();
    for record in reader.records() {
        let record = record?;
        rows.push((record.position().map_or(0, |p| p.line()), record));
    }
    Ok((header, rows))
}
