//! WMS GetFeatureInfo: the values of data layers at one pixel of a map, as
//! a GIS client's "identify" tool asks for them (WMS 1.3.0 §7.4).
//!
//! The request is a GetMap plus `QUERY_LAYERS`, `INFO_FORMAT` and the pixel
//! (`I`,`J` in 1.3.0, `X`,`Y` in 1.1.1; column from the left, row from the
//! top). The pixel's value is computed on a one-sample window of the map's
//! own grid, so it is the value the map shows there (the pipeline is
//! seamless: a window of a grid computes as the whole grid does). Every
//! layer is queryable: a picture answers with the data it shows.

use super::super::exception::{Code, Exception, escape};
use super::request::{self, GetMap, Limits, MapLayer, Params, Version};
use crate::cem::surface::SurfaceType;
use crate::cem::{self, Layer, LayerSamples};
use crate::grid::SampleGrid;
use crate::produce::ProduceError;
use crate::region::Region;

/// What a query of a picture (`relief`, `colour`) answers: the data it shows.
const PICTURED: [Layer; 4] = [Layer::Dem, Layer::Canopy, Layer::Cem, Layer::Surface];

/// A checked GetFeatureInfo request.
#[derive(Clone, Debug, PartialEq)]
pub struct FeatureInfo {
    /// The map the pixel is on.
    pub map: GetMap,
    /// The layers queried, in the order asked.
    pub layers: Vec<Layer>,
    /// The pixel: column from the left, row from the top.
    pub pixel: (usize, usize),
    /// How the answer is written.
    pub format: InfoFormat,
}

/// Answer formats.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum InfoFormat {
    /// One `layer = value unit` line per layer.
    Text,
    /// A small HTML table.
    Html,
    /// A GeoJSON FeatureCollection: a point feature per layer.
    Json,
    /// The same as a GML 2 FeatureCollection (GDAL's and QGIS's choice).
    Gml,
}

impl InfoFormat {
    /// Every format, as named in capabilities.
    pub const ALL: [(InfoFormat, &'static str); 4] = [
        (InfoFormat::Text, "text/plain"),
        (InfoFormat::Html, "text/html"),
        (InfoFormat::Json, "application/json"),
        (InfoFormat::Gml, "application/vnd.ogc.gml"),
    ];

    /// The format a MIME type (or a short name) asks for.
    pub fn parse(text: &str) -> Option<InfoFormat> {
        match text.trim().to_ascii_lowercase().as_str() {
            "text/plain" => Some(InfoFormat::Text),
            "text/html" => Some(InfoFormat::Html),
            "application/vnd.ogc.gml" | "gml" | "text/xml" => Some(InfoFormat::Gml),
            "application/json" | "application/geo+json" | "application/vnd.geo+json" | "json" => Some(InfoFormat::Json),
            _ => None,
        }
    }

    /// The MIME type answered.
    pub fn mime(self) -> &'static str {
        Self::ALL.iter().find(|(f, _)| *f == self).map_or("text/plain", |(_, m)| m)
    }
}

/// Parses a GetFeatureInfo's parameters.
pub(super) fn parse(params: &Params, version: Version, limits: Limits) -> Result<FeatureInfo, Exception> {
    let map = request::map_part(params, version, limits)?;
    let names = params
        .get("QUERY_LAYERS")
        .filter(|v| !v.trim().is_empty())
        .ok_or_else(|| Exception::new(Code::MissingParameterValue, "QUERY_LAYERS is missing"))?;
    let shown = shows(map.layer);
    let mut layers: Vec<Layer> = Vec::new();
    for name in names.split(',').map(str::trim) {
        let Some(queried) = MapLayer::parse(name) else {
            let e = Exception::new(Code::LayerNotDefined, format!("layer {name:?} is not served"));
            return Err(e.locator("QUERY_LAYERS"));
        };
        let on_map = queried == map.layer || matches!(queried, MapLayer::Data(l) if shown.contains(&l));
        if !on_map {
            let map = map.layer.name();
            let e = Exception::new(Code::LayerNotDefined, format!("{name} is not in the map (LAYERS={map})"));
            return Err(e.locator("QUERY_LAYERS"));
        }
        for layer in shows(queried) {
            if !layers.contains(&layer) {
                layers.push(layer);
            }
        }
    }
    let format = match params.get("INFO_FORMAT") {
        None => InfoFormat::Text,
        Some(text) => InfoFormat::parse(text).ok_or_else(|| {
            Exception::new(
                Code::InvalidFormat,
                format!("INFO_FORMAT={text}: offered are {}", InfoFormat::ALL.map(|(_, m)| m).join(", ")),
            )
            .locator("INFO_FORMAT")
        })?,
    };
    // One value per layer at a pixel: any count asked for holds it, but the
    // count must be one.
    if let Some(count) = params.get("FEATURE_COUNT").filter(|c| !c.trim().parse::<u32>().is_ok_and(|n| n > 0)) {
        let e =
            Exception::new(Code::InvalidParameterValue, format!("FEATURE_COUNT={count}: need a whole number above 0"));
        return Err(e.locator("FEATURE_COUNT"));
    }
    // InvalidPoint is 1.3.0's code; 1.1.1 has none for it.
    let ((x_key, y_key), off) = match version {
        Version::V130 => (("I", "J"), Code::InvalidPoint),
        Version::V111 => (("X", "Y"), Code::InvalidParameterValue),
    };
    let pixel = (
        coordinate(params, [x_key, "I", "X"], map.grid.width(), off)?,
        coordinate(params, [y_key, "J", "Y"], map.grid.height(), off)?,
    );
    Ok(FeatureInfo { map, layers, pixel, format })
}

