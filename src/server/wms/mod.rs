//! The `/wms` endpoint: GetCapabilities, GetMap, GetFeatureInfo and
//! GetLegendGraphic, with OGC exceptions.
//!
//! A GetMap whose pixel centres are exactly a tile's samples is that tile and
//! comes from the tile cache; one whose pixel centres lie on a level's lattice
//! is stitched from cached tiles; any other grid is computed directly.

pub mod capabilities;
pub mod info;
mod inimage;
pub mod legend;
pub mod picture;
pub mod request;
mod text;

use super::exception::Exception;
use super::products::{Encoding, Product};
use super::respond::TileMeta;
use super::routes::meta;
use super::{AppState, ServeError, respond};
use crate::cem::Layer;
use crate::encode::{self, Format, Samples};
use crate::grid::TileId;
use crate::raster::{Raster, Window};
use axum::extract::{RawQuery, State};
use axum::http::{HeaderMap, StatusCode, header};
use axum::response::{IntoResponse, Response};
use request::{ExceptionStyle, GetMap, Limits, MapLayer, Reply, Request};
use std::sync::Arc;

/// Most tiles a GetMap is stitched from; larger requests are computed directly.
const MAX_STITCHED_TILES: usize = 16;

/// Answers a WMS request.
pub async fn handle(State(state): State<Arc<AppState>>, RawQuery(query): RawQuery, headers: HeaderMap) -> Response {
    let limits = limits(&state);
    let query = query.as_deref().unwrap_or("");
    match request::parse(query, limits) {
        Err((e, reply)) => exception(&e, *reply, &state),
        Ok(Request::GetCapabilities(version)) => {
            let url = endpoint(&state, &headers);
            let r = state.region();
            let service = capabilities::Service {
                url: &url,
                title: &r.name,
                bounds: r.bounds,
                max_side: limits.max_side,
                heights_16: r.heights_16,
                map: r.map.is_some(),
            };
            let (mime, body) = capabilities::document(&service, version);
            ([(header::CONTENT_TYPE, mime)], body).into_response()
        }
        Ok(Request::GetMap(mut map)) => {
            map.grid = on_lattice(&state, map.grid);
            answer(&state, query, get_map(&state, &map, &headers).await)
        }
        Ok(Request::GetFeatureInfo(mut info)) => {
            info.map.grid = on_lattice(&state, info.map.grid);
            answer(&state, query, feature_info(&state, &info).await)
        }
        Ok(Request::GetLegendGraphic(request)) => match legend::draw(&request, state.region().map.is_some()) {
            Ok(body) => ([(header::CONTENT_TYPE, request.format.mime())], body).into_response(),
            Err(e) => answer(&state, query, Err(ServeError::Internal(e.to_string()))),
        },
    }
}

/// What a request may ask for.
fn limits(state: &AppState) -> Limits {
    Limits { max_side: state.settings.max_size }
}

/// A map's pixel centres as the tiles' lattice computes them, where they
/// are lattice points: so a map computed whole, and the pixel a
/// GetFeatureInfo computes alone, have the values of the tiles a map is
/// stitched from (regression: 2 ulp apart at a corner of four tiles).
fn on_lattice(state: &AppState, grid: crate::grid::SampleGrid) -> crate::grid::SampleGrid {
    state.region().tiles.on_lattice(&grid).unwrap_or(grid)
}

/// A GetMap's or GetFeatureInfo's answer to `query`, or its failure as the
/// query asks exceptions to be answered.
fn answer(state: &AppState, query: &str, result: Result<Response, ServeError>) -> Response {
    let e = match result {
        Ok(response) => return response,
        Err(e) => e,
    };
    let reply = request::reply_of(query, limits(state));
    match e {
        ServeError::BadRequest(m) => {
            exception(&Exception::new(super::exception::Code::InvalidParameterValue, m), reply, state)
        }
        // The server's or an upstream's failure, with its status.
        e => {
            let (status, headers, message) = e.parts();
            failure(state, reply, (status, headers), message)
        }
    }
}

/// A request that could not be answered for `message` (the server's or an
/// upstream's failure), with `status` and `headers`: a report, or an image
/// where a GetMap asks for in-image or blank exceptions. A server too busy
/// (503) answers the report: shedding load must cost nothing, and an image
/// may be as large as a map.
fn failure(
    state: &AppState,
    reply: Reply,
    (status, mut headers): (StatusCode, HeaderMap),
    message: String,
) -> Response {
    let e = Exception::new(super::exception::Code::NoApplicableCode, message);
    let drawn = (status != StatusCode::SERVICE_UNAVAILABLE).then(|| image(&e, &reply, state)).flatten();
    let (mime, body) = drawn.unwrap_or_else(|| {
        let (mime, text) = e.report(reply.version);
        (mime, text.into_bytes())
    });
    headers.insert(header::CONTENT_TYPE, axum::http::HeaderValue::from_static(mime));
    (status, headers, body).into_response()
}

