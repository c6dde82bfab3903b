//! WMS GetCapabilities documents, 1.1.1 and 1.3.0: one root layer holding
//! the served layers, their geographic box and a bounding box per CRS in
//! that CRS's axis order (1.3.0 EPSG:4326 is lat,lon), the formats, the size
//! limits, the GetFeatureInfo formats (every layer is queryable), and
//! — in each layer's abstract — how 16-bit PNG codes map to values, and
//! each layer's default style with its legend's URL (GetLegendGraphic, the
//! SLD profile's request, is offered beside the core ones).

use super::super::exception::escape;
use super::info::InfoFormat;
use super::legend;
use super::picture::PictureFormat;
use super::request::{LAYERS, MapFormat, MapLayer, RequestCrs, Version};
use crate::encode::{self, Quantization};
use crate::grid::BBox;
use crate::grid::mercator::to_mercator;

/// What the documents describe.
pub struct Service<'a> {
    /// Absolute URL of the WMS endpoint (without query).
    pub url: &'a str,
    /// Region name, the service title.
    pub title: &'a str,
    /// Where the data is.
    pub bounds: BBox,
    /// Largest WIDTH / HEIGHT.
    pub max_side: usize,
    /// PNG16 quantization of heights.
    pub heights_16: Quantization,
    /// Whether the pictures take a map's colours (the legends say so).
    pub map: bool,
}

/// The capabilities document of `version`, and its MIME type.
pub fn document(s: &Service, version: Version) -> (&'static str, String) {
    match version {
        Version::V130 => ("text/xml; charset=utf-8", v130(s)),
        Version::V111 => ("application/vnd.ogc.wms_xml; charset=utf-8", v111(s)),
    }
}

fn v130(s: &Service) -> String {
    let url = escape(s.url);
    // Longitudes within ±180, as the schema's longitudeType requires.
    let b = s.bounds.on_the_globe();
    let formats: String = MapFormat::ALL.iter().map(|(_, m)| format!("<Format>{m}</Format>")).collect();
    let crs: String = RequestCrs::ALL.iter().map(|(_, n)| format!("<CRS>{n}</CRS>")).collect();
    format!(
        r#"<?xml version="1.0" encoding="UTF-8"?>
<WMS_Capabilities version="1.3.0" xmlns="http://www.opengis.net/wms" xmlns:sld="http://www.opengis.net/sld" xmlns:xlink="http://www.w3.org/1999/xlink" xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance" xsi:schemaLocation="http://www.opengis.net/wms http://schemas.opengis.net/wms/1.3.0/capabilities_1_3_0.xsd http://www.opengis.net/sld http://schemas.opengis.net/sld/1.1.0/sld_capabilities.xsd">
<Service><Name>WMS</Name><Title>{title}</Title><Abstract>Combined elevation maps (terrain + forest canopy) computed on demand by Sylva.</Abstract><OnlineResource xlink:type="simple" xlink:href="{url}"/><LayerLimit>1</LayerLimit><MaxWidth>{max}</MaxWidth><MaxHeight>{max}</MaxHeight></Service>
<Capability><Request>
<GetCapabilities><Format>text/xml</Format>{dcp}</GetCapabilities>
<GetMap>{formats}{dcp}</GetMap>
<GetFeatureInfo>{info}{dcp}</GetFeatureInfo>
<sld:GetLegendGraphic>{legends}{dcp}</sld:GetLegendGraphic>
</Request>
<Exception><Format>XML</Format><Format>INIMAGE</Format><Format>BLANK</Format></Exception>
<Layer><Title>{title}</Title>{crs}
<EX_GeographicBoundingBox><westBoundLongitude>{w}</westBoundLongitude><eastBoundLongitude>{e}</eastBoundLongitude><southBoundLatitude>{so}</southBoundLatitude><northBoundLatitude>{n}</northBoundLatitude></EX_GeographicBoundingBox>
{boxes}
{layers}</Layer>
</Capability>
</WMS_Capabilities>
"#,
        title = escape(s.title),
        max = s.max_side,
        dcp = dcp(&url),
        info = info_formats(),
        legends = legend_formats(),
        w = b.west,
        e = b.east,
        so = b.south,
        n = b.north,
        boxes = bounding_boxes(b, Version::V130),
        layers = layers(s, Version::V130),
    )
}

