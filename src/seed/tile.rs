//! Seeding one tile: for each layer and format, claim its cache key (skip it
//! if a usable entry is there, wait if another process is making it), make
//! it with the server's own product code — a World Wind tile's samples once
//! for all its formats, from the four children's halves where that is
//! exact — encode, store, release. Each failure is retried a bounded number
//! of times.

use super::decimate;
use super::failed::Entry;
use super::pyramid::Pyramid;
use crate::cache::flight::{self, Claim};
use crate::cache::lease::Leases;
use crate::cache::{Lock, Stored, TileStore};
use crate::cem::{Layer, LayerSamples, Stats};
use crate::encode::Format;
use crate::grid::TileId;
use crate::region::Region;
use crate::server::products::{self, Encoding, Product};
use crate::server::wms::request::MapLayer;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, SystemTime};

/// Halved samples of a finished tile per layer (index as in the job's
/// layers), kept for its parent; `None` where the parent will not use them.
pub type Halves = Vec<Option<LayerSamples>>;

/// Tile files seen so far.
#[derive(Debug, Default)]
pub struct Counters {
    /// Computed with the pipeline.
    pub computed: AtomicU64,
    /// Built from their children.
    pub derived: AtomicU64,
    /// Found in the cache, usable.
    pub existing: AtomicU64,
    /// Failed after their retries.
    pub failed: AtomicU64,
    /// Off the region's data: not stored (the server makes them at once,
    /// without the cache).
    pub off_data: AtomicU64,
    /// Bytes of the tiles this run stored (a uniform tile's whole, though
    /// stored once).
    pub bytes: AtomicU64,
}

impl Counters {
    /// Every file counted.
    pub fn total(&self) -> u64 {
        let all = [&self.computed, &self.derived, &self.existing, &self.failed, &self.off_data];
        all.iter().map(|c| c.load(Ordering::Relaxed)).sum()
    }
}

/// How one tile file came about.
enum Made {
    Computed,
    Derived,
    Existing,
    OffData,
}

/// What seeding needs to know, shared by every worker.
pub struct Seeder<'a> {
    /// The region.
    pub region: &'a Region,
    /// The pyramid the tiles are in.
    pub pyramid: Pyramid,
    /// The tile cache.
    pub store: &'a dyn TileStore,
    /// Layers seeded.
    pub layers: Vec<MapLayer>,
    /// Formats of each layer (World Wind's tiles).
    pub formats: Vec<Format>,
    /// Entries written before this are remade.
    pub refresh_before: SystemTime,
    /// The store's locks this process holds, renewed while it makes their
    /// tiles (and their expiry).
    pub leases: &'a Leases,
    /// Retries of a failed tile.
    pub retries: u32,
    /// `[level][layer]`: a tile of the level is exactly its children decimated.
    pub from_children: Vec<Vec<bool>>,
    /// Counts.
    pub counters: &'a Counters,
    /// Said once, the first time a tile waits long for another's lock.
    pub wait_notice: &'a std::sync::Once,
}

/// Busy answers (~2 s of pauses) after which a wait for another's lock is
/// explained: a tile takes 5–50 ms, so a lock held this long is held by a
/// slow holder (a slow upstream: it renews the lock while it works) or left
/// by one that died on another machine (one that died on this one is taken
/// at once), which expires after the TTL.
const LONG_WAIT_PAUSES: u32 = 8;

