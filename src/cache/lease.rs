//! Tile locks kept while their holders work: a process's [`Leases`] renew
//! every lock it holds ([`Leases::hold`]) each third of the lock expiry, so
//! the expiry only has to outlast a renewal, not the longest computation.
//! A holder that dies stops renewing, and its lock is free one expiry
//! later at most; a slow tile (a loaded machine, a slow upstream) keeps its
//! lock however long it takes, up to [`MAX_HOLD`], and no other process
//! computes it meanwhile. A holder past that is taken for hung: its lock is
//! no longer renewed and expires, so that the others do not wait on it for
//! ever.

use super::{Lock, TileStore};
use std::collections::HashMap;
use std::sync::mpsc::{self, RecvTimeoutError};
use std::sync::{Arc, Mutex, PoisonError};
use std::time::{Duration, Instant};

/// The longest a lock is renewed: no tile takes that long (5–50 ms to
/// compute; an upstream's slowest reads, retried, about a minute).
pub const MAX_HOLD: Duration = Duration::from_secs(300);

/// The locks held, by token, each with when it was taken.
type Held = HashMap<String, (Lock, Instant)>;

/// The locks a process holds in one store, renewed by a thread of their
/// own while this lives.
pub struct Leases {
    held: Arc<Mutex<Held>>,
    ttl: Duration,
    _stop: mpsc::Sender<()>,
}

impl Leases {
    /// Renews the locks held in `store`, each to `ttl` every third of it.
    pub fn start(store: Arc<dyn TileStore>, ttl: Duration) -> Leases {
        let held: Arc<Mutex<Held>> = Arc::default();
        let (stop, stopped) = mpsc::channel::<()>();
        let locks = held.clone();
        let run = move || {
            let mut failing = false;
            while stopped.recv_timeout(ttl / 3) == Err(RecvTimeoutError::Timeout) {
                for lock in due(&locks) {
                    match store.renew(&lock, ttl) {
                        Ok(true) => failing = false,
                        Ok(false) => tracing::debug!(key = %lock.key, "tile lock lost: taken over after it expired"),
                        Err(e) if !std::mem::replace(&mut failing, true) => {
                            tracing::warn!(error = %e, "cannot renew a tile lock: it expires, and another process may compute the tile too");
                        }
                        Err(_) => {}
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

    /// Renews `lock` until the returned guard is dropped (or [`MAX_HOLD`]).
    pub fn hold(&self, lock: &Lock) -> Lease {
        lock_held(&self.held).insert(lock.token.clone(), (lock.clone(), Instant::now()));
        Lease { held: self.held.clone(), token: lock.token.clone() }
    }
}

/// The locks to renew now; those held past [`MAX_HOLD`] are dropped, said.
fn due(held: &Mutex<Held>) -> Vec<Lock> {
    let mut held = lock_held(held);
    held.retain(|_, (lock, since)| {
        let hung = since.elapsed() > MAX_HOLD;
        if hung {
            tracing::warn!(key = %lock.key, "a tile computed for over {} s: its lock is left to expire", MAX_HOLD.as_secs());
        }
        !hung
    });
    held.values().map(|(lock, _)| lock.clone()).collect()
}

fn lock_held(held: &Mutex<Held>) -> std::sync::MutexGuard<'_, Held> {
    held.lock().unwrap_or_else(PoisonError::into_inner)
}

/// A lock being renewed; dropping it stops the renewal (release the lock
/// after, or it expires).
pub struct Lease {
    held: Arc<Mutex<Held>>,
    token: String,
}

impl Drop for Lease {
    fn drop(&mut self) {
        lock_held(&self.held).remove(&self.token);
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
        // Renewed every half second: a lock is lost only if a renewal is a
        // second late.
        let ttl = Duration::from_millis(1500);
        let leases = Leases::start(store.clone(), ttl);
        let lock = store.try_lock("v0123456789abcdef/dem/1/0/0_0.bil", ttl).unwrap().unwrap();
        let lease = leases.hold(&lock);
        std::thread::sleep(ttl * 3);
        assert!(other.try_lock(&lock.key, ttl).unwrap().is_none(), "taken while its holder works");
        drop(lease);
        std::thread::sleep(ttl * 2);
        assert!(other.try_lock(&lock.key, ttl).unwrap().is_some(), "kept after its holder stopped");
        let _ = std::fs::remove_dir_all(&root);
    }

    #[test]
    fn a_lock_held_past_the_longest_hold_is_no_longer_renewed() {
        let held = Mutex::new(Held::new());
        let lock = |key: &str| Lock { key: key.into(), token: key.into() };
        let long_ago = Instant::now().checked_sub(MAX_HOLD + Duration::from_secs(1)).unwrap();
        lock_held(&held).insert("hung".into(), (lock("hung"), long_ago));
        lock_held(&held).insert("busy".into(), (lock("busy"), Instant::now()));
        assert_eq!(due(&held).iter().map(|l| l.key.as_str()).collect::<Vec<_>>(), ["busy"]);
        assert_eq!(lock_held(&held).len(), 1);
    }
}
