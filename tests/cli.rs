//! The command line: bad input gives a clear message and a non-zero exit.

use std::process::Command;

fn facelab(args: &[&str]) -> (bool, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_facelab"))
        .args(args)
        .output()
        .expect("run facelab");
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

fn temp(name: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("facelab-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

#[test]
fn unknown_muscle_is_named_with_a_suggestion() {
    let out = temp("unknown.png");
    let (ok, err) = facelab(&[
        "render",
        "--activation",
        "zygomatic_major_left=0.7",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(!ok);
    assert!(
        err.contains("unknown control `zygomatic_major_left`"),
        "{err}"
    );
    assert!(err.contains("zygomaticus_major_left"), "{err}");
    assert!(!out.exists(), "nothing written on error");
}

#[test]
fn activation_outside_unit_interval_is_rejected() {
    let out = temp("range.png");
    let (ok, err) = facelab(&[
        "render",
        "--activation",
        "frontalis_medial_left=1.5",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(!ok);
    assert!(
        err.contains("`frontalis_medial_left` = 1.5 is outside [0, 1]"),
        "{err}"
    );
    let (ok, err) = facelab(&[
        "render",
        "--jaw-rotation=-0.2",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(!ok);
    assert!(err.contains("jaw_rotation"), "{err}");
}

#[test]
fn missing_mesh_file_is_named() {
    let out = temp("missing.png");
    let (ok, err) = facelab(&[
        "render",
        "--mesh",
        "no/such/face.obj",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(!ok);
    assert!(err.contains("no/such/face.obj"), "{err}");
}

#[test]
fn malformed_mesh_file_names_the_line() {
    let mesh = temp("bad.obj");
    std::fs::write(&mesh, "v 0 0 0\nv 1 0 0\nv 0 1 zero\nf 1 2 3\n").unwrap();
    let out = temp("bad.png");
    let (ok, err) = facelab(&[
        "render",
        "--mesh",
        mesh.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(!ok);
    assert!(
        err.contains("bad.obj:3:") && err.contains("`zero` is not a number"),
        "{err}"
    );
    std::fs::write(&mesh, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n").unwrap();
    let (ok, err) = facelab(&[
        "render",
        "--mesh",
        mesh.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(!ok);
    assert!(err.contains("refers to vertex 8"), "{err}");
}

#[test]
fn render_writes_a_png() {
    let out = temp("joy.png");
    let (ok, err) = facelab(&[
        "render",
        "--expression",
        "joy",
        "--scale",
        "0.5",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
    let img = image::open(&out).unwrap();
    assert_eq!((img.width(), img.height()), (480, 560));
}
