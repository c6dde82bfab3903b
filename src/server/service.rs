//! The tile service: memory cache over the directory cache over the
//! pipeline, with one computation per tile however many requests ask for it
//! at once (the memory cache coalesces concurrent loads of a key), and the
//! pipeline run on the bounded worker pool, never on the async executor.

use super::ServeError;
use super::metrics::{CacheResult, Metrics};
use super::pool::Pool;
use super::products::{self, Computed, Product};
use crate::cache::{DirStore, Lookup};
use crate::cem::Stage;
use crate::region::Region;
use bytes::Bytes;
use moka::future::Cache;
use std::sync::Arc;

/// An encoded product ready to send.
#[derive(Debug)]
pub struct Tile {
    /// The bytes; empty for "no data here" (answered 404).
    pub bytes: Bytes,
    /// Strong entity tag: the CRC-32 and length of the bytes (a tag only
    /// tells versions of one URL apart; CRC-32 runs at memory speed).
    pub etag: String,
    /// `Server-Timing` value of the computation (or of the disk read).
    pub timing: String,
    /// Past its time to live: served because the upstream failed.
    pub stale: bool,
}

impl Tile {
    /// A tile of `bytes`, described by `timing` in `Server-Timing`.
    pub fn new(bytes: Vec<u8>, timing: String) -> Tile {
        let etag = format!("\"{:08x}{:08x}\"", crc32fast::hash(&bytes), bytes.len() as u32);
        Tile { bytes: Bytes::from(bytes), etag, timing, stale: false }
    }
}

/// Tiles for one region.
pub struct TileService {
    region: Arc<Region>,
    store: Arc<DirStore>,
    memory: Cache<String, Arc<Tile>>,
    pool: Arc<Pool>,
    metrics: Arc<Metrics>,
}

impl TileService {
    /// A service over `store`, keeping up to `memory_bytes` of tiles in memory.
    pub fn new(
        region: Arc<Region>,
        store: Arc<DirStore>,
        memory_bytes: u64,
        pool: Arc<Pool>,
        metrics: Arc<Metrics>,
    ) -> TileService {
        let builder = Cache::builder()
            .weigher(|k: &String, v: &Arc<Tile>| (k.len() + v.bytes.len() + 128).try_into().unwrap_or(u32::MAX))
            .max_capacity(memory_bytes);
        // Tiles made from an upstream's data expire, in memory as on disk.
        let memory = match region.upstream_ttl {
            Some(ttl) => builder.time_to_live(ttl).build(),
            None => builder.build(),
        };
        TileService { region, store, memory, pool, metrics }
    }

    /// Bytes of tiles held in memory (after pending evictions).
    pub async fn memory_bytes(&self) -> u64 {
        self.memory.run_pending_tasks().await;
        self.memory.weighted_size()
    }

    /// The region served.
    pub fn region(&self) -> &Arc<Region> {
        &self.region
    }

    /// The product, from memory, disk, or computed (and then stored).
    pub async fn get(&self, product: Product) -> Result<Arc<Tile>, ServeError> {
        let Some(key) = product.key(&self.region.version) else {
            return self.compute(product).await.map(|c| Arc::new(tile_of(c)));
        };
        let entry = self
            .memory
            .entry(key.clone())
            .or_try_insert_with(self.load(key, product))
            .await
            .map_err(|e| (*e).clone())?;
        if !entry.is_fresh() {
            self.metrics.cache(CacheResult::Memory);
        }
        Ok(entry.into_value())
    }

    async fn load(&self, key: String, product: Product) -> Result<Arc<Tile>, ServeError> {
        let store = self.store.clone();
        let k = key.clone();
        let found = tokio::task::spawn_blocking(move || store.get(&k)).await.map_err(ServeError::internal)?;
        let mut stale = None;
        match found.map_err(ServeError::internal)? {
            Lookup::Hit(stored) if !self.expired(stored.written) => {
                self.metrics.cache(CacheResult::Hit);
                return Ok(Arc::new(Tile::new(stored.bytes, "cache;desc=\"disk\"".into())));
            }
            Lookup::Hit(stored) => stale = Some(stored),
            Lookup::Corrupt => self.metrics.cache(CacheResult::Corrupt),
            Lookup::Miss => self.metrics.cache(CacheResult::Miss),
        }
        let computed = match (self.compute(product).await, stale) {
            (Ok(c), _) => c,
            // The upstream failed: the stale tile is better than none.
            (Err(ServeError::Upstream(why)), Some(old)) => {
                self.metrics.cache(CacheResult::Stale);
                tracing::warn!(error = %why, "upstream failed; serving a stale tile");
                let mut tile = Tile::new(old.bytes, "cache;desc=\"stale\"".into());
                tile.stale = true;
                return Ok(Arc::new(tile));
            }
            (Err(e), _) => return Err(e),
        };
        let tile = Arc::new(tile_of(computed));
        let store = self.store.clone();
        let bytes = tile.bytes.clone();
        let written =
            tokio::task::spawn_blocking(move || store.put(&key, &bytes)).await.map_err(ServeError::internal)?;
        if let Err(e) = written {
            tracing::warn!(error = %e, "tile cache write failed; serving the computed tile anyway");
        }
        Ok(tile)
    }

    /// True if a tile written at `written` is past the region's time to live.
    fn expired(&self, written: std::time::SystemTime) -> bool {
        self.region.upstream_ttl.is_some_and(|ttl| written.elapsed().is_ok_and(|age| age > ttl))
    }

    async fn compute(&self, product: Product) -> Result<Computed, ServeError> {
        let region = self.region.clone();
        let computed = self.pool.run(move || products::compute(&region, &product)).await??;
        self.metrics.computed(&computed.stats, computed.encode);
        Ok(computed)
    }
}

fn tile_of(c: Computed) -> Tile {
    let mut parts: Vec<String> = Stage::ALL
        .iter()
        .filter(|&&s| c.stats.runs(s) > 0)
        .map(|&s| format!("{};dur={:.2}", s.name(), c.stats.elapsed(s).as_secs_f64() * 1e3))
        .collect();
    parts.push(format!("encode;dur={:.2}", c.encode.as_secs_f64() * 1e3));
    Tile::new(c.bytes, parts.join(", "))
}
