//! Prometheus metrics at `/metrics`: requests and their latency by route and
//! status, tile cache hits and misses, tile computations, the time spent
//! in each pipeline stage, and the tile cache's trims to its bound.

use crate::cem::{Stage, Stats};
use prometheus_client::encoding::EncodeLabelSet;
use prometheus_client::metrics::counter::Counter;
use prometheus_client::metrics::family::Family;
use prometheus_client::metrics::gauge::Gauge;
use prometheus_client::metrics::histogram::{Histogram, exponential_buckets};
use prometheus_client::registry::Registry;
use std::sync::atomic::AtomicU64;
use std::time::Duration;

#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
struct RequestLabels {
    route: &'static str,
    status: u16,
}

#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
struct RouteLabel {
    route: &'static str,
}

#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
struct ResultLabel {
    result: &'static str,
}

#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
struct StageLabel {
    stage: &'static str,
}

/// What a tile lookup found.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CacheResult {
    /// In memory.
    Memory,
    /// On disk.
    Hit,
    /// Nowhere: computed.
    Miss,
    /// On disk but damaged: recomputed.
    Corrupt,
    /// Expired (upstream-fed tiles): recomputed, or served stale.
    Stale,
    /// The tile cache failed: computed and served without it.
    Unavailable,
}

/// The server's metrics.
pub struct Metrics {
    registry: Registry,
    requests: Family<RequestLabels, Counter>,
    latency: Family<RouteLabel, Histogram>,
    cache: Family<ResultLabel, Counter>,
    computations: Counter,
    stage_seconds: Family<StageLabel, Counter<f64, AtomicU64>>,
    trimmed_tiles: Counter,
    trimmed_bytes: Counter,
    cache_bytes: Gauge,
}

impl Metrics {
    /// Registers every metric.
    pub fn new() -> Metrics {
        let mut registry = Registry::with_prefix("sylva");
        let requests = Family::<RequestLabels, Counter>::default();
        // 0.5 ms to 16 s, doubling.
        let latency = Family::<RouteLabel, Histogram>::new_with_constructor(|| {
            Histogram::new(exponential_buckets(0.0005, 2.0, 16))
        });
        let cache = Family::<ResultLabel, Counter>::default();
        let computations = Counter::default();
        let stage_seconds = Family::<StageLabel, Counter<f64, AtomicU64>>::default();
        registry.register("http_requests", "HTTP requests by route and status", requests.clone());
        registry.register("http_request_duration_seconds", "Request latency by route", latency.clone());
        registry.register("tile_cache", "Tile cache lookups by result", cache.clone());
        registry.register(
            "tile_computations",
            "Tiles computed (cache misses that ran the pipeline)",
            computations.clone(),
        );
        registry.register("stage_seconds", "Time spent in each pipeline stage and in encoding", stage_seconds.clone());
        let (trimmed_tiles, trimmed_bytes, cache_bytes) = (Counter::default(), Counter::default(), Gauge::default());
        registry.register(
            "tile_cache_trimmed_tiles",
            "Tiles and shared entries this server's trims removed ([tile_cache] max_size)",
            trimmed_tiles.clone(),
        );
        registry.register("tile_cache_trimmed_bytes", "Bytes this server's trims removed", trimmed_bytes.clone());
        registry.register(
            "tile_cache_bytes",
            "Bytes of the tile cache after the last trim this server ran",
            cache_bytes.clone(),
        );
        Metrics {
            registry,
            requests,
            latency,
            cache,
            computations,
            stage_seconds,
            trimmed_tiles,
            trimmed_bytes,
            cache_bytes,
        }
    }

    /// Counts a finished request.
    pub fn request(&self, route: &'static str, status: u16, elapsed: Duration) {
        self.requests.get_or_create(&RequestLabels { route, status }).inc();
        self.latency.get_or_create(&RouteLabel { route }).observe(elapsed.as_secs_f64());
    }

    /// Counts a cache lookup.
    pub fn cache(&self, result: CacheResult) {
        let result = match result {
            CacheResult::Memory => "memory",
            CacheResult::Hit => "hit",
            CacheResult::Miss => "miss",
            CacheResult::Corrupt => "corrupt",
            CacheResult::Stale => "stale",
            CacheResult::Unavailable => "unavailable",
        };
        self.cache.get_or_create(&ResultLabel { result }).inc();
    }

    /// Counts a computation and its stage times.
    pub fn computed(&self, stats: &Stats, encode: Duration) {
        self.computations.inc();
        for stage in Stage::ALL {
            self.stage_seconds
                .get_or_create(&StageLabel { stage: stage.name() })
                .inc_by(stats.elapsed(stage).as_secs_f64());
        }
        self.stage_seconds.get_or_create(&StageLabel { stage: "encode" }).inc_by(encode.as_secs_f64());
    }

    /// Counts a trim of the tile cache.
    pub fn trimmed(&self, pruned: &crate::cache::prune::Pruned) {
        self.trimmed_tiles.inc_by(pruned.trimmed.0);
        self.trimmed_bytes.inc_by(pruned.trimmed.1);
        self.cache_bytes.set(i64::try_from(pruned.bytes_after).unwrap_or(i64::MAX));
    }

    /// Tiles computed so far.
    pub fn computations(&self) -> u64 {
        self.computations.get()
    }

    /// The text exposition format.
    pub fn render(&self) -> String {
        let mut out = String::new();
        // Writing into a String cannot fail.
        let _ = prometheus_client::encoding::text::encode(&mut out, &self.registry);
        out
    }
}

impl Default for Metrics {
    fn default() -> Self {
        Metrics::new()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_exposition_names_every_metric() {
        let m = Metrics::new();
        m.request("wms", 200, Duration::from_millis(3));
        m.cache(CacheResult::Miss);
        m.computed(&Stats::default(), Duration::from_millis(1));
        let text = m.render();
        for name in [
            "sylva_http_requests_total",
            "sylva_http_request_duration_seconds_bucket",
            "sylva_tile_cache_total",
            "sylva_tile_computations_total",
            "sylva_stage_seconds_total",
            "sylva_tile_cache_trimmed_tiles_total",
            "sylva_tile_cache_bytes",
        ] {
            assert!(text.contains(name), "{name} missing from\n{text}");
        }
        assert_eq!(m.computations(), 1);
    }
}
