//! The `photometeor` command line: parses and validates arguments, turns them into plain plans,
//! and hands those to the library crates. No physics lives here; each subcommand is one file
//! under `commands/`.

mod cli;
mod commands;
mod progress;

use std::process::ExitCode;

use clap::Parser;

fn main() -> ExitCode {
    let args = cli::Args::parse();
    match args.run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            // One line: the chain of causes, outermost first; a cause whose text an outer
            // message already carries (an error that prints its source) is not repeated.
            let mut line = e.to_string();
            for cause in e.chain().skip(1) {
                let text = cause.to_string();
                if !line.contains(&text) {
                    line.push_str(": ");
                    line.push_str(&text);
                }
            }
            eprintln!("error: {line}");
            ExitCode::from(2)
        }
    }
}
