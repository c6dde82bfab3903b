//! `sylva serve`: the tile proxy server (axum + tokio). WMS 1.1.1/1.3.0 at
//! `/wms`, World Wind tiles at `/tiles`, XYZ Terrarium tiles at `/xyz`, WMTS
//! 1.0.0 (those tiles, and geographic ones) at `/wmts`, Cesium terrain at
//! `/cesium`, `/health` and Prometheus `/metrics`; tiles cached on disk and
//! in memory (the cache held to a size if configured), computed once however
//! many clients ask (dissertation 6.5, "Preprocessing via Proxy Servers").
//!
//! [`router`] builds the application without a socket, so tests drive it in
//! process; [`serve`] binds it and shuts down gracefully on SIGTERM/SIGINT.
//!
//! Invariant: only this module knows HTTP; CPU work runs on [`pool::Pool`],
//! never on the async executor; no request can panic the server (bad input
//! is a 4xx with a message, an OGC exception report on `/wms` and `/wmts`).

pub mod cesium;
pub mod exception;
pub mod extent;
pub mod metrics;
pub mod pool;
pub mod products;
mod query;
mod respond;
mod routes;
pub use routes::MAX_XYZ_ZOOM;
pub mod service;
mod tilejson;
pub mod wms;
pub mod wmts;

use crate::cache::TileStore;
use crate::cache::quota::{Limit, Quota};
use crate::config::ServerConfig;
use crate::produce::ProduceError;
use crate::region::Region;
use axum::Router;
use metrics::Metrics;
use pool::{Pool, PoolError};
use service::TileService;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;
use thiserror::Error;

/// Why a request failed, sorted by who is at fault (mapped to HTTP statuses in
/// `respond`).
#[derive(Clone, Debug, Error)]
pub enum ServeError {
    /// The request is wrong (400).
    #[error("{0}")]
    BadRequest(String),
    /// Nothing there (404, no body).
    #[error("not found")]
    NotFound,
    /// Overloaded: retry later (503).
    #[error(transparent)]
    Busy(#[from] PoolError),
    /// An upstream server failed (502).
    #[error("{0}")]
    Upstream(String),
    /// The server failed (500).
    #[error("internal error: {0}")]
    Internal(String),
}

impl ServeError {
    fn internal(e: impl std::fmt::Display) -> ServeError {
        ServeError::Internal(e.to_string())
    }
}

impl From<ProduceError> for ServeError {
    fn from(e: ProduceError) -> ServeError {
        match e {
            ProduceError::Request(g) => ServeError::BadRequest(g.to_string()),
            ProduceError::Source(s @ crate::source::SourceError::Upstream { .. }) => {
                ServeError::Upstream(s.to_string())
            }
            other => ServeError::Internal(other.to_string()),
        }
    }
}

/// Everything the handlers share.
pub struct AppState {
    /// Tiles of the region.
    pub tiles: TileService,
    /// Metrics.
    pub metrics: Arc<Metrics>,
    /// Server settings.
    pub settings: ServerConfig,
}

impl AppState {
    /// State over a region, its tile cache and settings; tile locks expire
    /// after `lock_ttl`.
    pub fn new(
        region: Region,
        store: Arc<dyn TileStore>,
        lock_ttl: Duration,
        settings: ServerConfig,
    ) -> std::io::Result<Arc<AppState>> {
        settings.check().map_err(|e| std::io::Error::other(format!("[server] {e}")))?;
        let metrics = Arc::new(Metrics::new());
        let pool = Arc::new(Pool::new(settings.workers, settings.queue)?);
        let memory = settings.memory_cache_mb.max(1) * 1024 * 1024;
        let tiles = TileService::new(Arc::new(region), store, lock_ttl, memory, pool, metrics.clone());
        Ok(Arc::new(AppState { tiles, metrics, settings }))
    }

    /// The region served.
    pub fn region(&self) -> &Region {
        self.tiles.region()
    }

