//! Parsing and checking WMS requests (1.1.1 and 1.3.0), pure: a query string
//! in, a typed request or an OGC exception out.
//!
//! Keys are case-insensitive, repeated `&` and a trailing `&` are fine.
//! Axis order follows the specifications: WMS 1.3.0 with EPSG:4326 gives the
//! box as lat,lon; CRS:84, EPSG:3857 and all of WMS 1.1.1 as x,y (lon,lat).

use super::super::exception::{Code, Exception};
pub(super) use super::super::query::Params;
use super::picture::PictureFormat;
use crate::cem::Layer;
use crate::grid::mercator::MercatorBox;
use crate::grid::{BBox, SampleGrid};

/// WMS version.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Version {
    /// 1.1.1: `SRS`, lon,lat everywhere, `application/vnd.ogc.se_xml` exceptions.
    V111,
    /// 1.3.0: `CRS`, lat,lon for EPSG:4326, `text/xml` exceptions.
    V130,
}

/// A layer served over WMS: a pipeline layer, or the shaded preview.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MapLayer {
    /// One of the pipeline's layers.
    Data(Layer),
    /// Unshaded map colours (the renderer's texture; RGBA PNG).
    Colour,
    /// Hillshaded map colours with the canopy, for people (RGBA PNG).
    Relief,
}

/// Layers offered over WMS, in capabilities order.
pub const LAYERS: [MapLayer; 7] = [
    MapLayer::Data(Layer::Dem),
    MapLayer::Data(Layer::Cover),
    MapLayer::Data(Layer::Canopy),
    MapLayer::Data(Layer::Cem),
    MapLayer::Data(Layer::Surface),
    MapLayer::Colour,
    MapLayer::Relief,
];

impl MapLayer {
    /// The layer's name.
    pub fn name(self) -> &'static str {
        match self {
            MapLayer::Data(l) => l.name(),
            MapLayer::Colour => "colour",
            MapLayer::Relief => "relief",
        }
    }

    /// Whether the layer is an RGBA picture rather than data.
    pub fn is_picture(self) -> bool {
        matches!(self, MapLayer::Colour | MapLayer::Relief)
    }

    /// Whether the quadtree tiles (XYZ, WMTS) carry the layer: heights and
    /// the pictures, not cover or classes (no Terrarium or picture of them).
    pub fn in_quad_tiles(self) -> bool {
        !matches!(self, MapLayer::Data(Layer::Cover | Layer::Surface))
    }

    /// Whether GetMap offers the layer in `format`: pictures in PNG and
    /// JPEG, data in any format (in JPEG, a picture of it).
    pub fn offered_in(self, format: MapFormat) -> bool {
        !self.is_picture() || format.picture().is_some()
    }

    /// The layer with this name (any case).
    pub fn parse(text: &str) -> Option<MapLayer> {
        LAYERS.into_iter().find(|l| l.name().eq_ignore_ascii_case(text))
    }
}

/// Coordinate reference systems of requests.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RequestCrs {
    /// Geographic WGS84 (lat,lon axis order in WMS 1.3.0).
    Epsg4326,
    /// Geographic WGS84, lon,lat always.
    Crs84,
    /// Web Mercator.
    Epsg3857,
}

