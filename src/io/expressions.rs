//! Expression weight tables (`experiments/expressions.csv`): columns
//! `expression,control,weight,reason`. `control` is a muscle pair name (both sides get the
//! weight), a full control name (`zygomaticus_major_left`) or `jaw_rotation`.

use std::path::{Path, PathBuf};

use crate::sim::controls::{control_index, control_names, edit_distance, JAW_SLIDE, JAW_TWIST};
use crate::sim::expression::{Expression, ExpressionWeights};
use crate::sim::muscles::{Side, MUSCLE_PAIRS};
use crate::sim::Activations;

pub const DEFAULT_EXPRESSIONS: &str = "experiments/expressions.csv";

#[derive(Debug, thiserror::Error)]
pub enum ExpressionFileError {
    #[error("{path}: {cause}")]
    Csv { path: PathBuf, cause: csv::Error },
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

/// Parses a `name=value;name=value` cell of a data file (names as `resolve_control` takes
/// them), checking every name.
pub fn parse_controls(cell: &str) -> Result<Vec<(String, f64)>, String> {
    let mut controls = Vec::new();
    for item in cell.split(';').filter(|s| !s.trim().is_empty()) {
        let (name, value) = item
            .split_once('=')
            .ok_or_else(|| format!("`{item}` is not name=value"))?;
        let value: f64 = value
            .trim()
            .parse()
            .map_err(|_| format!("`{}` is not a number", value.trim()))?;
        resolve_control(name.trim())?;
        controls.push((name.trim().to_string(), value));
    }
    Ok(controls)
}

/// The activations that parsed controls set (a muscle pair on both sides), from neutral.
pub fn controls_activations(controls: &[(String, f64)]) -> Result<Activations, String> {
    let mut a = Activations::neutral();
    for (name, value) in controls {
        for index in resolve_control(name)? {
            a.set_index(index, *value).map_err(|e| e.to_string())?;
        }
    }
    Ok(a)
}

/// Reads W_e for the six expressions.
pub fn read_expressions(path: &Path) -> Result<ExpressionWeights, ExpressionFileError> {
    let csv_err = |cause| ExpressionFileError::Csv {
        path: path.to_path_buf(),
        cause,
    };
    let (header, records) = super::commented_csv(path).map_err(csv_err)?;
    if header != ["expression", "control", "weight", "reason"] {
        return Err(ExpressionFileError::Header {
            path: path.to_path_buf(),
            found: header.join(","),
        });
    }
    let mut weights = ExpressionWeights::default();
    for (line, record) in records {
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
