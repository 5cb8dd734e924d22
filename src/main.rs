//! The `photometeor` command line: parses and validates arguments, turns them into plain plans,
//! and hands those to the library crates. No physics lives here.

mod bench;
mod cli;
mod plot;
mod render;
mod tradeoff;

use std::process::ExitCode;

use clap::Parser;

fn main() -> ExitCode {
    let args = cli::Args::parse();
    match cli::run(args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            // One line: the chain of causes, outermost first.
            eprintln!("error: {e:#}");
            ExitCode::from(2)
        }
    }
}
