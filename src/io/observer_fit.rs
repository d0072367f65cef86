//! The fitted observer's files: the readout table (`experiments/au_observer_fit.csv`, written
//! by `facelab observe --fit`) and the list of real OpenFace files it is fitted on
//! (`experiments/realdata.csv`).
//!
//! The readout table is long: per AU an `intercept` row, then one row per nonzero input
//! weight (`features::input_names`). Its `#` lines say which files it was fitted on, with
//! their SHA-256, so a table names its data.
//!
//! The real-data list has columns `file,person,licence`: a path relative to the data folder
//! (`../shared/realdata` unless told), the person it shows (files of one person are held out
//! together in the validation) and the licence of the file (which stays where it is).

use std::path::{Path, PathBuf};

use crate::observe::au::{au_index, Calibration, FittedReadout, AU_COUNT, AU_NAMES};
use crate::observe::features::{input_names, INPUT_COUNT};
use crate::observe::fit::Allowed;

use super::calibration::read_calibration;
use super::commented_csv;

pub const DEFAULT_READOUT: &str = "experiments/au_observer_fit.csv";
pub const DEFAULT_REALDATA: &str = "experiments/realdata.csv";
pub const DEFAULT_READOUT_INPUTS: &str = "experiments/au_readout_inputs.csv";

const HEADER: [&str; 3] = ["au", "input", "weight"];
const REALDATA_HEADER: [&str; 3] = ["file", "person", "licence"];
const INPUTS_HEADER: [&str; 3] = ["au", "inputs", "why"];

#[derive(Debug, thiserror::Error)]
pub enum ObserverFileError {
    /// The CSV layer's own error follows as the cause.
    #[error("{path}")]
    Csv { path: PathBuf, source: csv::Error },
    #[error("{path}:{line}: {message}")]
    Row {
        path: PathBuf,
        line: u64,
        message: String,
    },
    #[error("{path}: {message}")]
    File { path: PathBuf, message: String },
}

/// The readout's text: `comments` (each written as a `#` line), header, rows.
pub fn readout_csv(readout: &FittedReadout, comments: &[String]) -> String {
    let names = input_names();
    let mut out = String::new();
    for c in comments {
        out.push_str("# ");
        out.push_str(c);
        out.push('\n');
    }
    out.push_str(&HEADER.join(","));
    out.push('\n');
    for (k, au) in AU_NAMES.iter().enumerate() {
        out.push_str(&format!("{au},intercept,{:e}\n", readout.intercept[k]));
        for (name, &w) in names.iter().zip(&readout.weights[k]) {
            if w != 0.0 {
                out.push_str(&format!("{au},{name},{w:e}\n"));
            }
        }
    }
    out
}

/// Reads a readout table: known AUs and inputs, nonnegative finite weights, an intercept for
/// every AU.
pub fn read_readout(path: &Path) -> Result<FittedReadout, ObserverFileError> {
    let csv_err = |source| ObserverFileError::Csv {
        path: path.to_path_buf(),
        source,
    };
    let row_err = |line, message| ObserverFileError::Row {
        path: path.to_path_buf(),
        line,
        message,
    };
    let (header, rows) = commented_csv(path).map_err(csv_err)?;
    if header != HEADER {
        return Err(row_err(1, format!("header must be `{}`", HEADER.join(","))));
    }
    let names = input_names();
    let mut readout = FittedReadout {
        intercept: [0.0; AU_COUNT],
        weights: [[0.0; INPUT_COUNT]; AU_COUNT],
    };
    let mut has_intercept = [false; AU_COUNT];
    for (line, record) in rows {
        let au = au_index(&record[0])
            .ok_or_else(|| row_err(line, format!("unknown AU `{}`", &record[0])))?;
        let value: f64 = record[2]
            .trim()
            .parse()
            .ok()
            .filter(|v: &f64| v.is_finite())
            .ok_or_else(|| row_err(line, format!("weight `{}` is not a number", &record[2])))?;
        let input = record[1].trim();
        if input == "intercept" {
            readout.intercept[au] = value;
            has_intercept[au] = true;
            continue;
        }
        let j = names
            .iter()
            .position(|n| n == input)
            .ok_or_else(|| row_err(line, format!("unknown input `{input}`")))?;
        if value < 0.0 {
            return Err(row_err(
                line,
                format!("weight {value} of `{input}` is negative; readout weights are >= 0"),
            ));
        }
        readout.weights[au][j] = value;
    }
    if let Some(k) = has_intercept.iter().position(|h| !h) {
        return Err(ObserverFileError::File {
            path: path.to_path_buf(),
            message: format!("no intercept row for {}", AU_NAMES[k]),
        });
    }
    Ok(readout)
}

/// An observer calibration from either kind of table, told by its header: the model-anchored
/// gains (`au,controls,target,raw,gain`) or a fitted readout (`au,input,weight`).
pub fn read_any_calibration(path: &Path) -> anyhow::Result<Calibration> {
    let (header, _) = commented_csv(path).map_err(|source| ObserverFileError::Csv {
        path: path.to_path_buf(),
        source,
    })?;
    if header == HEADER {
        Ok(Calibration::Fitted(Box::new(read_readout(path)?)))
    } else {
        Ok(read_calibration(path)?.calibration())
    }
}

