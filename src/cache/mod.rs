//! Content-addressed stage store (DESIGN 2.5): `root/<stage>/<key>/` holds a stage's output
//! files and `entry.json`, their SHA-256 sums. An entry is written into a temporary folder and
//! renamed into place, so it is either complete or absent; a damaged entry (a file changed or
//! cut short) fails its checksum, is removed and recomputed. Two runs that finish the same
//! entry at once both succeed: the second rename loses and its copy is dropped.
//! Uses nothing else from the crate.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use sha2::{Digest, Sha256};

#[derive(Debug, thiserror::Error)]
pub enum CacheError {
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
}

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> CacheError + '_ {
    move |source| CacheError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// Hex SHA-256 of bytes.
pub fn sha256(bytes: &[u8]) -> String {
    let digest = Sha256::digest(bytes);
    digest.iter().map(|b| format!("{b:02x}")).collect()
}

/// A stage's cache key: the hash of its name, code version, the resolved values it reads
/// (as canonical text) and its inputs' keys.
pub fn key(stage: &str, version: u32, values: &str, inputs: &[&str]) -> String {
    let mut text = format!("stage={stage}\nversion={version}\n{values}\n");
    for i in inputs {
        text.push_str("input=");
        text.push_str(i);
        text.push('\n');
    }
    sha256(text.as_bytes())
}

#[derive(Clone, Debug)]
pub struct Cache {
    root: PathBuf,
}

/// A complete, verified entry.
#[derive(Clone, Debug)]
pub struct Entry {
    pub dir: PathBuf,
    /// File name -> SHA-256.
    pub files: BTreeMap<String, String>,
}

impl Entry {
    pub fn path(&self, name: &str) -> PathBuf {
        self.dir.join(name)
    }

    pub fn read(&self, name: &str) -> Result<Vec<u8>, CacheError> {
        let p = self.path(name);
        std::fs::read(&p).map_err(io(&p))
    }
}

impl Cache {
    pub fn new(root: &Path) -> Cache {
        Cache {
            root: root.to_path_buf(),
        }
    }

    fn dir(&self, stage: &str, key: &str) -> PathBuf {
        self.root.join(stage).join(key)
    }

    /// The entry if it is present and every file matches its checksum. A damaged entry is
    /// removed (so the caller recomputes it) and reported as `Ok(None)`.
    pub fn get(&self, stage: &str, key: &str) -> Result<Option<Entry>, CacheError> {
        let dir = self.dir(stage, key);
        let listing = dir.join("entry.json");
        let Ok(text) = std::fs::read(&listing) else {
            if dir.exists() {
                let _ = std::fs::remove_dir_all(&dir);
            }
            return Ok(None);
        };
        let files: Option<BTreeMap<String, String>> = serde_json::from_slice(&text).ok();
        let verified = files.filter(|files| {
            files.iter().all(|(name, sum)| {
                std::fs::read(dir.join(name))
                    .map(|b| &sha256(&b) == sum)
                    .unwrap_or(false)
            })
        });
        match verified {
            Some(files) => Ok(Some(Entry { dir, files })),
            None => {
                // Move it aside first so a concurrent reader never sees half a removal.
                let trash = self
                    .root
                    .join(format!(".trash-{}-{key}", std::process::id()));
                if std::fs::rename(&dir, &trash).is_ok() {
                    let _ = std::fs::remove_dir_all(&trash);
                }
                Ok(None)
            }
        }
    }

    /// Stores `files` (name, bytes) as the entry for `key`, atomically.
    pub fn put(
        &self,
        stage: &str,
        key: &str,
        files: &[(String, Vec<u8>)],
    ) -> Result<Entry, CacheError> {
        let parent = self.root.join(stage);
        std::fs::create_dir_all(&parent).map_err(io(&parent))?;
        let tmp = parent.join(format!(".tmp-{}-{key}", std::process::id()));
        if tmp.exists() {
            std::fs::remove_dir_all(&tmp).map_err(io(&tmp))?;
        }
        std::fs::create_dir_all(&tmp).map_err(io(&tmp))?;
        let mut sums = BTreeMap::new();
        for (name, bytes) in files {
            let p = tmp.join(name);
            std::fs::write(&p, bytes).map_err(io(&p))?;
            sums.insert(name.clone(), sha256(bytes));
        }
        let listing = tmp.join("entry.json");
        let text = serde_json::to_vec_pretty(&sums).expect("a map of strings serializes");
        std::fs::write(&listing, text).map_err(io(&listing))?;
        if let Ok(f) = std::fs::File::open(&listing) {
            let _ = f.sync_all();
        }
        let dir = self.dir(stage, key);
        match std::fs::rename(&tmp, &dir) {
            Ok(()) => {}
            Err(_) if dir.join("entry.json").exists() => {
                // Another run finished the same entry first: keep theirs.
                let _ = std::fs::remove_dir_all(&tmp);
            }
            Err(e) => return Err(io(&dir)(e)),
        }
        Ok(Entry { dir, files: sums })
    }

    /// Removes temporary folders left by runs that were killed while writing an entry (their
    /// process id, in the folder's name, is no longer running). Folders of live runs stay.
    pub fn remove_stale(&self) {
        let Ok(stages) = std::fs::read_dir(&self.root) else {
            return;
        };
        for stage in stages.filter_map(Result::ok) {
            let Ok(entries) = std::fs::read_dir(stage.path()) else {
                continue;
            };
            for e in entries.filter_map(Result::ok) {
                let name = e.file_name().to_string_lossy().into_owned();
                let pid = name
                    .strip_prefix(".tmp-")
                    .and_then(|rest| rest.split('-').next())
                    .and_then(|p| p.parse::<u32>().ok());
                if let Some(pid) = pid {
                    let alive = Path::new(&format!("/proc/{pid}")).exists();
                    if !alive && pid != std::process::id() {
                        let _ = std::fs::remove_dir_all(e.path());
                    }
                }
            }
        }
    }

    /// Whether a verified entry exists (for `facelab status`).
    pub fn has(&self, stage: &str, key: &str) -> bool {
        matches!(self.get(stage, key), Ok(Some(_)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn damaged_entry_is_dropped_and_a_good_one_kept() {
        let root = std::env::temp_dir().join(format!("facelab-cache-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&root);
        let cache = Cache::new(&root);
        let k = key("s", 1, "a=1", &[]);
        assert!(cache.get("s", &k).unwrap().is_none());
        let e = cache
            .put("s", &k, &[("x.csv".into(), b"1,2,3\n".to_vec())])
            .unwrap();
        assert_eq!(e.read("x.csv").unwrap(), b"1,2,3\n");
        assert!(cache.get("s", &k).unwrap().is_some());
        std::fs::write(e.path("x.csv"), b"1,2").unwrap();
        assert!(cache.get("s", &k).unwrap().is_none());
        assert!(!e.dir.exists());
        assert_ne!(key("s", 1, "a=1", &[]), key("s", 2, "a=1", &[]));
        let _ = std::fs::remove_dir_all(&root);
    }
}
