//! The tile cache's bound, held by the servers (`[tile_cache] max_size`):
//! every quarter of the trim interval each server tries to take the cache's
//! trim lock for one interval; the one that takes it trims the least
//! recently used tiles back to the size ([`prune`], as `sylva cache prune
//! --max-size` does), renewing the lock while it trims and once more at the
//! end, and leaves it to expire: one trim at a time, one per interval,
//! however many servers share the cache. A server that dies holding it
//! delays the next trim by an interval at most (none on a directory cache of
//! the same machine: `holder.rs`).
//!
//! A trim walks the whole cache (every version, stale ones too: theirs are
//! the least recently used tiles, so they go first) and removes only tiles
//! and shared entries, which the servers compute again when asked; it runs
//! on a thread of its own, beside the requests.

use super::prune::{self, Plan, PruneError, Pruned};
use super::{Backend, Lock, TileStore};
use std::sync::Arc;
use std::sync::mpsc::{self, RecvTimeoutError};
use std::time::{Duration, SystemTime};

/// The trim lock's key: outside every version, so no walk counts it.
const LOCK: &str = "trim";

/// A size and how often to trim the cache back to it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Limit {
    /// Bytes the cache's versions may take.
    pub max_bytes: u64,
    /// How often one of the servers sharing the cache trims it.
    pub every: Duration,
}

/// Trims the cache at `backend` while it lives (a thread of its own);
/// dropping it tells the thread to stop, without waiting for a trim in hand.
pub struct Quota {
    _stop: mpsc::Sender<()>,
}

impl Quota {
    /// Holds the cache at `backend` (`store` its open store) to `limit`,
    /// from now on; `report` is told of every trim this process runs.
    pub fn start(
        backend: Backend,
        store: Arc<dyn TileStore>,
        limit: Limit,
        report: impl Fn(&Pruned) + Send + 'static,
    ) -> Quota {
        let (stop, stopped) = mpsc::channel::<()>();
        let run = move || {
            let mut failing = false;
            loop {
                match trim_if_due(&backend, &*store, limit) {
                    Ok(Some(pruned)) => {
                        log(&pruned, limit);
                        report(&pruned);
                        failing = false;
                    }
                    Ok(None) => {}
                    Err(e) if !std::mem::replace(&mut failing, true) => {
                        tracing::warn!(error = %e, "cannot trim the tile cache to [tile_cache] max_size");
                    }
                    Err(_) => {}
                }
                if stopped.recv_timeout(limit.every / 4) != Err(RecvTimeoutError::Timeout) {
                    return;
                }
            }
        };
        if let Err(e) = std::thread::Builder::new().name("sylva-quota".into()).spawn(run) {
            tracing::warn!(error = %e, "cannot start trimming the tile cache");
        }
        Quota { _stop: stop }
    }
}

/// Trims the cache to `limit` unless a trim ran within its interval (the
/// trim lock held: `None`).
pub fn trim_if_due(backend: &Backend, store: &dyn TileStore, limit: Limit) -> Result<Option<Pruned>, PruneError> {
    let Some(lock) = store.try_lock(LOCK, limit.every)? else { return Ok(None) };
    let plan = Plan {
        keep: Vec::new(),
        stale: false,
        force: false,
        max_bytes: Some(limit.max_bytes),
        grace: Duration::ZERO,
        dry_run: false,
    };
    holding(store, &lock, limit.every, || prune::prune(backend, &plan, SystemTime::now())).map(Some)
}

/// Runs `work` while renewing `lock` every quarter of `ttl` (a trim of a
/// large cache may outlast its interval; another would trim it again), and
/// once more at its end, so that the lock expires `ttl` after the work.
fn holding<T>(store: &dyn TileStore, lock: &Lock, ttl: Duration, work: impl FnOnce() -> T) -> T {
    let (done, finished) = mpsc::channel::<()>();
    std::thread::scope(|scope| {
        scope.spawn(move || {
            while finished.recv_timeout(ttl / 4) == Err(RecvTimeoutError::Timeout) {
                let _ = store.renew(lock, ttl);
            }
        });
        let out = work();
        drop(done);
        let _ = store.renew(lock, ttl);
        out
    })
}

