//! GeoTIFF reading with the `tiff` crate: integer and float bands, one band or
//! several (RGB), strips or tiles, chunky or planar; georeferencing from the
//! ModelPixelScale/ModelTiepoint or ModelTransformation tags and the CRS from
//! the GeoKey directory (EPSG codes, geographic or projected). Stored values
//! become heights as GDAL's per-band scale and offset (the GDAL_METADATA tag)
//! and the vertical CRS or unit (feet to metres, depths to heights) say. A
//! compression the decoder cannot undo, or a chunk past the end of the
//! file, is refused when the file is opened.
//!
//! Blocks are the file's own strips or tiles, decoded once into the block
//! cache. The decoder sits behind a mutex; decoding is short next to what is
//! done with the pixels, and cached blocks need no lock.

use super::{Crs, Georef, PixelSource, SourceError, palette};
use crate::raster::Raster;
use std::fs::File;
use std::io::BufReader;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use tiff::decoder::{Decoder, DecodingResult};
use tiff::tags::Tag;

/// GeoKey ids (GeoTIFF 1.1, section 7).
const GT_MODEL_TYPE: u16 = 1024;
const GT_RASTER_TYPE: u16 = 1025;
const GEOGRAPHIC_TYPE: u16 = 2048;
const PROJECTED_CS_TYPE: u16 = 3072;
const VERTICAL_CS_TYPE: u16 = 4096;
const VERTICAL_UNITS: u16 = 4099;
const USER_DEFINED: u16 = 32767;
const RASTER_PIXEL_IS_POINT: u16 = 2;
/// GDAL's metadata tag: XML items, among them each band's scale and offset.
const GDAL_METADATA: u16 = 42112;

/// Opens a GeoTIFF with its own CRS, or `crs_override` (an EPSG code) when
/// given. The file's nodata value reads as NaN.
pub fn open(path: &Path, crs_override: Option<u32>) -> Result<(Arc<dyn PixelSource>, Georef), SourceError> {
    let (file, georef) = TiffFile::open(path, crs_override)?;
    Ok((Arc::new(file), georef))
}

struct TiffFile {
    path: PathBuf,
    decoder: Mutex<Decoder<BufReader<File>>>,
    size: (usize, usize),
    bands: usize,
    planar: bool,
    chunk: (usize, usize),
    nodata: Option<f64>,
    /// Palette (indexed-colour) image: the indices are the data.
    palette: bool,
    /// Per band, `(a, b)`: a stored value `v` is `a · v + b` metres (or
    /// whatever the band holds); `None` where every band is stored as is.
    linear: Option<Vec<(f64, f64)>>,
}

impl TiffFile {
    fn open(path: &Path, crs_override: Option<u32>) -> Result<(TiffFile, Georef), SourceError> {
        let file = File::open(path).map_err(|source| SourceError::Open { path: path.into(), source })?;
        let bad = |problem: String| SourceError::Malformed { path: path.into(), problem };
        let mut dec = Decoder::new(BufReader::new(file)).map_err(|e| bad(format!("not a readable TIFF: {e}")))?;
        let (w, h) = dec.dimensions().map_err(|e| bad(e.to_string()))?;
        let bands = dec.find_tag_unsigned::<u16>(Tag::SamplesPerPixel).map_err(|e| bad(e.to_string()))?.unwrap_or(1);
        let planar = dec.find_tag_unsigned::<u16>(Tag::PlanarConfiguration).map_err(|e| bad(e.to_string()))? == Some(2);
        let nodata = read_nodata(&mut dec);
        let palette =
            dec.find_tag_unsigned::<u16>(Tag::PhotometricInterpretation).map_err(|e| bad(e.to_string()))? == Some(3);
        let keys = dec.get_tag_u16_vec(Tag::GeoKeyDirectoryTag).ok();
        let georef = read_georef(&mut dec, keys.as_deref(), path, crs_override)?;
        let linear =
            if palette { None } else { read_linear(&mut dec, keys.as_deref(), bands as usize).map_err(bad)? };
        let (cw, ch) = dec.chunk_dimensions();
        if w == 0 || h == 0 || cw == 0 || ch == 0 || bands == 0 {
            return Err(bad(format!("empty image ({w}×{h}, {bands} bands, chunks {cw}×{ch})")));
        }
        let compressed = check_compression(&mut dec).map_err(bad)?;
        let length = std::fs::metadata(path).map_err(|source| SourceError::Open { path: path.into(), source })?.len();
        check_chunks(&mut dec, length, compressed).map_err(bad)?;
        let tf = TiffFile {
            path: path.into(),
            decoder: Mutex::new(dec),
            size: (w as usize, h as usize),
            bands: bands as usize,
            planar,
            chunk: (cw as usize, ch as usize),
            nodata,
            palette,
            linear,
        };
        Ok((tf, georef))
    }

