//! OGC service exceptions: the codes of WMS 1.1.1 / 1.3.0 and WMTS 1.0.0
//! (and the OWS common `MissingParameterValue` / `InvalidParameterValue`),
//! the ServiceExceptionReport documents of both WMS versions, and the OWS
//! 1.1 ExceptionReport of WMTS.

use super::wms::request::Version;
use std::fmt;

/// Exception codes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Code {
    /// Unknown layer.
    LayerNotDefined,
    /// Unknown style (each layer has only its default one).
    StyleNotDefined,
    /// CRS not offered (1.3.0).
    InvalidCrs,
    /// SRS not offered (1.1.1).
    InvalidSrs,
    /// Format not offered.
    InvalidFormat,
    /// A required parameter is missing.
    MissingParameterValue,
    /// A parameter has a bad value.
    InvalidParameterValue,
    /// Request type not supported.
    OperationNotSupported,
    /// GetFeatureInfo's pixel is off the map (1.3.0 only).
    InvalidPoint,
    /// A WMTS tile's row or column is outside its matrix.
    TileOutOfRange,
    /// A WMTS GetFeatureInfo's pixel is outside its tile.
    PointIjOutOfRange,
    /// None of the versions a GetCapabilities accepts is served (OWS
    /// Common's `AcceptVersions`).
    VersionNegotiationFailed,
    /// The server failed (no standard code; reported without one).
    NoApplicableCode,
}

impl Code {
    /// The code as written in reports.
    pub fn as_str(self) -> &'static str {
        match self {
            Code::LayerNotDefined => "LayerNotDefined",
            Code::InvalidPoint => "InvalidPoint",
            Code::TileOutOfRange => "TileOutOfRange",
            Code::PointIjOutOfRange => "PointIJOutOfRange",
            Code::VersionNegotiationFailed => "VersionNegotiationFailed",
            Code::StyleNotDefined => "StyleNotDefined",
            Code::InvalidCrs => "InvalidCRS",
            Code::InvalidSrs => "InvalidSRS",
            Code::InvalidFormat => "InvalidFormat",
            Code::MissingParameterValue => "MissingParameterValue",
            Code::InvalidParameterValue => "InvalidParameterValue",
            Code::OperationNotSupported => "OperationNotSupported",
            Code::NoApplicableCode => "NoApplicableCode",
        }
    }
}

/// One exception: a code, a message and optionally the parameter at fault.
#[derive(Clone, Debug, PartialEq)]
pub struct Exception {
    /// The code.
    pub code: Code,
    /// What went wrong, for people.
    pub message: String,
    /// The parameter concerned.
    pub locator: Option<String>,
}

impl Exception {
    /// An exception without locator.
    pub fn new(code: Code, message: impl Into<String>) -> Exception {
        Exception { code, message: message.into(), locator: None }
    }

    /// The same exception, naming the parameter at fault.
    pub fn locator(mut self, parameter: impl Into<String>) -> Exception {
        self.locator = Some(parameter.into());
        self
    }

    /// The ServiceExceptionReport document for `version`, and its MIME type.
    pub fn report(&self, version: Version) -> (&'static str, String) {
        let code = match self.code {
            Code::NoApplicableCode => String::new(),
            c => format!(" code=\"{}\"", c.as_str()),
        };
        let locator = self.locator_attribute();
        let message = ascii_text(&self.message);
        match version {
            Version::V111 => (
                "application/vnd.ogc.se_xml",
                format!(
                    "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n\
                     <ServiceExceptionReport version=\"1.1.1\">\n  \
                     <ServiceException{code}{locator}>{message}</ServiceException>\n\
                     </ServiceExceptionReport>\n"
                ),
            ),
            Version::V130 => (
                "text/xml",
                format!(
                    "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n\
                     <ServiceExceptionReport version=\"1.3.0\" xmlns=\"http://www.opengis.net/ogc\" \
                     xmlns:xsi=\"http://www.w3.org/2001/XMLSchema-instance\" \
                     xsi:schemaLocation=\"http://www.opengis.net/ogc http://schemas.opengis.net/wms/1.3.0/exceptions_1_3_0.xsd\">\n  \
                     <ServiceException{code}{locator}>{message}</ServiceException>\n\
                     </ServiceExceptionReport>\n"
                ),
            ),
        }
    }

