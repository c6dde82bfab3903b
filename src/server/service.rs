//! The tile service: memory cache over the shared tile cache (directory or
//! Redis) over the pipeline, with one computation per tile however many
//! requests ask for it at once — the memory cache coalesces concurrent loads
//! of a key in this process, the cache's locks ([`crate::cache::flight`])
//! across processes — and the pipeline run on the bounded worker pool, never
//! on the async executor. A load runs as its own task: a requester that gives
//! up (request timeout, closed connection) does not abandon it, so the tile
//! lands in the cache for the retry instead of being computed again.

use super::ServeError;
use super::metrics::{CacheResult, Metrics};
use super::pool::Pool;
use super::products::{self, Computed, Product};
use crate::cache::flight::{self, Claim};
use crate::cache::lease::Leases;
use crate::cache::{Lock, Lookup, TileStore};
use crate::cem::Stage;
use crate::region::Region;
use bytes::Bytes;
use moka::future::Cache;
use std::sync::Arc;
use std::time::Duration;

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
        // Weak: one tile is served as it is and gzipped, two representations
        // of the same content (RFC 9110 §8.8.1).
        let etag = format!("W/\"{:08x}{:08x}\"", crc32fast::hash(&bytes), bytes.len() as u32);
        Tile { bytes: Bytes::from(bytes), etag, timing, stale: false }
    }
}

/// Tiles for one region. Clones share everything (the memory cache too).
#[derive(Clone)]
pub struct TileService {
    region: Arc<Region>,
    store: Arc<dyn TileStore>,
    leases: Arc<Leases>,
    memory: Cache<String, Arc<Tile>>,
    pool: Arc<Pool>,
    metrics: Arc<Metrics>,
}

