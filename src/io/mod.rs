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
pub mod layout;
pub mod mesh;
pub mod observer_fit;
pub mod openface;
pub mod photo;
pub mod reach;
pub mod realdata;
pub mod rows;

use std::path::Path;

pub use layout::{DataFile, Layout};

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
