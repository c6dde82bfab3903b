//! The tile cache: encoded tiles under keys such as
//! `v1a2b…/cem/9/1939/1939_2704.bil` (the region's version key, then the
//! World Wind path), in a directory ([`DirStore`], the default) or in Redis
//! ([`redis::RedisStore`], feature `server`), shared by every server and
//! seeder that opens the same place.
//!
//! Every entry carries its length and CRC-32 ([`envelope`]) and is written
//! whole (rename into place, or one Redis `SET`), so readers in any process
//! see the old entry or the whole new one, never half. Tiles whose samples
//! are all alike (all sea, all nodata) are stored once under a content key
//! and linked ([`TileStore::put_shared`]). A lock with an expiry per key
//! ([`TileStore::try_lock`]) lets processes agree on who computes a tile
//! ([`flight`]); a holder renews its lock while it computes ([`lease`]), and
//! one that dies frees it when it expires, or at once where its lock shows
//! it ran on this machine (`holder.rs`). Servers and
//! seeders mark their region's version in use ([`in_use`]), so that pruning
//! stale versions ([`prune`]) spares theirs; servers hold the cache to a
//! size, one trim per interval among them ([`quota`]).
//!
//! Invariant: no HTTP, no async; callers run it off the async executor.

pub mod dir;
pub mod envelope;
pub mod flight;
pub(crate) mod holder;
pub mod in_use;
pub mod lease;
pub mod prune;
pub mod quota;
#[cfg(feature = "server")]
pub mod redis;

pub use dir::DirStore;

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, SystemTime};
use thiserror::Error;

/// A cached payload and when it was written.
#[derive(Clone, Debug)]
pub struct Stored {
    /// The encoded tile (empty for a tile known to have no data).
    pub bytes: Vec<u8>,
    /// When the entry was written.
    pub written: SystemTime,
}

/// What reading an entry found.
#[derive(Debug)]
pub enum Lookup {
    /// A valid entry.
    Hit(Stored),
    /// No entry.
    Miss,
    /// An entry that failed its check (truncated, corrupt): treat as a miss.
    Corrupt,
}

/// A lock on one key, held until released or expired.
#[derive(Clone, Debug)]
pub struct Lock {
    /// The key locked.
    pub key: String,
    /// This holder's token (a later holder of an expired lock has another).
    pub token: String,
}

/// Why the cache could not be read or written.
#[derive(Debug, Error)]
pub enum CacheError {
    /// A file of the directory cache.
    #[error("cannot {doing} {path}: {source}")]
    Io {
        /// What failed, said after "cannot" ("create the cache directory").
        doing: &'static str,
        /// The file or directory.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The Redis server.
    #[error("Redis at {url}: {message}")]
    Redis {
        /// The server's URL.
        url: String,
        /// What went wrong.
        message: String,
    },
    /// A backend this build or configuration cannot open.
    #[error("{0}")]
    Unsupported(String),
}

impl CacheError {
    /// An I/O error on `path` while doing `doing` (said after "cannot").
    pub fn io(doing: &'static str, path: &Path, source: std::io::Error) -> CacheError {
        CacheError::Io { doing, path: path.to_path_buf(), source }
    }
}

/// Where encoded tiles are kept. Implementations are safe to share between
/// threads and, through the backing store, between processes.
pub trait TileStore: Send + Sync {
    /// Reads and checks an entry.
    fn get(&self, key: &str) -> Result<Lookup, CacheError>;

    /// Writes the entry of `lock`'s key whole, by the lock's holder (whose
    /// token names the directory backend's temporary file, so that whoever
    /// takes the lock over from a holder that died removes it).
    fn put(&self, lock: &Lock, payload: &[u8]) -> Result<(), CacheError>;

    /// Writes `payload` once under the content key `blob` (if it is not
    /// there already) and makes `lock`'s key refer to it.
    fn put_shared(&self, lock: &Lock, blob: &str, payload: &[u8]) -> Result<(), CacheError>;

    /// Takes the lock of `key` for at most `ttl`, unless another holder has
    /// it (`None`): a lock is taken over once it has expired, or at once
    /// where the backend knows its holder died (`holder.rs`).
    fn try_lock(&self, key: &str, ttl: Duration) -> Result<Option<Lock>, CacheError>;

    /// Releases a lock if it is still this holder's.
    fn unlock(&self, lock: &Lock) -> Result<(), CacheError>;

    /// Extends a lock still this holder's to `ttl` from now (on a directory,
    /// its expiry counts from now: takers judge it by their own `ttl`);
    /// false where it is not this holder's any more.
    fn renew(&self, lock: &Lock, ttl: Duration) -> Result<bool, CacheError>;

    /// Marks the region version `version` in use now ([`in_use`]: servers
    /// and seeders mark theirs while they run; `sylva cache prune --stale`
    /// keeps a version marked within its grace).
    fn mark_in_use(&self, version: &str) -> Result<(), CacheError>;

    /// Where the tiles are, for logs.
    fn describe(&self) -> String;
}

/// Which backend, and where.
#[derive(Clone, Debug, PartialEq)]
pub enum Backend {
    /// A directory (created on first write).
    Directory(PathBuf),
    /// A Redis server: URL and key prefix.
    Redis {
        /// `redis://host:port/db`, `redis+unix:///path`.
        url: String,
        /// Prepended to every key.
        prefix: String,
    },
}

/// Opens a backend (a Redis server must answer now, so a wrong URL is an
/// error at start-up, not at the first tile).
pub fn open(backend: &Backend) -> Result<Arc<dyn TileStore>, CacheError> {
    match backend {
        Backend::Directory(dir) => Ok(Arc::new(DirStore::open(dir)?)),
        #[cfg(feature = "server")]
        Backend::Redis { url, prefix } => Ok(Arc::new(redis::RedisStore::open(url, prefix)?)),
        #[cfg(not(feature = "server"))]
        Backend::Redis { url, .. } => Err(CacheError::Unsupported(format!(
            "the Redis tile cache at {url} needs Sylva built with the `server` feature"
        ))),
    }
}

/// A stable 64-bit digest (FNV-1a): ETags and version keys must agree
/// between processes and builds, which `std`'s hasher does not promise.
pub fn digest(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325u64, |h, &b| (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn digests_are_stable() {
        assert_eq!(digest(b""), 0xcbf2_9ce4_8422_2325);
        assert_eq!(digest(b"a"), 0xaf63_dc4c_8601_ec8c);
    }
}
