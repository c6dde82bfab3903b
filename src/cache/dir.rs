//! The directory backend: one file per entry at `{root}/{key}`, written to a
//! unique temporary name in the same directory and renamed into place, so
//! readers (other threads, other processes sharing the directory, over NFS
//! too) see either the old file or the whole new one.
//!
//! Shared entries (uniform tiles) are one file under their content key and a
//! relative symbolic link per tile; a link's own time is its entry's time.
//! Locks are files `{key}.lock` created exclusively, holding the holder's
//! token; one older than its expiry is taken over.

use super::{CacheError, Lock, Lookup, Stored, TileStore, envelope};
use std::fs;
use std::io::{self, Write};
use std::path::{Component, Path, PathBuf};
use std::time::{Duration, SystemTime};

/// What failed, as [`CacheError::Io`] says it: making a directory.
const CREATE_DIR: &str = "create the cache directory";
/// Reading an entry.
const READ_ENTRY: &str = "read the cache entry";
/// Writing an entry.
const WRITE_ENTRY: &str = "write the cache entry";

/// Encoded tiles in a directory.
#[derive(Debug)]
pub struct DirStore {
    root: PathBuf,
}

impl DirStore {
    /// A store rooted at `root`, unchecked (its directories are made on
    /// first write).
    pub fn new(root: impl Into<PathBuf>) -> DirStore {
        DirStore { root: root.into() }
    }

    /// A store rooted at `root`, made if missing, so that a server or seeder
    /// whose cache cannot be a directory says so when it starts, not on every
    /// tile. A read-only directory is accepted (a server reads a seeded cache
    /// and serves what is missing uncached; the seeder probes writing).
    pub fn open(root: impl Into<PathBuf>) -> Result<DirStore, CacheError> {
        let store = DirStore::new(root);
        let root = store.root();
        if root.exists() && !root.is_dir() {
            let why = io::Error::other("it must be a directory, and this is a file");
            return Err(CacheError::io("use the tile cache", root, why));
        }
        fs::create_dir_all(root).map_err(|e| CacheError::io(CREATE_DIR, root, e))?;
        Ok(store)
    }

    /// The directory.
    pub fn root(&self) -> &Path {
        &self.root
    }

    /// The file of `key` (a relative path such as `v1a2b/cem/9/1939/1939_2704.png`).
    pub fn path(&self, key: &str) -> PathBuf {
        self.root.join(key)
    }

    /// Runs `make` on a temporary name beside `key`'s file, then renames it
    /// into place (the temporary is removed if anything fails).
    fn replace(&self, key: &str, make: impl FnOnce(&Path) -> io::Result<()>) -> Result<(), CacheError> {
        let path = self.path(key);
        let no_parent = || CacheError::io(WRITE_ENTRY, &path, io::Error::other("no parent directory"));
        let dir = path.parent().ok_or_else(no_parent)?;
        fs::create_dir_all(dir).map_err(|e| CacheError::io(CREATE_DIR, dir, e))?;
        let tmp = crate::outputs::sibling_name(&path, "tmp");
        let result = make(&tmp).and_then(|()| fs::rename(&tmp, &path));
        if result.is_err() {
            let _ = fs::remove_file(&tmp);
        }
        result.map_err(|e| CacheError::io(WRITE_ENTRY, &path, e))
    }
}

impl TileStore for DirStore {
    fn get(&self, key: &str) -> Result<Lookup, CacheError> {
        let path = self.path(key);
        let data = match fs::read(&path) {
            Ok(d) => d,
            Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(Lookup::Miss),
            Err(e) => return Err(CacheError::io(READ_ENTRY, &path, e)),
        };
        // A link's own time, not its target's: the entry's time.
        let meta = fs::symlink_metadata(&path).map_err(|e| CacheError::io(READ_ENTRY, &path, e))?;
        let written = meta.modified().unwrap_or(SystemTime::UNIX_EPOCH);
        Ok(match envelope::open(data) {
            Some(bytes) => Lookup::Hit(Stored { bytes, written }),
            None => Lookup::Corrupt,
        })
    }

