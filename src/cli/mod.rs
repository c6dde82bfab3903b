//! The `sylva` command line's commands, each with its arguments (clap) and
//! its run; `main.rs` parses, dispatches and reports errors.

pub mod bench;
#[cfg(feature = "client")]
pub mod flight;
pub mod produce;
#[cfg(feature = "server")]
pub mod serving;
