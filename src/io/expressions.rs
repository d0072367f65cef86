//! Expression weight tables (`experiments/expressions.csv`): columns
//! `expression,control,weight,reason`. `control` is a muscle pair name (both sides get the
//! weight), a full control name (`zygomaticus_major_left`) or `jaw_rotation`.

use std::path::{Path, PathBuf};

use crate::sim::controls::{control_index, control_names, edit_distance, JAW_SLIDE, JAW_TWIST};
use crate::sim::expression::{Expression, ExpressionWeights};
use crate::sim::muscles::{Side, MUSCLE_PAIRS};

pub const DEFAULT_EXPRESSIONS: &str = "experiments/expressions.csv";

/// The default weights path, resolved against the crate root when not found locally.
pub fn default_expressions_path() -> PathBuf {
    super::data_path(DEFAULT_EXPRESSIONS)
}

#[derive(Debug, thiserror::Error)]
pub enum ExpressionFileError {
    #[error("{path}: {source}")]
    Csv { path: PathBuf, source: csv::Error },
    #[error("{path}:{line}: {message}")]
    Row {
        path: PathBuf,
        line: u64,
        message: String,
    },
    #[error("{path}: header must be `expression,control,weight,reason`, found `{found}`")]
    Header { path: PathBuf, found: String },
}

/// The control indices a name in a data file stands for: a muscle pair (both sides) or one
/// control. Unknown names get the nearest valid one suggested.
pub fn resolve_control(name: &str) -> Result<Vec<usize>, String> {
    if let Some(pair) = MUSCLE_PAIRS.iter().position(|m| m.name == name) {
        return Ok([Side::Left, Side::Right]
            .map(|side| crate::sim::controls::muscle_index(pair, side))
            .to_vec());
    }
    if let Some(index) = control_index(name) {
        return Ok(vec![index]);
    }
    let nearest = MUSCLE_PAIRS
        .iter()
        .map(|m| m.name.to_string())
        .chain(control_names().iter().cloned())
        .min_by_key(|c| edit_distance(name, c))
        .unwrap_or_default();
    Err(format!(
        "unknown control `{name}` (did you mean `{nearest}`?)"
    ))
}

/// Reads W_e for the six expressions.
pub fn read_expressions(path: &Path) -> Result<ExpressionWeights, ExpressionFileError> {
    let csv_err = |source| ExpressionFileError::Csv {
        path: path.to_path_buf(),
        source,
    };
    let mut reader = csv::ReaderBuilder::new()
        .comment(Some(b'#'))
        .from_path(path)
        .map_err(csv_err)?;
    let header: Vec<String> = reader
        .headers()
        .map_err(csv_err)?
        .iter()
        .map(str::to_string)
        .collect();
    if header != ["expression", "control", "weight", "reason"] {
        return Err(ExpressionFileError::Header {
            path: path.to_path_buf(),
            found: header.join(","),
        });
    }
    let mut weights = ExpressionWeights::default();
    for record in reader.records() {
        let record = record.map_err(csv_err)?;
        let line = record.position().map_or(0, |p| p.line());
        let row_err = |message: String| ExpressionFileError::Row {
            path: path.to_path_buf(),
            line,
            message,
        };
        let expression: Expression = record[0].parse().map_err(|e| row_err(format!("{e}")))?;
        let weight: f64 = record[2]
            .trim()
            .parse()
            .map_err(|_| row_err(format!("weight `{}` is not a number", &record[2])))?;
        if !(0.0..=1.0).contains(&weight) {
            return Err(row_err(format!("weight {weight} is outside [0, 1]")));
        }
        if record[3].trim().is_empty() {
            return Err(row_err("every weight needs a reason".to_string()));
        }
        for index in resolve_control(record[1].trim()).map_err(row_err)? {
            if index == JAW_SLIDE || index == JAW_TWIST {
                return Err(row_err(format!(
                    "`{}` stays neutral (0.5) in expressions (paper 4.2)",
                    record[1].trim()
                )));
            }
            weights.set(expression, index, weight);
        }
    }
    Ok(weights)
}
