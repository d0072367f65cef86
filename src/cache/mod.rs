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
    #[error("{path}: {cause}")]
    Io {
        path: PathBuf,
        cause: std::io::Error,
    },
}

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> CacheError + '_ {
    move |cause| CacheError::Io {
        path: path.to_path_buf(),
        cause,
    }
}

/// Whether process `pid` of this machine has ended, where the system can tell (`/proc`);
/// `false` where it cannot. What a killed run left (temporary entries, unfinished run
/// folders) is removed only once this says its owner is gone.
pub fn process_ended(pid: impl std::fmt::Display) -> bool {
    let proc = Path::new("/proc");
    proc.is_dir() && !proc.join(pid.to_string()).exists()
}

/// This machine's name (`/proc/sys/kernel/hostname`; "unknown" where there is none): with a
/// process id it names who owns a temporary entry or a lock in a cache other machines share.
pub fn host() -> String {
    std::fs::read_to_string("/proc/sys/kernel/hostname")
        .map(|h| h.trim().to_string())
        .unwrap_or_else(|_| "unknown".into())
}

/// Whether the owner `host pid` (as a lock or run folder names it) has ended: its process is
/// not running on this machine. An owner on another machine is never judged by process.
pub fn owner_ended(owner: &str) -> bool {
    let mut words = owner.split_whitespace();
    let (Some(owner_host), Some(pid)) = (words.next(), words.next()) else {
        return false;
    };
    owner_host == host() && process_ended(pid)
}

/// A lock older than this without a heartbeat belongs to a process that stopped (on any
/// machine: the holder touches it every `HEARTBEAT`).
const STALE: std::time::Duration = std::time::Duration::from_secs(120);
const HEARTBEAT: std::time::Duration = std::time::Duration::from_secs(20);

/// A lock file naming its owner (`host pid`), held until dropped: a unit's compute lock in
/// the cache (`<stage>/.lock-<key>`), so that runs sharing a cache (two local runs, the tasks
/// of a cluster job) compute each unit once, and a results folder's publish lock. A heartbeat
/// thread keeps the file's time fresh; the file is removed when the lock is dropped.
pub struct OwnerLock {
    path: PathBuf,
    stop: std::sync::Arc<std::sync::atomic::AtomicBool>,
    beat: Option<std::thread::JoinHandle<()>>,
}

impl Drop for OwnerLock {
    fn drop(&mut self) {
        self.stop.store(true, std::sync::atomic::Ordering::Relaxed);
        if let Some(b) = self.beat.take() {
            b.thread().unpark();
            let _ = b.join();
        }
        let _ = std::fs::remove_file(&self.path);
    }
}

