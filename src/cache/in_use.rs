//! A region version's mark of use: a server or a seeder marks its region's
//! version in the tile cache when it starts and every [`EVERY`] while it
//! runs, so that `sylva cache prune --stale` keeps that version however old
//! its tiles are (a server of a seeded cache only reads, and reads leave no
//! trace a prune can rely on).

use super::TileStore;
use std::sync::Arc;
use std::sync::mpsc::{self, RecvTimeoutError};
use std::thread::JoinHandle;
use std::time::Duration;

/// How often a running server or seeder marks its version.
pub const EVERY: Duration = Duration::from_secs(300);

/// Marks a version while it lives (a thread of its own); dropping it stops.
pub struct InUse {
    stop: Option<mpsc::Sender<()>>,
    thread: Option<JoinHandle<()>>,
}

impl InUse {
    /// Marks `version` in `store` now and every [`EVERY`]. A mark that
    /// fails (a read-only cache) is logged once.
    pub fn mark(store: Arc<dyn TileStore>, version: &str) -> InUse {
        let (stop, stopped) = mpsc::channel::<()>();
        let version = version.to_string();
        let run = move || {
            let mut warned = false;
            loop {
                if let Err(e) = store.mark_in_use(&version)
                    && !std::mem::replace(&mut warned, true)
                {
                    tracing::warn!(error = %e, "cannot mark the version in use: `sylva cache prune --stale` may remove it");
                }
                if stopped.recv_timeout(EVERY) != Err(RecvTimeoutError::Timeout) {
                    return;
                }
            }
        };
        let thread = std::thread::Builder::new().name("sylva-in-use".into()).spawn(run).ok();
        InUse { stop: Some(stop), thread }
    }
}

impl Drop for InUse {
    fn drop(&mut self) {
        drop(self.stop.take());
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}
