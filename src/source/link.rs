//! HTTP for sources and clients: GETs with a timeout, retried a bounded
//! number of times with exponential backoff where a retry may succeed (a
//! network error, a timeout, 408, 425, 429, a 5xx but 501 and 505; not a refusal
//! such as 400 or 403); after repeated failures a circuit breaker fails
//! requests at once for a cool-down, so a dead server costs no waiting.
//! Bodies are read up to a size limit, a larger one is an error; 404 is "no
//! data".

use super::SourceError;
use crate::config::UpstreamConfig;
use std::io::Read;
use std::sync::Mutex;
use std::sync::atomic::{AtomicU32, Ordering};
use std::time::{Duration, Instant};

/// Largest response read, bytes: a tile of the largest grid with the
/// largest halo in float32 ((4097 + 2 · 64)² · 4, 71 MB) fits.
const MAX_RESPONSE_BYTES: u64 = 128 << 20;

/// Why one attempt failed, and whether another may succeed.
struct Failure {
    problem: String,
    retry: bool,
}

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
    timeout: Duration,
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
            timeout: Duration::from_millis(c.timeout_ms.max(1)),
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
                Err(Failure { problem, retry }) => {
                    let tried = attempt + 1;
                    tracing::warn!(url, attempt = format!("{tried} of {}", self.retries + 1), error = %problem, "request failed");
                    last = format!("{problem} (after {tried} attempt{})", if tried == 1 { "" } else { "s" });
                    // A refusal says the server answers: no reason to
                    // open the breaker on it.
                    if !retry {
                        return Err(fail(last));
                    }
                }
            }
        }
        if self.failures.fetch_add(1, Ordering::Relaxed) + 1 >= self.threshold
            && let Ok(mut guard) = self.open_until.lock()
        {
            *guard = Some(Instant::now() + self.cooldown);
        }
        Err(fail(last))
    }

    /// A request's failure in words: a timeout by its limit (ureq says
    /// "timeout: global").
    fn said(&self, e: ureq::Error) -> String {
        match e {
            ureq::Error::Timeout(_) => format!("no answer within {} ms", self.timeout.as_millis()),
            e => e.to_string(),
        }
    }

    fn try_once(&self, url: &str) -> Result<Option<Vec<u8>>, Failure> {
        let again = |problem: String| Failure { problem, retry: true };
        let mut response = self.agent.get(url).call().map_err(|e| again(self.said(e)))?;
        match response.status().as_u16() {
            200 => {
                let too_large = || Failure {
                    problem: format!("the response is larger than {} MiB", MAX_RESPONSE_BYTES >> 20),
                    retry: false,
                };
                if response.body().content_length().is_some_and(|n| n > MAX_RESPONSE_BYTES) {
                    return Err(too_large());
                }
                let mut body = Vec::new();
                let mut reader = response.body_mut().as_reader().take(MAX_RESPONSE_BYTES + 1);
                reader.read_to_end(&mut body).map_err(|e| again(self.said(e.into())))?;
                if body.len() as u64 > MAX_RESPONSE_BYTES {
                    return Err(too_large());
                }
                // Some servers answer an exception report with 200.
                let xml = body.iter().find(|b| !b.is_ascii_whitespace()) == Some(&b'<');
                if let Some(said) =
                    xml.then(|| std::str::from_utf8(&body).ok()).flatten().and_then(|t| exception_text(t.trim_start()))
                {
                    return Err(Failure { problem: format!("an exception report: {said}"), retry: false });
                }
                Ok(Some(body))
            }
            404 => Ok(None),
            status => {
                // What the server says of it, if it says it briefly.
                let mut said = Vec::new();
                let _ = response.body_mut().as_reader().take(MAX_EXPLANATION_BYTES).read_to_end(&mut said);
                let problem = match explanation(&said) {
                    Some(text) => format!("HTTP {status}: {text}"),
                    None => format!("HTTP {status}"),
                };
                let retry = matches!(status, 408 | 425 | 429) || (status >= 500 && !matches!(status, 501 | 505));
                Err(Failure { problem, retry })
            }
        }
    }
}

/// Longest explanation read from a failed response's body, bytes.
const MAX_EXPLANATION_BYTES: u64 = 16 << 10;
/// Longest explanation quoted, characters.
const MAX_EXPLANATION_CHARS: usize = 300;

/// A body's explanation of a failure: the text of an OGC exception report
/// (WMS `ServiceException`, OWS `ExceptionText`, with its code), or short
/// plain text; none for anything else.
fn explanation(body: &[u8]) -> Option<String> {
    let text = std::str::from_utf8(body).ok()?.trim();
    let said = match exception_text(text) {
        Some(said) => said,
        None if !text.is_empty() && !text.starts_with('<') => text.lines().next().unwrap_or("").trim().to_string(),
        None => return None,
    };
    Some(match said.char_indices().nth(MAX_EXPLANATION_CHARS) {
        Some((cut, _)) => format!("{}…", &said[..cut]),
        None => said,
    })
}