impl Seeder<'_> {
    /// Seeds every layer of `tile`; `kids` are its children's halves (when
    /// all four were made here), `for_parent` whether to keep this tile's.
    /// Returns the halves and the layers that failed, with why.
    pub fn tile(&self, tile: TileId, kids: Option<&[Halves; 4]>, for_parent: bool) -> (Halves, Vec<(Entry, String)>) {
        let mut halves = Vec::with_capacity(self.layers.len());
        let mut failures = Vec::new();
        for i in 0..self.layers.len() {
            if !self.pyramid.serves_level(self.region, self.layers[i], tile.level) {
                halves.push(None);
                continue;
            }
            match self.layer(tile, i, kids) {
                Ok(samples) => {
                    let keep = for_parent && self.exact(tile.level.wrapping_sub(1), i);
                    halves.push(samples.filter(|_| keep).map(|s| decimate::half(&s)));
                }
                Err((why, formats)) => {
                    let entry = Entry { pyramid: self.pyramid, layer: self.layers[i], tile, formats };
                    self.counters.failed.fetch_add(entry.files(), Ordering::Relaxed);
                    failures.push((entry, why));
                    halves.push(None);
                }
            }
        }
        (halves, failures)
    }

    /// True if a tile of `level` is its children decimated for layer `i`.
    fn exact(&self, level: u32, i: usize) -> bool {
        self.from_children.get(level as usize).and_then(|l| l.get(i)).copied().unwrap_or(false)
    }

    /// Seeds one layer of a tile (World Wind's in every format); its
    /// samples if they were made, or why not and the formats left unmade
    /// (the one that failed and those after it).
    fn layer(
        &self,
        tile: TileId,
        i: usize,
        kids: Option<&[Halves; 4]>,
    ) -> Result<Option<LayerSamples>, (String, Vec<Format>)> {
        let layer = match (self.pyramid.product(self.layers[i], tile), self.layers[i]) {
            (Some(product), _) => return self.product(&product).map(|()| None).map_err(|why| (why, Vec::new())),
            (None, MapLayer::Data(layer)) => layer,
            (None, other) => return Err((format!("{} has no World Wind tiles to seed", other.name()), Vec::new())),
        };
        let product = |format| Product::Tile {
            layer: MapLayer::Data(layer),
            id: tile,
            halo: 0,
            encoding: Encoding::Data(format),
        };
        // Every format's grid is the tile's.
        if self.formats.first().is_some_and(|&f| product(f).off_data(self.region)) {
            self.formats.iter().for_each(|_| self.count(Made::OffData));
            return Ok(None);
        }
        let grid = self.region.tiles.tile_samples(tile, 0);
        let mut samples: Option<(Option<LayerSamples>, bool)> = None;
        for (k, &format) in self.formats.iter().enumerate() {
            let product = product(format);
            let key = product.key(&self.region.version).ok_or_else(|| "tiles have cache keys".to_string());
            let made = key.and_then(|key| {
                self.file(&key, || {
                    if samples.is_none() {
                        samples = Some(self.samples(tile, (i, layer), kids)?);
                    }
                    let (s, derived) = samples.as_ref().ok_or("samples were just made")?;
                    let c = products::encode_samples(
                        self.region,
                        &grid,
                        layer,
                        Encoding::Data(format),
                        s.as_ref(),
                        Stats::default(),
                    )
                    .map_err(|e| e.to_string())?;
                    Ok((c.bytes, c.uniform, *derived))
                })
            });
            self.count(made.map_err(|why| (why, self.formats[k..].to_vec()))?);
        }
        Ok(samples.and_then(|(s, _)| s))
    }

    /// Seeds a tile that is one product (a quadtree set's or Cesium's),
    /// computed as the server computes it.
    fn product(&self, product: &Product) -> Result<(), String> {
        if product.off_data(self.region) {
            self.count(Made::OffData);
            return Ok(());
        }
        let key = product.key(&self.region.version).ok_or("tiles have cache keys")?;
        let made = self.file(&key, || {
            let c = products::compute(self.region, product).map_err(|e| e.to_string())?;
            Ok((c.bytes, c.uniform, false))
        })?;
        self.count(made);
        Ok(())
    }

    fn count(&self, made: Made) {
        let counter = match made {
            Made::Computed => &self.counters.computed,
            Made::Derived => &self.counters.derived,
            Made::Existing => &self.counters.existing,
            Made::OffData => &self.counters.off_data,
        };
        counter.fetch_add(1, Ordering::Relaxed);
    }

    /// The samples of `layer` (the `i`th): assembled from the children if exact, else
    /// computed; the flag says they were assembled.
    fn samples(
        &self,
        tile: TileId,
        (i, layer): (usize, Layer),
        kids: Option<&[Halves; 4]>,
    ) -> Result<(Option<LayerSamples>, bool), String> {
        let quarters = kids.filter(|_| self.exact(tile.level, i)).and_then(|k| {
            let [a, b, c, d] = [&k[0][i], &k[1][i], &k[2][i], &k[3][i]];
            decimate::assemble([a.as_ref()?, b.as_ref()?, c.as_ref()?, d.as_ref()?])
        });
        if let Some(parent) = quarters {
            return Ok((Some(parent), true));
        }
        let grid = self.region.tiles.tile_samples(tile, 0);
        let (s, _) = products::samples(self.region, &grid, layer).map_err(|e| e.to_string())?;
        Ok((s, false))
    }

    /// Makes one tile file under `key` unless a usable one is there, with
    /// retries; `make` gives the bytes, whether they are uniform, and whether
    /// they were derived from children.
    fn file(&self, key: &str, mut make: impl FnMut() -> Result<(Vec<u8>, bool, bool), String>) -> Result<Made, String> {
        let usable = |s: &Stored| s.written >= self.refresh_before && !flight::expired(self.region.upstream_ttl, s);
        let (mut busy, mut failed) = (0, 0);
        loop {
            let claim = match flight::claim(self.store, key, &usable, self.leases.ttl()) {
                Ok(claim) => claim,
                // The cache unreadable for a moment (a Redis timeout): tried
                // again as a failed tile is.
                Err(_) if failed < self.retries => {
                    failed += 1;
                    std::thread::sleep(backoff(failed));
                    continue;
                }
                Err(e) => return Err(attempts_failed(failed + 1, &e)),
            };
            match claim {
                Claim::Ready(_) => return Ok(Made::Existing),
                Claim::Busy => {
                    if busy == LONG_WAIT_PAUSES {
                        self.explain_wait(key);
                    }
                    std::thread::sleep(flight::pause(busy));
                    busy += 1;
                }
                Claim::Compute { lock, .. } => {
                    let held = self.leases.hold(&lock);
                    let result = self.attempts(&lock, &mut make);
                    drop(held);
                    // A lock not released expires after the TTL; the tile is
                    // made (or failed) all the same.
                    let _ = self.store.unlock(&lock);
                    return result;
                }
            }
        }
    }

    fn explain_wait(&self, key: &str) {
        let ttl = self.leases.ttl().as_secs_f64();
        self.wait_notice.call_once(|| {
            crate::outputs::say(format_args!(
                "sylva seed: waiting for {key}, locked by another seeder or server: one computing it renews the lock while it works; one that died on another machine leaves it to expire {ttl:.1} s after its last renewal ([tile_cache] lock_ttl_s)"
            ));
        });
    }

    /// Up to `1 + retries` attempts, [`backoff`] apart, to make and store
    /// the file of `lock`'s key.
    fn attempts(
        &self,
        lock: &Lock,
        make: &mut impl FnMut() -> Result<(Vec<u8>, bool, bool), String>,
    ) -> Result<Made, String> {
        let mut last = String::new();
        for attempt in 0..=self.retries {
            if attempt > 0 {
                std::thread::sleep(backoff(attempt));
            }
            let saved = make().and_then(|(bytes, uniform, derived)| {
                flight::save(self.store, lock, &bytes, uniform).map_err(|e| e.to_string())?;
                self.counters.bytes.fetch_add(bytes.len() as u64, Ordering::Relaxed);
                Ok(if derived { Made::Derived } else { Made::Computed })
            });
            match saved {
                Ok(made) => return Ok(made),
                Err(e) => last = e,
            }
        }
        Err(attempts_failed(self.retries + 1, &last))
    }
}

