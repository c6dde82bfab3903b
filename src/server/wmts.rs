//! `/wmts`: OGC WMTS 1.0.0, for the GIS clients that read tiles by that
//! standard (QGIS, ArcGIS, OpenLayers, GDAL, OWSLib, Cesium).
//!
//! GetCapabilities (KVP at `/wmts`, or `/wmts` alone; RESTful at
//! `/wmts/1.0.0/WMTSCapabilities.xml`) lists the layers the XYZ routes serve
//! — heights as Terrarium PNG, the pictures as PNG and JPEG — in two tile
//! matrix sets of 256-pixel tiles ([`TileSet`]): `WebMercatorQuad`
//! (EPSG:3857 on the GoogleMapsCompatible scales; its tiles are the XYZ
//! tiles) and `WorldCRS84Quad` (longitude and latitude, two tiles at zoom 0;
//! it reaches the poles, so a polar region has it alone). Each set's zooms
//! run from 0 to the deepest any layer's sources are as fine as; each layer
//! gives the tiles of the region in each matrix of each set
//! (`TileMatrixSetLimits`) and a RESTful template ([`TILE_ROUTE`]). GetTile,
//! by KVP or by that path, answers a tile from the same cache as the XYZ
//! path (a Web Mercator tile is the XYZ tile, the same bytes);
//! GetFeatureInfo the values of the data under a pixel of it, as WMS
//! GetFeatureInfo does. Requests that are wrong get an OWS 1.1
//! ExceptionReport — a tile outside its layer's limits `TileOutOfRange`,
//! naming the matrix, row or column and the limits there; a tile within them
//! but off the region's data is a 404 without body (GDAL draws it empty),
//! as on the XYZ path.

use super::exception::{Code, Exception, escape};
use super::extent::{Extent, extent};
use super::products::Product;
use super::query::Params;
use super::routes::quad_tile;
use super::wms::capabilities::title;
use super::wms::info::{self, InfoFormat};
use super::wms::picture::PictureFormat;
use super::wms::request::{LAYERS, MapLayer};
use super::wms::{self, legend};
use super::{AppState, ServeError};
use crate::grid::mercator::HALF_WORLD_M;
use crate::grid::quad::{SIDE, TileSet};
use crate::region::Region;
use axum::extract::rejection::PathRejection;
use axum::extract::{Path, RawQuery, State};
use axum::http::{HeaderMap, StatusCode, header};
use axum::response::{IntoResponse, Response};
use std::fmt::Write;
use std::sync::Arc;

/// The RESTful GetTile path, the capabilities' template for every layer,
/// set and format (`{file}` is `{TileCol}.png` or `.jpg`).
pub const TILE_ROUTE: &str = "/wmts/1.0.0/{layer}/{style}/{set}/{z}/{row}/{file}";

/// Answers a WMTS KVP request.
pub async fn handle(State(state): State<Arc<AppState>>, RawQuery(query): RawQuery, headers: HeaderMap) -> Response {
    match parse(query.as_deref().unwrap_or(""), &|layer, set| extent(state.region(), layer, set)) {
        Err(e) => exception(&e, StatusCode::BAD_REQUEST),
        Ok(Request::Capabilities) => capabilities(&state, &headers),
        Ok(Request::Tile(t)) => tile(&state, &t, &headers).await,
        Ok(Request::FeatureInfo(t, pixel)) => feature_info(&state, &t, &pixel).await.unwrap_or_else(failure),
    }
}

/// The parts of a RESTful GetTile's path, by [`TILE_ROUTE`]'s names.
#[derive(serde::Deserialize)]
pub struct TilePath {
    layer: String,
    style: String,
    set: String,
    z: String,
    row: String,
    file: String,
}

/// Answers a RESTful GetTile ([`TILE_ROUTE`]), checked as its KVP form is.
pub async fn rest_tile(
    State(state): State<Arc<AppState>>,
    path: Result<Path<TilePath>, PathRejection>,
    headers: HeaderMap,
) -> Response {
    let Ok(Path(TilePath { layer, style, set, z, row, file })) = path else {
        let e = Exception::new(Code::InvalidParameterValue, "the tile path is not UTF-8 text");
        return exception(&e, StatusCode::BAD_REQUEST);
    };
    let Some((col, ext)) = file.rsplit_once('.') else {
        let message = format!("the tile's file {file:?} needs an extension: {{TileCol}}.png or .jpg");
        return exception(&invalid("FORMAT", message), StatusCode::BAD_REQUEST);
    };
    let format = PictureFormat::of_extension(ext).map_or_else(|| format!(".{ext}"), |f| f.mime().to_string());
    let params = Params::of([
        ("LAYER", layer.as_str()),
        ("STYLE", &style),
        ("FORMAT", &format),
        ("TILEMATRIXSET", &set),
        ("TILEMATRIX", &z),
        ("TILEROW", &row),
        ("TILECOL", col),
    ]);
    match tile_request(&params, &|layer, set| extent(state.region(), layer, set), Needs::Tile) {
        Ok(t) => tile(&state, &t, &headers).await,
        Err(e) => exception(&e, StatusCode::BAD_REQUEST),
    }
}

/// A GetTile's tile, from the cache or computed.
async fn tile(state: &AppState, t: &TileRequest, headers: &HeaderMap) -> Response {
    quad_tile(state, t.layer, t.set, t.zxy, t.picture, headers).await.unwrap_or_else(failure)
}

