//! The harness: spec errors, byte-identical reruns across thread counts, the cache (hits,
//! damaged entries, killed runs) and divergence, on `experiments/smoke.toml`.

use std::path::Path;
use std::process::{Command, Output};

use facelab::spec::{self, SpecError};

use crate::{assert_same_bytes, facelab, root};

fn temp(name: &str) -> crate::Scratch {
    crate::temp("harness", name)
}

fn smoke() -> String {
    root().join("experiments/smoke.toml").display().to_string()
}

fn run_smoke(results: &Path, extra: &[&str]) -> Output {
    let mut args = vec!["run", "experiments/smoke.toml", "--results"];
    let r = results.display().to_string();
    args.push(&r);
    args.extend_from_slice(extra);
    facelab(&args)
}

/// A committed spec of the checkout (`rel` from its root), resolved as a run would.
fn committed_spec(rel: &str) -> Vec<spec::Cell> {
    spec::load(&facelab::io::Layout::here(), &root().join(rel), &[]).unwrap()
}

fn latest(results: &Path, file: &str) -> Vec<u8> {
    std::fs::read(results.join("smoke/latest").join(file)).unwrap()
}

fn spec_error(text: &str, sets: &[&str]) -> String {
    let dir = temp(&format!("spec-{}", text.len()));
    std::fs::write(dir.join("base.toml"), "[train]\nepochs = 3\n").unwrap();
    let path = dir.join("s.toml");
    std::fs::write(&path, text).unwrap();
    let sets: Vec<String> = sets.iter().map(|s| s.to_string()).collect();
    match spec::load(&facelab::io::Layout::here(), &path, &sets) {
        Ok(_) => panic!("spec should fail:\n{text}"),
        Err(e) => e.to_string(),
    }
}

/// `dataset.grid` adds the grid of equilibria to a paper-family data set solved from
/// predictions, and changes its key; without it (the default), and for the broad family, the
/// plan is what it was before the grid.
#[test]
fn the_grid_of_equilibria_is_planned_only_where_it_is_asked_for() {
    let results = temp("grid-plan");
    let status = |sets: &[&str]| -> String {
        let mut args = vec!["status", "experiments/table1.toml"];
        for s in sets {
            args.extend(["--set", s]);
        }
        let results = results.display().to_string();
        args.extend(["--results", &results]);
        let out = facelab(&args);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        String::from_utf8_lossy(&out.stdout).into_owned()
    };
    let dataset = |plan: &str| -> String {
        let line = plan
            .lines()
            .find(|l| l.ends_with(" dataset"))
            .expect("a dataset");
        line.split_whitespace().nth(1).unwrap().to_string()
    };
    let default = status(&[]);
    let grid = status(&["dataset.grid=4"]);
    let broad = status(&["dataset.grid=4", "dataset.family=\"broad\""]);
    let broad_default = status(&["dataset.family=\"broad\""]);
    assert!(!default.contains(" grid\n"), "{default}");
    assert!(grid.contains(" grid\n"), "{grid}");
    assert!(!broad.contains(" grid\n"), "{broad}");
    assert_ne!(dataset(&default), dataset(&grid));
    assert_eq!(dataset(&broad), dataset(&broad_default));
}

