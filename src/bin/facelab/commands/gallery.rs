//! `facelab gallery`: the rest face, each expression and each muscle alone, rendered.

use facelab::tools::face::gallery;

use super::Context;
use crate::cli::GalleryArgs;

pub fn run(args: GalleryArgs, cx: &Context) -> anyhow::Result<()> {
    let written = gallery(&cx.layout, &args.face.source(&cx.layout), &args.out)?;
    println!("wrote {} images to {}", written.len(), args.out.display());
    Ok(())
}
