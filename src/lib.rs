//! `kac` as a library: the analyses shared by the command line and the service ([`analysis`]), the command line
//! ([`cli`]) and the HTTP service ([`service`]). The `kac` binary is `cli::run`; tests build the service's router
//! in process from here (`service::routes::router`) beside the end-to-end tests of the binary.

// Unsafe code (the style guide, "Unsafe code"): none here today; should any appear, it follows the core's rules.
#![deny(unsafe_op_in_unsafe_fn)]
#![deny(clippy::undocumented_unsafe_blocks)]

pub use kac_engine::analysis;
pub mod cli;
pub mod service;
