//! The `hybc` command: a thin layer over the library (`hybc::cli`).

fn main() -> std::process::ExitCode {
    hybc::cli::main()
}
