//! `facelab retarget`: one activation sequence on the base face and on cohort subjects.

use facelab::tools::edit::retarget;

use super::Context;
use crate::cli::RetargetArgs;

pub fn run(args: RetargetArgs, cx: &Context) -> anyhow::Result<()> {
    for p in retarget(
        &cx.layout,
        &args.curves,
        args.subjects,
        &args.frames,
        &args.out,
    )? {
        println!("wrote {}", p.display());
    }
    Ok(())
}
