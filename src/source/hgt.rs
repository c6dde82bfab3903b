//! SRTM `.hgt` tiles: a square of big-endian `i16` heights, 1201² (3″) or
//! 3601² (1″), point-registered on the 1° cell named by the file
//! (`N46E011.hgt` spans 46–47 N, 11–12 E, first row at the north edge);
//! −32768 marks voids.
//!
//! Read by strips of rows with positioned reads, so a tile touches only the
//! rows it needs.

use super::{Crs, Georef, PixelSource, SourceError};
use crate::raster::Raster;
use std::fs::File;
use std::io::{Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

const VOID: i16 = -32768;
/// Rows per block.
const STRIP: usize = 64;

/// Opens an SRTM `.hgt` file; voids read as NaN.
pub fn open(path: &Path) -> Result<(Arc<dyn PixelSource>, Georef), SourceError> {
    let file = HgtFile::open(path)?;
    let n = file.side as f64;
    let georef = Georef {
        crs: Arc::new(Crs::wgs84()),
        x0: file.lon,
        y0: file.lat + 1.0,
        dx: 1.0 / (n - 1.0),
        dy: -1.0 / (n - 1.0),
        overhang: 0.0,
    };
    Ok((Arc::new(file), georef))
}

struct HgtFile {
    path: PathBuf,
    file: Mutex<File>,
    side: usize,
    lat: f64,
    lon: f64,
}

impl HgtFile {
    fn open(path: &Path) -> Result<HgtFile, SourceError> {
        let bad = |problem: String| SourceError::Malformed { path: path.into(), problem };
        let file = File::open(path).map_err(|source| SourceError::Open { path: path.into(), source })?;
        let (lat, lon) =
            parse_name(path).ok_or_else(|| bad("name must be like N46E011.hgt (the south-west corner)".into()))?;
        let len = file.metadata().map_err(|source| SourceError::Open { path: path.into(), source })?.len();
        let side = match len {
            2_884_802 => 1201,
            25_934_402 => 3601,
            other => return Err(bad(format!("{other} bytes: an SRTM tile has 1201² or 3601² two-byte samples"))),
        };
        Ok(HgtFile { path: path.into(), file: Mutex::new(file), side, lat, lon })
    }
}

/// `N46E011` → (46, 11); `S01W072` → (−1, −72).
fn parse_name(path: &Path) -> Option<(f64, f64)> {
    let stem = path.file_stem()?.to_str()?.to_ascii_uppercase();
    let (ns, rest) = stem.split_at_checked(1)?;
    let (lat, rest) = rest.split_at_checked(2)?;
    let (ew, lon) = rest.split_at_checked(1)?;
    let lat: f64 = lat.parse().ok()?;
    let lon: f64 = lon.get(..3)?.parse().ok()?;
    let lat = match ns {
        "N" => lat,
        "S" => -lat,
        _ => return None,
    };
    let lon = match ew {
        "E" => lon,
        "W" => -lon,
        _ => return None,
    };
    (lat.abs() <= 90.0 && lon.abs() <= 180.0).then_some((lat, lon))
}

impl PixelSource for HgtFile {
    fn name(&self) -> &Path {
        &self.path
    }

    fn size(&self) -> (usize, usize) {
        (self.side, self.side)
    }

    fn bands(&self) -> usize {
        1
    }

    fn block_size(&self) -> (usize, usize) {
        (self.side, STRIP)
    }

    fn read_block(&self, _bx: usize, by: usize) -> Result<Vec<Raster<f32>>, SourceError> {
        let rows = STRIP.min(self.side - by * STRIP);
        let mut bytes = vec![0u8; rows * self.side * 2];
        {
            let io = |source| SourceError::Open { path: self.path.clone(), source };
            let mut file = self.file.lock().map_err(|_| SourceError::Malformed {
                path: self.path.clone(),
                problem: "file handle poisoned by an earlier panic".into(),
            })?;
            file.seek(SeekFrom::Start((by * STRIP * self.side * 2) as u64)).map_err(io)?;
            file.read_exact(&mut bytes).map_err(io)?;
        }
        let values = bytes
            .chunks_exact(2)
            .map(|b| match i16::from_be_bytes([b[0], b[1]]) {
                VOID => f32::NAN,
                v => f32::from(v),
            })
            .collect();
        let raster = Raster::from_vec(self.side, rows, values)
            .ok_or_else(|| SourceError::Malformed { path: self.path.clone(), problem: "short read".into() })?;
        Ok(vec![raster])
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::BBox;
    use crate::grid::TileGrid;
    use crate::raster::resample::Resampling;
    use crate::source::{BlockCache, NodataPolicy, OpenOptions};

    #[test]
    fn names_give_the_south_west_corner() {
        assert_eq!(parse_name(Path::new("/x/N46E011.hgt")), Some((46.0, 11.0)));
        assert_eq!(parse_name(Path::new("s01w072.HGT")), Some((-1.0, -72.0)));
        assert_eq!(parse_name(Path::new("X46E011.hgt")), None);
        assert_eq!(parse_name(Path::new("N4")), None);
    }

    #[test]
    fn a_written_tile_reads_back_at_its_corners_and_voids_are_nodata() {
        let dir = std::env::temp_dir().join(format!("sylva-hgt-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("N46E011.hgt");
        let n = 1201usize;
        let mut bytes = Vec::with_capacity(n * n * 2);
        for row in 0..n {
            for col in 0..n {
                let v: i16 = if (row, col) == (600, 600) { VOID } else { (row * 2 + col) as i16 };
                bytes.extend_from_slice(&v.to_be_bytes());
            }
        }
        std::fs::write(&path, &bytes).unwrap();
        let options = OpenOptions { nodata: NodataPolicy::Propagate, ..OpenOptions::default() };
        let src = crate::source::open_file(&path, &options, &BlockCache::new(1 << 26)).unwrap();
        let tiles = TileGrid::new(36.0, 513).unwrap();
        // A 3×3 grid at the file's own spacing whose north-west sample is (col, row).
        let at = |col: f64, row: f64| {
            let d = 1.0 / 1200.0;
            let bbox = BBox {
                west: 11.0 + col * d,
                east: 11.0 + (col + 2.0) * d,
                north: 47.0 - row * d,
                south: 47.0 - (row + 2.0) * d,
            };
            src.sample(&bbox.point_grid(3, 3, &tiles).unwrap(), 0, Resampling::Bilinear).unwrap()
        };
        // North-west corner is row 0, col 0; the south-east corner row 1200, col 1200.
        assert_eq!(at(0.0, 0.0).get(0, 0), 0.0);
        assert_eq!(at(1198.0, 1198.0).get(2, 2), (1200 * 2 + 1200) as f32);
        assert_eq!(at(10.0, 20.0).get(1, 1), (21 * 2 + 11) as f32);
        assert!(at(599.0, 599.0).get(1, 1).is_nan());
        std::fs::write(&path, &bytes[..1000]).unwrap();
        assert!(matches!(open(&path), Err(SourceError::Malformed { .. })));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