    fn put(&self, key: &str, payload: &[u8]) -> Result<(), CacheError> {
        self.replace(key, |tmp| {
            let mut file = fs::File::create(tmp)?;
            file.write_all(payload)?;
            file.write_all(&envelope::trailer(payload))
        })
    }

    fn put_shared(&self, key: &str, blob: &str, payload: &[u8]) -> Result<(), CacheError> {
        match self.get(blob)? {
            Lookup::Hit(s) if s.bytes == payload => {}
            _ => self.put(blob, payload)?,
        }
        let target = relative_target(key, blob);
        self.replace(key, |tmp| std::os::unix::fs::symlink(&target, tmp))
    }

    fn try_lock(&self, key: &str, ttl: Duration) -> Result<Option<Lock>, CacheError> {
        let path = self.path(&format!("{key}.lock"));
        let lock = Lock { key: key.to_string(), token: super::token() };
        // Twice at most: a second time after removing an expired lock.
        for _ in 0..2 {
            match create_exclusive(&path, &lock.token) {
                Ok(()) => return Ok(Some(lock)),
                Err(e) if e.kind() == io::ErrorKind::AlreadyExists => {}
                Err(e) => return Err(CacheError::io("create the lock", &path, e)),
            }
            let age = fs::metadata(&path).and_then(|m| m.modified()).ok().and_then(|t| t.elapsed().ok());
            match age {
                Some(age) if age > ttl => {
                    // Expired: its holder died or overran. (Two takers racing
                    // here may both compute the tile; the bytes are the same.)
                    let _ = fs::remove_file(&path);
                }
                // Held, or released just now: ask again later.
                _ => return Ok(None),
            }
        }
        Ok(None)
    }

    fn unlock(&self, lock: &Lock) -> Result<(), CacheError> {
        let path = self.path(&format!("{}.lock", lock.key));
        match fs::read_to_string(&path) {
            Ok(token) if token == lock.token => {
                fs::remove_file(&path).map_err(|e| CacheError::io("remove the lock", &path, e))
            }
            Ok(_) => Ok(()),
            Err(e) if e.kind() == io::ErrorKind::NotFound => Ok(()),
            Err(e) => Err(CacheError::io("read the lock", &path, e)),
        }
    }

    fn describe(&self) -> String {
        format!("directory {}", self.root.display())
    }
}

/// Creates `path` only if it does not exist, holding `token`.
fn create_exclusive(path: &Path, token: &str) -> io::Result<()> {
    if let Some(dir) = path.parent() {
        fs::create_dir_all(dir)?;
    }
    let mut file = fs::OpenOptions::new().write(true).create_new(true).open(path)?;
    file.write_all(token.as_bytes())
}

/// The link from `key`'s file to `blob`'s, relative (so the directory can move).
fn relative_target(key: &str, blob: &str) -> PathBuf {
    let depth = Path::new(key).components().filter(|c| matches!(c, Component::Normal(_))).count().saturating_sub(1);
    let mut target: PathBuf = std::iter::repeat_n("..", depth).collect();
    target.push(blob);
    target
}

#[cfg(test)]
mod tests {
    use super::*;

    fn store(tag: &str) -> DirStore {
        let dir = std::env::temp_dir().join(format!("sylva-cache-{tag}-{}", std::process::id()));
        let _ = fs::remove_dir_all(&dir);
        DirStore::new(dir)
    }

