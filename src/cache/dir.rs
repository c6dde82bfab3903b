//! The directory backend: one file per entry at `{root}/{key}`, written to a
//! temporary name unique to its writer and renamed into place, so readers
//! (other threads, other processes sharing the directory, over NFS too) see
//! either the old file or the whole new one.
//!
//! A version's directory holds `.in-use`, rewritten by each mark of use.
//!
//! Shared entries (uniform tiles) are one file under their content key and a
//! relative symbolic link per tile; a link's own time is its entry's time.
//! Locks are files `{key}.lock` created exclusively, holding the holder's
//! token; one older than its expiry, or whose holder died on this machine
//! (`cache::holder`), is taken over.
//!
//! A lock's holder writes only through its temporary file
//! `.{name}.{token}.tmp` beside the key's file (a shared entry's file too,
//! renamed from there into its own directory), so the one temporary a
//! holder killed mid-write leaves is removed by whoever takes its lock over,
//! without listing a directory.

use super::{CacheError, Lock, Lookup, Stored, TileStore, envelope, holder};
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
        make_dirs(root).map_err(|e| CacheError::io(CREATE_DIR, root, e))?;
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

    /// Writes `payload` and its trailer to `key`'s file, through `lock`'s
    /// temporary file.
    fn write(&self, lock: &Lock, key: &str, payload: &[u8]) -> Result<(), CacheError> {
        self.replace(lock, key, |tmp| {
            let mut file = fs::File::create(tmp)?;
            file.write_all(payload)?;
            file.write_all(&envelope::trailer(payload))
        })
    }

    /// Runs `make` on `lock`'s temporary file, then renames it to `key`'s
    /// file (the temporary is removed if anything fails).
    fn replace(&self, lock: &Lock, key: &str, make: impl FnOnce(&Path) -> io::Result<()>) -> Result<(), CacheError> {
        let path = self.path(key);
        let tmp = self.scratch(lock);
        for file in [&path, &tmp] {
            let no_parent = || CacheError::io(WRITE_ENTRY, file, io::Error::other("no parent directory"));
            let dir = file.parent().ok_or_else(no_parent)?;
            make_dirs(dir).map_err(|e| CacheError::io(CREATE_DIR, dir, e))?;
        }
        let result = make(&tmp).and_then(|()| fs::rename(&tmp, &path));
        if result.is_err() {
            let _ = fs::remove_file(&tmp);
        }
        result.map_err(|e| CacheError::io(WRITE_ENTRY, &path, e))
    }

    /// The temporary file of `lock`'s holder: `.{name}.{token}.tmp` beside
    /// the locked key's file, the token's characters kept to a safe set and
    /// its length bounded (a token read back from a damaged lock file may
    /// be anything).
    fn scratch(&self, lock: &Lock) -> PathBuf {
        crate::outputs::sibling_tagged(&self.path(&lock.key), &file_token(&lock.token), "tmp")
    }

    /// The lock file of `key`.
    fn lock_path(&self, key: &str) -> PathBuf {
        self.path(&format!("{key}.lock"))
    }

    /// Removes a lock whose holder is gone, and the temporary file it may
    /// have left, unless another taker has put its own lock there since.
    /// (Two takers racing between that look and the removal may both
    /// compute the tile; the bytes are the same. A holder that overran its
    /// expiry but still runs fails to store its tile, which its taker
    /// stores.)
    fn break_lock(&self, lock: &Lock) {
        let path = self.lock_path(&lock.key);
        if fs::read_to_string(&path).is_ok_and(|token| token == lock.token) {
            let _ = fs::remove_file(self.scratch(lock));
            let _ = fs::remove_file(&path);
        }
    }
}

/// A token as a file name may hold it: characters kept to a safe set, its
/// length bounded (a token read back from a damaged lock may be anything).
pub(crate) fn file_token(token: &str) -> String {
    token.chars().take(TOKEN_CHARS).map(holder::file_safe).collect()
}

