//! One computation per tile across processes: before computing a tile, a
//! server or seeder *claims* its key — a usable entry is taken as it is;
//! otherwise the key's lock decides who computes, and the others wait and
//! ask again until the entry appears (or the lock expires because its holder
//! died). Within one process the server's memory cache already coalesces
//! requests; this protocol extends that to every process sharing the store.

use super::{CacheError, Lock, Lookup, Stored, TileStore};
use std::time::Duration;

/// What to do about a key.
#[derive(Debug)]
pub enum Claim {
    /// A usable entry.
    Ready(Stored),
    /// Compute it: this caller holds the lock; `found` is what the store
    /// holds now (a miss, a damaged entry, or one too old to use).
    Compute {
        /// Release it after storing the tile (or failing).
        lock: Lock,
        /// The entry found under the lock.
        found: Lookup,
    },
    /// Another process is computing it: wait ([`pause`]) and claim again.
    Busy,
}

/// Claims `key`: entries for which `usable` is false are recomputed.
pub fn claim(
    store: &dyn TileStore,
    key: &str,
    usable: &dyn Fn(&Stored) -> bool,
    ttl: Duration,
) -> Result<Claim, CacheError> {
    if let Lookup::Hit(stored) = store.get(key)?
        && usable(&stored)
    {
        return Ok(Claim::Ready(stored));
    }
    let Some(lock) = store.try_lock(key, ttl)? else { return Ok(Claim::Busy) };
    // Another process may have stored it between the read and the lock.
    match store.get(key) {
        Ok(Lookup::Hit(stored)) if usable(&stored) => {
            store.unlock(&lock)?;
            Ok(Claim::Ready(stored))
        }
        Ok(found) => Ok(Claim::Compute { lock, found }),
        Err(e) => {
            let _ = store.unlock(&lock);
            Err(e)
        }
    }
}

/// How long to wait after the `attempt`-th busy answer: 20 ms doubling to
/// 500 ms (a tile takes 5–50 ms to compute; waiters should not hammer a
/// shared Redis or NFS server).
pub fn pause(attempt: u32) -> Duration {
    Duration::from_millis((20u64 << attempt.min(5)).min(500))
}

/// True if an entry made from an upstream's data (whose tiles live `ttl`)
/// is past its time.
pub fn expired(ttl: Option<Duration>, stored: &Stored) -> bool {
    ttl.is_some_and(|ttl| stored.written.elapsed().is_ok_and(|age| age > ttl))
}

/// Stores a computed tile under the key of `lock` (the caller's, from
/// [`Claim::Compute`]); a `uniform` tile (every sample alike, so its bytes
/// do not depend on where it is) is stored once per content under
/// `{version}/uniform/` and linked.
pub fn save(store: &dyn TileStore, lock: &Lock, bytes: &[u8], uniform: bool) -> Result<(), CacheError> {
    let key = &lock.key;
    match (uniform, key.split_once('/'), key.rsplit_once('.')) {
        (true, Some((version, _)), Some((_, ext))) => {
            let blob = format!("{version}/uniform/{:016x}{:08x}.{ext}", super::digest(bytes), bytes.len());
            store.put_shared(lock, &blob, bytes)
        }
        _ => store.put(lock, bytes),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cache::DirStore;

    #[test]
    fn a_claimed_key_is_busy_for_others_until_stored() {
        let dir = std::env::temp_dir().join(format!("sylva-flight-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let store = DirStore::new(&dir);
        let ttl = Duration::from_secs(60);
        let any = |_: &Stored| true;
        let Claim::Compute { lock, found: Lookup::Miss } = claim(&store, "v1/dem/1/1/1_1.bil", &any, ttl).unwrap()
        else {
            panic!()
        };
        assert!(matches!(claim(&store, "v1/dem/1/1/1_1.bil", &any, ttl).unwrap(), Claim::Busy));
        save(&store, &lock, b"tile", false).unwrap();
        store.unlock(&lock).unwrap();
        assert!(
            matches!(claim(&store, "v1/dem/1/1/1_1.bil", &any, ttl).unwrap(), Claim::Ready(s) if s.bytes == b"tile")
        );
        // An entry that is not usable (too old) is claimed for recomputing.
        let never = |_: &Stored| false;
        assert!(matches!(
            claim(&store, "v1/dem/1/1/1_1.bil", &never, ttl).unwrap(),
            Claim::Compute { found: Lookup::Hit(_), .. }
        ));
        assert!(pause(0) < pause(3) && pause(30) == Duration::from_millis(500));
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn uniform_tiles_share_one_entry() {
        let dir = std::env::temp_dir().join(format!("sylva-flight-uniform-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let store = DirStore::new(&dir);
        for key in ["v1/dem/3/1/1_1.bil", "v1/dem/3/1/1_2.bil"] {
            let lock = store.try_lock(key, Duration::from_secs(60)).unwrap().unwrap();
            save(&store, &lock, &[0u8; 64], true).unwrap();
            store.unlock(&lock).unwrap();
        }
        let blobs: Vec<_> = std::fs::read_dir(dir.join("v1/uniform")).unwrap().collect();
        assert_eq!(blobs.len(), 1);
        assert!(matches!(store.get("v1/dem/3/1/1_2.bil").unwrap(), Lookup::Hit(s) if s.bytes == [0u8; 64]));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
