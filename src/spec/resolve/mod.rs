//! The resolved layer: reads the raw tree into the parameter types of each stage, checking
//! types and ranges, filling defaults, and rejecting keys nobody reads (with the nearest
//! valid name suggested). Sweeps expand here into named cells.

use crate::io::{DataFile, Layout};
use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

use crate::cohort::CohortParams;
use crate::dataset::reader::Source;
use crate::dataset::{DatasetParams, Family, SolveStart};
use crate::headneck::HeadposeParams;
use crate::io::calibration::DEFAULT_CALIBRATION;
use crate::io::realdata::RealfacesParams;
use crate::learn::params::{ModelParams, Normalization, TrainParams};
use crate::observe::ObserverNoise;
use crate::sim::controls::edit_distance;
use crate::spec::raw::{Node, Value};
use crate::spec::SpecError;

mod sections;
mod sweep;

use sections::*;
pub use sections::{InversionParams, LauncherKind, LauncherParams};
pub use sweep::cells;

/// A table a spec's `tables` can ask for.
#[derive(
    Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, serde::Serialize, serde::Deserialize,
)]
#[serde(rename_all = "snake_case")]
pub enum Table {
    Table1,
    Table2,
    Inversion,
    Headpose,
    Realfaces,
    Photos,
}

impl Table {
    pub const ALL: [Table; 6] = [
        Table::Table1,
        Table::Table2,
        Table::Inversion,
        Table::Headpose,
        Table::Realfaces,
        Table::Photos,
    ];

    /// Its name in `tables` (and its results folder's).
    pub fn name(self) -> &'static str {
        match self {
            Table::Table1 => "table1",
            Table::Table2 => "table2",
            Table::Inversion => "inversion",
            Table::Headpose => "headpose",
            Table::Realfaces => "realfaces",
            Table::Photos => "photos",
        }
    }

    pub fn parse(name: &str) -> Option<Table> {
        Table::ALL.into_iter().find(|t| t.name() == name)
    }

    /// The tables whose products it reads, which a spec that lists it must list too (each
    /// runs before it: `experiments::REGISTRY`'s order, which a test checks against this).
    pub fn needs(self) -> &'static [Table] {
        match self {
            // Table 2's cohorts and the unified network.
            Table::Inversion => &[Table::Table2],
            _ => &[],
        }
    }

    /// Why it needs each of [`Table::needs`].
    fn why(self) -> &'static str {
        match self {
            Table::Inversion => "whose cohorts and network it uses",
            _ => "",
        }
    }
}

/// Everything a run needs, validated.
#[derive(Clone, Debug, PartialEq)]
pub struct Spec {
    /// `experiment`; default the file's stem. Names `results/<experiment>/`.
    pub experiment: String,
    /// Master seeds; each runs the whole pipeline. Default [1].
    pub seeds: Vec<u64>,
    /// Which tables to make: "table1", "table2". Default ["table1"]. Table 2 needs the
    /// unified network of Table 1's training stage, so it always trains it.
    pub tables: Vec<Table>,
    pub dataset: DatasetParams,
    pub observer: ObserverNoise,
    /// The observer's calibration (`observer.calibration`): the gains table
    /// `experiments/au_calibration.csv` (default) or a readout fitted to OpenFace
    /// (`experiments/au_observer_fit.csv`), relative to the repository.
    pub calibration: DataFile,
    /// Where the observer reads simulated faces from (`observer.source`: "mesh", the
    /// default, or "render": a picture of the face through the landmarker).
    pub observer_source: Source,
    pub model: ModelParams,
    pub train: TrainParams,
    /// The reference cohorts (`[cohort]`), used when `tables` has "table2".
    pub cohort: CohortParams,
    /// How Table 2's normalized rows map reference AUs into the training range
    /// (`table2.normalization`: "minmax" or "zscore"; default "minmax").
    pub table2_normalization: Normalization,
    /// A committed real OpenFace file whose transfer Table 2 reports beside the cohorts
    /// (`table2.openface`, relative to the repository; unset: none).
    pub table2_openface: Option<DataFile>,
    /// The inversion table (`[inversion]`), used when `tables` has "inversion".
    pub inversion: InversionParams,
    /// The head-neck experiment (`[headpose]`), used when `tables` has "headpose".
    pub headpose: HeadposeParams,
    /// The real-data table (`[realfaces]`), used when `tables` has "realfaces".
    pub realfaces: RealfacesParams,
    /// Where the run's units of work run (`[launcher]`).
    pub launcher: LauncherParams,
    /// Prefix of the paper-table and figure names (`report.prefix`), so a smoke or test run
    /// does not overwrite the committed `paper-tables/table1.md`. Default "".
    pub report_prefix: String,
    /// Where the checkout's files are: the spec's data files were found with it, and the
    /// stages find the face, the FACS tables and the photo list with it.
    pub layout: Layout,
    /// Every value read, with defaults filled in, by dotted key: what `to_toml` writes.
    /// Nothing past the spec layer reads it; stages read the typed fields.
    pub(in crate::spec) values: BTreeMap<String, toml::Value>,
}

