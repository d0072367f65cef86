//! Whether the committed runs are today's: for each `results/<experiment>/latest`, the units
//! its manifest recorded against the units its recorded spec plans with today's code. A unit
//! key hashes the typed inputs and the code version of its stage (and the face's), so a run
//! made before a stage's code changed its output (and bumped its version) recorded a key
//! today's code no longer plans.

use crate::io::Layout;
use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};

use crate::cache::Cache;
use crate::run::cell::{assets, Plan, Registry};
use crate::spec;

/// A committed run against today's code.
#[derive(Clone, Debug)]
pub struct Committed {
    /// The run folder `latest` points to.
    pub run: PathBuf,
    /// Units today's plan knows the key of (a unit whose key hashes a cached result that is
    /// not in the cache is left out: its key cannot be known without running).
    pub planned: usize,
    /// Units the run recorded that today's plan does not hold, as `stage/key` (the key's
    /// first 12 digits); stages whose key today's plan cannot know are not compared.
    pub stale: Vec<String>,
}

impl Committed {
    pub fn is_current(&self) -> bool {
        self.stale.is_empty()
    }
}

/// Every committed run under `results` (each experiment folder's `latest`), in name order,
/// planned with `registry` through the cache in `results/.cache`.
pub fn committed(layout: &Layout, results: &Path, registry: Registry) -> Result<Vec<Committed>> {
    let mut latest: Vec<PathBuf> = std::fs::read_dir(results)
        .with_context(|| format!("{}: cannot list", results.display()))?
        .filter_map(|e| Some(e.ok()?.path().join("latest")))
        .filter(|p| p.join("manifest.json").is_file())
        .collect();
    latest.sort();
    let a = assets(layout)?;
    let cache = Cache::new(&results.join(".cache"));
    latest
        .iter()
        .map(|l| {
            let run = std::fs::canonicalize(l)
                .with_context(|| format!("{}: cannot resolve", l.display()))?;
            against_today(layout, &run, &a, &cache, registry)
        })
        .collect()
}

fn against_today(
    layout: &Layout,
    run: &Path,
    a: &crate::run::cell::Assets,
    cache: &Cache,
    registry: Registry,
) -> Result<Committed> {
    let (manifest, prefixes) = super::recorded(run)?;
    let recorded: BTreeSet<(String, String)> = manifest["stages"]
        .as_array()
        .with_context(|| format!("{}: no stages", run.join("manifest.json").display()))?
        .iter()
        .filter_map(|s| Some((s["stage"].as_str()?.into(), s["key"].as_str()?.into())))
        .collect();
    // Today's plan of every cell; a unit whose key cannot be known without running (it
    // hashes a cached result not in the cache) is left out.
    let mut today: BTreeSet<(String, String)> = BTreeSet::new();
    let mut unknown_stages: BTreeSet<String> = BTreeSet::new();
    for prefix in &prefixes {
        let spec_path = run.join(prefix).join("spec.toml");
        let cells = spec::load(layout, &spec_path, &[])?;
        let cell = prefix.trim_end_matches('/');
        let plan = Plan::of(
            &cells[0].spec,
            cell,
            a,
            cache,
            registry.0,
            prefix.is_empty(),
        )
        .with_context(|| format!("{}: planning it with today's code", spec_path.display()))?;
        for p in plan {
            match p.unit {
                Ok(u) => {
                    today.insert((u.stage.to_string(), u.key));
                }
                Err(_) => {
                    unknown_stages.insert(p.label);
                }
            }
        }
    }
    // A recorded unit today's code would not make: its stage's code or inputs changed since.
    // (The other direction does not hold: a run records only the units it touched, and a
    // cached dataset leaves the basis it would have been predicted from untouched.)
    // Parts of a unit (a dataset's chunks, a cohort's parts) are recorded but not planned:
    // only stages the plan names are compared.
    let stages: BTreeSet<&str> = today.iter().map(|(stage, _)| stage.as_str()).collect();
    let stale: Vec<String> = recorded
        .iter()
        .filter(|(stage, key)| {
            stages.contains(stage.as_str())
                && !today.contains(&(stage.clone(), key.clone()))
                && !unknown_stages.iter().any(|l| l.starts_with(stage.as_str()))
        })
        .map(|(stage, key)| format!("{stage}/{}", &key[..key.len().min(12)]))
        .collect();
    let planned = today.len();
    Ok(Committed {
        run: run.to_path_buf(),
        planned,
        stale,
    })
}
