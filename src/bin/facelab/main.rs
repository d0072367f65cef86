//! The `facelab` command line: parse the arguments, set what every command shares (verbosity,
//! the thread counts, the checkout the data files come from), dispatch to the command's file in `commands/`,
//! print the error chain and exit non-zero on failure.

mod cli;
mod commands;

use std::process::ExitCode;

use clap::Parser;
use facelab::run::stage::Verbosity;

use cli::{Cli, Command};

fn run(cli: Cli) -> anyhow::Result<()> {
    // Handed to the commands that run stages; nothing else prints progress.
    let verbosity = match (cli.quiet, cli.verbose) {
        (true, _) => Verbosity::Quiet,
        (_, true) => Verbosity::Verbose,
        _ => Verbosity::Normal,
    };
    let threads = commands::set_threads(cli.command.threads())?;
    if let Some(path) = cli.command.anchor() {
        facelab::io::set_data_root(path.parent().unwrap_or(path));
    }
    match cli.command {
        Command::Render(args) => commands::render::run(args),
        Command::Gallery(args) => commands::gallery::run(args),
        Command::Observe(args) => commands::observe::run(args),
        Command::Run(args) => commands::run::run(args, threads, verbosity),
        Command::Task(args) => commands::task::run(args, verbosity),
        Command::Check(args) => commands::check::run(args),
        Command::Status(args) => commands::status::run(args),
        Command::Verify(args) => commands::verify::run(args, threads, verbosity),
        Command::Transfer(args) => commands::transfer::run(args),
        Command::Edit(args) => commands::edit::run(args),
        Command::Retarget(args) => commands::retarget::run(args),
        Command::Face { what } => commands::face::run(what),
        Command::Bench { what } => commands::bench::run(what),
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
