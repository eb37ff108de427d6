//! The `ffstream` command. Kept thin: parse (clap, in `cli`), build validated settings,
//! call the library. Exit codes: 0 success; 1 failure (one-line cause on stderr);
//! 2 usage error; 3 `verify` found problems.

mod cli;

use std::process::ExitCode;

use clap::Parser;

fn main() -> ExitCode {
    let args = cli::Cli::parse();
    cli::init_tracing(args.verbose);
    match cli::dispatch(args) {
        Ok(code) => code,
        Err(e) => {
            // One line: the cause chain joined, outermost first.
            // Causes whose text the outer message already quotes (errors that both
            // print and chain their source) are left out, so nothing is said twice.
            let mut line = String::new();
            for c in e.chain() {
                let text = c.to_string();
                if !line.contains(&text) {
                    if !line.is_empty() {
                        line += ": ";
                    }
                    line += &text;
                }
            }
            eprintln!("ffstream: error: {line}");
            ExitCode::from(1)
        }
    }
}
