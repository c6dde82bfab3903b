//! Routes and middleware: `/health`, `/metrics`, `/tiles.json` (the grid and
//! region a client flies over), World Wind tiles (path and
//! `?T=&L=&X=&Y=` forms), XYZ Terrarium tiles (zooms 0 to
//! [`MAX_XYZ_ZOOM`]) with a TileJSON per layer, `/wms`, `/wmts` and
//! `/cesium`; per-request timeout (503, an OGC exception report on `/wms`
//! and `/wmts`), URI length limit, CORS for browser clients (read-only data:
//! any origin may GET), gzip for BIL and Cesium terrain bodies, request
//! metrics and logs.

use super::products::{Encoding, Product};
use super::query::Params;
use super::respond::{self, TileMeta};
use super::service::Tile;
use super::wms::picture::{self, PictureFormat};
use super::wms::request::{MapFormat, MapLayer};
use super::{AppState, ServeError};
use crate::cem::Layer;
use crate::encode::{self, Format};
use crate::grid::TileId;
use crate::grid::quad::TileSet;
use axum::Router;
use axum::extract::{MatchedPath, Path, RawQuery, Request, State};
use axum::http::{HeaderMap, HeaderName, StatusCode, header};
use axum::middleware::{self, Next};
use axum::response::{IntoResponse, Response};
use axum::routing::get;
use std::sync::Arc;
use std::time::Instant;
use tower_http::compression::CompressionLayer;
use tower_http::cors::{Any, CorsLayer};
use tower_http::trace::TraceLayer;

/// Deepest XYZ zoom served (9.3 mm pixels at the equator), and the deepest
/// any extent advertises (TileJSON's, WMTS's sets, Cesium's terrain), which
/// end at the zoom as fine as a layer's finest source.
pub const MAX_XYZ_ZOOM: u32 = 24;

/// Longest request URI, bytes; a WMS request is a few hundred.
const MAX_URI_BYTES: usize = 8192;

pub fn router(state: Arc<AppState>) -> Router {
    // Elevation grids (BIL, Cesium terrain) compress well; PNG and TIFF are
    // compressed already.
    let grids_only = |_: StatusCode, _: axum::http::Version, h: &HeaderMap, _: &axum::http::Extensions| {
        let mime = h.get(header::CONTENT_TYPE).and_then(|v| v.to_str().ok());
        mime.is_some_and(|t| t.starts_with("application/bil") || t == Encoding::Heightmap.mime())
    };
    Router::new()
        .route("/health", get(health))
        .route("/metrics", get(metrics))
        .route("/wms", get(super::wms::handle).fallback(super::wms::other_method))
        .route("/wms/", get(super::wms::handle).fallback(super::wms::other_method))
        .route("/tiles.json", get(tileset))
        .route("/tiles", get(tile_query))
        .route("/tiles/{layer}/{level}/{row}/{file}", get(tile_path))
        .route("/xyz/{layer}/tiles.json", get(xyz_tilejson))
        .route("/xyz/{layer}/{z}/{x}/{file}", get(xyz))
        .route("/cesium/{layer}/layer.json", get(super::cesium::layer_json))
        .route("/cesium/{layer}/{z}/{x}/{file}", get(super::cesium::tile))
        .route("/wmts", get(super::wmts::handle).fallback(super::wmts::other_method))
        .route("/wmts/", get(super::wmts::handle).fallback(super::wmts::other_method))
        .route("/wmts/1.0.0/WMTSCapabilities.xml", get(super::wmts::capabilities_file))
        .route(super::wmts::TILE_ROUTE, get(super::wmts::rest_tile).fallback(super::wmts::other_method))
        .layer(CompressionLayer::new().gzip(true).compress_when(grids_only))
        .layer(middleware::from_fn_with_state(state.clone(), observe))
        .layer(cors())
        .layer(TraceLayer::new_for_http())
        .with_state(state)
}

/// Any web page may read tiles and maps (and their quantization headers),
/// with any request headers (a client revalidating with `If-None-Match`,
/// or adding its own, asks first).
fn cors() -> CorsLayer {
    let exposed = [header::ETAG, HeaderName::from_static("x-sylva-offset"), HeaderName::from_static("x-sylva-scale")];
    CorsLayer::new()
        .allow_origin(Any)
        .allow_methods([axum::http::Method::GET, axum::http::Method::HEAD])
        .allow_headers(Any)
        .expose_headers(exposed)
}

