//! File formats: the face mesh, expression weight tables, the AU calibration, OpenFace CSV.
//! The only place that knows file layouts and column names; every error names the file and
//! line.

pub mod atomic;
pub mod calibration;
pub mod curves;
pub mod expressions;
pub mod facs;
pub mod mesh;
pub mod observer_fit;
pub mod openface;
pub mod photo;
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
