//! The `sylva` command line's commands, each with its arguments (clap) and
//! its run; `main.rs` parses, dispatches and reports errors.

pub mod bench;
#[cfg(feature = "server")]
pub mod cache;
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

/// A usage error found after parsing (an option that does not apply, or a
/// box outside the region): reported as clap's own are, exit status 2.
pub fn usage(message: impl std::fmt::Display) -> anyhow::Error {
    clap::Error::raw(clap::error::ErrorKind::ValueValidation, format!("{message}\n")).into()
}

/// An option's parser of a finite number of `unit` above 0.
pub fn positive(unit: &'static str) -> impl Fn(&str) -> Result<f64, String> + Clone + Send + Sync + 'static {
    move |text| {
        let v = text.parse::<f64>().ok().filter(|v| v.is_finite() && *v > 0.0);
        v.ok_or_else(|| format!("not a positive number of {unit}"))
    }
}
