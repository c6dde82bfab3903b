//! Keeping a tile cache in hand (`sylva cache`): what it holds per version
//! key ([`usage`]), and [`prune`]: the versions no configuration names any
//! more (every change of a configuration or of a source file starts a new
//! key, and nothing reads the old one again), then the least recently used
//! tiles of the versions left, down to a size.
//!
//! The cache is walked twice at most (a Redis cache once more to remove
//! stale versions), in memory bounded by the number of versions and of
//! distinct minutes of use, not by the number of tiles: the first walk
//! measures every version and sorts the bytes of its tiles and shared
//! entries into a histogram by the minute they were last used; the oldest minutes whose
//! bytes reach the excess give the cut; the second walk removes the tiles
//! last used before the cut's minute, and of those used in it as many as
//! the excess still needs (in the order the walk meets them). A tile read
//! again between the walks is kept, so the cache may end a little above
//! its size (the report says where). A dry run is the same two walks,
//! counting instead of removing.
//!
//! Safe beside running servers and seeders: a tile removed is a miss,
//! computed again (a shared entry removed too: its links miss); a tile
//! being written lands after the walk or is kept; locks, temporaries and
//! marks of use are never trimmed; and a stale version written, read or
//! marked in use (`cache::in_use`: every running server and seeder marks
//! its own) within a grace period is kept, its mark checked again just
//! before it is removed. A stale version is removed whole, its locks too (no one is
//! computing its tiles, or it would not be stale).

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
    /// What it is.
    pub kind: Kind,
}

/// What an entry is, for counting and trimming.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum Kind {
    /// A tile (its file or its link to a shared entry): trimmed by use.
    Tile,
    /// A shared entry (a uniform tile's content): trimmed by use too (its
    /// links then find nothing, a miss, and the tile is made again).
    Shared,
    /// A lock, a writer's temporary, a mark of use, a directory: counted,
    /// never trimmed.
    Kept,
}

/// A backend's walk.
pub(crate) trait Maintain {
    /// Where the cache is, for messages.
    fn describe(&self) -> String;
    /// Visits every entry of every version in one walk; an entry for which
    /// `remove` (given its version) is true is removed if it is a tile or a
    /// shared entry (one already gone is no error).
    fn walk(&self, remove: &mut dyn FnMut(&str, &Entry) -> bool) -> Result<(), CacheError>;
    /// Removes whole versions, each unless it was marked in use
    /// (`cache::in_use`) at or after `since`; first, anything an earlier
    /// removal left half done.
    fn remove_versions(&self, versions: &[String], since: SystemTime) -> Result<Vec<Removal>, CacheError>;
}

/// What became of a stale version [`Maintain::remove_versions`] was given.
#[derive(Clone, Debug, PartialEq)]
pub(crate) enum Removal {
    /// Gone.
    Removed,
    /// Marked in use since the walk measured it: kept.
    Marked,
    /// Still there, for this reason.
    Failed(String),
}

/// True for a version key: `v` and 16 lowercase hex digits
/// (`config::version_key`). Anything else in a cache is not Sylva's tiles,
/// and is left alone.
pub(crate) fn is_version(name: &str) -> bool {
    name.len() == 17 && name.starts_with('v') && name[1..].bytes().all(|b| matches!(b, b'0'..=b'9' | b'a'..=b'f'))
}

/// What one version holds.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct VersionUsage {
    /// Its key.
    pub version: String,
    /// Tiles (files or links; shared entries not counted).
    pub tiles: u64,
    /// Bytes of everything under it.
    pub bytes: u64,
    /// When anything of it was last written, read or marked in use.
    pub last_used: Option<SystemTime>,
}

/// The versions of the cache at `backend`, largest first, and where it is.
pub fn usage(backend: &Backend) -> Result<(String, Vec<VersionUsage>), CacheError> {
    let store = open(backend)?;
    let mut versions: Vec<VersionUsage> = measure(&*store)?.into_values().map(|m| m.usage).collect();
    versions.sort_by(|a, b| b.bytes.cmp(&a.bytes).then(a.version.cmp(&b.version)));
    Ok((store.describe(), versions))
}