/// The values of the data a tile shows at one of its pixels, computed on
/// that pixel of the tile's grid (the value the tile shows there).
async fn feature_info(state: &AppState, t: &TileRequest, pixel: &Pixel) -> Result<Response, ServeError> {
    let product = Product::Quad { layer: t.layer, set: t.set, zxy: t.zxy };
    let (x, y) = pixel.at;
    let grid = product
        .grid(state.region())
        .map_err(|e| ServeError::BadRequest(e.to_string()))?
        .slice(x as i64, y as i64, 1, 1);
    let layers = info::shows(t.layer);
    let queried = layers.clone();
    let values = state.tiles.run(move |region| info::values(region, &grid, &queried)).await?;
    let (mime, body) = info::document(&layers, pixel.at, pixel.format, grid.on_globe(0, 0), &values);
    Ok(([(header::CONTENT_TYPE, mime)], body).into_response())
}

/// `/wmts/1.0.0/WMTSCapabilities.xml`: the capabilities, RESTful.
pub async fn capabilities_file(State(state): State<Arc<AppState>>, headers: HeaderMap) -> Response {
    capabilities(&state, &headers)
}

/// Answers a request to `/wmts` by another method than GET (or HEAD): KVP
/// and RESTful requests only, no SOAP.
pub async fn other_method() -> Response {
    let e = Exception::new(Code::OperationNotSupported, "WMTS here is GET: key-value pairs, or the RESTful paths");
    let (mime, body) = e.ows_report();
    (StatusCode::METHOD_NOT_ALLOWED, [(header::CONTENT_TYPE, mime), (header::ALLOW, "GET, HEAD")], body).into_response()
}

/// The report of a request refused before it was read (too long a URI, a
/// timeout), with `status`.
pub fn refused(status: StatusCode, message: String) -> Response {
    exception(&Exception::new(Code::NoApplicableCode, message), status)
}

/// What a KVP request asks for.
#[derive(Debug, PartialEq)]
enum Request {
    Capabilities,
    Tile(TileRequest),
    FeatureInfo(TileRequest, Pixel),
}

/// A GetFeatureInfo's pixel of its tile (column, row from the top left)
/// and the answer's format.
#[derive(Debug, PartialEq)]
struct Pixel {
    at: (usize, usize),
    format: InfoFormat,
}

/// One tile: the layer, its set, zoom, column and row, and picture format
/// (none: Terrarium PNG heights).
#[derive(Debug, PartialEq)]
struct TileRequest {
    layer: MapLayer,
    set: TileSet,
    zxy: (u32, u64, u64),
    picture: Option<PictureFormat>,
}

/// Each layer's extent in each matrix set (none: a set not offered): its
/// limits, and those of the sets (a set ends at its layers' deepest zoom).
type Limits<'a> = dyn Fn(MapLayer, TileSet) -> Option<Extent> + 'a;

/// Reads a KVP query (keys in any case) to the `limits` of the layers' tiles;
/// none at all asks for the capabilities (GDAL's `WMTS:` of the bare
/// endpoint asks so).
fn parse(query: &str, limits: &Limits) -> Result<Request, Exception> {
    if query.trim().is_empty() {
        return Ok(Request::Capabilities);
    }
    let params = Params::new(query);
    if let Some((key, message)) = params.conflict() {
        return Err(Exception::new(Code::InvalidParameterValue, message).locator(key));
    }
    let service = required(&params, "SERVICE")?;
    if !service.eq_ignore_ascii_case("WMTS") {
        return Err(invalid("SERVICE", format!("this endpoint is WMTS, not {service:?}")));
    }
    match required(&params, "REQUEST")? {
        r if r.eq_ignore_ascii_case("GetCapabilities") => accepts_ours(&params).map(|()| Request::Capabilities),
        r if r.eq_ignore_ascii_case("GetTile") => tile_request(&params, limits, Needs::Tile).map(Request::Tile),
        r if r.eq_ignore_ascii_case("GetFeatureInfo") => {
            Ok(Request::FeatureInfo(tile_request(&params, limits, Needs::Values)?, pixel(&params)?))
        }
        r => Err(Exception::new(
            Code::OperationNotSupported,
            format!("request {r:?} is not offered: GetCapabilities, GetTile or GetFeatureInfo"),
        )
        .locator("REQUEST")),
    }
}

/// A GetCapabilities's `AcceptVersions`, if given, includes 1.0.0 (OWS
/// Common 1.1 §7.3.2).
fn accepts_ours(params: &Params) -> Result<(), Exception> {
    match params.get("ACCEPTVERSIONS") {
        Some(list) if !list.split(',').any(|v| v.trim() == "1.0.0") => Err(Exception::new(
            Code::VersionNegotiationFailed,
            format!("AcceptVersions {list:?}: this server offers WMTS 1.0.0"),
        )
        .locator("AcceptVersions")),
        _ => Ok(()),
    }
}

/// What a request needs of its tile.
#[derive(Clone, Copy, PartialEq)]
enum Needs {
    /// Its bytes (GetTile).
    Tile,
    /// The values under a pixel (GetFeatureInfo).
    Values,
}

