//! The real-data table on the one real file the project commits (py-feat's OpenFace output):
//! a tiny run of `experiments/realfaces.toml`'s pipeline, its table, its cache, and the message
//! when the real files are missing.

use std::path::{Path, PathBuf};

use crate::{facelab, root};

fn spec(dir: &Path, data: &Path) -> PathBuf {
    std::fs::write(
        dir.join("list.csv"),
        "file,person,licence\npy-feat/OpenFace_Test.csv,py-feat,MIT\n",
    )
    .unwrap();
    let path = dir.join("tiny.toml");
    std::fs::write(
        &path,
        format!(
            "extends = \"{}\"\nexperiment = \"realfaces_tiny\"\n\
             [dataset]\npairs_per_expression = 6\nstart = \"rest\"\n\
             [model]\nlayers = 2\nwidth = 16\n[train]\nepochs = 5\nbatch_size = 8\n\
             [realfaces]\nfiles = \"{}\"\ndata = \"{}\"\nframe_stride = 10\n\
             [report]\nprefix = \"tiny_\"\n",
            root().join("experiments/realfaces.toml").display(),
            dir.join("list.csv").display(),
            data.display()
        ),
    )
    .unwrap();
    path
}

#[test]
fn realfaces_transfers_a_real_file_by_each_route_and_reruns_from_the_cache() {
    let dir = crate::temp("realfaces", "tiny");
    let path = spec(&dir, &root().join("assets/openface"));
    let results = dir.join("results");
    let run = |results: &Path| {
        let out = facelab(&[
            "run",
            &path.display().to_string(),
            "--results",
            &results.display().to_string(),
        ]);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        String::from_utf8_lossy(&out.stdout).to_string()
    };
    run(&results);
    let md = std::fs::read_to_string(dir.join("paper-tables/tiny_realfaces.md")).unwrap();
    // py-feat's file: 100 rows with success = 1, every 10th transferred.
    for setting in ["unnormalized", "normalized", "au_fit"] {
        assert!(
            md.contains(&format!(
                "| py-feat/OpenFace_Test.csv | py-feat | {setting} | 10 (0) |"
            )),
            "{md}"
        );
    }
    assert!(
        md.contains("au_observer_fit.csv") && md.contains("OpenFace's scale"),
        "{md}"
    );
    // Its Table 1 stays in the run folder: `tables` does not list it.
    assert!(!dir.join("paper-tables/tiny_table1.md").exists());
    let latest = results.join("realfaces_tiny/latest");
    let csv = std::fs::read_to_string(latest.join("realfaces.csv")).unwrap();
    assert_eq!(csv.lines().count(), 4, "{csv}");
    let mut means = Vec::new();
    for line in csv.lines().skip(1) {
        let mean: f64 = line.split(',').nth(6 + 17).unwrap().parse().unwrap();
        assert!((0.0..1.0).contains(&mean), "{line}");
        means.push(mean);
    }
    // The fit matches the file's AUs through the face itself; the tiny network barely
    // learnt the face.
    assert!(means[2] < means[0], "{csv}");
    let first = std::fs::read(latest.join("realfaces.csv")).unwrap();
    let again = run(&results);
    assert!(again.contains("0 computed"), "{again}");
    assert_eq!(
        std::fs::read(results.join("realfaces_tiny/latest/realfaces.csv")).unwrap(),
        first,
        "the cached rerun gives the same bytes"
    );
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn realfaces_says_which_files_it_needs_and_writes_nothing_without_them() {
    let dir = crate::temp("realfaces", "missing");
    let path = spec(&dir, &dir.join("nowhere"));
    let results = dir.join("results");
    let out = facelab(&[
        "run",
        &path.display().to_string(),
        "--results",
        &results.display().to_string(),
    ]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("tiny.toml")
            && err.contains("py-feat/OpenFace_Test.csv")
            && err.contains("realfaces.data"),
        "{err}"
    );
    assert!(!results.join("realfaces_tiny").exists());
    assert!(!dir.join("paper-tables").exists());
    std::fs::remove_dir_all(&dir).ok();
}
