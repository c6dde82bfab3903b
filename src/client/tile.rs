//! A tile made ready for ray casting: what a tile source delivers (CEM,
//! ground, surface classes and map colour with a halo) moved into the tile's
//! flat frame, with its acceleration data and its hull mesh.
//!
//! - **Heights** are measured from the tile's tangent plane raised to a base
//!   height (the middle of the tile's range), so `f32` keeps sub-millimetre
//!   steps even on a 2 mm level-22 tile; the ellipsoid's drop below the
//!   plane is added to every sample ([`super::frame`]).
//! - **Texels** are stored row 0 at the south, so texel `(i + B, j + B)`
//!   holds sample `(i, j)` (east, north) of a tile with halo `B`. Each texel
//!   carries CEM, ground and the two safety zones (dissertation 6.4: the
//!   maximum within 4 and 32 samples), the linear march reads all four in
//!   one fetch.
//! - **Cast range.** A tile's rays look for hits in the cells between
//!   samples −1 and N (one cell of overlap with each neighbour, read from the
//!   halo), so no sliver between two flat frames lets a ray through. The
//!   maximum mipmap covers exactly those `N + 1` cells: cell `m` has its
//!   south-west corner at sample `m − 1`.
//! - **Nodata** is [`NODATA_M`], far below any surface: cells with a nodata
//!   corner hold no surface, and bound nothing. A sample without data in
//!   one layer (ground, CEM or class) has none in any.

use super::frame::TileFrame;
use super::globe::Geodetic;
use super::hull::Hull;
use super::terrain::TerrainMesh;
use crate::cem::accel::{MaxMipmap, ZONE_FAR, ZONE_NEAR};
use crate::cem::surface::NODATA;
use crate::grid::{TileGrid, TileId};
use crate::raster::Raster;
use crate::raster::morphology::dilate;
use glam::DVec2;
use std::sync::Arc;

/// How far outside its sector, in samples, a point is still on a tile's
/// edge, and how near a sample it is on it (rounding of degrees to
/// samples).
const EDGE_SAMPLES: f64 = 1e-6;

/// Height of nodata texels: below this is no surface.
pub const NODATA_M: f32 = -1.0e30;

/// Heights a tile may hold, metres: ten times Earth's relief (−11 to
/// +9 km; synthetic scenes scaled to a 1,000 km tile reach ±50 km), where
/// `f32` still resolves 8 mm. Anything else a source delivers (an
/// infinity, GDAL's float32 nodata left unflagged) is nodata: one such
/// sample would raise the tile's frame to it and its bounds to infinity.
pub const PLAUSIBLE_M: std::ops::RangeInclusive<f32> = -100_000.0..=100_000.0;

/// What a tile source delivers for one tile: `(N + 2B)²` samples per
/// layer, row 0 at the north (the server's order), NaN for nodata.
#[derive(Clone, Debug)]
pub struct TilePayload {
    /// The tile.
    pub id: TileId,
    /// Halo `B`, samples per side.
    pub halo: usize,
    /// Combined elevation (ground + canopy), metres.
    pub cem: Vec<f32>,
    /// Ground elevation, metres.
    pub dem: Vec<f32>,
    /// Surface class ids.
    pub surface: Vec<u8>,
    /// Map colour, sRGB with alpha 0 for nodata.
    pub colour: Vec<[u8; 4]>,
}

/// `v`, or nodata (NaN) outside [`PLAUSIBLE_M`].
pub fn plausible(v: f32) -> f32 {
    if PLAUSIBLE_M.contains(&v) { v } else { f32::NAN }
}

impl TilePayload {
    /// The payload with heights outside [`PLAUSIBLE_M`] made nodata, and
    /// every sample that is nodata in one layer made nodata in all (the
    /// server's rule: no ground, no class), so the ray casters, which read
    /// the heights, and the plain mesh, which reads the class, agree on
    /// holes. The layers must be of one length.
    fn consistent(mut self) -> TilePayload {
        for k in 0..self.cem.len() {
            let (cem, dem) = (plausible(self.cem[k]), plausible(self.dem[k]));
            let none = cem.is_nan() || dem.is_nan() || self.surface[k] == NODATA;
            (self.cem[k], self.dem[k]) = if none { (f32::NAN, f32::NAN) } else { (cem, dem) };
            if none {
                self.surface[k] = NODATA;
                self.colour[k][3] = 0;
            }
        }
        self
    }
}

