//! The Redis backend: one value per entry under `{prefix}{key}`, so several
//! servers and seeders on different machines share one cache. A value is a
//! 4-byte tag, the time it was written (Unix ms, little-endian u64), then
//! either the payload in its [`envelope`] (`TILE`) or the key of a shared
//! entry (`LINK`). Locks are `SET {prefix}lock:{key} token NX PX ttl`,
//! released by a script that deletes the lock only if it still holds the
//! holder's token. A version's mark of use is `{prefix}in-use:{version}`,
//! a `MARK` value (its time the mark's) that expires after 30 days.
//!
//! Connections are kept in a small pool of idle ones; each has connect, read
//! and write timeouts, so an unreachable server is an error, not a hang.

use super::{CacheError, Lock, Lookup, Stored, TileStore, envelope};
use redis::{Client, Connection, RedisError};
use std::sync::Mutex;
use std::time::{Duration, SystemTime, UNIX_EPOCH};

const TILE: &[u8; 4] = b"TILE";
const LINK: &[u8; 4] = b"LINK";
const MARK: &[u8; 4] = b"MARK";
/// Tag and time.
const HEADER: usize = 12;
/// Connecting, reading or writing longer than this is a failure.
const TIMEOUT: Duration = Duration::from_secs(5);
/// Deletes the lock only if it is still the caller's.
const UNLOCK: &str =
    "if redis.call('get', KEYS[1]) == ARGV[1] then return redis.call('del', KEYS[1]) else return 0 end";

/// A lock's expiry in whole milliseconds, as `PX` and `PEXPIRE` take it.
fn millis(ttl: Duration) -> u64 {
    ttl.as_millis().clamp(1, u128::from(u32::MAX)) as u64
}

/// Extends a lock's expiry (ARGV[2] ms) if it is still the caller's (ARGV[1]).
const RENEW: &str =
    "if redis.call('get', KEYS[1]) == ARGV[1] then return redis.call('pexpire', KEYS[1], ARGV[2]) else return 0 end";

/// `url` as messages and records show it: without its password (the
/// user information before `@`, a `password` or `pass` parameter).
pub fn shown(url: &str) -> String {
    let (scheme, rest) = url.split_once("://").unwrap_or(("", url));
    let (authority, tail) = rest.split_at(rest.find(['/', '?']).unwrap_or(rest.len()));
    let host = authority.rsplit_once('@').map_or(authority, |(_, host)| host);
    let (path, query) = tail.split_once('?').map_or((tail, None), |(p, q)| (p, Some(q)));
    let secret = |param: &&str| param.starts_with("password=") || param.starts_with("pass=");
    let query = query.map(|q| q.split('&').filter(|p| !secret(p)).collect::<Vec<_>>().join("&"));
    let query = query.filter(|q| !q.is_empty()).map_or(String::new(), |q| format!("?{q}"));
    format!("{scheme}://{host}{path}{query}")
}

/// Encoded tiles in a Redis server.
pub struct RedisStore {
    client: Client,
    /// The URL as shown ([`shown`]).
    url: String,
    prefix: String,
    idle: Mutex<Vec<Connection>>,
}

impl RedisStore {
    /// The Redis key of `key`'s lock.
    fn lock_key(&self, key: &str) -> String {
        format!("{}lock:{key}", self.prefix)
    }

    /// Connects to `url` (`redis://host:port/db`, `redis+unix:///path`) and
    /// checks that the server answers.
    pub fn open(url: &str, prefix: &str) -> Result<RedisStore, CacheError> {
        let client = Client::open(url).map_err(|e| CacheError::Redis { url: shown(url), message: e.to_string() })?;
        let store = RedisStore { client, url: shown(url), prefix: prefix.into(), idle: Mutex::new(Vec::new()) };
        store.with(|c| redis::cmd("PING").query::<String>(c))?;
        Ok(store)
    }

    /// Runs `op` on a pooled connection (a failed connection is dropped).
    pub(crate) fn with<T>(&self, op: impl FnOnce(&mut Connection) -> Result<T, RedisError>) -> Result<T, CacheError> {
        let pooled = self.idle.lock().ok().and_then(|mut idle| idle.pop());
        let mut conn = match pooled {
            Some(c) => c,
            None => self.connect()?,
        };
        let out = op(&mut conn).map_err(|e| self.error(e))?;
        if let Ok(mut idle) = self.idle.lock() {
            idle.push(conn);
        }
        Ok(out)
    }

    fn connect(&self) -> Result<Connection, CacheError> {
        let conn = self.client.get_connection_with_timeout(TIMEOUT).map_err(|e| self.error(e))?;
        conn.set_read_timeout(Some(TIMEOUT)).map_err(|e| self.error(e))?;
        conn.set_write_timeout(Some(TIMEOUT)).map_err(|e| self.error(e))?;
        Ok(conn)
    }

    /// The prefix of every key.
    pub(crate) fn prefix(&self) -> &str {
        &self.prefix
    }

    fn error(&self, e: RedisError) -> CacheError {
        CacheError::Redis { url: self.url.clone(), message: e.to_string() }
    }

    fn set(&self, key: &str, tag: &[u8; 4], body: &[u8]) -> Result<(), CacheError> {
        let value = stamped(tag, body);
        self.with(|c| redis::cmd("SET").arg(format!("{}{key}", self.prefix)).arg(value).query::<()>(c))
    }

    /// Sets `key` to `payload` in its envelope.
    fn set_tile(&self, key: &str, payload: &[u8]) -> Result<(), CacheError> {
        let mut sealed = payload.to_vec();
        sealed.extend_from_slice(&envelope::trailer(payload));
        self.set(key, TILE, &sealed)
    }

