//! The client's CPU-side tile store: prepared tiles fetched from a tile
//! source, kept within a memory budget (least recently used out first),
//! with what is known of every tile ever seen ([`Known`]: the height range
//! for the quadtree's bounding boxes, the terrain mesh's error for the LOD
//! cost model) in a map the selection thread shares ([`Knowledge`]), and
//! tiles known to be empty so they are not asked again.
//!
//! Missing tiles of a frame are fetched and prepared in parallel on the
//! store's own thread pool, whose size bounds the requests in flight: while
//! the frame waits (`sylva fly`), or in the background (`sylva view`: a
//! frame never waits; a tile not here yet is drawn as its nearest loaded
//! ancestor, [`TileStore::get_cut`]; its ancestors load coarsest first, and
//! the coarse tiles over the region are loaded first and kept, so every
//! tile of the region has one).

use super::envelope::HeightEnvelope;
use super::source::{FetchError, TileSource};
use super::tile::{TileData, TileError, TilePayload};
use crate::grid::TileId;
use rayon::prelude::*;
use std::collections::{HashMap, HashSet};
use std::sync::mpsc::{Receiver, Sender, channel};
use std::sync::{Arc, PoisonError, RwLock};
use std::time::{Duration, Instant};

/// What a loaded tile told about itself.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Known {
    /// Lowest ground and highest CEM above the ellipsoid, metres.
    pub heights_m: (f64, f64),
    /// How far its terrain mesh departs from its ground, metres.
    pub mesh_error_m: f64,
    /// How far its flat frame misplaces it, metres.
    pub flat_error_m: f64,
}

/// A shared, growing map of what is known of tiles.
#[derive(Clone, Debug, Default)]
pub struct Knowledge {
    map: Arc<RwLock<HashMap<TileId, Known>>>,
}

impl Knowledge {
    /// The absolute height range of a tile, or of its nearest ancestor
    /// seen so far.
    pub fn range(&self, id: TileId) -> Option<(f64, f64)> {
        let map = self.map.read().unwrap_or_else(PoisonError::into_inner);
        let mut at = Some(id);
        while let Some(t) = at {
            if let Some(k) = map.get(&t) {
                return Some(k.heights_m);
            }
            at = t.parent();
        }
        None
    }

    /// What is known of the tile itself.
    pub fn get(&self, id: TileId) -> Option<Known> {
        self.map.read().unwrap_or_else(PoisonError::into_inner).get(&id).copied()
    }

    fn insert(&self, id: TileId, known: Known) {
        self.map.write().unwrap_or_else(PoisonError::into_inner).insert(id, known);
    }
}

