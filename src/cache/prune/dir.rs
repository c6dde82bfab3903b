//! The directory cache's walk: a version is the directory `{root}/{version}`;
//! its entries are every file, link and directory under it, counted by the
//! blocks they take (as `du` counts); a tile is a file or link outside
//! `uniform/` (where shared entries are) whose name does not start with a
//! dot (writers' temporaries, the mark of use) or end in `.lock`. A file's
//! last use is the later of its modification and access times: a file
//! system mounted `relatime` (Linux's default) records the first read
//! after each write and at most one a day after that; one mounted `noatime`
//! none, and its tiles are trimmed oldest written first.
//!
//! A version is removed by renaming it out of the way
//! (`.{version}.removing.{token}`, which no walk takes for a version) and
//! deleting that: a writer that comes after the rename makes the version's
//! directory anew; what a prune killed or failing mid-deletion leaves, the
//! next one deletes first. Directories a
//! trim empties stay: a tile computed there again needs them, and its
//! writer may be making it at that moment.

use super::{Entry, Kind, Maintain, Removal, is_version};
use crate::cache::dir::{IN_USE, file_token};
use crate::cache::{CacheError, DirStore, TileStore, holder};
use std::fs;
use std::io;
use std::os::unix::fs::MetadataExt;
use std::path::{Path, PathBuf};
use std::time::{Duration, SystemTime};

/// What failed, as [`CacheError::Io`] says it.
const READ_DIR: &str = "read the cache directory";

/// The walk of a directory cache.
pub(crate) struct Walker(DirStore);

impl Walker {
    /// The cache at `root`, which must be a directory (it is not made).
    pub fn open(root: &Path) -> Result<Walker, CacheError> {
        match fs::metadata(root) {
            Ok(m) if m.is_dir() => Ok(Walker(DirStore::new(root))),
            Ok(_) => Err(CacheError::io("use the tile cache", root, io::Error::other("it is not a directory"))),
            Err(e) => Err(CacheError::io("use the tile cache", root, e)),
        }
    }

    /// Visits `path` of `version` (a directory after everything in it) and
    /// removes the tiles and shared entries `remove` asks for.
    fn visit(
        &self,
        version: &str,
        path: &Path,
        shared: bool,
        remove: &mut dyn FnMut(&str, &Entry) -> bool,
    ) -> Result<(), CacheError> {
        let meta = match fs::symlink_metadata(path) {
            Ok(m) => m,
            // Removed by another process since its directory was read.
            Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(()),
            Err(e) => return Err(CacheError::io(READ_DIR, path, e)),
        };
        if meta.is_dir() {
            let top = path == self.0.path(version);
            for child in read_dir(path)? {
                let into_shared = shared || (top && child.file_name().is_some_and(|n| n == "uniform"));
                self.visit(version, &child, into_shared, remove)?;
            }
        }
        let kind = kind(&meta, path, shared);
        let entry = Entry { bytes: meta.blocks() * 512, last_used: (!meta.is_dir()).then(|| last_used(&meta)), kind };
        if remove(version, &entry) && kind != Kind::Kept {
            match fs::remove_file(path) {
                Err(e) if e.kind() != io::ErrorKind::NotFound => {
                    return Err(CacheError::io("remove the cache entry", path, e));
                }
                _ => {}
            }
        }
        Ok(())
    }
}

impl Maintain for Walker {
    fn describe(&self) -> String {
        self.0.describe()
    }

    fn walk(&self, remove: &mut dyn FnMut(&str, &Entry) -> bool) -> Result<(), CacheError> {
        let mut versions: Vec<String> = read_dir(self.0.root())?
            .into_iter()
            .filter_map(|p| p.file_name().and_then(|n| n.to_str()).map(str::to_string))
            .filter(|name| is_version(name))
            .collect();
        versions.sort();
        for version in versions {
            let path = self.0.path(&version);
            if path.is_dir() {
                self.visit(&version, &path, false, remove)?;
            }
        }
        Ok(())
    }

    fn remove_versions(&self, versions: &[String], since: SystemTime) -> Result<Vec<Removal>, CacheError> {
        self.sweep()?;
        Ok(versions.iter().map(|v| self.remove_version(v, since)).collect())
    }
}

