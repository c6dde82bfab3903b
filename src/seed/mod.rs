//! `sylva seed`: batch pregeneration of a region's tiles into the tile cache
//! the servers read, so clients never wait (`../shared/DESIGN.md`, use 3).
//!
//! A job is layers × formats × the tiles of a level range over a box or
//! polygons ([`coverage`]) in one of the server's tile pyramids
//! ([`pyramid`]: World Wind's, the XYZ/WMTS quadtree sets, Cesium's
//! terrain), walked depth first ([`walk`]) on a pool of workers; each tile
//! file is claimed, made with the server's own product code (so the bytes
//! are the server's) or, where exact, from its finished children
//! ([`decimate`]), and stored ([`tile`]). Progress is shown
//! ([`display`]) and saved for `--resume` ([`progress`]); tiles that still
//! fail after their retries are listed for `--tiles-from` ([`failed`]); a
//! job holds both files while it runs, refusing them to another ([`hold`]).
//! `--shard I/N` seeds one of N disjoint parts; any number of seeders and
//! servers can share one cache, directory or Redis, and compute each tile
//! once ([`crate::cache::flight`]).
//!
//! Invariant: a seeded tile file is byte-identical to the one the server
//! would compute for the same key.

pub mod coverage;
pub mod decimate;
pub mod display;
pub mod failed;
pub mod hold;
pub mod options;
pub mod progress;
pub mod pyramid;
pub mod tile;
pub mod walk;

pub use options::SeedOptions;
pub use tile::Counters;

use crate::grid::TileId;
use crate::server::wms::request::MapLayer;
use options::Job;
use progress::Progress;
use pyramid::Pyramid;
use rayon::prelude::*;
use std::path::Path;
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};
use thiserror::Error;
use tile::{Halves, Seeder};
use walk::{Node, Walk};

