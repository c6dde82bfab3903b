//! Keeping a tile cache in hand (`sylva cache`): what it holds per version
//! key ([`usage`]), and [`prune`]: the versions no configuration names any
//! more (every change of a configuration or of a source file starts a new
//! key, and nothing reads the old one again), then the least recently used
//! tiles of the versions left, down to a size.
//!
//! The cache is walked twice at most, in memory bounded by the number of
//! versions and of distinct minutes of use, not by the number of tiles: the
//! first walk measures every version and sorts its tiles' bytes into a
//! histogram by the minute they were last used; the oldest minutes whose
//! bytes reach the excess give the cut; the second walk removes the tiles
//! last used before the cut's minute, and of those used in it as many as
//! the excess still needs (in the order the walk meets them). A tile read
//! again between the walks is kept, so the cache may end a little above
//! its size (the report says where). A dry run is the same two walks,
//! counting instead of removing.
//!
//! Safe beside running servers and seeders: a tile removed is a miss,
//! computed again; a tile being written lands after the walk or is kept;
//! locks, temporaries and shared (uniform) entries are never trimmed; and a
//! stale version used within a grace period is kept, as in use.

mod dir;
#[cfg(feature = "server")]
mod redis;

use super::{Backend, CacheError};
use std::collections::BTreeMap;
use std::time::{Duration, SystemTime};

/// One thing a walk meets.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Entry {
    /// Bytes it takes (allocated blocks on disk, memory in Redis).
    pub bytes: u64,
    /// When it was last written or read, as far as the backend knows
    /// (`None` for a directory: listing it is no use of a tile).
    pub last_used: Option<SystemTime>,
    /// Whether trimming may remove it.
    pub kind: Kind,
}

/// What an entry is, for trimming.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum Kind {
    /// A tile (its file or its link to a shared entry): trimmed by use.
    Tile,
    /// Anything else of the version (shared entries, locks, temporaries,
    /// directories): counted, never trimmed.
    Kept,
}

/// A backend's walk over its versions.
pub(crate) trait Maintain {
    /// Where the cache is, for messages.
    fn describe(&self) -> String;
    /// The version keys present.
    fn versions(&self) -> Result<Vec<String>, CacheError>;
    /// Visits every entry of `version`; an entry for which `remove` is true
    /// is removed (one already gone is no error).
    fn walk(&self, version: &str, remove: &mut dyn FnMut(&Entry) -> bool) -> Result<(), CacheError>;
    /// Removes a whole version.
    fn remove_version(&self, version: &str) -> Result<(), CacheError>;
}

/// True for a version key: `v` and 16 hex digits (`config::version_key`).
/// Anything else in a cache is not Sylva's tiles, and is left alone.
pub(crate) fn is_version(name: &str) -> bool {
    name.len() == 17 && name.starts_with('v') && name[1..].bytes().all(|b| b.is_ascii_hexdigit())
}

/// What one version holds.
#[derive(Clone, Debug, PartialEq)]
pub struct VersionUsage {
    /// Its key.
    pub version: String,
    /// Tiles (files or links; shared entries not counted).
    pub tiles: u64,
    /// Bytes of everything under it.
    pub bytes: u64,
    /// When anything of it was last written or read.
    pub last_used: Option<SystemTime>,
}

/// The versions of the cache at `backend`, largest first.
pub fn usage(backend: &Backend) -> Result<(String, Vec<VersionUsage>), CacheError> {
    let store = open(backend)?;
    let mut measured = measure(&*store)?;
    measured.sort_by(|a, b| b.usage.bytes.cmp(&a.usage.bytes).then(a.usage.version.cmp(&b.usage.version)));
    Ok((store.describe(), measured.into_iter().map(|m| m.usage).collect()))
}

/// What to prune.
#[derive(Clone, Debug)]
pub struct Plan {
    /// The versions in use (of the configurations served and seeded).
    pub keep: Vec<String>,
    /// Remove the other versions.
    pub stale: bool,
    /// Then trim the least recently used tiles until the cache holds at
    /// most this many bytes.
    pub max_bytes: Option<u64>,
    /// A stale version written or read within this long is kept, as in use.
    pub grace: Duration,
    /// Say what would go, remove nothing.
    pub dry_run: bool,
}

/// What a prune did (or, dry, would do).
#[derive(Clone, Debug, Default)]
pub struct Pruned {
    /// Where the cache is.
    pub cache: String,
    /// Bytes before.
    pub bytes_before: u64,
    /// Stale versions removed.
    pub removed: Vec<VersionUsage>,
    /// Stale versions kept because they were used within the grace.
    pub in_use: Vec<VersionUsage>,
    /// Tiles trimmed, and their bytes.
    pub trimmed: (u64, u64),
    /// Bytes after.
    pub bytes_after: u64,
}

/// Prunes the cache at `backend` by `plan`, `now` being the time the grace
/// counts back from.
pub fn prune(backend: &Backend, plan: &Plan, now: SystemTime) -> Result<Pruned, CacheError> {
    let store = open(backend)?;
    let measured = measure(&*store)?;
    let mut pruned = Pruned {
        cache: store.describe(),
        bytes_before: measured.iter().map(|m| m.usage.bytes).sum(),
        ..Pruned::default()
    };
    let mut left = Vec::new();
    for m in measured {
        let recent = m.usage.last_used.is_some_and(|t| now.duration_since(t).map_or(true, |age| age < plan.grace));
        match (plan.stale && !plan.keep.contains(&m.usage.version), recent) {
            (false, _) => left.push(m),
            (true, true) => {
                pruned.in_use.push(m.usage.clone());
                left.push(m);
            }
            (true, false) => {
                if !plan.dry_run {
                    store.remove_version(&m.usage.version)?;
                }
                pruned.removed.push(m.usage);
            }
        }
    }
    let bytes_left: u64 = left.iter().map(|m| m.usage.bytes).sum();
    let excess = plan.max_bytes.map_or(0, |max| bytes_left.saturating_sub(max));
    pruned.trimmed = match excess {
        0 => (0, 0),
        _ => trim(&*store, &left, excess, plan.dry_run)?,
    };
    pruned.bytes_after = bytes_left - pruned.trimmed.1;
    Ok(pruned)
}