/// A GetTile's parameters checked: the layer, style, format and matrix set
/// offered, the tile within its matrix and the layer's limits there.
fn tile_request(params: &Params, limits: &Limits, needs: Needs) -> Result<TileRequest, Exception> {
    if let Some(v) = params.get("VERSION").filter(|v| v.trim() != "1.0.0") {
        return Err(invalid("VERSION", format!("version {v:?} is not offered: 1.0.0")));
    }
    let name = required(params, "LAYER")?;
    let layer = offered().find(|l| l.name().eq_ignore_ascii_case(name.trim())).ok_or_else(|| {
        let names: Vec<&str> = offered().map(MapLayer::name).collect();
        invalid("LAYER", format!("no layer {name:?}: {}", names.join(", ")))
    })?;
    // STYLE is required by the standard; a client leaving it out means the one style.
    if let Some(style) = params.get("STYLE").filter(|s| !s.is_empty() && !s.eq_ignore_ascii_case("default")) {
        return Err(invalid("STYLE", format!("no style {style:?}: each layer has one, \"default\"")));
    }
    // A GetFeatureInfo's values do not depend on the tile's format, and
    // GDAL leaves it out there.
    let format = match (params.get("FORMAT"), needs) {
        (None, Needs::Values) => mime(encodings(layer)[0]),
        _ => required(params, "FORMAT")?,
    };
    let picture =
        *encodings(layer).iter().find(|&&e| mime(e).eq_ignore_ascii_case(format.trim())).ok_or_else(|| {
            let offered: Vec<&str> = encodings(layer).iter().map(|&e| mime(e)).collect();
            invalid("FORMAT", format!("{} tiles are {}, not {format:?}", layer.name(), offered.join(" or ")))
        })?;
    let name = required(params, "TILEMATRIXSET")?;
    // The layer's extent in a set offered (a set is offered for every layer or none).
    let offered_set = |set| Some((set, deepest(limits, set)?, limits(layer, set)?));
    let (set, last, extent) = TileSet::parse(name).and_then(offered_set).ok_or_else(|| {
        let names: Vec<&str> =
            TileSet::ALL.iter().filter(|&&s| deepest(limits, s).is_some()).map(|s| s.name()).collect();
        invalid("TILEMATRIXSET", format!("no tile matrix set {name:?}: {}", names.join(", ")))
    })?;
    let z = number(params, "TILEMATRIX")?;
    let z = u32::try_from(z)
        .ok()
        .filter(|&z| z <= last)
        .ok_or_else(|| invalid("TILEMATRIX", format!("no tile matrix {z} in {}: 0 to {last}", set.name())))?;
    let (row, col) = (number(params, "TILEROW")?, number(params, "TILECOL")?);
    let (cols, rows) = set.matrix(z);
    for (value, key, n) in [(row, "TILEROW", rows), (col, "TILECOL", cols)] {
        if value >= n {
            let message = format!("{key} {value} is outside tile matrix {z}: 0 to {}", n - 1);
            return Err(Exception::new(Code::TileOutOfRange, message).locator(key));
        }
    }
    let zxy = (z, col, row);
    match extent.holds(set, zxy) {
        true => Ok(TileRequest { layer, set, zxy, picture }),
        false => Err(outside_limits(layer, set, &extent, zxy)),
    }
}

/// The error of a tile outside a layer's limits: its row, or else its
/// column, outside them.
fn outside_limits(layer: MapLayer, set: TileSet, e: &Extent, (z, col, row): (u32, u64, u64)) -> Exception {
    let ((c0, r0), (c1, r1)) = set.tiles_over(&e.bounds, z);
    let (key, value, first, last) =
        if (r0..=r1).contains(&row) { ("TILECOL", col, c0, c1) } else { ("TILEROW", row, r0, r1) };
    let message = format!("{key} {value} is outside {}'s limits in tile matrix {z}: {first} to {last}", layer.name());
    Exception::new(Code::TileOutOfRange, message).locator(key)
}

/// A GetFeatureInfo's pixel (`I`, `J`) and `INFOFORMAT`.
fn pixel(params: &Params) -> Result<Pixel, Exception> {
    let mut at = [0; 2];
    for (value, key) in at.iter_mut().zip(["I", "J"]) {
        let text = required(params, key)?;
        let whole: i64 =
            text.trim().parse().map_err(|_| invalid(key, format!("{key} must be a whole number, not {text:?}")))?;
        *value = usize::try_from(whole).ok().filter(|&v| v < SIDE).ok_or_else(|| {
            let message = format!("{key}={whole} is off the tile: 0 to {}", SIDE - 1);
            Exception::new(Code::PointIjOutOfRange, message).locator(key)
        })?;
    }
    let text = required(params, "INFOFORMAT")?;
    let offered = || InfoFormat::ALL.map(|(_, m)| m).join(", ");
    let format =
        InfoFormat::parse(text).ok_or_else(|| invalid("INFOFORMAT", format!("{text:?}: offered are {}", offered())))?;
    Ok(Pixel { at: (at[0], at[1]), format })
}

/// A parameter that must be given.
fn required<'a>(params: &'a Params, key: &str) -> Result<&'a str, Exception> {
    params
        .get(key)
        .filter(|v| !v.trim().is_empty())
        .ok_or_else(|| Exception::new(Code::MissingParameterValue, format!("{key} is missing")).locator(key))
}

/// A parameter that must be a whole number.
fn number(params: &Params, key: &str) -> Result<u64, Exception> {
    let text = required(params, key)?;
    text.trim().parse().map_err(|_| invalid(key, format!("{key} must be a whole number, not {text:?}")))
}

fn invalid(key: &str, message: String) -> Exception {
    Exception::new(Code::InvalidParameterValue, message).locator(key)
}

