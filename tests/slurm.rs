//! `facelab run --launcher slurm` on a one-node Slurm cluster this test starts on localhost
//! (munged, slurmctld, slurmd; a `slurm.conf` in a temporary folder; the daemons it started
//! are stopped at the end): a sweep of two cells x two seeds of the smoke spec gives the local
//! run's bytes; a cancelled array leaves the final job naming the missing units and `status`
//! naming the failed tasks; resubmitting submits only what is missing.
//!
//! Skipped, saying why, where Slurm is not installed or its daemons cannot be started, unless
//! `FACELAB_REQUIRE_SLURM=1` (as `.ci/run` sets it), where that is a failure.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output};
use std::time::{Duration, Instant};

use crate::{assert_same_bytes, root, temp};

/// A one-node cluster; stops the daemons it started when dropped.
struct Cluster {
    conf: PathBuf,
    daemons: Vec<Child>,
    munged: Option<PathBuf>,
}

impl Drop for Cluster {
    fn drop(&mut self) {
        let _ = self.command("scancel").args(["--user", &user()]).output();
        for d in &mut self.daemons {
            let _ = d.kill();
            let _ = d.wait();
        }
        if let Some(pid_file) = &self.munged {
            if let Ok(pid) = std::fs::read_to_string(pid_file) {
                let _ = Command::new("kill").arg(pid.trim()).output();
            }
        }
    }
}

fn user() -> String {
    std::env::var("USER").unwrap_or_else(|_| "root".into())
}

fn installed(program: &str) -> bool {
    Command::new("sh")
        .args(["-c", &format!("command -v {program}")])
        .output()
        .is_ok_and(|o| o.status.success())
}

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .map(|a| a.port())
        .expect("a free port")
}

impl Cluster {
    fn command(&self, program: &str) -> Command {
        let mut c = Command::new(program);
        c.env("SLURM_CONF", &self.conf);
        c
    }

    /// Starts the cluster, or says why it cannot.
    fn start(dir: &Path) -> Result<Cluster, String> {
        for program in [
            "munged",
            "slurmctld",
            "slurmd",
            "sbatch",
            "squeue",
            "scancel",
        ] {
            if !installed(program) {
                return Err(format!(
                    "{program} is not installed (Debian: slurm-wlm, munge)"
                ));
            }
        }
        let id = Command::new("id")
            .arg("-u")
            .output()
            .map_err(|e| e.to_string())?;
        if String::from_utf8_lossy(&id.stdout).trim() != "0" {
            return Err("slurmd runs as root, and this test is not root".into());
        }
        std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
        // munge: use the running daemon, or start one.
        let munge_works = || {
            Command::new("sh")
                .args(["-c", "munge -n | unmunge"])
                .output()
                .is_ok_and(|o| o.status.success())
        };
        let mut munged = None;
        if !munge_works() {
            let pid_file = dir.join("munged.pid");
            let socket = "/run/munge/munge.socket.2";
            let _ = std::fs::create_dir_all("/run/munge");
            let out = Command::new("munged")
                .args(["--force", "--pid-file"])
                .arg(&pid_file)
                .args(["--socket", socket])
                .output()
                .map_err(|e| format!("munged: {e}"))?;
            if !out.status.success() || !munge_works() {
                return Err(format!(
                    "munged does not start: {}",
                    String::from_utf8_lossy(&out.stderr).trim()
                ));
            }
            munged = Some(pid_file);
        }
        let host = std::fs::read_to_string("/proc/sys/kernel/hostname")
            .map(|h| h.trim().to_string())
            .map_err(|e| e.to_string())?;
        for sub in ["state", "spool", "log"] {
            std::fs::create_dir_all(dir.join(sub)).map_err(|e| e.to_string())?;
        }
        let d = dir.display();
        let conf = dir.join("slurm.conf");
        let text = format!(
            "ClusterName=facelab\nSlurmctldHost={host}\nSlurmctldPort={}\nSlurmdPort={}\n\
             AuthType=auth/munge\nSlurmUser=root\nSlurmdUser=root\nStateSaveLocation={d}/state\n\
             SlurmdSpoolDir={d}/spool\nSlurmctldPidFile={d}/slurmctld.pid\n\
             SlurmdPidFile={d}/slurmd.pid\nSlurmctldLogFile={d}/log/slurmctld.log\n\
             SlurmdLogFile={d}/log/slurmd.log\nProctrackType=proctrack/linuxproc\n\
             TaskPlugin=task/none\nSchedulerType=sched/backfill\nSelectType=select/cons_tres\n\
             SelectTypeParameters=CR_CPU\nReturnToService=2\nMailProg=/bin/true\n\
             JobAcctGatherType=jobacct_gather/none\nAccountingStorageType=accounting_storage/none\n\
             MpiDefault=none\nNodeName={host} CPUs=2 RealMemory=4000 State=UNKNOWN\n\
             PartitionName=facelab Nodes={host} Default=YES MaxTime=INFINITE State=UP\n",
            free_port(),
            free_port()
        );
        std::fs::write(&conf, text).map_err(|e| e.to_string())?;
        let mut cluster = Cluster {
            conf: conf.clone(),
            daemons: Vec::new(),
            munged,
        };
        for daemon in ["slurmctld", "slurmd"] {
            let child = cluster
                .command(daemon)
                .args(["-D", "-f"])
                .arg(&conf)
                .stdout(std::process::Stdio::null())
                .stderr(std::process::Stdio::null())
                .spawn()
                .map_err(|e| format!("{daemon}: {e}"))?;
            cluster.daemons.push(child);
        }
        let t = Instant::now();
        loop {
            let out = cluster.command("sinfo").args(["-h", "-o", "%T"]).output();
            if out.is_ok_and(|o| String::from_utf8_lossy(&o.stdout).trim() == "idle") {
                return Ok(cluster);
            }
            if t.elapsed() > Duration::from_secs(60) {
                let log =
                    std::fs::read_to_string(dir.join("log/slurmctld.log")).unwrap_or_default();
                return Err(format!(
                    "the node did not come up in 60 s; slurmctld.log:\n{log}"
                ));
            }
            std::thread::sleep(Duration::from_millis(500));
        }
    }