/// Reads which inputs each AU's readout may use: one row per AU, inputs joined by `;` (`*`
/// for all of them), and a reason.
pub fn read_readout_inputs(path: &Path) -> Result<Box<Allowed>, ObserverFileError> {
    let row_err = |line, message| ObserverFileError::Row {
        path: path.to_path_buf(),
        line,
        message,
    };
    let (header, rows) = commented_csv(path).map_err(|source| ObserverFileError::Csv {
        path: path.to_path_buf(),
        source,
    })?;
    if header != INPUTS_HEADER {
        return Err(row_err(
            1,
            format!("header must be `{}`", INPUTS_HEADER.join(",")),
        ));
    }
    let names = input_names();
    let mut allowed = Box::new([[false; INPUT_COUNT]; AU_COUNT]);
    let mut seen = [false; AU_COUNT];
    for (line, record) in rows {
        let au = au_index(&record[0])
            .ok_or_else(|| row_err(line, format!("unknown AU `{}`", &record[0])))?;
        if seen[au] {
            return Err(row_err(line, format!("{} listed twice", AU_NAMES[au])));
        }
        seen[au] = true;
        if record[2].trim().is_empty() {
            return Err(row_err(line, format!("{}: say why (`why`)", AU_NAMES[au])));
        }
        for input in record[1].split(';').map(str::trim) {
            if input == "*" {
                allowed[au] = [true; INPUT_COUNT];
                continue;
            }
            let j = names
                .iter()
                .position(|n| n == input)
                .ok_or_else(|| row_err(line, format!("unknown input `{input}`")))?;
            allowed[au][j] = true;
        }
    }
    if let Some(k) = seen.iter().position(|s| !s) {
        return Err(ObserverFileError::File {
            path: path.to_path_buf(),
            message: format!("no row for {}", AU_NAMES[k]),
        });
    }
    Ok(allowed)
}

/// One real OpenFace file of the list.
#[derive(Clone, Debug, PartialEq)]
pub struct RealFile {
    pub file: PathBuf,
    pub person: String,
    pub licence: String,
}

/// Reads the list of real files (paths as written, relative to the data folder).
pub fn read_realdata(path: &Path) -> Result<Vec<RealFile>, ObserverFileError> {
    let (header, rows) = commented_csv(path).map_err(|source| ObserverFileError::Csv {
        path: path.to_path_buf(),
        source,
    })?;
    if header != REALDATA_HEADER {
        return Err(ObserverFileError::Row {
            path: path.to_path_buf(),
            line: 1,
            message: format!("header must be `{}`", REALDATA_HEADER.join(",")),
        });
    }
    let mut out = Vec::new();
    for (line, record) in rows {
        let cell = |i: usize| record[i].trim().to_string();
        if (0..3).any(|i| cell(i).is_empty()) {
            return Err(ObserverFileError::Row {
                path: path.to_path_buf(),
                line,
                message: "every row needs a file, a person and a licence".into(),
            });
        }
        out.push(RealFile {
            file: PathBuf::from(cell(0)),
            person: cell(1),
            licence: cell(2),
        });
    }
    if out.is_empty() {
        return Err(ObserverFileError::File {
            path: path.to_path_buf(),
            message: "lists no file".into(),
        });
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn readout_table_round_trips_and_names_bad_rows() {
        let dir = std::env::temp_dir().join(format!("facelab-readout-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let mut r = FittedReadout {
            intercept: std::array::from_fn(|k| 0.01 * k as f64 - 0.05),
            weights: [[0.0; INPUT_COUNT]; AU_COUNT],
        };
        r.weights[3][7] = 1.5;
        r.weights[16][INPUT_COUNT - 1] = 2.25;
        let path = dir.join("fit.csv");
        std::fs::write(&path, readout_csv(&r, &["fitted on nothing".into()])).unwrap();
        assert_eq!(read_readout(&path).unwrap(), r);
        assert!(matches!(
            read_any_calibration(&path).unwrap(),
            Calibration::Fitted(_)
        ));

        let text = std::fs::read_to_string(&path).unwrap();
        std::fs::write(&path, text.replace("1.5e0", "-1.5")).unwrap();
        let e = read_readout(&path).unwrap_err().to_string();
        assert!(e.contains("fit.csv:7") && e.contains("negative"), "{e}");
        std::fs::write(&path, text.replace("AU04,intercept", "AU04,cheek")).unwrap();
        let e = read_readout(&path).unwrap_err().to_string();
        assert!(e.contains("unknown input `cheek`"), "{e}");
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn the_shipped_input_lists_read_and_bad_ones_are_named() {
        let shipped = read_readout_inputs(&crate::io::Layout::here().readout_inputs()).unwrap();
        let names = input_names();
        let au12 = au_index("AU12").unwrap();
        let m12 = names.iter().position(|n| n == "m_AU12+").unwrap();
        assert!(shipped[au12][m12]);
        assert!(shipped.iter().all(|row| row.iter().any(|&a| a)));

        let dir = std::env::temp_dir().join(format!("facelab-inputs-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("inputs.csv");
        std::fs::write(&path, "au,inputs,why\nAU01,m_AU01+;d_1_2+,brow\n").unwrap();
        let e = read_readout_inputs(&path).unwrap_err().to_string();
        assert!(e.contains("inputs.csv:2") && e.contains("`d_1_2+`"), "{e}");
        std::fs::write(&path, "au,inputs,why\nAU01,*,all\n").unwrap();
        let e = read_readout_inputs(&path).unwrap_err().to_string();
        assert!(e.contains("no row for AU02"), "{e}");
        std::fs::remove_dir_all(&dir).ok();
    }
}
