//! The raw layer: a spec file as a tree of values, each remembering where it was written
//! (file, line, column, or the `--set` that gave it), with `extends` chains merged and
//! command-line overrides applied. Nothing here knows which keys exist; `resolve` does.

use crate::io::Layout;
use std::collections::BTreeMap;
use std::fmt;
use std::path::{Path, PathBuf};

use toml::de::{DeTable, DeValue};

use super::SpecError;

/// Where a value came from.
#[derive(Clone, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum Origin {
    File {
        path: PathBuf,
        line: usize,
        column: usize,
    },
    Set(String),
    Sweep {
        path: PathBuf,
        line: usize,
        column: usize,
    },
}

impl fmt::Display for Origin {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Origin::File { path, line, column } => {
                write!(f, "{}:{line}:{column}", path.display())
            }
            Origin::Set(text) => write!(f, "--set {text}"),
            Origin::Sweep { path, line, column } => {
                write!(f, "{}:{line}:{column} (sweep)", path.display())
            }
        }
    }
}

#[derive(Clone, Debug, PartialEq)]
pub enum Value {
    Integer(i64),
    Float(f64),
    Bool(bool),
    String(String),
    Array(Vec<Node>),
    Table(BTreeMap<String, Node>),
}

impl Value {
    pub fn type_name(&self) -> &'static str {
        match self {
            Value::Integer(_) => "an integer",
            Value::Float(_) => "a float",
            Value::Bool(_) => "a boolean",
            Value::String(_) => "a string",
            Value::Array(_) => "an array",
            Value::Table(_) => "a table",
        }
    }
}

#[derive(Clone, Debug, PartialEq)]
pub struct Node {
    pub value: Value,
    pub origin: Origin,
}

impl Node {
    /// The value as TOML text (for resolved specs, cache keys and sweep cell names).
    pub fn to_toml(&self) -> toml::Value {
        match &self.value {
            Value::Integer(i) => toml::Value::Integer(*i),
            Value::Float(x) => toml::Value::Float(*x),
            Value::Bool(b) => toml::Value::Boolean(*b),
            Value::String(s) => toml::Value::String(s.clone()),
            Value::Array(a) => toml::Value::Array(a.iter().map(Node::to_toml).collect()),
            Value::Table(t) => {
                toml::Value::Table(t.iter().map(|(k, v)| (k.clone(), v.to_toml())).collect())
            }
        }
    }
}

fn line_column(text: &str, offset: usize) -> (usize, usize) {
    let before = &text[..offset.min(text.len())];
    let line = before.matches('\n').count() + 1;
    let column = before.len() - before.rfind('\n').map_or(0, |i| i + 1) + 1;
    (line, column)
}

/// Converts a parsed (spanned) value; numbers are read back through `toml::Value` so every
/// TOML number form (underscores, hex, inf) parses as TOML says.
fn convert(value: &DeValue<'_>, span: std::ops::Range<usize>, text: &str, path: &Path) -> Node {
    let (line, column) = line_column(text, span.start);
    let origin = Origin::File {
        path: path.to_path_buf(),
        line,
        column,
    };
    let scalar = |raw: &str| -> toml::Value {
        toml::from_str::<toml::Table>(&format!("v = {raw}"))
            .ok()
            .and_then(|t| t.get("v").cloned())
            .unwrap_or(toml::Value::String(raw.to_string()))
    };
    let value = match value {
        DeValue::String(s) => Value::String(s.to_string()),
        DeValue::Integer(i) => match scalar(&text[span.clone()]) {
            toml::Value::Integer(v) => Value::Integer(v),
            _ => Value::String(i.as_str().to_string()),
        },
        DeValue::Float(x) => match scalar(&text[span.clone()]) {
            toml::Value::Float(v) => Value::Float(v),
            _ => Value::String(x.as_str().to_string()),
        },
        DeValue::Boolean(b) => Value::Bool(*b),
        DeValue::Datetime(d) => Value::String(d.to_string()),
        DeValue::Array(a) => Value::Array(
            a.iter()
                .map(|v| convert(v.get_ref(), v.span(), text, path))
                .collect(),
        ),
        DeValue::Table(t) => Value::Table(table(t, text, path)),
    };
    Node { value, origin }
}