impl RequestCrs {
    /// Every CRS served, as named in capabilities.
    pub const ALL: [(RequestCrs, &'static str); 3] =
        [(RequestCrs::Epsg4326, "EPSG:4326"), (RequestCrs::Crs84, "CRS:84"), (RequestCrs::Epsg3857, "EPSG:3857")];

    fn parse(text: &str) -> Option<RequestCrs> {
        let t = text.trim().to_ascii_uppercase();
        match t.as_str() {
            "EPSG:4326" => Some(RequestCrs::Epsg4326),
            "CRS:84" | "EPSG:4326:LONLAT" => Some(RequestCrs::Crs84),
            "EPSG:3857" | "EPSG:900913" => Some(RequestCrs::Epsg3857),
            _ => None,
        }
    }
}

/// GetMap output formats.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MapFormat {
    /// `application/bil16`.
    Bil16,
    /// `application/bil32`.
    Bil32,
    /// `image/png`: 16-bit grey for data layers, RGBA for `relief`.
    Png,
    /// `image/tiff`: float32 GeoTIFF.
    Tiff,
    /// `image/jpeg`: pictures (`relief`, `colour`, and data layers drawn
    /// as pictures), on their background.
    Jpeg,
}

impl MapFormat {
    /// Every format, as named in capabilities.
    pub const ALL: [(MapFormat, &'static str); 5] = [
        (MapFormat::Png, "image/png"),
        (MapFormat::Jpeg, "image/jpeg"),
        (MapFormat::Tiff, "image/tiff"),
        (MapFormat::Bil16, "application/bil16"),
        (MapFormat::Bil32, "application/bil32"),
    ];

    /// A `FORMAT` value (a MIME type, or a short name such as `png`).
    pub fn parse(text: &str) -> Option<MapFormat> {
        match text.trim().to_ascii_lowercase().as_str() {
            "image/png" | "png" => Some(MapFormat::Png),
            "image/tiff" | "image/geotiff" | "tiff" => Some(MapFormat::Tiff),
            "application/bil16" | "application/bil" | "image/bil" => Some(MapFormat::Bil16),
            "application/bil32" => Some(MapFormat::Bil32),
            "image/jpeg" | "image/jpg" | "jpeg" | "jpg" => Some(MapFormat::Jpeg),
            _ => None,
        }
    }

    /// The data encoding a data layer is answered in: `None` for JPEG,
    /// which answers a picture of it.
    pub fn data(self) -> Option<crate::encode::Format> {
        use crate::encode::Format;
        match self {
            MapFormat::Png => Some(Format::Png16),
            MapFormat::Tiff => Some(Format::Tiff),
            MapFormat::Bil16 => Some(Format::Bil16),
            MapFormat::Bil32 => Some(Format::Bil32),
            MapFormat::Jpeg => None,
        }
    }

    /// The picture encoding of PNG and JPEG.
    pub fn picture(self) -> Option<PictureFormat> {
        match self {
            MapFormat::Png => Some(PictureFormat::Png),
            MapFormat::Jpeg => Some(PictureFormat::Jpeg),
            _ => None,
        }
    }

    /// The MIME type answered.
    pub fn mime(self) -> &'static str {
        Self::ALL.iter().find(|(f, _)| *f == self).map_or("application/octet-stream", |(_, m)| m)
    }
}

/// How errors are reported (the `EXCEPTIONS` parameter).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ExceptionStyle {
    /// A ServiceExceptionReport document.
    Xml,
    /// An image of the requested size with the message drawn in it.
    InImage,
    /// A blank (transparent) image of the requested size.
    Blank,
}

/// A checked GetMap request.
#[derive(Clone, Debug, PartialEq)]
pub struct GetMap {
    /// Version asked for.
    pub version: Version,
    /// The layer.
    pub layer: MapLayer,
    /// The request CRS.
    pub crs: RequestCrs,
    /// Pixel centres of the image, row 0 at the north.
    pub grid: SampleGrid,
    /// Output format.
    pub format: MapFormat,
    /// What pictures (`relief`, `colour`) show where there is no data:
    /// `BGCOLOR` (white unless given), or nothing with `TRANSPARENT=TRUE`.
    pub background: Option<[u8; 3]>,
}

/// A parsed request.
#[derive(Clone, Debug, PartialEq)]
pub enum Request {
    /// Capabilities document.
    GetCapabilities(Version),
    /// A map.
    GetMap(GetMap),
    /// Values at a pixel of a map.
    GetFeatureInfo(super::info::FeatureInfo),
    /// What a layer's colours mean.
    GetLegendGraphic(super::legend::LegendRequest),
}

/// Limits a request must respect.
#[derive(Clone, Copy, Debug)]
pub struct Limits {
    /// Largest WIDTH and HEIGHT.
    pub max_side: usize,
}

/// How an exception must be answered: its style, and the image it replaces.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Reply {
    /// Version for the report's form.
    pub version: Version,
    /// XML, in-image or blank.
    pub style: ExceptionStyle,
    /// Image size and format for in-image and blank replies.
    pub image: Option<(usize, usize, MapFormat)>,
    /// Their background (`TRANSPARENT` and `BGCOLOR`, if they parse).
    pub background: Option<[u8; 3]>,
    /// The layer asked for, if it is served and offered in the format: what
    /// a blank reply is blank in.
    pub layer: Option<MapLayer>,
    /// Where the image lies, if its CRS and box parse: what a blank GeoTIFF
    /// is georeferenced to.
    pub place: Option<SampleGrid>,
}

/// How a failure to answer `query` is answered (a report unless it is a
/// GetMap that asks for in-image or blank exceptions).
pub fn reply_of(query: &str, limits: Limits) -> Reply {
    let params = Params::new(query);
    reply_for(&params, negotiate(&params), limits)
}