/// Most characters of a token kept in a temporary file's name: a token is
/// a host name (at most 64), a boot id (12), a PID namespace (10 digits), a
/// PID (7), Unix nanoseconds (19), a count (20) and 5 separators, 137 in all.
const TOKEN_CHARS: usize = 140;

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

    fn put(&self, lock: &Lock, payload: &[u8]) -> Result<(), CacheError> {
        self.write(lock, &lock.key, payload)
    }

    fn put_shared(&self, lock: &Lock, blob: &str, payload: &[u8]) -> Result<(), CacheError> {
        match self.get(blob)? {
            Lookup::Hit(s) if s.bytes == payload => {}
            _ => self.write(lock, blob, payload)?,
        }
        let target = relative_target(&lock.key, blob);
        self.replace(lock, &lock.key, |tmp| std::os::unix::fs::symlink(&target, tmp))
    }

    fn try_lock(&self, key: &str, ttl: Duration) -> Result<Option<Lock>, CacheError> {
        let path = self.lock_path(key);
        let lock = Lock { key: key.to_string(), token: holder::token() };
        // Twice at most: a second time after breaking an abandoned lock.
        for _ in 0..2 {
            match create_exclusive(&path, &lock.token) {
                Ok(()) => return Ok(Some(lock)),
                Err(e) if e.kind() == io::ErrorKind::AlreadyExists => {}
                Err(e) => return Err(CacheError::io("create the lock", &path, e)),
            }
            match abandoned(&path, ttl) {
                Some(token) => self.break_lock(&Lock { key: key.to_string(), token }),
                // Held, or released just now: ask again later.
                None => return Ok(None),
            }
        }
        Ok(None)
    }

    fn unlock(&self, lock: &Lock) -> Result<(), CacheError> {
        let path = self.lock_path(&lock.key);
        match fs::read_to_string(&path) {
            Ok(token) if token == lock.token => {
                fs::remove_file(&path).map_err(|e| CacheError::io("remove the lock", &path, e))
            }
            Ok(_) => Ok(()),
            Err(e) if e.kind() == io::ErrorKind::NotFound => Ok(()),
            Err(e) => Err(CacheError::io("read the lock", &path, e)),
        }
    }

    fn renew(&self, lock: &Lock, _ttl: Duration) -> Result<bool, CacheError> {
        let path = self.lock_path(&lock.key);
        // One handle for the token and the time: a lock removed and taken
        // again meanwhile is another file, left alone.
        let renewed = fs::File::options().read(true).write(true).open(&path).and_then(|mut file| {
            let mut token = String::new();
            io::Read::read_to_string(&mut file, &mut token)?;
            match token == lock.token {
                true => file.set_modified(SystemTime::now()).map(|()| true),
                false => Ok(false),
            }
        });
        match renewed {
            Err(e) if e.kind() == io::ErrorKind::NotFound => Ok(false),
            other => other.map_err(|e| CacheError::io("renew the lock", &path, e)),
        }
    }

    fn mark_in_use(&self, version: &str) -> Result<(), CacheError> {
        let path = self.path(&format!("{version}/{IN_USE}"));
        let dir = self.path(version);
        make_dirs(&dir).map_err(|e| CacheError::io(CREATE_DIR, &dir, e))?;
        // Through a temporary, as tiles are: a mark another user left is
        // replaced as theirs are, with the directory's permission alone.
        let token = holder::token();
        let tmp = crate::outputs::sibling_tagged(&path, &file_token(&token), "tmp");
        let written = fs::write(&tmp, &token).and_then(|()| fs::rename(&tmp, &path));
        if written.is_err() {
            let _ = fs::remove_file(&tmp);
        }
        written.map_err(|e| CacheError::io("mark the version in use", &path, e))
    }

    fn describe(&self) -> String {
        format!("directory {}", self.root.display())
    }
}

/// The file in a version's directory whose time is its last mark of use.
pub(crate) const IN_USE: &str = ".in-use";

/// The token of the lock at `path` if its holder is gone: it died on this
/// machine, or the lock expired (its holder died elsewhere, or overran).
/// `None` while it is held, or if it was released just now.
fn abandoned(path: &Path, ttl: Duration) -> Option<String> {
    use std::os::unix::fs::MetadataExt;
    let token = fs::read_to_string(path).ok()?;
    let meta = fs::metadata(path).ok()?;
    let age = meta.modified().ok().and_then(|t| t.elapsed().ok());
    (holder::died(&token, meta.uid()) || age.is_some_and(|age| age > ttl)).then_some(token)
}

/// `fs::create_dir_all`, naming what is in the way when part of `dir`
/// is no directory (a file, or a link to nothing) rather than saying
/// "File exists".
fn make_dirs(dir: &Path) -> io::Result<()> {
    fs::create_dir_all(dir).map_err(|e| {
        if !matches!(e.kind(), io::ErrorKind::AlreadyExists | io::ErrorKind::NotADirectory) {
            return e;
        }
        // Without a trailing slash, which would follow a link.
        let dir: PathBuf = dir.components().collect();
        let parts: Vec<&Path> = dir.ancestors().filter(|a| !a.as_os_str().is_empty()).collect();
        match parts.into_iter().rev().find(|a| !a.is_dir()) {
            Some(part) => match fs::read_link(part) {
                Ok(target) => io::Error::other(format!(
                    "{} is a link to {}, which is no directory",
                    part.display(),
                    target.display()
                )),
                Err(_) => io::Error::other(format!("{} is a file, not a directory", part.display())),
            },
            None => e,
        }
    })
}