/// The layers offered: those with XYZ tiles.
pub fn offered() -> impl Iterator<Item = MapLayer> {
    LAYERS.into_iter().filter(|l| l.in_quad_tiles())
}

/// The matrix sets offered, those that hold the region (not Web Mercator
/// around a pole), and the deepest zoom of each.
fn sets(region: &Region) -> impl Iterator<Item = (TileSet, u32)> + '_ {
    TileSet::ALL.into_iter().filter_map(|set| Some((set, deepest_matrix(region, set)?)))
}

/// The deepest matrix of `set` served over `region` (none: the set is not
/// offered there).
pub fn deepest_matrix(region: &Region, set: TileSet) -> Option<u32> {
    deepest(&|layer, set| extent(region, layer, set), set)
}

/// The deepest zoom of a matrix set: the deepest a layer's sources are as
/// fine as (clients such as GDAL take the last matrix for the full
/// resolution; they draw deeper views from it); none where the set does not
/// hold the region.
fn deepest(limits: &Limits, set: TileSet) -> Option<u32> {
    offered().filter_map(|l| limits(l, set)).map(|e| e.max_zoom).max()
}

/// A layer's tile encodings: Terrarium PNG heights (`None`), or the
/// picture formats.
fn encodings(layer: MapLayer) -> &'static [Option<PictureFormat>] {
    if layer.is_picture() { &[Some(PictureFormat::Png), Some(PictureFormat::Jpeg)] } else { &[None] }
}

/// An encoding's MIME type.
fn mime(encoding: Option<PictureFormat>) -> &'static str {
    encoding.map_or("image/png", PictureFormat::mime)
}

/// An exception report with `status` (501 for an operation not offered).
fn exception(e: &Exception, status: StatusCode) -> Response {
    let status = if e.code == Code::OperationNotSupported { StatusCode::NOT_IMPLEMENTED } else { status };
    let (mime, body) = e.ows_report();
    (status, [(header::CONTENT_TYPE, mime)], body).into_response()
}

/// A tile that could not be answered: none there (404, as on the XYZ
/// path), or a report with the error's status and headers.
fn failure(e: ServeError) -> Response {
    match e {
        ServeError::NotFound => StatusCode::NOT_FOUND.into_response(),
        ServeError::BadRequest(m) => {
            exception(&Exception::new(Code::InvalidParameterValue, m), StatusCode::BAD_REQUEST)
        }
        e => {
            let (status, headers, message) = e.parts();
            let (mime, body) = Exception::new(Code::NoApplicableCode, message).ows_report();
            (status, headers, [(header::CONTENT_TYPE, mime)], body).into_response()
        }
    }
}

/// The capabilities, their URLs under the server's public base.
fn capabilities(state: &AppState, headers: &HeaderMap) -> Response {
    let body = document(state.region(), &state.public_base(headers));
    ([(header::CONTENT_TYPE, "application/xml")], body).into_response()
}

/// The capabilities document of `region` served under `base`.
fn document(region: &Region, base: &str) -> String {
    let layers: String = offered().map(|l| layer(region, l, base)).collect();
    let matrix_sets: String = sets(region).map(|(set, deepest)| matrix_set(set, deepest)).collect();
    format!(
        r#"<?xml version="1.0" encoding="UTF-8"?>
<Capabilities xmlns="http://www.opengis.net/wmts/1.0" xmlns:ows="http://www.opengis.net/ows/1.1" xmlns:xlink="http://www.w3.org/1999/xlink" xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance" xsi:schemaLocation="http://www.opengis.net/wmts/1.0 http://schemas.opengis.net/wmts/1.0/wmtsGetCapabilities_response.xsd" version="1.0.0">
<ows:ServiceIdentification><ows:Title>{title}</ows:Title><ows:Abstract>Combined elevation maps (terrain + forest canopy) computed on demand by Sylva.</ows:Abstract><ows:ServiceType>OGC WMTS</ows:ServiceType><ows:ServiceTypeVersion>1.0.0</ows:ServiceTypeVersion></ows:ServiceIdentification>
<ows:OperationsMetadata>{get_capabilities}{get_tile}{get_feature_info}</ows:OperationsMetadata>
<Contents>
{layers}{matrix_sets}</Contents>
<ServiceMetadataURL xlink:href="{base}/wmts/1.0.0/WMTSCapabilities.xml"/>
</Capabilities>
"#,
        title = escape(&region.name),
        base = escape(base),
        get_capabilities = operation("GetCapabilities", base),
        get_tile = operation("GetTile", base),
        get_feature_info = operation("GetFeatureInfo", base),
    )
}

/// An operation, by KVP at `/wmts`.
fn operation(name: &str, base: &str) -> String {
    format!(
        r#"<ows:Operation name="{name}"><ows:DCP><ows:HTTP><ows:Get xlink:href="{}/wmts?"><ows:Constraint name="GetEncoding"><ows:AllowedValues><ows:Value>KVP</ows:Value></ows:AllowedValues></ows:Constraint></ows:Get></ows:HTTP></ows:DCP></ows:Operation>"#,
        escape(base)
    )
}