/// Height statistics of a prepared tile, in its local frame.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct TileRange {
    /// Lowest ground in the cast range, local metres.
    pub min_m: f32,
    /// Highest CEM in the cast range, local metres.
    pub max_m: f32,
    /// Highest CEM over all texels, halo included (what shadow rays can
    /// meet), local metres.
    pub texels_max_m: f32,
    /// Tallest canopy (CEM − ground) in the cast range, metres.
    pub canopy_max_m: f32,
    /// How far the coarse terrain mesh departs from the ground samples,
    /// metres: the error of drawing the tile without ray casting.
    pub mesh_error_m: f32,
    /// Lowest ground and highest CEM above the ellipsoid, metres (what the
    /// quadtree bounds the tile and its descendants with).
    pub heights_m: (f64, f64),
}

/// A tile ready for the ray casters, on the CPU.
#[derive(Clone, Debug)]
pub struct TileData {
    /// The tile's flat frame, raised to its base height.
    pub frame: TileFrame,
    /// The base height: local heights are measured from it, metres.
    pub base_m: f64,
    /// Unique to this preparation in this process: the GPU cache's key, so
    /// two sources' tiles with one address are never confused.
    pub serial: u64,
    /// Halo `B`.
    pub halo: usize,
    /// Texels per side, `N + 2B`.
    pub size: usize,
    /// Per texel: CEM, ground, 4-sample zone, 32-sample zone (local metres).
    pub texels: Vec<[f32; 4]>,
    /// Map colour per texel.
    pub colour: Vec<[u8; 4]>,
    /// Surface class per texel.
    pub surface: Vec<u8>,
    /// Maximum mipmap of the CEM over the cast cells.
    pub mip: MaxMipmap,
    /// The hull the rays start on.
    pub hull: Hull,
    /// The ground as a mesh at its true place on the ellipsoid.
    pub terrain: TerrainMesh,
    /// Height statistics.
    pub range: TileRange,
    /// The coarser surface the tile is drawn morphing from or to, CEM and
    /// ground per texel ([`Self::morphing`]); none for a tile drawn as it is.
    pub morph_from: Option<Vec<[f32; 2]>>,
}

/// Why a payload cannot become a tile.
#[derive(Debug, thiserror::Error)]
pub enum TileError {
    /// The layers do not have `(N + 2B)²` samples.
    #[error("tile {id}: expected {expected} samples per layer, got {got}")]
    Size {
        /// The tile.
        id: TileId,
        /// `(N + 2B)²`.
        expected: usize,
        /// What the payload had.
        got: usize,
    },
    /// The halo must reach the overlap cell.
    #[error("tile {0}: a halo of at least one sample is needed")]
    NoHalo(TileId),
}

impl TileData {
    /// Prepares a payload on `grid`.
    pub fn prepare(grid: &TileGrid, payload: TilePayload) -> Result<TileData, TileError> {
        let id = payload.id;
        let halo = payload.halo;
        let size = grid.samples() as usize + 2 * halo;
        let expected = size * size;
        for got in [payload.cem.len(), payload.dem.len(), payload.surface.len(), payload.colour.len()] {
            if got != expected {
                return Err(TileError::Size { id, expected, got });
            }
        }
        if halo == 0 {
            return Err(TileError::NoHalo(id));
        }
        let payload = payload.consistent();
        let flat = TileFrame::new(grid, id);
        let base = base_height(&payload.cem);
        let frame = flat.raised(base);
        let drops = frame.drops_m(halo);
        let south_up = |k: usize| (size - 1 - k / size) * size + k % size;
        let local = |layer: &[f32]| -> Raster<f32> {
            Raster::from_fn(size, size, |x, y| {
                let v = layer[(size - 1 - y) * size + x];
                if v.is_nan() { f32::NAN } else { (v as f64 + drops[y * size + x]) as f32 }
            })
        };
        let (cem, dem) = (local(&payload.cem), local(&payload.dem));
        let colour = (0..expected).map(|k| payload.colour[south_up(k)]).collect();
        let surface = (0..expected).map(|k| payload.surface[south_up(k)]).collect();
        let n = grid.samples() as usize;
        let terrain =
            TerrainMesh::build(&frame, &dem.crop(crate::raster::Window::new(halo as i64, halo as i64, n, n), f32::NAN));
        let bounded = Bounded::new((&cem, &dem), Reach { cem: &cem, ground: (&dem, &dem) }, halo, n);
        Ok(TileData {
            frame,
            base_m: base,
            serial: next_serial(),
            halo,
            size,
            texels: bounded.texels,
            colour,
            surface,
            mip: bounded.mip,
            hull: bounded.hull,
            range: TileRange {
                mesh_error_m: terrain.mesh_error_m,
                heights_m: height_range(&payload.dem, &payload.cem),
                ..bounded.range
            },
            terrain,
            morph_from: None,
        })
    }

