//! Integration tests, one binary (see STYLE.md): `sim` physics, the
//! observer, OpenFace files, the command line and Table 2's transfer.

mod architecture;
mod choe;
mod cli;
mod harness;
mod landmarker;
mod neck;
mod observe;
mod openface;
mod reach;
mod realfaces;
mod robustness;
mod sim;
mod slurm;
mod transfer;

use std::sync::OnceLock;

use facelab::sim::FaceModel;

/// The base face model, built once for all tests.
pub fn model() -> &'static FaceModel {
    static MODEL: OnceLock<FaceModel> = OnceLock::new();
    MODEL.get_or_init(|| {
        let mesh = facelab::io::mesh::read_obj(&facelab::io::Layout::here().mesh()).unwrap();
        FaceModel::new(&mesh, Default::default()).unwrap()
    })
}

/// The crate root (where `experiments/` and `results/` are).
pub fn root() -> std::path::PathBuf {
    std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// This test process's folder in the system's temporary folder. The first call removes the
/// folders earlier test processes left (their process is gone), so runs do not pile up.
pub fn tests_root() -> &'static std::path::Path {
    static ROOT: OnceLock<std::path::PathBuf> = OnceLock::new();
    ROOT.get_or_init(|| {
        let tmp = std::env::temp_dir();
        if let Ok(entries) = std::fs::read_dir(&tmp) {
            for e in entries.flatten() {
                let name = e.file_name().to_string_lossy().into_owned();
                let Some(pid) = name.strip_prefix("facelab-tests-") else {
                    continue;
                };
                if facelab::cache::process_ended(pid) {
                    let _ = std::fs::remove_dir_all(e.path());
                }
            }
        }
        let root = tmp.join(format!("facelab-tests-{}", std::process::id()));
        std::fs::create_dir_all(&root).unwrap();
        root
    })
}

/// A test's scratch folder, removed when the test is done with it (dropped).
pub struct Scratch(std::path::PathBuf);

impl std::ops::Deref for Scratch {
    type Target = std::path::PathBuf;
    fn deref(&self) -> &std::path::PathBuf {
        &self.0
    }
}

impl AsRef<std::path::Path> for Scratch {
    fn as_ref(&self) -> &std::path::Path {
        &self.0
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// A fresh scratch folder for one test, named by the test module and case.
pub fn temp(module: &str, name: &str) -> Scratch {
    let dir = tests_root().join(format!("{module}-{name}"));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    Scratch(dir)
}

/// Runs the `facelab` binary in the crate root.
pub fn facelab(args: &[&str]) -> std::process::Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_facelab"))
        .args(args)
        .current_dir(root())
        .output()
        .expect("run facelab")
}

/// Asserts that each of `files` has the same bytes under folder `a` and folder `b`; `what`
/// says how the two runs differ.
pub fn assert_same_bytes(a: &std::path::Path, b: &std::path::Path, files: &[&str], what: &str) {
    for file in files {
        let read = |dir: &std::path::Path| {
            std::fs::read(dir.join(file))
                .unwrap_or_else(|e| panic!("{}: {e}", dir.join(file).display()))
        };
        assert!(read(a) == read(b), "{file} differs between {what}");
    }
}

/// One frame of a test OpenFace file: whether the face was found, the values of the extra
/// columns as written, and the 17 AU intensities in `AU_NAMES` order.
pub struct Frame {
    pub success: bool,
    pub extra: Vec<String>,
    pub aus: [f64; facelab::observe::AU_COUNT],
}

/// Writes an OpenFace 2 CSV as OpenFace separates it (`, `) to `dir/name`: frame, timestamp
/// (30 fps), confidence, success, the `extra` columns, then the AU intensities.
pub fn openface_file(
    dir: &std::path::Path,
    name: &str,
    extra: &[&str],
    frames: &[Frame],
) -> std::path::PathBuf {
    let mut header = vec!["frame", "timestamp", "confidence", "success"];
    header.extend_from_slice(extra);
    let aus = facelab::observe::AU_NAMES.map(|a| format!("{a}_r"));
    header.extend(aus.iter().map(String::as_str));
    let mut text = header.join(", ") + "\n";
    for (f, frame) in frames.iter().enumerate() {
        let mut row = vec![
            (f + 1).to_string(),
            format!("{:.3}", f as f64 / 30.0),
            "0.98".to_string(),
            u8::from(frame.success).to_string(),
        ];
        row.extend(frame.extra.iter().cloned());
        row.extend(frame.aus.iter().map(|v| format!("{v:.2}")));
        text += &(row.join(", ") + "\n");
    }
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap();
    path
}
