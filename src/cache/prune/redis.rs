//! The Redis cache's walk: one `SCAN` of the keys under the prefix, each
//! key given to its version — `{prefix}{version}/…` (tiles, and shared
//! entries under `uniform/`), `{prefix}lock:{version}/…` (locks) and
//! `{prefix}in-use:{version}` (the mark of use) — and measured by `MEMORY
//! USAGE`. An entry's last use is the time written in its value (Redis
//! keeps no read time under every eviction policy), so a trim removes the
//! oldest written first; a mark's is the mark's; a lock, which lives only
//! while held, is in use now. Stale versions are removed by one more
//! `SCAN`, their marks checked first. (Redis can bound its memory itself, by least
//! recent use: `maxmemory` with `maxmemory-policy allkeys-lru`; every key of
//! Sylva's may go.)

use super::{Entry, Kind, Maintain, Removal, is_version};
use crate::cache::redis::{IN_USE, RedisStore};
use crate::cache::{CacheError, TileStore};
use std::collections::HashSet;
use std::time::{Duration, SystemTime, UNIX_EPOCH};

/// Keys asked for per `SCAN` step.
const SCAN_COUNT: usize = 1000;
/// The prefix of lock keys, after the cache's own.
const LOCK: &str = "lock:";

/// The walk of a Redis cache.
pub(crate) struct Walker(pub RedisStore);

impl Walker {
    /// Calls `each` with every batch of keys matching `pattern`.
    fn scan(
        &self,
        pattern: &str,
        each: &mut dyn FnMut(Vec<Vec<u8>>) -> Result<(), CacheError>,
    ) -> Result<(), CacheError> {
        let mut cursor = 0u64;
        loop {
            let (next, keys): (u64, Vec<Vec<u8>>) = self.0.with(|c| {
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
        let replies: Vec<redis::Value> = self.0.with(|c| pipe.query(c))?;
        Ok(replies
            .chunks(2)
            .map(|pair| {
                let bytes: Option<u64> = redis::from_redis_value_ref(&pair[0]).ok().flatten();
                let stamp: Vec<u8> = redis::from_redis_value_ref(&pair[1]).unwrap_or_default();
                bytes.map(|b| (b, written(&stamp)))
            })
            .collect())
    }

    /// The version of `key` (after the prefix) and what the key is.
    fn classify(key: &str) -> Option<(&str, Kind)> {
        let (version, kind) = match (key.strip_prefix(LOCK), key.strip_prefix(IN_USE)) {
            (Some(locked), _) => (locked.split_once('/')?.0, Kind::Kept),
            (_, Some(version)) => (version, Kind::Kept),
            _ => match key.split_once('/')? {
                (version, rest) if rest.starts_with("uniform/") => (version, Kind::Shared),
                (version, _) => (version, Kind::Tile),
            },
        };
        is_version(version).then_some((version, kind))
    }

    /// Unlinks `keys` (none: nothing to do).
    fn unlink(&self, keys: Vec<Vec<u8>>) -> Result<(), CacheError> {
        match keys.is_empty() {
            true => Ok(()),
            false => self.0.with(|c| redis::cmd("UNLINK").arg(keys).query::<u64>(c)).map(|_| ()),
        }
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
        self.0.describe()
    }

    fn walk(&self, remove: &mut dyn FnMut(&str, &Entry) -> bool) -> Result<(), CacheError> {
        let prefix = self.0.prefix().to_string();
        self.scan(&format!("{}*", glob_literal(&prefix)), &mut |keys| {
            let ours: Vec<Vec<u8>> = keys
                .into_iter()
                .filter(|k| {
                    std::str::from_utf8(k)
                        .ok()
                        .and_then(|k| k.strip_prefix(&prefix))
                        .and_then(Walker::classify)
                        .is_some()
                })
                .collect();
            let measured = self.measure(&ours)?;
            let mut gone = Vec::new();
            for (key, m) in ours.into_iter().zip(measured) {
                let text = String::from_utf8_lossy(&key);
                let (Some((bytes, written)), Some((version, kind))) = (m, Walker::classify(&text[prefix.len()..]))
                else {
                    continue;
                };
                // A lock lives only while held; a mark has its time.
                let last_used = if text[prefix.len()..].starts_with(LOCK) { SystemTime::now() } else { written };
                if remove(version, &Entry { bytes, last_used: Some(last_used), kind }) && kind != Kind::Kept {
                    gone.push(key);
                }
            }
            self.unlink(gone)
        })
    }

    fn remove_versions(&self, versions: &[String], since: SystemTime) -> Result<Vec<Removal>, CacheError> {
        if versions.is_empty() {
            return Ok(Vec::new());
        }
        let prefix = self.0.prefix().to_string();
        let mut marks = redis::pipe();
        for version in versions {
            marks.cmd("GETRANGE").arg(format!("{prefix}{IN_USE}{version}")).arg(4).arg(11);
        }
        let stamps: Vec<Vec<u8>> = self.0.with(|c| marks.query(c))?;
        let outcomes: Vec<Removal> = stamps
            .iter()
            .map(|stamp| if written(stamp) >= since { Removal::Marked } else { Removal::Removed })
            .collect();
        let going: HashSet<&str> =
            versions.iter().zip(&outcomes).filter(|(_, o)| **o == Removal::Removed).map(|(v, _)| v.as_str()).collect();
        if !going.is_empty() {
            self.scan(&format!("{}*", glob_literal(&prefix)), &mut |keys| {
                let theirs = keys.into_iter().filter(|k| {
                    let version =
                        std::str::from_utf8(k).ok().and_then(|k| k.strip_prefix(&prefix)).and_then(Walker::classify);
                    version.is_some_and(|(v, _)| going.contains(v))
                });
                self.unlink(theirs.collect())
            })?;
        }
        Ok(outcomes)
    }
}