/// Why a seed did not run or stopped.
#[derive(Debug, Error)]
pub enum SeedError {
    /// A bad flag.
    #[error("{0}")]
    Usage(String),
    /// The configuration.
    #[error(transparent)]
    Config(#[from] crate::config::ConfigError),
    /// The tile cache.
    #[error(transparent)]
    Cache(#[from] crate::cache::CacheError),
    /// The coverage file.
    #[error(transparent)]
    Coverage(#[from] coverage::CoverageError),
    /// The tile list.
    #[error(transparent)]
    List(#[from] failed::ListError),
    /// The progress file.
    #[error(transparent)]
    Progress(#[from] progress::ProgressError),
    /// An output file that may not be written.
    #[error(transparent)]
    Output(#[from] crate::outputs::OutputError),
    /// A progress or failed-tiles file another job holds.
    #[error(
        "{} is in use by another seed job ({holder}; it holds {}): run this job in another working directory, or give it its own --progress-file and --failed-file",
        .file.display(),
        .lock.display()
    )]
    InUse {
        /// The file.
        file: std::path::PathBuf,
        /// Its lock file.
        lock: std::path::PathBuf,
        /// The other job, by its PID.
        holder: String,
    },
    /// A file of the run.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: std::path::PathBuf,
        /// The error.
        source: std::io::Error,
    },
    /// Ctrl-C or SIGTERM: the tiles in hand were finished.
    #[error("interrupted by signal {signal}: the tiles in hand were finished; {next}")]
    Interrupted {
        /// The signal.
        signal: i32,
        /// How to go on.
        next: String,
    },
    /// More tiles failed than allowed; the progress was saved.
    #[error("stopped: {failed} tile files failed (more than --max-failures {max}); they are listed in {list}; {next}")]
    TooManyFailures {
        /// Failed so far.
        failed: u64,
        /// The threshold.
        max: u64,
        /// The failed-tiles file.
        list: String,
        /// How to go on.
        next: String,
    },
}

/// What a run did.
#[derive(Debug)]
pub struct Report {
    /// A summary for people.
    pub text: String,
    /// Tile files that failed (listed in the failed-tiles file).
    pub failed: u64,
}

/// Runs `sylva seed`; `counters` count the tile files as they come.
pub fn run(options: &SeedOptions, counters: &Counters) -> Result<Report, SeedError> {
    let job = Job::new(options)?;
    let backend = job.config.tile_cache.backend(options.cache_dir.as_deref());
    if options.dry_run {
        let caches = cache_names(&backend);
        let resumed = options.resume.then(|| Progress::resume(&job.files.0, &job.fingerprint, &caches)).transpose()?;
        return dry_run(&job, options, resumed.as_ref());
    }
    let store = crate::cache::open(&backend)?;
    probe(&*store, &job.region.version)?;
    let _in_use = crate::cache::in_use::InUse::mark(store.clone(), &job.region.version);
    // The holds are kept (not `_`, which would drop them) to the end.
    let Records { list, progress, failed, holds: _holds } = records(&job, options, &cache_names(&backend))?;
    let threads =
        rayon::ThreadPoolBuilder::new().num_threads(options.concurrency).thread_name(|i| format!("sylva-seed-{i}"));
    let pool = threads.build().map_err(|e| SeedError::Usage(format!("--concurrency {}: {e}", options.concurrency)))?;
    let refresh_before = job.refresh_before.unwrap_or_else(|| progress.started() - CLOCK_SLACK);
    let started = Instant::now();
    let interrupt = crate::interrupt::Interrupt::watch();
    let run = Run {
        job: &job,
        store: &*store,
        leases: crate::cache::lease::Leases::start(store.clone(), job.config.tile_cache.lock_ttl()),
        counters,
        progress: &progress,
        failed: &failed,
        options,
        stop: AtomicBool::new(false),
        interrupt: &interrupt,
        refresh_before,
        warned: Mutex::new(false),
        wait_notice: std::sync::Once::new(),
    };
    match list {
        Some(entries) => pool.install(|| run.list(&entries)),
        None => pool.install(|| run.walk(job.walk.as_ref()))?,
    }
    let n = counters.failed.load(Ordering::Relaxed);
    if let Some(signal) = interrupt.came() {
        failed.abandon();
        return Err(SeedError::Interrupted { signal, next: how_to_go_on(options, &job.files.0) });
    }
    if run.stop.load(Ordering::Relaxed) {
        return Err(SeedError::TooManyFailures {
            failed: n,
            max: options.max_failures,
            list: failed.path().display().to_string(),
            next: how_to_go_on(options, &job.files.0),
        });
    }
    let list = failed.finish().map_err(|source| SeedError::Io { path: job.files.1.clone(), source })?;
    let mut text = summary(&job, &*store, counters, started.elapsed(), &list);
    let wrote = counters.bytes.load(Ordering::Relaxed);
    if let Some(max) = job.config.tile_cache.max_size.filter(|&max| wrote > max) {
        text.push_str(&format!(
            "\nthis seed wrote {}, more than [tile_cache] max_size ({}): the servers will trim the cache back to it, least recently used tiles first, some of these among them",
            crate::config::show_size(wrote),
            crate::config::show_size(max)
        ));
    }
    Ok(Report { text, failed: n })
}

/// The run's records.
struct Records {
    /// The tiles listed by `--tiles-from`, if any.
    list: Option<Vec<failed::Entry>>,
    /// The progress, resumed or new.
    progress: Progress,
    /// The failed-tiles file (replaced at the end when it is the list
    /// re-run or the run resumes, else emptied).
    failed: failed::Failed,
    /// This job's holds on the progress and failed-tiles files.
    holds: [Option<hold::Hold>; 2],
}

/// The run's records, once this job holds their files.
fn records(job: &Job, options: &SeedOptions, caches: &[String]) -> Result<Records, SeedError> {
    let (progress_path, failed_path) = &job.files;
    let holds = [hold::hold(progress_path)?, hold::hold(failed_path)?];
    // A list is read before the failed-tiles file (perhaps the same) is emptied.
    let list = read_list(job, options)?;
    let progress = match options.resume && list.is_none() {
        true => Progress::resume(progress_path, &job.fingerprint, caches)?,
        false => Progress::start(progress_path, &job.fingerprint, &caches[0]),
    };
    let rerun_in_place = options.tiles_from.as_deref().is_some_and(|l| crate::outputs::same_file(l, failed_path));
    // A resumed run retries the earlier failures: they are listed anew.
    let failed = match rerun_in_place || (options.resume && list.is_none()) {
        true => failed::Failed::replacing(failed_path),
        false => failed::Failed::open(failed_path),
    }
    .map_err(|source| SeedError::Io { path: failed_path.clone(), source })?;
    Ok(Records { list, progress, failed, holds })
}

/// The names of the cache a job writes to, the first as its progress file
/// records it: a directory by its absolute path, then (if another) the path
/// with its links resolved, so that either finds it again; a Redis server by
/// its URL (without a password) and key prefix.
fn cache_names(backend: &crate::cache::Backend) -> Vec<String> {
    match backend {
        crate::cache::Backend::Directory(dir) => {
            let absolute = std::path::absolute(dir).unwrap_or_else(|_| dir.clone());
            let resolved = std::fs::canonicalize(dir).ok().filter(|r| *r != absolute);
            let paths = std::iter::once(absolute).chain(resolved);
            paths.map(|p| format!("directory {}", p.display())).collect()
        }
        crate::cache::Backend::Redis { url, prefix } => {
            vec![format!("Redis {} prefix {prefix:?}", crate::cache::redis::shown(url))]
        }
    }
}

/// This shard's tiles of the `--tiles-from` list, if one is given.
fn read_list(job: &Job, options: &SeedOptions) -> Result<Option<Vec<failed::Entry>>, SeedError> {
    let Some(path) = options.tiles_from.as_deref() else { return Ok(None) };
    let all = failed::read(path, &job.region)?;
    let (listed, shard) = (all.len(), job.shard);
    let mine = shard.of_list(all);
    if shard.count > 1 && options.display != display::Mode::Quiet {
        let (i, n, m) = (shard.index, shard.count, mine.len());
        crate::outputs::say(format_args!("sylva seed: shard {i}/{n} of {}: {m} of its {listed} tiles", path.display()));
    }
    Ok(Some(mine))
}

/// What an interrupted run tells its operator to do next.
fn how_to_go_on(options: &SeedOptions, progress_path: &Path) -> String {
    match &options.tiles_from {
        Some(list) => format!("run --tiles-from {} again, with --skip-existing to keep what was made", list.display()),
        None => format!("the progress is saved in {}; resume with --resume", progress_path.display()),
    }
}

/// Cache entries written up to this long before a job started count as the
/// job's own: file times come from the kernel's coarse clock, up to one tick
/// (1–10 ms) behind the clock the job's start is read from, and Redis and
/// the progress file keep milliseconds.
const CLOCK_SLACK: Duration = Duration::from_millis(50);

/// True if `every` has passed since `last` (then `last` becomes now).
fn due(last: &Mutex<Instant>, every: Duration) -> bool {
    last.lock().is_ok_and(|mut t| {
        let due = t.elapsed() >= every;
        if due {
            *t = Instant::now();
        }
        due
    })
}

/// One run's shared state.
struct Run<'a> {
    job: &'a Job,
    store: &'a dyn crate::cache::TileStore,
    /// The locks this run holds, renewed while it makes their tiles.
    leases: crate::cache::lease::Leases,
    counters: &'a Counters,
    progress: &'a Progress,
    failed: &'a failed::Failed,
    options: &'a SeedOptions,
    /// Too many failures.
    stop: AtomicBool,
    interrupt: &'a crate::interrupt::Interrupt,
    refresh_before: std::time::SystemTime,
    warned: Mutex<bool>,
    /// Whether a long wait for a lock was explained.
    wait_notice: std::sync::Once,
}

impl Run<'_> {
    fn seeder(&self, pyramid: Pyramid, layers: Vec<MapLayer>) -> Seeder<'_> {
        let region = &self.job.region;
        let from_children = match (&self.job.walk, self.options.from_children, pyramid) {
            (Some(walk), true, Pyramid::WorldWind(_)) => exact_levels(region, &layers, *walk.levels().end()),
            _ => Vec::new(),
        };
        Seeder {
            region,
            pyramid,
            store: self.store,
            layers,
            formats: self.job.formats.clone(),
            refresh_before: self.refresh_before,
            leases: &self.leases,
            retries: self.options.retries,
            from_children,
            counters: self.counters,
            wait_notice: &self.wait_notice,
        }
    }