impl Walker {
    /// Removes `version` unless marked in use since `since`: set aside by a
    /// rename, then deleted (what the deletion leaves, the next prune's
    /// sweep takes).
    fn remove_version(&self, version: &str, since: SystemTime) -> Removal {
        let path = self.0.path(version);
        let marked = fs::metadata(path.join(IN_USE)).and_then(|m| m.modified());
        if marked.is_ok_and(|t| t >= since) {
            return Removal::Marked;
        }
        let aside = self.0.path(&format!(".{version}{ASIDE}{}", file_token(&holder::token())));
        match fs::rename(&path, &aside) {
            Ok(()) => {
                if let Err(e) = fs::remove_dir_all(&aside) {
                    tracing::warn!(error = %e, path = %aside.display(), "a stale version set aside is not all deleted; the next prune tries again");
                }
                Removal::Removed
            }
            Err(e) if e.kind() == io::ErrorKind::NotFound => Removal::Removed,
            Err(e) => Removal::Failed(CacheError::io("set aside the version", &path, e).to_string()),
        }
    }

    /// Deletes the versions earlier removals set aside and left.
    fn sweep(&self) -> Result<(), CacheError> {
        for path in read_dir(self.0.root())? {
            let name = path.file_name().and_then(|n| n.to_str()).unwrap_or_default();
            let left = name.strip_prefix('.').and_then(|n| n.split_once(ASIDE)).is_some_and(|(v, _)| is_version(v));
            if left {
                fs::remove_dir_all(&path).map_err(|e| CacheError::io("remove the version set aside", &path, e))?;
            }
        }
        Ok(())
    }
}

/// What a version set aside for removal has after its key in its name.
const ASIDE: &str = ".removing.";

/// The paths in directory `path` (none if it went meanwhile).
fn read_dir(path: &Path) -> Result<Vec<PathBuf>, CacheError> {
    let entries = match fs::read_dir(path) {
        Ok(entries) => entries,
        Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(Vec::new()),
        Err(e) => return Err(CacheError::io(READ_DIR, path, e)),
    };
    entries.map(|e| e.map(|e| e.path()).map_err(|e| CacheError::io(READ_DIR, path, e))).collect()
}

/// What the file, link or directory at `path` is; `shared`: under the
/// version's `uniform/`.
fn kind(meta: &fs::Metadata, path: &Path, shared: bool) -> Kind {
    let name = path.file_name().and_then(|n| n.to_str()).unwrap_or_default();
    // Locks, writers' temporaries (`.{name}.{token}.tmp`) and the mark of use.
    let kept = meta.is_dir() || name.starts_with('.') || name.ends_with(".lock");
    match (kept, shared) {
        (true, _) => Kind::Kept,
        (false, true) => Kind::Shared,
        (false, false) => Kind::Tile,
    }
}

/// The later of the modification and access times.
fn last_used(meta: &fs::Metadata) -> SystemTime {
    let at = |secs: i64, nanos: i64| {
        let since = Duration::new(secs.max(0) as u64, nanos.clamp(0, 999_999_999) as u32);
        SystemTime::UNIX_EPOCH + since
    };
    at(meta.mtime(), meta.mtime_nsec()).max(at(meta.atime(), meta.atime_nsec()))
}

#[cfg(test)]
mod tests {
    use super::super::{Plan, Pruned, Removal, prune, usage};
    use super::Walker;
    use crate::cache::{Backend, DirStore, TileStore, flight};
    use std::fs;
    use std::time::{Duration, SystemTime};

    const CURRENT: &str = "v00000000000000aa";
    const OLD: &str = "v00000000000000bb";
    const RECENT: &str = "v00000000000000cc";
    const MARKED: &str = "v00000000000000dd";
    const TILE_BYTES: usize = 40_000;

    fn store(tag: &str) -> DirStore {
        let dir = std::env::temp_dir().join(format!("sylva-prune-{tag}-{}", std::process::id()));
        let _ = fs::remove_dir_all(&dir);
        fs::create_dir_all(&dir).unwrap();
        DirStore::new(dir)
    }

    /// `key`'s tile, written and read `minutes` ago.
    fn tile(s: &DirStore, key: &str, minutes: u64) {
        tile_read(s, key, minutes, minutes);
    }

