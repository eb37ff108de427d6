//! The `ffstream` command. Kept thin: parse (clap, in `cli`), build validated settings,
//! call the library. Exit codes: 0 success; 1 failure (one-line cause on stderr);
//! 2 usage error (clap's, or a [`cli::Usage`] found later); 3 `verify` found problems; 128 + N `compute` or `run` stopped
//! cleanly by signal N (SIGINT 130, SIGTERM 143).

mod cli;

use std::process::ExitCode;

use clap::Parser;

fn main() -> ExitCode {
    let args = cli::Cli::parse();
    cli::init_tracing(args.verbose);
    match cli::dispatch(args) {
        Ok(code) => code,
        Err(e) => {
            // One line: the cause chain joined, outermost first. Every error type of
            // the library either quotes its cause in its message or returns it as its
            // source, never both, so nothing is said twice.
            let line = e
                .chain()
                .map(ToString::to_string)
                .collect::<Vec<_>>()
                .join(": ");
            eprintln!("ffstream: error: {line}");
            // A usage mistake found after parsing exits as clap's own do.
            if e.chain().any(|c| c.is::<cli::Usage>()) {
                ExitCode::from(2)
            } else {
                ExitCode::from(1)
            }
        }
    }
}