    /// Walks the job's tiles.
    fn walk(&self, walk: Option<&Walk>) -> Result<(), SeedError> {
        let Some(walk) = walk else { return Ok(()) };
        let files = |counts: Vec<u64>| -> u64 {
            counts.into_iter().zip(walk.levels()).map(|(n, level)| n * self.job.files_at(level)).sum()
        };
        let total = files(walk.count_per_level());
        // Those left are counted from the finished subtrees, not from the
        // files earlier runs made: tiles made after a run's last save are
        // walked again (and found in the cache).
        let left = if self.progress.complete { 0 } else { files(walk.count_left(&self.progress.finished())) };
        let display = display::Display::new(self.options.display, total, total - left);
        if !self.progress.complete {
            let seeder = self.seeder(self.job.pyramid, self.job.layers.clone());
            walk.roots().par_iter().for_each(|&root| {
                self.visit(walk, &seeder, &display, root);
            });
        }
        let failed = self.counters.failed.load(Ordering::Relaxed);
        display.finish(failed);
        // With tiles failed, a resumed run retries them.
        let complete = !self.stopped() && failed == 0;
        let path = &self.job.files.0;
        self.progress
            .save(self.counters.total(), complete)
            .map_err(|source| SeedError::Io { path: path.clone(), source })
    }