/// Why a tile could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum LoadError {
    /// Fetching failed.
    #[error(transparent)]
    Fetch(#[from] FetchError),
    /// The payload was unusable.
    #[error(transparent)]
    Tile(#[from] TileError),
    /// No threads for fetching.
    #[error("cannot start the tile fetch threads: {0}")]
    Threads(#[from] rayon::ThreadPoolBuildError),
}

struct Entry {
    tile: Arc<TileData>,
    last_used: u64,
    bytes: usize,
}

/// A tile loaded on the store's threads: its id and what came of it.
type Loaded = (TileId, Result<Option<TileData>, LoadError>);

/// Loading in the background: the source, the tiles asked for and not yet
/// back, and the channel they come back on.
struct Background {
    source: Arc<dyn TileSource>,
    pending: HashSet<TileId>,
    /// Tiles whose load failed: when each may be asked again, and how
    /// often it failed in a row.
    failed: HashMap<TileId, (Instant, u32)>,
    failures: usize,
    sender: Sender<Loaded>,
    receiver: Receiver<Loaded>,
}

/// Seconds before a tile that failed to load is asked for again, doubling
/// with each failure in a row up to [`RETRY_MAX_S`].
const RETRY_S: f64 = 2.0;
/// The longest wait before a tile that keeps failing is asked for again.
const RETRY_MAX_S: f64 = 120.0;

/// How long a tile that failed `times` in a row waits to be asked again.
fn retry_after(times: u32) -> Duration {
    Duration::from_secs_f64((RETRY_S * 2f64.powi(times.saturating_sub(1).min(16) as i32)).min(RETRY_MAX_S))
}

/// Tiles asked for in the background and not yet back, at most: a camera
/// moving fast asks for more than the source can deliver, and what it
/// passed by need not load.
const PENDING_LIMIT: usize = 64;

/// Prepared tiles in memory.
pub struct TileStore {
    halo: usize,
    budget_bytes: usize,
    tiles: HashMap<TileId, Entry>,
    empty: HashSet<TileId>,
    /// Never evicted: the coarse tiles that stand in for any tile loading
    /// in the background.
    pinned: HashSet<TileId>,
    known: Knowledge,
    bytes: usize,
    clock: u64,
    pool: rayon::ThreadPool,
    background: Option<Background>,
    /// The heights of the coarse tiles, once held.
    envelope: Option<Arc<HeightEnvelope>>,
}

impl TileStore {
    /// A store of tiles with `halo`, holding at most about `budget_bytes`,
    /// loading at most `in_flight` tiles at once.
    pub fn new(halo: usize, budget_bytes: usize, in_flight: usize) -> Result<TileStore, LoadError> {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(in_flight.max(1))
            .thread_name(|k| format!("tile-fetch-{k}"))
            .build()?;
        Ok(TileStore {
            pool,
            halo,
            budget_bytes,
            tiles: HashMap::new(),
            empty: HashSet::new(),
            pinned: HashSet::new(),
            known: Knowledge::default(),
            bytes: 0,
            clock: 0,
            background: None,
            envelope: None,
        })
    }

    /// Loads and keeps the coarse tiles over `source`'s region
    /// ([`super::envelope::covering`]), once: some tile is held under every
    /// point of the region ([`Self::finest_at`]). Returns their heights,
    /// the envelope of every finer tile's.
    pub fn hold_coarse(&mut self, source: &dyn TileSource) -> Result<Arc<HeightEnvelope>, LoadError> {
        if let Some(envelope) = &self.envelope {
            return Ok(envelope.clone());
        }
        let (grid, halo) = (source.grid(), self.halo);
        let anchors = super::envelope::covering(&grid, &source.bounds());
        let fetched: Result<Vec<(TileId, Option<TilePayload>)>, FetchError> =
            self.pool.install(|| anchors.par_iter().map(|&id| Ok((id, source.fetch(id, halo)?))).collect());
        let payloads = fetched?;
        let envelope = Arc::new(HeightEnvelope::of(&grid, payloads.iter().filter_map(|p| p.1.as_ref())));
        for (id, payload) in payloads {
            self.keep(id, payload.map(|p| TileData::prepare(&grid, p)).transpose()?);
        }
        self.pinned.extend(anchors);
        self.envelope = Some(envelope.clone());
        Ok(envelope)
    }

    /// From now on loads tiles from `source` in the background, after
    /// holding the coarse tiles over its region ([`Self::hold_coarse`]):
    /// [`Self::get`] returns at once with the tiles here and asks for the
    /// rest.
    pub fn load_in_background(&mut self, source: Arc<dyn TileSource>) -> Result<(), LoadError> {
        self.hold_coarse(source.as_ref())?;
        let (sender, receiver) = channel();
        let (pending, failed) = (HashSet::new(), HashMap::new());
        self.background = Some(Background { source, pending, failed, failures: 0, sender, receiver });
        Ok(())
    }

    /// Tiles asked for in the background and not yet loaded.
    pub fn pending(&self) -> usize {
        self.background.as_ref().map_or(0, |b| b.pending.len())
    }

    /// Bytes held.
    pub fn bytes(&self) -> usize {
        self.bytes
    }

    /// The absolute height range of a tile, or of its nearest ancestor
    /// seen so far.
    pub fn range(&self, id: TileId) -> Option<(f64, f64)> {
        self.known.range(id)
    }

    /// The map of what is known of tiles, shared.
    pub fn knowledge(&self) -> Knowledge {
        self.known.clone()
    }

    /// Loads the tiles of `ids` that are not here (in parallel), then
    /// returns those with data, in the order asked. Loading in the
    /// background, returns those here and asks for the rest.
    pub fn get(&mut self, source: &dyn TileSource, ids: &[TileId]) -> Result<Vec<Arc<TileData>>, LoadError> {
        if self.background.is_some() {
            self.receive();
            let missing = self.missing(ids);
            self.ask(&missing);
        } else {
            let (missing, grid, halo) = (self.missing(ids), source.grid(), self.halo);
            let loaded: Vec<Loaded> =
                self.pool.install(|| missing.par_iter().map(|&id| (id, load(source, &grid, id, halo))).collect());
            // The tiles that came are kept, whatever failed beside them.
            let mut failed = None;
            for (id, tile) in loaded {
                match tile {
                    Ok(tile) => self.keep(id, tile),
                    Err(e) => failed = failed.or(Some(e)),
                }
            }
            if let Some(e) = failed {
                self.evict();
                return Err(e);
            }
        }
        let out = ids.iter().filter_map(|&id| self.touch(id)).collect();
        self.evict();
        Ok(out)
    }

    /// A frame's cut `ids`: the tiles here, and for each not here yet (while
    /// loading in the background) its nearest ancestor here instead — once,
    /// and without the tiles under it, so the tiles drawn still cover the
    /// view once. Tiles not used by this frame may be evicted.
    pub fn get_cut(&mut self, source: &dyn TileSource, ids: &[TileId]) -> Result<Vec<Arc<TileData>>, LoadError> {
        self.clock += 1;
        let here = self.get(source, ids)?;
        if here.len() == ids.len() || self.background.is_none() {
            return Ok(here);
        }
        let stand_ins: Vec<TileId> = self.missing(ids).into_iter().filter_map(|id| self.nearest_ancestor(id)).collect();
        let drawn = stand_in(&here.iter().map(|t| t.id()).collect::<Vec<_>>(), &stand_ins);
        Ok(drawn.into_iter().filter_map(|id| self.touch(id)).collect())
    }

    /// Tiles loading failures in the background so far.
    pub fn failures(&self) -> usize {
        self.background.as_ref().map_or(0, |b| b.failures)
    }

    /// The tiles of `ids` neither here nor known to be empty.
    fn missing(&self, ids: &[TileId]) -> Vec<TileId> {
        ids.iter().filter(|id| !self.tiles.contains_key(id) && !self.empty.contains(id)).copied().collect()
    }

    /// The finest tile held that contains the point `(lon, lat)`, degrees.
    pub fn finest_at(&self, grid: &crate::grid::TileGrid, lon: f64, lat: f64) -> Option<Arc<TileData>> {
        let deepest = self.tiles.keys().map(|id| id.level).max()?;
        (0..=deepest).rev().find_map(|level| Some(self.tiles.get(&grid.tile_containing(lon, lat, level))?.tile.clone()))
    }

    /// The nearest ancestor of `id` held here.
    fn nearest_ancestor(&self, id: TileId) -> Option<TileId> {
        std::iter::successors(id.parent(), TileId::parent).find(|a| self.tiles.contains_key(a))
    }

    /// The tile `id` if held, marked used this frame (loading nothing).
    pub fn touch(&mut self, id: TileId) -> Option<Arc<TileData>> {
        let e = self.tiles.get_mut(&id)?;
        e.last_used = self.clock;
        Some(e.tile.clone())
    }

    /// Keeps a loaded tile, or remembers that it has no data.
    fn keep(&mut self, id: TileId, tile: Option<TileData>) {
        match tile {
            Some(t) => self.insert(t),
            None => {
                self.empty.insert(id);
            }
        }
    }

    /// Keeps the tiles loaded in the background since the last frame. A
    /// tile that failed is asked again after [`retry_after`] (and counted).
    fn receive(&mut self) {
        let Some(b) = &mut self.background else { return };
        let done: Vec<Loaded> = b.receiver.try_iter().collect();
        let mut kept = Vec::with_capacity(done.len());
        for (id, result) in done {
            b.pending.remove(&id);
            match result {
                Ok(tile) => {
                    b.failed.remove(&id);
                    kept.push((id, tile));
                }
                Err(_) => {
                    let times = b.failed.get(&id).map_or(1, |&(_, times)| times + 1);
                    b.failed.insert(id, (Instant::now() + retry_after(times), times));
                    b.failures += 1;
                }
            }
        }
        for (id, tile) in kept {
            self.keep(id, tile);
        }
    }

    /// Asks for `missing` tiles in the background, coarsest first, each with
    /// the ancestors between it and the nearest one here (so a place shows
    /// finer tiles as they come, not the coarsest until all arrive), up to
    /// [`PENDING_LIMIT`] in all.
    fn ask(&mut self, missing: &[TileId]) {
        let mut wanted: Vec<TileId> = missing
            .iter()
            .flat_map(|&id| {
                let up = std::iter::successors(Some(id), TileId::parent);
                up.take_while(|a| !self.tiles.contains_key(a) && !self.empty.contains(a)).collect::<Vec<_>>()
            })
            .collect();
        wanted.sort_unstable();
        wanted.dedup();
        let Some(b) = &mut self.background else { return };
        for id in wanted {
            if b.pending.len() >= PENDING_LIMIT {
                break;
            }
            let failed_lately = b.failed.get(&id).is_some_and(|&(again, _)| Instant::now() < again);
            if !failed_lately && b.pending.insert(id) {
                let (source, sender, halo) = (b.source.clone(), b.sender.clone(), self.halo);
                self.pool.spawn(move || {
                    // The store may be gone: nobody waits for the tile then.
                    let _ = sender.send((id, load(source.as_ref(), &source.grid(), id, halo)));
                });
            }
        }
    }

    fn insert(&mut self, tile: TileData) {
        let known = Known {
            heights_m: tile.range.heights_m,
            mesh_error_m: f64::from(tile.range.mesh_error_m),
            flat_error_m: tile.flat_error_m(),
        };
        self.known.insert(tile.id(), known);
        let bytes = tile.cpu_bytes();
        self.bytes += bytes;
        if let Some(old) = self.tiles.insert(tile.id(), Entry { tile: Arc::new(tile), last_used: self.clock, bytes }) {
            self.bytes -= old.bytes;
        }
    }

    /// Drops least recently used tiles not used this frame until within
    /// budget, the pinned ones never.
    fn evict(&mut self) {
        while self.bytes > self.budget_bytes {
            let victim = self
                .tiles
                .iter()
                .filter(|(id, e)| e.last_used < self.clock && !self.pinned.contains(id))
                .min_by_key(|(_, e)| e.last_used)
                .map(|(id, _)| *id);
            let Some(id) = victim else { break };
            if let Some(e) = self.tiles.remove(&id) {
                self.bytes -= e.bytes;
            }
        }
    }
}

/// Fetches and prepares one tile.
fn load(
    source: &dyn TileSource,
    grid: &crate::grid::TileGrid,
    id: TileId,
    halo: usize,
) -> Result<Option<TileData>, LoadError> {
    Ok(source.fetch(id, halo)?.map(|p| TileData::prepare(grid, p)).transpose()?)
}

/// A cut's tiles with `stand_ins` (ancestors of tiles not here) added once,
/// and the tiles under any of them left out: each place is drawn once.
fn stand_in(here: &[TileId], stand_ins: &[TileId]) -> Vec<TileId> {
    let all: HashSet<TileId> = here.iter().chain(stand_ins).copied().collect();
    let covered = |id: &TileId| std::iter::successors(id.parent(), TileId::parent).any(|a| all.contains(&a));
    let mut drawn: Vec<TileId> = all.iter().filter(|id| !covered(id)).copied().collect();
    drawn.sort_unstable();
    drawn
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::client::source::RegionSource;

    #[test]
    fn stand_ins_replace_the_tiles_under_them_once() {
        let parent = TileId::new(11, 100, 200);
        let [a, b, c, _] = parent.children();
        let elsewhere = TileId::new(12, 0, 0);
        // Three children here, the fourth loading twice over (two of its
        // own children asked): the parent is drawn once, alone.
        let drawn = stand_in(&[a, b, c, elsewhere], &[parent, parent]);
        assert_eq!(drawn, vec![parent, elsewhere]);
        // Nothing loading: the cut as it is.
        assert_eq!(stand_in(&[a, b], &[]), vec![a, b]);
    }

    /// The demo region as a source whose tiles of `failing` never load,
    /// counting its fetches.
    struct Flaky {
        inner: RegionSource,
        failing: TileId,
        fetches: std::sync::atomic::AtomicUsize,
    }

    impl Flaky {
        fn new(region: &Arc<crate::region::Region>, failing: TileId) -> Flaky {
            Flaky { inner: RegionSource::new(region.clone()), failing, fetches: Default::default() }
        }

        fn fetches(&self) -> usize {
            self.fetches.load(std::sync::atomic::Ordering::SeqCst)
        }
    }

    impl TileSource for Flaky {
        fn grid(&self) -> crate::grid::TileGrid {
            self.inner.grid()
        }
        fn bounds(&self) -> crate::grid::BBox {
            self.inner.bounds()
        }
        fn fetch(&self, id: TileId, halo: usize) -> Result<Option<super::super::tile::TilePayload>, FetchError> {
            self.fetches.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
            if id == self.failing {
                return Err(FetchError::Http { id, url: "test".into(), reason: "refused".into() });
            }
            self.inner.fetch(id, halo)
        }
        fn bytes_fetched(&self) -> u64 {
            0
        }
        fn describe(&self) -> String {
            "a flaky demo".into()
        }
    }

    /// Calls `get_cut` until nothing is loading; the tiles drawn then.
    fn settle(store: &mut TileStore, source: &dyn TileSource, cut: &[TileId]) -> Vec<TileId> {
        let start = std::time::Instant::now();
        loop {
            let drawn: Vec<TileId> = store.get_cut(source, cut).unwrap().iter().map(|t| t.id()).collect();
            if store.pending() == 0 {
                return drawn;
            }
            assert!(start.elapsed().as_secs() < 120, "tiles still loading");
            std::thread::sleep(std::time::Duration::from_millis(20));
        }
    }

    #[test]
    fn the_coarse_tiles_are_fetched_once_and_bound_the_finer_ones() {
        let region = Arc::new(crate::config::load(None).unwrap());
        let source = Flaky::new(&region, TileId::new(30, 0, 0));
        let mut store = TileStore::new(4, usize::MAX, 2).unwrap();
        let envelope = store.hold_coarse(&source).unwrap();
        let anchors = crate::client::envelope::covering(&source.grid(), &source.bounds());
        store.hold_coarse(&source).unwrap();
        assert_eq!(source.fetches(), anchors.len());
        assert!(anchors.iter().all(|id| store.tiles.contains_key(id)));
        // Their halos cropped, the heights of the tiles fetched without.
        let plain = HeightEnvelope::fetch(&source.inner).unwrap();
        let b = region.bounds;
        for level in [6, 9, 12] {
            let sector = region.tiles.sector(region.tiles.tile_containing(b.west + 0.01, b.south + 0.01, level));
            assert_eq!(envelope.range(&sector), plain.range(&sector), "level {level}");
            assert!(envelope.range(&sector).is_some());
        }
    }

    #[test]
    fn a_failed_tile_loses_none_loaded_beside_it() {
        let region = Arc::new(crate::config::load(None).unwrap());
        let b = region.bounds;
        let fine = region.tiles.tile_containing(0.5 * (b.west + b.east), 0.5 * (b.south + b.north), 12);
        let [good, failing, ..] = fine.parent().unwrap().children();
        let source = Flaky::new(&region, failing);
        let mut store = TileStore::new(2, usize::MAX, 2).unwrap();
        assert!(store.get(&source, &[good, failing]).is_err());
        assert!(store.tiles.contains_key(&good), "regression: the batch's good tiles were dropped");
        assert_eq!(store.get(&source, &[good]).unwrap().len(), 1);
        assert_eq!(source.fetches(), 2, "the good tile is not fetched again");
    }

    #[test]
    fn a_background_store_answers_at_once_and_loads_for_later_frames() {
        let region = Arc::new(crate::config::load(None).unwrap());
        let b = region.bounds;
        let fine = region.tiles.tile_containing(0.5 * (b.west + b.east), 0.5 * (b.south + b.north), 12);
        let [a, _, c, d] = fine.parent().unwrap().children();
        let failing = fine.parent().unwrap().children()[1];
        let source: Arc<dyn TileSource> = Arc::new(Flaky::new(&region, failing));
        let mut store = TileStore::new(4, usize::MAX, 2).unwrap();
        store.load_in_background(source.clone()).unwrap();
        let anchors = crate::client::envelope::covering(&source.grid(), &source.bounds());
        let cut = [a, failing, c, d];
        let first: Vec<TileId> = store.get_cut(source.as_ref(), &cut).unwrap().iter().map(|t| t.id()).collect();
        assert_eq!(first.len(), 1);
        assert!(anchors.contains(&first[0]), "{first:?} stands in for {cut:?}");
        // The four, and their ancestors below the coarse tile, coarsest first.
        assert_eq!(store.pending(), 4 + (fine.level - first[0].level - 1) as usize);
        // Three arrive; the fourth failed, so its parent stands in for it
        // alone (with no tile under it drawn twice), and the failure is
        // counted instead of ending the frame.
        let drawn = settle(&mut store, source.as_ref(), &cut);
        assert_eq!(drawn, vec![fine.parent().unwrap()]);
        assert!(store.failures() >= 1);
        // Asked again later and later (regression: every 2 s for ever).
        let (again, times) = store.background.as_ref().unwrap().failed[&failing];
        assert!(times >= 1 && again > Instant::now(), "{times}");
        let waits: Vec<f64> = [1, 2, 3, 7, 8, u32::MAX].map(|n| retry_after(n).as_secs_f64()).to_vec();
        assert_eq!(waits, [2.0, 4.0, 8.0, 120.0, 120.0, 120.0]);
        // A budget below one tile: evicted to it, but for the coarse tiles.
        store.budget_bytes = 1;
        store.get_cut(source.as_ref(), &anchors[..1]).unwrap();
        assert_eq!(store.tiles.len(), anchors.len());
    }
}
