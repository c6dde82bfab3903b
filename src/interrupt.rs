//! Ctrl-C or SIGTERM during a long run — a seed (feature `server`), a
//! flight (feature `client`), a build: the first signal stops it after the
//! work in hand (a seed's tiles, so their locks are released and the
//! progress is saved; a flight's frame, so its frames and statistics are
//! written; a build's computation, so no output is half written); a
//! second one exits at once. Outside such a run the signals keep their
//! default action (the process ends), also in a process that runs several
//! (`sylva bench seed`).

use signal_hook::consts::{SIGINT, SIGTERM};
use signal_hook::flag;
use std::sync::OnceLock;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

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
pub struct Interrupt(());

impl Interrupt {
    /// Starts watching (one run at a time per process).
    pub fn watch() -> Interrupt {
        install();
        CAME.store(false, Ordering::SeqCst);
        IDLE.store(false, Ordering::SeqCst);
        Interrupt(())
    }

    /// The signal that came, if one did.
    pub fn came(&self) -> Option<i32> {
        CAME.load(Ordering::Acquire).then(|| WHICH.load(Ordering::Acquire) as i32)
    }
}

impl Drop for Interrupt {
    fn drop(&mut self) {
        IDLE.store(true, Ordering::SeqCst);
    }
}