/// Refuses overlong URIs, gives up on requests past the timeout, and
/// records every request's route, status and time.
async fn observe(State(state): State<Arc<AppState>>, request: Request, next: Next) -> Response {
    let start = Instant::now();
    let route = request.extensions().get::<MatchedPath>().map_or("other", |p| route_label(p.as_str()));
    // Checked with the configuration: positive and at most a day.
    let timeout = std::time::Duration::from_secs_f64(state.settings.request_timeout_s);
    // Kept for a WMS timeout's report, which speaks the request's version.
    let query = (route == "wms").then(|| request.uri().query().unwrap_or("").to_string());
    let response = if request.uri().to_string().len() > MAX_URI_BYTES {
        let message = format!("request URI longer than {MAX_URI_BYTES} bytes");
        refused(route, query.as_deref(), StatusCode::URI_TOO_LONG, message)
    } else {
        match tokio::time::timeout(timeout, next.run(request)).await {
            Ok(response) => response,
            // Its tile is still computed and cached for the retry.
            Err(_) => {
                let message = format!("the request took longer than {timeout:?}; retry later");
                refused(route, query.as_deref(), StatusCode::SERVICE_UNAVAILABLE, message)
            }
        }
    };
    state.metrics.request(route, response.status().as_u16(), start.elapsed());
    response
}

/// A request refused before its handler answered (a 503 is to be retried
/// in 5 s): an OGC exception report on `/wms` (in the version its `query`
/// asks for) and `/wmts`, text elsewhere.
fn refused(route: &str, query: Option<&str>, status: StatusCode, message: String) -> Response {
    let mut response = match route {
        "wms" => super::wms::refused(query.unwrap_or(""), status, message),
        "wmts" => super::wmts::refused(status, message),
        _ => (status, message).into_response(),
    };
    if status == StatusCode::SERVICE_UNAVAILABLE {
        response.headers_mut().insert(header::RETRY_AFTER, axum::http::HeaderValue::from_static("5"));
    }
    response
}

fn route_label(path: &str) -> &'static str {
    match path {
        "/health" => "health",
        "/metrics" => "metrics",
        "/wms" | "/wms/" => "wms",
        "/tiles" | "/tiles/{layer}/{level}/{row}/{file}" | "/tiles.json" => "tiles",
        "/xyz/{layer}/{z}/{x}/{file}" | "/xyz/{layer}/tiles.json" => "xyz",
        "/wmts" | "/wmts/" | "/wmts/1.0.0/WMTSCapabilities.xml" | super::wmts::TILE_ROUTE => "wmts",
        "/cesium/{layer}/layer.json" | "/cesium/{layer}/{z}/{x}/{file}" => "cesium",
        _ => "other",
    }
}

async fn health(State(state): State<Arc<AppState>>) -> Response {
    let r = state.region();
    let body = format!("{{\"status\":\"ok\",\"region\":{:?},\"version\":{:?}}}\n", r.name, r.version);
    ([(header::CONTENT_TYPE, "application/json")], body).into_response()
}

/// The tiling, bounds and halo limit, for tile clients such as `sylva fly`.
async fn tileset(State(state): State<Arc<AppState>>) -> Response {
    let tileset = state.region().tileset(state.settings.max_halo);
    let body = serde_json::to_string(&tileset).unwrap_or_default();
    ([(header::CONTENT_TYPE, "application/json")], body).into_response()
}

async fn metrics(State(state): State<Arc<AppState>>) -> Response {
    ([(header::CONTENT_TYPE, "application/openmetrics-text; version=1.0.0; charset=utf-8")], state.metrics.render())
        .into_response()
}

/// `/tiles/{layer}/{level}/{row}/{row}_{col}.{ext}?halo=B`.
async fn tile_path(
    State(state): State<Arc<AppState>>,
    Path((layer, level, row, file)): Path<(String, String, String, String)>,
    RawQuery(query): RawQuery,
    headers: HeaderMap,
) -> Result<Response, ServeError> {
    let (level, row) = (level_number(&level, "level")?, whole_number(&row, "row")?);
    let named =
        || ServeError::BadRequest(format!("tile files are {{row}}_{{col}}.{{ext}}, e.g. {row}_0.bil, not {file:?}"));
    let (stem, ext) = file.rsplit_once('.').ok_or_else(named)?;
    let (file_row, col) = stem.split_once('_').ok_or_else(named)?;
    if whole_number(file_row, "row")? != row {
        let why =
            format!("the file's row {file_row} is not the directory's, {row}: /{{level}}/{{row}}/{{row}}_{{col}}");
        return Err(ServeError::BadRequest(why));
    }
    let col = whole_number(col, "column")?;
    let params = query_params(query.as_deref())?;
    tile(&state, &layer, TileId::new(level, row, col), ext, halo(&params, &state)?, &headers).await
}

/// A tile coordinate: a whole number (past any tile where too large to
/// hold: no such tile), or the request is bad.
pub(super) fn whole_number(text: &str, what: &str) -> Result<u64, ServeError> {
    text.parse().map_err(|_| match !text.is_empty() && text.bytes().all(|b| b.is_ascii_digit()) {
        true => ServeError::NotFound,
        false => ServeError::BadRequest(format!("{what} must be a whole number, not {text:?}")),
    })
}

