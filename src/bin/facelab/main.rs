//! The `facelab` command line: parse the arguments, set what every command shares (verbosity,
//! the thread counts, the checkout the data files come from), dispatch to the command's file
//! in `commands/`, print the error chain and exit non-zero on failure.

mod cli;
mod commands;

use std::process::ExitCode;

use clap::Parser;
use facelab::run::stage::Verbosity;

use cli::{Cli, Command};

fn run(cli: Cli) -> anyhow::Result<()> {
    // Only the commands that run stages print progress.
    let verbosity = match (cli.quiet, cli.verbose) {
        (true, _) => Verbosity::Quiet,
        (_, true) => Verbosity::Verbose,
        _ => Verbosity::Normal,
    };
    let threads = commands::set_threads(cli.command.threads())?;
    let cx = commands::Context {
        // The checkout the data files come from: the working folder's, else the one holding
        // the spec or run folder the command names.
        layout: facelab::io::Layout::find(cli.command.anchor()),
        threads,
        verbosity,
    };
    match cli.command {
        Command::Render(args) => commands::render::run(args, &cx),
        Command::Gallery(args) => commands::gallery::run(args, &cx),
        Command::Observe(args) => commands::observe::run(args, &cx),
        Command::Run(args) => commands::run::run(args, &cx),
        Command::Task(args) => commands::task::run(args, &cx),
        Command::Check(args) => commands::check::run(args, &cx),
        Command::Status(args) => commands::status::run(args, &cx),
        Command::Verify(args) => commands::verify::run(args, &cx),
        Command::Transfer(args) => commands::transfer::run(args, &cx),
        Command::Edit(args) => commands::edit::run(args, &cx),
        Command::Retarget(args) => commands::retarget::run(args, &cx),
        Command::Face { what } => commands::face::run(what, &cx),
        Command::Bench { what } => commands::bench::run(what, &cx),
    }
}

fn main() -> ExitCode {
    match run(Cli::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) => {
            eprintln!("error: {err:#}");
            ExitCode::FAILURE
        }
    }
}
