//! Ctrl-C or SIGTERM during a seed: the first signal stops it after the
//! tiles in hand, so their locks are released and the progress is saved
//! for `--resume`; a second signal exits at once.

use signal_hook::SigId;
use signal_hook::consts::{SIGINT, SIGTERM};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

/// Exit status of a second signal (128 + SIGINT, as a shell reports it).
const AT_ONCE: i32 = 130;

/// The signals a seed heeds, registered while it lives.
pub struct Interrupt {
    flag: Arc<AtomicBool>,
    ids: Vec<SigId>,
}

impl Interrupt {
    /// Registers for SIGINT and SIGTERM; a signal the system refuses to
    /// register leaves its default action (the process ends, as before).
    pub fn register() -> Interrupt {
        let flag = Arc::new(AtomicBool::new(false));
        let mut ids = Vec::new();
        for signal in [SIGINT, SIGTERM] {
            // The exit comes first: it fires only once the flag is set.
            ids.extend(signal_hook::flag::register_conditional_shutdown(signal, AT_ONCE, flag.clone()).ok());
            ids.extend(signal_hook::flag::register(signal, flag.clone()).ok());
        }
        Interrupt { flag, ids }
    }

    /// True once a signal came.
    pub fn came(&self) -> bool {
        self.flag.load(Ordering::Relaxed)
    }
}

impl Drop for Interrupt {
    fn drop(&mut self) {
        for &id in &self.ids {
            signal_hook::low_level::unregister(id);
        }
    }
}
