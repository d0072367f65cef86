//! `facelab run`: a spec's stages, locally or as Slurm job arrays.

use facelab::experiments::REGISTRY;
use facelab::run;
use facelab::spec::LauncherKind;

use super::Context;
use crate::cli::RunArgs;

pub fn run(args: RunArgs, cx: &Context) -> anyhow::Result<()> {
    let spec = cx.layout.file(args.spec.spec);
    let given = args.launcher.as_deref().and_then(LauncherKind::parse);
    let opts = run::RunOptions {
        results: cx.layout.results(args.results),
        sets: args.spec.sets,
        threads: cx.threads,
        publish: args.publish,
        assemble: args.assemble,
        registry: REGISTRY,
        verbosity: cx.verbosity,
        layout: cx.layout.clone(),
    };
    let kind = run::launcher_of(&cx.layout, &spec, &opts.sets, given)?;
    if kind == LauncherKind::Slurm && opts.assemble.is_none() {
        let l = run::launch(&spec, &opts)?;
        let job = |j: &Option<String>| j.clone().unwrap_or_else(|| "-".into());
        println!(
            "submitted {} task(s) ({} cached, not submitted): cells array {}, seeds array {}, \
             final job {}; run folder {}",
            l.tasks,
            l.skipped,
            job(&l.cells_job),
            job(&l.seeds_job),
            l.final_job,
            l.run_dir.display()
        );
        if args.wait {
            run::wait(&l)?;
        }
        return Ok(());
    }
    if args.wait {
        anyhow::bail!("--wait is for --launcher slurm; a local run always waits");
    }
    let summary = run::run(&spec, &opts)?;
    let hits = summary.stages.iter().filter(|s| s.hit).count();
    println!(
        "{} stages, {} cached, {} computed; wrote {}",
        summary.stages.len(),
        hits,
        summary.stages.len() - hits,
        summary.dir.display()
    );
    Ok(())
}
