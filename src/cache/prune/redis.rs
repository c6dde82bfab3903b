//! The Redis cache's walk: a version is every key `{prefix}{version}/…`
//! (tiles, and shared entries under `uniform/`) and `{prefix}lock:{version}/…`
//! (locks), found by `SCAN`, measured by `MEMORY USAGE`. An entry's last use
//! is the time written in its value (Redis keeps no read time under every
//! eviction policy), so a trim removes the oldest written first; a lock,
//! which lives only while held, is in use now. (Redis can bound its memory
//! itself, by least recent use: `maxmemory` with `maxmemory-policy
//! allkeys-lru`; every key of Sylva's may go.)

use super::{Entry, Kind, Maintain, is_version};
use crate::cache::CacheError;
use redis::{Client, Connection, RedisError};
use std::collections::BTreeSet;
use std::sync::Mutex;
use std::time::{Duration, SystemTime, UNIX_EPOCH};

/// Keys asked for per `SCAN` step.
const SCAN_COUNT: usize = 1000;

/// The walk of a Redis cache.
pub(crate) struct Walker {
    url: String,
    prefix: String,
    conn: Mutex<Connection>,
}

impl Walker {
    /// Connects to the cache at `url` whose keys start with `prefix`.
    pub fn open(url: &str, prefix: &str) -> Result<Walker, CacheError> {
        let error = |e: RedisError| CacheError::Redis { url: url.into(), message: e.to_string() };
        let conn =
            Client::open(url).and_then(|c| c.get_connection_with_timeout(Duration::from_secs(5))).map_err(error)?;
        Ok(Walker { url: url.into(), prefix: prefix.into(), conn: Mutex::new(conn) })
    }

    fn error(&self, e: RedisError) -> CacheError {
        CacheError::Redis { url: self.url.clone(), message: e.to_string() }
    }

    /// Runs `op` on the connection.
    fn with<T>(&self, op: impl FnOnce(&mut Connection) -> Result<T, RedisError>) -> Result<T, CacheError> {
        let mut conn = self.conn.lock().map_err(|_| CacheError::Unsupported("the Redis connection broke".into()))?;
        op(&mut conn).map_err(|e| self.error(e))
    }

    /// Calls `each` with every batch of keys matching `pattern`.
    fn scan(
        &self,
        pattern: &str,
        each: &mut dyn FnMut(Vec<Vec<u8>>) -> Result<(), CacheError>,
    ) -> Result<(), CacheError> {
        let mut cursor = 0u64;
        loop {
            let (next, keys): (u64, Vec<Vec<u8>>) = self.with(|c| {
                redis::cmd("SCAN").arg(cursor).arg("MATCH").arg(pattern).arg("COUNT").arg(SCAN_COUNT).query(c)
            })?;
            each(keys)?;
            if next == 0 {
                return Ok(());
            }
            cursor = next;
        }
    }

    /// Each key's bytes and the time written in its value (`None`: gone).
    fn measure(&self, keys: &[Vec<u8>]) -> Result<Vec<Option<(u64, SystemTime)>>, CacheError> {
        // A `SCAN` step may find none, and Redis refuses an empty pipeline.
        if keys.is_empty() {
            return Ok(Vec::new());
        }
        let mut pipe = redis::pipe();
        for key in keys {
            pipe.cmd("MEMORY").arg("USAGE").arg(key).arg("SAMPLES").arg(0);
            pipe.cmd("GETRANGE").arg(key).arg(4).arg(11);
        }
        let replies: Vec<redis::Value> = self.with(|c| pipe.query(c))?;
        Ok(replies
            .chunks(2)
            .map(|pair| {
                let bytes: Option<u64> = redis::from_redis_value_ref(&pair[0]).ok().flatten();
                let stamp: Vec<u8> = redis::from_redis_value_ref(&pair[1]).unwrap_or_default();
                bytes.map(|b| (b, written(&stamp)))
            })
            .collect())
    }
}

/// The time in a value's header (Unix ms, little-endian), or the epoch.
fn written(stamp: &[u8]) -> SystemTime {
    let ms = <[u8; 8]>::try_from(stamp).map_or(0, u64::from_le_bytes);
    UNIX_EPOCH + Duration::from_millis(ms)
}

/// The glob that matches `text` as it is (`SCAN MATCH` treats `*?[]\` as
/// patterns).
fn glob_literal(text: &str) -> String {
    text.chars().flat_map(|c| if "*?[]\\".contains(c) { vec!['\\', c] } else { vec![c] }).collect()
}

impl Maintain for Walker {
    fn describe(&self) -> String {
        format!("Redis {} (keys {}…)", self.url, self.prefix)
    }

    fn versions(&self) -> Result<Vec<String>, CacheError> {
        let mut versions = BTreeSet::new();
        self.scan(&format!("{}*", glob_literal(&self.prefix)), &mut |keys| {
            for key in keys {
                let key = String::from_utf8_lossy(&key);
                let rest = key.strip_prefix(self.prefix.as_str()).unwrap_or_default();
                let rest = rest.strip_prefix("lock:").unwrap_or(rest);
                if let Some((version, _)) = rest.split_once('/').filter(|(v, _)| is_version(v)) {
                    versions.insert(version.to_string());
                }
            }
            Ok(())
        })?;
        Ok(versions.into_iter().collect())
    }

    fn walk(&self, version: &str, remove: &mut dyn FnMut(&Entry) -> bool) -> Result<(), CacheError> {
        let prefix = glob_literal(&self.prefix);
        let shared = format!("{}{version}/uniform/", self.prefix);
        for (pattern, lock) in [(format!("{prefix}{version}/*"), false), (format!("{prefix}lock:{version}/*"), true)] {
            self.scan(&pattern, &mut |keys| {
                let measured = self.measure(&keys)?;
                let mut gone = Vec::new();
                for (key, m) in keys.into_iter().zip(measured) {
                    let Some((bytes, written)) = m else { continue };
                    let tile = !lock && !key.starts_with(shared.as_bytes());
                    let last_used = if lock { SystemTime::now() } else { written };
                    let entry =
                        Entry { bytes, last_used: Some(last_used), kind: if tile { Kind::Tile } else { Kind::Kept } };
                    if remove(&entry) && tile {
                        gone.push(key);
                    }
                }
                if !gone.is_empty() {
                    self.with(|c| redis::cmd("UNLINK").arg(gone).query::<u64>(c))?;
                }
                Ok(())
            })?;
        }
        Ok(())
    }

    fn remove_version(&self, version: &str) -> Result<(), CacheError> {
        let prefix = glob_literal(&self.prefix);
        for pattern in [format!("{prefix}{version}/*"), format!("{prefix}lock:{version}/*")] {
            self.scan(&pattern, &mut |keys| {
                if !keys.is_empty() {
                    self.with(|c| redis::cmd("UNLINK").arg(keys).query::<u64>(c))?;
                }
                Ok(())
            })?;
        }
        Ok(())
    }
}