fn v111(s: &Service) -> String {
    let url = escape(s.url);
    // Longitudes within ±180, as the schema's longitudeType requires.
    let b = s.bounds.on_the_globe();
    let formats: String = MapFormat::ALL.iter().map(|(_, m)| format!("<Format>{m}</Format>")).collect();
    let srs: String = RequestCrs::ALL
        .iter()
        .filter(|(c, _)| *c != RequestCrs::Crs84)
        .map(|(_, n)| format!("<SRS>{n}</SRS>"))
        .collect();
    format!(
        r#"<?xml version="1.0" encoding="UTF-8"?>
<!DOCTYPE WMT_MS_Capabilities SYSTEM "http://schemas.opengis.net/wms/1.1.1/WMS_MS_Capabilities.dtd">
<WMT_MS_Capabilities version="1.1.1">
<Service><Name>OGC:WMS</Name><Title>{title}</Title><Abstract>Combined elevation maps (terrain + forest canopy) computed on demand by Sylva.</Abstract><OnlineResource xmlns:xlink="http://www.w3.org/1999/xlink" xlink:type="simple" xlink:href="{url}"/></Service>
<Capability><Request>
<GetCapabilities><Format>application/vnd.ogc.wms_xml</Format>{dcp}</GetCapabilities>
<GetMap>{formats}{dcp}</GetMap>
<GetFeatureInfo>{info}{dcp}</GetFeatureInfo>
<GetLegendGraphic>{legends}{dcp}</GetLegendGraphic>
</Request>
<Exception><Format>application/vnd.ogc.se_xml</Format><Format>application/vnd.ogc.se_inimage</Format><Format>application/vnd.ogc.se_blank</Format></Exception>
<Layer><Title>{title}</Title>{srs}
<LatLonBoundingBox minx="{w}" miny="{so}" maxx="{e}" maxy="{n}"/>
{boxes}
{layers}</Layer>
</Capability>
</WMT_MS_Capabilities>
"#,
        title = escape(s.title),
        dcp = dcp_111(&url),
        info = info_formats(),
        legends = legend_formats(),
        w = b.west,
        e = b.east,
        so = b.south,
        n = b.north,
        boxes = bounding_boxes(b, Version::V111),
        layers = layers(s, Version::V111),
    )
}

fn legend_formats() -> String {
    [PictureFormat::Png, PictureFormat::Jpeg].map(|f| format!("<Format>{}</Format>", f.mime())).concat()
}

fn info_formats() -> String {
    InfoFormat::ALL.iter().map(|(_, m)| format!("<Format>{m}</Format>")).collect()
}

