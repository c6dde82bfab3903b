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

/// Longest `timeout_ms` and `backoff_ms`: ten minutes.
const MAX_WAIT_MS: u64 = 600_000;
/// Most `retries`.
const MAX_RETRIES: u32 = 10;
/// Longest `breaker_cooldown_s` and `ttl_s`: a day and a year.
const MAX_COOLDOWN_S: f64 = 86_400.0;
const MAX_TTL_S: u64 = 365 * 86_400;

impl UpstreamConfig {
    /// The area with data.
    pub fn bbox(&self) -> Result<BBox, String> {
        let [west, south, east, north] = self.bounds;
        BBox { west, south, east, north }.checked().map_err(|e| e.to_string())
    }

    /// Checks the timing settings, naming the first one out of bounds.
    pub fn check(&self) -> Result<(), String> {
        let out = |key: &str, value: String, range: String| Err(format!("{key} = {value}: must be {range}"));
        if !(1..=MAX_WAIT_MS).contains(&self.timeout_ms) {
            return out("timeout_ms", self.timeout_ms.to_string(), format!("1 to {MAX_WAIT_MS}"));
        }
        if self.backoff_ms > MAX_WAIT_MS {
            return out("backoff_ms", self.backoff_ms.to_string(), format!("0 to {MAX_WAIT_MS}"));
        }
        if self.retries > MAX_RETRIES {
            return out("retries", self.retries.to_string(), format!("0 to {MAX_RETRIES}"));
        }
        if !(0.0..=MAX_COOLDOWN_S).contains(&self.breaker_cooldown_s) {
            return out("breaker_cooldown_s", self.breaker_cooldown_s.to_string(), format!("0 to {MAX_COOLDOWN_S}"));
        }
        if self.ttl_s > MAX_TTL_S {
            return out("ttl_s", self.ttl_s.to_string(), format!("0 to {MAX_TTL_S} (a year)"));
        }
        Ok(())
    }

    /// The longest one block's read may take: every attempt timing out,
    /// with the backoffs between them.
    pub fn longest_read(&self) -> std::time::Duration {
        let attempts = u64::from(self.retries) + 1;
        let backoffs = self.backoff_ms * ((1u64 << self.retries.min(MAX_RETRIES)) - 1);
        std::time::Duration::from_millis(attempts * self.timeout_ms + backoffs)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn upstream(settings: &str) -> UpstreamConfig {
        toml::from_str(&format!("service = \"wms\"\nurl = \"http://h/wms\"\nbounds = [0, 0, 1, 1]\n{settings}"))
            .unwrap()
    }

    #[test]
    fn timings_out_of_bounds_are_named() {
        assert_eq!(upstream("").check(), Ok(()));
        for (setting, said) in [
            ("breaker_cooldown_s = inf", "breaker_cooldown_s = inf: must be 0 to 86400"),
            ("breaker_cooldown_s = nan", "breaker_cooldown_s = NaN"),
            ("breaker_cooldown_s = -1.0", "breaker_cooldown_s = -1"),
            ("ttl_s = 18446744073709551615", "ttl_s = 18446744073709551615: must be 0 to 31536000"),
            ("timeout_ms = 0", "timeout_ms = 0"),
            ("retries = 11", "retries = 11: must be 0 to 10"),
            ("backoff_ms = 600001", "backoff_ms = 600001"),
        ] {
            let e = upstream(setting).check().unwrap_err();
            assert!(e.starts_with(said), "{setting}: {e}");
        }
    }

    #[test]
    fn the_longest_read_counts_every_attempt_and_backoff() {
        // Three attempts of 3 s, backoffs of 0.1 and 0.2 s.
        assert_eq!(upstream("").longest_read(), std::time::Duration::from_millis(9_300));
    }
}
