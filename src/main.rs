//! `kac`: the command-line interface and (with `kac serve`) the HTTP service.
//! Every subcommand prints one JSON object on stdout; unreadable input exits 2 with one line on stderr.

mod analysis;
mod cli;
mod service;

fn main() {
    std::process::exit(cli::run());
}
