//! Command-line interface of the `rigtwin` binary (clap). `main.rs` only calls [`main`].

/// Entry point of the binary.
pub fn main() -> std::process::ExitCode {
    std::process::ExitCode::SUCCESS
}
