//! The `rbfsurf` binary: parse the command line and run it (see `rbfsurf --help`).

fn main() {
    std::process::exit(rbfsurf::cli::run(std::env::args_os()));
}
