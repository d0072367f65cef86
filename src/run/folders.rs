//! Run folders and their provenance: numbering, `.partial` until finished, `latest`, the git
//! state of the checkout, and the copies into `paper-tables/`.

use crate::io::atomic::write_atomic;
use anyhow::{Context, Result};
use std::path::{Path, PathBuf};

pub(super) fn sanitize(name: &str) -> String {
    name.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || "-_.=".contains(c) {
                c
            } else {
                '_'
            }
        })
        .collect()
}

/// `git args` in the working folder; `None` outside a git checkout, which the manifest
/// records as "unknown".
pub(super) fn git(args: &[&str]) -> Option<String> {
    let out = std::process::Command::new("git").args(args).output().ok()?;
    out.status
        .success()
        .then(|| String::from_utf8_lossy(&out.stdout).trim().to_string())
}

/// Whether the checkout differs from its commit, outputs aside: what runs write (`outputs`,
/// where they lie inside the checkout) is not a change to what produced them, so a run after
/// another in the same checkout still counts as clean.
pub(super) fn checkout_dirty(outputs: &[PathBuf]) -> Option<bool> {
    let top = PathBuf::from(git(&["rev-parse", "--show-toplevel"])?);
    let mut args: Vec<String> = ["status", "--porcelain", "--", ":/"]
        .map(String::from)
        .into();
    for path in outputs {
        let Ok(abs) = std::path::absolute(path) else {
            continue;
        };
        if let Ok(rel) = abs.strip_prefix(&top) {
            if !rel.as_os_str().is_empty() {
                args.push(format!(":(top,exclude){}", rel.display()));
            }
        }
    }
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    git(&args).map(|s| !s.is_empty())
}

/// A new run folder, `run-NNNN.partial` until `finish_run_dir` names it `run-NNNN`: a run that
/// fails or is killed leaves no folder that looks finished. Concurrent runs each get their own
/// number.
pub(super) fn new_run_dir(experiment_dir: &Path) -> Result<PathBuf> {
    std::fs::create_dir_all(experiment_dir)
        .with_context(|| format!("{}: cannot create", experiment_dir.display()))?;
    let mut n = std::fs::read_dir(experiment_dir)
        .with_context(|| format!("{}: cannot list", experiment_dir.display()))?
        .filter_map(|e| e.ok())
        .filter_map(|e| {
            let name = e.file_name();
            let name = name.to_str()?.strip_prefix("run-")?;
            name.strip_suffix(PARTIAL)
                .unwrap_or(name)
                .parse::<u32>()
                .ok()
        })
        .max()
        .unwrap_or(0);
    loop {
        n += 1;
        if experiment_dir.join(format!("run-{n:04}")).exists() {
            continue;
        }
        let dir = experiment_dir.join(format!("run-{n:04}{PARTIAL}"));
        match std::fs::create_dir(&dir) {
            Ok(()) => {
                let owner = dir.join(OWNER);
                std::fs::write(&owner, format!("{} {}\n", host(), std::process::id()))
                    .with_context(|| format!("{}: cannot write", owner.display()))?;
                remove_dead_runs(experiment_dir, &dir);
                return Ok(dir);
            }
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => continue,
            Err(e) => return Err(e).with_context(|| format!("{}: cannot create", dir.display())),
        }
    }
}

/// Held while a run publishes into a results folder (`<results>/.publish.lock`, a
/// `cache::OwnerLock`); a lock whose owner has ended (a killed run) is taken over.
pub(super) struct PublishLock {
    _held: crate::cache::OwnerLock,
}

impl PublishLock {
    /// Takes the lock, waiting (and saying so once) while a live run holds it.
    pub(super) fn acquire(results: &Path) -> Result<PublishLock> {
        let path = results.join(".publish.lock");
        let lock = crate::cache::OwnerLock::acquire(
            &path,
            &mut |owner| {
                eprintln!(
                    "{}: another run ({owner}) is publishing its tables; waiting for it",
                    path.display()
                )
            },
            &mut |owner| {
                eprintln!(
                    "{}: its run ({owner}) stopped while publishing; taking it over",
                    path.display()
                )
            },
        )?;
        Ok(PublishLock { _held: lock })
    }
}

/// Suffix of a run folder whose run has not finished.
pub(super) const PARTIAL: &str = ".partial";

/// The file in a `.partial` folder naming the run that owns it: `host pid`.
pub(super) const OWNER: &str = ".owner";

fn host() -> String {
    crate::cache::host()
}

/// Whether the run that owns a `.partial` folder is gone: its process is not running on this
/// machine. A folder of another machine (a shared file system) is never judged; on a system
/// without `/proc` nothing is.
fn owner_is_gone(partial: &Path) -> bool {
    let Ok(owner) = std::fs::read_to_string(partial.join(OWNER)) else {
        // Runs before owners were recorded; a live one would be seconds old.
        return std::fs::metadata(partial)
            .and_then(|m| m.modified())
            .is_ok_and(|t| t.elapsed().is_ok_and(|age| age.as_secs() > 24 * 3600));
    };
    owner_ended(&owner)
}

/// Whether the process an owner line (`host pid`) names has ended: only a process of this
/// machine is judged.
fn owner_ended(owner: &str) -> bool {
    crate::cache::owner_ended(owner)
}

