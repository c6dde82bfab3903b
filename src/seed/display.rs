//! What the operator sees: a progress bar with rate and ETA (indicatif) on
//! a terminal, plain log lines every few seconds otherwise (a Kubernetes
//! Job's log, CI), or nothing.

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressState, ProgressStyle};
use std::io::IsTerminal;
use std::sync::Mutex;
use std::time::{Duration, Instant};

/// Plain lines at most this often.
const LOG_EVERY: Duration = Duration::from_secs(5);

/// How progress is shown.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mode {
    /// A bar if stderr is a terminal, else plain lines.
    Auto,
    /// Plain lines on stderr.
    Plain,
    /// Nothing.
    Quiet,
}

/// Progress of tile files (made, found or failed) out of a total.
pub struct Display {
    bar: ProgressBar,
    /// The bar is drawn on the terminal.
    drawn: bool,
    plain: bool,
    logged: Mutex<Instant>,
}

impl Display {
    /// A display for `total` files of which `already` were done by earlier runs.
    pub fn new(mode: Mode, total: u64, already: u64) -> Display {
        let bar_wanted = mode == Mode::Auto && std::io::stderr().is_terminal();
        let target = if bar_wanted { ProgressDrawTarget::stderr() } else { ProgressDrawTarget::hidden() };
        let bar = ProgressBar::with_draw_target(Some(total), target);
        let style = ProgressStyle::with_template("{wide_bar} {pos}/{len} tile files {rate} ETA {eta} {msg}");
        if let Ok(style) = style {
            let rate = |state: &ProgressState, w: &mut dyn std::fmt::Write| {
                let _ = write!(w, "{:.1}/s", state.per_sec());
            };
            bar.set_style(style.with_key("rate", rate));
        }
        bar.set_position(already.min(total));
        bar.reset_eta();
        let plain = mode == Mode::Plain || (mode == Mode::Auto && !bar_wanted);
        Display { bar, drawn: bar_wanted, plain, logged: Mutex::new(Instant::now()) }
    }

    /// `n` more files; `failed` so far.
    pub fn advance(&self, n: u64, failed: u64) {
        self.bar.inc(n);
        if failed > 0 {
            self.bar.set_message(format!("{failed} failed"));
        }
        if self.plain && super::due(&self.logged, LOG_EVERY) {
            crate::outputs::say(format_args!("{}", self.line(failed)));
        }
    }

    /// The plain progress line.
    fn line(&self, failed: u64) -> String {
        let (pos, len) = (self.bar.position(), self.bar.length().unwrap_or(0));
        let pct = if len > 0 { 100.0 * pos as f64 / len as f64 } else { 100.0 };
        format!(
            "seed: {pos}/{len} tile files ({pct:.1} %), {:.1} files/s, ETA {}, {failed} failed",
            self.bar.per_sec(),
            indicatif::HumanDuration(self.bar.eta())
        )
    }

    /// Ends the bar (or logs the last line).
    pub fn finish(&self, failed: u64) {
        if self.plain {
            crate::outputs::say(format_args!("{}", self.line(failed)));
        }
        self.bar.abandon();
        if self.drawn {
            // The bar's line is left open: what is printed next starts below it.
            eprintln!();
        }
    }
}
