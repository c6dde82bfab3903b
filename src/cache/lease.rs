//! Tile locks kept while their holders work: a process's [`Leases`] renew
//! every lock it holds ([`Leases::hold`]) each third of the lock expiry, so
//! the expiry only has to outlast a renewal, not the longest computation.
//! A holder that dies stops renewing, and its lock is free one expiry
//! later at most; a slow tile (a loaded machine, a slow upstream) keeps its
//! lock however long it takes, and no other process computes it meanwhile.

use super::{Lock, TileStore};
use std::collections::HashMap;
use std::sync::mpsc::{self, RecvTimeoutError};
use std::sync::{Arc, Mutex, PoisonError};
use std::time::Duration;

/// The locks a process holds in one store, renewed by a thread of their
/// own while this lives.
pub struct Leases {
    held: Arc<Mutex<HashMap<String, Lock>>>,
    ttl: Duration,
    _stop: mpsc::Sender<()>,
}

impl Leases {
    /// Renews the locks held in `store`, each to `ttl` every third of it.
    pub fn start(store: Arc<dyn TileStore>, ttl: Duration) -> Leases {
        let held: Arc<Mutex<HashMap<String, Lock>>> = Arc::default();
        let (stop, stopped) = mpsc::channel::<()>();
        let locks = held.clone();
        let run = move || {
            let mut said = false;
            while stopped.recv_timeout(ttl / 3) == Err(RecvTimeoutError::Timeout) {
                let now: Vec<Lock> = locks.lock().unwrap_or_else(PoisonError::into_inner).values().cloned().collect();
                for lock in now {
                    if let Err(e) = store.renew(&lock, ttl)
                        && !std::mem::replace(&mut said, true)
                    {
                        tracing::warn!(error = %e, "cannot renew a tile lock: it expires, and another process may compute the tile too");
                    }
                }
            }
        };
        if let Err(e) = std::thread::Builder::new().name("sylva-leases".into()).spawn(run) {
            tracing::warn!(error = %e, "cannot start renewing tile locks: they expire after [tile_cache] lock_ttl_s");
        }
        Leases { held, ttl, _stop: stop }
    }

    /// The lock expiry.
    pub fn ttl(&self) -> Duration {
        self.ttl
    }

    /// Renews `lock` until the returned guard is dropped.
    pub fn hold(&self, lock: &Lock) -> Held {
        self.held.lock().unwrap_or_else(PoisonError::into_inner).insert(lock.token.clone(), lock.clone());
        Held { held: self.held.clone(), token: lock.token.clone() }
    }
}

/// A lock being renewed; dropping it stops the renewal (release the lock
/// after, or it expires).
pub struct Held {
    held: Arc<Mutex<HashMap<String, Lock>>>,
    token: String,
}

impl Drop for Held {
    fn drop(&mut self) {
        self.held.lock().unwrap_or_else(PoisonError::into_inner).remove(&self.token);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cache::DirStore;

    #[test]
    fn a_held_lock_outlives_its_expiry_and_a_dropped_one_does_not() {
        let root = std::env::temp_dir().join(format!("sylva-leases-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&root);
        let store: Arc<dyn TileStore> = Arc::new(DirStore::open(&root).unwrap());
        let other = DirStore::open(&root).unwrap();
        let ttl = Duration::from_millis(300);
        let leases = Leases::start(store.clone(), ttl);
        let lock = store.try_lock("v0123456789abcdef/dem/1/0/0_0.bil", ttl).unwrap().unwrap();
        let held = leases.hold(&lock);
        std::thread::sleep(ttl * 3);
        assert!(other.try_lock(&lock.key, ttl).unwrap().is_none(), "taken while its holder works");
        drop(held);
        std::thread::sleep(ttl * 2);
        assert!(other.try_lock(&lock.key, ttl).unwrap().is_some(), "kept after its holder stopped");
        let _ = std::fs::remove_dir_all(&root);
    }
}
