//! The AU calibration table (`experiments/au_calibration.csv`): per AU, the activations it is
//! calibrated on (`controls`, `name=value` joined by `;`, a name being a muscle pair or a
//! control), the intensity those activations should read (`target`), the raw measure the
//! model gave for them (`raw`) and the resulting `gain = target / raw`. `facelab observe
//! --calibrate` rewrites `raw` and `gain`; everything else is edited by hand.

use std::path::{Path, PathBuf};

use crate::observe::au::{au_index, Calibration, AU_COUNT, AU_NAMES};
use crate::sim::Activations;

use super::expressions::{controls_activations, parse_controls};

pub const DEFAULT_CALIBRATION: &str = "experiments/au_calibration.csv";

const HEADER: [&str; 5] = ["au", "controls", "target", "raw", "gain"];

#[derive(Clone, Debug, PartialEq)]
pub struct CalibrationRow {
    pub controls: Vec<(String, f64)>,
    pub target: f64,
    pub raw: f64,
    pub gain: f64,
}

/// The whole table: one row per AU in `AU_NAMES` order, plus the file's comment lines.
#[derive(Clone, Debug, PartialEq)]
pub struct CalibrationTable {
    pub comments: Vec<String>,
    pub rows: Vec<CalibrationRow>,
}

#[derive(Debug, thiserror::Error)]
pub enum CalibrationFileError {
    #[error("{path}: {cause}")]
    Io {
        path: PathBuf,
        cause: std::io::Error,
    },
    #[error("{path}:{line}: {message}")]
    Row {
        path: PathBuf,
        line: usize,
        message: String,
    },
    #[error("{path}: no row for {au}")]
    Missing { path: PathBuf, au: &'static str },
}

impl CalibrationTable {
    pub fn calibration(&self) -> Calibration {
        Calibration::Gains(std::array::from_fn(|k| self.rows[k].gain))
    }

    /// The activations an AU is calibrated on.
    pub fn activations(&self, au: usize) -> Result<Activations, String> {
        controls_activations(&self.rows[au].controls)
    }

    /// The file's text: comments, header, one row per AU (numbers with 6 significant digits).
    pub fn to_csv(&self) -> String {
        let mut out = String::new();
        for c in &self.comments {
            out.push_str(c);
            out.push('\n');
        }
        out.push_str(&HEADER.join(","));
        out.push('\n');
        for (name, row) in AU_NAMES.iter().zip(&self.rows) {
            let controls: Vec<String> = row
                .controls
                .iter()
                .map(|(n, v)| format!("{n}={v}"))
                .collect();
            out.push_str(&format!(
                "{name},{},{},{:.6e},{:.6e}\n",
                controls.join(";"),
                row.target,
                row.raw,
                row.gain
            ));
        }
        out
    }
}

/// Reads and checks the table: every AU once, known controls, positive finite gains.
pub fn read_calibration(path: &Path) -> Result<CalibrationTable, CalibrationFileError> {
    let text = std::fs::read_to_string(path).map_err(|cause| CalibrationFileError::Io {
        path: path.to_path_buf(),
        cause,
    })?;
    parse_calibration(&text, path)
}

pub fn parse_calibration(
    text: &str,
    path: &Path,
) -> Result<CalibrationTable, CalibrationFileError> {
    let err = |line: usize, message: String| CalibrationFileError::Row {
        path: path.to_path_buf(),
        line,
        message,
    };
    let mut comments = Vec::new();
    let mut rows: [Option<CalibrationRow>; AU_COUNT] = Default::default();
    let mut header_seen = false;
    for (i, raw_line) in text.lines().enumerate() {
        let line = i + 1;
        let l = raw_line.trim();
        if l.starts_with('#') {
            comments.push(raw_line.to_string());
            continue;
        }
        if l.is_empty() {
            continue;
        }
        let cells: Vec<&str> = l.split(',').map(str::trim).collect();
        if !header_seen {
            if cells != HEADER {
                return Err(err(line, format!("header must be `{}`", HEADER.join(","))));
            }
            header_seen = true;
            continue;
        }
        if cells.len() != HEADER.len() {
            return Err(err(
                line,
                format!("{} cells, expected {}", cells.len(), HEADER.len()),
            ));
        }
        let au =
            au_index(cells[0]).ok_or_else(|| err(line, format!("unknown AU `{}`", cells[0])))?;
        if rows[au].is_some() {
            return Err(err(line, format!("{} appears twice", AU_NAMES[au])));
        }
        let number = |col: usize| -> Result<f64, CalibrationFileError> {
            let v: f64 = cells[col].parse().map_err(|_| {
                err(
                    line,
                    format!("{} `{}` is not a number", HEADER[col], cells[col]),
                )
            })?;
            if !v.is_finite() || v < 0.0 {
                return Err(err(
                    line,
                    format!("{} must be finite and >= 0, got {v}", HEADER[col]),
                ));
            }
            Ok(v)
        };
        let controls = parse_controls(cells[1]).map_err(|m| err(line, m))?;
        let row = CalibrationRow {
            controls,
            target: number(2)?,
            raw: number(3)?,
            gain: number(4)?,
        };
        rows[au] = Some(row);
    }
    let mut out = Vec::with_capacity(AU_COUNT);
    for (k, row) in rows.into_iter().enumerate() {
        out.push(row.ok_or(CalibrationFileError::Missing {
            path: path.to_path_buf(),
            au: AU_NAMES[k],
        })?);
    }
    Ok(CalibrationTable {
        comments,
        rows: out,
    })
}