fn reply_for(params: &Params, version: Version, limits: Limits) -> Reply {
    let mut reply =
        Reply { version, style: ExceptionStyle::Xml, image: None, background: None, layer: None, place: None };
    let request = params.get("REQUEST").unwrap_or("").to_ascii_lowercase();
    if !matches!(request.as_str(), "getmap" | "map") {
        return reply;
    }
    // An ambiguous style is no style: the report.
    let ambiguous = params.conflict().is_some_and(|(key, _)| key == "EXCEPTIONS");
    reply.style = exception_style(params.get("EXCEPTIONS").filter(|_| !ambiguous));
    reply.image = image_of(params, limits);
    reply.background = background(params, reply.image.map(|(_, _, f)| f)).unwrap_or(None);
    reply.layer = layer_of(params, reply.image.map(|(_, _, f)| f));
    reply.place = reply.image.and_then(|(w, h, _)| place_of(params, version, w, h));
    reply
}

/// Parses a query string; an exception comes with how to answer it.
pub fn parse(query: &str, limits: Limits) -> Result<Request, (Exception, Box<Reply>)> {
    let params = Params::new(query);
    let version = negotiate(&params);
    request(&params, version, limits).map_err(|e| (e, Box::new(reply_for(&params, version, limits))))
}

fn request(params: &Params, version: Version, limits: Limits) -> Result<Request, Exception> {
    if let Some((key, message)) = params.conflict() {
        return Err(Exception::new(Code::InvalidParameterValue, message).locator(key));
    }
    if let Some(service) = params.get("SERVICE").filter(|s| !s.eq_ignore_ascii_case("WMS")) {
        return Err(Exception::new(Code::InvalidParameterValue, format!("SERVICE={service}: only WMS is served")));
    }
    let Some(request) = params.get("REQUEST") else {
        return Err(Exception::new(Code::MissingParameterValue, "REQUEST is missing"));
    };
    match request.to_ascii_lowercase().as_str() {
        "getcapabilities" | "capabilities" => Ok(Request::GetCapabilities(version)),
        "getmap" | "map" => get_map(params, version, limits).map(Request::GetMap),
        "getfeatureinfo" | "feature_info" => super::info::parse(params, version, limits).map(Request::GetFeatureInfo),
        "getlegendgraphic" => super::legend::parse(params).map(Request::GetLegendGraphic),
        other => Err(Exception::new(Code::OperationNotSupported, format!("REQUEST={other} is not supported"))),
    }
}

/// The version a query string is answered in.
pub fn version_of(query: &str) -> Version {
    negotiate(&Params::new(query))
}

/// The version answered (WMS 1.3.0 §6.2.4): below 1.3.0 the highest known
/// version lower than the one asked for, 1.1.1 (also the lowest known, for
/// anything older); 1.3.0 from there on, and when none or no number is given.
fn negotiate(params: &Params) -> Version {
    match asked_version(params).and_then(|(_, number)| number) {
        Some(v) if v < [1, 3, 0] => Version::V111,
        _ => Version::V130,
    }
}

/// The version asked for (`VERSION`, or WMS 1.0's `WMTVER`) as written and
/// as a number, if it is one ("1.3" is 1.3.0: missing parts are zeros).
fn asked_version(params: &Params) -> Option<(&str, Option<[u32; 3]>)> {
    let text = params.get("VERSION").or(params.get("WMTVER"))?;
    let parts: Option<Vec<u32>> = text.trim().split('.').map(|p| p.parse().ok()).collect();
    let number = parts.filter(|p| p.len() <= 3).map(|p| std::array::from_fn(|i| p.get(i).copied().unwrap_or(0)));
    Some((text, number))
}

/// A GetMap or GetFeatureInfo names a version served (1.0 and 1.1 read as
/// 1.1.1), or none (1.3.0): only capabilities are negotiated.
fn check_map_version(params: &Params) -> Result<(), Exception> {
    match asked_version(params) {
        None | Some((_, Some([1, 0 | 1, _] | [1, 3, 0]))) => Ok(()),
        Some((text, _)) => Err(Exception::new(
            Code::InvalidParameterValue,
            format!("VERSION={text}: maps are served in WMS 1.1.1 and 1.3.0"),
        )
        .locator("VERSION")),
    }
}

fn exception_style(value: Option<&str>) -> ExceptionStyle {
    let v = value.unwrap_or("").to_ascii_lowercase();
    if v.ends_with("inimage") {
        ExceptionStyle::InImage
    } else if v.ends_with("blank") {
        ExceptionStyle::Blank
    } else {
        ExceptionStyle::Xml
    }
}

/// Size and format of the image an in-image exception replaces, if they
/// parse and the size is one a map may have (a larger one gets the XML
/// report: an error costs no more than a map).
fn image_of(params: &Params, limits: Limits) -> Option<(usize, usize, MapFormat)> {
    let w = params.get("WIDTH")?.trim().parse().ok()?;
    let h = params.get("HEIGHT")?.trim().parse().ok()?;
    let f = MapFormat::parse(params.get("FORMAT")?)?;
    let fits = |side: usize| (1..=limits.max_side).contains(&side);
    (fits(w) && fits(h)).then_some((w, h, f))
}

