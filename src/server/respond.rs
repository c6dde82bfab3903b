//! HTTP responses for tiles and errors: entity tags with `304 Not Modified`,
//! a byte range of a body (`206 Partial Content`, as GDAL's `/vsicurl/`
//! reads a remote GeoTIFF), `Cache-Control`, `Server-Timing`, the 16-bit
//! quantization of PNG16 and BIL16 bodies in `X-Sylva-Scale` /
//! `X-Sylva-Offset`, and status codes by who is at fault.

use super::ServeError;
use super::service::Tile;
use crate::encode::Quantization;
use axum::body::Body;
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};

/// What a tile response says beyond its bytes.
pub struct TileMeta {
    /// MIME type.
    pub mime: &'static str,
    /// How 16-bit codes read back, for 16-bit bodies.
    pub quantization: Option<Quantization>,
    /// `Cache-Control: max-age`, seconds.
    pub max_age_s: u64,
}

/// 200 with the tile, 206 with the one byte range asked for (416 for a
/// range outside it), 304 if the client has it, 404 (no body) for a tile
/// without data.
pub fn tile(t: &Tile, meta: &TileMeta, request: &HeaderMap) -> Response {
    if t.bytes.is_empty() {
        return StatusCode::NOT_FOUND.into_response();
    }
    let mut headers = HeaderMap::new();
    insert(&mut headers, header::ETAG, &t.etag);
    // A stale tile is kept nowhere: the next request asks again.
    let max_age = if t.stale { 0 } else { meta.max_age_s };
    insert(&mut headers, header::CACHE_CONTROL, &format!("public, max-age={max_age}"));
    insert(&mut headers, "server-timing", &t.timing);
    if t.stale {
        insert(&mut headers, header::WARNING, "110 sylva \"Response is Stale\"");
    }
    if let Some(q) = meta.quantization {
        insert(&mut headers, "x-sylva-scale", &q.scale.to_string());
        insert(&mut headers, "x-sylva-offset", &q.offset.to_string());
    }
    let matches = request
        .get(header::IF_NONE_MATCH)
        .and_then(|v| v.to_str().ok())
        .is_some_and(|v| v.split(',').any(|e| e.trim() == "*" || weak_match(e.trim(), &t.etag)));
    if matches {
        return (StatusCode::NOT_MODIFIED, headers).into_response();
    }
    insert(&mut headers, header::CONTENT_TYPE, meta.mime);
    insert(&mut headers, header::ACCEPT_RANGES, "bytes");
    let len = t.bytes.len();
    match byte_range(request, len) {
        None => (StatusCode::OK, headers, Body::from(t.bytes.clone())).into_response(),
        Some(Some(range)) => {
            insert(&mut headers, header::CONTENT_RANGE, &format!("bytes {}-{}/{len}", range.start(), range.end()));
            (StatusCode::PARTIAL_CONTENT, headers, Body::from(t.bytes.slice(range))).into_response()
        }
        Some(None) => {
            insert(&mut headers, header::CONTENT_RANGE, &format!("bytes */{len}"));
            (StatusCode::RANGE_NOT_SATISFIABLE, headers).into_response()
        }
    }
}

/// The one byte range of a `len`-byte body a request asks for: `None` for
/// the whole body (no `Range`, one that is not in bytes, several ranges, or
/// an `If-Range`, which the weak entity tags cannot validate), `Some(None)`
/// for a range outside it.
fn byte_range(request: &HeaderMap, len: usize) -> Option<Option<std::ops::RangeInclusive<usize>>> {
    let asked = request.get(header::RANGE)?.to_str().ok()?;
    if request.contains_key(header::IF_RANGE) {
        return None;
    }
    // A header that is no byte range (another unit) is ignored.
    match http_range_header::parse_range_header(asked).ok()?.validate(len as u64) {
        Ok(ranges) if ranges.len() == 1 => Some(Some(*ranges[0].start() as usize..=*ranges[0].end() as usize)),
        Ok(_) => None,
        Err(_) => Some(None),
    }
}

/// The weak comparison of two entity tags (RFC 9110 §8.8.3.2), which
/// `If-None-Match` uses: equal once any `W/` is set aside.
fn weak_match(a: &str, b: &str) -> bool {
    a.trim_start_matches("W/") == b.trim_start_matches("W/")
}

fn insert(headers: &mut HeaderMap, name: impl axum::http::header::IntoHeaderName, value: &str) {
    if let Ok(v) = HeaderValue::from_str(value) {
        headers.insert(name, v);
    }
}

/// What a client is told of a server failure.
const INTERNAL: &str = "internal error; the server's log has the details";

impl ServeError {
    /// The status (who is at fault), headers (when to retry an overloaded
    /// server) and message of the error's response; server failures are logged.
    pub fn parts(&self) -> (StatusCode, HeaderMap, String) {
        let mut headers = HeaderMap::new();
        let status = match self {
            ServeError::NotFound => StatusCode::NOT_FOUND,
            ServeError::BadRequest(_) => StatusCode::BAD_REQUEST,
            ServeError::Busy(_) => {
                insert(&mut headers, header::RETRY_AFTER, "1");
                StatusCode::SERVICE_UNAVAILABLE
            }
            ServeError::Upstream(_) => StatusCode::BAD_GATEWAY,
            ServeError::Internal(m) => {
                tracing::error!(error = %m, "request failed");
                // The details (paths, say) stay in the server's log.
                return (StatusCode::INTERNAL_SERVER_ERROR, headers, INTERNAL.into());
            }
        };
        (status, headers, self.to_string())
    }
}

impl IntoResponse for ServeError {
    fn into_response(self) -> Response {
        match self {
            // Absent tiles have no body.
            ServeError::NotFound => StatusCode::NOT_FOUND.into_response(),
            other => other.parts().into_response(),
        }
    }
}