    /// Seeds a subtree (children first): the halves its parent can use, and
    /// whether every tile of it was made. Only then is it recorded as
    /// finished, so that a resumed run retries what failed.
    fn visit(&self, walk: &Walk, seeder: &Seeder, display: &display::Display, node: Node) -> (Option<Halves>, bool) {
        let tile = node.0;
        if self.progress.is_done(tile) {
            return (None, true);
        }
        if self.stopped() {
            return (None, false);
        }
        let children = walk.children(node);
        let kids: Vec<(Option<Halves>, bool)> =
            children.par_iter().map(|&c| self.visit(walk, seeder, display, c)).collect();
        if self.stopped() {
            return (None, false);
        }
        let mut made = kids.iter().all(|k| k.1);
        let mut halves = None;
        if walk.seeds(tile) {
            let four: Option<[Halves; 4]> =
                kids.into_iter().map(|k| k.0).collect::<Option<Vec<_>>>().and_then(|k| k.try_into().ok());
            let for_parent = tile.parent().is_some_and(|p| walk.seeds(p));
            let (h, failures) = seeder.tile(tile, four.as_ref(), for_parent);
            made &= failures.is_empty();
            self.record(failures);
            display.advance(self.job.files_at(tile.level), self.counters.failed.load(Ordering::Relaxed));
            halves = h.iter().any(Option::is_some).then_some(h);
        }
        if made {
            let ids: Vec<TileId> = children.iter().map(|c| c.0).collect();
            if let Err(e) = self.progress.finish(tile, &ids, self.counters.total()) {
                self.warn_once(&format!("cannot save the progress file {}: {e}", self.job.files.0.display()));
            }
        }
        (halves, made)
    }

    /// Seeds the tiles of a list, World Wind's each in the formats it lists
    /// (or the job's), with a seeder per pyramid, layer and formats.
    fn list(&self, entries: &[failed::Entry]) {
        // The tiles of each pyramid, layer and formats (those a line lists,
        // or the job's), in the order they first appear.
        let mut groups: Vec<(Pyramid, MapLayer, &[crate::encode::Format], Vec<TileId>)> = Vec::new();
        for e in entries {
            let formats = self.job.formats_of(e);
            match groups.iter_mut().find(|(p, layer, f, _)| (*p, *layer, *f) == (e.pyramid, e.layer, formats)) {
                Some(group) => group.3.push(e.tile),
                None => groups.push((e.pyramid, e.layer, formats, vec![e.tile])),
            }
        }
        let files = failed::files;
        let total = groups.iter().map(|(_, _, formats, tiles)| files(formats) * tiles.len() as u64).sum();
        let display = display::Display::new(self.options.display, total, 0);
        for (pyramid, layer, formats, tiles) in groups {
            let seeder = Seeder { formats: formats.to_vec(), ..self.seeder(pyramid, vec![layer]) };
            tiles.par_iter().for_each(|&tile| {
                if !self.stopped() {
                    let (_, failures) = seeder.tile(tile, None, false);
                    self.record(failures);
                    display.advance(files(formats), self.counters.failed.load(Ordering::Relaxed));
                }
            });
        }
        display.finish(self.counters.failed.load(Ordering::Relaxed));
    }

