//! One file per subcommand, each a `run(args)` that main dispatches to, and what they share:
//! the worker count, where a named checkout file or the results folder is, how a picture's
//! neutral face is named and how its landmarking is reported.

pub mod bench;
pub mod check;
pub mod edit;
pub mod face;
pub mod gallery;
pub mod observe;
pub mod render;
pub mod retarget;
pub mod run;
pub mod status;
pub mod task;
pub mod transfer;
pub mod verify;

use anyhow::Context as _;
use facelab::transfer::pictures::{LandmarkOutput, PhotoNeutral};

/// Sets the thread counts, once, before any command runs: rayon's pool gets `threads` workers
/// (else the Slurm task's cores, else `RAYON_NUM_THREADS` as the caller set it, else all
/// cores), and candle runs each operation on one thread. candle sizes its matrix products by
/// `RAYON_NUM_THREADS`, which it reads at every product; facelab runs its parallel work
/// (frames, faces, seeds) on rayon's workers, and a small network trains fastest on one thread
/// (`bench train`), so the variable is set to 1 here and never changed after. The bytes of
/// every result do not depend on either count. Returns the worker count.
pub fn set_threads(threads: Option<usize>) -> anyhow::Result<usize> {
    let from = |var: &str| {
        std::env::var(var)
            .ok()
            .and_then(|v| v.parse::<usize>().ok())
            .filter(|&n| n > 0)
    };
    // Inside a Slurm allocation, "all cores" are the task's (a task inherits the submitting
    // process's environment, where the variable below is already 1).
    let n = threads
        .or_else(|| from("SLURM_CPUS_PER_TASK"))
        .or_else(|| from("RAYON_NUM_THREADS"))
        .unwrap_or_else(|| {
            std::thread::available_parallelism()
                .map(|n| n.get())
                .unwrap_or(1)
        });
    if n == 0 {
        anyhow::bail!("--threads must be at least 1");
    }
    // Before any thread starts: main calls this first.
    std::env::set_var("RAYON_NUM_THREADS", "1");
    rayon::ThreadPoolBuilder::new()
        .num_threads(n)
        .build_global()
        .context("starting the thread pool")?;
    Ok(n)
}

/// What main finds once, before any command runs, and hands each command: where the
/// checkout's files are, the worker count (already set) and what to print.
pub struct Context {
    pub layout: facelab::io::Layout,
    pub threads: usize,
    pub verbosity: facelab::run::stage::Verbosity,
}

/// `--neutral` of a picture input (clap allows only `model` and `median`).
pub fn photo_neutral(name: &str) -> PhotoNeutral {
    match name {
        "model" => PhotoNeutral::Model,
        _ => PhotoNeutral::Median,
    }
}

/// What the landmarker found in a picture input, and its warnings.
pub fn print_landmarked(l: &LandmarkOutput) {
    for w in &l.warnings {
        eprintln!("warning: {w}");
    }
    println!(
        "{:?}: a face in {} frame(s), none in {}",
        l.kind, l.faces, l.missing
    );
}
