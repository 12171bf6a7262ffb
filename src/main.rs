use std::process::ExitCode;

fn main() -> ExitCode {
    mocapstore::cli::main()
}
