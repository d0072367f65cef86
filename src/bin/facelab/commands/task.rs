//! `facelab task` (hidden): one Slurm array task of a submitted run, its units into the cache.

use facelab::experiments::REGISTRY;
use facelab::run;

use super::Context;
use crate::cli::TaskArgs;

pub fn run(args: TaskArgs, cx: &Context) -> anyhow::Result<()> {
    run::task(
        &cx.layout,
        &args.launch,
        &args.array,
        args.index,
        REGISTRY,
        cx.verbosity,
    )?;
    Ok(())
}