/// Why a tile failed after `n` attempts, the last with `last`.
fn attempts_failed(n: u32, last: &dyn std::fmt::Display) -> String {
    match n {
        1 => format!("failed: {last}"),
        n => format!("{n} attempts failed; last: {last}"),
    }
}

/// The pause before the `attempt`-th retry: 100 ms, doubling.
fn backoff(attempt: u32) -> Duration {
    Duration::from_millis(100 << (attempt.max(1) - 1).min(6))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cache::dir::DirStore;
    use crate::cache::{CacheError, Lookup};
    use std::sync::atomic::AtomicU32;

    /// A directory cache whose first `failing` reads and every unlock fail,
    /// as a Redis server that timed out would.
    struct Flaky {
        dir: DirStore,
        failing: AtomicU32,
    }

    impl Flaky {
        fn error(&self) -> CacheError {
            CacheError::io("read the cache entry", "flaky".as_ref(), std::io::Error::other("timed out"))
        }
    }

    impl TileStore for Flaky {
        fn get(&self, key: &str) -> Result<Lookup, CacheError> {
            let left = self.failing.load(Ordering::SeqCst);
            if left > 0 {
                self.failing.store(left - 1, Ordering::SeqCst);
                return Err(self.error());
            }
            self.dir.get(key)
        }
        fn put(&self, lock: &Lock, payload: &[u8]) -> Result<(), CacheError> {
            self.dir.put(lock, payload)
        }
        fn put_shared(&self, lock: &Lock, blob: &str, payload: &[u8]) -> Result<(), CacheError> {
            self.dir.put_shared(lock, blob, payload)
        }
        fn try_lock(&self, key: &str, ttl: Duration) -> Result<Option<Lock>, CacheError> {
            self.dir.try_lock(key, ttl)
        }
        fn unlock(&self, _: &Lock) -> Result<(), CacheError> {
            Err(self.error())
        }
        fn renew(&self, lock: &Lock, ttl: Duration) -> Result<bool, CacheError> {
            self.dir.renew(lock, ttl)
        }
        fn mark_in_use(&self, version: &str) -> Result<(), CacheError> {
            self.dir.mark_in_use(version)
        }
        fn describe(&self) -> String {
            "flaky".into()
        }
    }

    #[test]
    fn cache_errors_are_retried_and_a_lock_left_does_not_fail_a_made_tile() {
        // Regression: a read that failed (a Redis timeout) failed the tile at
        // once, skipping --retries, and a tile stored but not unlocked was
        // counted failed.
        let region = crate::config::load(None).unwrap();
        let (counters, notice) = (Counters::default(), std::sync::Once::new());
        let root = std::env::temp_dir().join(format!("sylva-flaky-{}", std::process::id()));
        let store = std::sync::Arc::new(Flaky { dir: DirStore::new(&root), failing: AtomicU32::new(0) });
        let leases = Leases::start(store.clone(), Duration::from_secs(5));
        let seeder = |retries| Seeder {
            region: &region,
            pyramid: Pyramid::WorldWind(region.tiles),
            store: &*store,
            layers: vec![],
            formats: vec![],
            refresh_before: SystemTime::now(),
            leases: &leases,
            retries,
            from_children: vec![],
            counters: &counters,
            wait_notice: &notice,
        };
        let make = || Ok((b"tile".to_vec(), false, false));
        store.failing.store(2, Ordering::SeqCst);
        assert!(matches!(seeder(2).file("a", make), Ok(Made::Computed)));
        store.failing.store(2, Ordering::SeqCst);
        let err = seeder(1).file("b", make).err().unwrap();
        assert!(err.starts_with("2 attempts failed; last: cannot read the cache entry flaky: timed out"), "{err}");
        std::fs::remove_dir_all(&root).ok();
    }

    #[test]
    fn tiles_off_the_data_are_counted_and_not_stored() {
        // The demo lies at 10° E: World Wind's level-0 tile at -180° and
        // Cesium's western zoom-0 tile hold none of it; the server makes
        // such tiles at once and never reads them from the cache.
        let region = crate::config::load(None).unwrap();
        let (counters, notice) = (Counters::default(), std::sync::Once::new());
        let root = std::env::temp_dir().join(format!("sylva-off-data-{}", std::process::id()));
        let store = std::sync::Arc::new(DirStore::new(&root));
        let leases = Leases::start(store.clone(), Duration::from_secs(5));
        let seeder = |pyramid, formats| Seeder {
            region: &region,
            pyramid,
            store: &*store,
            layers: vec![MapLayer::Data(Layer::Cem)],
            formats,
            refresh_before: SystemTime::now(),
            leases: &leases,
            retries: 0,
            from_children: vec![],
            counters: &counters,
            wait_notice: &notice,
        };
        let far = TileId::new(0, 0, 0);
        let world_wind = seeder(Pyramid::WorldWind(region.tiles), vec![Format::Bil16, Format::Png16]);
        assert!(world_wind.tile(far, None, false).1.is_empty());
        assert!(seeder(Pyramid::Cesium, vec![]).tile(far, None, false).1.is_empty());
        let made = [&counters.computed, &counters.existing, &counters.failed].map(|c| c.load(Ordering::Relaxed));
        assert_eq!((counters.off_data.load(Ordering::Relaxed), made), (3, [0, 0, 0]));
        let keys = [
            Pyramid::Cesium.product(MapLayer::Data(Layer::Cem), far).unwrap(),
            Product::Tile {
                layer: MapLayer::Data(Layer::Cem),
                id: far,
                halo: 0,
                encoding: Encoding::Data(Format::Bil16),
            },
        ]
        .map(|p| p.key(&region.version).unwrap());
        assert!(keys.iter().all(|k| matches!(store.get(k), Ok(Lookup::Miss))), "{keys:?}");
        std::fs::remove_dir_all(&root).ok();
    }
}