/// One point of a sweep grid (the only one when there is no `[sweep]`).
#[derive(Clone, Debug, PartialEq)]
pub struct Cell {
    /// `key=value` pairs of this cell joined by `,`, or empty without a sweep.
    pub name: String,
    pub spec: Spec,
}

/// Typed, recorded access to the raw tree.
struct Reader<'a> {
    tree: &'a BTreeMap<String, Node>,
    file: &'a Path,
    layout: &'a Layout,
    known: BTreeSet<String>,
    values: BTreeMap<String, toml::Value>,
}

fn lookup<'a>(tree: &'a BTreeMap<String, Node>, key: &str) -> Option<&'a Node> {
    let mut parts = key.split('.');
    let mut node = tree.get(parts.next()?)?;
    for part in parts {
        match &node.value {
            Value::Table(t) => node = t.get(part)?,
            _ => return None,
        }
    }
    Some(node)
}

impl Spec {
    /// The default mesh and weights with the face keys of `[dataset]`.
    pub fn face_source(&self) -> crate::io::face::FaceSource {
        crate::io::face::FaceSource {
            subdivisions: self.dataset.subdivisions,
            shear_modulus_fraction: Some(self.dataset.shear_modulus_fraction),
            ..crate::io::face::FaceSource::of(&self.layout)
        }
    }

    /// Whether faces are read with the readout fitted to OpenFace, so that the observer's
    /// AUs and a real file's are on the same scale.
    pub fn reads_on_openface_scale(&self) -> bool {
        self.calibration == crate::io::observer_fit::DEFAULT_READOUT
    }

    /// The resolved spec as TOML text, every key a file or `--set` wrote and every default
    /// read (what a run records as its cell's `spec.toml`, and `verify` reruns).
    pub fn to_toml(&self) -> String {
        super::to_toml(&self.values)
    }

    /// Whether the resolved spec records `key` (a dotted key, or a section's prefix ending
    /// in `.`).
    pub fn records(&self, key: &str) -> bool {
        self.values
            .keys()
            .any(|k| k == key || (key.ends_with('.') && k.starts_with(key)))
    }
}

impl<'a> Reader<'a> {
    fn invalid(&self, node: &Node, key: &str, message: String) -> SpecError {
        SpecError::Invalid {
            origin: node.origin.clone(),
            key: key.to_string(),
            message,
        }
    }