/// The `LegendURL` of layer `l`: its WMS GetLegendGraphic.
fn legend_url(region: &Region, l: MapLayer, base: &str) -> String {
    let (w, h) = legend::size(l, region.map.is_some(), (legend::SWATCH_PX, legend::SWATCH_PX));
    let href = wms::capabilities::legend_url(&format!("{base}/wms"), l, wms::request::Version::V130);
    format!(r#"<LegendURL format="image/png" xlink:href="{}" width="{w}" height="{h}"/>"#, escape(&href))
}

/// One layer of `region`: its box, style, formats, each set's limits and
/// the RESTful templates.
fn layer(region: &Region, l: MapLayer, base: &str) -> String {
    let b = region.bounds.on_the_globe();
    let about = if l.is_picture() {
        "PNG with transparency where there is no data, or JPEG on white.".to_string()
    } else {
        let zooms: Vec<String> = sets(region)
            .filter_map(|(set, _)| Some(format!("zoom {} of {}", extent(region, l, set)?.max_zoom, set.name())))
            .collect();
        format!(
            "Heights in metres, Terrarium PNG: h = R * 256 + G + B / 256 - 32768 (black: no data). Tiles deeper than {} are resampled from the sources.",
            zooms.join(", ")
        )
    };
    let mut out = format!(
        r#"<Layer><ows:Title>{}</ows:Title><ows:Abstract>{about}</ows:Abstract><ows:WGS84BoundingBox><ows:LowerCorner>{} {}</ows:LowerCorner><ows:UpperCorner>{} {}</ows:UpperCorner></ows:WGS84BoundingBox><ows:Identifier>{}</ows:Identifier><Style isDefault="true"><ows:Identifier>default</ows:Identifier>{}</Style>"#,
        title(l),
        b.west,
        b.south,
        b.east,
        b.north,
        l.name(),
        legend_url(region, l, base)
    );
    for &encoding in encodings(l) {
        let _ = write!(out, "<Format>{}</Format>", mime(encoding));
    }
    for (_, format) in InfoFormat::ALL {
        let _ = write!(out, "<InfoFormat>{format}</InfoFormat>");
    }
    for (set, deepest) in sets(region) {
        if let Some(e) = extent(region, l, set) {
            out.push_str(&link(set, &e, deepest));
        }
    }
    for &encoding in encodings(l) {
        let ext = encoding.map_or("png", PictureFormat::extension);
        // TILE_ROUTE's path.
        let template = format!(
            "{base}/wmts/1.0.0/{}/default/{{TileMatrixSet}}/{{TileMatrix}}/{{TileRow}}/{{TileCol}}.{ext}",
            l.name()
        );
        let format = mime(encoding);
        let _ = write!(out, r#"<ResourceURL format="{format}" resourceType="tile" template="{}"/>"#, escape(&template));
    }
    out.push_str("</Layer>\n");
    out
}

/// A layer's link to `set`: the tiles over its extent in each of the set's
/// matrices, 0 to `deepest` (the standard wants limits for all of them;
/// GDAL reads every layer at the set's deepest).
fn link(set: TileSet, extent: &Extent, deepest: u32) -> String {
    let mut out = format!("<TileMatrixSetLink><TileMatrixSet>{}</TileMatrixSet><TileMatrixSetLimits>", set.name());
    for z in 0..=deepest {
        let ((c0, r0), (c1, r1)) = set.tiles_over(&extent.bounds, z);
        let _ = write!(
            out,
            "<TileMatrixLimits><TileMatrix>{z}</TileMatrix><MinTileRow>{r0}</MinTileRow><MaxTileRow>{r1}</MaxTileRow><MinTileCol>{c0}</MinTileCol><MaxTileCol>{c1}</MaxTileCol></TileMatrixLimits>"
        );
    }
    out.push_str("</TileMatrixSetLimits></TileMatrixSetLink>");
    out
}

/// A tile matrix set, zooms 0 to `deepest`: its CRS, its well-known scale
/// set if it has one, and the corner its matrices start at (in the CRS's
/// axis order: CRS84's is longitude first).
fn matrix_set(set: TileSet, deepest: u32) -> String {
    let (crs, scales, corner) = match set {
        TileSet::WebMercator => (
            "urn:ogc:def:crs:EPSG::3857",
            "<WellKnownScaleSet>urn:ogc:def:wkss:OGC:1.0:GoogleMapsCompatible</WellKnownScaleSet>",
            format!("{} {HALF_WORLD_M}", -HALF_WORLD_M),
        ),
        TileSet::Crs84 => ("urn:ogc:def:crs:OGC:1.3:CRS84", "", "-180 90".to_string()),
    };
    let mut out = format!(
        "<TileMatrixSet><ows:Identifier>{}</ows:Identifier><ows:SupportedCRS>{crs}</ows:SupportedCRS>{scales}\n",
        set.name()
    );
    for z in 0..=deepest {
        let (cols, rows) = set.matrix(z);
        let _ = writeln!(
            out,
            "<TileMatrix><ows:Identifier>{z}</ows:Identifier><ScaleDenominator>{}</ScaleDenominator><TopLeftCorner>{corner}</TopLeftCorner><TileWidth>{SIDE}</TileWidth><TileHeight>{SIDE}</TileHeight><MatrixWidth>{cols}</MatrixWidth><MatrixHeight>{rows}</MatrixHeight></TileMatrix>",
            set.scale_denominator(z),
        );
    }
    out.push_str("</TileMatrixSet>\n");
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cem::Layer;
    use crate::grid::BBox;
    use crate::server::MAX_XYZ_ZOOM;

    /// Every layer over the whole globe, zooms 0 to `deepest`.
    fn world(deepest: u32) -> Option<Extent> {
        Some(Extent { bounds: BBox::WORLD, min_zoom: 0, max_zoom: deepest })
    }

    fn tile(query: &str) -> Result<TileRequest, Exception> {
        match parse(query, &|_, _| world(MAX_XYZ_ZOOM))? {
            Request::Tile(t) => Ok(t),
            other => panic!("{other:?}"),
        }
    }

    const RELIEF: &str = "SERVICE=WMTS&REQUEST=GetTile&VERSION=1.0.0&LAYER=relief&STYLE=default&FORMAT=image/jpeg&TILEMATRIXSET=WebMercatorQuad&TILEMATRIX=12&TILEROW=1449&TILECOL=2161";

    #[test]
    fn a_get_tile_is_the_tile_of_its_set_matrix_column_and_row() {
        let t = tile(RELIEF).unwrap();
        let relief = TileRequest {
            layer: MapLayer::Relief,
            set: TileSet::WebMercator,
            zxy: (12, 2161, 1449),
            picture: Some(PictureFormat::Jpeg),
        };
        assert_eq!(t, relief);
        // Keys and names in any case; heights are Terrarium PNG.
        let t = tile("service=wmts&request=gettile&layer=CEM&format=image/png&tilematrixset=WebMercatorQuad&tilematrix=0&tilerow=0&tilecol=0").unwrap();
        let cem =
            TileRequest { layer: MapLayer::Data(Layer::Cem), set: TileSet::WebMercator, zxy: (0, 0, 0), picture: None };
        assert_eq!(t, cem);
        // Geographic tiles: twice as many columns as rows.
        let crs84 = RELIEF.replace("WebMercatorQuad", "WorldCRS84Quad").replace("TILECOL=2161", "TILECOL=8191");
        assert_eq!(tile(&crs84).unwrap(), TileRequest { set: TileSet::Crs84, zxy: (12, 8191, 1449), ..relief });
        let none = |_, _| world(0);
        assert_eq!(parse("SERVICE=WMTS&REQUEST=GetCapabilities", &none).unwrap(), Request::Capabilities);
        assert_eq!(parse("", &none).unwrap(), Request::Capabilities);
        // The pixel of a GetFeatureInfo.
        let info = format!("{}&I=255&J=0&INFOFORMAT=application/json", RELIEF.replace("GetTile", "GetFeatureInfo"));
        let Request::FeatureInfo(t, pixel) = parse(&info, &|_, _| world(MAX_XYZ_ZOOM)).unwrap() else {
            panic!("{info}")
        };
        assert_eq!((t.zxy, pixel), ((12, 2161, 1449), Pixel { at: (255, 0), format: InfoFormat::Json }));
    }

    #[test]
    fn tiles_outside_a_layers_limits_are_out_of_range() {
        // The demo's box, zooms 3 to 14: tile matrix 12 holds its columns
        // 2161 to 2164 and rows 1449 to 1452 (independently: the
        // fractional tiles of its corners are 2161.8, 1449.8 and 2164.6,
        // 1452.3).
        let bounds = BBox { west: 10.0, south: 46.3, east: 10.25, north: 46.45 };
        let demo = |_, _| Some(Extent { bounds, min_zoom: 3, max_zoom: 14 });
        let at = |z: u32, row: u64, col: u64| {
            let q = RELIEF.replace(
                "TILEMATRIX=12&TILEROW=1449&TILECOL=2161",
                &format!("TILEMATRIX={z}&TILEROW={row}&TILECOL={col}"),
            );
            parse(&q, &demo).map(|_| ()).map_err(|e| (e.code, e.locator.unwrap_or_default(), e.message))
        };
        assert!(at(12, 1449, 2161).is_ok() && at(12, 1452, 2164).is_ok());
        let (code, locator, message) = at(12, 1453, 2161).unwrap_err();
        assert_eq!((code, locator.as_str()), (Code::TileOutOfRange, "TILEROW"));
        assert!(message.contains("relief's limits in tile matrix 12: 1449 to 1452"), "{message}");
        let (code, locator, message) = at(12, 1449, 2160).unwrap_err();
        assert_eq!((code, locator.as_str()), (Code::TileOutOfRange, "TILECOL"));
        assert!(message.contains("2161 to 2164"), "{message}");
        // Limits hold at every matrix of the set: above the layer's
        // shallowest zoom (the region under a pixel) and past its deepest
        // within the set's (GDAL reads every layer at the set's deepest).
        assert!(at(0, 0, 0).is_ok() && at(2, 1, 2).is_ok());
        assert_eq!(at(2, 0, 2).unwrap_err().1, "TILEROW");
        let two = |layer: MapLayer, _| {
            Some(Extent { bounds, min_zoom: 3, max_zoom: if layer.is_picture() { 14 } else { 13 } })
        };
        let dem = RELIEF.replace("LAYER=relief", "LAYER=dem").replace("image/jpeg", "image/png");
        let deep = dem.replace("TILEMATRIX=12&TILEROW=1449&TILECOL=2161", "TILEMATRIX=14&TILEROW=5800&TILECOL=8650");
        assert!(parse(&deep, &two).is_ok());
        let e = parse(&deep.replace("TILECOL=8650", "TILECOL=8659"), &two).unwrap_err();
        assert_eq!((e.code, e.locator.as_deref()), (Code::TileOutOfRange, Some("TILECOL")), "{e}");
    }

    #[test]
    fn wrong_requests_name_the_code_and_the_parameter() {
        let fails = |query: String, code: Code, locator: &str| {
            let e = parse(&query, &|_, _| world(MAX_XYZ_ZOOM)).unwrap_err();
            assert_eq!((e.code, e.locator.as_deref()), (code, Some(locator)), "{query}: {e}");
        };
        let with = |key: &str, value: &str| RELIEF.replace(&format!("{key}="), &format!("{key}={value}&X{key}="));
        fails(RELIEF.replace("SERVICE=WMTS&", ""), Code::MissingParameterValue, "SERVICE");
        fails(RELIEF.replace("SERVICE=WMTS", "SERVICE=WMS"), Code::InvalidParameterValue, "SERVICE");
        fails(RELIEF.replace("GetTile", "DescribeDomains"), Code::OperationNotSupported, "REQUEST");
        let info = format!("{}&INFOFORMAT=text/plain", RELIEF.replace("GetTile", "GetFeatureInfo"));
        fails(format!("{info}&J=0"), Code::MissingParameterValue, "I");
        fails(format!("{info}&I=256&J=0"), Code::PointIjOutOfRange, "I");
        fails(format!("{info}&I=0&J=-1"), Code::PointIjOutOfRange, "J");
        fails(format!("{info}&I=0&J=x"), Code::InvalidParameterValue, "J");
        fails(format!("{info}&I=0&J=0").replace("text/plain", "image/png"), Code::InvalidParameterValue, "INFOFORMAT");
        // FORMAT may be left out of a GetFeatureInfo (GDAL does), not a GetTile.
        fails(RELIEF.replace("&FORMAT=image/jpeg", ""), Code::MissingParameterValue, "FORMAT");
        assert!(
            parse(&format!("{info}&I=0&J=0").replace("&FORMAT=image/jpeg", ""), &|_, _| world(MAX_XYZ_ZOOM)).is_ok()
        );
        // Each matrix set ends at its deepest zoom served.
        let deepest = |_, set| world(if set == TileSet::WebMercator { 11 } else { 12 });
        let e = parse(RELIEF, &deepest).unwrap_err();
        assert_eq!((e.code, e.locator.as_deref()), (Code::InvalidParameterValue, Some("TILEMATRIX")));
        assert!(parse(&RELIEF.replace("WebMercatorQuad", "WorldCRS84Quad"), &deepest).is_ok());
        // A set not offered (Web Mercator around a pole) is no set.
        let polar = |_, set| world(12).filter(|_| set == TileSet::Crs84);
        let e = parse(RELIEF, &polar).unwrap_err();
        assert_eq!((e.code, e.locator.as_deref()), (Code::InvalidParameterValue, Some("TILEMATRIXSET")));
        let crs84 = |key: &str, value: &str| {
            let query = with(key, value).replace("WebMercatorQuad", "WorldCRS84Quad");
            fails(query, Code::TileOutOfRange, key);
        };
        crs84("TILEROW", "4096");
        crs84("TILECOL", "8192");
        fails(with("VERSION", "2.0.0"), Code::InvalidParameterValue, "VERSION");
        let capabilities = |accepted: &str| {
            parse(&format!("SERVICE=WMTS&REQUEST=GetCapabilities{accepted}"), &|_, _| world(MAX_XYZ_ZOOM))
        };
        assert!(matches!(capabilities("&AcceptVersions=2.0.0,1.0.0"), Ok(Request::Capabilities)));
        let Err(e) = capabilities("&ACCEPTVERSIONS=2.0.0") else { panic!("2.0.0 alone accepted") };
        assert_eq!((e.code, e.locator.as_deref()), (Code::VersionNegotiationFailed, Some("AcceptVersions")));
        fails(with("LAYER", "cover"), Code::InvalidParameterValue, "LAYER");
        fails(with("STYLE", "dark"), Code::InvalidParameterValue, "STYLE");
        fails(with("FORMAT", "image/tiff"), Code::InvalidParameterValue, "FORMAT");
        fails(
            RELIEF.replace("LAYER=relief&STYLE=default&FORMAT=image/jpeg", "LAYER=dem&FORMAT=image/jpeg"),
            Code::InvalidParameterValue,
            "FORMAT",
        );
        fails(with("TILEMATRIXSET", "GoogleCRS84Quad"), Code::InvalidParameterValue, "TILEMATRIXSET");
        fails(with("TILEMATRIX", "25"), Code::InvalidParameterValue, "TILEMATRIX");
        fails(with("TILEROW", "-1"), Code::InvalidParameterValue, "TILEROW");
        fails(with("TILEROW", "4096"), Code::TileOutOfRange, "TILEROW");
        fails(with("TILECOL", "4096"), Code::TileOutOfRange, "TILECOL");
        fails(RELIEF.replace("&TILECOL=2161", ""), Code::MissingParameterValue, "TILECOL");
        fails(format!("{RELIEF}&LAYER=dem"), Code::InvalidParameterValue, "LAYER");
        // STYLE may be left out (the one style).
        assert!(tile(&RELIEF.replace("STYLE=default&", "")).is_ok());
    }

    /// The text of `n`'s first child named `tag`.
    fn child(n: roxmltree::Node, tag: &str) -> String {
        n.children().find(|c| c.tag_name().name() == tag).and_then(|c| c.text()).unwrap_or_default().to_string()
    }

    /// The names of the sets `n` (a layer or the contents) has.
    fn set_names(n: roxmltree::Node, tag: &str) -> Vec<String> {
        n.descendants().filter(|c| c.has_tag_name(tag)).map(|c| child(c, "TileMatrixSet")).collect()
    }

    /// Column and row of the tile of `set` at zoom `z` holding a point,
    /// computed here from the sets' definitions.
    fn tile_at(set: TileSet, z: u32, lon: f64, lat: f64) -> (u64, u64) {
        let n = f64::from(1u32 << z);
        match set {
            TileSet::WebMercator => {
                let lat = lat.to_radians();
                let row = (1.0 - (lat.tan() + 1.0 / lat.cos()).ln() / std::f64::consts::PI) / 2.0 * n;
                (((lon + 180.0) / 360.0 * n).floor() as u64, row.floor() as u64)
            }
            TileSet::Crs84 => (((lon + 180.0) / 180.0 * n).floor() as u64, ((90.0 - lat) / 180.0 * n).floor() as u64),
        }
    }

    #[test]
    fn the_capabilities_give_each_layer_the_tiles_over_the_region_in_both_sets() {
        let region = crate::config::load(None).unwrap();
        let xml = document(&region, "http://h:1");
        let doc = roxmltree::Document::parse(&xml).unwrap();
        let layers: Vec<_> = doc.descendants().filter(|n| n.has_tag_name("Layer")).collect();
        let names: Vec<String> = layers.iter().map(|&l| child(l, "Identifier")).collect();
        assert_eq!(names, ["dem", "canopy", "cem", "colour", "relief"]);
        let relief = layers[4];
        let templates: Vec<&str> = relief
            .children()
            .filter(|n| n.has_tag_name("ResourceURL"))
            .filter_map(|n| n.attribute("template"))
            .collect();
        assert_eq!(
            templates,
            [
                "http://h:1/wmts/1.0.0/relief/default/{TileMatrixSet}/{TileMatrix}/{TileRow}/{TileCol}.png",
                "http://h:1/wmts/1.0.0/relief/default/{TileMatrixSet}/{TileMatrix}/{TileRow}/{TileCol}.jpg"
            ]
        );
        assert_eq!(set_names(relief, "TileMatrixSetLink"), ["WebMercatorQuad", "WorldCRS84Quad"]);
        // Each zoom's limits are the tiles holding the region's corners.
        let b = region.bounds;
        for link in relief.children().filter(|n| n.has_tag_name("TileMatrixSetLink")) {
            let set = TileSet::parse(&child(link, "TileMatrixSet")).unwrap();
            let extent = extent(&region, MapLayer::Relief, set).unwrap();
            let limits: Vec<_> = link.descendants().filter(|n| n.has_tag_name("TileMatrixLimits")).collect();
            let deepest = deepest_matrix(&region, set).unwrap();
            assert!(deepest >= extent.max_zoom);
            assert_eq!(limits.len() as u32, deepest + 1, "every matrix of the set");
            for l in limits {
                let z: u32 = child(l, "TileMatrix").parse().unwrap();
                let ((c0, r0), (c1, r1)) = (tile_at(set, z, b.west, b.north), tile_at(set, z, b.east, b.south));
                let got = ["MinTileCol", "MinTileRow", "MaxTileCol", "MaxTileRow"]
                    .map(|k| child(l, k).parse::<u64>().unwrap());
                assert_eq!(got, [c0, r0, c1, r1], "{set:?} zoom {z}");
            }
        }
        // Every zoom served is a matrix, zoom 0 on the standard scale.
        let contents = doc.descendants().find(|n| n.has_tag_name("Contents")).unwrap();
        let set_nodes: Vec<_> = contents.children().filter(|n| n.has_tag_name("TileMatrixSet")).collect();
        assert_eq!(set_nodes.len(), 2);
        for set_node in set_nodes {
            let set = TileSet::parse(&child(set_node, "Identifier")).unwrap();
            let matrices: Vec<_> = set_node.children().filter(|n| n.has_tag_name("TileMatrix")).collect();
            let deepest = deepest(&|layer, set| extent(&region, layer, set), set).unwrap();
            assert_eq!(matrices.len() as u32, deepest + 1);
            let finest = extent(&region, MapLayer::Relief, set).unwrap().max_zoom;
            assert_eq!(deepest, finest, "the map's pixels are the finest source's");
            let scale: f64 = child(matrices[0], "ScaleDenominator").parse().unwrap();
            let world_m = scale * 0.000_28 * 256.0 * set.matrix(0).0 as f64;
            assert!((world_m - 2.0 * HALF_WORLD_M).abs() < 1e-3, "{set:?}: {world_m} m");
            let size = ["MatrixWidth", "MatrixHeight"].map(|k| child(matrices[0], k).parse::<u64>().unwrap());
            assert_eq!((size[0], size[1]), set.matrix(0));
        }
    }

    #[test]
    fn a_polar_region_is_offered_in_geographic_tiles_alone() {
        let mut region = crate::config::load(None).unwrap();
        region.bounds = crate::grid::BBox { west: -180.0, south: -90.0, east: 180.0, north: -86.0 };
        let xml = document(&region, "http://h:1");
        let doc = roxmltree::Document::parse(&xml).unwrap();
        let contents = doc.descendants().find(|n| n.has_tag_name("Contents")).unwrap();
        let sets: Vec<String> =
            contents.children().filter(|n| n.has_tag_name("TileMatrixSet")).map(|n| child(n, "Identifier")).collect();
        assert_eq!(sets, ["WorldCRS84Quad"]);
        for layer in contents.children().filter(|n| n.has_tag_name("Layer")) {
            assert_eq!(set_names(layer, "TileMatrixSetLink"), ["WorldCRS84Quad"]);
        }
    }
}
