//! Hostile and broken inputs: truncated, garbage, ungeoreferenced files give
//! an error that names the file, never a panic.

use crate::common::{TempDir, data};
use sylva::raster::Window;
use sylva::source::{BlockCache, OpenOptions, SourceError, open_file};

fn open(path: &std::path::Path) -> Result<sylva::source::GeoRaster, SourceError> {
    open_file(path, &OpenOptions::default(), &BlockCache::new(1 << 24))
}

#[test]
fn a_truncated_geotiff_fails_when_its_missing_part_is_read() {
    let dir = TempDir::new("truncated");
    let bytes = std::fs::read(data("rmnp/rmnp-rgb.tif")).unwrap();
    let path = dir.join("half.tif");
    std::fs::write(&path, &bytes[..bytes.len() / 2]).unwrap();
    // The header and directory are at the start: opening may succeed, reading the whole image must not.
    let err = match open(&path) {
        Err(e) => e,
        Ok(r) => {
            let (w, h) = r.size();
            r.base().read(Window::new(0, 0, w, h)).expect_err("the second half is missing")
        }
    };
    assert!(err.to_string().contains("half.tif"), "{err}");
}

#[test]
fn garbage_and_plain_tiffs_are_refused_with_the_reason() {
    let dir = TempDir::new("garbage");
    let garbage = dir.join("garbage.tif");
    std::fs::write(&garbage, b"this is not a tiff at all").unwrap();
    let err = open(&garbage).expect_err("garbage").to_string();
    assert!(err.contains("garbage.tif") && err.contains("not a readable TIFF"), "{err}");

    // A valid TIFF without georeferencing.
    let plain = plain_tiff(&dir);
    let err = open(&plain).expect_err("no georeferencing").to_string();
    assert!(err.contains("plain.tif") && err.contains("EPSG"), "{err}");

    let missing = dir.join("missing.hgt");
    let err = open(&missing).expect_err("missing").to_string();
    assert!(err.contains("missing.hgt") && err.contains("cannot open"), "{err}");
    let unknown = dir.join("x.jp2");
    std::fs::write(&unknown, b"").unwrap();
    assert!(open(&unknown).expect_err("type").to_string().contains("unsupported"));

    // Wider than the globe (0…400° E): refused, naming the file.
    use sylva::grid::{Axis, SampleGrid};
    let grid = SampleGrid { lon: Axis::degrees(0.5, 1.0, 0, 400), lat: Axis::degrees(9.5, -1.0, 0, 10) };
    let heights = sylva::raster::Raster::filled(400, 10, 1.0f32);
    let wide = dir.join("wide.tif");
    std::fs::write(&wide, sylva::encode::geotiff::write(sylva::encode::Samples::Float(&heights), &grid).unwrap())
        .unwrap();
    let err = open(&wide).expect_err("wider than the globe").to_string();
    assert!(err.contains("wide.tif") && err.contains("400.000000° of longitude"), "{err}");
}

#[test]
fn a_crs_override_georeferences_a_file_without_geokeys() {
    // The same plain TIFF with a CRS given in the configuration still lacks a transform.
    let dir = TempDir::new("override");
    let plain = plain_tiff(&dir);
    let options = OpenOptions { crs: Some(32632), ..OpenOptions::default() };
    let err = open_file(&plain, &options, &BlockCache::new(1 << 20)).expect_err("no transform").to_string();
    assert!(err.contains("not georeferenced"), "{err}");
}

/// A valid 4 × 4 TIFF without georeferencing, `plain.tif` in `dir`.
fn plain_tiff(dir: &TempDir) -> std::path::PathBuf {
    let path = dir.join("plain.tif");
    let mut bytes = std::io::Cursor::new(Vec::new());
    tiff::encoder::TiffEncoder::new(&mut bytes)
        .unwrap()
        .write_image::<tiff::encoder::colortype::Gray8>(4, 4, &[0u8; 16])
        .unwrap();
    std::fs::write(&path, bytes.into_inner()).unwrap();
    path
}
