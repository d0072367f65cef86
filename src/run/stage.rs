//! The unit of work of a run (DESIGN 2.5): a stage named and keyed by what it reads, computed
//! once and cached. Every cached stage of every experiment goes through one
//! [`Stages::get_or_compute`]: look the unit up, decode it on a hit, else compute, store and
//! record it. A unit is addressable by its stage name and key ([`Unit::id`]), which is what a
//! status report lists and what a cluster launcher submits one by one.

use std::io::IsTerminal;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Mutex;
use std::time::{Duration, Instant};

use anyhow::{Context as _, Result};
use indicatif::{ProgressBar, ProgressStyle};
use serde::Serialize;

use crate::cache::{self, Cache, Entry, Lookup};

/// One unit of work: the stage (its folder in the cache) and the key of its inputs.
#[derive(Clone, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub struct Unit {
    pub stage: &'static str,
    pub key: String,
}

impl Unit {
    /// A unit whose key hashes the stage's name, code version, the typed values it reads
    /// (serialized canonically: fields in declaration order) and its inputs' keys
    /// (`cache::key`).
    pub fn new<T: Serialize + ?Sized>(
        stage: &'static str,
        version: u32,
        values: &T,
        inputs: &[&str],
    ) -> Unit {
        // Plain structs of numbers, strings and enums: serializing them cannot fail.
        let text = serde_json::to_string(values).expect("stage inputs serialize");
        Unit {
            stage,
            key: cache::key(stage, version, &text, inputs),
        }
    }

    /// A unit under a key computed elsewhere (a stage cached under another stage's key
    /// scheme, e.g. the dataset's noisy copy under the dataset's key).
    pub fn keyed(stage: &'static str, key: &str) -> Unit {
        Unit {
            stage,
            key: key.to_string(),
        }
    }

    /// `stage/key-prefix`, how logs and status reports name the unit.
    pub fn id(&self) -> String {
        format!("{}/{}", self.stage, &self.key[..self.key.len().min(12)])
    }
}

/// What a stage leaves in the cache: named files, and how they read back.
pub trait Artifact: Sized {
    fn encode(&self) -> Result<Vec<(String, Vec<u8>)>>;
    fn decode(entry: &Entry) -> Result<Self>;
}

/// Files kept as they are (renders, network weights), read back in name order.
pub struct Files(pub Vec<(String, Vec<u8>)>);

impl Artifact for Files {
    fn encode(&self) -> Result<Vec<(String, Vec<u8>)>> {
        Ok(self.0.clone())
    }
    fn decode(entry: &Entry) -> Result<Self> {
        let files = entry
            .files
            .keys()
            .map(|name| Ok((name.clone(), entry.read(name)?)))
            .collect::<Result<_>>()?;
        Ok(Files(files))
    }
}

/// A cache entry's file as UTF-8 text.
pub fn text(entry: &Entry, name: &str) -> Result<String> {
    String::from_utf8(entry.read(name)?)
        .with_context(|| format!("{}: not UTF-8", entry.path(name).display()))
}

/// How much a run says while it works (`--quiet`, default, `--verbose`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Verbosity {
    /// Errors only.
    Quiet,
    /// Each computed stage's start and end; progress (bars on a terminal, a line at most
    /// every 10 s otherwise).
    Normal,
    /// Also every cache hit.
    Verbose,
}

/// How often a progress line is printed when the output is not a terminal.
const LINE_EVERY: Duration = Duration::from_secs(10);

/// Progress of one stage: a bar on a terminal; on a pipe or file (CI, a cluster job) a line
/// at most every 10 s with done/total, rate and time left, and one at the end. Shared by the
/// worker threads (`inc` takes `&self`).
pub struct Progress {
    bar: Option<ProgressBar>,
    label: String,
    total: u64,
    done: AtomicU64,
    start: Instant,
    last_line: Mutex<Instant>,
    lines: bool,
}

impl Progress {
    fn new(total: u64, label: &str, v: Verbosity) -> Progress {
        let terminal = std::io::stderr().is_terminal();
        let bar = (v != Verbosity::Quiet && terminal).then(|| {
            let b = ProgressBar::new(total);
            b.set_style(
                ProgressStyle::with_template(
                    "{msg:>10} [{bar:40}] {pos}/{len} {elapsed_precise} eta {eta}",
                )
                .expect("valid template")
                .progress_chars("=> "),
            );
            b.set_message(label.to_string());
            b
        });
        let now = Instant::now();
        Progress {
            bar,
            label: label.to_string(),
            total,
            done: AtomicU64::new(0),
            start: now,
            last_line: Mutex::new(now),
            lines: v != Verbosity::Quiet && !terminal,
        }
    }

