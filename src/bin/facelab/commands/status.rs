//! `facelab status`: which stages of a spec are cached, missing, damaged or queued.

use facelab::experiments::REGISTRY;
use facelab::run::{self, UnitState};

use super::Context;
use crate::cli::StatusArgs;

pub fn run(args: StatusArgs, cx: &Context) -> anyhow::Result<()> {
    let results = cx.layout.results(args.results);
    let lines = run::status(
        &cx.layout,
        &cx.layout.file(args.spec.spec),
        &args.spec.sets,
        &results,
        REGISTRY,
    )?;
    let (mut cached, mut todo) = (0, 0);
    for line in &lines {
        let (state, note) = match &line.state {
            UnitState::Cached => ("cached", String::new()),
            UnitState::Missing => ("missing", String::new()),
            UnitState::Damaged(why) => ("damaged", format!(" ({why})")),
            UnitState::Waiting(why) => ("waiting", format!(" ({why})")),
            UnitState::Queued(by) => ("queued", format!(" ({by})")),
            UnitState::Running(by) => ("running", format!(" ({by})")),
            UnitState::Failed(why) => ("failed", format!(" ({why})")),
        };
        if line.state == UnitState::Cached {
            cached += 1;
        } else {
            todo += 1;
        }
        let cell = if line.cell.is_empty() {
            String::new()
        } else {
            format!(" [{}]", line.cell)
        };
        let key = line
            .unit
            .as_ref()
            .map_or("-".to_string(), |u| u.key[..12].to_string());
        println!("{state:<8} {key:<12} {}{cell}{note}", line.label);
    }
    println!(
        "{cached} cached, {todo} to run in {}; status reads the cache and changes nothing",
        results.join(".cache").display()
    );
    Ok(())
}