/// The pixel grid of a `width × height` image, if its CRS and box parse.
fn place_of(params: &Params, version: Version, width: usize, height: usize) -> Option<SampleGrid> {
    grid(numbers(params.get("BBOX")?).ok()?, crs_of(params, version).ok()?, version, width, height).ok()
}

/// The one layer `LAYERS` names, if it is served and offered in `format`.
fn layer_of(params: &Params, format: Option<MapFormat>) -> Option<MapLayer> {
    let (layer, format) = (MapLayer::parse(params.get("LAYERS")?.trim())?, format?);
    layer.offered_in(format).then_some(layer)
}

/// A GetMap: the map part, in a format its layer is offered in.
pub(super) fn get_map(params: &Params, version: Version, limits: Limits) -> Result<GetMap, Exception> {
    let map = map_part(params, version, limits)?;
    let layer = map.layer;
    if !layer.offered_in(map.format) {
        let why = format!("{} is a picture: ask for image/png or image/jpeg", layer.name());
        return Err(Exception::new(Code::InvalidFormat, why).locator("FORMAT"));
    }
    Ok(map)
}

/// The map part of a GetMap or a GetFeatureInfo: any format offered, since
/// a GetFeatureInfo draws no map (GDAL's WMS driver names JPEG whatever the
/// layer).
pub(super) fn map_part(params: &Params, version: Version, limits: Limits) -> Result<GetMap, Exception> {
    let required = |key: &'static str| {
        params
            .get(key)
            .filter(|v| !v.is_empty())
            .ok_or_else(|| Exception::new(Code::MissingParameterValue, format!("{key} is missing")))
    };
    check_map_version(params)?;
    let layers = required("LAYERS")?;
    let layer = match layers.split(',').collect::<Vec<_>>()[..] {
        [one] => MapLayer::parse(one.trim()).ok_or_else(|| {
            Exception::new(Code::LayerNotDefined, format!("layer {one:?} is not served")).locator("LAYERS")
        })?,
        _ => return Err(Exception::new(Code::InvalidParameterValue, "one layer per request").locator("LAYERS")),
    };
    check_styles(params.get("STYLES"), "STYLES")?;
    let crs = crs_of(params, version)?;
    let format_text = required("FORMAT")?;
    let format = MapFormat::parse(format_text).ok_or_else(|| {
        Exception::new(Code::InvalidFormat, format!("format {format_text:?} is not offered")).locator("FORMAT")
    })?;
    let (width, height) = (size(required("WIDTH")?, "WIDTH", limits)?, size(required("HEIGHT")?, "HEIGHT", limits)?);
    let bbox = numbers(required("BBOX")?)?;
    let grid = grid(bbox, crs, version, width, height)?;
    let background = background(params, Some(format))?;
    Ok(GetMap { version, layer, crs, grid, format, background })
}

/// The CRS asked for: `CRS` in 1.3.0, `SRS` in 1.1.1 (either is read).
fn crs_of(params: &Params, version: Version) -> Result<RequestCrs, Exception> {
    let crs_key = if version == Version::V130 { "CRS" } else { "SRS" };
    let crs_text = params.get(crs_key).or(params.get(if crs_key == "CRS" { "SRS" } else { "CRS" }));
    let crs_text =
        crs_text.ok_or_else(|| Exception::new(Code::MissingParameterValue, format!("{crs_key} is missing")))?;
    RequestCrs::parse(crs_text).ok_or_else(|| {
        let code = if version == Version::V130 { Code::InvalidCrs } else { Code::InvalidSrs };
        Exception::new(code, format!("{crs_text} is not offered (EPSG:4326, CRS:84, EPSG:3857)")).locator(crs_key)
    })
}

/// `TRANSPARENT` (`FALSE` unless given) and `BGCOLOR` (`0xRRGGBB`, white
/// unless given): the background colour, or `None` for transparent. JPEG
/// has no alpha: it lies on `BGCOLOR` whatever `TRANSPARENT` says.
pub(super) fn background(params: &Params, format: Option<MapFormat>) -> Result<Option<[u8; 3]>, Exception> {
    let transparent = params.get("TRANSPARENT").filter(|_| format != Some(MapFormat::Jpeg));
    let colour = params.get("BGCOLOR");
    let bad = |key: &'static str, text: &str, want: &str| {
        Exception::new(Code::InvalidParameterValue, format!("{key}={text}: {want}")).locator(key)
    };
    let see_through = match transparent.map(|t| t.trim().to_ascii_uppercase()) {
        None => false,
        Some(t) if t == "TRUE" => true,
        Some(t) if t == "FALSE" || t.is_empty() => false,
        Some(_) => return Err(bad("TRANSPARENT", transparent.unwrap_or(""), "need TRUE or FALSE")),
    };
    let rgb = match colour.map(str::trim).filter(|c| !c.is_empty()) {
        None => [255, 255, 255],
        Some(c) => c
            .strip_prefix("0x")
            .or_else(|| c.strip_prefix("0X"))
            .filter(|hex| hex.len() == 6 && hex.bytes().all(|b| b.is_ascii_hexdigit()))
            .and_then(|hex| u32::from_str_radix(hex, 16).ok())
            .map(|v| [(v >> 16) as u8, (v >> 8) as u8, v as u8])
            .ok_or_else(|| bad("BGCOLOR", c, "need 0xRRGGBB"))?,
    };
    Ok((!see_through).then_some(rgb))
}

