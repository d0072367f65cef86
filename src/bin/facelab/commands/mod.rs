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

use std::path::{Path, PathBuf};

use anyhow::Context;
use facelab::transfer::pictures::{LandmarkOutput, PhotoNeutral};

/// Sets the thread counts, once, before any command runs: rayon's pool gets `threads` workers
/// (else the Slurm task's cores, else `RAYON_NUM_THREADS` as the caller set it, else all
/// cores), and candle runs each operation on one thread. candle sizes its matrix products by `RAYON_NUM_THREADS`, which it reads at every
/// product; facelab runs its parallel work (frames, faces, seeds) on rayon's workers, and a
/// small network trains fastest on one thread (`bench train`), so the variable is set to 1
/// here and never changed after. The bytes of every result do not depend on either count.
/// Returns the worker count.
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

/// A file or folder of the checkout named on the command line (a spec, a run folder): as
/// given where it exists, else found in the checkout or the binary's built-in copy
/// ([`facelab::io::data_path`]), so `facelab run experiments/smoke.toml` and the default
/// `--model results/paper/latest` work from any folder.
pub fn data_arg(given: PathBuf) -> PathBuf {
    if given.exists() || given.is_absolute() {
        return given;
    }
    given.to_str().map_or(given.clone(), facelab::io::data_path)
}

/// The results folder: the default `results` means the checkout's `results/` when the working
/// folder is inside a checkout (so a run from a subfolder writes where a run from the root
/// does); anything else is taken as given, relative to the working folder.
pub fn results_folder(given: PathBuf) -> PathBuf {
    if given != Path::new("results") {
        return given;
    }
    std::env::current_dir()
        .ok()
        .and_then(|d| facelab::io::find_root(&d))
        .map_or(given, |root| root.join("results"))
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
