//! The `rigtwin` binary: parses the command line and dispatches to [`rigtwin::cli`].

fn main() -> std::process::ExitCode {
    rigtwin::cli::main()
}
