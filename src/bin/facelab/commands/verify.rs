//! `facelab verify`: a run recomputed in a temporary folder, its CSVs compared by hash.

use facelab::experiments::REGISTRY;

use super::set_threads;
use crate::cli::VerifyArgs;

pub fn run(args: VerifyArgs, verbosity: facelab::run::stage::Verbosity) -> anyhow::Result<()> {
    let threads = set_threads(args.threads)?;
    let differ = facelab::run::verify(&args.run_dir, threads, REGISTRY, verbosity)?;
    if differ.is_empty() {
        println!(
            "{}: every CSV reproduced byte for byte",
            args.run_dir.display()
        );
        Ok(())
    } else {
        anyhow::bail!(
            "{}: these outputs differ on rerun: {}",
            args.run_dir.display(),
            differ.join(", ")
        )
    }
}
