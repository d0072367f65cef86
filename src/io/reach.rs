//! The range-of-motion table (`experiments/au_reach.csv`): per row (an OpenFace AU, or one of
//! the combined actions `AU01+02` and `jaw_max`), the activations it is measured at, the AU(s)
//! whose reading is reported, the skin landmark and how it is measured, the published band
//! and facelab's own target where nothing is published. `facelab face reach` reads it and
//! writes `au_reach.csv` and `muscle_au_matrix.csv` in the layouts below.

use std::path::{Path, PathBuf};

use serde::Serialize;

use crate::observe::au::au_index;
use crate::observe::LANDMARK_COUNT;

use super::expressions::parse_controls;

pub const DEFAULT_REACH: &str = "experiments/au_reach.csv";

const HEADER: [&str; 11] = [
    "row",
    "controls",
    "observed_au",
    "landmark",
    "ibug",
    "measure",
    "band_min_mm",
    "band_max_mm",
    "chosen_min_mm",
    "chosen_max_mm",
    "why",
];

/// How a row's landmark motion is measured.
#[derive(Clone, Debug, PartialEq)]
pub enum Measure {
    /// Mean 3D displacement of the landmarks from rest.
    Displacement(Vec<usize>),
    /// Change of the distance between the means of two landmark groups.
    Separation(Vec<usize>, Vec<usize>),
}

#[derive(Clone, Debug, PartialEq)]
pub struct ReachRow {
    pub row: String,
    /// `name=value` as in the file (muscle pairs on both sides).
    pub controls: Vec<(String, f64)>,
    /// The AUs whose mean reading is reported.
    pub observed: Vec<usize>,
    pub landmark: String,
    /// The `ibug` cell as written, for the output's landmark column.
    pub ibug: String,
    pub measure: Measure,
    /// Published band (mm).
    pub band: Option<(f64, f64)>,
    /// facelab's own target (mm): where no band is published, or where stronger evidence
    /// puts the maximum beyond the published band (the real landmark data for the smile; the
    /// published band then says what a typical effort does, and `why` says both).
    pub chosen: Option<(f64, f64)>,
    pub why: String,
}

impl ReachRow {
    /// The band a measurement is judged by: facelab's choice where it gives one, else the
    /// published band.
    pub fn target(&self) -> Option<(f64, f64)> {
        self.chosen.or(self.band)
    }

    /// The `controls` cell as written.
    pub fn controls_text(&self) -> String {
        self.controls
            .iter()
            .map(|(n, v)| format!("{n}={v}"))
            .collect::<Vec<_>>()
            .join(";")
    }
}

#[derive(Debug, thiserror::Error)]
pub enum ReachFileError {
    #[error("{path}: {cause}")]
    Csv { path: PathBuf, cause: csv::Error },
    #[error("{path}:{line}: {message}")]
    Row {
        path: PathBuf,
        line: u64,
        message: String,
    },
    #[error("{path}: header must be `{}`, found `{found}`", HEADER.join(","))]
    Header { path: PathBuf, found: String },
}

fn landmark_list(cell: &str) -> Result<Vec<usize>, String> {
    let list: Vec<usize> = cell
        .split(';')
        .map(|s| {
            s.trim()
                .parse::<usize>()
                .ok()
                .filter(|&i| i < LANDMARK_COUNT)
                .ok_or_else(|| format!("`{}` is not an iBUG landmark (0-67)", s.trim()))
        })
        .collect::<Result<_, _>>()?;
    if list.is_empty() {
        return Err("no landmark".to_string());
    }
    Ok(list)
}

fn band(lo: &str, hi: &str, what: &str) -> Result<Option<(f64, f64)>, String> {
    match (lo.trim(), hi.trim()) {
        ("", "") => Ok(None),
        (a, b) => {
            let parse = |s: &str| {
                s.parse::<f64>()
                    .ok()
                    .filter(|v| v.is_finite() && *v >= 0.0)
                    .ok_or_else(|| format!("{what} `{s}` is not a number >= 0"))
            };
            let (a, b) = (parse(a)?, parse(b)?);
            if a > b {
                return Err(format!("{what} runs from {a} down to {b}"));
            }
            Ok(Some((a, b)))
        }
    }
}

/// Reads and checks the table.
pub fn read_reach(path: &Path) -> Result<Vec<ReachRow>, ReachFileError> {
    let csv_err = |cause| ReachFileError::Csv {
        path: path.to_path_buf(),
        cause,
    };
    let (header, records) = super::commented_csv(path).map_err(csv_err)?;
    if header != HEADER {
        return Err(ReachFileError::Header {
            path: path.to_path_buf(),
            found: header.join(","),
        });
    }
    let mut rows = Vec::new();
    for (line, record) in records {
        let row_err = |message: String| ReachFileError::Row {
            path: path.to_path_buf(),
            line,
            message,
        };
        let observed = record[2]
            .split(';')
            .map(|a| au_index(a).ok_or_else(|| format!("unknown AU `{}`", a.trim())))
            .collect::<Result<Vec<_>, _>>()
            .map_err(row_err)?;
        let measure = match record[5].trim() {
            "displacement" => Measure::Displacement(landmark_list(&record[4]).map_err(row_err)?),
            "separation" => {
                let (a, b) = record[4]
                    .split_once('|')
                    .ok_or_else(|| row_err("a separation needs `a|b` landmarks".to_string()))?;
                Measure::Separation(
                    landmark_list(a).map_err(row_err)?,
                    landmark_list(b).map_err(row_err)?,
                )
            }
            other => {
                return Err(row_err(format!(
                    "measure `{other}` is not `displacement` or `separation`"
                )))
            }
        };
        let band_published = band(&record[6], &record[7], "band").map_err(row_err)?;
        let chosen = band(&record[8], &record[9], "chosen").map_err(row_err)?;
        if band_published.is_none() && chosen.is_none() {
            return Err(row_err(
                "give the published band, facelab's chosen one, or both".to_string(),
            ));
        }
        if record[10].trim().is_empty() {
            return Err(row_err("every row needs its reason (`why`)".to_string()));
        }
        rows.push(ReachRow {
            row: record[0].trim().to_string(),
            controls: parse_controls(&record[1]).map_err(row_err)?,
            observed,
            landmark: record[3].trim().to_string(),
            ibug: record[4].trim().to_string(),
            measure,
            band: band_published,
            chosen,
            why: record[10].trim().to_string(),
        });
    }
    Ok(rows)
}

/// One row of `au_reach.csv`.
#[derive(Clone, Debug, PartialEq, Serialize, serde::Deserialize)]
pub struct ReachLine {
    pub au: String,
    pub controls: String,
    pub landmark: String,
    pub displacement_mm: String,
    pub band_min_mm: String,
    pub band_max_mm: String,
    pub observed: String,
}

impl crate::io::rows::CsvRow for ReachLine {}
