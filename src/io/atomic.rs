//! Atomic file writes: the bytes go to a temporary file beside the target (named with the
//! process id, so two runs at once never share one), then a rename puts it in place. A killed
//! run leaves either the old file or the new one, never half of one.

use std::io::Write;
use std::path::{Path, PathBuf};

fn temp_path(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    path.with_file_name(format!(".{name}.{}.tmp", std::process::id()))
}

/// A write that failed, naming the file (the OS's reason once).
#[derive(Debug, thiserror::Error)]
#[error("{}: cannot write ({cause})", path.display())]
pub struct WriteError {
    pub path: PathBuf,
    pub cause: std::io::Error,
}

/// Writes `bytes` to `path` atomically, creating the parent folder if needed; an error names
/// `path`.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), WriteError> {
    write_in_place(path, bytes).map_err(|cause| WriteError {
        path: path.to_path_buf(),
        cause,
    })
}

fn write_in_place(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir)?;
    }
    let tmp = temp_path(path);
    let result = (|| {
        let mut file = std::fs::File::create(&tmp)?;
        file.write_all(bytes)?;
        file.sync_all()?;
        std::fs::rename(&tmp, path)
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A failed write names its file once and gives the OS's reason once (a parent that is a
    /// file fails for every user, root included).
    #[test]
    fn a_failed_write_names_its_file_once() {
        let dir = std::env::temp_dir().join(format!("facelab-atomic-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let blocker = dir.join("paper-tables");
        std::fs::write(&blocker, b"a file where a folder should be").unwrap();
        let target = blocker.join("table1.md");
        let err = anyhow::Error::from(write_atomic(&target, b"x").unwrap_err());
        let text = format!("{err:#}");
        assert_eq!(text.matches("table1.md").count(), 1, "{text}");
        assert!(text.contains("cannot write"), "{text}");
        assert_eq!(text.matches("(os error").count(), 1, "{text}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