    fn bad(&self, problem: String) -> SourceError {
        SourceError::Malformed { path: self.path.clone(), problem }
    }

    /// Decodes one chunk into `bands` f32 planes (nodata → NaN).
    /// Returns the row-major samples (bands interleaved) and the chunk width.
    fn decode(
        &self,
        dec: &mut Decoder<BufReader<File>>,
        index: u32,
        planes: usize,
    ) -> Result<(Vec<f32>, usize), SourceError> {
        let (w, h) = dec.chunk_data_dimensions(index);
        let data = if self.palette {
            palette::read_indices(dec, index, self.chunk).map_err(|e| self.bad(format!("chunk {index}: {e}")))?
        } else {
            dec.read_chunk(index).map_err(|e| self.bad(format!("chunk {index}: {e}")))?
        };
        let values = to_f32(data, self.nodata).ok_or_else(|| self.bad("unsupported sample type".into()))?;
        if values.len() < (w * h) as usize * planes {
            return Err(self.bad(format!("chunk {index} is truncated")));
        }
        Ok((values, w as usize))
    }
}

impl PixelSource for TiffFile {
    fn name(&self) -> &Path {
        &self.path
    }

    fn size(&self) -> (usize, usize) {
        self.size
    }

    fn bands(&self) -> usize {
        self.bands
    }

    fn block_size(&self) -> (usize, usize) {
        self.chunk
    }

    fn read_block(&self, bx: usize, by: usize) -> Result<Vec<Raster<f32>>, SourceError> {
        let across = self.size.0.div_ceil(self.chunk.0);
        let per_plane = across * self.size.1.div_ceil(self.chunk.1);
        let index = by * across + bx;
        let mut dec = self.decoder.lock().map_err(|_| self.bad("decoder poisoned by an earlier panic".into()))?;
        let (h, w) =
            (self.chunk.1.min(self.size.1 - by * self.chunk.1), self.chunk.0.min(self.size.0 - bx * self.chunk.0));
        let value = |b: usize, v: f32| match &self.linear {
            Some(linear) => (linear[b].0 * f64::from(v) + linear[b].1) as f32,
            None => v,
        };
        if self.planar {
            (0..self.bands)
                .map(|b| {
                    let (v, row_len) = self.decode(&mut dec, (b * per_plane + index) as u32, 1)?;
                    Ok(Raster::from_fn(w, h, |x, y| value(b, v[y * row_len + x])))
                })
                .collect()
        } else {
            let (v, row_len) = self.decode(&mut dec, index as u32, self.bands)?;
            let n = self.bands;
            Ok((0..n).map(|b| Raster::from_fn(w, h, |x, y| value(b, v[(y * row_len + x) * n + b]))).collect())
        }
    }
}

fn to_f32(data: DecodingResult, nodata: Option<f64>) -> Option<Vec<f32>> {
    fn conv<T: Copy + Into<f64>>(v: Vec<T>, nodata: Option<f64>) -> Vec<f32> {
        v.into_iter()
            .map(|x| {
                let x: f64 = x.into();
                if Some(x) == nodata || x.is_nan() { f32::NAN } else { x as f32 }
            })
            .collect()
    }
    Some(match data {
        DecodingResult::U8(v) => conv(v, nodata),
        DecodingResult::I8(v) => conv(v, nodata),
        DecodingResult::U16(v) => conv(v, nodata),
        DecodingResult::I16(v) => conv(v, nodata),
        DecodingResult::U32(v) => conv(v, nodata),
        DecodingResult::I32(v) => conv(v, nodata),
        // GDAL writes the nodata text of the double it was given; float32
        // pixels hold it rounded to float32, and GDAL compares them so.
        DecodingResult::F32(v) => conv(v, nodata.map(|n| f64::from(n as f32))),
        DecodingResult::F64(v) => conv(v, nodata),
        _ => return None,
    })
}