/// Removes the `.partial` folders of runs that died (killed, crashed) before finishing, saying
/// so; `own` (the new run's folder) and folders of live runs are kept.
fn remove_dead_runs(experiment_dir: &Path, own: &Path) {
    let Ok(entries) = std::fs::read_dir(experiment_dir) else {
        return;
    };
    for path in entries.filter_map(|e| e.ok().map(|e| e.path())) {
        let partial = path
            .file_name()
            .and_then(|n| n.to_str())
            .is_some_and(|n| n.starts_with("run-") && n.ends_with(PARTIAL));
        if partial && path != own && owner_is_gone(&path) {
            match std::fs::remove_dir_all(&path) {
                Ok(()) => eprintln!(
                    "removed {}: its run stopped before finishing",
                    path.display()
                ),
                Err(e) => eprintln!("{}: cannot remove ({e})", path.display()),
            }
        }
    }
}

/// The folder a `run-NNNN.partial` folder becomes when its run finishes.
pub(super) fn finished_path(partial: &Path) -> Result<PathBuf> {
    let name = partial
        .file_name()
        .and_then(|n| n.to_str())
        .and_then(|n| n.strip_suffix(PARTIAL))
        .context("a partial run folder's name ends in .partial")?;
    Ok(partial.with_file_name(name))
}

/// Renames a finished run's folder to `run-NNNN` and returns the new path.
pub(super) fn finish_run_dir(partial: &Path) -> Result<PathBuf> {
    let done = finished_path(partial)?;
    let owner = partial.join(OWNER);
    std::fs::remove_file(&owner).with_context(|| format!("{}: cannot remove", owner.display()))?;
    std::fs::rename(partial, &done)
        .with_context(|| format!("{}: cannot rename to {}", partial.display(), done.display()))?;
    Ok(done)
}

pub(super) fn point_latest(experiment_dir: &Path, run: &Path) -> Result<()> {
    let name = run.file_name().context("run folder has a name")?;
    let tmp = experiment_dir.join(format!(".latest-{}", std::process::id()));
    let _ = std::fs::remove_file(&tmp);
    #[cfg(unix)]
    std::os::unix::fs::symlink(name, &tmp)
        .with_context(|| format!("{}: cannot create the link", tmp.display()))?;
    #[cfg(not(unix))]
    std::fs::write(&tmp, name.to_string_lossy().as_bytes())
        .with_context(|| format!("{}: cannot write", tmp.display()))?;
    let latest = experiment_dir.join("latest");
    std::fs::rename(&tmp, &latest)
        .with_context(|| format!("{}: cannot replace", latest.display()))?;
    Ok(())
}

/// Where a run's tables and figures go, and the overrides their captions name.
pub(super) struct Publish {
    pub(super) tables: PathBuf,
    pub(super) figures: PathBuf,
    /// The run's `--set` values (none for the committed record).
    pub(super) overrides: Vec<String>,
    /// For a published run: `tables` and `figures` are a staging folder, copied to these at the
    /// end (`copy_out`).
    pub(super) staged: Option<Staged>,
}

/// A published run's staging folder and where its two subfolders are copied.
pub(super) struct Staged {
    pub(super) staging: PathBuf,
    pub(super) tables: PathBuf,
    pub(super) figures: PathBuf,
}

/// The folder in a run's folder where a published run stages its tables and figures.
pub(super) const STAGING: &str = ".publish";

/// Files under `dir`, relative to it, in name order.
fn files_under(dir: &Path) -> Result<Vec<PathBuf>> {
    let mut out = Vec::new();
    let mut todo = vec![PathBuf::new()];
    while let Some(rel) = todo.pop() {
        let path = dir.join(&rel);
        if !path.exists() {
            continue;
        }
        for e in
            std::fs::read_dir(&path).with_context(|| format!("{}: cannot list", path.display()))?
        {
            let e = e.with_context(|| format!("{}: cannot list", path.display()))?;
            let child = rel.join(e.file_name());
            if e.file_type()
                .with_context(|| format!("{}: cannot read", e.path().display()))?
                .is_dir()
            {
                todo.push(child);
            } else {
                out.push(child);
            }
        }
    }
    out.sort();
    Ok(out)
}

impl Publish {
    /// Copies a published run's staged tables and figures to their folders (each file
    /// atomically) and removes the staging folder. Call under the `PublishLock`.
    pub(super) fn copy_out(&self) -> Result<()> {
        let Some(s) = &self.staged else {
            return Ok(());
        };
        for (from, to) in [(&self.tables, &s.tables), (&self.figures, &s.figures)] {
            for rel in files_under(from)? {
                let src = from.join(&rel);
                let bytes = std::fs::read(&src)
                    .with_context(|| format!("{}: cannot read", src.display()))?;
                write_atomic(&to.join(&rel), &bytes)?;
            }
        }
        if s.staging.exists() {
            std::fs::remove_dir_all(&s.staging)
                .with_context(|| format!("{}: cannot remove", s.staging.display()))?;
        }
        Ok(())
    }

    /// Writes the table `name` (Markdown or LaTeX) into the tables folder; an overridden run's
    /// table says so under its title (Markdown) or in a first comment line (LaTeX).
    pub(super) fn table(&self, name: &str, text: &str) -> Result<()> {
        let text = if self.overrides.is_empty() {
            text.to_string()
        } else {
            let sets: Vec<String> = self
                .overrides
                .iter()
                .map(|s| format!("--set {s}"))
                .collect();
            if name.ends_with(".tex") {
                format!("% run with overrides: {}\n{text}", sets.join(" "))
            } else {
                let (title, rest) = text.split_once('\n').unwrap_or((text, ""));
                let sets: Vec<String> = sets.iter().map(|s| format!("`{s}`")).collect();
                format!(
                    "{title}\n\nRun with overrides: {}.\n{rest}",
                    sets.join(", ")
                )
            }
        };
        Ok(write_atomic(&self.tables.join(name), text.as_bytes())?)
    }
}