    #[test]
    fn entries_round_trip_and_damage_is_detected() {
        let s = store("roundtrip");
        assert!(matches!(s.get("v1/cem/1/2/2_3.png").unwrap(), Lookup::Miss));
        s.put("v1/cem/1/2/2_3.png", b"tile bytes").unwrap();
        let Lookup::Hit(hit) = s.get("v1/cem/1/2/2_3.png").unwrap() else { panic!() };
        assert_eq!(hit.bytes, b"tile bytes");
        // Truncated, flipped, or foreign files are not served.
        let path = s.path("v1/cem/1/2/2_3.png");
        let whole = fs::read(&path).unwrap();
        for damaged in [
            whole[..whole.len() - 3].to_vec(),
            {
                let mut d = whole.clone();
                d[2] ^= 1;
                d
            },
            b"junk".to_vec(),
        ] {
            fs::write(&path, damaged).unwrap();
            assert!(matches!(s.get("v1/cem/1/2/2_3.png").unwrap(), Lookup::Corrupt));
        }
        s.put("v1/empty", b"").unwrap();
        assert!(matches!(s.get("v1/empty").unwrap(), Lookup::Hit(Stored { ref bytes, .. }) if bytes.is_empty()));
        fs::remove_dir_all(s.root()).unwrap();
    }

    #[test]
    fn concurrent_writers_leave_one_whole_file_and_no_temporaries() {
        let s = std::sync::Arc::new(store("writers"));
        let handles: Vec<_> = (0..8)
            .map(|i| {
                let s = s.clone();
                std::thread::spawn(move || {
                    for _ in 0..20 {
                        s.put("v1/x/0/0/0_0.bil", &vec![i as u8; 100_000]).unwrap();
                        assert!(matches!(s.get("v1/x/0/0/0_0.bil").unwrap(), Lookup::Hit(_)));
                    }
                })
            })
            .collect();
        handles.into_iter().for_each(|h| h.join().unwrap());
        let files: Vec<_> = fs::read_dir(s.path("v1/x/0/0")).unwrap().collect();
        assert_eq!(files.len(), 1);
        fs::remove_dir_all(s.root()).unwrap();
    }

    #[test]
    fn shared_entries_are_one_file_and_links() {
        let s = store("shared");
        for col in 0..3 {
            s.put_shared(&format!("v1/dem/5/7/7_{col}.bil"), "v1/uniform/abc.bil", b"sea").unwrap();
        }
        for col in 0..3 {
            let key = format!("v1/dem/5/7/7_{col}.bil");
            assert!(matches!(s.get(&key).unwrap(), Lookup::Hit(Stored { ref bytes, .. }) if bytes == b"sea"));
            assert!(fs::symlink_metadata(s.path(&key)).unwrap().file_type().is_symlink());
        }
        // Replacing a link by a plain tile leaves the shared file alone.
        s.put("v1/dem/5/7/7_0.bil", b"land").unwrap();
        assert!(
            matches!(s.get("v1/dem/5/7/7_1.bil").unwrap(), Lookup::Hit(Stored { ref bytes, .. }) if bytes == b"sea")
        );
        fs::remove_dir_all(s.root()).unwrap();
    }

    #[test]
    fn a_lock_has_one_holder_until_released_or_expired() {
        let s = store("locks");
        let ttl = Duration::from_secs(60);
        let first = s.try_lock("v1/a.bil", ttl).unwrap().expect("free");
        assert!(s.try_lock("v1/a.bil", ttl).unwrap().is_none());
        // Unlocking someone else's lock does nothing.
        s.unlock(&Lock { key: "v1/a.bil".into(), token: "other".into() }).unwrap();
        assert!(s.try_lock("v1/a.bil", ttl).unwrap().is_none());
        s.unlock(&first).unwrap();
        let second = s.try_lock("v1/a.bil", ttl).unwrap().expect("released");
        // An expired lock is taken over.
        std::thread::sleep(Duration::from_millis(20));
        let third = s.try_lock("v1/a.bil", Duration::from_millis(1)).unwrap().expect("expired");
        assert_ne!(second.token, third.token);
        fs::remove_dir_all(s.root()).unwrap();
    }
}