#[test]
fn spec_errors_name_file_line_column_and_key() {
    let e = spec_error(
        "extends = \"base.toml\"\n[train]\nlearning_rat = 0.1\n",
        &[],
    );
    assert!(
        e.contains("s.toml:3:1")
            && e.contains("train.learning_rat")
            && e.contains("did you mean `train.learning_rate`"),
        "{e}"
    );
    let e = spec_error("[train]\nepochs = \"many\"\n", &[]);
    assert!(
        e.contains("s.toml:2:1") && e.contains("must be an integer"),
        "{e}"
    );
    let e = spec_error("[train]\nlearning_rate = -0.1\n", &[]);
    assert!(
        e.contains("train.learning_rate") && e.contains("must be positive"),
        "{e}"
    );
    let e = spec_error("[train]\nbatch_size = 0\n", &[]);
    assert!(
        e.contains("train.batch_size") && e.contains("outside"),
        "{e}"
    );
    let e = spec_error("[dataset]\ntest_fraction = 1.5\n", &[]);
    assert!(
        e.contains("dataset.test_fraction") && e.contains("(0, 1)"),
        "{e}"
    );
    let e = spec_error("[dataset]\nshear_modulus_fraction = -1\n", &[]);
    assert!(
        e.contains("s.toml:2:1")
            && e.contains("dataset.shear_modulus_fraction")
            && e.contains(">= 0"),
        "{e}"
    );
    let e = spec_error("[dataset]\ngrid = 2\n", &[]);
    assert!(
        e.contains("s.toml:2:1") && e.contains("dataset.grid") && e.contains("4 faces per axis"),
        "{e}"
    );
    let e = spec_error("[dataset]\nfamily = \"wide\"\n", &[]);
    assert!(
        e.contains("s.toml:2:1") && e.contains("dataset.family") && e.contains("paper, broad"),
        "{e}"
    );
    let e = spec_error("[observer]\ncalibration = \"nope.csv\"\n", &[]);
    assert!(
        e.contains("s.toml:2:1")
            && e.contains("observer.calibration")
            && e.contains("no such file"),
        "{e}"
    );
    let e = spec_error("[table2]\nopenface = \"nope.csv\"\n", &[]);
    assert!(
        e.contains("s.toml:2:1") && e.contains("table2.openface") && e.contains("no such file"),
        "{e}"
    );
    let e = spec_error("[realfaces]\nframe_stride = 0\n", &[]);
    assert!(
        e.contains("realfaces.frame_stride") && e.contains("outside"),
        "{e}"
    );
    let e = spec_error("[sweep]\n\"train.epoch\" = [1, 2]\n", &[]);
    assert!(
        e.contains("s.toml:2") && e.contains("sweep") && e.contains("train.epoch"),
        "{e}"
    );
    let e = spec_error("extends = \"missing.toml\"\n", &[]);
    assert!(e.contains("extends") && e.contains("missing.toml"), "{e}");
    let e = spec_error("seeds = [1]\n", &["train.epochs=-3"]);
    assert!(e.contains("--set train.epochs=-3"), "{e}");

    let dir = temp("cycle");
    std::fs::write(dir.join("a.toml"), "extends = \"b.toml\"\n").unwrap();
    std::fs::write(dir.join("b.toml"), "extends = \"a.toml\"\n").unwrap();
    let e = spec::load(&facelab::io::Layout::here(), &dir.join("a.toml"), &[]).unwrap_err();
    assert!(matches!(e, SpecError::Cycle(_)), "{e}");
    // Named as they are given, relative to the working folder, with each `extends` line.
    let out = Command::new(env!("CARGO_BIN_EXE_facelab"))
        .current_dir(&dir)
        .args(["check", "a.toml"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success()
            && err.contains("a.toml:1 extends -> b.toml:1 extends -> a.toml")
            && !err.contains(&dir.display().to_string()),
        "{err}"
    );
    // An empty spec is an error, not a full default run.
    std::fs::write(dir.join("empty.toml"), "# nothing here\n\n").unwrap();
    let e = spec::load(&facelab::io::Layout::here(), &dir.join("empty.toml"), &[]).unwrap_err();
    assert!(
        matches!(e, SpecError::Empty { .. }) && e.to_string().contains("empty.toml"),
        "{e}"
    );

    // The CLI: message on stderr, non-zero exit, nothing run.
    let out = facelab(&["check", &smoke(), "--set", "train.learning_rate=0"]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("train.learning_rate") && err.contains("must be positive"),
        "{err}"
    );
}

/// Keys added later are recorded in a run's `spec.toml` only where a spec sets them, so the
/// committed runs' recorded specs read as they were written.
#[test]
fn later_keys_change_nothing_for_specs_that_do_not_set_them() {
    for name in ["paper", "table1", "smoke"] {
        let cells = committed_spec(&format!("experiments/{name}.toml"));
        for later in ["dataset.family", "realfaces."] {
            assert!(!cells[0].spec.records(later), "{name}.toml records {later}");
        }
    }
    // The smoke spec sets none of the later keys; the paper's specs read every face with the
    // readout fitted to OpenFace, and Table 2 adds the committed real file.
    let smoke = &committed_spec("experiments/smoke.toml")[0].spec;
    assert!(!smoke.records("observer.calibration"));
    assert!(!smoke.records("table2.openface"));
    assert_eq!(smoke.table2_openface, None);
    let paper = &committed_spec("experiments/paper.toml")[0].spec;
    assert_eq!(paper.calibration, "experiments/au_observer_fit.csv");
    assert_eq!(
        paper.table2_openface.as_ref().map(|f| f.name.as_str()),
        Some("assets/openface/py-feat/OpenFace_Test.csv")
    );
    let cells = committed_spec("experiments/realfaces.toml");
    let s = &cells[0].spec;
    assert_eq!(s.dataset.family, facelab::dataset::Family::Broad);
    assert_eq!(s.calibration, "experiments/au_observer_fit.csv");
    assert!(s.records("realfaces.frame_stride"));
    let sweep = committed_spec("experiments/ablations/family.toml");
    let names: Vec<&str> = sweep.iter().map(|c| c.name.as_str()).collect();
    assert_eq!(
        names,
        ["dataset.family=\"paper\"", "dataset.family=\"broad\""]
    );
}

/// Table 2's real rows: the committed py-feat file through each seed's network, unnormalized
/// and normalized, in the markdown table and per seed in `table2_real.csv`.
#[test]
fn table2_reports_the_committed_real_file_per_seed_and_setting() {
    let dir = temp("table2-real");
    let out = run_smoke(
        &dir.join("results"),
        &[
            "--set",
            "table2.openface=\"assets/openface/py-feat/OpenFace_Test.csv\"",
            "--set",
            "realfaces.frame_stride=20",
        ],
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let csv = String::from_utf8(latest(&dir.join("results"), "table2_real.csv")).unwrap();
    let rows: Vec<&str> = csv.lines().skip(1).collect();
    // 2 seeds x 2 settings, each over every 20th of the file's 99 used frames (5).
    assert_eq!(rows.len(), 4, "{csv}");
    for r in &rows {
        assert!(r.contains("py-feat"), "{r}");
    }
    let md =
        String::from_utf8(latest(&dir.join("results"), "paper-tables/smoke_table2.md")).unwrap();
    for name in ["| py-feat-unnormalized |", "| py-feat-normalized |"] {
        assert!(md.contains(name), "{md}");
    }
    assert!(
        md.contains("assets/openface/py-feat/OpenFace_Test.csv") && md.contains("5 frames"),
        "{md}"
    );
}

#[test]
fn sweeps_expand_into_named_cells() {
    let cells = committed_spec("experiments/ablations/depth.toml");
    assert_eq!(cells.len(), 18);
    assert_eq!(cells[0].name, "model.layers=1,model.width=50");
    assert_eq!(cells[17].spec.model.layers, 6);
    assert_eq!(cells[17].spec.model.width, 200);
    assert_eq!(cells[3].spec.train.learning_rate, 0.01);
}

#[test]
fn same_spec_gives_the_same_bytes_across_threads_and_from_the_cache() {
    let one = temp("threads1");
    let two = temp("threads2");
    let a = run_smoke(&one.join("results"), &["--threads", "1"]);
    assert!(a.status.success(), "{}", String::from_utf8_lossy(&a.stderr));
    let b = run_smoke(&two.join("results"), &["--threads", "2"]);
    assert!(b.status.success(), "{}", String::from_utf8_lossy(&b.stderr));
    assert_same_bytes(
        &one.join("results/smoke/latest"),
        &two.join("results/smoke/latest"),
        &[
            "table1.csv",
            "curves.csv",
            "spec.toml",
            "table2.csv",
            "reference.csv",
            "table2_frames.csv",
            "unified.safetensors",
        ],
        "1 and 2 threads",
    );
    assert_same_bytes(
        &one,
        &two,
        &[
            "paper-tables/smoke_table1.md",
            "paper-tables/smoke_table2.md",
            "figures/smoke_table2/transfer_grid.png",
            "figures/smoke_table2/talking_videos.gif",
        ],
        "1 and 2 threads",
    );

    // A second run computes nothing and writes the same bytes.
    let first = latest(&one.join("results"), "table1.csv");
    let again = run_smoke(&one.join("results"), &["--threads", "2"]);
    let stdout = String::from_utf8_lossy(&again.stdout);
    assert!(stdout.contains("0 computed"), "{stdout}");
    assert_eq!(latest(&one.join("results"), "table1.csv"), first);
    let manifest = String::from_utf8(latest(&one.join("results"), "manifest.json")).unwrap();
    assert!(!manifest.contains("\"hit\": false"), "{manifest}");

    // A damaged cache entry is found and recomputed, with the same result.
    let cache = one.join("results/.cache/dataset");
    let entry = std::fs::read_dir(&cache)
        .unwrap()
        .next()
        .unwrap()
        .unwrap()
        .path();
    let csv = entry.join("dataset.csv");
    let bytes = std::fs::read(&csv).unwrap();
    // Before the damage, `status` lists every stage of the spec as cached.
    let status = |results: &Path| -> String {
        let out = facelab(&[
            "status",
            "experiments/smoke.toml",
            "--results",
            &results.display().to_string(),
        ]);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        String::from_utf8_lossy(&out.stdout).into_owned()
    };
    let all = status(&one.join("results"));
    for stage in [
        "dataset",
        "train unified seed 1",
        "cohort",
        "transfer seed 2",
        "renders",
        "inversion",
    ] {
        assert!(all.contains(stage), "{stage} missing from:\n{all}");
    }
    assert!(
        !all.contains("missing") && all.contains(" 0 to run"),
        "{all}"
    );
    std::fs::write(&csv, &bytes[..bytes.len() / 2]).unwrap();
    // `status` reports the damage and leaves the entry as it is.
    let damaged = status(&one.join("results"));
    assert!(
        damaged.contains("damaged") && damaged.contains("dataset.csv does not match its checksum"),
        "{damaged}"
    );
    assert!(csv.exists());
    let healed = run_smoke(&one.join("results"), &[]);
    assert!(
        healed.status.success(),
        "{}",
        String::from_utf8_lossy(&healed.stderr)
    );
    // The run says which entry was damaged before recomputing it.
    let err = String::from_utf8_lossy(&healed.stderr);
    assert!(
        err.contains("is damaged") && err.contains("recomputing"),
        "{err}"
    );
    let manifest = String::from_utf8(latest(&one.join("results"), "manifest.json")).unwrap();
    assert!(manifest.contains("\"stage\": \"dataset\"") && manifest.contains("\"hit\": false"));
    assert_eq!(latest(&one.join("results"), "table1.csv"), first);
    assert_eq!(std::fs::read(&csv).unwrap(), bytes);

    // A diverging configuration names the epoch and fails (the dataset comes from the cache).
    let bad = run_smoke(&one.join("results"), &["--set", "train.learning_rate=1e6"]);
    assert!(!bad.status.success());
    let err = String::from_utf8_lossy(&bad.stderr);
    assert!(err.contains("diverged at epoch"), "{err}");

    // Detector noise reuses the clean faces: no face is solved again, the noise is drawn on
    // the cached readings, and the networks see other inputs (Table 1 alone: what is checked
    // is the data set's reuse and Table 1's change).
    let noisy = run_smoke(
        &one.join("results"),
        &[
            "--set",
            "observer.noise_sd=0.3",
            "--set",
            "tables=[\"table1\"]",
        ],
    );
    assert!(
        noisy.status.success(),
        "{}",
        String::from_utf8_lossy(&noisy.stderr)
    );
    let manifest: serde_json::Value =
        serde_json::from_slice(&latest(&one.join("results"), "manifest.json")).unwrap();
    let stages = manifest["stages"].as_array().unwrap();
    let stage = |name: &str| stages.iter().find(|s| s["stage"] == name).cloned();
    assert_eq!(stage("dataset").unwrap()["hit"], true, "{manifest}");
    assert_eq!(stage("dataset_noise").unwrap()["hit"], false, "{manifest}");
    assert!(stage("basis").is_none_or(|b| b["hit"] == true));
    assert_ne!(latest(&one.join("results"), "table1.csv"), first);
}

#[cfg(unix)]
#[test]
fn a_killed_run_resumes_and_finishes_with_the_same_outputs() {
    let clean = temp("clean");
    let killed = temp("killed");
    // Table 1 alone: the kill lands in its first stages, and Table 2's parts have their own
    // killed-run test below.
    let sets = [
        "--set",
        "dataset.pairs_per_expression=12",
        "--set",
        "tables=[\"table1\"]",
    ];
    let ok = run_smoke(&clean.join("results"), &sets);
    assert!(
        ok.status.success(),
        "{}",
        String::from_utf8_lossy(&ok.stderr)
    );

    let results = killed.join("results");
    let mut child = Command::new(env!("CARGO_BIN_EXE_facelab"))
        .args(["run", "experiments/smoke.toml", "--results"])
        .arg(&results)
        .args(sets)
        .current_dir(root())
        .spawn()
        .unwrap();
    std::thread::sleep(std::time::Duration::from_millis(1500));
    child.kill().unwrap(); // SIGKILL
    child.wait().unwrap();
    // The killed run's folder says it did not finish.
    let folders = |results: &Path| -> Vec<String> {
        let mut names: Vec<String> = std::fs::read_dir(results.join("smoke"))
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        names.sort();
        names
    };
    assert_eq!(folders(&results), ["run-0001.partial"]);
    // No half-written file anywhere: every cache entry that exists verifies.
    let resumed = run_smoke(&results, &sets);
    assert!(
        resumed.status.success(),
        "{}",
        String::from_utf8_lossy(&resumed.stderr)
    );
    // The killed run's unfinished entries are gone.
    for stage in std::fs::read_dir(results.join(".cache")).unwrap() {
        for e in std::fs::read_dir(stage.unwrap().path()).unwrap() {
            let name = e.unwrap().file_name().to_string_lossy().into_owned();
            assert!(!name.starts_with(".tmp-"), "stale {name}");
        }
    }
    // The dead run's folder is gone; the new run took the next number.
    assert_eq!(folders(&results), ["latest", "run-0002"]);
    // An overridden run keeps its tables and figures in its run folder, saying so; the
    // committed record beside the results folder is untouched.
    assert!(!killed.join("paper-tables").exists());
    assert!(!killed.join("figures").exists());
    let md = String::from_utf8(latest(&results, "paper-tables/smoke_table1.md")).unwrap();
    assert!(
        md.contains("Run with overrides: `--set dataset.pairs_per_expression=12`, "),
        "{md}"
    );
    assert!(results.join("smoke/latest/figures/smoke_table1").is_dir());
    for file in ["table1.csv", "curves.csv"] {
        assert_eq!(
            latest(&results, file),
            latest(&clean.join("results"), file),
            "{file}"
        );
    }
}

/// Table 2's cohorts and transfers are cached in parts (per cohort; per setting and cohort): a
/// run killed after two transfer parts finished reuses them when resumed, and its tables equal
/// an uninterrupted run's.
#[test]
fn a_run_killed_in_the_transfer_resumes_from_its_parts() {
    let clean = temp("transfer-clean");
    let killed = temp("transfer-killed");
    let tables = ["--set", "tables=[\"table1\", \"table2\"]"];
    let ok = run_smoke(&clean.join("results"), &tables);
    assert!(
        ok.status.success(),
        "{}",
        String::from_utf8_lossy(&ok.stderr)
    );

    let results = killed.join("results");
    let log = killed.join("stderr.txt");
    let mut child = Command::new(env!("CARGO_BIN_EXE_facelab"))
        .args(["run", "experiments/smoke.toml", "--results"])
        .arg(&results)
        .args(tables)
        .current_dir(root())
        .stdout(std::process::Stdio::null())
        .stderr(std::fs::File::create(&log).unwrap())
        .spawn()
        .unwrap();
    let parts_done = |text: &str| {
        text.lines()
            .filter(|l| l.starts_with("transfer_part/") && l.contains(": done in"))
            .count()
    };
    let start = std::time::Instant::now();
    while parts_done(&std::fs::read_to_string(&log).unwrap()) < 2 {
        assert!(child.try_wait().unwrap().is_none(), "the run ended first");
        assert!(start.elapsed().as_secs() < 600, "no transfer part finished");
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    child.kill().unwrap(); // SIGKILL
    child.wait().unwrap();

    let resumed = run_smoke(&results, &tables);
    assert!(
        resumed.status.success(),
        "{}",
        String::from_utf8_lossy(&resumed.stderr)
    );
    let text = std::fs::read_to_string(results.join("smoke/latest/manifest.json")).unwrap();
    let manifest: serde_json::Value = serde_json::from_str(&text).unwrap();
    let hits = |stage: &str| {
        manifest["stages"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|r| r["stage"] == stage && r["hit"] == true)
            .count()
    };
    assert!(hits("transfer_part") >= 2, "{text}");
    // The cohorts finished before the kill: cached whole, their parts not looked up.
    assert_eq!(hits("cohort"), 1, "{text}");
    assert_same_bytes(
        &clean.join("results/smoke/latest"),
        &results.join("smoke/latest"),
        &["table2.csv", "reference.csv", "table2_frames.csv"],
        "killed in the transfer and resumed",
    );
}

#[test]
fn two_runs_at_once_share_a_results_folder_and_verify_reproduces_them() {
    let dir = temp("concurrent");
    let results = dir.join("results");
    let r = results.display().to_string();
    // Table 1 alone: what is shared (the cache, the run numbers, `latest`, the publish lock)
    // is the same for every table.
    let spawn = || {
        Command::new(env!("CARGO_BIN_EXE_facelab"))
            .args([
                "run",
                "experiments/smoke.toml",
                "--threads",
                "1",
                "--results",
                &r,
                "--set",
                "tables=[\"table1\"]",
            ])
            .current_dir(root())
            .output()
            .unwrap()
    };
    let (a, b) = std::thread::scope(|s| {
        let a = s.spawn(spawn);
        let b = s.spawn(spawn);
        (a.join().unwrap(), b.join().unwrap())
    });
    assert!(a.status.success(), "{}", String::from_utf8_lossy(&a.stderr));
    assert!(b.status.success(), "{}", String::from_utf8_lossy(&b.stderr));
    let one = std::fs::read(results.join("smoke/run-0001/table1.csv")).unwrap();
    let two = std::fs::read(results.join("smoke/run-0002/table1.csv")).unwrap();
    assert_eq!(one, two);
    // The run that finished second says that it replaces the first as latest.
    let said = [&a, &b]
        .iter()
        .filter(|o| String::from_utf8_lossy(&o.stderr).contains("replaces it as latest"))
        .count();
    assert_eq!(said, 1);

    let verify = facelab(&[
        "verify",
        &results.join("smoke/run-0001").display().to_string(),
    ]);
    let stdout = String::from_utf8_lossy(&verify.stdout);
    assert!(
        verify.status.success(),
        "{}",
        String::from_utf8_lossy(&verify.stderr)
    );
    assert!(stdout.contains("reproduced byte for byte"), "{stdout}");
}

/// A run publishes its tables, figures and `latest` under the results folder's lock: while a
/// live process holds it the run waits (saying so) and publishes nothing; a lock left by a
/// process that has ended is taken over.
#[test]
fn a_run_waits_for_the_publish_lock_and_takes_over_a_dead_one() {
    let dir = temp("publish-lock");
    let results = dir.join("results");
    std::fs::create_dir_all(&results).unwrap();
    let lock = results.join(".publish.lock");
    let host = std::fs::read_to_string("/proc/sys/kernel/hostname").unwrap();
    let host = host.trim();
    // This test's own process: alive for as long as the run waits.
    std::fs::write(&lock, format!("{host} {}\n", std::process::id())).unwrap();
    let log = dir.join("stderr.txt");
    let mut child = Command::new(env!("CARGO_BIN_EXE_facelab"))
        .args(["run", &smoke(), "--results", &results.display().to_string()])
        .args(["--set", "tables=[\"table1\"]", "--publish"])
        .stdout(std::process::Stdio::null())
        .stderr(std::fs::File::create(&log).unwrap())
        .spawn()
        .unwrap();
    let waiting = "is publishing its tables; waiting for it";
    let start = std::time::Instant::now();
    while !std::fs::read_to_string(&log).unwrap().contains(waiting) {
        assert!(
            child.try_wait().unwrap().is_none(),
            "the run ended without waiting"
        );
        assert!(
            start.elapsed().as_secs() < 600,
            "the run never reached the lock"
        );
        std::thread::sleep(std::time::Duration::from_millis(200));
    }
    let tables = dir.join("paper-tables");
    assert!(!tables.join("smoke_table1.md").exists());
    assert!(!results.join("smoke/latest").exists());
    std::fs::remove_file(&lock).unwrap();
    assert!(child.wait().unwrap().success());
    assert!(tables.join("smoke_table1.md").exists());
    assert!(results.join("smoke/latest/table1.csv").exists());
    assert!(!lock.exists(), "the run left its lock");
    assert!(!results.join("smoke/latest/.publish").exists());

    // A lock whose process has ended (a run killed while publishing) is taken over.
    std::fs::write(&lock, format!("{host} 4194303999\n")).unwrap();
    let out = facelab(&[
        "run",
        &smoke(),
        "--results",
        &results.display().to_string(),
        "--set",
        "tables=[\"table1\"]",
        "--publish",
    ]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert!(
        stderr.contains("stopped while publishing; taking it over"),
        "{stderr}"
    );
    assert!(!lock.exists());
}

#[test]
fn manifest_names_the_commit_and_a_clean_checkout_whatever_the_run_writes_into_it() {
    // A run inside a checkout writes its outputs there; they must not make the checkout it
    // started from look modified.
    let dir = temp("provenance");
    let git = |args: &[&str]| {
        let o = Command::new("git")
            .args([
                "-c",
                "user.name=facelab",
                "-c",
                "user.email=facelab@localhost",
            ])
            .args(args)
            .current_dir(&dir)
            .output()
            .expect("run git");
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        String::from_utf8(o.stdout).unwrap().trim().to_string()
    };
    git(&["init", "-q"]);
    git(&["commit", "-q", "--allow-empty", "-m", "start"]);
    let head = git(&["rev-parse", "HEAD"]);
    let run = || {
        let out = Command::new(env!("CARGO_BIN_EXE_facelab"))
            .args(["run", &smoke(), "--results", "results"])
            .args(["--set", "tables=[\"table1\"]"])
            .current_dir(&dir)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
    };
    run();
    assert!(
        !git(&["status", "--porcelain"]).is_empty(),
        "the run wrote nothing into the checkout"
    );
    let manifest = || -> (serde_json::Value, String) {
        let text = std::fs::read_to_string(dir.join("results/smoke/latest/manifest.json")).unwrap();
        (serde_json::from_str(&text).unwrap(), text)
    };
    let (m, text) = manifest();
    assert_eq!(m["git_revision"], head.as_str(), "{text}");
    // The code's provenance is the binary's own, recorded when it was built from this
    // repository, not the checkout it runs in.
    let built = Command::new("git")
        .args(["rev-parse", "HEAD"])
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .unwrap();
    let built = String::from_utf8_lossy(&built.stdout).trim().to_string();
    assert_eq!(m["build"]["revision"], built.as_str(), "{text}");
    assert_ne!(m["build"]["revision"], head.as_str(), "{text}");
    assert_eq!(m["git_dirty"], false, "{text}");
    // Nor do an earlier run's outputs make the next run's checkout look modified; anything
    // else does.
    run();
    let (m, text) = manifest();
    assert_eq!(m["git_dirty"], false, "{text}");
    std::fs::write(dir.join("notes.txt"), "an uncommitted change").unwrap();
    run();
    let (m, text) = manifest();
    assert_eq!(m["git_dirty"], true, "{text}");
}

/// The committed runs (`results/*/latest`) that predate a change of their stages' code: their
/// manifests recorded unit keys that their recorded specs, planned with today's code, no
/// longer make. They are named here until they are rerun; a named run that is current fails
/// the test as well, so the list only shrinks.
const NOT_YET_RERUN: &[&str] = &[];

#[test]
fn every_committed_run_is_from_todays_code_but_the_named_ones() {
    let runs = facelab::run::committed(
        &facelab::io::Layout::here(),
        &root().join("results"),
        facelab::experiments::REGISTRY,
    )
    .expect("the committed runs plan");
    assert!(runs.len() >= 6, "{} committed runs", runs.len());
    let mut wrong = Vec::new();
    for r in &runs {
        let experiment = r
            .run
            .parent()
            .unwrap()
            .file_name()
            .unwrap()
            .to_string_lossy();
        let named = NOT_YET_RERUN.contains(&experiment.as_ref());
        assert!(r.planned > 0, "{}: plans nothing", r.run.display());
        if r.is_current() == named {
            wrong.push(format!(
                "{experiment} ({}): {} recorded units today's code does not plan ({} planned){}",
                if named {
                    "named as not rerun, but current"
                } else {
                    "stale"
                },
                r.stale.len(),
                r.planned,
                r.stale
                    .first()
                    .map_or(String::new(), |s| format!(", e.g. {s}"))
            ));
        }
    }
    assert!(wrong.is_empty(), "{}", wrong.join("\n"));
}
