//! Run folders and their provenance: numbering, `.partial` until finished, `latest`, the git
//! state of the checkout, and the copies into `paper-tables/`.

use crate::io::atomic::write_atomic;
use crate::spec::Spec;
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
    let mut n = std::fs::read_dir(experiment_dir)?
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
            Ok(()) => return Ok(dir),
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => continue,
            Err(e) => return Err(e).with_context(|| format!("{}: cannot create", dir.display())),
        }
    }
}

/// Suffix of a run folder whose run has not finished.
pub(super) const PARTIAL: &str = ".partial";

/// Renames a finished run's folder to `run-NNNN` and returns the new path.
pub(super) fn finish_run_dir(partial: &Path) -> Result<PathBuf> {
    let name = partial
        .file_name()
        .and_then(|n| n.to_str())
        .and_then(|n| n.strip_suffix(PARTIAL))
        .context("a partial run folder's name ends in .partial")?;
    let done = partial.with_file_name(name);
    std::fs::rename(partial, &done)
        .with_context(|| format!("{}: cannot rename to {name}", partial.display()))?;
    Ok(done)
}

pub(super) fn point_latest(experiment_dir: &Path, run: &Path) -> Result<()> {
    let name = run.file_name().context("run folder has a name")?;
    let tmp = experiment_dir.join(format!(".latest-{}", std::process::id()));
    let _ = std::fs::remove_file(&tmp);
    #[cfg(unix)]
    std::os::unix::fs::symlink(name, &tmp)?;
    #[cfg(not(unix))]
    std::fs::write(&tmp, name.to_string_lossy().as_bytes())?;
    std::fs::rename(&tmp, experiment_dir.join("latest"))?;
    Ok(())
}

/// Writes `paper-tables/<report prefix><name>`.
pub(super) fn paper_table(out_root: &Path, spec: &Spec, name: &str, text: &str) -> Result<()> {
    let path = out_root
        .join("paper-tables")
        .join(format!("{}{name}", spec.report_prefix));
    write_atomic(&path, text.as_bytes())
        .with_context(|| format!("{}: cannot write", path.display()))
}
