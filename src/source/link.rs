//! HTTP for sources and clients: GETs with a timeout, retried a bounded
//! number of times with exponential backoff; after repeated failures a
//! circuit breaker fails requests at once for a cool-down, so a dead server
//! costs no waiting. Bodies are read up to a size limit; 404 is "no data".

use super::SourceError;
use crate::config::UpstreamConfig;
use std::io::Read;
use std::sync::Mutex;
use std::sync::atomic::{AtomicU32, Ordering};
use std::time::{Duration, Instant};

/// Largest response read, bytes (a 577² float32 tile is 1.3 MiB).
const MAX_RESPONSE_BYTES: u64 = 16 << 20;

/// Timeouts, retries and the breaker.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LinkSettings {
    /// Whole-request timeout, ms.
    pub timeout_ms: u64,
    /// Retries after the first attempt.
    pub retries: u32,
    /// First backoff, ms (doubling).
    pub backoff_ms: u64,
    /// Consecutive failed fetches that open the breaker.
    pub breaker_failures: u32,
    /// How long the breaker stays open, s.
    pub breaker_cooldown_s: f64,
}

impl From<&UpstreamConfig> for LinkSettings {
    fn from(c: &UpstreamConfig) -> LinkSettings {
        LinkSettings {
            timeout_ms: c.timeout_ms,
            retries: c.retries,
            backoff_ms: c.backoff_ms,
            breaker_failures: c.breaker_failures,
            breaker_cooldown_s: c.breaker_cooldown_s,
        }
    }
}

/// HTTP GETs with a timeout, retries and a circuit breaker.
pub struct Link {
    agent: ureq::Agent,
    retries: u32,
    backoff: Duration,
    threshold: u32,
    cooldown: Duration,
    failures: AtomicU32,
    open_until: Mutex<Option<Instant>>,
}

impl Link {
    /// A link with these settings.
    pub fn new(c: &LinkSettings) -> Link {
        let agent = ureq::Agent::config_builder()
            .timeout_global(Some(Duration::from_millis(c.timeout_ms.max(1))))
            .http_status_as_error(false)
            .build()
            .into();
        Link {
            agent,
            retries: c.retries,
            backoff: Duration::from_millis(c.backoff_ms),
            threshold: c.breaker_failures.max(1),
            cooldown: Duration::from_secs_f64(c.breaker_cooldown_s.max(0.0)),
            failures: AtomicU32::new(0),
            open_until: Mutex::new(None),
        }
    }

    /// The body at `url`; `None` for 404 (no data there).
    pub fn fetch(&self, url: &str) -> Result<Option<Vec<u8>>, SourceError> {
        let fail = |problem: String| SourceError::Upstream { url: url.to_string(), problem };
        if let Ok(guard) = self.open_until.lock()
            && let Some(until) = *guard
            && Instant::now() < until
        {
            return Err(fail("circuit breaker open after repeated failures".into()));
        }
        let mut last = String::new();
        for attempt in 0..=self.retries {
            if attempt > 0 {
                std::thread::sleep(self.backoff * 2u32.pow(attempt - 1));
            }
            match self.try_once(url) {
                Ok(body) => {
                    self.failures.store(0, Ordering::Relaxed);
                    return Ok(body);
                }
                Err(e) => {
                    let attempt = format!("{} of {}", attempt + 1, self.retries + 1);
                    tracing::warn!(url, attempt, error = %e, "request failed");
                    last = e;
                }
            }
        }
        if self.failures.fetch_add(1, Ordering::Relaxed) + 1 >= self.threshold
            && let Ok(mut guard) = self.open_until.lock()
        {
            *guard = Some(Instant::now() + self.cooldown);
        }
        Err(fail(format!("{last} (after {} attempts)", self.retries + 1)))
    }

    fn try_once(&self, url: &str) -> Result<Option<Vec<u8>>, String> {
        let mut response = self.agent.get(url).call().map_err(|e| e.to_string())?;
        match response.status().as_u16() {
            200 => {
                let mut body = Vec::new();
                response
                    .body_mut()
                    .as_reader()
                    .take(MAX_RESPONSE_BYTES)
                    .read_to_end(&mut body)
                    .map_err(|e| e.to_string())?;
                Ok(Some(body))
            }
            404 => Ok(None),
            status => Err(format!("HTTP {status}")),
        }
    }
}