impl TileService {
    /// A service over `store` (whose tile locks expire after `lock_ttl`,
    /// renewed while this process computes their tiles), keeping up to
    /// `memory_bytes` of tiles in memory.
    pub fn new(
        region: Arc<Region>,
        store: Arc<dyn TileStore>,
        lock_ttl: Duration,
        memory_bytes: u64,
        pool: Arc<Pool>,
        metrics: Arc<Metrics>,
    ) -> TileService {
        let builder = Cache::builder()
            .weigher(|k: &String, v: &Arc<Tile>| (k.len() + v.bytes.len() + 128).try_into().unwrap_or(u32::MAX))
            .max_capacity(memory_bytes);
        // Tiles made from an upstream's data expire, in memory as on disk;
        // a stale one soon, so the upstream is asked again once it is back.
        let memory = builder.expire_after(Expiry { ttl: region.upstream_ttl }).build();
        let leases = Arc::new(Leases::start(store.clone(), lock_ttl));
        TileService { region, store, leases, memory, pool, metrics }
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

    /// The product, from memory, disk, or computed (and then stored; an
    /// image in memory only, where it fits).
    pub async fn get(&self, product: Product) -> Result<Arc<Tile>, ServeError> {
        let version = &self.region.version;
        let (key, stored) = (product.memory_key(version), product.key(version));
        let this = self.clone();
        // In a task of its own, which the request's timeout does not cancel:
        // requests for the same product meanwhile wait for it (an image has
        // no lock in the shared cache to meet them there).
        let task = tokio::spawn(async move {
            let load = async {
                let off_data = product.off_data(&this.region);
                let tile = match stored.filter(|_| !off_data) {
                    Some(stored) => this.load(stored, product).await?,
                    None => Arc::new(this.compute(product).await?.tile),
                };
                Ok::<_, ServeError>(tile)
            };
            let entry = this.memory.entry(key).or_try_insert_with(load).await.map_err(|e| (*e).clone())?;
            if !entry.is_fresh() {
                this.metrics.cache(CacheResult::Memory);
            }
            Ok(entry.into_value())
        });
        task.await.map_err(ServeError::internal)?
    }

    /// The tile from the shared cache, or computed here if no other process
    /// is computing it (else waited for).
    async fn load(&self, key: String, product: Product) -> Result<Arc<Tile>, ServeError> {
        let mut attempt = 0;
        loop {
            let (store, k, ttl, upstream_ttl) =
                (self.store.clone(), key.clone(), self.leases.ttl(), self.region.upstream_ttl);
            let claimed = tokio::task::spawn_blocking(move || {
                flight::claim(&*store, &k, &|s| !flight::expired(upstream_ttl, s), ttl)
            })
            .await
            .map_err(ServeError::internal)?;
            let claim = match claimed {
                Ok(claim) => claim,
                // The cache is down (a Redis gone, a disk failing): the
                // tile is computed here and served, not refused.
                Err(e) => {
                    tracing::warn!(error = %e, "tile cache unreadable; computing the tile without it");
                    self.metrics.cache(CacheResult::Unavailable);
                    return Ok(Arc::new(self.compute(product).await?.tile));
                }
            };
            match claim {
                Claim::Ready(stored) => {
                    self.metrics.cache(CacheResult::Hit);
                    return Ok(Arc::new(Tile::new(stored.bytes, "cache;desc=\"disk\"".into())));
                }
                Claim::Busy => {
                    tokio::time::sleep(flight::pause(attempt)).await;
                    attempt += 1;
                }
                Claim::Compute { lock, found } => {
                    let held = self.leases.hold(&lock);
                    let result = self.fill(&lock, product, found).await;
                    drop(held);
                    let store = self.store.clone();
                    let unlocked = tokio::task::spawn_blocking(move || store.unlock(&lock).map_err(|e| e.to_string()))
                        .await
                        .map_err(|e| e.to_string())
                        .and_then(|r| r);
                    if let Err(e) = unlocked {
                        tracing::warn!(error = %e, "tile lock not released; it expires");
                    }
                    return result;
                }
            }
        }
    }

    /// Computes and stores the tile of `lock`, which this process holds;
    /// `found` is what the cache held (served, stale, if the upstream fails).
    async fn fill(&self, lock: &Lock, product: Product, found: Lookup) -> Result<Arc<Tile>, ServeError> {
        let stale = match found {
            Lookup::Hit(stored) => Some(stored),
            Lookup::Corrupt => {
                self.metrics.cache(CacheResult::Corrupt);
                None
            }
            Lookup::Miss => {
                self.metrics.cache(CacheResult::Miss);
                None
            }
        };
        let made = match (self.compute(product).await, stale) {
            (Ok(made), _) => made,
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
        // Made of stale source data: served, with its warning, not stored.
        let tile = Arc::new(made.tile);
        if tile.stale {
            return Ok(tile);
        }
        let (store, lock, bytes, uniform) = (self.store.clone(), lock.clone(), tile.bytes.clone(), made.uniform);
        let written = tokio::task::spawn_blocking(move || flight::save(&*store, &lock, &bytes, uniform))
            .await
            .map_err(ServeError::internal)?;
        if let Err(e) = written {
            tracing::warn!(error = %e, "tile cache write failed; serving the computed tile anyway");
        }
        Ok(tile)
    }

    /// Computes the product on the pool. It is stale where the sources
    /// read expired blocks meanwhile (an upstream failing; another
    /// computation may have read them: stale errs on the safe side).
    async fn compute(&self, product: Product) -> Result<Made, ServeError> {
        let stale_reads = self.region.cache.stale_reads();
        let computed = self.run(move |region| products::compute(region, &product)).await?;
        self.metrics.computed(&computed.stats, computed.encode);
        let uniform = computed.uniform;
        let mut tile = tile_of(computed);
        tile.stale = self.region.cache.stale_reads() != stale_reads;
        Ok(Made { tile, uniform })
    }

    /// Runs `job` over the region on the compute pool (503 when it is
    /// full): work that is not a cached product, such as a GetFeatureInfo.
    pub async fn run<T: Send + 'static, E: Into<ServeError> + Send + 'static>(
        &self,
        job: impl FnOnce(&Region) -> Result<T, E> + Send + 'static,
    ) -> Result<T, ServeError> {
        let region = self.region.clone();
        self.pool.run(move || job(&region)).await?.map_err(Into::into)
    }
}

/// A product computed, as a tile, and whether its samples are all alike.
struct Made {
    tile: Tile,
    uniform: bool,
}

/// How long a tile stays in memory: a tile made from an upstream's data
/// for the upstream's time to live, a stale one for [`STALE_RETRY`] at most.
struct Expiry {
    ttl: Option<Duration>,
}

/// How long a stale tile is served from memory before the upstream is
/// asked again.
const STALE_RETRY: Duration = Duration::from_secs(5);

impl moka::Expiry<String, Arc<Tile>> for Expiry {
    fn expire_after_create(&self, _: &String, tile: &Arc<Tile>, _: std::time::Instant) -> Option<Duration> {
        match tile.stale {
            true => Some(self.ttl.map_or(STALE_RETRY, |ttl| ttl.min(STALE_RETRY))),
            false => self.ttl,
        }
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

#[cfg(test)]
mod tests {
    use super::*;
    use moka::Expiry as _;

    #[test]
    fn a_stale_tile_leaves_memory_soon_a_fresh_one_with_its_upstream() {
        // Regression: a stale tile was kept for the upstream's whole time to
        // live (an hour by default) after the upstream was back.
        let now = std::time::Instant::now();
        let fresh = Arc::new(Tile::new(vec![1], String::new()));
        let stale = Arc::new(Tile { stale: true, ..Tile::new(vec![1], String::new()) });
        let key = String::new();
        let hour = Expiry { ttl: Some(Duration::from_secs(3600)) };
        assert_eq!(hour.expire_after_create(&key, &fresh, now), Some(Duration::from_secs(3600)));
        assert_eq!(hour.expire_after_create(&key, &stale, now), Some(STALE_RETRY));
        let second = Expiry { ttl: Some(Duration::from_secs(1)) };
        assert_eq!(second.expire_after_create(&key, &stale, now), Some(Duration::from_secs(1)));
        let files = Expiry { ttl: None };
        assert_eq!(files.expire_after_create(&key, &fresh, now), None, "no upstream: kept until evicted");
    }
}