/// Each layer has only its default style: `STYLES` (`key`) may be empty
/// (or left out, as some clients do) or name `default`.
pub(super) fn check_styles(styles: Option<&str>, key: &'static str) -> Result<(), Exception> {
    match styles.unwrap_or("").split(',').map(str::trim).find(|s| !s.is_empty() && !s.eq_ignore_ascii_case("default")) {
        Some(style) => {
            Err(Exception::new(Code::StyleNotDefined, format!("style {style:?} is not served: leave {key} empty"))
                .locator(key))
        }
        None => Ok(()),
    }
}

fn size(text: &str, key: &'static str, limits: Limits) -> Result<usize, Exception> {
    let bad = |why: String| Exception::new(Code::InvalidParameterValue, format!("{key}={text}: {why}")).locator(key);
    let v: Option<usize> = text.trim().parse().ok();
    v.filter(|v| (1..=limits.max_side).contains(v))
        .ok_or_else(|| bad(format!("must be a whole number from 1 to {}", limits.max_side)))
}

fn numbers(text: &str) -> Result<[f64; 4], Exception> {
    let bad = || {
        Exception::new(Code::InvalidParameterValue, format!("BBOX={text}: need four finite numbers")).locator("BBOX")
    };
    let v: Vec<f64> = text.split(',').map(|p| p.trim().parse::<f64>()).collect::<Result<_, _>>().map_err(|_| bad())?;
    <[f64; 4]>::try_from(v).ok().filter(|b| b.iter().all(|x| x.is_finite())).ok_or_else(bad)
}