    /// `key`'s tile, written `written` minutes ago and read `read` ago.
    fn tile_read(s: &DirStore, key: &str, written: u64, read: u64) {
        let lock = s.try_lock(key, Duration::from_secs(60)).unwrap().unwrap();
        flight::save(s, &lock, &vec![7; TILE_BYTES], false).unwrap();
        s.unlock(&lock).unwrap();
        let ago = |minutes: u64| SystemTime::now() - Duration::from_secs(minutes * 60);
        let file = fs::File::options().write(true).open(s.path(key)).unwrap();
        file.set_times(fs::FileTimes::new().set_accessed(ago(read)).set_modified(ago(written))).unwrap();
    }

    /// What `du` says the directory takes.
    fn du(path: &std::path::Path) -> u64 {
        let out = std::process::Command::new("du").arg("-sB1").arg(path).output().unwrap();
        String::from_utf8(out.stdout).unwrap().split_whitespace().next().unwrap().parse().unwrap()
    }

    fn run(s: &DirStore, plan: &Plan) -> Pruned {
        prune(&Backend::Directory(s.root().to_path_buf()), plan, SystemTime::now()).unwrap()
    }

    fn plan(stale: bool, max_bytes: Option<u64>, dry_run: bool) -> Plan {
        let grace = Duration::from_secs(3600);
        Plan { keep: vec![CURRENT.into()], stale, force: false, max_bytes, grace, dry_run }
    }

    /// A lock left held, a writer's temporary, and a shared entry linked
    /// twice, in `version`.
    fn others(s: &DirStore, version: &str) {
        s.try_lock(&format!("{version}/cem/5/1/1_1.bil"), Duration::from_secs(60)).unwrap().unwrap();
        fs::write(s.path(&format!("{version}/cem/5/1/.1_2.bil.token.tmp")), [0; 5000]).unwrap();
        for col in [3, 4] {
            let lock = s.try_lock(&format!("{version}/cem/5/1/1_{col}.bil"), Duration::from_secs(60)).unwrap().unwrap();
            flight::save(s, &lock, &[0; 9000], true).unwrap();
            s.unlock(&lock).unwrap();
        }
    }

    #[test]
    fn usage_counts_what_du_counts_and_only_tiles_as_tiles() {
        let s = store("usage");
        for row in 0..3 {
            tile(&s, &format!("{CURRENT}/cem/6/{row}/{row}_0.bil"), 5);
        }
        others(&s, CURRENT);
        // Not a version: left out, whatever it holds.
        fs::create_dir_all(s.path("notes")).unwrap();
        fs::write(s.path("notes/readme.txt"), "x").unwrap();
        fs::write(s.path("seed-progress.json"), "{}").unwrap();
        let (_, versions) = usage(&Backend::Directory(s.root().to_path_buf())).unwrap();
        assert_eq!(versions.len(), 1);
        // Three tiles and two links to the shared entry.
        assert_eq!((versions[0].version.as_str(), versions[0].tiles), (CURRENT, 5));
        assert_eq!(versions[0].bytes, du(&s.path(CURRENT)));
        fs::remove_dir_all(s.root()).unwrap();
    }

    #[test]
    fn a_trim_removes_the_least_recently_used_tiles_down_to_the_size() {
        let s = store("trim");
        let key = |i: u64| format!("{CURRENT}/cem/7/{i}/{i}_0.bil");
        // Tiles 0..10, tile 0 the oldest; 3 and 10 used in the same minute;
        // 11 written before all, but read since.
        for i in 0..10 {
            tile(&s, &key(i), 100 - 10 * i);
        }
        tile(&s, &key(10), 70);
        tile_read(&s, &key(11), 200, 1);
        others(&s, CURRENT);
        let version = s.path(CURRENT);
        let before = du(&version);
        let one = std::os::unix::fs::MetadataExt::blocks(&fs::metadata(s.path(&key(0))).unwrap()) * 512;
        // Room for all but three and a half tiles: the four oldest go, and
        // only one of the two of the cut's minute.
        let max = before - one * 7 / 2;
        let dry = run(&s, &plan(false, Some(max), true));
        assert_eq!(du(&version), before, "a dry run removes nothing");
        let done = run(&s, &plan(false, Some(max), false));
        assert_eq!((dry.trimmed, done.trimmed), ((4, 4 * one), (4, 4 * one)));
        let kept: Vec<u64> = (0..12).filter(|&i| s.path(&key(i)).exists()).collect();
        assert!(kept.starts_with(&[4, 5, 6, 7, 8, 9]) && kept.ends_with(&[11]) && kept.len() == 8, "{kept:?}");
        assert!(kept.contains(&3) != kept.contains(&10));
        assert_eq!((done.bytes_after, du(&version)), (before - 4 * one, before - 4 * one));
        assert!(done.bytes_after <= max);
        // Locks, temporaries and the (newer) shared entry stay.
        assert!(s.path(&format!("{CURRENT}/cem/5/1/1_1.bil.lock")).exists());
        assert!(s.path(&format!("{CURRENT}/cem/5/1/.1_2.bil.token.tmp")).exists());
        assert_eq!(fs::read_dir(s.path(&format!("{CURRENT}/uniform"))).unwrap().count(), 1);
        fs::remove_dir_all(s.root()).unwrap();
    }