    /// Where clients reach the server, without a trailing `/`: `[server]
    /// public_url`, else from the request's Host header.
    pub fn public_base(&self, headers: &axum::http::HeaderMap) -> String {
        if let Some(url) = &self.settings.public_url {
            return url.trim_end_matches('/').to_string();
        }
        let host = headers.get(axum::http::header::HOST).and_then(|h| h.to_str().ok()).filter(|h| !h.is_empty());
        match host {
            Some(host) => format!("http://{host}"),
            None => {
                let port = self.settings.bind.rsplit_once(':').map_or("80", |(_, port)| port);
                format!("http://localhost:{port}")
            }
        }
    }
}

/// The application: every route and layer, no socket.
pub fn router(state: Arc<AppState>) -> Router {
    routes::router(state)
}

/// Options of `sylva serve` beyond the configuration file.
#[derive(Clone, Debug, Default)]
pub struct ServeOptions {
    /// Listen here instead of `[server] bind`.
    pub bind: Option<String>,
    /// Cache tiles in this directory instead of `[tile_cache]`.
    pub cache_dir: Option<PathBuf>,
}

/// A server bound to its socket, not yet serving.
pub struct Bound {
    /// The socket.
    pub listener: tokio::net::TcpListener,
    /// What the handlers share.
    pub state: Arc<AppState>,
    /// Where tiles are cached, for logs.
    pub cache: String,
    /// The region's version marked in use in the tile cache while this lives.
    pub in_use: crate::cache::in_use::InUse,
    /// The tile cache held to `[tile_cache] max_size` while this lives.
    pub quota: Option<crate::cache::quota::Quota>,
}

impl Bound {
    /// `http://ADDRESS` of the socket.
    pub fn base_url(&self) -> std::io::Result<String> {
        Ok(format!("http://{}", self.listener.local_addr()?))
    }

    /// Serves until `shutdown` resolves, then finishes the requests in flight.
    pub async fn run(self, shutdown: impl std::future::Future<Output = ()> + Send + 'static) -> std::io::Result<()> {
        let _held = (self.in_use, self.quota);
        axum::serve(self.listener, router(self.state)).with_graceful_shutdown(shutdown).await
    }
}

/// Loads the configuration (off the executor: it opens files) and binds.
pub async fn bind(config: Option<&Path>, options: ServeOptions) -> anyhow::Result<Bound> {
    let config = config.map(Path::to_path_buf);
    let (cfg, region) =
        tokio::task::spawn_blocking(move || crate::config::load_with_config(config.as_deref())).await??;
    let mut settings = cfg.server.clone();
    let bind = options.bind.unwrap_or_else(|| settings.bind.clone());
    let backend = cfg.tile_cache.backend(options.cache_dir.as_deref());
    let (opened, version) = (backend.clone(), region.version.clone());
    let (store, in_use) = tokio::task::spawn_blocking(move || {
        let store = crate::cache::open(&opened)?;
        let in_use = crate::cache::in_use::InUse::mark(store.clone(), &version);
        anyhow::Ok((store, in_use))
    })
    .await??;
    let cache = store.describe();
    let listener =
        tokio::net::TcpListener::bind(&bind).await.map_err(|e| anyhow::anyhow!("cannot listen on {bind}: {e}"))?;
    // The address listened on, its port chosen if 0 was asked for.
    settings.bind = listener.local_addr()?.to_string();
    let state = AppState::new(region, store.clone(), cfg.tile_cache.lock_ttl(), settings)?;
    let quota = cfg.tile_cache.max_size.map(|max| {
        let limit = Limit { max_bytes: max, every: cfg.tile_cache.trim_interval() };
        let metrics = state.metrics.clone();
        Quota::start(backend, store, limit, move |pruned| metrics.trimmed(pruned))
    });
    Ok(Bound { listener, state, cache, in_use, quota })
}

/// Loads the configuration, binds, serves until SIGTERM or SIGINT, then
/// finishes the requests in flight.
pub async fn serve(config: Option<&Path>, options: ServeOptions) -> anyhow::Result<()> {
    let shutdown = shutdown_signal()?;
    let bound = bind(config, options).await?;
    let (state, cache) = (bound.state.clone(), bound.cache.clone());
    tracing::info!(
        address = %bound.listener.local_addr()?,
        region = %state.region().name,
        cache = %cache,
        version = %state.region().version,
        workers = state.settings.workers,
        "serving"
    );
    bound.run(shutdown).await?;
    tracing::info!("stopped");
    Ok(())
}

/// Registers for SIGTERM and Ctrl-C at once (a signal that comes before
/// the first poll must not take the default action and kill the server
/// uncleanly) and resolves on either.
fn shutdown_signal() -> std::io::Result<impl std::future::Future<Output = ()> + Send + 'static> {
    #[cfg(unix)]
    let signalled = {
        use tokio::signal::unix::{SignalKind, signal};
        let (mut term, mut interrupt) = (signal(SignalKind::terminate())?, signal(SignalKind::interrupt())?);
        async move {
            tokio::select! {
                _ = term.recv() => {},
                _ = interrupt.recv() => {},
            }
        }
    };
    #[cfg(not(unix))]
    let signalled = async {
        let _ = tokio::signal::ctrl_c().await;
    };
    Ok(async move {
        signalled.await;
        tracing::info!("shutting down: finishing requests in flight");
    })
}