/// The values of the queried layers at the pixel, computed on the pool.
async fn feature_info(state: &AppState, info: &info::FeatureInfo) -> Result<Response, ServeError> {
    let (grid, layers) = (info::point(info), info.layers.clone());
    let values = state.tiles.run(move |region| info::values(region, &grid, &layers)).await?;
    // Longitudes wrapped into [-180, 180) (a box may reach past the antimeridian).
    let (mime, body) = info::document(&info.layers, info.pixel, info.format, info::point(info).on_globe(0, 0), &values);
    Ok(([(header::CONTENT_TYPE, mime)], body).into_response())
}

/// The report of a request refused before it was read (too long a URI, a
/// timeout), with `status`: in the version `query` asks for, never an image
/// (a refusal costs nothing).
pub fn refused(query: &str, status: StatusCode, message: String) -> Response {
    let e = Exception::new(super::exception::Code::NoApplicableCode, message);
    let (mime, body) = e.report(request::version_of(query));
    (status, [(header::CONTENT_TYPE, mime)], body).into_response()
}

/// Answers a request to `/wms` by another method than GET (or HEAD): the
/// service takes key-value pairs in the query.
pub async fn other_method() -> Response {
    let e = Exception::new(
        super::exception::Code::OperationNotSupported,
        "WMS here is GET with the query's key-value pairs",
    );
    let (mime, body) = e.report(request::Version::V130);
    (StatusCode::METHOD_NOT_ALLOWED, [(header::CONTENT_TYPE, mime), (header::ALLOW, "GET, HEAD")], body).into_response()
}

/// The absolute URL of this endpoint: configured, or from the Host header
/// (an HTTP/1.0 request may have none: `localhost` at the port listened on).
fn endpoint(state: &AppState, headers: &HeaderMap) -> String {
    format!("{}/wms", state.public_base(headers))
}

async fn get_map(state: &AppState, map: &GetMap, headers: &HeaderMap) -> Result<Response, ServeError> {
    let encoding = match map.format.data() {
        _ if map.layer.is_picture() => Encoding::Rgba,
        Some(format) => Encoding::Data(format),
        None => Encoding::Picture,
    };
    let meta = TileMeta { mime: map.format.mime(), ..meta(state, map.layer, encoding) };
    let tiles = &state.region().tiles;
    let tile = match tiles.tile_of(&map.grid) {
        Some(id) => state.tiles.get(Product::Tile { layer: map.layer, id, halo: 0, encoding }).await?,
        None => match stitched(state, map, encoding).await? {
            Some(bytes) => Arc::new(super::service::Tile::new(bytes, "stitch".into())),
            None => state.tiles.get(Product::Image { layer: map.layer, grid: map.grid, encoding }).await?,
        },
    };
    if tile.bytes.is_empty() {
        // No data here: WMS still answers with an image, empty, with the
        // headers of any other (its heights' encoding, its ETag).
        let body = inimage::blank(&map.grid, map.layer, map.format, state.region().heights_16, map.background);
        let blank = super::service::Tile::new(body, "blank".into());
        return Ok(respond::tile(&blank, &meta, headers));
    }
    let tile = match map.format.picture().filter(|_| matches!(encoding, Encoding::Rgba | Encoding::Picture)) {
        Some(format) => picture::answer(&state.tiles, tile, map.background, format).await?,
        None => tile,
    };
    Ok(respond::tile(&tile, &meta, headers))
}