/// A version measured by the first walk.
struct Measured {
    usage: VersionUsage,
    /// Its tiles' bytes by the minute they were last used.
    by_minute: BTreeMap<u64, u64>,
}

/// The first walk: every version measured, nothing removed.
fn measure(store: &dyn Maintain) -> Result<Vec<Measured>, CacheError> {
    let mut out = Vec::new();
    for version in store.versions()? {
        let mut m = Measured {
            usage: VersionUsage { version: version.clone(), tiles: 0, bytes: 0, last_used: None },
            by_minute: BTreeMap::new(),
        };
        store.walk(&version, &mut |e| {
            m.usage.bytes += e.bytes;
            m.usage.last_used = m.usage.last_used.max(e.last_used);
            if let (Kind::Tile, Some(t)) = (e.kind, e.last_used) {
                m.usage.tiles += 1;
                *m.by_minute.entry(minute(t)).or_default() += e.bytes;
            }
            false
        })?;
        out.push(m);
    }
    Ok(out)
}

/// Minutes since the Unix epoch (0 before it).
fn minute(t: SystemTime) -> u64 {
    t.duration_since(SystemTime::UNIX_EPOCH).map_or(0, |d| d.as_secs() / 60)
}

/// The versions' tile bytes by minute of last use, merged.
fn histogram(versions: &[Measured]) -> BTreeMap<u64, u64> {
    let mut all = BTreeMap::new();
    for (&minute, &bytes) in versions.iter().flat_map(|m| &m.by_minute) {
        *all.entry(minute).or_default() += bytes;
    }
    all
}

/// Where a trim stops: the tiles last used before `minute` go, and of
/// those used in it, `bytes` more (in the order the walk meets them).
#[derive(Clone, Copy, Debug, PartialEq)]
struct Cut {
    minute: u64,
    bytes: u64,
}

/// The cut that removes `excess` bytes of the oldest tiles (all of them,
/// if they do not add up to it).
fn cut(histogram: &BTreeMap<u64, u64>, excess: u64) -> Option<Cut> {
    let mut older = 0;
    let mut last = None;
    for (&minute, &bytes) in histogram {
        last = Some(Cut { minute, bytes });
        if older + bytes >= excess {
            return Some(Cut { minute, bytes: excess - older });
        }
        older += bytes;
    }
    last
}

/// The second walk: the oldest tiles removed, up to the cut (counted
/// only, on a dry run).
fn trim(store: &dyn Maintain, versions: &[Measured], excess: u64, dry_run: bool) -> Result<(u64, u64), CacheError> {
    let Some(cut) = cut(&histogram(versions), excess) else { return Ok((0, 0)) };
    let (mut removed, mut at_cut) = ((0, 0), 0);
    for m in versions {
        store.walk(&m.usage.version, &mut |e| {
            let minute = e.last_used.map_or(0, minute);
            let old = e.kind == Kind::Tile && (minute < cut.minute || (minute == cut.minute && at_cut < cut.bytes));
            if old {
                at_cut += if minute == cut.minute { e.bytes } else { 0 };
                removed = (removed.0 + 1, removed.1 + e.bytes);
            }
            old && !dry_run
        })?;
    }
    Ok(removed)
}

/// The backend's walker.
fn open(backend: &Backend) -> Result<Box<dyn Maintain>, CacheError> {
    match backend {
        Backend::Directory(root) => Ok(Box::new(dir::Walker::open(root)?)),
        #[cfg(feature = "server")]
        Backend::Redis { url, prefix } => Ok(Box::new(redis::Walker::open(url, prefix)?)),
        #[cfg(not(feature = "server"))]
        Backend::Redis { url, .. } => Err(CacheError::Unsupported(format!(
            "the Redis tile cache at {url} needs Sylva built with the `server` feature"
        ))),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_cut_takes_the_oldest_minutes_and_what_the_excess_needs_of_the_next() {
        let h: BTreeMap<u64, u64> = [(10, 100), (20, 100), (30, 100)].into();
        assert_eq!(cut(&h, 1), Some(Cut { minute: 10, bytes: 1 }));
        assert_eq!(cut(&h, 100), Some(Cut { minute: 10, bytes: 100 }));
        assert_eq!(cut(&h, 150), Some(Cut { minute: 20, bytes: 50 }));
        // More than all tiles take: all of them.
        assert_eq!(cut(&h, 1000), Some(Cut { minute: 30, bytes: 100 }));
        assert_eq!(cut(&BTreeMap::new(), 1), None);
    }

    #[test]
    fn version_keys_are_told_from_other_names() {
        assert!(is_version("v0123456789abcdef"));
        for name in ["v0123456789abcde", "w0123456789abcdef", "v0123456789abcdeg", "uniform", "seed-progress.json"] {
            assert!(!is_version(name), "{name}");
        }
    }
}