/// Refuses, when the file is opened and not at its first read, a
/// compression the decoder cannot undo, naming it; else whether the file is
/// compressed.
fn check_compression(dec: &mut Decoder<BufReader<File>>) -> Result<bool, String> {
    let code = dec.find_tag_unsigned::<u16>(Tag::Compression).map_err(|e| e.to_string())?.unwrap_or(1);
    let name = match code {
        1 => return Ok(false),
        // LZW, JPEG, Deflate (and its old code), PackBits, CCITT Group 4, Zstandard.
        5 | 7 | 8 | 32946 | 32773 | 4 | 50000 => return Ok(true),
        2 => "CCITT RLE",
        3 => "CCITT Group 3",
        6 => "old-style JPEG",
        34712 => "JPEG 2000",
        34887 => "LERC",
        34925 => "LZMA",
        50001 => "WebP",
        50002 => "JPEG XL",
        _ => "an unknown method",
    };
    Err(format!(
        "compressed with {name} (TIFF compression {code}), which Sylva cannot read; recompress it with DEFLATE, LZW or ZSTD (gdal_translate -co COMPRESS=DEFLATE IN OUT)"
    ))
}

/// Refuses a file cut short: every chunk must lie within its `length` bytes
/// (uncompressed, only its first byte: the decoder reads the rows it needs,
/// and libtiff and GDAL accept a last strip whose stated size runs past the
/// end).
fn check_chunks(dec: &mut Decoder<BufReader<File>>, length: u64, compressed: bool) -> Result<(), String> {
    let tiled = dec.find_tag(Tag::TileOffsets).map_err(|e| e.to_string())?.is_some();
    let (offsets, counts) =
        if tiled { (Tag::TileOffsets, Tag::TileByteCounts) } else { (Tag::StripOffsets, Tag::StripByteCounts) };
    let offsets = dec.get_tag_u64_vec(offsets).map_err(|e| e.to_string())?;
    let counts = dec.get_tag_u64_vec(counts).map_err(|e| e.to_string())?;
    let stated = |c: u64| if compressed { c } else { c.min(1) };
    match offsets.iter().zip(&counts).position(|(o, c)| o.saturating_add(stated(*c)) > length) {
        Some(i) => Err(format!("truncated: chunk {i} lies past the end of its {length} bytes")),
        None => Ok(()),
    }
}

/// GDAL's nodata tag (ASCII, e.g. "-32768" or "nan").
fn read_nodata(dec: &mut Decoder<BufReader<File>>) -> Option<f64> {
    let text = dec.get_tag_ascii_string(Tag::GdalNodata).ok()?;
    text.trim_matches(char::from(0)).trim().parse().ok()
}

/// How each of `bands` bands' stored values become values: GDAL's scale
/// and offset items, then, in a one-band file (a DEM), metres up per stored
/// unit ([`vertical_unit_m`]). `None` where nothing changes a value.
fn read_linear(
    dec: &mut Decoder<BufReader<File>>,
    keys: Option<&[u16]>,
    bands: usize,
) -> Result<Option<Vec<(f64, f64)>>, String> {
    let mut linear = vec![(1.0, 0.0); bands];
    if let Ok(text) = dec.get_tag_ascii_string(Tag::Unknown(GDAL_METADATA)) {
        scale_and_offset(text.trim_matches(char::from(0)), &mut linear)?;
    }
    let unit_m = keys.map_or(1.0, vertical_unit_m);
    if bands == 1 {
        linear[0] = (linear[0].0 * unit_m, linear[0].1 * unit_m);
    }
    Ok(linear.iter().any(|&l| l != (1.0, 0.0)).then_some(linear))
}

/// Metres up per stored unit of the GeoKey directory `keys`: its vertical
/// CRS's (GDAL writes no unit key beside an EPSG code), else its vertical
/// unit key's (feet and US survey feet).
fn vertical_unit_m(keys: &[u16]) -> f64 {
    let by_crs = geokey(keys, VERTICAL_CS_TYPE).and_then(super::vertical::metres_up);
    by_crs.unwrap_or(match geokey(keys, VERTICAL_UNITS) {
        Some(9002) => 0.3048,
        Some(9003) => 1200.0 / 3937.0,
        _ => 1.0,
    })
}

