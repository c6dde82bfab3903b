//! The client's CPU-side tile store: prepared tiles fetched from a tile
//! source, kept within a memory budget (least recently used out first),
//! with what is known of every tile ever seen ([`Known`]: the height range
//! for the quadtree's bounding boxes, the terrain mesh's error for the LOD
//! cost model) in a map the selection thread shares ([`Knowledge`]), and
//! tiles known to be empty so they are not asked again.
//!
//! Missing tiles of a frame are fetched and prepared in parallel on the
//! store's own thread pool, whose size bounds the requests in flight.

use super::source::{FetchError, TileSource};
use super::tile::{TileData, TileError};
use crate::grid::TileId;
use rayon::prelude::*;
use std::collections::{HashMap, HashSet};
use std::sync::{Arc, PoisonError, RwLock};

/// What a loaded tile told about itself.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Known {
    /// Lowest ground and highest CEM above the ellipsoid, metres.
    pub heights_m: (f64, f64),
    /// How far its terrain mesh departs from its ground, metres.
    pub mesh_error_m: f64,
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

/// Prepared tiles in memory.
pub struct TileStore {
    halo: usize,
    budget_bytes: usize,
    tiles: HashMap<TileId, Entry>,
    empty: HashSet<TileId>,
    known: Knowledge,
    bytes: usize,
    clock: u64,
    pool: rayon::ThreadPool,
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
            known: Knowledge::default(),
            bytes: 0,
            clock: 0,
        })
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
    /// returns those with data, in the order asked.
    pub fn get(&mut self, source: &dyn TileSource, ids: &[TileId]) -> Result<Vec<Arc<TileData>>, LoadError> {
        self.clock += 1;
        let missing: Vec<TileId> =
            ids.iter().filter(|id| !self.tiles.contains_key(id) && !self.empty.contains(id)).copied().collect();
        let grid = source.grid();
        let halo = self.halo;
        let loaded: Vec<(TileId, Option<TileData>)> = self.pool.install(|| {
            missing
                .par_iter()
                .map(|&id| -> Result<_, LoadError> {
                    let tile = source.fetch(id, halo)?.map(|p| TileData::prepare(&grid, p)).transpose()?;
                    Ok((id, tile))
                })
                .collect::<Result<_, _>>()
        })?;
        for (id, tile) in loaded {
            match tile {
                Some(t) => self.insert(t),
                None => {
                    self.empty.insert(id);
                }
            }
        }
        let clock = self.clock;
        let out = ids
            .iter()
            .filter_map(|id| {
                let e = self.tiles.get_mut(id)?;
                e.last_used = clock;
                Some(e.tile.clone())
            })
            .collect();
        self.evict();
        Ok(out)
    }

    fn insert(&mut self, tile: TileData) {
        let known = Known { heights_m: tile.range.heights_m, mesh_error_m: f64::from(tile.range.mesh_error_m) };
        self.known.insert(tile.id(), known);
        let bytes = tile.gpu_bytes() + tile.hull.vertices.len() * 20 + tile.hull.indices.len() * 4;
        self.bytes += bytes;
        self.tiles.insert(tile.id(), Entry { tile: Arc::new(tile), last_used: self.clock, bytes });
    }

    /// Drops least recently used tiles not used this frame until within budget.
    fn evict(&mut self) {
        while self.bytes > self.budget_bytes {
            let victim = self
                .tiles
                .iter()
                .filter(|(_, e)| e.last_used < self.clock)
                .min_by_key(|(_, e)| e.last_used)
                .map(|(id, _)| *id);
            let Some(id) = victim else { break };
            if let Some(e) = self.tiles.remove(&id) {
                self.bytes -= e.bytes;
            }
        }
    }
}