impl OwnerLock {
    /// Creates the lock file `path`, waiting while a live owner holds it: `waiting(owner)` is
    /// called once if it has to wait. A lock whose owner ended (this machine) or whose
    /// heartbeat stopped (any machine, `STALE`) is removed, saying so by `taken_over(owner)`,
    /// and taken.
    pub fn acquire(
        path: &Path,
        waiting: &mut dyn FnMut(&str),
        taken_over: &mut dyn FnMut(&str),
    ) -> Result<OwnerLock, CacheError> {
        let mut said = false;
        loop {
            match std::fs::OpenOptions::new()
                .write(true)
                .create_new(true)
                .open(path)
            {
                Ok(mut file) => {
                    use std::io::Write as _;
                    writeln!(file, "{} {}", host(), std::process::id()).map_err(io(path))?;
                    let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
                    let (flag, beat_path) = (stop.clone(), path.to_path_buf());
                    let beat = std::thread::spawn(move || {
                        while !flag.load(std::sync::atomic::Ordering::Relaxed) {
                            std::thread::park_timeout(HEARTBEAT);
                            if let Ok(f) = std::fs::File::options().write(true).open(&beat_path) {
                                let _ = f.set_modified(std::time::SystemTime::now());
                            }
                        }
                    });
                    return Ok(OwnerLock {
                        path: path.to_path_buf(),
                        stop,
                        beat: Some(beat),
                    });
                }
                Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {
                    let owner = std::fs::read_to_string(path).unwrap_or_default();
                    let age = std::fs::metadata(path)
                        .and_then(|m| m.modified())
                        .ok()
                        .and_then(|t| t.elapsed().ok());
                    if owner_ended(&owner) || age.is_some_and(|a| a > STALE) {
                        taken_over(owner.trim());
                        let _ = std::fs::remove_file(path);
                        continue;
                    }
                    if !said {
                        waiting(owner.trim());
                        said = true;
                    }
                    std::thread::sleep(std::time::Duration::from_millis(100));
                }
                Err(e) => return Err(io(path)(e)),
            }
        }
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

/// What a cache lookup found.
#[derive(Clone, Debug)]
pub enum Lookup {
    Hit(Entry),
    Missing,
    Damaged { dir: PathBuf, reason: String },
}

impl Lookup {
    pub fn entry(self) -> Option<Entry> {
        match self {
            Lookup::Hit(e) => Some(e),
            _ => None,
        }
    }
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

    /// What the cache holds under `key`, read-only: a complete entry whose every file matches
    /// its checksum, nothing, or a damaged entry (and what is wrong with it).
    pub fn inspect(&self, stage: &str, key: &str) -> Lookup {
        let dir = self.dir(stage, key);
        let listing = dir.join("entry.json");
        let text = match std::fs::read(&listing) {
            Ok(text) => text,
            Err(_) if !dir.exists() => return Lookup::Missing,
            Err(_) => {
                return Lookup::Damaged {
                    dir,
                    reason: "entry.json is missing".into(),
                }
            }
        };
        let Ok(files) = serde_json::from_slice::<BTreeMap<String, String>>(&text) else {
            return Lookup::Damaged {
                dir,
                reason: "entry.json is not a file list".into(),
            };
        };
        for (name, sum) in &files {
            match std::fs::read(dir.join(name)) {
                Ok(bytes) if &sha256(&bytes) == sum => {}
                Ok(_) => {
                    return Lookup::Damaged {
                        dir,
                        reason: format!("{name} does not match its checksum"),
                    }
                }
                Err(e) => {
                    return Lookup::Damaged {
                        dir,
                        reason: format!("{name} cannot be read ({e})"),
                    }
                }
            }
        }
        Lookup::Hit(Entry { dir, files })
    }

    /// The entry if it is present and every file matches its checksum. A damaged entry is
    /// removed (so the caller recomputes it) and returned as `Damaged`, for the caller to say.
    pub fn get(&self, stage: &str, key: &str) -> Result<Lookup, CacheError> {
        let found = self.inspect(stage, key);
        if let Lookup::Damaged { dir, .. } = &found {
            // Move it aside first so a concurrent reader never sees half a removal.
            let trash = self
                .root
                .join(format!(".trash-{}-{key}", std::process::id()));
            if std::fs::rename(dir, &trash).is_ok() {
                let _ = std::fs::remove_dir_all(&trash);
            }
        }
        Ok(found)
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
        let tmp = parent.join(format!(".tmp-{}-{key}-{}", std::process::id(), host()));
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

    /// Takes the compute lock of a unit (`OwnerLock`), waiting while a live process holds
    /// it; `waiting` is called once (with the holder) if it has to wait. The caller looks the
    /// unit up again once it holds the lock: the holder may have finished it.
    pub fn lock(
        &self,
        stage: &str,
        key: &str,
        waiting: &mut dyn FnMut(&str),
    ) -> Result<OwnerLock, CacheError> {
        let parent = self.root.join(stage);
        std::fs::create_dir_all(&parent).map_err(io(&parent))?;
        OwnerLock::acquire(&parent.join(format!(".lock-{key}")), waiting, &mut |_| {})
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
                // `.tmp-<pid>-<key>-<host>` (entries from before hosts were named: this one).
                let Some(rest) = name.strip_prefix(".tmp-") else {
                    continue;
                };
                let mut parts = rest.splitn(3, '-');
                let pid = parts.next().and_then(|p| p.parse::<u32>().ok());
                let mine = parts.nth(1).is_none_or(|h| h == host());
                if let (Some(pid), true) = (pid, mine) {
                    if process_ended(pid) && pid != std::process::id() {
                        let _ = std::fs::remove_dir_all(e.path());
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A second holder waits until the first lock is dropped; a lock whose owner ended is
    /// taken over at once, saying whose it was.
    #[test]
    fn an_owner_lock_waits_for_a_live_owner_and_takes_over_a_dead_one() {
        let root = std::env::temp_dir().join(format!("facelab-lock-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&root);
        std::fs::create_dir_all(&root).unwrap();
        let path = root.join(".lock-k");
        let first = OwnerLock::acquire(&path, &mut |_| panic!("free"), &mut |_| {}).unwrap();
        let (tx, rx) = std::sync::mpsc::channel();
        let p = path.clone();
        let second = std::thread::spawn(move || {
            let mut waited = String::new();
            let lock =
                OwnerLock::acquire(&p, &mut |o| waited = o.to_string(), &mut |_| {}).unwrap();
            tx.send(waited).unwrap();
            drop(lock);
        });
        assert!(rx
            .recv_timeout(std::time::Duration::from_millis(400))
            .is_err());
        drop(first);
        let waited = rx.recv_timeout(std::time::Duration::from_secs(5)).unwrap();
        assert_eq!(waited, format!("{} {}", host(), std::process::id()));
        second.join().unwrap();
        assert!(!path.exists());
        // A dead owner on this machine (no such process).
        std::fs::write(&path, format!("{} 4000000000\n", host())).unwrap();
        let mut gone = String::new();
        let lock = OwnerLock::acquire(&path, &mut |_| panic!("dead"), &mut |o| gone = o.into());
        assert!(lock.is_ok());
        assert_eq!(gone, format!("{} 4000000000", host()));
        drop(lock);
        let _ = std::fs::remove_dir_all(&root);
    }

    #[test]
    fn damaged_entry_is_dropped_and_a_good_one_kept() {
        let root = std::env::temp_dir().join(format!("facelab-cache-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&root);
        let cache = Cache::new(&root);
        let k = key("s", 1, "a=1", &[]);
        assert!(cache.get("s", &k).unwrap().entry().is_none());
        let e = cache
            .put("s", &k, &[("x.csv".into(), b"1,2,3\n".to_vec())])
            .unwrap();
        assert_eq!(e.read("x.csv").unwrap(), b"1,2,3\n");
        assert!(cache.get("s", &k).unwrap().entry().is_some());
        std::fs::write(e.path("x.csv"), b"1,2").unwrap();
        // Inspecting says what is wrong and leaves the entry; getting removes it.
        assert!(
            matches!(cache.inspect("s", &k), Lookup::Damaged { reason, .. } if reason.contains("x.csv"))
        );
        assert!(e.dir.exists());
        assert!(matches!(
            cache.get("s", &k).unwrap(),
            Lookup::Damaged { .. }
        ));
        assert!(!e.dir.exists());
        assert_ne!(key("s", 1, "a=1", &[]), key("s", 2, "a=1", &[]));
        let _ = std::fs::remove_dir_all(&root);
    }
}
