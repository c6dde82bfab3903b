//! Upstream sources in the configuration: another server to read a DEM or
//! a map from (see [`crate::source::remote`]).

use crate::grid::BBox;
use serde::{Deserialize, Serialize};

/// An upstream service and how to talk to it.
#[derive(Clone, Debug, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct UpstreamConfig {
    /// `terrarium`: an XYZ URL template with `{z}`, `{x}`, `{y}`; `wms`: a
    /// GetMap URL with every parameter but `BBOX`, `WIDTH` and `HEIGHT`
    /// (`CRS=CRS:84`, a `FORMAT` of `application/bil32` or `image/png`).
    pub service: UpstreamService,
    /// The URL or template.
    pub url: String,
    /// Terrarium: the zoom read at full resolution.
    #[serde(default = "default_zoom")]
    pub zoom: u32,
    /// WMS: pixel size read at full resolution, degrees.
    #[serde(default = "default_resolution")]
    pub resolution_deg: f64,
    /// The area the upstream has data for, `[W, S, E, N]` degrees.
    pub bounds: [f64; 4],
    /// Time limit of one HTTP request, milliseconds.
    #[serde(default = "default_timeout")]
    pub timeout_ms: u64,
    /// Retries after a failed request.
    #[serde(default = "default_retries")]
    pub retries: u32,
    /// Wait before the first retry, doubling each time, milliseconds.
    #[serde(default = "default_backoff")]
    pub backoff_ms: u64,
    /// Consecutive failures that open the circuit breaker.
    #[serde(default = "default_breaker")]
    pub breaker_failures: u32,
    /// How long the open breaker fails requests at once, seconds.
    #[serde(default = "default_cooldown")]
    pub breaker_cooldown_s: f64,
    /// Tiles made from this upstream are recomputed after this many seconds;
    /// while the upstream fails, the stale tile is served.
    #[serde(default = "default_ttl")]
    pub ttl_s: u64,
}

fn default_zoom() -> u32 {
    12
}
fn default_resolution() -> f64 {
    1.0 / 3600.0
}
fn default_timeout() -> u64 {
    3000
}
fn default_retries() -> u32 {
    2
}
fn default_backoff() -> u64 {
    100
}
fn default_breaker() -> u32 {
    5
}
fn default_cooldown() -> f64 {
    10.0
}
fn default_ttl() -> u64 {
    3600
}

/// Kinds of upstream service.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum UpstreamService {
    /// XYZ tiles, Terrarium-encoded heights.
    Terrarium,
    /// OGC WMS GetMap.
    Wms,
}

impl UpstreamConfig {
    /// The area with data.
    pub fn bbox(&self) -> Result<BBox, String> {
        let [west, south, east, north] = self.bounds;
        BBox { west, south, east, north }.checked().map_err(|e| e.to_string())
    }
}