/// The image stitched from cached BIL32 tiles, when its pixel centres lie on
/// a level's lattice and it needs at most [`MAX_STITCHED_TILES`] tiles.
async fn stitched(state: &AppState, map: &GetMap, encoding: Encoding) -> Result<Option<Vec<u8>>, ServeError> {
    let (MapLayer::Data(layer), Encoding::Data(format)) = (map.layer, encoding) else { return Ok(None) };
    let tiles = &state.region().tiles;
    let Some((level, gx, top)) = tiles.lattice_position(&map.grid) else { return Ok(None) };
    let n1 = (tiles.samples() - 1) as i64;
    let (w, h) = (map.grid.width() as i64, map.grid.height() as i64);
    let (rows, cols) = tiles.tiles_on_level(level);
    let (c0, c1) = (gx.div_euclid(n1), (gx + w - 2).div_euclid(n1).max(gx.div_euclid(n1)));
    let (r0, r1) = ((top - h + 1).div_euclid(n1), (top - 1).div_euclid(n1).max((top - h + 1).div_euclid(n1)));
    let count = ((c1 - c0 + 1) * (r1 - r0 + 1)) as usize;
    if c0 < 0 || r0 < 0 || c1 >= cols as i64 || r1 >= rows as i64 || count > MAX_STITCHED_TILES {
        return Ok(None);
    }
    let mut out = Raster::filled(w as usize, h as usize, f32::NAN);
    for row in r0..=r1 {
        for col in c0..=c1 {
            let id = TileId::new(level, row as u64, col as u64);
            let product = Product::Tile { layer: map.layer, id, halo: 0, encoding: Encoding::Data(Format::Bil32) };
            let tile = state.tiles.get(product).await?;
            paste(&mut out, &tile.bytes, n1, (col * n1 - gx, top - (row + 1) * n1));
        }
    }
    // BIL32 carries nodata as −32768.
    let bytes = match layer {
        Layer::Surface => {
            let classes = out
                .map(|v| if v.is_nan() || v == encode::NODATA_HEIGHT { crate::cem::surface::NODATA } else { v as u8 });
            encode::encode(layer, Samples::Class(&classes), &map.grid, format, state.region().heights_16)
        }
        _ => {
            let heights = out.map(|v| if v == encode::NODATA_HEIGHT { f32::NAN } else { v });
            encode::encode(layer, Samples::Float(&heights), &map.grid, format, state.region().heights_16)
        }
    };
    bytes.map(|e| Some(e.bytes)).map_err(ServeError::internal)
}

/// Copies a BIL32 tile (N × N, row 0 north) into `out`, the tile's
/// north-west sample landing on sample `(x0, y0)` of `out`.
fn paste(out: &mut Raster<f32>, bil32: &[u8], n1: i64, (x0, y0): (i64, i64)) {
    let n = (n1 + 1) as usize;
    let values = bil32.chunks_exact(4).map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect();
    let Some(tile) = Raster::from_vec(n, n, values) else { return };
    let Some(common) = Window::new(x0, y0, n, n).intersect(&Window::new(0, 0, out.width(), out.height())) else {
        return;
    };
    let local = Window::new(common.x - x0, common.y - y0, common.width, common.height);
    out.paste(&tile, local, common.x as usize, common.y as usize);
}

/// A bad request's exception answered as the request asked: a report
/// (400), or an image.
fn exception(e: &Exception, reply: Reply, state: &AppState) -> Response {
    match image(e, &reply, state) {
        Some((mime, body)) => ([(header::CONTENT_TYPE, mime)], body).into_response(),
        None => {
            let (mime, body) = e.report(reply.version);
            (StatusCode::BAD_REQUEST, [(header::CONTENT_TYPE, mime)], body).into_response()
        }
    }
}

/// The image that replaces the map for an in-image or blank exception, and
/// its type: the message drawn on a picture, or nodata in the layer and
/// format asked for (a picture of its background), where the request asks
/// for one and it can be made.
fn image(e: &Exception, reply: &Reply, state: &AppState) -> Option<(&'static str, Vec<u8>)> {
    let (w, h, format) = reply.image?;
    let body = match (reply.style, format.picture()) {
        (ExceptionStyle::Xml, _) => return None,
        (ExceptionStyle::InImage, Some(picture)) => inimage::message(&e.to_string(), w, h, reply.background, picture),
        _ => {
            let grid = reply.place.or_else(|| unplaced(w, h, format))?;
            let layer = reply.layer.unwrap_or(match format.picture() {
                Some(_) => MapLayer::Relief,
                None => MapLayer::Data(Layer::Dem),
            });
            inimage::blank(&grid, layer, format, state.region().heights_16, reply.background)
        }
    };
    Some((format.mime(), body))
}

/// A grid of `w × h` pixels anywhere, for a blank image whose box did not
/// parse, in a format that does not say where it lies (a GeoTIFF would say
/// it wrongly: the report instead).
fn unplaced(w: usize, h: usize, format: request::MapFormat) -> Option<crate::grid::SampleGrid> {
    let anywhere = crate::grid::BBox { west: 0.0, south: 0.0, east: 1.0, north: 1.0 };
    (format != request::MapFormat::Tiff).then(|| anywhere.area_grid(w, h).ok()).flatten()
}