/// What to prune.
#[derive(Clone, Debug)]
pub struct Plan {
    /// The versions current (of the configurations served and seeded).
    pub keep: Vec<String>,
    /// Remove the other versions.
    pub stale: bool,
    /// Remove them even if no current version has tiles in the cache
    /// (otherwise a sign that the current versions were computed elsewise
    /// than the servers': another Sylva, other source files).
    pub force: bool,
    /// Then trim the least recently used tiles until the cache's versions
    /// take at most this many bytes.
    pub max_bytes: Option<u64>,
    /// A stale version written, read or marked in use within this long is
    /// kept, as in use.
    pub grace: Duration,
    /// Say what would go, remove nothing.
    pub dry_run: bool,
}

/// Why a prune did not run.
#[derive(Debug, thiserror::Error)]
pub enum PruneError {
    /// The cache could not be read or changed.
    #[error(transparent)]
    Cache(#[from] CacheError),
    /// No current version is in the cache, but stale ones are.
    #[error(
        "none of the current versions ({}) has tiles in {cache}, so every version there would be stale: are the servers' configurations, source files and Sylva the same as this command's? (`sylva cache usage` lists the versions; --force removes them anyway)",
        keep.join(", ")
    )]
    NoCurrentVersion {
        /// The versions kept.
        keep: Vec<String>,
        /// Where the cache is.
        cache: String,
    },
}

/// What a prune did (or, dry, would do).
#[derive(Clone, Debug, Default)]
pub struct Pruned {
    /// Where the cache is.
    pub cache: String,
    /// Bytes of its versions before.
    pub bytes_before: u64,
    /// Stale versions removed.
    pub removed: Vec<VersionUsage>,
    /// Stale versions kept because they were used within the grace.
    pub in_use: Vec<VersionUsage>,
    /// Stale versions that could not be removed, and why.
    pub failed: Vec<(VersionUsage, String)>,
    /// Tiles and shared entries trimmed, and their bytes.
    pub trimmed: (u64, u64),
    /// Why the trim stopped short, if it did.
    pub trim_failed: Option<String>,
    /// Bytes of its versions after.
    pub bytes_after: u64,
}

/// Prunes the cache at `backend` by `plan`, `now` being the time the grace
/// counts back from.
pub fn prune(backend: &Backend, plan: &Plan, now: SystemTime) -> Result<Pruned, PruneError> {
    let store = open(backend)?;
    let mut measured = measure(&*store)?;
    let any_stale = plan.stale && measured.keys().any(|v| !plan.keep.contains(v));
    let current_has_tiles = plan.keep.iter().any(|v| measured.get(v).is_some_and(|m| m.usage.tiles > 0));
    if any_stale && !current_has_tiles && !plan.force {
        return Err(PruneError::NoCurrentVersion { keep: plan.keep.clone(), cache: store.describe() });
    }
    let mut pruned = Pruned {
        cache: store.describe(),
        bytes_before: measured.values().map(|m| m.usage.bytes).sum(),
        ..Pruned::default()
    };
    let since = now.checked_sub(plan.grace).unwrap_or(SystemTime::UNIX_EPOCH);
    remove_stale(&*store, &mut measured, plan, since, &mut pruned)?;
    let bytes_left: u64 = measured.values().map(|m| m.usage.bytes).sum();
    let excess = plan.max_bytes.map_or(0, |max| bytes_left.saturating_sub(max));
    if excess > 0 {
        match trim(&*store, &measured, excess, plan.dry_run) {
            Ok(trimmed) => pruned.trimmed = trimmed,
            Err(e) => pruned.trim_failed = Some(e.to_string()),
        }
    }
    pruned.bytes_after = bytes_left.saturating_sub(pruned.trimmed.1);
    Ok(pruned)
}