/// The pixel-centre grid of the request, its box read in the CRS's axis order.
fn grid(b: [f64; 4], crs: RequestCrs, version: Version, width: usize, height: usize) -> Result<SampleGrid, Exception> {
    let bad = |e: crate::grid::GridError| Exception::new(Code::InvalidParameterValue, e.to_string()).locator("BBOX");
    match (crs, version) {
        (RequestCrs::Epsg3857, _) => MercatorBox { west: b[0], south: b[1], east: b[2], north: b[3] }
            .checked()
            .and_then(|m| m.area_grid(width, height))
            .map_err(bad),
        (RequestCrs::Epsg4326, Version::V130) => BBox { south: b[0], west: b[1], north: b[2], east: b[3] }
            .checked()
            .and_then(|g| g.area_grid(width, height))
            .map_err(bad),
        _ => BBox { west: b[0], south: b[1], east: b[2], north: b[3] }
            .checked()
            .and_then(|g| g.area_grid(width, height))
            .map_err(bad),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const LIMITS: Limits = Limits { max_side: 4096 };

    fn map(q: &str) -> GetMap {
        match parse(q, LIMITS) {
            Ok(Request::GetMap(m)) => m,
            other => panic!("{q}: {other:?}"),
        }
    }

    fn code(q: &str) -> Code {
        match parse(q, LIMITS) {
            Err((e, _)) => e.code,
            Ok(r) => panic!("{q}: accepted as {r:?}"),
        }
    }

    #[test]
    fn axis_order_follows_version_and_crs() {
        let a = map(
            "SERVICE=WMS&VERSION=1.3.0&REQUEST=GetMap&LAYERS=dem&STYLES=&CRS=EPSG:4326&BBOX=40,-106,41,-105&WIDTH=4&HEIGHT=2&FORMAT=image/tiff",
        );
        let b = map(
            "service=wms&version=1.3.0&request=getmap&layers=dem&crs=CRS:84&bbox=-106,40,-105,41&width=4&height=2&format=image/tiff&",
        );
        let c = map(
            "SERVICE=WMS&VERSION=1.1.1&REQUEST=GetMap&LAYERS=dem&SRS=EPSG:4326&BBOX=-106,40,-105,41&WIDTH=4&HEIGHT=2&FORMAT=image/tiff",
        );
        assert_eq!(a.grid, b.grid);
        assert_eq!(a.grid, c.grid);
        assert_eq!(a.grid.lon_lat(0, 0), (-105.875, 40.75));
    }

    #[test]
    fn errors_carry_the_specification_codes() {
        let base = "SERVICE=WMS&VERSION=1.3.0&REQUEST=GetMap&CRS=EPSG:4326&BBOX=40,-106,41,-105&WIDTH=4&HEIGHT=2&FORMAT=image/png";
        assert_eq!(code(&format!("{base}&LAYERS=nope")), Code::LayerNotDefined);
        assert_eq!(
            code(&base.replace("CRS=EPSG:4326", "CRS=EPSG:2193").replace("&REQUEST", "&LAYERS=dem&REQUEST")),
            Code::InvalidCrs
        );
        assert_eq!(
            code(
                &(base.replace("VERSION=1.3.0", "VERSION=1.1.1").replace("CRS=EPSG:4326", "SRS=EPSG:2193")
                    + "&LAYERS=dem")
            ),
            Code::InvalidSrs
        );
        assert_eq!(code(&(base.replace("image/png", "image/gif") + "&LAYERS=dem")), Code::InvalidFormat);
        assert_eq!(code(&(base.replace("&WIDTH=4", "") + "&LAYERS=dem")), Code::MissingParameterValue);
        assert_eq!(code(&(base.replace("WIDTH=4", "WIDTH=99999") + "&LAYERS=dem")), Code::InvalidParameterValue);
        // One message for every size that is no side (regression: −5 was
        // "not a whole number").
        for width in ["-5", "0", "99999", "1.5", "x"] {
            let query = base.replace("WIDTH=4", &format!("WIDTH={width}")) + "&LAYERS=dem";
            let Err((e, _)) = parse(&query, LIMITS) else { panic!("{width}") };
            assert_eq!(e.message, format!("WIDTH={width}: must be a whole number from 1 to 4096"));
        }
        assert_eq!(
            code(&(base.replace("BBOX=40,-106,41,-105", "BBOX=41,-106,40,-105") + "&LAYERS=dem")),
            Code::InvalidParameterValue
        );
        assert_eq!(
            code(&(base.replace("BBOX=40,-106,41,-105", "BBOX=a,b") + "&LAYERS=dem")),
            Code::InvalidParameterValue
        );
        assert_eq!(code("SERVICE=WMS&REQUEST=DescribeLayer"), Code::OperationNotSupported);
        assert_eq!(code("SERVICE=WMS"), Code::MissingParameterValue);
        assert_eq!(code(&format!("{base}&LAYERS=relief").replace("image/png", "image/tiff")), Code::InvalidFormat);
        assert_eq!(code(&format!("{base}&LAYERS=dem&STYLES=fancy")), Code::StyleNotDefined);
        for b in ["NaN,-106,41,-105", "40,-inf,41,-105"] {
            let q = base.replace("BBOX=40,-106,41,-105", &format!("BBOX={b}")) + "&LAYERS=dem";
            match parse(&q, LIMITS) {
                Err((e, _)) => assert!(e.to_string().contains("finite"), "{e}"),
                other => panic!("{b}: {other:?}"),
            }
        }
    }

    #[test]
    fn only_the_default_style_is_served() {
        let base = "SERVICE=WMS&VERSION=1.3.0&REQUEST=GetMap&LAYERS=dem&CRS=EPSG:4326&BBOX=40,-106,41,-105&WIDTH=4&HEIGHT=2&FORMAT=image/png";
        for styles in ["", "&STYLES=", "&STYLES=default", "&STYLES=Default"] {
            assert_eq!(map(&format!("{base}{styles}")).layer, MapLayer::Data(Layer::Dem), "{styles}");
        }
        assert_eq!(code(&format!("{base}&STYLES=,hillshade")), Code::StyleNotDefined);
    }

    #[test]
    fn pictures_are_opaque_on_their_background_unless_transparent() {
        let base = "SERVICE=WMS&VERSION=1.3.0&REQUEST=GetMap&LAYERS=relief&CRS=EPSG:4326&BBOX=40,-106,41,-105&WIDTH=4&HEIGHT=2&FORMAT=image/png";
        assert_eq!(map(base).background, Some([255, 255, 255]));
        assert_eq!(map(&format!("{base}&TRANSPARENT=true")).background, None);
        assert_eq!(map(&format!("{base}&TRANSPARENT=FALSE&BGCOLOR=0x2040FF")).background, Some([0x20, 0x40, 0xFF]));
        assert_eq!(map(&format!("{base}&TRANSPARENT=TRUE&BGCOLOR=0x2040FF")).background, None);
        for bad in ["&TRANSPARENT=maybe", "&BGCOLOR=red", "&BGCOLOR=0x12345", "&BGCOLOR=0xGG0000"] {
            assert_eq!(code(&format!("{base}{bad}")), Code::InvalidParameterValue, "{bad}");
        }
    }

    #[test]
    fn versions_are_negotiated_as_the_specification_says() {
        let asked = |v: &str| match parse(&format!("SERVICE=WMS&REQUEST=GetCapabilities&VERSION={v}"), LIMITS) {
            Ok(Request::GetCapabilities(version)) => version,
            other => panic!("{v}: {other:?}"),
        };
        for v in ["1.0.0", "1.0.7", "1.1", "1.1.0", "1.1.1", "1.2.0", "1.2.9"] {
            assert_eq!(asked(v), Version::V111, "{v}");
        }
        for v in ["1.3.0", "1.3", "1.4.0", "2.0.0", "", "x.y"] {
            assert_eq!(asked(v), Version::V130, "{v}");
        }
    }

    #[test]
    fn get_map_names_a_version_served() {
        let base = "SERVICE=WMS&REQUEST=GetMap&LAYERS=dem&SRS=CRS:84&CRS=CRS:84&BBOX=-106,40,-105,41&WIDTH=4&HEIGHT=2&FORMAT=image/png";
        for (v, version) in [("1.0.0", Version::V111), ("1.1.0", Version::V111), ("1.1.1", Version::V111)] {
            assert_eq!(map(&format!("{base}&VERSION={v}")).version, version, "{v}");
        }
        assert_eq!(map(&format!("{base}&VERSION=1.3")).version, Version::V130);
        assert_eq!(map(base).version, Version::V130, "no version: the latest");
        for v in ["abc", "1.2.0", "1.4.0", "2.0.0", "1.3.0.1", ""] {
            let Err((e, _)) = parse(&format!("{base}&VERSION={v}"), LIMITS) else { panic!("{v} accepted") };
            assert_eq!(e.code, Code::InvalidParameterValue, "{v}");
            assert!(e.to_string().contains("1.1.1 and 1.3.0"), "{v}: {e}");
        }
    }

    #[test]
    fn a_key_given_twice_must_say_the_same() {
        let base = "SERVICE=WMS&VERSION=1.3.0&REQUEST=GetMap&CRS=EPSG:4326&BBOX=40,-106,41,-105&WIDTH=4&HEIGHT=2&FORMAT=image/png&LAYERS=dem";
        assert_eq!(map(&format!("{base}&service=wms&Layers=DEM ")).layer, MapLayer::Data(Layer::Dem));
        for twice in ["&LAYERS=cem", "&version=1.1.1", "&bbox=40,-106,41,-104"] {
            let Err((e, _)) = parse(&format!("{base}{twice}"), LIMITS) else { panic!("{twice} accepted") };
            assert_eq!(e.code, Code::InvalidParameterValue, "{twice}");
            assert!(e.to_string().contains("given twice"), "{twice}: {e}");
        }
    }

    #[test]
    fn exception_style_and_image_are_kept_for_in_image_replies() {
        let q = "REQUEST=GetMap&VERSION=1.1.1&LAYERS=x&SRS=EPSG:4326&BBOX=0,0,1,1&WIDTH=8&HEIGHT=4&FORMAT=image/png&EXCEPTIONS=application/vnd.ogc.se_inimage";
        let Err((e, reply)) = parse(q, LIMITS) else { panic!() };
        assert_eq!(e.code, Code::LayerNotDefined);
        assert_eq!(
            *reply,
            Reply {
                version: Version::V111,
                style: ExceptionStyle::InImage,
                image: Some((8, 4, MapFormat::Png)),
                background: Some([255, 255, 255]),
                layer: None,
                place: BBox { west: 0.0, south: 0.0, east: 1.0, north: 1.0 }.area_grid(8, 4).ok(),
            }
        );
        // A blank reply is blank in the layer asked for where it is offered
        // in the format (regression: a DEM in PNG came back as white relief).
        let blank = |layers: &str, format: &str| {
            let q = format!(
                "REQUEST=GetMap&VERSION=1.3.0&LAYERS={layers}&CRS=CRS:84&BBOX=1,0,0,1&WIDTH=8&HEIGHT=4&FORMAT={format}&EXCEPTIONS=BLANK"
            );
            parse(&q, LIMITS).err().map(|(_, reply)| reply.layer)
        };
        assert_eq!(blank("dem", "image/png"), Some(Some(MapLayer::Data(Layer::Dem))));
        assert_eq!(blank("relief", "image/png"), Some(Some(MapLayer::Relief)));
        assert_eq!(blank("dem", "image/jpeg"), Some(Some(MapLayer::Data(Layer::Dem))));
        assert_eq!(blank("relief", "application/bil16"), Some(None));
    }

    #[test]
    fn an_image_larger_than_a_map_may_be_is_no_in_image_reply() {
        let q = "REQUEST=GetMap&VERSION=1.3.0&LAYERS=relief&CRS=CRS:84&BBOX=0,0,1,1&WIDTH=4097&HEIGHT=4&FORMAT=image/png&EXCEPTIONS=INIMAGE";
        let Err((e, reply)) = parse(q, LIMITS) else { panic!() };
        assert!(e.to_string().contains("WIDTH"), "{e}");
        assert_eq!((reply.style, reply.image), (ExceptionStyle::InImage, None));
    }

    /// Queries giving each parameter a value good for it (which may not go
    /// with the others'), one bad for any, or none, in a shuffled order.
    fn queries() -> impl proptest::strategy::Strategy<Value = String> {
        use proptest::prelude::*;
        let fields: [(&str, &[&str]); 19] = [
            ("SERVICE", &["WMS", "wms"]),
            ("version", &["1.3.0", "1.1.1", "1.3", "1.0.0"]),
            ("REQUEST", &["GetMap", "GetFeatureInfo", "GetCapabilities", "GetLegendGraphic"]),
            ("LAYERS", &["dem", "relief", "surface", "colour"]),
            ("LAYER", &["canopy", "relief", "cover"]),
            ("STYLES", &["", "default"]),
            ("CRS", &["EPSG:4326", "CRS:84", "EPSG:3857"]),
            ("srs", &["EPSG:4326", "EPSG:3857"]),
            ("BBOX", &["46.3,10,46.45,10.25", "10,46.3,10.25,46.45", "-90,-180,90,180", "1e6,5e6,2e6,6e6"]),
            ("WIDTH", &["1", "256", "4096"]),
            ("height", &["1", "200", "4096"]),
            ("FORMAT", &["image/png", "image/jpeg", "application/bil32", "image/tiff"]),
            ("TRANSPARENT", &["TRUE", "false"]),
            ("BGCOLOR", &["0xFFFFFF", "0x203040"]),
            ("EXCEPTIONS", &["XML", "INIMAGE", "application/vnd.ogc.se_blank"]),
            ("QUERY_LAYERS", &["dem", "colour,cover", "cem"]),
            ("INFO_FORMAT", &["text/plain", "application/vnd.ogc.gml", "application/json"]),
            ("I", &["0", "255"]),
            ("j", &["0", "199"]),
        ];
        let bad = ["", "%ZZ", "NaN", "-1", "1e308,0,-1e308,1", "18446744073709551616", "a\u{0}b"];
        let pairs: Vec<BoxedStrategy<Option<String>>> = fields
            .into_iter()
            .map(|(key, good)| {
                let value =
                    prop_oneof![15 => prop::sample::select(good.to_vec()), 1 => prop::sample::select(bad.to_vec())];
                prop::option::weighted(0.9, value).prop_map(move |v| v.map(|v| format!("{key}={v}"))).boxed()
            })
            .collect();
        pairs.prop_map(|p| p.into_iter().flatten().collect::<Vec<_>>()).prop_shuffle().prop_map(|p| p.join("&"))
    }

    proptest::proptest! {
        #![proptest_config(proptest::test_runner::Config::with_cases(2000))]
        #[test]
        fn any_query_parses_or_is_refused_without_panic(query in queries()) {
            match parse(&query, LIMITS) {
                Ok(Request::GetMap(m)) => {
                    proptest::prop_assert!(m.grid.width() <= 4096 && m.grid.height() <= 4096);
                }
                Ok(Request::GetFeatureInfo(info)) => {
                    proptest::prop_assert!(info.pixel.0 < info.map.grid.width() && info.pixel.1 < info.map.grid.height());
                    proptest::prop_assert!(!info.layers.is_empty());
                }
                Ok(Request::GetLegendGraphic(legend)) => {
                    let (w, h) = legend.swatch;
                    proptest::prop_assert!((1..=256).contains(&w) && (1..=256).contains(&h));
                }
                Ok(Request::GetCapabilities(_)) => {}
                Err((e, _)) => proptest::prop_assert!(!e.message.is_empty()),
            }
        }
    }

    #[test]
    fn web_mercator_boxes_give_mercator_grids() {
        let m = map(
            "REQUEST=GetMap&LAYERS=cem&CRS=EPSG:3857&BBOX=0,0,20037508.342789244,20037508.342789244&WIDTH=2&HEIGHT=2&FORMAT=application/bil32",
        );
        assert_eq!(m.crs, RequestCrs::Epsg3857);
        // Pixel centres at a quarter and three quarters of the north half: 40.98° and 79.17°.
        assert!((m.grid.lat.coord(1) - 40.979_898_069_620_14).abs() < 1e-9);
        assert!((m.grid.lon.coord(0) - 45.0).abs() < 1e-9);
    }
}