/// A level or zoom: a whole number (past any level: no such tile).
pub(super) fn level_number(text: &str, what: &str) -> Result<u32, ServeError> {
    u32::try_from(whole_number(text, what)?).map_err(|_| ServeError::NotFound)
}

/// `/tiles?T={layer}&L={level}&X={col}&Y={row}` (World Wind's request form);
/// `F` or `FORMAT` names the extension (or its MIME type): BIL16 and PNG
/// pictures unless one names another.
async fn tile_query(
    State(state): State<Arc<AppState>>,
    RawQuery(query): RawQuery,
    headers: HeaderMap,
) -> Result<Response, ServeError> {
    let params = query_params(query.as_deref())?;
    let need = |k: &str| params.get(k).ok_or_else(|| ServeError::BadRequest(format!("parameter {k} is missing")));
    let id =
        TileId::new(level_number(need("L")?, "L")?, whole_number(need("Y")?, "Y")?, whole_number(need("X")?, "X")?);
    let layer = need("T")?;
    let picture = parse_layer(layer)?.is_picture();
    let given: Vec<&str> = [params.get("F"), params.get("FORMAT")].into_iter().flatten().map(extension_of).collect();
    let ext = match given[..] {
        [] if picture => "png",
        [] => "bil",
        [f] => f,
        [f, g] if f.eq_ignore_ascii_case(g) => f,
        _ => return Err(ServeError::BadRequest("F and FORMAT name two formats: give one".into())),
    };
    tile(&state, layer, id, ext, halo(&params, &state)?, &headers).await
}

/// A tile's extension, given as one or as a MIME type (`FORMAT=image/png`,
/// read as WMS reads it).
fn extension_of(format: &str) -> &str {
    match format.contains('/').then(|| MapFormat::parse(format)).flatten() {
        Some(MapFormat::Png) => "png",
        Some(MapFormat::Jpeg) => "jpg",
        Some(MapFormat::Tiff) => "tif",
        Some(MapFormat::Bil16) => "bil",
        Some(MapFormat::Bil32) => "bil32",
        None => format,
    }
}

fn halo(params: &Params, state: &AppState) -> Result<usize, ServeError> {
    let Some(text) = params.get("HALO") else { return Ok(0) };
    let max = state.settings.max_halo;
    text.parse::<usize>()
        .ok()
        .filter(|&h| h <= max)
        .ok_or_else(|| ServeError::BadRequest(format!("halo must be 0 to {max}")))
}

async fn tile(
    state: &AppState,
    layer: &str,
    id: TileId,
    ext: &str,
    halo: usize,
    headers: &HeaderMap,
) -> Result<Response, ServeError> {
    let layer = parse_layer(layer)?;
    let picture = match layer.is_picture() {
        true => Some((picture_extension(layer, ext)?, Encoding::Rgba)),
        // A data layer in JPEG is a picture of it.
        false => PictureFormat::of_extension(ext).filter(|&f| f == PictureFormat::Jpeg).map(|f| (f, Encoding::Picture)),
    };
    if let Some((format, encoding)) = picture {
        tile_exists(state, id)?;
        let t = state.tiles.get(Product::Tile { layer, id, halo, encoding }).await?;
        return picture_tile(state, layer, t, format, headers).await;
    }
    let encoding = match ext.to_ascii_lowercase().as_str() {
        "bil" | "bil16" => Encoding::Data(Format::Bil16),
        "bil32" => Encoding::Data(Format::Bil32),
        "png" => Encoding::Data(Format::Png16),
        "tif" | "tiff" => Encoding::Data(Format::Tiff),
        other => {
            return Err(ServeError::BadRequest(format!(
                "tile extension .{other}: use bil, bil32, png, tif or jpg (a picture)"
            )));
        }
    };
    tile_exists(state, id)?;
    let product = Product::Tile { layer, id, halo, encoding };
    let t = state.tiles.get(product).await?;
    Ok(respond::tile(&t, &meta(state, layer, encoding), headers))
}