    pub fn inc(&self, n: u64) {
        let done = self.done.fetch_add(n, Ordering::Relaxed) + n;
        if let Some(b) = &self.bar {
            b.inc(n);
        }
        if !self.lines {
            return;
        }
        let mut last = self.last_line.lock().unwrap_or_else(|e| e.into_inner());
        if last.elapsed() >= LINE_EVERY && done < self.total {
            *last = Instant::now();
            let secs = self.start.elapsed().as_secs_f64();
            let rate = done as f64 / secs.max(1e-9);
            let left = (self.total - done) as f64 / rate.max(1e-9);
            eprintln!(
                "  {}: {done}/{} ({:.0}%), {rate:.2}/s, about {} left",
                self.label,
                self.total,
                100.0 * done as f64 / self.total.max(1) as f64,
                duration(left)
            );
        }
    }

    /// Steps done so far.
    pub fn position(&self) -> u64 {
        self.done.load(Ordering::Relaxed)
    }

    pub fn finish_and_clear(&self) {
        if let Some(b) = &self.bar {
            b.finish_and_clear();
        }
    }
}

/// Computes a unit's artifact and stores it, saying so (as `name`) unless quiet; returns it
/// with the seconds it took and whether it was found after all. The unit's compute lock is
/// held meanwhile, so that runs sharing the cache compute it once: a run that finds it taken
/// waits, then reads what the other run stored.
fn store<T: Artifact>(
    cache: &Cache,
    name: &str,
    unit: &Unit,
    v: Verbosity,
    compute: impl FnOnce() -> Result<T>,
) -> Result<(T, f64, bool)> {
    let names = [name.to_string()];
    let mut one = store_group(cache, &names, std::slice::from_ref(unit), &[0], v, |_| {
        Ok(vec![compute()?])
    })?;
    Ok(one.remove(0).1)
}

/// A unit of a group, stored: its index, its artifact, its seconds and whether another run
/// had stored it.
type Stored<T> = (usize, (T, f64, bool));

/// `store` for a group of units computed by one call (`store` is this for one unit): each
/// locked, those another run stored meanwhile read back, the rest computed together and
/// stored one by one.
fn store_group<T: Artifact>(
    cache: &Cache,
    names: &[String],
    units: &[Unit],
    members: &[usize],
    v: Verbosity,
    compute: impl FnOnce(&[usize]) -> Result<Vec<T>>,
) -> Result<Vec<Stored<T>>> {
    let t = Instant::now();
    let mut locks = Vec::with_capacity(members.len());
    for &i in members {
        let unit = &units[i];
        locks.push(cache.lock(unit.stage, &unit.key, &mut |owner| {
            eprintln!(
                "{}: another run ({owner}) is computing it; waiting",
                names[i]
            );
        })?);
    }
    let mut out = Vec::with_capacity(members.len());
    let mut todo = Vec::new();
    for &i in members {
        match lookup(cache, &names[i], &units[i], v)? {
            Some(value) => out.push((i, (value, t.elapsed().as_secs_f64(), true))),
            None => todo.push(i),
        }
    }
    if !todo.is_empty() {
        if v != Verbosity::Quiet {
            for &i in &todo {
                eprintln!("{}: computing", names[i]);
            }
        }
        let values = compute(&todo)?;
        anyhow::ensure!(
            values.len() == todo.len(),
            "a group computed {} artifacts for {} units",
            values.len(),
            todo.len()
        );
        let seconds = t.elapsed().as_secs_f64() / todo.len() as f64;
        for (&i, value) in todo.iter().zip(values) {
            cache.put(units[i].stage, &units[i].key, &value.encode()?)?;
            if v != Verbosity::Quiet {
                let shared = if todo.len() > 1 {
                    " (with its group)"
                } else {
                    ""
                };
                eprintln!("{}: done in {}{shared}", names[i], duration(seconds));
            }
            out.push((i, (value, seconds, false)));
        }
    }
    drop(locks);
    Ok(out)
}

/// The unit's artifact if the cache holds a complete entry; a damaged entry is named (it
/// will be recomputed).
fn lookup<T: Artifact>(cache: &Cache, name: &str, unit: &Unit, v: Verbosity) -> Result<Option<T>> {
    match cache.get(unit.stage, &unit.key)? {
        Lookup::Hit(entry) => {
            let value = T::decode(&entry)
                .with_context(|| format!("the cached {} in {}", unit.stage, entry.dir.display()))?;
            if v == Verbosity::Verbose {
                eprintln!("{name}: cached");
            }
            Ok(Some(value))
        }
        Lookup::Damaged { dir, reason } => {
            eprintln!(
                "{name}: the cached entry {} is damaged ({reason}); recomputing",
                dir.display()
            );
            Ok(None)
        }
        Lookup::Missing => Ok(None),
    }
}

