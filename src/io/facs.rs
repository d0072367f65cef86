//! FACS maps for Table 1 (`experiments/expression_aus.csv`, `experiments/au_muscles.csv`):
//! which AUs make each expression and which model controls make each AU. Errors name the
//! file and line.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use crate::observe::au::{au_index, AU_COUNT};
use crate::sim::expression::Expression;

use super::expressions::resolve_control;

pub const DEFAULT_EXPRESSION_AUS: &str = "experiments/expression_aus.csv";
pub const DEFAULT_AU_MUSCLES: &str = "experiments/au_muscles.csv";

#[derive(Debug, thiserror::Error)]
pub enum FacsFileError {
    #[error("{path}: {cause}")]
    Csv { path: PathBuf, cause: csv::Error },
    #[error("{path}:{line}: {message}")]
    Row {
        path: PathBuf,
        line: u64,
        message: String,
    },
}

#[derive(Clone, Debug, PartialEq)]
pub struct FacsMaps {
    /// Per expression (in `Expression::ALL` order): AU indices, sorted.
    pub expression_aus: Vec<Vec<usize>>,
    /// Per AU: control indices, sorted.
    pub au_controls: Vec<Vec<usize>>,
}

impl FacsMaps {
    /// The controls an expression's network predicts: the union over its AUs.
    pub fn expression_controls(&self, e: Expression) -> Vec<usize> {
        let set: BTreeSet<usize> = self.expression_aus[e as usize]
            .iter()
            .flat_map(|&au| self.au_controls[au].iter().copied())
            .collect();
        set.into_iter().collect()
    }
}

fn rows(path: &Path) -> Result<Vec<(u64, Vec<String>)>, FacsFileError> {
    let err = |cause| FacsFileError::Csv {
        path: path.to_path_buf(),
        cause,
    };
    let (_, records) = super::commented_csv(path).map_err(err)?;
    Ok(records
        .into_iter()
        .map(|(line, record)| (line, record.iter().map(|s| s.trim().to_string()).collect()))
        .collect())
}

pub fn read_facs(expression_aus: &Path, au_muscles: &Path) -> Result<FacsMaps, FacsFileError> {
    let mut ex: Vec<BTreeSet<usize>> = vec![BTreeSet::new(); Expression::ALL.len()];
    for (line, r) in rows(expression_aus)? {
        let row_err = |message: String| FacsFileError::Row {
            path: expression_aus.to_path_buf(),
            line,
            message,
        };
        if r.len() < 2 {
            return Err(row_err(format!(
                "{} column(s); expected 2: expression,au",
                r.len()
            )));
        }
        let e: Expression = r[0].parse().map_err(|e| row_err(format!("{e}")))?;
        let au = au_index(&r[1]).ok_or_else(|| row_err(format!("unknown AU `{}`", r[1])))?;
        ex[e as usize].insert(au);
    }
    let mut au: Vec<BTreeSet<usize>> = vec![BTreeSet::new(); AU_COUNT];
    for (line, r) in rows(au_muscles)? {
        let row_err = |message: String| FacsFileError::Row {
            path: au_muscles.to_path_buf(),
            line,
            message,
        };
        if r.len() < 2 {
            return Err(row_err(format!(
                "{} column(s); expected 2: au,controls",
                r.len()
            )));
        }
        let a = au_index(&r[0]).ok_or_else(|| row_err(format!("unknown AU `{}`", r[0])))?;
        for c in resolve_control(&r[1]).map_err(row_err)? {
            au[a].insert(c);
        }
    }
    for (e, aus) in Expression::ALL.iter().zip(&ex) {
        if aus.is_empty() {
            return Err(FacsFileError::Row {
                path: expression_aus.to_path_buf(),
                line: 0,
                message: format!("{e} has no AUs"),
            });
        }
    }
    Ok(FacsMaps {
        expression_aus: ex.into_iter().map(|s| s.into_iter().collect()).collect(),
        au_controls: au.into_iter().map(|s| s.into_iter().collect()).collect(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A one-column table used to index past its row (a panic); it is now an error naming
    /// the file and line.
    #[test]
    fn a_one_column_table_is_an_error_not_a_panic() {
        let dir = std::env::temp_dir().join(format!("facelab-facs-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let one = dir.join("one.csv");
        std::fs::write(&one, "expression\njoy\n").unwrap();
        let (ea, am) = crate::io::Layout::here().facs();
        let err = read_facs(&one, &am).unwrap_err().to_string();
        assert!(
            err.contains("one.csv:2") && err.contains("expected 2"),
            "{err}"
        );
        std::fs::write(&one, "au\nAU12\n").unwrap();
        let err = read_facs(&ea, &one).unwrap_err().to_string();
        assert!(
            err.contains("one.csv:2") && err.contains("expected 2"),
            "{err}"
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
