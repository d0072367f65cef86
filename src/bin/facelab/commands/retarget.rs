//! `facelab retarget`: one activation sequence on the base face and on cohort subjects.

use facelab::tools::edit::retarget;

use crate::cli::RetargetArgs;

pub fn run(args: RetargetArgs) -> anyhow::Result<()> {
    for p in retarget(&args.curves, args.subjects, &args.frames, &args.out)? {
        println!("wrote {}", p.display());
    }
    Ok(())
}
