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
mod transfer;

use std::sync::OnceLock;

use facelab::sim::FaceModel;

/// The base face model, built once for all tests.
pub fn model() -> &'static FaceModel {
    static MODEL: OnceLock<FaceModel> = OnceLock::new();
    MODEL.get_or_init(|| {
        let mesh = facelab::io::mesh::read_obj(&facelab::io::mesh::default_mesh_path()).unwrap();
        FaceModel::new(&mesh, Default::default()).unwrap()
    })
}

/// The crate root (where `experiments/` and `results/` are).
pub fn root() -> std::path::PathBuf {
    std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// A fresh temporary folder for one test, named by the test module and case.
pub fn temp(module: &str, name: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("facelab-{module}-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
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