/// Says what a trim did: at info when it removed anything or fell short.
fn log(pruned: &Pruned, limit: Limit) {
    let (tiles, bytes) = pruned.trimmed;
    if let Some(why) = &pruned.trim_failed {
        tracing::warn!(cache = %pruned.cache, error = %why, "the tile cache's trim stopped short");
    } else if tiles > 0 {
        tracing::info!(
            cache = %pruned.cache,
            tiles,
            bytes,
            before = pruned.bytes_before,
            after = pruned.bytes_after,
            max = limit.max_bytes,
            "trimmed the least recently used tiles to [tile_cache] max_size"
        );
    } else {
        tracing::debug!(cache = %pruned.cache, bytes = pruned.bytes_before, max = limit.max_bytes, "tile cache within its bound");
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cache::{DirStore, Lookup};

    /// A directory cache of `n` tiles of 10 kB in one version, and its store.
    fn filled(tag: &str, n: usize) -> (std::path::PathBuf, Arc<dyn TileStore>) {
        let root = std::env::temp_dir().join(format!("sylva-quota-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&root);
        let store: Arc<dyn TileStore> = Arc::new(DirStore::open(&root).unwrap());
        fill(&*store, n);
        (root, store)
    }

    /// `len` bytes no file system compresses (xorshift from `seed`).
    fn noise(seed: usize, len: usize) -> Vec<u8> {
        let mut x = (seed as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15) | 1;
        (0..len)
            .map(|_| {
                x ^= x << 13;
                x ^= x >> 7;
                x ^= x << 17;
                x as u8
            })
            .collect()
    }

    /// Writes tiles `0..n`.
    fn fill(store: &dyn TileStore, n: usize) {
        for i in 0..n {
            let lock = store.try_lock(&format!("v0123456789abcdef/cem/5/1/1_{i}.bil"), Duration::from_secs(5));
            let lock = lock.unwrap().unwrap();
            store.put(&lock, &noise(i, 10_000)).unwrap();
            store.unlock(&lock).unwrap();
        }
    }

    fn tiles_left(store: &dyn TileStore, n: usize) -> usize {
        (0..n)
            .filter(|i| matches!(store.get(&format!("v0123456789abcdef/cem/5/1/1_{i}.bil")), Ok(Lookup::Hit(_))))
            .count()
    }

    #[test]
    fn one_trim_per_interval_however_many_servers_share_the_cache() {
        let (root, store) = filled("once", 40);
        let backend = Backend::Directory(root.clone());
        let limit = Limit { max_bytes: 200_000, every: Duration::from_secs(3600) };
        let pruned = trim_if_due(&backend, &*store, limit).unwrap().expect("the first trim runs");
        assert!(pruned.trimmed.0 > 0 && pruned.bytes_after <= limit.max_bytes, "{pruned:?}");
        assert!(tiles_left(&*store, 40) < 40);
        // Another server (another store on the same directory), within the
        // interval: no second walk.
        let other = DirStore::open(&root).unwrap();
        assert!(trim_if_due(&backend, &other, limit).unwrap().is_none());
        // Its lock is no tile: the cache's usage does not count it.
        let (_, versions) = prune::usage(&backend).unwrap();
        assert_eq!(versions.len(), 1);
        let _ = std::fs::remove_dir_all(&root);
    }

    #[test]
    fn a_quota_trims_when_started_and_again_each_interval() {
        let (root, store) = filled("interval", 30);
        let backend = Backend::Directory(root.clone());
        let limit = Limit { max_bytes: 150_000, every: Duration::from_millis(400) };
        let (told, trims) = mpsc::channel();
        let quota = Quota::start(backend, store.clone(), limit, move |p: &Pruned| {
            let _ = told.send(p.trimmed.0);
        });
        let first = trims.recv_timeout(Duration::from_secs(20)).expect("a trim at start");
        assert!(first > 0 && tiles_left(&*store, 30) < 30);
        // Filled again past the bound, trimmed again once the interval is over.
        fill(&*store, 30);
        let again = std::iter::from_fn(|| trims.recv_timeout(Duration::from_secs(20)).ok()).find(|&n| n > 0);
        assert!(again.is_some(), "no second trim");
        drop(quota);
        let _ = std::fs::remove_dir_all(&root);
    }

    #[test]
    fn a_trim_that_outlasts_its_interval_keeps_the_others_out() {
        let (root, store) = filled("long", 1);
        // Renewed every quarter second: lost only if a renewal is 3/4 s late.
        let every = Duration::from_secs(1);
        let lock = store.try_lock(LOCK, every).unwrap().unwrap();
        let other = DirStore::open(&root).unwrap();
        let taken = holding(&*store, &lock, every, || {
            std::thread::sleep(every * 3);
            other.try_lock(LOCK, every).unwrap()
        });
        assert!(taken.is_none(), "another server took the lock of a trim still running");
        assert!(store.renew(&lock, every).unwrap());
        // Once expired it is another's, and no longer this holder's to renew.
        std::thread::sleep(every * 2);
        assert!(other.try_lock(LOCK, every).unwrap().is_some());
        assert!(!store.renew(&lock, every).unwrap());
        let _ = std::fs::remove_dir_all(&root);
    }

    #[test]
    fn the_interval_counts_from_the_end_of_a_trim() {
        let (root, store) = filled("end", 1);
        let every = Duration::from_secs(3600);
        let lock = store.try_lock(LOCK, every).unwrap().unwrap();
        // Taken an hour ago, and the work instant: renewed only at its end.
        let path = root.join(format!("{LOCK}.lock"));
        let hour_ago = SystemTime::now() - Duration::from_secs(3600);
        std::fs::File::options().write(true).open(&path).unwrap().set_modified(hour_ago).unwrap();
        holding(&*store, &lock, every, || ());
        let age = std::fs::metadata(&path).unwrap().modified().unwrap().elapsed().unwrap_or_default();
        assert!(age < Duration::from_secs(60), "the lock's time is the trim's end: {age:?} ago");
        let _ = std::fs::remove_dir_all(&root);
    }
}
