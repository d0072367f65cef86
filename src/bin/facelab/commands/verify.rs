//! `facelab verify`: a run recomputed in a temporary folder, its CSVs compared by hash.

use facelab::experiments::REGISTRY;

use super::Context;
use crate::cli::VerifyArgs;

pub fn run(args: VerifyArgs, cx: &Context) -> anyhow::Result<()> {
    let differ = facelab::run::verify(
        &cx.layout,
        &args.run_dir,
        cx.threads,
        REGISTRY,
        cx.verbosity,
    )?;
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
