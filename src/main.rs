//! The `mocapstore` command line: the service, folder ingest, conversion, benchmarks,
//! archives. Built only with the `cli` feature (on by default), so that code embedding the
//! library (codecs, store, service) compiles no HTTP client, plotting stack or font.

mod cli;

use std::process::ExitCode;

fn main() -> ExitCode {
    cli::main()
}
