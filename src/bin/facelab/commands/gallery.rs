//! `facelab gallery`: the rest face, each expression and each muscle alone, rendered.

use facelab::tools::face::gallery;

use crate::cli::GalleryArgs;

pub fn run(args: GalleryArgs) -> anyhow::Result<()> {
    let written = gallery(&args.face.source(), &args.out)?;
    println!("wrote {} images to {}", written.len(), args.out.display());
    Ok(())
}