    /// This tile drawn morphing between its own surface and a coarser one:
    /// `from` holds that surface's CEM and ground per texel in this tile's
    /// frame (as [`Self::texels`]; NaN where it has no data), `from_heights_m`
    /// its range above the ellipsoid. The texels keep the tile's own
    /// heights, which the GPU blends with `from` by each draw's weight; every
    /// bound (zones, mipmap, hull, range) encloses both ends, so no ray
    /// misses the surface at any weight, and the terrain mesh under it is
    /// lowered as far as the coarser ground lies below its own.
    pub fn morphing(&self, from: &[[f32; 2]], (lowest_m, highest_m): (f64, f64)) -> TileData {
        let size = self.size;
        let own = |c: usize| Raster::from_fn(size, size, |x, y| nodata_nan(self.texels[y * size + x][c]));
        let (cem, dem) = (own(0), own(1));
        // Where the coarser tile has no data the tile keeps its own heights.
        let from: Vec<[f32; 2]> = from
            .iter()
            .zip(&self.texels)
            .map(|(f, t)| [0, 1].map(|c| if f[c].is_nan() { t[c] } else { f[c] }))
            .collect();
        let end = |own: &Raster<f32>, c: usize, pick: fn(f32, f32) -> f32| {
            Raster::from_fn(size, size, |x, y| {
                let mine = own.get(x, y);
                if mine.is_nan() { mine } else { pick(mine, from[y * size + x][c]) }
            })
        };
        let (upper, lower) = (end(&cem, 0, f32::max), end(&dem, 1, f32::min));
        let reach = Reach { cem: &upper, ground: (&end(&dem, 1, f32::max), &lower) };
        let n = self.frame.samples as usize;
        let bounded = Bounded::new((&cem, &dem), reach, self.halo, n);
        let sink = cast_window(&dem, self.halo, n)
            .data()
            .iter()
            .zip(cast_window(&lower, self.halo, n).data())
            .map(|(mine, low)| mine - low)
            .filter(|v| v.is_finite())
            .fold(0.0, f32::max);
        let (lo, hi) = self.range.heights_m;
        TileData {
            frame: self.frame,
            base_m: self.base_m,
            serial: next_serial(),
            halo: self.halo,
            size,
            texels: bounded.texels,
            colour: self.colour.clone(),
            surface: self.surface.clone(),
            mip: bounded.mip,
            hull: bounded.hull,
            terrain: self.terrain.clone(),
            range: TileRange {
                mesh_error_m: self.range.mesh_error_m + sink,
                heights_m: (lo.min(lowest_m), hi.max(highest_m)),
                ..bounded.range
            },
            morph_from: Some(from),
        }
    }

    /// The tile.
    pub fn id(&self) -> TileId {
        self.frame.id
    }

    /// How far its flat frame misplaces any of its points, metres
    /// ([`TileFrame::flat_error_m`] at its largest height: its base and
    /// its range).
    pub fn flat_error_m(&self) -> f64 {
        let largest_m = self.base_m.abs() + f64::from(self.range.max_m.abs().max(self.range.min_m.abs()));
        self.frame.flat_error_m(largest_m.max(1.0))
    }

    /// The surface, canopy included, at `(lon, lat)` (degrees), metres
    /// above the ellipsoid: its samples in their true place, bilinear
    /// between them. `None` outside its sector or beside nodata.
    pub fn surface_height_m(&self, lon_deg: f64, lat_deg: f64) -> Option<f64> {
        self.height_m(lon_deg, lat_deg, 0)
    }

    /// The ground under the canopy, as [`Self::surface_height_m`].
    pub fn ground_height_m(&self, lon_deg: f64, lat_deg: f64) -> Option<f64> {
        self.height_m(lon_deg, lat_deg, 1)
    }

