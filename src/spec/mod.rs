//! Experiment specs: TOML files in `experiments/` -> a validated, total `Spec` per sweep
//! cell (DESIGN 2.5). Two layers: `raw` mirrors the files (with `extends`, `--set` and where
//! every value was written), `resolve` reads it into the parameter types that live beside the
//! code they configure. The only module that knows TOML.

pub mod raw;
pub mod resolve;

use crate::io::Layout;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

pub use raw::Origin;
pub use resolve::{Cell, InversionParams, LauncherKind, LauncherParams, Spec, Table};

#[derive(Debug, thiserror::Error, PartialEq)]
pub enum SpecError {
    #[error("{path}: {message}")]
    Io { path: PathBuf, message: String },
    #[error("{origin}: {message}")]
    Syntax { origin: Origin, message: String },
    #[error("{origin}: `{key}` {message}")]
    Invalid {
        origin: Origin,
        key: String,
        message: String,
    },
    #[error("{origin}: unknown key `{key}`{suggestion}")]
    Unknown {
        origin: Origin,
        key: String,
        suggestion: String,
    },
    #[error("`extends` cycle: {0}")]
    Cycle(String),
    #[error("{path}: the spec is empty (it sets no key; a spec names at least `experiment` or `extends`)")]
    Empty { path: PathBuf },
    #[error("--set {text}: {message}")]
    Override { text: String, message: String },
}

/// Loads a spec file with its `extends` chain and `--set` overrides, and resolves every
/// sweep cell; its data files (and an `extends` that is not beside it) are found with
/// `layout`, which each cell's spec keeps for the stages.
pub fn load(layout: &Layout, path: &Path, sets: &[String]) -> Result<Vec<Cell>, SpecError> {
    let mut tree = raw::load(layout, path)?;
    for text in sets {
        let (key, node) = raw::parse_override(text)?;
        raw::set_path(&mut tree, &key, node)?;
    }
    resolve::cells(tree, path, layout)
}

/// The resolved values of a cell as TOML text (`Spec::to_toml`).
fn to_toml(values: &BTreeMap<String, toml::Value>) -> String {
    let mut root = toml::Table::new();
    for (key, value) in values {
        let parts: Vec<&str> = key.split('.').collect();
        let mut table = &mut root;
        for part in &parts[..parts.len() - 1] {
            table = table
                .entry(part.to_string())
                .or_insert_with(|| toml::Value::Table(toml::Table::new()))
                .as_table_mut()
                .expect("spec keys never mix tables and values");
        }
        table.insert(parts[parts.len() - 1].to_string(), value.clone());
    }
    toml::to_string(&root).expect("TOML values serialize")
}
