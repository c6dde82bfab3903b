//! Ctrl-C or SIGTERM during a long run. A seed (feature `server`) or a
//! flight (feature `client`) is [`Interrupt`]ed: the first signal stops it
//! after the work in hand (a seed's tiles, so their locks are released and
//! the progress is saved; a flight's frame, so its frames and statistics
//! are written); a second one exits at once (what was written stays: a
//! flight writes each frame and its row of statistics once it is done, in
//! a directory made with the first). Outside such a run the signals
//! keep their default action (the process ends), also in a process that
//! runs several (`sylva bench seed`). A build, whose work is worth nothing
//! until its outputs are written whole, is [`Abandon`]ed: the process ends
//! at once unless it is writing them, which it finishes first (a second
//! signal abandons them, none left half-written).

use signal_hook::consts::{SIGINT, SIGTERM};
use signal_hook::flag;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, OnceLock};

/// True while no run is watched: a signal then takes its default action.
static IDLE: AtomicBool = AtomicBool::new(true);
/// True once a signal came during the watched run.
static CAME: AtomicBool = AtomicBool::new(false);
/// Which signal that was.
static WHICH: AtomicUsize = AtomicUsize::new(0);

/// The actions, installed once per process, run in this order on a signal.
fn install() {
    static INSTALLED: OnceLock<()> = OnceLock::new();
    INSTALLED.get_or_init(|| {
        for signal in [SIGINT, SIGTERM] {
            let installed = flag::register_conditional_default(signal, &IDLE)
                // A second signal in a run: 128 + its number, as a shell
                // reports a death by it.
                .and_then(|_| flag::register_conditional_shutdown(signal, 128 + signal, &CAME))
                .and_then(|_| flag::register_usize(signal, &WHICH, signal as usize))
                .and_then(|_| flag::register(signal, &CAME));
            if let Err(e) = installed {
                tracing::warn!("Ctrl-C will end the run at once (signal {signal} not watched: {e})");
            }
        }
    });
}

/// A run's watch for the signals, from `watch` until dropped.
pub struct Interrupt {
    /// Tells the thread that says a signal came to end.
    done: Arc<AtomicBool>,
}

/// How often the run's watch looks whether a signal came, to say so.
const SAY_EVERY: std::time::Duration = std::time::Duration::from_millis(100);

impl Interrupt {
    /// Starts watching (one run at a time per process); the first signal
    /// is answered at once with what happens next, since the work in hand
    /// (a tile, a frame waiting on a server) may take minutes.
    pub fn watch() -> Interrupt {
        install();
        CAME.store(false, Ordering::SeqCst);
        IDLE.store(false, Ordering::SeqCst);
        let done = Arc::new(AtomicBool::new(false));
        let ended = done.clone();
        let _ = std::thread::Builder::new().name("interrupt".into()).spawn(move || {
            while !ended.load(Ordering::Acquire) {
                if CAME.load(Ordering::Acquire) {
                    eprintln!("\nstopping after the work in hand (press Ctrl-C again to stop at once)");
                    return;
                }
                std::thread::sleep(SAY_EVERY);
            }
        });
        Interrupt { done }
    }

    /// The signal that came, if one did.
    pub fn came(&self) -> Option<i32> {
        CAME.load(Ordering::Acquire).then(|| WHICH.load(Ordering::Acquire) as i32)
    }
}

impl Drop for Interrupt {
    fn drop(&mut self) {
        IDLE.store(true, Ordering::SeqCst);
        self.done.store(true, Ordering::Release);
    }
}

/// A process that ends at once on the first signal, saying whether its
/// outputs were written, except while [`Abandon::writing`] runs: the
/// writing then ends first, and a second signal ends the process at once,
/// the outputs not yet in place removed.
pub struct Abandon {
    /// Held while writing; true once the outputs are written.
    written: Arc<Mutex<bool>>,
    /// The first signal that came (0: none).
    signal: Arc<AtomicUsize>,
}

impl Abandon {
    /// Starts watching, for the rest of the process.
    pub fn watch() -> Abandon {
        let (written, signal) = (Arc::new(Mutex::new(false)), Arc::new(AtomicUsize::new(0)));
        let (watched, came) = (written.clone(), signal.clone());
        let signals = signal_hook::iterator::Signals::new([SIGINT, SIGTERM]);
        let started = signals.and_then(|mut signals| {
            std::thread::Builder::new().name("signals".into()).spawn(move || {
                let mut signals = signals.forever();
                let Some(first) = signals.next() else { return };
                // Said before looking: writing that ends after this sees it.
                came.store(first as usize, Ordering::SeqCst);
                let idle = match watched.try_lock() {
                    Ok(written) => Some(*written),
                    Err(std::sync::TryLockError::Poisoned(e)) => Some(*e.into_inner()),
                    Err(std::sync::TryLockError::WouldBlock) => None,
                };
                if let Some(written) = idle {
                    end(first, written);
                }
                crate::outputs::say(format_args!(
                    "sylva: signal {first}: finishing the outputs (a second signal abandons them)"
                ));
                if let Some(second) = signals.next() {
                    crate::outputs::remove_partial();
                    crate::outputs::say(format_args!(
                        "sylva: interrupted by signal {second} while writing; the outputs not yet in place abandoned"
                    ));
                    std::process::exit(128 + second);
                }
            })
        });
        if let Err(e) = started {
            tracing::warn!("Ctrl-C may leave a half-written output (signals not watched: {e})");
        }
        Abandon { written, signal }
    }

    /// Runs `write`, which a first signal lets finish (then ends the
    /// process) and a second one abandons
    /// ([`crate::outputs::remove_partial`]); its success marks the outputs
    /// written.
    pub fn writing<T, E>(&self, write: impl FnOnce() -> Result<T, E>) -> Result<T, E> {
        let mut written = self.written.lock().unwrap_or_else(|e| e.into_inner());
        let result = write();
        *written = result.is_ok();
        match self.signal.load(Ordering::SeqCst) {
            0 => result,
            signal => end(signal as i32, *written),
        }
    }
}

/// Ends the process after `signal`, saying whether the outputs were
/// `written`.
fn end(signal: i32, written: bool) -> ! {
    let what = if written { " after the outputs were written" } else { "; nothing written" };
    crate::outputs::say(format_args!("sylva: interrupted by signal {signal}{what}"));
    std::process::exit(128 + signal);
}
