//! A region version's mark of use: a server or a seeder marks its region's
//! version in the tile cache when it starts and every [`EVERY`] while it
//! runs, so that `sylva cache prune --stale` keeps that version however old
//! its tiles are (a server of a seeded cache only reads, and reads leave no
//! trace a prune can rely on).

use super::{CacheError, TileStore};
use std::sync::Arc;
use std::sync::mpsc::{self, RecvTimeoutError};
use std::time::Duration;

/// How often a running server or seeder marks its version.
pub const EVERY: Duration = Duration::from_secs(300);

/// Marks a version while it lives (a thread of its own); dropping it tells
/// the thread to stop, without waiting for a mark in hand (a cache that
/// hangs must not hold up a server's shutdown).
pub struct InUse {
    _stop: mpsc::Sender<()>,
}

impl InUse {
    /// Marks `version` in `store` now (before returning: the version is
    /// marked from its user's start) and every [`EVERY`] after. A mark that
    /// fails is logged once (at info where the cache is read-only: it is
    /// then seeded, and served as it is).
    pub fn mark(store: Arc<dyn TileStore>, version: &str) -> InUse {
        let (stop, stopped) = mpsc::channel::<()>();
        let version = version.to_string();
        let mut said = false;
        let mut mark = move || {
            if let Err(e) = store.mark_in_use(&version)
                && !std::mem::replace(&mut said, true)
            {
                let why = "cannot mark the version in use: `sylva cache prune --stale` may remove it";
                match read_only(&e) {
                    true => tracing::info!(error = %e, "{why}"),
                    false => tracing::warn!(error = %e, "{why}"),
                }
            }
        };
        mark();
        let run = move || {
            while stopped.recv_timeout(EVERY) == Err(RecvTimeoutError::Timeout) {
                mark();
            }
        };
        if let Err(e) = std::thread::Builder::new().name("sylva-in-use".into()).spawn(run) {
            tracing::warn!(error = %e, "cannot start marking the version in use");
        }
        InUse { _stop: stop }
    }
}

/// True for a cache this process may not write.
fn read_only(e: &CacheError) -> bool {
    use std::io::ErrorKind::{PermissionDenied, ReadOnlyFilesystem};
    matches!(e, CacheError::Io { source, .. } if matches!(source.kind(), PermissionDenied | ReadOnlyFilesystem))
}
