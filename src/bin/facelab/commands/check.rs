//! `facelab check`: a spec validated and printed resolved, one block per cell.

use super::data_arg;
use crate::cli::SpecArgs;

pub fn run(args: SpecArgs) -> anyhow::Result<()> {
    for cell in facelab::spec::load(&data_arg(args.spec), &args.sets)? {
        if !cell.name.is_empty() {
            println!("# cell {}", cell.name);
        }
        print!("{}", cell.spec.to_toml());
    }
    Ok(())
}