/// The data layers a map layer shows, which querying it answers with:
/// itself, or for a picture the data it shows.
pub fn shows(layer: MapLayer) -> Vec<Layer> {
    match layer {
        MapLayer::Data(layer) => vec![layer],
        _ => PICTURED.to_vec(),
    }
}

/// The pixel coordinate under the first of `keys` given, below `len` (the
/// map's width or height); a fraction, which some web clients send, is the
/// pixel it falls in. Off the map is exception `off`.
fn coordinate(params: &Params, keys: [&'static str; 3], len: usize, off: Code) -> Result<usize, Exception> {
    let Some((key, text)) = keys.into_iter().find_map(|k| params.get(k).map(|v| (k, v))) else {
        return Err(Exception::new(Code::MissingParameterValue, format!("{} is missing", keys[0])));
    };
    text.trim()
        .parse::<f64>()
        .ok()
        .filter(|v| (0.0..len as f64).contains(v))
        .map(|v| v.floor() as usize)
        .ok_or_else(|| Exception::new(off, format!("{key}={text}: need a pixel 0 to {}", len - 1)).locator(key))
}

/// The one-sample grid of the pixel asked for.
pub fn point(info: &FeatureInfo) -> SampleGrid {
    let (x, y) = info.pixel;
    info.map.grid.slice(x as i64, y as i64, 1, 1)
}

/// The queried layers' values on `grid` (one sample), `None` where there is
/// no data.
pub fn values(region: &Region, grid: &SampleGrid, layers: &[Layer]) -> Result<Vec<Option<f64>>, ProduceError> {
    if !region.dem.may_cover(grid) {
        return Ok(vec![None; layers.len()]);
    }
    let mut products = cem::compute(region, grid, layers)?;
    Ok(layers
        .iter()
        .map(|&layer| match products.take(layer)? {
            LayerSamples::Float(r) => Some(f64::from(r.get(0, 0))).filter(|v| v.is_finite()),
            LayerSamples::Class(r) => Some(f64::from(r.get(0, 0))).filter(|&v| v != f64::from(cem::surface::NODATA)),
        })
        .collect())
}

/// The answer in `format` for the pixel `(x, y)` of a map or tile, whose
/// centre is at `(lon, lat)`: `values` those of `layers`.
pub fn document(
    layers: &[Layer],
    (x, y): (usize, usize),
    format: InfoFormat,
    (lon, lat): (f64, f64),
    values: &[Option<f64>],
) -> (&'static str, String) {
    let rows: Vec<(Layer, Option<f64>)> = layers.iter().copied().zip(values.iter().copied()).collect();
    let body = match format {
        InfoFormat::Text => {
            let head = format!("Sylva feature info at lon {lon:.8}, lat {lat:.8} (pixel {x}, {y})\n");
            rows.iter().map(|&(l, v)| format!("{} = {}\n", l.name(), reading(l, v))).fold(head, |t, r| t + &r)
        }
        InfoFormat::Html => {
            let cells: String = rows
                .iter()
                .map(|&(l, v)| format!("<tr><th>{}</th><td>{}</td></tr>", l.name(), escape(&reading(l, v))))
                .collect();
            format!(
                "<!DOCTYPE html>\n<html><head><meta charset=\"utf-8\"><title>Sylva feature info</title></head><body>\
                 <p>lon {lon:.8}, lat {lat:.8}</p><table>{cells}</table></body></html>\n"
            )
        }
        InfoFormat::Json => geojson(&rows, lon, lat),
        InfoFormat::Gml => gml(&rows, lon, lat),
    };
    (format.mime(), body)
}

/// A value as people read it: with its unit, a class with its name.
fn reading(layer: Layer, value: Option<f64>) -> String {
    let Some(v) = value else { return "no data".into() };
    match layer {
        Layer::Surface => {
            let name = SurfaceType::from_id(v as u8).map_or("unknown", SurfaceType::name);
            format!("{v} ({name})")
        }
        Layer::Cover => format!("{v:.3}"),
        _ => format!("{v:.2} m"),
    }
}

/// What a layer's values are in, and a class's name.
fn unit_and_class(layer: Layer, value: Option<f64>) -> (&'static str, Option<&'static str>) {
    match layer {
        Layer::Surface => ("class", value.and_then(|v| SurfaceType::from_id(v as u8)).map(SurfaceType::name)),
        Layer::Cover => ("fraction", None),
        _ => ("m", None),
    }
}

fn gml(rows: &[(Layer, Option<f64>)], lon: f64, lat: f64) -> String {
    let members: String = rows
        .iter()
        .map(|&(layer, value)| {
            let (unit, class) = unit_and_class(layer, value);
            let value = value.map(|v| format!("<sylva:value>{v}</sylva:value>")).unwrap_or_default();
            let class = class.map(|c| format!("<sylva:class>{c}</sylva:class>")).unwrap_or_default();
            format!(
                "<gml:featureMember><sylva:{name} fid=\"{name}\"><sylva:location><gml:Point srsName=\"EPSG:4326\">\
                 <gml:coordinates>{lon},{lat}</gml:coordinates></gml:Point></sylva:location>{value}\
                 <sylva:unit>{unit}</sylva:unit>{class}</sylva:{name}></gml:featureMember>\n",
                name = layer.name()
            )
        })
        .collect();
    format!(
        "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n<wfs:FeatureCollection xmlns:wfs=\"http://www.opengis.net/wfs\" \
         xmlns:gml=\"http://www.opengis.net/gml\" xmlns:sylva=\"urn:x-sylva:features\">\n{members}</wfs:FeatureCollection>\n"
    )
}

fn geojson(rows: &[(Layer, Option<f64>)], lon: f64, lat: f64) -> String {
    let features: Vec<serde_json::Value> = rows
        .iter()
        .map(|&(layer, value)| {
            let (unit, class) = unit_and_class(layer, value);
            let mut properties = serde_json::json!({ "layer": layer.name(), "value": value, "unit": unit });
            if layer == Layer::Surface {
                properties["class"] = class.into();
            }
            serde_json::json!({
                "type": "Feature",
                "id": layer.name(),
                "geometry": { "type": "Point", "coordinates": [lon, lat] },
                "properties": properties,
            })
        })
        .collect();
    serde_json::json!({ "type": "FeatureCollection", "features": features }).to_string()
}

#[cfg(test)]
mod tests {
    use super::*;

    const LIMITS: Limits = Limits { max_side: 4096 };
    const BASE: &str = "SERVICE=WMS&VERSION=1.3.0&REQUEST=GetFeatureInfo&LAYERS=relief&STYLES=&CRS=CRS:84&BBOX=-106,40,-105,41&WIDTH=10&HEIGHT=4&FORMAT=image/png";

    fn parsed(query: &str) -> Result<FeatureInfo, Exception> {
        let params = Params::new(query);
        parse(&params, request::version_of(query), LIMITS)
    }

    #[test]
    fn the_pixel_and_layers_are_read_in_each_version() {
        let info = parsed(&format!("{BASE}&QUERY_LAYERS=dem,surface&I=9&J=0&INFO_FORMAT=application/json")).unwrap();
        assert_eq!(
            (info.layers.clone(), info.pixel, info.format),
            (vec![Layer::Dem, Layer::Surface], (9, 0), InfoFormat::Json)
        );
        let g = point(&info);
        assert_eq!((g.width(), g.height()), (1, 1));
        assert_eq!(g.lon_lat(0, 0), info.map.grid.lon_lat(9, 0), "the pixel's centre");
        let old = format!("{BASE}&QUERY_LAYERS=cem&X=3&Y=2")
            .replace("VERSION=1.3.0", "VERSION=1.1.1")
            .replace("CRS=", "SRS=");
        let info = parsed(&old).unwrap();
        assert_eq!((info.pixel, info.format), ((3, 2), InfoFormat::Text));
        let picture = parsed(&format!("{BASE}&QUERY_LAYERS=cem,relief&I=0&J=0")).unwrap();
        assert_eq!(picture.layers, [Layer::Cem, Layer::Dem, Layer::Canopy, Layer::Surface], "a picture's data, once");
    }

    #[test]
    fn bad_queries_carry_the_specification_codes() {
        let code = |q: &str| parsed(&format!("{BASE}{q}")).unwrap_err().code;
        assert_eq!(code("&QUERY_LAYERS=trees&I=0&J=0"), Code::LayerNotDefined);
        assert_eq!(code("&I=0&J=0"), Code::MissingParameterValue);
        assert_eq!(code("&QUERY_LAYERS=dem&I=10&J=0"), Code::InvalidPoint);
        assert_eq!(code("&QUERY_LAYERS=dem&I=-1&J=0"), Code::InvalidPoint);
        assert_eq!(code("&QUERY_LAYERS=dem&I=NaN&J=0"), Code::InvalidPoint);
        let old = BASE.replace("VERSION=1.3.0", "VERSION=1.1.1").replace("CRS=", "SRS=");
        let in_111 = parsed(&format!("{old}&QUERY_LAYERS=dem&X=10&Y=0")).unwrap_err();
        assert_eq!(in_111.code, Code::InvalidParameterValue, "1.1.1 has no InvalidPoint");
        let fraction = parsed(&format!("{BASE}&QUERY_LAYERS=dem&I=9.7&J=0.2")).unwrap();
        assert_eq!(fraction.pixel, (9, 0), "the pixel a fraction falls in");
        assert_eq!(code("&QUERY_LAYERS=dem&I=0"), Code::MissingParameterValue);
        assert_eq!(code("&QUERY_LAYERS=dem&I=0&J=0&INFO_FORMAT=image/png"), Code::InvalidFormat);
        assert_eq!(code("&QUERY_LAYERS=dem&I=0&J=0&FEATURE_COUNT=abc"), Code::InvalidParameterValue);
        assert_eq!(code("&QUERY_LAYERS=dem&I=0&J=0&FEATURE_COUNT=0"), Code::InvalidParameterValue);
        assert!(parsed(&format!("{BASE}&QUERY_LAYERS=dem&I=0&J=0&FEATURE_COUNT=10")).is_ok());
        // Only what the map shows: a data map shows itself alone.
        let cem_map = |q: &str| parsed(&format!("{}{q}&I=0&J=0", BASE.replace("LAYERS=relief", "LAYERS=cem")));
        assert_eq!(cem_map("&QUERY_LAYERS=dem").unwrap_err().code, Code::LayerNotDefined);
        assert_eq!(cem_map("&QUERY_LAYERS=relief").unwrap_err().code, Code::LayerNotDefined);
        assert_eq!(cem_map("&QUERY_LAYERS=cem").unwrap().layers, [Layer::Cem]);
        assert_eq!(code("&QUERY_LAYERS=cover&I=0&J=0"), Code::LayerNotDefined, "relief does not show the cover");
        assert_eq!(code("&QUERY_LAYERS=colour&I=0&J=0"), Code::LayerNotDefined, "another picture");
    }

    #[test]
    fn answers_name_each_value_with_its_unit() {
        let mut info = parsed(&format!("{BASE}&QUERY_LAYERS=dem&I=0&J=0")).unwrap();
        info.layers = vec![Layer::Dem, Layer::Cover, Layer::Surface, Layer::Canopy];
        let values = [Some(1234.5), Some(0.25), Some(1.0), None];
        let (mime, text) = document(&info.layers, info.pixel, info.format, (-105.95, 40.875), &values);
        assert_eq!(mime, "text/plain");
        for line in ["dem = 1234.50 m", "cover = 0.250", "surface = 1 (forest)", "canopy = no data", "lon -105.95"] {
            assert!(text.contains(line), "{line}:\n{text}");
        }
        info.format = InfoFormat::Json;
        let (_, json) = document(&info.layers, info.pixel, info.format, (-105.95, 40.875), &values);
        let doc: serde_json::Value = serde_json::from_str(&json).unwrap();
        let features = doc["features"].as_array().unwrap();
        assert_eq!(features.len(), 4);
        assert_eq!(features[0]["geometry"]["coordinates"], serde_json::json!([-105.95, 40.875]));
        assert_eq!(features[2]["properties"]["class"], "forest");
        assert!(features[3]["properties"]["value"].is_null());
        info.format = InfoFormat::Html;
        assert!(
            document(&info.layers, info.pixel, info.format, (0.0, 0.0), &values)
                .1
                .contains("<th>dem</th><td>1234.50 m</td>")
        );
        info.format = InfoFormat::Gml;
        let (mime, xml) = document(&info.layers, info.pixel, info.format, (-105.95, 40.875), &values);
        assert_eq!(mime, "application/vnd.ogc.gml");
        let doc = roxmltree::Document::parse(&xml).unwrap();
        let members: Vec<_> = doc.descendants().filter(|n| n.has_tag_name("featureMember")).collect();
        assert_eq!(members.len(), 4);
        let text = |tag: &str| {
            doc.descendants().filter(|n| n.has_tag_name(tag)).map(|n| n.text().unwrap_or("")).collect::<Vec<_>>()
        };
        assert_eq!(text("value"), ["1234.5", "0.25", "1"], "no value where there is no data");
        assert_eq!(text("class"), ["forest"]);
        assert_eq!(text("coordinates")[0], "-105.95,40.875");
    }
}
