//! `facelab check`: a spec validated and printed resolved, one block per cell.

use super::Context;
use crate::cli::SpecArgs;

pub fn run(args: SpecArgs, cx: &Context) -> anyhow::Result<()> {
    for cell in facelab::spec::load(&cx.layout, &cx.layout.file(args.spec), &args.sets)? {
        if !cell.name.is_empty() {
            println!("# cell {}", cell.name);
        }
        print!("{}", cell.spec.to_toml());
    }
    Ok(())
}
