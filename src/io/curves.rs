//! Activation curves as CSV: a `frame` column, then one column per control, named as in the
//! model (what `facelab transfer` writes to `activations.csv` and `facelab edit` reads).

use std::path::Path;

use anyhow::{bail, Context, Result};

/// Curves: `values[row][column]`.
#[derive(Clone, Debug, PartialEq)]
pub struct Curves {
    pub names: Vec<String>,
    pub frames: Vec<f64>,
    pub values: Vec<Vec<f64>>,
}

impl Curves {
    /// The column of `name`, or an error naming the nearest column.
    pub fn column(&self, name: &str) -> Result<usize> {
        if let Some(i) = self.names.iter().position(|n| n == name) {
            return Ok(i);
        }
        let nearest = self
            .names
            .iter()
            .min_by_key(|n| crate::sim::controls::edit_distance(n, name))
            .map(|n| format!(" (did you mean `{n}`?)"))
            .unwrap_or_default();
        bail!("no curve named `{name}`{nearest}")
    }

    pub fn to_csv(&self) -> String {
        let mut out = format!("frame,{}\n", self.names.join(","));
        for (f, row) in self.frames.iter().zip(&self.values) {
            out.push_str(&format!("{f}"));
            for v in row {
                out.push_str(&format!(",{v:.6}"));
            }
            out.push('\n');
        }
        out
    }
}

pub fn read_curves(path: &Path) -> Result<Curves> {
    let name = path.display().to_string();
    let mut reader = csv::ReaderBuilder::new()
        .trim(csv::Trim::All)
        .from_path(path)
        .with_context(|| format!("{name}: cannot read"))?;
    let header: Vec<String> = reader
        .headers()
        .with_context(|| format!("{name}: no header"))?
        .iter()
        .map(String::from)
        .collect();
    if header.first().map(String::as_str) != Some("frame") || header.len() < 2 {
        bail!("{name}:1: the header must be `frame` and at least one curve name");
    }
    let mut frames = Vec::new();
    let mut values = Vec::new();
    for (i, record) in reader.records().enumerate() {
        let line = i + 2;
        let record = record.with_context(|| format!("{name}:{line}: malformed row"))?;
        if record.len() != header.len() {
            bail!(
                "{name}:{line}: {} cells, expected {}",
                record.len(),
                header.len()
            );
        }
        let num = |k: usize| -> Result<f64> {
            let v: f64 = record[k].parse().with_context(|| {
                format!(
                    "{name}:{line}: `{}` in `{}` is not a number",
                    &record[k], header[k]
                )
            })?;
            if !v.is_finite() {
                bail!("{name}:{line}: `{}` is not finite", header[k]);
            }
            Ok(v)
        };
        let frame = num(0)?;
        if frames.last().is_some_and(|&f: &f64| f >= frame) {
            bail!("{name}:{line}: frame {frame} does not increase");
        }
        frames.push(frame);
        values.push((1..header.len()).map(num).collect::<Result<Vec<f64>>>()?);
    }
    if frames.is_empty() {
        bail!("{name}: no rows");
    }
    Ok(Curves {
        names: header[1..].to_vec(),
        frames,
        values,
    })
}
