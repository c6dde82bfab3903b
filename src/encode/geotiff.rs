//! GeoTIFF output that GDAL reads with the right geotransform: tiles and
//! builds in EPSG:4326 (or 3857), and rasters on a metric grid in a projected
//! CRS (canopy height models and proxies, [`write_metric`]).
//!
//! Sylva's samples are points; GeoTIFF is written as `PixelIsArea` with each
//! pixel centred on its sample (origin half a step west and north of the
//! first sample), which every reader interprets the same way. Heights are
//! float32 with the GDAL nodata tag; surface classes are 8-bit.

use super::{EncodeError, NODATA_HEIGHT, Samples};
use crate::canopy::grid::MetricGrid;
use crate::grid::SampleGrid;
use crate::grid::lattice::Mapping;
use crate::raster::Raster;
use std::io::Cursor;
use tiff::encoder::{TiffEncoder, colortype};
use tiff::tags::Tag;

/// GeoKeyDirectory: version 1.1.0, three keys: model geographic, raster
/// pixel-is-area, geographic CRS EPSG:4326.
const GEOKEYS_4326: [u16; 16] = [1, 1, 0, 3, 1024, 0, 1, 2, 1025, 0, 1, 1, 2048, 0, 1, 4326];
/// The same for Web Mercator: model projected, projected CRS EPSG:3857.
const GEOKEYS_3857: [u16; 16] = [1, 1, 0, 3, 1024, 0, 1, 1, 1025, 0, 1, 1, 3072, 0, 1, 3857];

/// Writes the samples as a one-band GeoTIFF over `grid`, in EPSG:4326 or,
/// for grids regular in Web Mercator metres, EPSG:3857.
pub fn write(samples: Samples, grid: &SampleGrid) -> Result<Vec<u8>, EncodeError> {
    let (dx, dy) = (grid.lon.step.abs(), grid.lat.step.abs());
    let tiepoint = [0.0, 0.0, 0.0, grid.lon.value(0) - 0.5 * dx, grid.lat.value(0) + 0.5 * dy, 0.0];
    let geokeys = if grid.lat.mapping == Mapping::Degrees { GEOKEYS_4326 } else { GEOKEYS_3857 };
    encode(samples, [dx, dy, 0.0], tiepoint, &geokeys, None)
}

/// Writes heights on a metric grid in the projected CRS `epsg`, with an
/// optional ImageDescription (tile sets record their layout there).
pub fn write_metric(
    heights: &Raster<f32>,
    grid: &MetricGrid,
    epsg: u32,
    description: Option<&str>,
) -> Result<Vec<u8>, EncodeError> {
    let code = u16::try_from(epsg).map_err(|_| EncodeError(format!("EPSG:{epsg} does not fit a GeoKey")))?;
    let mut geokeys = GEOKEYS_3857;
    geokeys[15] = code;
    let tiepoint = [0.0, 0.0, 0.0, grid.x0, grid.y0, 0.0];
    encode(Samples::Float(heights), [grid.cell_m, grid.cell_m, 0.0], tiepoint, &geokeys, description)
}

fn encode(
    samples: Samples,
    scale: [f64; 3],
    tiepoint: [f64; 6],
    geokeys: &[u16],
    description: Option<&str>,
) -> Result<Vec<u8>, EncodeError> {
    let err = |e: tiff::TiffError| EncodeError(e.to_string());
    let (w, h) = match samples {
        Samples::Float(r) => (r.width() as u32, r.height() as u32),
        Samples::Class(r) => (r.width() as u32, r.height() as u32),
    };
    let mut out = Cursor::new(Vec::new());
    let mut enc = TiffEncoder::new(&mut out).map_err(err)?;
    macro_rules! image {
        ($color:ty, $data:expr, $nodata:expr) => {{
            let mut img = enc.new_image::<$color>(w, h).map_err(err)?;
            let dir = img.encoder();
            dir.write_tag(Tag::ModelPixelScaleTag, &scale[..]).map_err(err)?;
            dir.write_tag(Tag::ModelTiepointTag, &tiepoint[..]).map_err(err)?;
            dir.write_tag(Tag::GeoKeyDirectoryTag, geokeys).map_err(err)?;
            dir.write_tag(Tag::GdalNodata, $nodata).map_err(err)?;
            if let Some(text) = description {
                dir.write_tag(Tag::ImageDescription, text).map_err(err)?;
            }
            img.write_data($data).map_err(err)?;
        }};
    }
    match samples {
        Samples::Float(r) => {
            let data: Vec<f32> = r.data().iter().map(|&v| if v.is_nan() { NODATA_HEIGHT } else { v }).collect();
            image!(colortype::Gray32Float, &data, "-32768")
        }
        Samples::Class(r) => image!(colortype::Gray8, r.data(), "255"),
    }
    Ok(out.into_inner())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::{BBox, TileGrid};
    use crate::source::{BlockCache, OpenOptions, open_file};

    #[test]
    fn written_tiffs_read_back_through_our_own_reader() {
        let grid =
            BBox::parse("10,46,10.3,46.2").unwrap().point_grid(4, 3, &TileGrid::new(36.0, 513).unwrap()).unwrap();
        let r = Raster::from_fn(4, 3, |x, y| if (x, y) == (1, 1) { f32::NAN } else { (x + 10 * y) as f32 + 0.25 });
        let bytes = write(Samples::Float(&r), &grid).unwrap();
        let path = std::env::temp_dir().join(format!("sylva-geotiff-{}.tif", std::process::id()));
        std::fs::write(&path, bytes).unwrap();
        let options = OpenOptions { nodata: crate::source::NodataPolicy::Propagate, ..OpenOptions::default() };
        let src = open_file(&path, &options, &BlockCache::new(1 << 20)).unwrap();
        let g = src.georef();
        assert!((g.x0 - 10.0).abs() < 1e-12 && (g.y0 - 46.2).abs() < 1e-12 && (g.dx - 0.1).abs() < 1e-12);
        let back = src.sample(&grid, 0, crate::raster::resample::Resampling::Nearest).unwrap();
        for (a, b) in back.data().iter().zip(r.data()) {
            assert!(a == b || (a.is_nan() && b.is_nan()), "{a} {b}");
        }
        std::fs::remove_file(path).unwrap();
    }
}