    /// The height of texel channel `channel` (0 the CEM, 1 the ground).
    fn height_m(&self, lon_deg: f64, lat_deg: f64, channel: usize) -> Option<f64> {
        let s = self.frame.sample_at(lon_deg, lat_deg);
        let last = f64::from(self.frame.samples - 1);
        // On its edge within rounding: a point on a sector's border belongs
        // to both tiles there.
        let inside = |v: f64| (-EDGE_SAMPLES..=last + EDGE_SAMPLES).contains(&v);
        if !(inside(s.x) && inside(s.y)) {
            return None;
        }
        // On a sample within rounding is on it: a corner of no weight is
        // not read (beside the last sample the halo may hold no data).
        let snap = |v: f64| if (v - v.round()).abs() < EDGE_SAMPLES { v.round() } else { v };
        let s = DVec2::new(snap(s.x), snap(s.y)).clamp(DVec2::ZERO, DVec2::splat(last));
        let (c, f) = (s.floor(), s - s.floor());
        let height = |di: f64, dj: f64| {
            let (i, j) = (c.x + if f.x > 0.0 { di } else { 0.0 }, c.y + if f.y > 0.0 { dj } else { 0.0 });
            let h = self.texel(i as i64, j as i64)[channel];
            (h > NODATA_M).then(|| f64::from(h) - self.frame.ellipsoid_local(i, j).z)
        };
        let corners = [height(0.0, 0.0)?, height(1.0, 0.0)?, height(0.0, 1.0)?, height(1.0, 1.0)?];
        Some(super::raycast::bilinear(corners, f.x, f.y))
    }

    /// Texel at sample `(i, j)` (may be in the halo).
    pub fn texel(&self, i: i64, j: i64) -> [f32; 4] {
        let b = self.halo as i64;
        self.texels[((j + b) as usize) * self.size + (i + b) as usize]
    }

    /// Bytes the tile holds on the CPU: what it takes on the GPU, its hull,
    /// its terrain mesh and the coarser surface it morphs from.
    pub fn cpu_bytes(&self) -> usize {
        use std::mem::size_of_val;
        let meshes = size_of_val(&self.hull.vertices[..])
            + size_of_val(&self.hull.indices[..])
            + size_of_val(&self.terrain.vertices[..])
            + size_of_val(&self.terrain.indices[..]);
        self.gpu_bytes() + meshes + self.morph_from.as_ref().map_or(0, |m| size_of_val(&m[..]))
    }

    /// Bytes the tile takes on the GPU (texels, mipmap, colour, classes).
    pub fn gpu_bytes(&self) -> usize {
        let mip: usize = (0..self.mip.levels()).map(|l| self.mip.level(l).data().len() * 4).sum();
        self.texels.len() * 16 + mip + self.colour.len() * 4 + self.surface.len()
    }
}

/// The height of `eye` above the surface of `tiles` under it (the highest
/// where several hold it, [`TileData::surface_height_m`]), canopy included
/// (negative below it), metres; `None` where no tile has surface under the
/// eye. Taken along the ellipsoid's normal with samples in their true
/// place, so it holds where a coarse tile's flat frame misplaces its
/// ground by kilometres (at a pole, where such a tile is drawn plain).
pub fn clearance_m(eye: Geodetic, tiles: &[Arc<TileData>]) -> Option<f64> {
    let highest = tiles.iter().filter_map(|t| t.surface_height_m(eye.lon_deg, eye.lat_deg)).max_by(f64::total_cmp);
    highest.map(|h| eye.height_m - h)
}

/// The eye's height above the ground (the canopy left out) of the highest
/// of `tiles` under it.
pub fn ground_clearance_m(eye: Geodetic, tiles: &[Arc<TileData>]) -> Option<f64> {
    let highest = tiles.iter().filter_map(|t| t.ground_height_m(eye.lon_deg, eye.lat_deg)).max_by(f64::total_cmp);
    highest.map(|h| eye.height_m - h)
}

fn next_serial() -> u64 {
    static SERIAL: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    SERIAL.fetch_add(1, std::sync::atomic::Ordering::Relaxed)
}

/// The height the frame is raised to: the middle of the valid CEM range.
fn base_height(cem: &[f32]) -> f64 {
    let (lo, hi) =
        cem.iter().filter(|v| v.is_finite()).fold((f32::MAX, f32::MIN), |(lo, hi), &v| (lo.min(v), hi.max(v)));
    if lo > hi { 0.0 } else { ((lo as f64 + hi as f64) / 2.0).round() }
}