    fn record(&self, failures: Vec<(failed::Entry, String)>) {
        for (entry, why) in failures {
            if let Err(e) = self.failed.record(&entry, &why) {
                self.warn_once(&format!("cannot write {}: {e}", self.failed.path().display()));
            }
        }
        if self.counters.failed.load(Ordering::Relaxed) > self.options.max_failures {
            self.stop.store(true, Ordering::Relaxed);
        }
    }

    /// True once too many tiles failed or a signal came: no more tiles.
    fn stopped(&self) -> bool {
        self.stop.load(Ordering::Relaxed) || self.interrupt.came().is_some()
    }

    fn warn_once(&self, message: &str) {
        if self.warned.lock().is_ok_and(|mut w| !std::mem::replace(&mut *w, true)) {
            crate::outputs::say(format_args!("sylva seed: warning: {message}"));
        }
    }
}

/// `[level][layer]`: whether a World Wind tile of that level is exactly its
/// children decimated (levels 0 to `last`; tiles need an even number of
/// cells; data layers only).
fn exact_levels(region: &crate::region::Region, layers: &[MapLayer], last: u32) -> Vec<Vec<bool>> {
    let even = (region.tiles.samples() - 1).is_multiple_of(2);
    (0..last)
        .map(|level| {
            let coarse = region.tiles.tile_samples(TileId::new(level, 0, 0), 0);
            let fine = region.tiles.tile_samples(TileId::new(level + 1, 0, 0), 0);
            let alike = |l| match l {
                MapLayer::Data(l) => crate::cem::alike_across(region, l, &fine, &coarse),
                _ => false,
            };
            layers.iter().map(|&l| even && alike(l)).collect()
        })
        .collect()
}

/// Takes and releases a lock among `version`'s tiles: a cache that cannot
/// be written there fails the job at once, not every tile of it.
fn probe(store: &dyn crate::cache::TileStore, version: &str) -> Result<(), crate::cache::CacheError> {
    match store.try_lock(&format!("{version}/.sylva-seed-probe"), Duration::from_secs(1))? {
        Some(lock) => store.unlock(&lock),
        None => Ok(()),
    }
}

/// The dry run: tiles per level for this shard, or with `resumed` (the
/// job's progress file) those it has left.
fn dry_run(job: &Job, options: &SeedOptions, resumed: Option<&Progress>) -> Result<Report, SeedError> {
    let Some(walk) = &job.walk else {
        return Ok(dry_run_list(job, &read_list(job, options)?.unwrap_or_default()));
    };
    let counts = match resumed {
        Some(p) if p.complete => vec![0; walk.levels().count()],
        Some(p) => walk.count_left(&p.finished()),
        None => walk.count_per_level(),
    };
    let files: Vec<u64> = walk.levels().zip(&counts).map(|(level, n)| n * job.files_at(level)).collect();
    let rows: Vec<Vec<String>> = walk
        .levels()
        .zip(counts.iter().zip(&files))
        .map(|(level, (n, f))| vec![level.to_string(), n.to_string(), f.to_string()])
        .chain(std::iter::once(vec![
            "all".into(),
            counts.iter().sum::<u64>().to_string(),
            files.iter().sum::<u64>().to_string(),
        ]))
        .collect();
    let resuming = resumed.map_or(String::new(), |p| {
        format!(
            ", left to walk after {} tile files made earlier ({}){}",
            p.earlier,
            job.files.0.display(),
            failed_earlier(job)
        )
    });
    let what = match job.pyramid {
        Pyramid::WorldWind(_) => format!("{} layer(s) × {} format(s)", job.layers.len(), job.formats.len()),
        p => format!("{} layer(s) of {} tiles", job.layers.len(), p.name()),
    };
    let head = format!("{} — shard {}/{}, {what}{resuming}", job.region.name, job.shard.index, job.shard.count);
    Ok(Report { text: format!("{head}\n{}", crate::bench::table(&["level", "tiles", "files"], &rows)), failed: 0 })
}