    /// The OWS 1.1 ExceptionReport document of WMTS 1.0.0, and its MIME type.
    pub fn ows_report(&self) -> (&'static str, String) {
        let locator = self.locator_attribute();
        (
            "application/xml",
            format!(
                "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n\
                 <ExceptionReport xmlns=\"http://www.opengis.net/ows/1.1\" version=\"1.0.0\" xml:lang=\"en\">\n  \
                 <Exception exceptionCode=\"{}\"{locator}><ExceptionText>{}</ExceptionText></Exception>\n\
                 </ExceptionReport>\n",
                self.code.as_str(),
                ascii_text(&self.message)
            ),
        )
    }

    /// ` locator="…"`, or nothing.
    fn locator_attribute(&self) -> String {
        self.locator.as_deref().map(|l| format!(" locator=\"{}\"", escape(l))).unwrap_or_default()
    }
}

/// `text` escaped for XML, in ASCII: characters beyond it as references
/// (clients match the MIME type exactly, no charset, and some then decode
/// as Latin-1).
fn ascii_text(text: &str) -> String {
    escape(text).chars().map(|c| if c.is_ascii() { c.to_string() } else { format!("&#x{:X};", u32::from(c)) }).collect()
}

impl fmt::Display for Exception {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}: {}", self.code.as_str(), self.message)
    }
}

/// Escapes text for XML content and attribute values.
pub fn escape(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&apos;"),
            c => out.push(c),
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reports_are_valid_xml_with_code_and_locator() {
        let e = Exception::new(Code::InvalidCrs, "EPSG:2193 <not offered> & more").locator("CRS");
        for version in [Version::V111, Version::V130] {
            let (mime, xml) = e.report(version);
            let doc = roxmltree::Document::parse(&xml).unwrap();
            let ex = doc.descendants().find(|n| n.has_tag_name("ServiceException")).unwrap();
            assert_eq!(ex.attribute("code"), Some("InvalidCRS"));
            assert_eq!(ex.attribute("locator"), Some("CRS"));
            assert_eq!(ex.text(), Some("EPSG:2193 <not offered> & more"));
            assert!(mime.contains("xml"));
        }
        assert!(!Exception::new(Code::NoApplicableCode, "x").report(Version::V130).1.contains("code="));
        // Read alike whatever charset a client assumes.
        let (_, xml) = Exception::new(Code::InvalidParameterValue, "need 1 ≤ x").report(Version::V130);
        assert!(xml.is_ascii() && xml.contains("1 &#x2264; x"), "{xml}");
        let doc = roxmltree::Document::parse(&xml).unwrap();
        assert_eq!(doc.descendants().find(|n| n.has_tag_name("ServiceException")).unwrap().text(), Some("need 1 ≤ x"));
    }

    #[test]
    fn ows_reports_carry_the_code_locator_and_text() {
        let (mime, xml) = Exception::new(Code::TileOutOfRange, "row 9 ≥ 8").locator("TILEROW").ows_report();
        assert_eq!(mime, "application/xml");
        assert!(xml.is_ascii(), "{xml}");
        let doc = roxmltree::Document::parse(&xml).unwrap();
        assert_eq!(doc.root_element().tag_name().namespace(), Some("http://www.opengis.net/ows/1.1"));
        let ex = doc.descendants().find(|n| n.has_tag_name("Exception")).unwrap();
        assert_eq!(ex.attribute("exceptionCode"), Some("TileOutOfRange"));
        assert_eq!(ex.attribute("locator"), Some("TILEROW"));
        assert_eq!(ex.first_element_child().unwrap().text(), Some("row 9 ≥ 8"));
    }
}