fn dcp(url: &str) -> String {
    format!(r#"<DCPType><HTTP><Get><OnlineResource xlink:type="simple" xlink:href="{url}?"/></Get></HTTP></DCPType>"#)
}

fn dcp_111(url: &str) -> String {
    format!(
        r#"<DCPType><HTTP><Get><OnlineResource xmlns:xlink="http://www.w3.org/1999/xlink" xlink:type="simple" xlink:href="{url}?"/></Get></HTTP></DCPType>"#
    )
}

/// A `BoundingBox` per CRS, in the CRS's axis order for `version` (within
/// each CRS's domain: longitudes within ±180).
fn bounding_boxes(b: BBox, version: Version) -> String {
    let b = b.on_the_globe();
    let (x0, y0) = to_mercator(b.west, b.south);
    let (x1, y1) = to_mercator(b.east, b.north);
    let attr = if version == Version::V130 { "CRS" } else { "SRS" };
    let mut out = Vec::new();
    for (crs, name) in RequestCrs::ALL {
        let [a, bb, c, d] = match (crs, version) {
            // A region beyond Web Mercator's latitudes has no box in it.
            (RequestCrs::Epsg3857, _) if y0 >= y1 => continue,
            (RequestCrs::Epsg3857, _) => [x0, y0, x1, y1],
            (RequestCrs::Epsg4326, Version::V130) => [b.south, b.west, b.north, b.east],
            (RequestCrs::Crs84, Version::V111) => continue,
            _ => [b.west, b.south, b.east, b.north],
        };
        out.push(format!(r#"<BoundingBox {attr}="{name}" minx="{a}" miny="{bb}" maxx="{c}" maxy="{d}"/>"#));
    }
    out.join("\n")
}

fn layers(s: &Service, version: Version) -> String {
    LAYERS
        .iter()
        .map(|&l| {
            format!(
                r#"<Layer queryable="1"><Name>{}</Name><Title>{}</Title><Abstract>{}</Abstract>{}{}</Layer>"#,
                l.name(),
                title(l),
                escape(&abstract_of(l, s)),
                bounding_boxes(s.bounds, version).replace('\n', ""),
                style(l, s, version)
            )
        })
        .collect::<Vec<_>>()
        .join("\n")
}

/// A layer's one style, the default, with the URL of its legend.
fn style(layer: MapLayer, s: &Service, version: Version) -> String {
    let (w, h) = legend::size(layer, s.map, (legend::SWATCH_PX, legend::SWATCH_PX));
    let href = escape(&legend_url(s.url, layer, version));
    let xmlns = if version == Version::V111 { r#" xmlns:xlink="http://www.w3.org/1999/xlink""# } else { "" };
    format!(
        r#"<Style><Name>default</Name><Title>Default</Title><LegendURL width="{w}" height="{h}"><Format>image/png</Format><OnlineResource{xmlns} xlink:type="simple" xlink:href="{href}"/></LegendURL></Style>"#
    )
}

/// The GetLegendGraphic URL of `layer`'s legend at the WMS endpoint `url`.
pub(crate) fn legend_url(url: &str, layer: MapLayer, version: Version) -> String {
    let v = if version == Version::V111 { "1.1.1" } else { "1.3.0" };
    format!("{url}?SERVICE=WMS&REQUEST=GetLegendGraphic&VERSION={v}&FORMAT=image/png&LAYER={}&STYLE=", layer.name())
}

/// A layer's title, for people.
pub(crate) fn title(layer: MapLayer) -> &'static str {
    use crate::cem::Layer::*;
    match layer {
        MapLayer::Data(Dem) => "Ground elevation (m)",
        MapLayer::Data(Cover) => "Vegetation cover (0-1)",
        MapLayer::Data(Canopy) => "Canopy height above ground (m)",
        MapLayer::Data(Cem) => "Combined elevation map: ground + canopy (m)",
        MapLayer::Data(Surface) => "Surface type (class id)",
        MapLayer::Data(_) => "Safety zone (m)",
        MapLayer::Colour => "Map colours, unshaded (the renderer's texture)",
        MapLayer::Relief => "Shaded relief with map colours and canopy",
    }
}

/// How to read the layer's encodings.
fn abstract_of(layer: MapLayer, s: &Service) -> String {
    let picture = "PNG for viewing: RGBA with TRANSPARENT=TRUE, else RGB on BGCOLOR (white).";
    let l = match layer {
        MapLayer::Data(l) => l,
        MapLayer::Colour => return format!("The map colours, unshaded. {picture}"),
        MapLayer::Relief => return format!("Hillshade of the combined elevation map over the map colours. {picture}"),
    };
    let (units, png_nodata, jpeg) = match l {
        crate::cem::Layer::Surface => {
            return "Class id (0 plain, 1 forest, 2 water, 3 rock, 4 ice, 5 built, 255 nodata), the id itself in \
                    every data format: image/png 16-bit grey, application/bil16 int16, application/bil32 float32, \
                    image/tiff 8-bit. image/jpeg: a picture, a colour per class."
                .into();
        }
        crate::cem::Layer::Cover => {
            ("cover fraction", "no nodata code: read bil or tiff to tell no data from 0", "grey, black 0 to white 1")
        }
        crate::cem::Layer::Canopy => ("metres", "code 0 is nodata", "grey, black 0 m to white 30 m"),
        _ => ("metres", "code 0 is nodata", "shaded grey"),
    };
    let (bil16, png16) = encode::quantizations(l, s.heights_16);
    format!(
        "Values in {units}. image/png: 16-bit grey, value = {} + {} * code ({png_nodata}). \
         application/bil16: little-endian int16, value = {} + {} * code, nodata -32768. \
         application/bil32 and image/tiff: float32, nodata -32768. image/jpeg: a picture, {jpeg}, on BGCOLOR \
         (white) where there is no data.",
        png16.offset, png16.scale, bil16.offset, bil16.scale
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn service() -> Service<'static> {
        Service {
            url: "http://127.0.0.1:8080/wms",
            title: "Test & region",
            bounds: BBox { west: -106.0, south: 40.0, east: -105.0, north: 41.0 },
            max_side: 4096,
            heights_16: Quantization::PNG16_HEIGHTS,
            map: false,
        }
    }

    #[test]
    fn a_region_across_the_antimeridian_is_advertised_within_180() {
        // Regression: a region of 179.5…180.5° E said eastBoundLongitude
        // 180.5 and an EPSG:3857 box past the world's edge (the schema's
        // longitudeType is −180…180).
        let fiji = Service { bounds: BBox { west: 179.5, south: -17.0, east: 180.5, north: -16.0 }, ..service() };
        for version in [Version::V111, Version::V130] {
            let (_, xml) = document(&fiji, version);
            assert!(!xml.contains("180.5") && !xml.contains("179.5"), "{xml}");
            assert!(xml.contains(r#"minx="-20037508.342789244""#), "{xml}");
        }
        // Beyond Web Mercator's latitudes: no EPSG:3857 box.
        let pole = Service { bounds: BBox { west: -180.0, south: -90.0, east: 180.0, north: -86.0 }, ..service() };
        for version in [Version::V111, Version::V130] {
            let (_, xml) = document(&pole, version);
            assert!(!xml.contains(r#"BoundingBox CRS="EPSG:3857""#) && !xml.contains(r#"SRS="EPSG:3857""#), "{xml}");
        }
    }

    #[test]
    fn both_versions_are_well_formed_and_list_every_layer() {
        for version in [Version::V111, Version::V130] {
            let (_, xml) = document(&service(), version);
            let options = roxmltree::ParsingOptions { allow_dtd: true, ..Default::default() };
            let doc = roxmltree::Document::parse_with_options(&xml, options)
                .unwrap_or_else(|e| panic!("{version:?}: {e}\n{xml}"));
            let names: Vec<&str> = doc
                .descendants()
                .filter(|n| n.has_tag_name("Name") && n.parent().is_some_and(|p| p.has_tag_name("Layer")))
                .filter_map(|n| n.text())
                .collect();
            assert_eq!(names, ["dem", "cover", "canopy", "cem", "surface", "colour", "relief"]);
            let queryable: Vec<&str> = doc
                .descendants()
                .filter(|n| n.has_tag_name("Layer"))
                .filter_map(|n| n.attribute("queryable"))
                .collect();
            assert_eq!(queryable, ["1"; 7], "every layer answers GetFeatureInfo");
            assert!(doc.descendants().any(|n| n.has_tag_name("GetFeatureInfo")));
        }
    }

    #[test]
    fn bounding_boxes_use_each_crs_axis_order() {
        let (_, xml) = document(&service(), Version::V130);
        let doc = roxmltree::Document::parse(&xml).unwrap();
        let boxes: Vec<_> = doc.descendants().filter(|n| n.has_tag_name("BoundingBox")).take(3).collect();
        let attr = |i: usize, a: &str| boxes[i].attribute(a).unwrap().parse::<f64>().unwrap();
        assert_eq!(boxes[0].attribute("CRS"), Some("EPSG:4326"));
        assert_eq!((attr(0, "minx"), attr(0, "miny")), (40.0, -106.0));
        assert_eq!(boxes[1].attribute("CRS"), Some("CRS:84"));
        assert_eq!((attr(1, "minx"), attr(1, "miny")), (-106.0, 40.0));
        assert!(attr(2, "minx") < -1.1e7 && attr(2, "miny") > 4.8e6);
        assert!(xml.contains("-500.15 + 0.15 * code"));
        let abstracts = doc.descendants().filter(|n| n.has_tag_name("Abstract")).filter_map(|n| n.text());
        assert!(abstracts.clone().any(|t| t.contains("the id itself in every data format")));
        assert!(abstracts.into_iter().all(|t| !t.contains("  ")), "abstracts read as single-spaced prose");
    }
}