/// "42 s", "3 min 20 s", "1 h 05 min".
pub fn duration(seconds: f64) -> String {
    let s = seconds.max(0.0).round() as u64;
    match s {
        0..60 => format!("{s} s"),
        60..3600 => format!("{} min {:02} s", s / 60, s % 60),
        _ => format!("{} h {:02} min", s / 3600, (s % 3600) / 60),
    }
}

/// What one stage did.
#[derive(Clone, Debug, PartialEq)]
pub struct StageRecord {
    pub cell: String,
    pub stage: String,
    pub key: String,
    pub hit: bool,
    pub seconds: f64,
}

/// The run context every stage works in: the cache, the records of what ran (for the
/// manifest) and progress bars.
pub struct Stages<'a> {
    pub cache: &'a Cache,
    cell: String,
    records: &'a mut Vec<StageRecord>,
    /// What the stages print (the command line's `--quiet` / `--verbose`).
    verbosity: Verbosity,
}

impl<'a> Stages<'a> {
    pub fn new(
        cache: &'a Cache,
        cell: &str,
        records: &'a mut Vec<StageRecord>,
        verbosity: Verbosity,
    ) -> Stages<'a> {
        Stages {
            cache,
            cell: cell.to_string(),
            records,
            verbosity,
        }
    }

    /// The unit's artifact: from the cache if it holds a complete entry, else `compute`d and
    /// stored. Either way the unit is recorded with its time.
    pub fn get_or_compute<T: Artifact>(
        &mut self,
        unit: &Unit,
        compute: impl FnOnce(&mut Self) -> Result<T>,
    ) -> Result<T> {
        let t = Instant::now();
        if let Some(value) = self.lookup(unit)? {
            self.record(unit, true, t.elapsed().as_secs_f64());
            return Ok(value);
        }
        let name = self.name(unit);
        let (value, seconds, hit) =
            store(self.cache, &name, unit, self.verbosity, || compute(self))?;
        self.record(unit, hit, seconds);
        Ok(value)
    }

    /// Independent units of one stage: each read from the cache, or computed — the missing
    /// ones in parallel on rayon's workers, each stored as it finishes, so a killed run keeps
    /// every unit that finished. `compute(i)` makes unit `i`'s artifact; the result and the
    /// records are in the units' order whatever order they finish in.
    pub fn get_or_compute_each<T: Artifact + Send>(
        &mut self,
        units: &[Unit],
        compute: impl Fn(usize) -> Result<T> + Sync,
    ) -> Result<Vec<T>> {
        let alone: Vec<Vec<usize>> = (0..units.len()).map(|i| vec![i]).collect();
        self.get_or_compute_groups(units, &alone, |members| {
            members.iter().map(|&i| compute(i)).collect()
        })
    }

    /// Like [`Stages::get_or_compute_each`] (which is this with groups of one), for units
    /// computed best together: each group's
    /// missing units go to one `compute(members)` call (the groups in parallel), which returns
    /// their artifacts in the members' order; each is stored under its own unit, so what a
    /// unit's artifact is may not depend on which units share its call. Every unit of a group
    /// is locked while it computes. A computed unit records its group's time shared evenly.
    pub fn get_or_compute_groups<T: Artifact + Send>(
        &mut self,
        units: &[Unit],
        groups: &[Vec<usize>],
        compute: impl Fn(&[usize]) -> Result<Vec<T>> + Sync,
    ) -> Result<Vec<T>> {
        use rayon::prelude::*;
        let mut found: Vec<Option<(T, f64)>> = Vec::with_capacity(units.len());
        for unit in units {
            let t = Instant::now();
            found.push(self.lookup(unit)?.map(|v| (v, t.elapsed().as_secs_f64())));
        }
        let mut hits: Vec<bool> = found.iter().map(Option::is_some).collect();
        let missing: Vec<Vec<usize>> = groups
            .iter()
            .map(|g| g.iter().copied().filter(|&i| !hits[i]).collect::<Vec<_>>())
            .filter(|g| !g.is_empty())
            .collect();
        let names: Vec<String> = units.iter().map(|u| self.name(u)).collect();
        let (cache, v) = (self.cache, self.verbosity);
        let computed: Vec<Vec<Stored<T>>> = missing
            .par_iter()
            .map(|members| store_group(cache, &names, units, members, v, &compute))
            .collect::<Result<_>>()?;
        for (i, (value, seconds, hit)) in computed.into_iter().flatten() {
            found[i] = Some((value, seconds));
            hits[i] = hit;
        }
        let mut out = Vec::with_capacity(units.len());
        for ((unit, hit), slot) in units.iter().zip(hits).zip(found) {
            let (value, seconds) = slot.context("every missing unit is computed")?;
            self.record(unit, hit, seconds);
            out.push(value);
        }
        Ok(out)
    }

    fn lookup<T: Artifact>(&self, unit: &Unit) -> Result<Option<T>> {
        lookup(self.cache, &self.name(unit), unit, self.verbosity)
    }

    /// Records what a unit did (a cache hit or a computation) and how long it took.
    fn record(&mut self, unit: &Unit, hit: bool, seconds: f64) {
        self.records.push(StageRecord {
            cell: self.cell.clone(),
            stage: unit.stage.to_string(),
            key: unit.key.clone(),
            hit,
            seconds,
        });
    }

    /// Progress of `len` steps labelled `message`.
    pub fn bar(&self, len: u64, message: &str) -> Progress {
        Progress::new(len, message, self.verbosity)
    }

    /// How log lines name a unit: `[cell] stage key-prefix`.
    fn name(&self, unit: &Unit) -> String {
        if self.cell.is_empty() {
            unit.id()
        } else {
            format!("[{}] {}", self.cell, unit.id())
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    struct Number(u32);

    impl Artifact for Number {
        fn encode(&self) -> Result<Vec<(String, Vec<u8>)>> {
            Ok(vec![("n.txt".into(), self.0.to_string().into_bytes())])
        }
        fn decode(entry: &Entry) -> Result<Self> {
            Ok(Number(text(entry, "n.txt")?.parse()?))
        }
    }

    #[test]
    fn independent_units_come_back_in_order_whichever_were_cached() {
        let dir = std::env::temp_dir().join(format!("facelab-stage-each-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let cache = Cache::new(&dir);
        let units: Vec<Unit> = (0..6).map(|i| Unit::new("each", 1, &i, &[])).collect();
        let mut records = Vec::new();
        // Units 1 and 4 are cached first, one at a time.
        for i in [1, 4] {
            Stages::new(&cache, "", &mut records, Verbosity::Normal)
                .get_or_compute(&units[i], |_| Ok(Number(10 * i as u32)))
                .unwrap();
        }
        records.clear();
        let calls = std::sync::atomic::AtomicU32::new(0);
        let got = Stages::new(&cache, "", &mut records, Verbosity::Normal)
            .get_or_compute_each(&units, |i| {
                calls.fetch_add(1, Ordering::Relaxed);
                Ok(Number(10 * i as u32))
            })
            .unwrap();
        assert_eq!(
            got.iter().map(|n| n.0).collect::<Vec<_>>(),
            [0, 10, 20, 30, 40, 50]
        );
        assert_eq!(calls.load(Ordering::Relaxed), 4);
        let hits: Vec<bool> = records.iter().map(|r| r.hit).collect();
        assert_eq!(hits, [false, true, false, false, true, false]);
        let keys: Vec<&str> = records.iter().map(|r| r.key.as_str()).collect();
        let expected: Vec<&str> = units.iter().map(|u| u.key.as_str()).collect();
        assert_eq!(keys, expected);
        // A failing unit fails the call; the units that finished stay cached.
        let err = Stages::new(&cache, "", &mut Vec::new(), Verbosity::Normal)
            .get_or_compute_each(&[Unit::new("each", 1, &99, &[])], |_| -> Result<Number> {
                anyhow::bail!("no number")
            })
            .map(|_| ())
            .unwrap_err();
        assert_eq!(err.to_string(), "no number");
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_unit_is_computed_once_then_read_back() {
        let dir = std::env::temp_dir().join(format!("facelab-stage-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let cache = Cache::new(&dir);
        let mut records = Vec::new();
        let unit = Unit::new("count", 1, "n = 7\n", &[]);
        let mut calls = 0;
        for _ in 0..2 {
            let mut stages = Stages::new(&cache, "cell", &mut records, Verbosity::Normal);
            let n = stages
                .get_or_compute(&unit, |_| {
                    calls += 1;
                    Ok(Number(7))
                })
                .unwrap();
            assert_eq!(n.0, 7);
        }
        assert_eq!(calls, 1);
        let hits: Vec<bool> = records.iter().map(|r| r.hit).collect();
        assert_eq!(hits, [false, true]);
        assert!(unit.id().starts_with("count/") && unit.id().len() == 18);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