    #[test]
    fn stale_versions_go_unless_used_within_the_grace() {
        let s = store("stale");
        tile(&s, &format!("{CURRENT}/cem/6/0/0_0.bil"), 600);
        tile(&s, &format!("{OLD}/cem/6/0/0_0.bil"), 180);
        tile(&s, &format!("{OLD}/dem/6/0/0_0.bil"), 240);
        tile(&s, &format!("{RECENT}/cem/6/0/0_0.bil"), 5);
        // Old tiles, but a server of that version runs: marked in use.
        tile(&s, &format!("{MARKED}/cem/6/0/0_0.bil"), 300);
        s.mark_in_use(MARKED).unwrap();
        fs::create_dir_all(s.path("backup")).unwrap();
        let dry = run(&s, &plan(true, None, true));
        assert!(s.path(OLD).exists(), "a dry run removes nothing");
        let done = run(&s, &plan(true, None, false));
        for pruned in [&dry, &done] {
            let names = |v: &[super::super::VersionUsage]| v.iter().map(|v| v.version.clone()).collect::<Vec<_>>();
            assert_eq!(
                (names(&pruned.removed), names(&pruned.in_use)),
                (vec![OLD.to_string()], vec![RECENT.to_string(), MARKED.to_string()])
            );
            assert_eq!(pruned.removed[0].tiles, 2);
        }
        assert!(!s.path(OLD).exists());
        for kept in [CURRENT, RECENT, MARKED, "backup"] {
            assert!(s.path(kept).exists(), "{kept}");
        }
        let versions = [CURRENT, RECENT, MARKED].map(|v| du(&s.path(v)));
        assert_eq!(done.bytes_after, versions.iter().sum::<u64>());
        // A version marked after the walk measured it is kept all the same.
        let hour_ago = SystemTime::now() - Duration::from_secs(3600);
        assert_eq!(Walker::open(s.root()).unwrap().remove_version(MARKED, hour_ago), Removal::Marked);
        fs::remove_dir_all(s.root()).unwrap();
    }

    #[test]
    fn what_a_removal_left_set_aside_goes_with_the_next_prune() {
        let s = store("aside");
        tile(&s, &format!("{CURRENT}/cem/6/0/0_0.bil"), 5);
        let left = s.path(&format!(".{OLD}.removing.killed"));
        fs::create_dir_all(left.join("cem/6/0")).unwrap();
        fs::write(left.join("cem/6/0/0_0.bil"), [0; 100]).unwrap();
        // Not a version to the walks.
        let (_, versions) = usage(&Backend::Directory(s.root().to_path_buf())).unwrap();
        assert_eq!(versions.len(), 1);
        run(&s, &plan(true, None, true));
        assert!(left.exists(), "a dry run removes nothing");
        run(&s, &plan(true, None, false));
        assert!(!left.exists());
        fs::remove_dir_all(s.root()).unwrap();
    }

    #[test]
    fn a_prune_that_finds_no_current_version_removes_nothing_unless_forced() {
        let s = store("none-current");
        tile(&s, &format!("{OLD}/cem/6/0/0_0.bil"), 180);
        // The current version marked (a server started once), but no tiles.
        s.mark_in_use(CURRENT).unwrap();
        let backend = Backend::Directory(s.root().to_path_buf());
        let refused = prune(&backend, &plan(true, None, false), SystemTime::now()).unwrap_err();
        assert!(
            refused.to_string().contains(&format!("none of the current versions ({CURRENT}) has tiles")),
            "{refused}"
        );
        assert!(s.path(OLD).exists());
        let forced = prune(&backend, &Plan { force: true, ..plan(true, None, false) }, SystemTime::now()).unwrap();
        assert_eq!((forced.removed.len(), s.path(OLD).exists()), (1, false));
        fs::remove_dir_all(s.root()).unwrap();
    }
}