    fn raw(&self, key: &str) -> Result<Option<Vec<u8>>, CacheError> {
        self.with(|c| redis::cmd("GET").arg(format!("{}{key}", self.prefix)).query::<Option<Vec<u8>>>(c))
    }
}

/// Unix milliseconds now, as a value's header holds them.
fn now_ms() -> [u8; 8] {
    SystemTime::now().duration_since(UNIX_EPOCH).map_or(0, |d| d.as_millis() as u64).to_le_bytes()
}

/// A value: `tag`, the time now, `body`.
fn stamped(tag: &[u8; 4], body: &[u8]) -> Vec<u8> {
    [tag.as_slice(), &now_ms(), body].concat()
}

/// Splits a value into its tag, time and body.
fn parse(value: &[u8]) -> Option<(&[u8], SystemTime, &[u8])> {
    let header = value.get(..HEADER)?;
    let ms = u64::from_le_bytes(header[4..].try_into().ok()?);
    Some((&header[..4], UNIX_EPOCH + Duration::from_millis(ms), &value[HEADER..]))
}

impl TileStore for RedisStore {
    fn get(&self, key: &str) -> Result<Lookup, CacheError> {
        let Some(value) = self.raw(key)? else { return Ok(Lookup::Miss) };
        let Some((tag, written, body)) = parse(&value) else { return Ok(Lookup::Corrupt) };
        let sealed = match (tag, std::str::from_utf8(body)) {
            (t, _) if t == TILE => body.to_vec(),
            (t, Ok(blob)) if t == LINK => match self.raw(blob)? {
                Some(shared) => match parse(&shared) {
                    Some((t, _, body)) if t == TILE => body.to_vec(),
                    _ => return Ok(Lookup::Corrupt),
                },
                None => return Ok(Lookup::Miss),
            },
            _ => return Ok(Lookup::Corrupt),
        };
        Ok(envelope::open(sealed).map_or(Lookup::Corrupt, |bytes| Lookup::Hit(Stored { bytes, written })))
    }

    fn put(&self, lock: &Lock, payload: &[u8]) -> Result<(), CacheError> {
        self.set_tile(&lock.key, payload)
    }

    fn put_shared(&self, lock: &Lock, blob: &str, payload: &[u8]) -> Result<(), CacheError> {
        match self.get(blob)? {
            // Its time renewed: a trim takes it for used (Redis keeps no
            // read time), as it is.
            Lookup::Hit(s) if s.bytes == payload => self.with(|c| {
                redis::cmd("SETRANGE").arg(format!("{}{blob}", self.prefix)).arg(4).arg(&now_ms()[..]).query::<()>(c)
            })?,
            _ => self.set_tile(blob, payload)?,
        }
        self.set(&lock.key, LINK, blob.as_bytes())
    }

    fn try_lock(&self, key: &str, ttl: Duration) -> Result<Option<Lock>, CacheError> {
        let lock = Lock { key: key.to_string(), token: super::holder::token() };
        let ms = millis(ttl);
        let set = self.with(|c| {
            redis::cmd("SET")
                .arg(self.lock_key(key))
                .arg(&lock.token)
                .arg("NX")
                .arg("PX")
                .arg(ms)
                .query::<Option<String>>(c)
        })?;
        Ok(set.map(|_| lock))
    }

    fn unlock(&self, lock: &Lock) -> Result<(), CacheError> {
        let key = self.lock_key(&lock.key);
        self.with(|c| redis::cmd("EVAL").arg(UNLOCK).arg(1).arg(key).arg(&lock.token).query::<i64>(c)).map(|_| ())
    }

    fn renew(&self, lock: &Lock, ttl: Duration) -> Result<bool, CacheError> {
        let key = self.lock_key(&lock.key);
        let ms = millis(ttl);
        let renewed =
            self.with(|c| redis::cmd("EVAL").arg(RENEW).arg(1).arg(key).arg(&lock.token).arg(ms).query::<i64>(c))?;
        Ok(renewed == 1)
    }

    fn mark_in_use(&self, version: &str) -> Result<(), CacheError> {
        let value = stamped(MARK, super::holder::token().as_bytes());
        let key = format!("{}{IN_USE}{version}", self.prefix);
        self.with(|c| redis::cmd("SET").arg(key).arg(value).arg("EX").arg(MARK_TTL.as_secs()).query::<()>(c))
    }

    fn describe(&self) -> String {
        format!("Redis {} (keys {}…)", self.url, self.prefix)
    }
}

/// The key (after the prefix, before the version) that marks a version in
/// use; its value is a `MARK` with the time of the last mark.
pub(crate) const IN_USE: &str = "in-use:";

/// A mark outlives any grace a prune may be given, then goes by itself.
const MARK_TTL: Duration = Duration::from_secs(30 * 86_400);

#[cfg(test)]
mod tests {
    use super::shown;

    #[test]
    fn a_url_is_shown_without_its_password() {
        assert_eq!(shown("redis://:s3cret@cache:6379/1"), "redis://cache:6379/1");
        assert_eq!(shown("rediss://user:p@ss@cache.example.org"), "rediss://cache.example.org");
        assert_eq!(shown("redis+unix:///run/redis.sock?db=2&pass=s3cret"), "redis+unix:///run/redis.sock?db=2");
        assert_eq!(shown("redis+unix:///run/redis.sock?password=s3cret"), "redis+unix:///run/redis.sock");
        assert_eq!(shown("redis://127.0.0.1:1/0"), "redis://127.0.0.1:1/0");
    }
}
