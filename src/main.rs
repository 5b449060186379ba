//! `kac`: the command-line interface and (with `kac serve`) the HTTP service.
//! Every subcommand prints one JSON object on stdout; unreadable input exits 2 with one line on stderr.

fn main() {
    std::process::exit(kac::cli::run());
}
