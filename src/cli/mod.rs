//! The `sylva` command line's commands, each with its arguments (clap) and
//! its run; `main.rs` parses, dispatches and reports errors.

pub mod bench;
#[cfg(feature = "client")]
pub mod flight;
pub mod produce;
#[cfg(feature = "server")]
pub mod serving;

/// Writes a command's report to stdout. A reader that went away (`sylva
/// info | head -1`) is no error: the run goes on to its end and its exit
/// status, where `println!` would panic.
pub fn print(text: impl std::fmt::Display) -> anyhow::Result<()> {
    use std::io::Write;
    match writeln!(std::io::stdout().lock(), "{text}") {
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => Ok(()),
        written => Ok(written?),
    }
}