/// `/xyz/{layer}/{z}/{x}/{y}.png`: Terrarium heights, or the pictures (also
/// `.jpg`).
async fn xyz(
    State(state): State<Arc<AppState>>,
    Path((layer, z, x, file)): Path<(String, String, String, String)>,
    headers: HeaderMap,
) -> Result<Response, ServeError> {
    let (z, x) = (level_number(&z, "zoom")?, whole_number(&x, "x")?);
    let layer = xyz_layer(&layer)?;
    let (y, ext) = file.rsplit_once('.').ok_or(ServeError::NotFound)?;
    let picture = match layer.is_picture() {
        true => Some(picture_extension(layer, ext)?),
        false if ext.eq_ignore_ascii_case("png") => None,
        false => return Err(ServeError::BadRequest(format!("{} XYZ tiles are Terrarium .png", layer.name()))),
    };
    let y = whole_number(y, "y")?;
    if z > MAX_XYZ_ZOOM || x >= 1 << z || y >= 1 << z {
        return Err(ServeError::NotFound);
    }
    quad_tile(&state, layer, TileSet::WebMercator, (z, x, y), picture, &headers).await
}

/// The tile `zxy` of `layer` in `set`: a picture in `picture`'s format, or
/// Terrarium heights (`None`).
pub(super) async fn quad_tile(
    state: &AppState,
    layer: MapLayer,
    set: TileSet,
    zxy: (u32, u64, u64),
    picture: Option<PictureFormat>,
    headers: &HeaderMap,
) -> Result<Response, ServeError> {
    let t = state.tiles.get(Product::Quad { layer, set, zxy }).await?;
    match picture {
        Some(format) => picture_tile(state, layer, t, format, headers).await,
        None => Ok(respond::tile(&t, &meta(state, layer, Encoding::Terrarium), headers)),
    }
}

/// `/xyz/{layer}/tiles.json`: the layer's XYZ tiles as TileJSON.
async fn xyz_tilejson(
    State(state): State<Arc<AppState>>,
    Path(layer): Path<String>,
    headers: HeaderMap,
) -> Result<Response, ServeError> {
    let doc = super::tilejson::document(state.region(), xyz_layer(&layer)?, &state.public_base(&headers))
        .ok_or(ServeError::NotFound)?;
    Ok(([(header::CONTENT_TYPE, "application/json")], doc.to_string()).into_response())
}

/// A layer XYZ tiles are served in: heights or the pictures.
fn xyz_layer(name: &str) -> Result<MapLayer, ServeError> {
    let layer = parse_layer(name)?;
    if !layer.in_quad_tiles() {
        return Err(ServeError::BadRequest(format!(
            "{} is not a height: XYZ tiles carry heights or the pictures",
            layer.name()
        )));
    }
    Ok(layer)
}

/// The encoding a picture tile's extension asks for.
fn picture_extension(layer: MapLayer, ext: &str) -> Result<PictureFormat, ServeError> {
    PictureFormat::of_extension(ext)
        .ok_or_else(|| ServeError::BadRequest(format!("{} tiles are .png or .jpg", layer.name())))
}

/// A cached picture tile answered as a transparent PNG or as JPEG on white.
async fn picture_tile(
    state: &AppState,
    layer: MapLayer,
    t: Arc<Tile>,
    format: PictureFormat,
    headers: &HeaderMap,
) -> Result<Response, ServeError> {
    let t = picture::answer(&state.tiles, t, None, format).await?;
    let meta = TileMeta { mime: format.mime(), ..meta(state, layer, Encoding::Rgba) };
    Ok(respond::tile(&t, &meta, headers))
}

/// Tiles outside the region's tiling are not found.
fn tile_exists(state: &AppState, id: TileId) -> Result<(), ServeError> {
    state.region().tiles.check(id).map_err(|_| ServeError::NotFound)
}

fn parse_layer(name: &str) -> Result<MapLayer, ServeError> {
    MapLayer::parse(name)
        .or_else(|| Layer::parse(name).map(MapLayer::Data))
        .ok_or_else(|| ServeError::BadRequest(format!("unknown layer {name:?}")))
}

/// MIME type, quantization and caching of a tile response.
pub fn meta(state: &AppState, layer: MapLayer, encoding: Encoding) -> TileMeta {
    let quantization = match (layer, encoding) {
        (MapLayer::Data(l), Encoding::Data(Format::Bil16)) => {
            Some(encode::quantizations(l, state.region().heights_16).0)
        }
        (MapLayer::Data(l), Encoding::Data(Format::Png16)) => {
            Some(encode::quantizations(l, state.region().heights_16).1)
        }
        _ => None,
    };
    // A tile made from an upstream's data is kept by clients no longer than here.
    let upstream_s = state.region().upstream_ttl.map_or(u64::MAX, |ttl| ttl.as_secs());
    TileMeta { mime: encoding.mime(), quantization, max_age_s: state.settings.tile_max_age_s.min(upstream_s) }
}

/// A tile route's query; a key given twice differently is refused.
fn query_params(query: Option<&str>) -> Result<Params, ServeError> {
    let params = Params::new(query.unwrap_or(""));
    match params.conflict() {
        Some((_, message)) => Err(ServeError::BadRequest(message)),
        None => Ok(params),
    }
}
