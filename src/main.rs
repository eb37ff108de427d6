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
            let msg: Vec<String> = e.chain().map(|c| c.to_string()).collect();
            eprintln!("ffstream: error: {}", msg.join(": "));
            ExitCode::from(1)
        }
    }
}