/// The dry run of a tile list: this shard's tiles and files per pyramid
/// and level, in the order they first appear.
fn dry_run_list(job: &Job, entries: &[failed::Entry]) -> Report {
    let mut rows: Vec<(String, u64, u64)> = Vec::new();
    for e in entries {
        let level = format!("{} {}", e.pyramid.name(), e.tile.level);
        let files = failed::files(job.formats_of(e));
        match rows.iter_mut().find(|r| r.0 == level) {
            Some(row) => (row.1, row.2) = (row.1 + 1, row.2 + files),
            None => rows.push((level, 1, files)),
        }
    }
    let all = ("all".to_string(), rows.iter().map(|r| r.1).sum(), rows.iter().map(|r| r.2).sum());
    let rows: Vec<Vec<String>> = rows
        .into_iter()
        .chain([all])
        .map(|(level, tiles, files)| vec![level, tiles.to_string(), files.to_string()])
        .collect();
    let head = format!("{} — shard {}/{}, the tiles listed", job.region.name, job.shard.index, job.shard.count);
    Report { text: format!("{head}\n{}", crate::bench::table(&["level", "tiles", "files"], &rows)), failed: 0 }
}

/// What a resumed dry run's count includes above the failures of earlier
/// runs: the tiles over a failed tile were made, but their subtrees are not
/// finished, so the walk visits them again and finds them in the cache.
fn failed_earlier(job: &Job) -> String {
    let path = &job.files.1;
    match failed::read(path, &job.region) {
        Ok(list) if !list.is_empty() => format!(
            "; {} tile(s) failed earlier (listed in {}): the tiles above them are counted but will be found in the cache",
            list.len(),
            path.display()
        ),
        _ => String::new(),
    }
}

fn summary(job: &Job, store: &dyn crate::cache::TileStore, c: &Counters, took: Duration, failed: &Path) -> String {
    let get = |a: &std::sync::atomic::AtomicU64| a.load(Ordering::Relaxed);
    let made = get(&c.computed) + get(&c.derived);
    let mut text = format!(
        "seeded {} into {}: {made} tile files made ({} computed, {} from their children), {} already there, {} failed, in {:.1} s ({:.1} files/s)",
        job.region.name,
        store.describe(),
        get(&c.computed),
        get(&c.derived),
        get(&c.existing),
        get(&c.failed),
        took.as_secs_f64(),
        made as f64 / took.as_secs_f64().max(1e-9)
    );
    if get(&c.off_data) > 0 {
        let n = get(&c.off_data);
        text.push_str(&format!(
            "\n{n} tile files lie off the region's data: not stored (the server makes them at once, without the cache)"
        ));
    }
    if get(&c.failed) > 0 {
        text.push_str(&format!("\nfailed tiles are listed in {}; re-run them with --tiles-from {0}", failed.display()));
    }
    text
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cache::Backend;

    #[test]
    fn a_cache_is_named_by_its_absolute_path_or_its_server_without_a_password() {
        let dir = std::env::temp_dir().join(format!("sylva-names-{}", std::process::id()));
        std::fs::create_dir_all(dir.join("real")).unwrap();
        std::os::unix::fs::symlink(dir.join("real"), dir.join("link")).unwrap();
        let names = cache_names(&Backend::Directory(dir.join("link")));
        let real = std::fs::canonicalize(dir.join("real")).unwrap();
        assert_eq!(
            names,
            [format!("directory {}", dir.join("link").display()), format!("directory {}", real.display())]
        );
        std::fs::remove_dir_all(&dir).unwrap();
        let redis = |url: &str| cache_names(&Backend::Redis { url: url.into(), prefix: "sylva".into() });
        assert_eq!(redis("redis://:p@ss@cache:6379/0"), ["Redis redis://cache:6379/0 prefix \"sylva\""]);
        assert_eq!(redis("redis://cache:6379"), ["Redis redis://cache:6379 prefix \"sylva\""]);
    }
}