/// The exceptions of an OGC exception report, `code: text` each, joined.
fn exception_text(xml: &str) -> Option<String> {
    if !xml.starts_with('<') {
        return None;
    }
    let options = roxmltree::ParsingOptions { allow_dtd: true, ..Default::default() };
    let doc = roxmltree::Document::parse_with_options(xml, options).ok()?;
    let said: Vec<String> = doc
        .descendants()
        .filter(|n| n.has_tag_name("ServiceException") || n.has_tag_name("ExceptionText"))
        .map(|n| {
            let text = n.text().unwrap_or("").trim();
            let owner = if n.has_tag_name("ExceptionText") { n.parent().unwrap_or(n) } else { n };
            match owner.attribute("code").or(owner.attribute("exceptionCode")) {
                Some(code) => format!("{code}: {text}"),
                None => text.to_string(),
            }
        })
        .collect();
    (!said.is_empty()).then(|| said.join("; "))
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Write;

    /// A loopback server answering every request with `head` (a status
    /// line and headers); the requests it had.
    fn answering(head: &'static str) -> (String, std::sync::Arc<AtomicU32>) {
        let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
        let url = format!("http://{}/tile", listener.local_addr().unwrap());
        let count = std::sync::Arc::new(AtomicU32::new(0));
        let counted = count.clone();
        std::thread::spawn(move || {
            for mut stream in listener.incoming().flatten() {
                counted.fetch_add(1, Ordering::SeqCst);
                let _ = stream.read(&mut [0u8; 2048]);
                // A head with a body gets its length.
                match head.split_once("\r\n\r\n") {
                    Some((h, body)) => {
                        let n = body.len();
                        let _ = write!(stream, "{h}\r\nContent-Length: {n}\r\nConnection: close\r\n\r\n{body}");
                    }
                    None => {
                        let _ = write!(stream, "{head}\r\nConnection: close\r\n\r\n");
                    }
                }
            }
        });
        (url, count)
    }

    #[test]
    fn refusals_and_oversized_bodies_are_not_retried() {
        // Regression: a 400 or 403 was asked 7 times, backing off, 16 s.
        let settings = LinkSettings {
            timeout_ms: 2000,
            retries: 3,
            backoff_ms: 1,
            breaker_failures: 100,
            breaker_cooldown_s: 1.0,
        };
        for (head, tries, said) in [
            ("HTTP/1.1 403 Forbidden\r\nContent-Length: 0", 1, "HTTP 403 (after 1 attempt)"),
            ("HTTP/1.1 200 OK\r\nContent-Length: 200000000", 1, "larger than 128 MiB (after 1 attempt)"),
            ("HTTP/1.1 503 Service Unavailable\r\nContent-Length: 0", 4, "HTTP 503 (after 4 attempts)"),
            ("HTTP/1.1 429 Too Many Requests\r\nContent-Length: 0", 4, "HTTP 429 (after 4 attempts)"),
            // What the server says is passed on.
            (
                "HTTP/1.1 400 Bad Request\r\n\r\n<ServiceExceptionReport><ServiceException code=\"LayerNotDefined\">no layer dme</ServiceException></ServiceExceptionReport>",
                1,
                "HTTP 400: LayerNotDefined: no layer dme (after 1 attempt)",
            ),
            (
                "HTTP/1.1 200 OK\r\n\r\n<ows:ExceptionReport xmlns:ows=\"http://www.opengis.net/ows/1.1\"><ows:Exception exceptionCode=\"X\"><ows:ExceptionText>bad</ows:ExceptionText></ows:Exception></ows:ExceptionReport>",
                1,
                "an exception report: X: bad (after 1 attempt)",
            ),
            ("HTTP/1.1 502 Bad Gateway\r\n\r\nno route\n", 4, "HTTP 502: no route (after 4"),
        ] {
            let (url, count) = answering(head);
            let err = Link::new(&settings).fetch(&url).unwrap_err().to_string();
            assert!(err.contains(said), "{head}: {err}");
            assert_eq!(count.load(Ordering::SeqCst), tries, "{head}");
        }
        // Nor do refusals open the breaker: the server answers.
        let (url, count) = answering("HTTP/1.1 400 Bad Request\r\nContent-Length: 0");
        let link = Link::new(&LinkSettings { breaker_failures: 1, ..settings });
        for _ in 0..3 {
            assert!(link.fetch(&url).unwrap_err().to_string().contains("HTTP 400"));
        }
        assert_eq!(count.load(Ordering::SeqCst), 3);
    }
}