    fn get(&mut self, key: &str) -> Option<&'a Node> {
        self.known.insert(key.to_string());
        lookup(self.tree, key)
    }

    fn float(
        &mut self,
        key: &str,
        default: f64,
        valid: &dyn Fn(f64) -> Option<String>,
    ) -> Result<f64, SpecError> {
        let value = match self.get(key) {
            None => default,
            Some(node) => {
                let v = match node.value {
                    Value::Float(x) => x,
                    Value::Integer(i) => i as f64,
                    ref other => {
                        return Err(self.invalid(
                            node,
                            key,
                            format!("must be a number, not {}", other.type_name()),
                        ))
                    }
                };
                if let Some(message) = valid(v) {
                    return Err(self.invalid(node, key, message));
                }
                v
            }
        };
        self.values.insert(key.into(), toml::Value::Float(value));
        Ok(value)
    }

    fn integer(&mut self, key: &str, default: i64, min: i64, max: i64) -> Result<i64, SpecError> {
        let value = match self.get(key) {
            None => default,
            Some(node) => match node.value {
                Value::Integer(i) if (min..=max).contains(&i) => i,
                Value::Integer(i) => {
                    return Err(self.invalid(node, key, format!("= {i} is outside [{min}, {max}]")))
                }
                ref other => {
                    return Err(self.invalid(
                        node,
                        key,
                        format!("must be an integer, not {}", other.type_name()),
                    ))
                }
            },
        };
        self.values.insert(key.into(), toml::Value::Integer(value));
        Ok(value)
    }

    /// Keys added after runs were committed are recorded in `values` (and so in cache keys
    /// and a run's `spec.toml`) only when a spec sets them, so that those runs' keys and
    /// outputs stay valid.
    fn forget_if_unset(&mut self, key: &str) {
        if lookup(self.tree, key).is_none() {
            self.values.remove(key);
        }
    }

    /// A data file, named relative to the repository (as `experiments/au_calibration.csv`),
    /// found with the layout; it must exist.
    fn data_file(&mut self, key: &str, default: &str) -> Result<DataFile, SpecError> {
        let value = match self.get(key) {
            None => self.layout.data_file(default),
            Some(node) => match &node.value {
                Value::String(s) => {
                    let file = self.layout.data_file(s);
                    if !file.path.is_file() {
                        return Err(self.invalid(
                            node,
                            key,
                            format!(
                                "= \"{s}\": no such file (paths are relative to the repository)"
                            ),
                        ));
                    }
                    file
                }
                other => {
                    return Err(self.invalid(
                        node,
                        key,
                        format!("must be a string, not {}", other.type_name()),
                    ))
                }
            },
        };
        self.values
            .insert(key.into(), toml::Value::String(value.name.clone()));
        Ok(value)
    }

    fn choice(&mut self, key: &str, default: &str, allowed: &[&str]) -> Result<String, SpecError> {
        let value = match self.get(key) {
            None => default.to_string(),
            Some(node) => match &node.value {
                Value::String(s) if allowed.contains(&s.as_str()) => s.clone(),
                Value::String(s) => {
                    return Err(self.invalid(
                        node,
                        key,
                        format!("= \"{s}\" is not one of {}", allowed.join(", ")),
                    ))
                }
                other => {
                    return Err(self.invalid(
                        node,
                        key,
                        format!("must be a string, not {}", other.type_name()),
                    ))
                }
            },
        };
        self.values
            .insert(key.into(), toml::Value::String(value.clone()));
        Ok(value)
    }

    fn list(&mut self, key: &str, default: Vec<toml::Value>) -> Result<Vec<&'a Node>, SpecError> {
        match self.get(key) {
            None => {
                self.values.insert(key.into(), toml::Value::Array(default));
                Ok(Vec::new())
            }
            Some(node) => match &node.value {
                Value::Array(items) if !items.is_empty() => {
                    self.values.insert(key.into(), node.to_toml());
                    Ok(items.iter().collect())
                }
                Value::Array(_) => Err(self.invalid(node, key, "must not be empty".into())),
                other => Err(self.invalid(
                    node,
                    key,
                    format!("must be an array, not {}", other.type_name()),
                )),
            },
        }
    }

    /// Every leaf in the tree must have been read.
    fn finish(self) -> Result<BTreeMap<String, toml::Value>, SpecError> {
        fn walk(
            prefix: &str,
            tree: &BTreeMap<String, Node>,
            known: &BTreeSet<String>,
        ) -> Result<(), SpecError> {
            for (k, node) in tree {
                let key = if prefix.is_empty() {
                    k.clone()
                } else {
                    format!("{prefix}.{k}")
                };
                if known.contains(&key) {
                    continue;
                }
                if let Value::Table(t) = &node.value {
                    if known.iter().any(|n| n.starts_with(&format!("{key}."))) {
                        walk(&key, t, known)?;
                        continue;
                    }
                }
                let nearest = known
                    .iter()
                    .min_by_key(|n| edit_distance(&key, n))
                    .filter(|n| edit_distance(&key, n) <= key.len().max(4) / 2 + 1);
                return Err(SpecError::Unknown {
                    origin: node.origin.clone(),
                    key,
                    suggestion: nearest
                        .map(|n| format!(" (did you mean `{n}`?)"))
                        .unwrap_or_default(),
                });
            }
            Ok(())
        }
        walk("", self.tree, &self.known)?;
        let _ = self.file;
        Ok(self.values)
    }
}

/// `tables`: which tables the spec makes (default Table 1 alone).
fn read_tables(r: &mut Reader) -> Result<Vec<Table>, SpecError> {
    let mut tables = Vec::new();
    for node in r.list("tables", vec![toml::Value::String("table1".into())])? {
        match &node.value {
            Value::String(s) if Table::parse(s).is_some() => {
                tables.push(Table::parse(s).expect("checked"))
            }
            _ => {
                return Err(r.invalid(
                    node,
                    "tables",
                    format!(
                        "may list only {}",
                        Table::ALL.map(|t| format!("\"{}\"", t.name())).join(", ")
                    ),
                ))
            }
        }
    }
    if tables.is_empty() {
        tables.push(Table::Table1);
    }
    Ok(tables)
}

