//! LAS and LAZ point clouds (the `las` crate, LAZ through `laz`): the
//! positions, heights and classes of every point of one or more files, for
//! building canopy height models (`sylva canopy`, dissertation 6.6: "a LIDAR
//! scan ... converted to an elevation map").
//!
//! Invariants: every file must carry a CRS (GeoTIFF keys or WKT in its VLRs,
//! or the caller's override) that is projected and in metres, and all files
//! of one cloud share it; the point count read from a header is bounded
//! ([`MAX_POINTS`]) and points are decoded in batches, so a hostile header
//! cannot make us allocate; a truncated or corrupt file is an error that names
//! it, never a short cloud.

use super::{Crs, SourceError};
use std::path::{Path, PathBuf};

/// Most points one cloud may hold (all files together): 21 bytes a point,
/// about 1 GiB.
pub const MAX_POINTS: u64 = 50_000_000;

/// Points decoded per batch.
const BATCH: u64 = 1 << 20;

/// GeoKey ids (GeoTIFF 1.1, section 7) in the `LASF_Projection` VLR.
const PROJECTED_CS_TYPE: u16 = 3072;
const GEOGRAPHIC_TYPE: u16 = 2048;

/// The points of one or more LAS/LAZ files, in their common projected CRS.
#[derive(Clone, Debug, Default)]
pub struct PointCloud {
    /// Easting, metres.
    pub x: Vec<f64>,
    /// Northing, metres.
    pub y: Vec<f64>,
    /// Elevation or height, metres.
    pub z: Vec<f64>,
    /// ASPRS classification (2 = ground, 7 and 18 = noise).
    pub class: Vec<u8>,
    /// EPSG code of the CRS.
    pub epsg: u32,
    /// The files read, for messages.
    pub files: Vec<PathBuf>,
}

impl PointCloud {
    /// Number of points.
    pub fn len(&self) -> usize {
        self.z.len()
    }

    /// True when the cloud has no points.
    pub fn is_empty(&self) -> bool {
        self.z.is_empty()
    }

    /// A description of the files, for messages: `a.laz + b.laz`.
    pub fn name(&self) -> String {
        let names: Vec<String> = self.files.iter().map(|f| f.display().to_string()).collect();
        names.join(" + ")
    }
}

/// Reads every point of `paths` into one cloud. `crs_override` (an EPSG code)
/// replaces the files' own CRS.
pub fn read(paths: &[PathBuf], crs_override: Option<u32>) -> Result<PointCloud, SourceError> {
    let mut cloud = PointCloud::default();
    for path in paths {
        read_file(path, crs_override, &mut cloud)?;
    }
    if cloud.is_empty() {
        let path = paths.first().cloned().unwrap_or_default();
        return Err(SourceError::Malformed { path, problem: "the point cloud is empty (0 points)".into() });
    }
    Ok(cloud)
}

fn read_file(path: &Path, crs_override: Option<u32>, cloud: &mut PointCloud) -> Result<(), SourceError> {
    let bad = |problem: String| SourceError::Malformed { path: path.into(), problem };
    let file = std::fs::File::open(path).map_err(|source| SourceError::Open { path: path.into(), source })?;
    let mut reader = las::Reader::new(std::io::BufReader::new(file)).map_err(|e| match ends_early(&e) {
        true => bad(format!("truncated: the file ends inside its header or LAZ chunk table ({e})")),
        false => bad(format!("not a readable LAS/LAZ file: {e}")),
    })?;
    let header = reader.header().clone();
    let epsg = match crs_override {
        Some(code) => code,
        None => header_epsg(&header).ok_or_else(|| SourceError::Unsupported {
            path: path.into(),
            what: "no CRS (no GeoTIFF keys with an EPSG code in its VLRs); give one with --crs EPSG:code".into(),
        })?,
    };
    check_crs(path, epsg)?;
    if !cloud.files.is_empty() && cloud.epsg != epsg {
        return Err(bad(format!("its CRS EPSG:{epsg} differs from EPSG:{} of {}", cloud.epsg, cloud.name())));
    }
    let total = header.number_of_points();
    if total + cloud.len() as u64 > MAX_POINTS {
        return Err(bad(format!("{total} points: more than the {MAX_POINTS} a cloud may hold")));
    }
    cloud.epsg = epsg;
    cloud.files.push(path.into());
    let mut done = 0u64;
    let mut batch = las::PointDataBuilder::new().for_header(&header).build();
    while done < total {
        let n = reader
            .fill_points(BATCH, &mut batch)
            .map_err(|e| bad(format!("truncated or corrupt point data after {done} of {total} points: {e}")))?;
        if n == 0 {
            return Err(bad(format!("truncated: {done} of {total} points")));
        }
        cloud.x.extend(batch.x());
        cloud.y.extend(batch.y());
        cloud.z.extend(batch.z());
        cloud.class.extend(batch.classification());
        done += n;
    }
    Ok(())
}

/// True when reading stopped at the end of the file (the `laz` crate
/// reports it only in its message).
fn ends_early(e: &las::Error) -> bool {
    matches!(e, las::Error::Io(io) if io.kind() == std::io::ErrorKind::UnexpectedEof)
        || e.to_string().contains("failed to fill whole buffer")
}

/// The EPSG code in the header's GeoTIFF keys: the projected CRS, else the
/// geographic one.
fn header_epsg(header: &las::Header) -> Option<u32> {
    let keys = header.get_geotiff_crs().ok()??;
    let code = |id: u16| {
        keys.entries.iter().find(|e| e.id == id).and_then(|e| match e.data {
            las::crs::GeoTiffData::U16(v) if v != 0 && v != 32767 => Some(u32::from(v)),
            _ => None,
        })
    };
    code(PROJECTED_CS_TYPE).or_else(|| code(GEOGRAPHIC_TYPE))
}

/// The CRS must be known, projected and in metres: heights and cell sizes
/// are metres.
fn check_crs(path: &Path, epsg: u32) -> Result<(), SourceError> {
    let crs = Crs::from_epsg(epsg).map_err(|source| SourceError::Crs { path: path.into(), source })?;
    match crs.metres_per_unit() {
        Some(m) if (m - 1.0).abs() < 1e-9 => Ok(()),
        Some(m) => Err(SourceError::Unsupported {
            path: path.into(),
            what: format!("EPSG:{epsg} is in units of {m} m; a cloud must be in metres"),
        }),
        None => Err(SourceError::Unsupported {
            path: path.into(),
            what: format!("EPSG:{epsg} is geographic; a cloud must be in a projected CRS in metres"),
        }),
    }
}
