//! `facelab task` (hidden): one Slurm array task of a submitted run, its units into the cache.

use facelab::experiments::REGISTRY;
use facelab::run;

use crate::cli::TaskArgs;

pub fn run(args: TaskArgs, verbosity: facelab::run::stage::Verbosity) -> anyhow::Result<()> {
    run::task(&args.launch, &args.array, args.index, REGISTRY, verbosity)?;
    Ok(())
}
