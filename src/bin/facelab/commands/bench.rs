//! `facelab bench ...`: the benchmarks (run with --release), each printing its numbers and how
//! they were measured.

use facelab::sim::SolveParams;
use facelab::tools::bench::{
    bench_landmark, bench_neck, bench_observe, bench_solve, bench_train, bench_transfer,
};

use super::Context;
use crate::cli::Bench;

pub fn run(what: Bench, cx: &Context) -> anyhow::Result<()> {
    let out = &mut std::io::stdout().lock();
    match what {
        // The thread counts were set by main from each benchmark's own (`Command::threads`).
        Bench::Landmark {
            frames, seconds, ..
        } => bench_landmark(&cx.layout, frames, seconds, out),
        Bench::Train {
            pairs,
            epochs,
            export,
            ..
        } => bench_train(pairs, epochs, export.as_deref(), out),
        Bench::Transfer { model, clips } => {
            bench_transfer(&cx.layout, &cx.layout.file(model), clips, out)
        }
        Bench::Neck { seconds } => bench_neck(seconds, out),
        Bench::Observe { frames } => bench_observe(&cx.layout, frames, out),
        Bench::Solve {
            face,
            samples,
            seed,
            levels,
            tolerance,
            grid,
        } => bench_solve(
            &face.source(&cx.layout),
            &levels,
            samples,
            seed,
            grid,
            &SolveParams {
                tolerance,
                ..SolveParams::default()
            },
            out,
        ),
    }
}
