//! `facelab render`: one face, posed and rendered.

use facelab::report::render::{Camera, RenderOptions};
use facelab::tools::face::render_to;

use super::Context;
use crate::cli::{RenderArgs, View};

pub fn run(args: RenderArgs, cx: &Context) -> anyhow::Result<()> {
    let request = args.pose.request()?;
    let options = RenderOptions {
        width: args.width,
        height: args.height,
        camera: match args.view {
            View::Frontal => Camera::frontal(),
            View::ThreeQuarter => Camera::three_quarter(),
        },
        muscle_overlay: args.overlay,
    };
    render_to(&args.face.source(&cx.layout), &request, &options, &args.out)?;
    println!("wrote {}", args.out.display());
    Ok(())
}