/// Reads the `scale` and `offset` items of GDAL's metadata XML into
/// `linear`, per band (`sample`, 0 when absent).
fn scale_and_offset(xml: &str, linear: &mut [(f64, f64)]) -> Result<(), String> {
    let doc = roxmltree::Document::parse(xml).map_err(|e| format!("its GDAL_METADATA tag is not XML: {e}"))?;
    for item in doc.descendants().filter(|n| n.has_tag_name("Item")) {
        let role = item.attribute("role").unwrap_or("");
        if role != "scale" && role != "offset" {
            continue;
        }
        let text = item.text().unwrap_or("").trim();
        let value: f64 = text.parse().map_err(|_| format!("GDAL_METADATA {role} {text:?} is not a number"))?;
        let band = item.attribute("sample").map_or(Ok(0), str::parse::<usize>);
        let Some(l) = band.ok().and_then(|b| linear.get_mut(b)) else {
            return Err(format!("GDAL_METADATA {role} for sample {:?}: no such band", item.attribute("sample")));
        };
        match role {
            "scale" => l.0 = value,
            _ => l.1 = value,
        }
    }
    Ok(())
}

/// The georeferencing from the file's tags and its GeoKey directory `keys`.
fn read_georef(
    dec: &mut Decoder<BufReader<File>>,
    keys: Option<&[u16]>,
    path: &Path,
    crs_override: Option<u32>,
) -> Result<Georef, SourceError> {
    let bad = |problem: &str| SourceError::Malformed { path: path.into(), problem: problem.into() };
    let key = |id: u16| keys.and_then(|k| geokey(k, id));
    let crs = match crs_override.or_else(|| crs_code(key(GT_MODEL_TYPE), key(GEOGRAPHIC_TYPE), key(PROJECTED_CS_TYPE)))
    {
        Some(code) => Crs::from_epsg(code).map_err(|source| SourceError::Crs { path: path.into(), source })?,
        None => {
            return Err(SourceError::Unsupported {
                path: path.into(),
                what:
                    "no EPSG code in its GeoKeys (user-defined or missing CRS); set `crs = \"EPSG:…\"` for this source"
                        .into(),
            });
        }
    };
    let point = key(GT_RASTER_TYPE) == Some(RASTER_PIXEL_IS_POINT);
    // Corner of pixel (0, 0) and pixel size, from either georeferencing form.
    let (corner_x, corner_y, dx, dy) = if let Ok(m) = dec.get_tag_f64_vec(Tag::ModelTransformationTag) {
        if m.len() < 8 || m[1] != 0.0 || m[4] != 0.0 {
            return Err(SourceError::Unsupported {
                path: path.into(),
                what: "rotated or sheared ModelTransformation".into(),
            });
        }
        (m[3], m[7], m[0], m[5])
    } else {
        let scale = dec
            .get_tag_f64_vec(Tag::ModelPixelScaleTag)
            .map_err(|_| bad("no ModelPixelScale or ModelTransformation tag: not georeferenced"))?;
        let tie =
            dec.get_tag_f64_vec(Tag::ModelTiepointTag).map_err(|_| bad("no ModelTiepoint tag: not georeferenced"))?;
        if scale.len() < 2 || tie.len() < 6 {
            return Err(bad("short ModelPixelScale or ModelTiepoint tag"));
        }
        (tie[3] - tie[0] * scale[0], tie[4] + tie[1] * scale[1], scale[0], -scale[1])
    };
    if !(dx.is_finite() && dy.is_finite() && dx != 0.0 && dy != 0.0 && corner_x.is_finite() && corner_y.is_finite()) {
        return Err(bad("degenerate georeferencing (zero or non-finite pixel size)"));
    }
    // PixelIsArea: the tiepoint is the pixel's corner; PixelIsPoint: its centre.
    let half = if point { 0.0 } else { 0.5 };
    Ok(Georef {
        crs: Arc::new(crs),
        x0: corner_x + half * dx,
        y0: corner_y + half * dy,
        dx,
        dy,
        overhang: if point { 0.0 } else { 0.5 },
    })
}