/// The lowest ground and highest CEM of a payload, metres above the
/// ellipsoid (0, 0 without data).
fn height_range(dem: &[f32], cem: &[f32]) -> (f64, f64) {
    let lo = dem.iter().filter(|v| v.is_finite()).fold(f32::MAX, |a, &b| a.min(b));
    let hi = cem.iter().filter(|v| v.is_finite()).fold(f32::MIN, |a, &b| a.max(b));
    if lo > hi { (0.0, 0.0) } else { (lo as f64, hi as f64) }
}

fn nodata_low(v: f32) -> f32 {
    if v.is_nan() { NODATA_M } else { v }
}

/// The samples of the cast range, −1 ..= N on both axes (row 0 south).
fn cast_window(layer: &Raster<f32>, halo: usize, samples: usize) -> Raster<f32> {
    let w = crate::raster::Window::new(halo as i64 - 1, halo as i64 - 1, samples + 2, samples + 2);
    layer.crop(w, f32::NAN)
}

fn nodata_nan(v: f32) -> f32 {
    if v <= NODATA_M { f32::NAN } else { v }
}

/// Where a tile's surface can lie at any morph weight, per texel: the
/// highest CEM and the highest and lowest ground of its two ends (its own
/// heights unless it morphs). Local metres, rows south-up, halo included,
/// NaN for nodata.
struct Reach<'a> {
    cem: &'a Raster<f32>,
    ground: (&'a Raster<f32>, &'a Raster<f32>),
}

/// A tile's texels and what bounds its surface, from its own CEM and
/// ground and the [`Reach`] of that surface. Layers are local metres, rows
/// south-up, halo included, NaN for nodata.
struct Bounded {
    texels: Vec<[f32; 4]>,
    mip: MaxMipmap,
    hull: Hull,
    /// Without the terrain mesh's error and the heights above the ellipsoid.
    range: TileRange,
}

impl Bounded {
    fn new((cem, dem): (&Raster<f32>, &Raster<f32>), reach: Reach, halo: usize, n: usize) -> Bounded {
        let (upper, (high, lower)) = (reach.cem, reach.ground);
        let near = dilate(upper, ZONE_NEAR);
        let far = dilate(&near, ZONE_FAR - ZONE_NEAR);
        let texels = (0..cem.data().len())
            .map(|k| [cem.data()[k], dem.data()[k], near.data()[k], far.data()[k]].map(nodata_low))
            .collect();
        let (cast, cast_lower) = (cast_window(upper, halo, n), cast_window(lower, halo, n));
        let hull = Hull::build(&cast, (&cast_window(high, halo, n), &cast_lower));
        let range = TileRange {
            min_m: hull.bottom_m,
            max_m: cast.min_max().map_or(0.0, |(_, hi)| hi),
            texels_max_m: upper.min_max().map_or(0.0, |(_, hi)| hi),
            canopy_max_m: canopy_max(&cast, &cast_lower),
            ..TileRange::default()
        };
        Bounded { texels, mip: MaxMipmap::build(&cast), hull, range }
    }
}