/// Removes (or, dry, counts) the stale versions not used since `since`
/// and leaves out of `measured` those removed.
fn remove_stale(
    store: &dyn Maintain,
    measured: &mut BTreeMap<String, Measured>,
    plan: &Plan,
    since: SystemTime,
    pruned: &mut Pruned,
) -> Result<(), CacheError> {
    let stale = measured.values().filter(|m| plan.stale && !plan.keep.contains(&m.usage.version));
    let (recent, unused): (Vec<&Measured>, Vec<&Measured>) =
        stale.partition(|m| m.usage.last_used.is_some_and(|t| t >= since));
    pruned.in_use = recent.iter().map(|m| m.usage.clone()).collect();
    let unused: Vec<String> = unused.iter().map(|m| m.usage.version.clone()).collect();
    let outcomes = match (plan.stale, plan.dry_run) {
        (true, false) => store.remove_versions(&unused, since)?,
        _ => vec![Removal::Removed; unused.len()],
    };
    for (version, outcome) in unused.iter().zip(outcomes) {
        let usage = measured[version].usage.clone();
        match outcome {
            Removal::Removed => {
                measured.remove(version);
                pruned.removed.push(usage);
            }
            Removal::Marked => pruned.in_use.push(usage),
            Removal::Failed(why) => pruned.failed.push((usage, why)),
        }
    }
    Ok(())
}

/// A version measured by the first walk.
#[derive(Default)]
struct Measured {
    usage: VersionUsage,
    /// Its trimmable entries' bytes by the minute they were last used.
    by_minute: BTreeMap<u64, u64>,
}

/// The first walk: every version measured, nothing removed.
fn measure(store: &dyn Maintain) -> Result<BTreeMap<String, Measured>, CacheError> {
    let mut out: BTreeMap<String, Measured> = BTreeMap::new();
    store.walk(&mut |version, e| {
        let m = out.entry(version.to_string()).or_default();
        m.usage.version = version.to_string();
        m.usage.bytes += e.bytes;
        m.usage.last_used = m.usage.last_used.max(e.last_used);
        m.usage.tiles += u64::from(e.kind == Kind::Tile);
        if e.kind != Kind::Kept {
            *m.by_minute.entry(e.last_used.map_or(0, minute)).or_default() += e.bytes;
        }
        false
    })?;
    Ok(out)
}

/// Minutes since the Unix epoch (0 before it).
fn minute(t: SystemTime) -> u64 {
    t.duration_since(SystemTime::UNIX_EPOCH).map_or(0, |d| d.as_secs() / 60)
}

/// The versions' trimmable bytes by minute of last use, merged.
fn histogram(versions: &BTreeMap<String, Measured>) -> BTreeMap<u64, u64> {
    let mut all = BTreeMap::new();
    for (&minute, &bytes) in versions.values().flat_map(|m| &m.by_minute) {
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

/// The second walk: the oldest tiles and shared entries of `versions`
/// removed, up to the cut (counted only, on a dry run).
fn trim(
    store: &dyn Maintain,
    versions: &BTreeMap<String, Measured>,
    excess: u64,
    dry_run: bool,
) -> Result<(u64, u64), CacheError> {
    let Some(cut) = cut(&histogram(versions), excess) else { return Ok((0, 0)) };
    let (mut removed, mut at_cut) = ((0, 0), 0);
    store.walk(&mut |version, e| {
        let minute = e.last_used.map_or(0, minute);
        let old = e.kind != Kind::Kept
            && versions.contains_key(version)
            && (minute < cut.minute || (minute == cut.minute && at_cut < cut.bytes));
        if old {
            at_cut += if minute == cut.minute { e.bytes } else { 0 };
            removed = (removed.0 + 1, removed.1 + e.bytes);
        }
        old && !dry_run
    })?;
    Ok(removed)
}

/// The backend's walker.
fn open(backend: &Backend) -> Result<Box<dyn Maintain>, CacheError> {
    match backend {
        Backend::Directory(root) => Ok(Box::new(dir::Walker::open(root)?)),
        #[cfg(feature = "server")]
        Backend::Redis { url, prefix } => Ok(Box::new(redis::Walker(super::redis::RedisStore::open(url, prefix)?))),
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
        for name in
            ["v0123456789abcde", "w0123456789abcdef", "v0123456789abcdeg", "vDEADBEEFDEADBEEF", "uniform", "in-use"]
        {
            assert!(!is_version(name), "{name}");
        }
    }
}