fn table(t: &DeTable<'_>, text: &str, path: &Path) -> BTreeMap<String, Node> {
    t.iter()
        .map(|(k, v)| {
            // Point at the key, not the value, so `unknown key` errors land on its name.
            let mut node = convert(v.get_ref(), v.span(), text, path);
            if !matches!(node.value, Value::Table(_)) {
                let (line, column) = line_column(text, k.span().start);
                node.origin = Origin::File {
                    path: path.to_path_buf(),
                    line,
                    column,
                };
            }
            (k.get_ref().to_string(), node)
        })
        .collect()
}

/// Parses one file (no `extends` handling).
pub fn parse_file(path: &Path) -> Result<BTreeMap<String, Node>, SpecError> {
    let text = std::fs::read_to_string(path).map_err(|e| SpecError::Io {
        path: path.to_path_buf(),
        message: e.to_string(),
    })?;
    parse_text(&text, path)
}

pub fn parse_text(text: &str, path: &Path) -> Result<BTreeMap<String, Node>, SpecError> {
    let parsed = DeTable::parse(text).map_err(|e| {
        let (line, column) = e
            .span()
            .map(|s| line_column(text, s.start))
            .unwrap_or((1, 1));
        SpecError::Syntax {
            origin: Origin::File {
                path: path.to_path_buf(),
                line,
                column,
            },
            message: e.message().to_string(),
        }
    })?;
    Ok(table(parsed.get_ref(), text, path))
}

/// `base` with `over` merged in: tables merge key by key, anything else is replaced.
pub fn merge(base: &mut BTreeMap<String, Node>, over: BTreeMap<String, Node>) {
    for (k, v) in over {
        match (base.get_mut(&k), v) {
            (
                Some(Node {
                    value: Value::Table(b),
                    ..
                }),
                Node {
                    value: Value::Table(o),
                    ..
                },
            ) => merge(b, o),
            (_, v) => {
                base.insert(k, v);
            }
        }
    }
}

/// Loads `path` with its `extends` chain (each relative to the file naming it), base first.
pub fn load(layout: &Layout, path: &Path) -> Result<BTreeMap<String, Node>, SpecError> {
    let mut chain: Vec<(PathBuf, String)> = Vec::new();
    load_chain(layout, path, &mut chain)
}

/// `path` relative to the working folder where it lies below it, else as it is.
fn shown(path: &Path) -> String {
    let cwd = std::env::current_dir().and_then(|d| d.canonicalize());
    match cwd.as_ref().map(|d| path.strip_prefix(d)) {
        Ok(Ok(rel)) => rel.display().to_string(),
        _ => path.display().to_string(),
    }
}