fn canopy_max(cem: &Raster<f32>, dem: &Raster<f32>) -> f32 {
    cem.data().iter().zip(dem.data()).map(|(c, d)| c - d).filter(|v| v.is_finite()).fold(0.0, f32::max)
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// A payload whose CEM is a ramp plus canopy on the east half.
    pub(crate) fn ramp(grid: &TileGrid, id: TileId, halo: usize) -> TilePayload {
        let size = grid.samples() as usize + 2 * halo;
        let dem: Vec<f32> = (0..size * size).map(|k| 1000.0 + (k % size) as f32 * 2.0 + (k / size) as f32).collect();
        let cem = dem.iter().enumerate().map(|(k, d)| d + if k % size > size / 2 { 20.0 } else { 0.0 }).collect();
        TilePayload { id, halo, cem, dem, surface: vec![1; size * size], colour: vec![[90, 140, 80, 255]; size * size] }
    }

    #[test]
    fn texels_are_south_up_and_measured_from_the_raised_plane() {
        let grid = TileGrid::new(36.0, 33).unwrap();
        let id = grid.tile_containing(10.2, 46.4, 12);
        let t = TileData::prepare(&grid, ramp(&grid, id, 2)).unwrap();
        // Payload row 0 is the north edge: sample (0, N−1+B) in texel space.
        let size = 37;
        let north_west = t.texel(-2, 34);
        let payload_first = 1000.0f64;
        let drop = t.frame.drops_m(2)[36 * size];
        assert!((north_west[1] as f64 - (payload_first + drop)).abs() < 1e-3, "{north_west:?}");
        // The canopy of 20 m is there and the zones bound the CEM.
        assert!((t.range.canopy_max_m - 20.0).abs() < 1e-3);
        for tx in &t.texels {
            assert!(tx[2] >= tx[0] && tx[3] >= tx[2]);
        }
    }

    #[test]
    fn the_surface_height_is_the_payloads_in_its_true_place_even_near_a_pole() {
        // A level-1 tile 18° wide by the South Pole: its flat frame puts its
        // corners kilometres off, the heights stay the payload's.
        let grid = TileGrid::new(36.0, 33).unwrap();
        let id = grid.tile_containing(10.0, -85.0, 1);
        let halo = 2;
        let mut payload = ramp(&grid, id, halo);
        let size = 33 + 2 * halo;
        // Hills 800 m high a sample or two apart.
        for (k, h) in payload.cem.iter_mut().enumerate() {
            *h = 1000.0 + 800.0 * ((k % size) as f32 * 1.3).sin() * ((k / size) as f32 * 0.9).cos();
        }
        let at = |i: usize, j: usize| (size - 1 - (j + halo)) * size + i + halo;
        payload.cem[at(20, 5)] = f32::NAN;
        let cem = payload.cem.clone();
        let t = TileData::prepare(&grid, payload).unwrap();
        assert!(t.flat_error_m() > 1e4, "{}", t.flat_error_m());
        let (sector, step) = (grid.sector(id), grid.spacing_deg(id.level));
        let place = |i: f64, j: f64| (sector.min_lon + i * step, sector.min_lat + j * step);
        let height = |i: f64, j: f64| t.surface_height_m(place(i, j).0, place(i, j).1);
        for (i, j) in [(0, 0), (32, 32), (16, 16), (3, 29), (32, 0)] {
            let got = height(i as f64, j as f64).unwrap();
            assert!((got - f64::from(cem[at(i, j)])).abs() < 0.05, "({i}, {j}): {got} vs {}", cem[at(i, j)]);
        }
        // Bilinear between samples; none beside nodata, none off the tile.
        let mean = [(7, 9), (8, 9), (7, 10), (8, 10)].map(|(i, j)| f64::from(cem[at(i, j)])).iter().sum::<f64>() / 4.0;
        assert!((height(7.5, 9.5).unwrap() - mean).abs() < 0.05);
        assert_eq!(height(19.5, 4.5), None);
        assert!(height(20.0, 4.0).is_some() && height(19.0, 5.0).is_some(), "a neighbour of no weight");
        assert_eq!((height(-0.01, 3.0), height(3.0, 32.01)), (None, None));
        // A ray cast down in the flat frame found no ground or ground 400 m
        // off at these corners.
        let t = [Arc::new(t)];
        for (i, j) in [(1, 1), (3, 29), (30, 2)] {
            let eye = Geodetic::new(place(i as f64, j as f64).0, place(i as f64, j as f64).1, 5000.0);
            let got = clearance_m(eye, &t).unwrap();
            assert!((got - (5000.0 - f64::from(cem[at(i, j)]))).abs() < 0.05, "({i}, {j}): {got}");
        }
    }

    #[test]
    fn a_morphing_tile_is_bounded_at_every_weight() {
        let grid = TileGrid::new(36.0, 33).unwrap();
        let id = grid.tile_containing(10.2, 46.4, 12);
        let own = TileData::prepare(&grid, ramp(&grid, id, 2)).unwrap();
        // A coarser surface waving 40 m above and below, without data in a corner.
        let from: Vec<[f32; 2]> = own
            .texels
            .iter()
            .enumerate()
            .map(|(k, t)| {
                let wave = 40.0 * ((k % 37) as f32 * 0.7).sin() * ((k / 37) as f32 * 0.4).cos();
                if k < 5 { [f32::NAN; 2] } else { [t[0] + wave, t[1] + wave] }
            })
            .collect();
        let m = own.morphing(&from, (900.0, 1200.0));
        assert_eq!(m.range.heights_m, (900.0, own.range.heights_m.1.max(1200.0)));
        assert_ne!(m.serial, own.serial);
        let stored = m.morph_from.as_ref().expect("the coarser surface");
        assert_eq!(stored[0], [own.texels[0][0], own.texels[0][1]], "the tile's own where the coarser has no data");
        let (b, n, size) = (2, 33, 37);
        let mut sank = 0.0f32;
        for w in [0.0f32, 0.3, 0.7, 1.0] {
            let at = |x: usize, y: usize, c: usize| {
                let k = y * size + x;
                stored[k][c] + w * (m.texels[k][c] - stored[k][c])
            };
            // Cast cell (cx, cy) has its south-west corner at texel (b - 1 + cx, b - 1 + cy).
            for cy in 0..=n {
                for cx in 0..=n {
                    let (x, y) = (b - 1 + cx, b - 1 + cy);
                    let corners = [(x, y), (x + 1, y), (x, y + 1), (x + 1, y + 1)];
                    let top = corners.iter().map(|&(i, j)| at(i, j, 0)).fold(f32::MIN, f32::max);
                    assert!(top <= m.mip.level(0).get(cx, cy) + 1e-3, "w {w} cell {cx},{cy}");
                    assert!(top <= m.texels[y * size + x][2] + 1e-3, "w {w}: the 4-sample zone at {x},{y}");
                    for &(i, j) in &corners {
                        assert!(at(i, j, 1) >= m.range.min_m, "w {w} ground at {i},{j} below the hull");
                        sank = sank.max(own.texels[j * size + i][1] - at(i, j, 1));
                    }
                }
            }
            // The hull over each top vertex bounds the surface there at every
            // canopy fade (regression: its ground height was the lower end's,
            // 40 m under a coarser ground above the tile's own).
            let k = m.hull.quads;
            for v in &m.hull.vertices[..(k + 1) * (k + 1)] {
                let [x, y] = v.sample.map(|s| (s.round() as i64 + b as i64) as usize);
                for f in [0.0f32, 0.5, 1.0] {
                    let surface = at(x, y, 1) + f * (at(x, y, 0) - at(x, y, 1));
                    let hull = v.hull_m[0] + f * (v.hull_m[1] - v.hull_m[0]);
                    assert!(surface <= hull + 1e-3, "w {w} f {f}: surface {surface} above the hull {hull} at {x},{y}");
                }
            }
        }
        assert!(sank > 10.0, "the coarser ground lies below the tile's: {sank}");
        assert!(m.range.mesh_error_m >= own.range.mesh_error_m + sank - 1e-3, "the filler mesh sinks with it");
    }

    #[test]
    fn implausible_heights_are_nodata() {
        // Regression: one infinite or 3·10³⁸ m sample (a float nodata left
        // unflagged) raised the frame and every bound to it, and the flight
        // drew nothing.
        let grid = TileGrid::new(36.0, 33).unwrap();
        let id = grid.tile_containing(10.2, 46.4, 12);
        let mut payload = ramp(&grid, id, 2);
        let size = 37;
        let spikes = [(f32::INFINITY, 5), (3.0e38, 6), (f32::MIN, 7), (-200_000.0, 8)];
        for (v, k) in spikes {
            payload.cem[k * size + 10] = v;
            payload.dem[k * size + 11] = v;
        }
        let t = TileData::prepare(&grid, payload).unwrap();
        let good = TileData::prepare(&grid, ramp(&grid, id, 2)).unwrap();
        assert_eq!(t.base_m, good.base_m);
        let (lo, hi) = t.range.heights_m;
        assert!((1000.0..1200.0).contains(&lo) && (1000.0..1200.0).contains(&hi), "{lo} {hi}");
        // A sample without data in one layer has none in any: its ground,
        // its CEM and its class (which the plain mesh reads) agree.
        for (_, k) in spikes {
            let row = size - 1 - k;
            for x in [10, 11] {
                assert_eq!(t.texels[row * size + x][..2], [NODATA_M; 2]);
                assert_eq!(t.surface[row * size + x], NODATA);
                assert_eq!(t.colour[row * size + x][3], 0);
            }
        }
    }

    #[test]
    fn bad_payloads_are_refused() {
        let grid = TileGrid::new(36.0, 33).unwrap();
        let id = TileId::new(3, 1, 1);
        let mut p = ramp(&grid, id, 2);
        p.dem.pop();
        assert!(matches!(TileData::prepare(&grid, p), Err(TileError::Size { .. })));
        assert!(matches!(TileData::prepare(&grid, ramp(&grid, id, 0)), Err(TileError::NoHalo(_))));
    }
}
