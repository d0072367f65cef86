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

/// A file path in the command-line tests' shared folder (removed with the test process's
/// folder by the next test run).
fn temp(name: &str) -> std::path::PathBuf {
    let dir = crate::tests_root().join("cli");
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
fn negative_shear_modulus_fraction_is_rejected() {
    let out = temp("shear.png");
    let (ok, err) = facelab(&[
        "render",
        "--shear-modulus-fraction=-1",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(!ok);
    assert!(
        err.contains("--shear-modulus-fraction must be a finite number >= 0, got -1"),
        "{err}"
    );
    assert!(!out.exists(), "nothing written on error");
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

/// An OpenFace-style file with 3D landmarks (mm, camera frame) of the model's rest face and
/// its joy face, and AU columns as OpenFace would write them.
fn landmark_file(path: &std::path::Path) {
    use facelab::io::expressions::read_expressions;
    use facelab::observe::{landmarks, AU_NAMES};
    use facelab::sim::expression::Expression;
    use facelab::sim::{solve_from_rest, SolveParams, Workspace};

    let m = super::model();
    let weights = read_expressions(&facelab::io::Layout::here().expressions()).unwrap();
    let mut ws = Workspace::new(m).unwrap();
    let (joy, _) = solve_from_rest(
        m,
        &weights.activations(Expression::Joy, 1.0),
        &mut ws,
        &SolveParams::default(),
    )
    .unwrap();
    let rest = m.rest_state();
    let mut header = vec!["frame", "face_id", "timestamp", "confidence", "success"]
        .into_iter()
        .map(String::from)
        .collect::<Vec<_>>();
    for a in ["X", "Y", "Z"] {
        header.extend((0..68).map(|i| format!("{a}_{i}")));
    }
    header.extend(AU_NAMES.iter().map(|a| format!("{a}_r")));
    let mut text = header.join(",") + "\n";
    for (frame, state, au12) in [(1, &rest, 0.0), (2, &joy, 2.5), (3, &rest, 0.1)] {
        let l = landmarks(state.surface(m.vertex_count()));
        let mut row = vec![frame.to_string(), "0".into(), "0.0".into(), "0.98".into()];
        row.push(if frame == 3 { "0" } else { "1" }.into());
        for (axis, sign) in [(0, 1.0), (1, -1.0), (2, -1.0)] {
            row.extend(l.iter().map(|p| format!("{:.3}", sign * p[axis] * 1000.0)));
        }
        row.extend((0..17).map(|k| format!("{:.2}", if k == 8 { au12 } else { 0.0 })));
        text += &(row.join(",") + "\n");
    }
    std::fs::write(path, text).unwrap();
}

#[test]
fn observe_reads_a_files_landmarks_and_writes_our_aus() {
    let input = temp("landmarks.csv");
    let out = temp("ours.csv");
    landmark_file(&input);
    let run = Command::new(env!("CARGO_BIN_EXE_facelab"))
        .args(["observe", "--openface"])
        .arg(&input)
        .arg("--neutral-frame")
        .arg("1")
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let stdout = String::from_utf8_lossy(&run.stdout);
    assert!(stdout.contains("2 rows observed, 1 skipped"), "{stdout}");
    let written = facelab::io::openface::read_openface(&out).unwrap();
    assert_eq!(written.rows.len(), 2);
    assert!(written.rows[0].aus.iter().all(|&a| a < 0.01));
    assert!(
        written.rows[1].aus[8] > 1.5,
        "AU12 of joy: {:?}",
        written.rows[1].aus
    );
}

#[test]
fn observe_without_3d_landmarks_says_so() {
    let input = temp("aus_only.csv");
    let au: Vec<String> = facelab::observe::AU_NAMES
        .iter()
        .map(|a| format!("{a}_r"))
        .collect();
    std::fs::write(
        &input,
        format!(
            "frame,success,{}\n1,1,{}\n",
            au.join(","),
            vec!["0.5"; 17].join(",")
        ),
    )
    .unwrap();
    let out = temp("never.csv");
    let (ok, err) = facelab(&[
        "observe",
        "--openface",
        input.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(!ok);
    assert!(
        err.contains("no 3D landmarks") && err.contains("aus_only.csv"),
        "{err}"
    );
    assert!(!out.exists(), "nothing written on error");
}

/// A copy of the binary, as `cargo install` leaves it, run from an empty folder outside any
/// checkout with a cache folder of its own: it reads a photo, transfers it with the default
/// model and neck, renders an expression and runs the smoke spec by its checkout name and
/// through a spec the user wrote that extends it, all from the data compiled into it
/// (written out once under `$XDG_CACHE_HOME/facelab`), and writes only where it is told.
#[test]
fn an_installed_binary_runs_from_an_empty_folder() {
    let dir = crate::temp("cli", "installed-binary");
    let work = dir.join("elsewhere");
    std::fs::create_dir_all(&work).unwrap();
    let binary = dir.join("facelab");
    std::fs::copy(env!("CARGO_BIN_EXE_facelab"), &binary).unwrap();
    std::fs::copy(
        crate::root().join("tests/data/landmarker/photos/grace_hopper.jpg"),
        work.join("photo.jpg"),
    )
    .unwrap();
    let cache = dir.join("cache");
    let facelab = |args: &[&str]| {
        let out = Command::new(&binary)
            .current_dir(&work)
            .env("XDG_CACHE_HOME", &cache)
            .args(args)
            .output()
            .expect("run the copied binary");
        assert!(
            out.status.success(),
            "facelab {}: {}",
            args.join(" "),
            String::from_utf8_lossy(&out.stderr)
        );
    };
    facelab(&["observe", "photo.jpg", "--out", "observed"]);
    assert!(work.join("observed/openface.csv").is_file());
    facelab(&["transfer", "photo.jpg", "--out", "transferred"]);
    assert!(work.join("transferred/activations.csv").is_file());
    facelab(&["render", "--expression", "joy", "--out", "joy.png"]);
    assert!(work.join("joy.png").is_file());
    facelab(&["run", "experiments/smoke.toml", "--results", "out/results"]);
    let run = work.join("out/results/smoke/latest");
    for file in ["table1.csv", "table2.csv", "inversion.csv", "spec.toml"] {
        assert!(run.join(file).is_file(), "{file} missing");
    }
    assert!(work.join("out/paper-tables/smoke_table1.md").is_file());
    assert!(work.join("out/paper-tables/smoke_methods.md").is_file());
    assert!(run.join("timings/inversion.md").is_file());
    // A spec of one's own extends a built-in one; its cells are the smoke run's, cached.
    std::fs::write(
        work.join("mine.toml"),
        "extends = \"experiments/smoke.toml\"\nexperiment = \"mine\"\n",
    )
    .unwrap();
    facelab(&["run", "mine.toml", "--results", "out/results"]);
    assert_eq!(
        std::fs::read(work.join("out/results/mine/latest/table1.csv")).unwrap(),
        std::fs::read(run.join("table1.csv")).unwrap()
    );
    // The built-in data was written under the cache folder given, and nowhere in the work.
    let data: Vec<_> = std::fs::read_dir(cache.join("facelab")).unwrap().collect();
    assert_eq!(data.len(), 1);
    assert!(!work.join("experiments").exists() && !work.join("assets").exists());
}

/// From a subfolder of the checkout the default results folder is still the checkout's.
#[test]
fn status_from_a_subfolder_reads_the_checkouts_results() {
    let out = Command::new(env!("CARGO_BIN_EXE_facelab"))
        .current_dir(crate::root().join("experiments"))
        .args(["status", "smoke.toml"])
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let cache = crate::root().join("results/.cache");
    assert!(
        stdout.contains(&format!("in {};", cache.display())),
        "{stdout}"
    );
    assert!(!crate::root().join("experiments/results").exists());
}