    fn facelab(&self, args: &[&str]) -> Output {
        self.command(env!("CARGO_BIN_EXE_facelab"))
            .args(args)
            .current_dir(root())
            .output()
            .expect("run facelab")
    }

    /// Waits until the queue is empty.
    fn drain(&self) {
        let t = Instant::now();
        loop {
            let out = self.command("squeue").args(["-h"]).output().unwrap();
            if String::from_utf8_lossy(&out.stdout).trim().is_empty() {
                return;
            }
            assert!(
                t.elapsed() < Duration::from_secs(900),
                "jobs still queued after 15 min"
            );
            std::thread::sleep(Duration::from_secs(1));
        }
    }
}

fn text(o: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

/// Every file under `dir`, relative to it, without what is not a result (the manifest,
/// timings, Slurm's logs).
fn outputs(dir: &Path) -> Vec<String> {
    let mut out = Vec::new();
    let mut todo = vec![dir.to_path_buf()];
    while let Some(d) = todo.pop() {
        for e in std::fs::read_dir(&d).unwrap().flatten() {
            let p = e.path();
            if p.is_dir() {
                todo.push(p);
            } else {
                out.push(p.strip_prefix(dir).unwrap().display().to_string());
            }
        }
    }
    out.retain(|f| {
        !f.ends_with("manifest.json") && !f.contains("timings/") && !f.starts_with("logs/")
    });
    out.sort();
    out
}

#[test]
fn a_sweep_on_slurm_gives_the_local_bytes_and_resubmits_only_what_is_missing() {
    let dir = temp("slurm", "cluster");
    let cluster = match Cluster::start(&dir.join("slurm")) {
        Ok(c) => c,
        Err(why) => {
            assert!(
                std::env::var("FACELAB_REQUIRE_SLURM").as_deref() != Ok("1"),
                "FACELAB_REQUIRE_SLURM=1 but the one-node cluster cannot start: {why}"
            );
            eprintln!("skipped: a one-node Slurm cluster cannot start here: {why}");
            return;
        }
    };
    // Two cells (epochs) x two seeds of the smoke spec, one CPU per task; Tables 1 and 2,
    // whose units are split between the cells and the seeds arrays (the inversion's would
    // add a unit to each cell task and nothing to the split).
    let spec = dir.join("sweep.toml");
    std::fs::write(
        &spec,
        format!(
            "extends = \"{}\"\nexperiment = \"slurm_sweep\"\ntables = [\"table1\", \"table2\"]\n\n\
             [sweep]\n\"train.epochs\" = [4, 5]\n\n[launcher]\ncpus_per_task = 1\n",
            root().join("experiments/smoke.toml").display()
        ),
    )
    .unwrap();
    let spec = spec.display().to_string();
    let results = |name: &str| dir.join(name).join("results").display().to_string();

    // The local run: the reference bytes.
    let local = cluster.facelab(&[
        "run",
        &spec,
        "--launcher",
        "local",
        "--results",
        &results("local"),
    ]);
    assert!(local.status.success(), "{}", text(&local));

    // The first submission; its seeds array cancelled before it starts.
    let first = cluster.facelab(&[
        "run",
        &spec,
        "--launcher",
        "slurm",
        "--results",
        &results("slurm"),
    ]);
    assert!(first.status.success(), "{}", text(&first));
    let said = text(&first);
    assert!(said.contains("submitted 4 task(s)"), "{said}");
    let seeds_job = said
        .split("seeds array ")
        .nth(1)
        .and_then(|s| s.split(',').next())
        .expect("the seeds array's job id")
        .to_string();
    let cancel = cluster.command("scancel").arg(&seeds_job).output().unwrap();
    assert!(cancel.status.success(), "{}", text(&cancel));
    cluster.drain();
    let experiment = dir.join("slurm/results/slurm_sweep");
    let partial = experiment.join("run-0001.partial");
    let final_log = std::fs::read_to_string(partial.join("logs/final.log")).unwrap();
    assert!(
        final_log.contains("missing from the cache after the Slurm tasks")
            && final_log.contains("seeds-0"),
        "{final_log}"
    );
    let status = cluster.facelab(&["status", &spec, "--results", &results("slurm")]);
    let status = text(&status);
    assert!(
        status.contains("failed") && status.contains("task seeds-1"),
        "{status}"
    );

    // Resubmitted: only the cancelled tasks run, and the run finishes.
    let again = cluster.facelab(&[
        "run",
        &spec,
        "--launcher",
        "slurm",
        "--wait",
        "--results",
        &results("slurm"),
    ]);
    assert!(again.status.success(), "{}", text(&again));
    assert!(
        text(&again).contains("submitted 2 task(s) (2 cached, not submitted)"),
        "{}",
        text(&again)
    );
    // Into the CI log, past the test harness' capture: what the cluster ran.
    {
        use std::io::Write as _;
        let again = text(&again);
        let lines: Vec<&str> = said
            .lines()
            .chain(again.lines())
            .filter(|l| l.starts_with("submitted") || l.starts_with("Slurm jobs finished"))
            .collect();
        let _ = writeln!(
            std::io::stderr(),
            "slurm test: {}",
            lines.join("\nslurm test: ")
        );
    }
    let a = dir.join("local/results/slurm_sweep/latest");
    let b = experiment.join("latest");
    let files = outputs(&a);
    // The sweep's summary and, per cell, Table 1's (table1, curves), Table 2's (table2,
    // reference, frames) and its spec.
    assert_eq!(files.len(), 1 + 2 * 6, "{files:?}");
    assert_eq!(files, outputs(&b));
    let names: Vec<&str> = files.iter().map(String::as_str).collect();
    assert_same_bytes(&a, &b, &names, "the local and the Slurm run");
    for published in [
        "paper-tables/slurm_sweep.md",
        "figures/slurm_sweep/sweep.png",
    ] {
        assert_same_bytes(
            &dir.join("local"),
            &dir.join("slurm"),
            &[published],
            "the two runs",
        );
    }
    let manifest = std::fs::read_to_string(b.join("manifest.json")).unwrap();
    assert!(
        manifest.contains("\"kind\": \"slurm\"") && manifest.contains("\"host\""),
        "{manifest}"
    );
    assert!(b.join("logs/final.log").exists() && b.join("logs/seeds-0.log").exists());
}

#[test]
fn without_sbatch_a_slurm_run_says_slurm_is_not_installed() {
    let out = Command::new(env!("CARGO_BIN_EXE_facelab"))
        .args([
            "run",
            "experiments/smoke.toml",
            "--launcher",
            "slurm",
            "--results",
        ])
        .arg(temp("slurm", "missing").join("results"))
        .current_dir(root())
        .env("PATH", "/nonexistent")
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("Slurm is not installed"), "{err}");
}