/// A table listed without a table whose products it reads is an error at `tables`.
fn check_needs(r: &mut Reader, tables: &[Table]) -> Result<(), SpecError> {
    for &t in tables {
        for need in t.needs() {
            if let (false, Some(node)) = (tables.contains(need), r.get("tables")) {
                return Err(r.invalid(
                    node,
                    "tables",
                    format!(
                        "lists \"{}\" without \"{}\", {}",
                        t.name(),
                        need.name(),
                        t.why()
                    ),
                ));
            }
        }
    }
    Ok(())
}

/// Reads one cell's tree.
pub fn resolve(
    tree: &BTreeMap<String, Node>,
    file: &Path,
    layout: &Layout,
) -> Result<Spec, SpecError> {
    let mut r = Reader {
        tree,
        file,
        layout,
        known: BTreeSet::new(),
        values: BTreeMap::new(),
    };
    let stem = file
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "experiment".into());
    let experiment = match r.get("experiment") {
        None => stem,
        Some(node) => match &node.value {
            Value::String(s)
                if !s.is_empty()
                    && s.chars()
                        .all(|c| c.is_ascii_alphanumeric() || "-_".contains(c)) =>
            {
                s.clone()
            }
            _ => {
                return Err(r.invalid(
                    node,
                    "experiment",
                    "must be a name of letters, digits, - and _".into(),
                ))
            }
        },
    };
    r.values
        .insert("experiment".into(), toml::Value::String(experiment.clone()));

    let mut seeds = Vec::new();
    for node in r.list("seeds", vec![toml::Value::Integer(1)])? {
        match node.value {
            Value::Integer(i) if i >= 0 => seeds.push(i as u64),
            _ => return Err(r.invalid(node, "seeds", "must list non-negative integers".into())),
        }
    }
    if seeds.is_empty() {
        seeds.push(1);
    }
    let tables = read_tables(&mut r)?;

    let dataset = read_dataset(&mut r)?;
    let observer = ObserverNoise {
        noise_sd: r.float("observer.noise_sd", 0.0, &nonneg)?,
        gain_spread: r.float("observer.gain_spread", 0.0, &nonneg)?,
    };
    let calibration = r.data_file("observer.calibration", DEFAULT_CALIBRATION)?;
    r.forget_if_unset("observer.calibration");
    let observer_source =
        Source::parse(&r.choice("observer.source", Source::default().name(), &Source::NAMES)?)
            .expect("choice checked");
    r.forget_if_unset("observer.source");
    let (model, train) = read_training(&mut r)?;
    check_needs(&mut r, &tables)?;
    let inversion = read_inversion(&mut r)?;
    let headpose = read_headpose(&mut r)?;
    let realfaces = read_realfaces(&mut r, &tables)?;
    let cohort = read_cohort(&mut r)?;
    let table2_normalization =
        Normalization::parse(&r.choice("table2.normalization", "minmax", &["minmax", "zscore"])?)
            .expect("choice checked");
    let table2_openface = match r.get("table2.openface") {
        None => None,
        Some(_) => Some(r.data_file("table2.openface", "")?),
    };
    let report_prefix = match r.get("report.prefix") {
        None => String::new(),
        Some(node) => match &node.value {
            Value::String(s)
                if s.chars()
                    .all(|c| c.is_ascii_alphanumeric() || "-_".contains(c)) =>
            {
                s.clone()
            }
            _ => {
                return Err(r.invalid(
                    node,
                    "report.prefix",
                    "must be letters, digits, - and _".into(),
                ))
            }
        },
    };
    r.values.insert(
        "report.prefix".into(),
        toml::Value::String(report_prefix.clone()),
    );
    let launcher = read_launcher(&mut r)?;
    let values = r.finish()?;
    Ok(Spec {
        launcher,
        report_prefix,
        experiment,
        seeds,
        tables,
        dataset,
        observer,
        observer_source,
        calibration,
        model,
        train,
        cohort,
        table2_normalization,
        table2_openface,
        inversion,
        headpose,
        realfaces,
        layout: layout.clone(),
        values,
    })
}
