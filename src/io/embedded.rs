//! The data files an installed `facelab` needs, compiled into the binary: the face mesh, the
//! expression, muscle and reach tables, the default calibrations and readouts, the committed
//! specs, and the committed default model (the paper's run: its unified network and the
//! head-neck controller). The landmarker's weights and the font are compiled in where they
//! are used. A data file found in the working folder or in a checkout wins
//! ([`super::Layout::file`]); only where there is none are these bytes written out, once, to a
//! folder named for their content under the user's cache folder, and read from there like a
//! checkout, so every reader keeps taking paths.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use super::atomic::write_atomic;

macro_rules! embedded {
    ($($path:literal),* $(,)?) => {
        &[$(($path, include_bytes!(concat!(env!("CARGO_MANIFEST_DIR"), "/", $path)))),*]
    };
}

/// Each file's path in the checkout and its bytes.
pub const FILES: &[(&str, &[u8])] = embedded![
    "assets/face/canonical_face.obj",
    "experiments/au_calibration.csv",
    "experiments/au_muscles.csv",
    "experiments/au_observer_fit.csv",
    "experiments/au_reach.csv",
    "experiments/au_readout_inputs.csv",
    "experiments/expression_aus.csv",
    "experiments/expressions.csv",
    "experiments/base.toml",
    "experiments/paper.toml",
    "experiments/smoke.toml",
    "experiments/table1.toml",
    "experiments/table2.toml",
    "experiments/inversion.toml",
    "experiments/headpose.toml",
    "assets/openface/py-feat/OpenFace_Test.csv",
    "assets/openface/py-feat/LICENSE",
    "results/paper/latest/spec.toml",
    "results/paper/latest/unified.safetensors",
    "results/paper/latest/voluntary.safetensors",
    "results/paper/latest/training_aus.csv",
];

/// The files `rel` names: the file itself, or every file under it when it is a folder.
fn matching(rel: &str) -> Vec<(&'static str, &'static [u8])> {
    let rel = rel.trim_end_matches('/');
    FILES
        .iter()
        .filter(|(p, _)| {
            *p == rel
                || (p.len() > rel.len() && p.starts_with(rel) && p[rel.len()..].starts_with('/'))
        })
        .copied()
        .collect()
}

/// Whether `rel` (relative, `/`-separated) is an embedded file or folder.
pub fn contains(rel: &str) -> bool {
    !matching(rel).is_empty()
}

/// The folder the embedded files are written to: `facelab/data-<hash>` under
/// `$XDG_CACHE_HOME`, else `~/.cache`, else the system's temporary folder. The hash is of
/// every embedded path and byte, so two builds with different data never share a folder.
pub fn folder() -> &'static Path {
    static FOLDER: OnceLock<PathBuf> = OnceLock::new();
    FOLDER.get_or_init(|| {
        let base = std::env::var_os("XDG_CACHE_HOME")
            .filter(|v| !v.is_empty())
            .map(PathBuf::from)
            .or_else(|| {
                std::env::var_os("HOME")
                    .filter(|v| !v.is_empty())
                    .map(|h| PathBuf::from(h).join(".cache"))
            })
            .unwrap_or_else(std::env::temp_dir);
        let mut all = Vec::new();
        for (p, bytes) in FILES {
            all.extend_from_slice(p.as_bytes());
            all.push(0);
            all.extend_from_slice(crate::cache::sha256(bytes).as_bytes());
        }
        let hash = crate::cache::sha256(&all);
        base.join("facelab").join(format!("data-{}", &hash[..16]))
    })
}

/// Writes every embedded file into `root` (those not already there at their size),
/// atomically, so a copy interrupted midway is finished by the next, never read half.
/// `root` then has a checkout's shape (`experiments/`, `assets/face/`).
pub fn write_all(root: &Path) -> Result<(), super::atomic::WriteError> {
    for (p, bytes) in FILES {
        let path = root.join(p);
        let current = std::fs::metadata(&path).is_ok_and(|m| m.len() == bytes.len() as u64);
        if !current {
            write_atomic(&path, bytes)?;
        }
    }
    Ok(())
}

/// The path of the embedded file or folder `rel` in [`folder`], the embedded files written
/// there first (once per process), or `None` when nothing embedded matches `rel`.
pub fn materialize(rel: &str) -> Option<Result<PathBuf, String>> {
    static WRITTEN: OnceLock<Result<(), String>> = OnceLock::new();
    if !contains(rel) {
        return None;
    }
    let root = folder();
    let written = WRITTEN.get_or_init(|| write_all(root).map_err(|e| e.to_string()));
    Some(written.clone().map(|()| root.join(rel)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn written_out_the_files_make_a_checkout_that_reads_back() {
        let dir = std::env::temp_dir().join(format!("facelab-embedded-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        write_all(&dir).unwrap();
        assert_eq!(
            super::super::layout::find_root(&dir.join("experiments")),
            Some(std::path::absolute(&dir).unwrap())
        );
        for (p, bytes) in FILES {
            assert_eq!(std::fs::read(dir.join(p)).unwrap(), *bytes, "{p}");
        }
        // A file cut short (a copy killed midway) is written again.
        let obj = dir.join("assets/face/canonical_face.obj");
        std::fs::write(&obj, b"v 0 0 0").unwrap();
        write_all(&dir).unwrap();
        assert_eq!(std::fs::read(&obj).unwrap(), FILES[0].1);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn folders_match_their_files_and_nothing_else() {
        assert_eq!(matching("results/paper/latest").len(), 4);
        assert_eq!(matching("results/paper/latest/").len(), 4);
        assert_eq!(matching("results/paper/lat").len(), 0);
        assert!(contains("experiments/smoke.toml"));
        assert!(!contains("experiments/smoke"));
        assert!(!contains("results/realfaces/latest"));
    }
}
