//! Sweeps: `[sweep]` axes expanded into named cells, each a resolved spec.

use crate::io::Layout;
use crate::spec::raw::{set_path, Node, Origin, Value};
use crate::spec::SpecError;
use std::collections::BTreeMap;
use std::path::Path;

use super::*;

/// Flattens `[sweep]` into dotted keys with their value lists.
pub(super) fn sweep_axes(
    sweep: &Node,
    prefix: &str,
    out: &mut Vec<(String, Node)>,
) -> Result<(), SpecError> {
    match &sweep.value {
        Value::Table(t) => {
            for (k, v) in t {
                let key = if prefix.is_empty() {
                    k.clone()
                } else {
                    format!("{prefix}.{k}")
                };
                sweep_axes(v, &key, out)?;
            }
            Ok(())
        }
        Value::Array(items) if !items.is_empty() => {
            out.push((prefix.to_string(), sweep.clone()));
            Ok(())
        }
        _ => Err(SpecError::Invalid {
            origin: sweep.origin.clone(),
            key: format!("sweep.{prefix}"),
            message: "must be a non-empty list of values".into(),
        }),
    }
}

/// Expands `[sweep]` as a grid (keys in sorted order, values in file order) and resolves each
/// cell. A sweep key that no stage reads is an unknown key at the sweep's line.
pub fn cells(
    mut tree: BTreeMap<String, Node>,
    file: &Path,
    layout: &Layout,
) -> Result<Vec<Cell>, SpecError> {
    let Some(sweep) = tree.remove("sweep") else {
        return Ok(vec![Cell {
            name: String::new(),
            spec: resolve(&tree, file, layout)?,
        }]);
    };
    let mut axes = Vec::new();
    sweep_axes(&sweep, "", &mut axes)?;
    let mut grid: Vec<Vec<(String, Node)>> = vec![Vec::new()];
    for (key, list) in &axes {
        let Value::Array(items) = &list.value else {
            unreachable!("sweep_axes keeps arrays")
        };
        let mut next = Vec::new();
        for cell in &grid {
            for item in items {
                let mut c = cell.clone();
                let origin = match &item.origin {
                    Origin::File { path, line, column } => Origin::Sweep {
                        path: path.clone(),
                        line: *line,
                        column: *column,
                    },
                    other => other.clone(),
                };
                c.push((
                    key.clone(),
                    Node {
                        value: item.value.clone(),
                        origin,
                    },
                ));
                next.push(c);
            }
        }
        grid = next;
    }
    let mut out = Vec::with_capacity(grid.len());
    for cell in grid {
        let mut t = tree.clone();
        let mut name = Vec::new();
        for (key, node) in cell {
            name.push(format!("{key}={}", node.to_toml()));
            set_path(&mut t, &key, node)?;
        }
        out.push(Cell {
            name: name.join(","),
            spec: resolve(&t, file, layout)?,
        });
    }
    Ok(out)
}
