//! `kac`: the command-line interface and (with `kac serve`) the HTTP service.
//! Every subcommand prints one JSON object on stdout; unreadable input exits 2 with one line on stderr.

// Unsafe code (the style guide, "Unsafe code"): none here today; should any appear, it follows the core's rules.
#![deny(unsafe_op_in_unsafe_fn)]
#![deny(clippy::undocumented_unsafe_blocks)]

mod analysis;
mod cli;
mod service;

fn main() {
    std::process::exit(cli::run());
}
