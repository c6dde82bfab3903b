//! The tile cache on disk: encoded tiles under the World Wind path layout,
//! below a version key that changes with anything that changes the bytes
//! (configuration, source files, Sylva's version).
//!
//! Every file is the payload followed by a 16-byte trailer — magic, payload
//! length, CRC-32 — so a truncated or corrupt file is detected on read and
//! recomputed, never served. Files are written to a unique temporary name in
//! the same directory and renamed into place, so readers (other threads, other
//! processes sharing the directory) see either the old file or the whole new
//! one.
//!
//! Invariant: no HTTP, no async; callers run it off the async executor.

use std::fs;
use std::io::{self, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::SystemTime;

/// Marks the end of a cache file.
const MAGIC: &[u8; 4] = b"SYLV";
/// Magic, payload length (u64), CRC-32 (u32).
const TRAILER: usize = 16;

/// A cached payload and when it was written.
#[derive(Clone, Debug)]
pub struct Stored {
    /// The encoded tile (empty for a tile known to have no data).
    pub bytes: Vec<u8>,
    /// When the file was written.
    pub written: SystemTime,
}

/// What reading a cache file found.
#[derive(Debug)]
pub enum Lookup {
    /// A valid entry.
    Hit(Stored),
    /// No entry.
    Miss,
    /// An entry that failed its check (truncated, corrupt): treat as a miss.
    Corrupt,
}

/// Encoded tiles in a directory.
#[derive(Debug)]
pub struct DirStore {
    root: PathBuf,
    counter: AtomicU64,
}

impl DirStore {
    /// A store rooted at `root` (created on first write).
    pub fn new(root: impl Into<PathBuf>) -> DirStore {
        DirStore { root: root.into(), counter: AtomicU64::new(0) }
    }

    /// The directory.
    pub fn root(&self) -> &Path {
        &self.root
    }

    /// The file of `key` (a relative path such as `v1a2b/cem/9/1939/1939_2704.png`).
    pub fn path(&self, key: &str) -> PathBuf {
        self.root.join(key)
    }

    /// Reads and checks an entry.
    pub fn get(&self, key: &str) -> io::Result<Lookup> {
        let path = self.path(key);
        let data = match fs::read(&path) {
            Ok(d) => d,
            Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(Lookup::Miss),
            Err(e) => return Err(e),
        };
        let written = fs::metadata(&path)?.modified().unwrap_or(SystemTime::UNIX_EPOCH);
        Ok(match open_envelope(data) {
            Some(bytes) => Lookup::Hit(Stored { bytes, written }),
            None => Lookup::Corrupt,
        })
    }

    /// Writes an entry atomically.
    pub fn put(&self, key: &str, payload: &[u8]) -> io::Result<()> {
        let path = self.path(key);
        let dir = path.parent().ok_or_else(|| io::Error::other(format!("{key}: no parent directory")))?;
        fs::create_dir_all(dir)?;
        let n = self.counter.fetch_add(1, Ordering::Relaxed);
        let tmp = dir.join(format!(
            ".{}.{}.{n}.tmp",
            path.file_name().and_then(|f| f.to_str()).unwrap_or("tile"),
            std::process::id()
        ));
        let result = (|| {
            let mut file = fs::File::create(&tmp)?;
            file.write_all(payload)?;
            file.write_all(&trailer(payload))?;
            fs::rename(&tmp, &path)
        })();
        if result.is_err() {
            let _ = fs::remove_file(&tmp);
        }
        result
    }
}

fn trailer(payload: &[u8]) -> [u8; TRAILER] {
    let mut t = [0u8; TRAILER];
    t[..4].copy_from_slice(MAGIC);
    t[4..12].copy_from_slice(&(payload.len() as u64).to_le_bytes());
    t[12..].copy_from_slice(&crc32fast::hash(payload).to_le_bytes());
    t
}

/// The payload of a file if its trailer checks out.
fn open_envelope(mut data: Vec<u8>) -> Option<Vec<u8>> {
    let n = data.len().checked_sub(TRAILER)?;
    let t = &data[n..];
    let len = u64::from_le_bytes(t[4..12].try_into().ok()?);
    let crc = u32::from_le_bytes(t[12..].try_into().ok()?);
    if &t[..4] != MAGIC || len != n as u64 || crc != crc32fast::hash(&data[..n]) {
        return None;
    }
    data.truncate(n);
    Some(data)
}

/// A stable 64-bit digest (FNV-1a): ETags and version keys must agree
/// between processes and builds, which `std`'s hasher does not promise.
pub fn digest(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325u64, |h, &b| (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3))
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
    fn digests_are_stable() {
        assert_eq!(digest(b""), 0xcbf2_9ce4_8422_2325);
        assert_eq!(digest(b"a"), 0xaf63_dc4c_8601_ec8c);
    }
}
