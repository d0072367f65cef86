//! `facelab edit`: activation curves edited by keyframes (Choe et al.'s displacement map).

use facelab::tools::edit::edit_file;

use super::Context;
use crate::cli::EditArgs;

pub fn run(args: EditArgs, _cx: &Context) -> anyhow::Result<()> {
    let written = edit_file(
        &args.curves,
        &args.keys,
        args.knot_spacing,
        &args.out,
        args.figure
            .as_deref()
            .map(|f| (f, args.figure_spacings.as_slice())),
    )?;
    for p in written {
        println!("wrote {}", p.display());
    }
    Ok(())
}