/// Creates `path` only if it does not exist, holding `token`.
fn create_exclusive(path: &Path, token: &str) -> io::Result<()> {
    if let Some(dir) = path.parent() {
        make_dirs(dir)?;
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

    /// A lock on `key` as its holder has it (where who holds it does not
    /// matter, the lock file is not made).
    fn held(key: &str) -> Lock {
        Lock { key: key.into(), token: holder::token() }
    }

    #[test]
    fn entries_round_trip_and_damage_is_detected() {
        let s = store("roundtrip");
        assert!(matches!(s.get("v1/cem/1/2/2_3.png").unwrap(), Lookup::Miss));
        s.put(&held("v1/cem/1/2/2_3.png"), b"tile bytes").unwrap();
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
        s.put(&held("v1/empty"), b"").unwrap();
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
                        s.put(&held("v1/x/0/0/0_0.bil"), &vec![i as u8; 100_000]).unwrap();
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
            s.put_shared(&held(&format!("v1/dem/5/7/7_{col}.bil")), "v1/uniform/abc.bil", b"sea").unwrap();
        }
        for col in 0..3 {
            let key = format!("v1/dem/5/7/7_{col}.bil");
            assert!(matches!(s.get(&key).unwrap(), Lookup::Hit(Stored { ref bytes, .. }) if bytes == b"sea"));
            assert!(fs::symlink_metadata(s.path(&key)).unwrap().file_type().is_symlink());
        }
        // The shared file was written beside the first link and moved.
        assert_eq!(fs::read_dir(s.path("v1/dem/5/7")).unwrap().count(), 3, "temporaries left");
        // Replacing a link by a plain tile leaves the shared file alone.
        s.put(&held("v1/dem/5/7/7_0.bil"), b"land").unwrap();
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

    /// A lock file on `key` holding `token`, as a holder left it.
    fn left_lock(s: &DirStore, key: &str, token: &str) -> Lock {
        fs::create_dir_all(s.path(key).parent().unwrap()).unwrap();
        fs::write(s.lock_path(key), token).unwrap();
        Lock { key: key.into(), token: token.into() }
    }

    #[test]
    fn a_lock_whose_holder_died_on_this_machine_is_taken_at_once() {
        // Regression: a seed resumed after a SIGKILL waited out the TTL on
        // every lock the dead seeder held.
        let s = store("dead-holder");
        let ttl = Duration::from_secs(3600);
        let here = holder::machine().unwrap();
        let (dead, alive) = (holder::tests::dead_pid(), std::process::id());
        let namespace = here.rsplit(':').next().unwrap();
        for (token, taken) in [
            (format!("{here}:{dead}:0:0"), true),
            (format!("{here}:{alive}:0:0"), false),
            (format!("another-host:{namespace}:{dead}:0:0"), false),
            ("killed-seeder".to_string(), false),
        ] {
            left_lock(&s, "v1/a.bil", &token);
            let lock = s.try_lock("v1/a.bil", ttl).unwrap();
            assert_eq!(lock.is_some(), taken, "{token}");
            let _ = fs::remove_file(s.lock_path("v1/a.bil"));
        }
        fs::remove_dir_all(s.root()).unwrap();
    }

    #[test]
    fn the_temporary_file_of_a_holder_killed_mid_write_goes_with_its_lock() {
        // Regression: a seed killed with SIGKILL while writing left its
        // temporary file in the cache for good.
        let s = store("dead-scratch");
        let here = holder::machine().unwrap();
        let dead_here = format!("{here}:{}:0:0", holder::tests::dead_pid());
        // Taken at once (died here) and taken once expired (died elsewhere).
        for (key, token, ttl) in [
            ("v1/cem/13/1/1_2.bil", dead_here.as_str(), Duration::from_secs(3600)),
            ("v1/cem/13/1/1_3.bil", "another-host:1:2:0:0", Duration::from_millis(1)),
        ] {
            let dead = left_lock(&s, key, token);
            fs::write(s.scratch(&dead), b"half a ti").unwrap();
            std::thread::sleep(Duration::from_millis(20));
            let taker = s.try_lock(key, ttl).unwrap().expect("abandoned");
            assert!(!s.scratch(&dead).exists(), "{token}");
            s.put(&taker, b"tile").unwrap();
            s.unlock(&taker).unwrap();
        }
        let mut names: Vec<_> = fs::read_dir(s.path("v1/cem/13/1")).unwrap().map(|e| e.unwrap().file_name()).collect();
        names.sort();
        assert_eq!(names, ["1_2.bil", "1_3.bil"]);
        fs::remove_dir_all(s.root()).unwrap();
    }
}