/// The value of a GeoKey stored inline in the directory.
fn geokey(dir: &[u16], id: u16) -> Option<u16> {
    let count = *dir.get(3)? as usize;
    dir.get(4..4 + 4 * count)?.chunks_exact(4).find(|e| e[0] == id && e[1] == 0).map(|e| e[3])
}

fn crs_code(model: Option<u16>, geographic: Option<u16>, projected: Option<u16>) -> Option<u32> {
    let usable = |c: Option<u16>| c.filter(|&c| c != 0 && c != USER_DEFINED).map(u32::from);
    match model {
        Some(1) => usable(projected),
        Some(2) => usable(geographic),
        _ => usable(projected).or(usable(geographic)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn geokeys_are_looked_up_inline_only() {
        let dir = [1, 1, 0, 3, 1024, 0, 1, 1, 1025, 0, 1, 1, 3072, 0, 1, 26910];
        assert_eq!(geokey(&dir, PROJECTED_CS_TYPE), Some(26910));
        assert_eq!(geokey(&dir, GEOGRAPHIC_TYPE), None);
        assert_eq!(crs_code(Some(1), None, Some(26910)), Some(26910));
        assert_eq!(crs_code(Some(1), Some(4269), Some(USER_DEFINED)), None);
        assert_eq!(geokey(&[1, 1, 0, 9], 1024), None);
    }

    /// A 4 × 2 UInt16 GeoTIFF (values 0, 100, …, 700) in EPSG:4326 with
    /// `metadata` and, if given, the vertical GeoKey `(key, value)`.
    fn stored(name: &str, metadata: Option<&str>, vertical: Option<(u16, u16)>) -> PathBuf {
        use tiff::encoder::{TiffEncoder, colortype};
        let path = std::env::temp_dir().join(format!("sylva-geotiff-{}-{name}.tif", std::process::id()));
        let mut keys = vec![1, 1, 0, 3, 1024, 0, 1, 2, 1025, 0, 1, 1, 2048, 0, 1, 4326];
        if let Some((key, value)) = vertical {
            keys[3] = 4;
            keys.extend([key, 0, 1, value]);
        }
        let mut enc = TiffEncoder::new(std::fs::File::create(&path).unwrap()).unwrap();
        let mut img = enc.new_image::<colortype::Gray16>(4, 2).unwrap();
        let dir = img.encoder();
        dir.write_tag(Tag::ModelPixelScaleTag, &[0.1, 0.1, 0.0][..]).unwrap();
        dir.write_tag(Tag::ModelTiepointTag, &[0.0, 0.0, 0.0, 10.0, 47.0, 0.0][..]).unwrap();
        dir.write_tag(Tag::GeoKeyDirectoryTag, &keys[..]).unwrap();
        if let Some(text) = metadata {
            dir.write_tag(Tag::Unknown(GDAL_METADATA), text).unwrap();
        }
        img.write_data(&(0..8).map(|v| v * 100).collect::<Vec<u16>>()).unwrap();
        path
    }

    /// The first row of the file at `path`, which is then removed.
    fn first_row(path: &Path) -> Result<Vec<f32>, SourceError> {
        let read = open(path, None).and_then(|(file, _)| Ok(file.read_block(0, 0)?[0].data()[..4].to_vec()));
        std::fs::remove_file(path).ok();
        read
    }

    #[test]
    fn scaled_and_offset_bands_and_heights_in_feet_are_read_in_metres() {
        // Regression: GDAL's scale and offset and the vertical unit were
        // ignored: a DEM stored in decimetres from −500 m read 10× too high.
        let gdal = r#"<GDALMetadata>
  <Item name="OFFSET" sample="0" role="offset">-500</Item>
  <Item name="SCALE" sample="0" role="scale">0.1</Item>
</GDALMetadata>"#;
        assert_eq!(first_row(&stored("plain", None, None)).unwrap(), [0.0, 100.0, 200.0, 300.0]);
        assert_eq!(first_row(&stored("scaled", Some(gdal), None)).unwrap(), [-500.0, -490.0, -480.0, -470.0]);
        let feet = first_row(&stored("feet", None, Some((VERTICAL_UNITS, 9002)))).unwrap();
        assert_eq!(feet, [0.0, 30.48, 60.96, 91.44]);
        let metres = first_row(&stored("metres", None, Some((VERTICAL_UNITS, 9001)))).unwrap();
        assert_eq!(metres, [0.0, 100.0, 200.0, 300.0]);
        // GDAL writes a vertical CRS's code and no unit key (regression:
        // heights in NAVD88 US survey feet were read as metres); depths
        // are heights below.
        let navd88_ft = first_row(&stored("navd88-ft", None, Some((VERTICAL_CS_TYPE, 6360)))).unwrap();
        assert!((navd88_ft[3] - 91.44018).abs() < 1e-4, "{navd88_ft:?}");
        let depth = first_row(&stored("depth", None, Some((VERTICAL_CS_TYPE, 5715)))).unwrap();
        assert_eq!(depth, [0.0, -100.0, -200.0, -300.0]);
        let navd88_m = first_row(&stored("navd88-m", None, Some((VERTICAL_CS_TYPE, 5703)))).unwrap();
        assert_eq!(navd88_m, [0.0, 100.0, 200.0, 300.0]);
        let bad = stored("bad", Some(r#"<GDALMetadata><Item role="scale">ten</Item></GDALMetadata>"#), None);
        let err = first_row(&bad).expect_err("a scale that is no number").to_string();
        assert!(err.contains("sylva-geotiff") && err.contains("scale \"ten\" is not a number"), "{err}");
        let other =
            stored("band", Some(r#"<GDALMetadata><Item sample="3" role="scale">2</Item></GDALMetadata>"#), None);
        assert!(first_row(&other).expect_err("a band that is not there").to_string().contains("no such band"));
    }

    /// Sets the low 16 bits of the value of the first IFD's tag `tag` (one
    /// short or long) in the little-endian TIFF at `path`.
    fn patch_tag(path: &Path, tag: u16, value: u16) {
        let mut bytes = std::fs::read(path).unwrap();
        let ifd = u32::from_le_bytes(bytes[4..8].try_into().unwrap()) as usize;
        let count = u16::from_le_bytes([bytes[ifd], bytes[ifd + 1]]) as usize;
        let entry = (0..count).map(|i| ifd + 2 + 12 * i).find(|&e| bytes[e..e + 2] == tag.to_le_bytes()).unwrap();
        bytes[entry + 8..entry + 10].copy_from_slice(&value.to_le_bytes());
        std::fs::write(path, bytes).unwrap();
    }

    #[test]
    fn unreadable_compression_and_truncation_are_refused_at_open() {
        // Regression: both opened (`sylva info` passed them) and failed at
        // the first read, the compression as "Unknown(34887)".
        let lerc = stored("lerc", None, None);
        patch_tag(&lerc, 259, 34887);
        let err = first_row(&lerc).expect_err("LERC").to_string();
        assert!(
            err.contains("sylva-geotiff") && err.contains("compressed with LERC (TIFF compression 34887)"),
            "{err}"
        );
        // A strip at byte 65535 of a file of a few hundred, as if cut short.
        let cut = stored("cut", None, None);
        patch_tag(&cut, 273, u16::MAX);
        let err = first_row(&cut).expect_err("cut short").to_string();
        assert!(err.contains("truncated: chunk 0 lies past the end of its"), "{err}");
    }

    #[test]
    fn float32_pixels_match_the_nodata_text_gdal_wrote() {
        // Regression: GDAL writes the double it was given ("-3.402823e+38"
        // as below); float32 pixels hold it rounded, and compared as
        // doubles they were heights of −3.4·10³⁸.
        for text in ["-3.40282299999999995e+38", "0.100000000000000006"] {
            let nodata: f64 = text.parse().unwrap();
            let pixels = vec![nodata as f32, 1500.0];
            let read = to_f32(DecodingResult::F32(pixels), Some(nodata)).unwrap();
            assert!(read[0].is_nan() && read[1] == 1500.0, "{text}: {read:?}");
        }
        let read = to_f32(DecodingResult::I16(vec![-32768, 7]), Some(-32768.0)).unwrap();
        assert!(read[0].is_nan() && read[1] == 7.0);
    }
}