/// Loads one file of an `extends` chain; `chain` holds the files above it, each with how it
/// names its base (`file:line`, for the cycle message).
fn load_chain(
    layout: &Layout,
    path: &Path,
    chain: &mut Vec<(PathBuf, String)>,
) -> Result<BTreeMap<String, Node>, SpecError> {
    let canonical = path.canonicalize().map_err(|e| SpecError::Io {
        path: path.to_path_buf(),
        message: e.to_string(),
    })?;
    if chain.iter().any(|(p, _)| *p == canonical) {
        let mut steps: Vec<String> = chain.iter().map(|(_, at)| at.clone()).collect();
        steps.push(shown(&canonical));
        return Err(SpecError::Cycle(steps.join(" -> ")));
    }
    let mut own = parse_file(path)?;
    if own.is_empty() {
        return Err(SpecError::Empty {
            path: path.to_path_buf(),
        });
    }
    let line = match own.get("extends").map(|n| &n.origin) {
        Some(Origin::File { line, .. }) => format!(":{line}"),
        _ => String::new(),
    };
    chain.push((
        canonical.clone(),
        format!("{}{line} extends", shown(&canonical)),
    ));
    let result = match own.remove("extends") {
        None => own,
        Some(Node {
            value: Value::String(base),
            origin,
        }) => {
            // Beside the spec, else a spec of the checkout or the binary's built-in copy
            // (`extends = "experiments/paper.toml"` from a spec of one's own, anywhere).
            let mut base_path = path.parent().unwrap_or(Path::new(".")).join(&base);
            if !base_path.exists() && Path::new(&base).is_relative() {
                let found = layout.file(&base);
                if found.exists() {
                    base_path = found;
                }
            }
            if !base_path.exists() {
                return Err(SpecError::Invalid {
                    origin,
                    key: "extends".into(),
                    message: format!("{} does not exist", base_path.display()),
                });
            }
            let mut merged = load_chain(layout, &base_path, chain)?;
            merge(&mut merged, own);
            merged
        }
        Some(other) => {
            return Err(SpecError::Invalid {
                origin: other.origin,
                key: "extends".into(),
                message: format!(
                    "must be a file name (a string), not {}",
                    other.value.type_name()
                ),
            })
        }
    };
    chain.pop();
    Ok(result)
}

/// Sets `dotted.key = value` in the tree, creating tables on the way.
pub fn set_path(tree: &mut BTreeMap<String, Node>, key: &str, node: Node) -> Result<(), SpecError> {
    let parts: Vec<&str> = key.split('.').collect();
    let mut table = tree;
    for (i, part) in parts.iter().enumerate() {
        if i + 1 == parts.len() {
            table.insert(part.to_string(), node);
            return Ok(());
        }
        let entry = table.entry(part.to_string()).or_insert_with(|| Node {
            value: Value::Table(BTreeMap::new()),
            origin: node.origin.clone(),
        });
        table = match &mut entry.value {
            Value::Table(t) => t,
            other => {
                return Err(SpecError::Invalid {
                    origin: node.origin.clone(),
                    key: parts[..=i].join("."),
                    message: format!("is {}, not a table", other.type_name()),
                })
            }
        };
    }
    Ok(())
}

/// Parses the right-hand side of `--set key=value` as a TOML value (bare words are strings).
pub fn parse_override(text: &str) -> Result<(String, Node), SpecError> {
    let (key, raw) = text.split_once('=').ok_or_else(|| SpecError::Override {
        text: text.to_string(),
        message: "expected key=value".into(),
    })?;
    let origin = Origin::Set(text.to_string());
    let value = match toml::from_str::<toml::Table>(&format!("v = {}", raw.trim())) {
        Ok(t) => t.get("v").cloned().expect("parsed v"),
        Err(_) => toml::Value::String(raw.trim().to_string()),
    };
    Ok((key.trim().to_string(), from_toml(&value, &origin)))
}

/// A `toml::Value` as a node with one origin for all of it.
pub fn from_toml(value: &toml::Value, origin: &Origin) -> Node {
    let value = match value {
        toml::Value::Integer(i) => Value::Integer(*i),
        toml::Value::Float(x) => Value::Float(*x),
        toml::Value::Boolean(b) => Value::Bool(*b),
        toml::Value::String(s) => Value::String(s.clone()),
        toml::Value::Datetime(d) => Value::String(d.to_string()),
        toml::Value::Array(a) => Value::Array(a.iter().map(|v| from_toml(v, origin)).collect()),
        toml::Value::Table(t) => Value::Table(
            t.iter()
                .map(|(k, v)| (k.clone(), from_toml(v, origin)))
                .collect(),
        ),
    };
    Node {
        value,
        origin: origin.clone(),
    }
}
