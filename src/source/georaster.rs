//! A georeferenced source with overviews, evaluated on a [`SampleGrid`].
//!
//! Sample positions go from lat/lon to source pixels through the source CRS.
//! Geographic sources map each column and row independently. Projected sources
//! are projected exactly at control points every `m` lattice samples (`m` a
//! power of two chosen so that a mesh cell is at most [`MESH_CELL_M`] on the
//! ground) and interpolated bilinearly between them. Control points sit at
//! global lattice indices, so the interpolated position of a sample does not
//! depend on which tile or build asks for it.

use super::pyramid::{self, Reducer, level_map};
use super::{BlockCache, Blocks, Crs, SourceError};
use crate::geo::METRES_PER_DEGREE;
use crate::grid::{SampleGrid, Sector};
use crate::raster::mesh::{Mesh, unwrap_periodic, unwrap_rows};
use crate::raster::resample::{self, Extent, PixelCoords, Resampling};
use crate::raster::{Raster, Window};
use rayon::prelude::*;
use std::path::Path;
use std::sync::Arc;

/// Largest projection mesh cell on the ground. Over 512 m the bilinear
/// interpolation of a UTM or NZTM mapping is off by < 1 mm (measured by
/// `projected_mesh_matches_exact_projection` in the source tests).
pub const MESH_CELL_M: f64 = 512.0;

/// Where a source's pixels are: the centre of pixel `(col, row)` is at
/// `(x0 + col·dx, y0 + row·dy)` in `crs`.
#[derive(Clone, Debug)]
pub struct Georef {
    /// The source CRS.
    pub crs: Arc<Crs>,
    /// Centre of the first pixel, x.
    pub x0: f64,
    /// Centre of the first pixel, y.
    pub y0: f64,
    /// Pixel width in CRS units.
    pub dx: f64,
    /// Pixel height in CRS units (negative when north is up).
    pub dy: f64,
    /// How far data reaches past the outer pixel centres, in pixels: 0.5 for
    /// area pixels (GeoTIFF `PixelIsArea`), 0 for point samples (SRTM).
    pub overhang: f64,
}

impl Georef {
    /// Pixel size in degrees (projected units converted to metres, then at
    /// the sphere's scale).
    pub fn pixel_deg(&self) -> f64 {
        match self.crs.metres_per_unit() {
            None => self.dx.abs().min(self.dy.abs()),
            Some(_) => self.pixel_m() / METRES_PER_DEGREE,
        }
    }

    /// A geographic georeference whose longitudes lie wholly past ±180°
    /// (a file of 180.5…181.5°E) turned by 360° onto −180…180, so that its
    /// bounds and the grids that read it meet; others as they are (one
    /// across the antimeridian keeps its numbers, and grids reach it by
    /// longitudes taken modulo 360°).
    fn turned_onto_the_globe(self, width: usize) -> Georef {
        if !self.crs.is_geographic() {
            return self;
        }
        let edges = [self.x0 - self.overhang * self.dx, self.x0 + (width as f64 - 1.0 + self.overhang) * self.dx];
        let (west, east) = (edges[0].min(edges[1]), edges[0].max(edges[1]));
        let turn = if west >= 180.0 {
            -360.0 * ((west + 180.0) / 360.0).floor()
        } else if east <= -180.0 {
            360.0 * ((180.0 - east) / 360.0).floor()
        } else {
            0.0
        };
        Georef { x0: self.x0 + turn, ..self }
    }

    /// Pixel size on the ground, metres (north–south for geographic
    /// sources; a CRS in feet converted).
    pub fn pixel_m(&self) -> f64 {
        match self.crs.metres_per_unit() {
            None => self.dy.abs() * METRES_PER_DEGREE,
            Some(metres) => self.dx.abs().min(self.dy.abs()) * metres,
        }
    }
}

/// A source with georeferencing and overviews.
#[derive(Clone)]
pub struct GeoRaster {
    levels: Vec<Blocks>,
    georef: Georef,
    bounds: Sector,
    /// How the overviews reduce each band (none: means, or the source's own).
    reducers: Arc<[Reducer]>,
    /// Whether the columns go once around the globe, the last bordering
    /// the first.
    wraps: bool,
}

impl GeoRaster {
    /// Wraps `base` with its georeferencing; overviews reduce band `b` with
    /// `reducers[b]` (the last entry for further bands).
    pub fn new(base: Blocks, georef: Georef, reducers: &[Reducer], cache: &Arc<BlockCache>) -> GeoRaster {
        let raster = GeoRaster::from_levels(pyramid::build(base, reducers, cache), georef);
        GeoRaster { reducers: reducers.into(), ..raster }
    }

    /// A source whose overviews come with it (level `k` halves level
    /// `k − 1`), such as an upstream server's zoom levels.
    pub fn from_levels(levels: Vec<Blocks>, georef: Georef) -> GeoRaster {
        let size = levels.first().map_or((0, 0), Blocks::size);
        let georef = georef.turned_onto_the_globe(size.0);
        let wraps = around_the_globe(&georef, size.0);
        let bounds = lon_lat_bounds(&georef, size, wraps);
        GeoRaster { levels, georef, bounds, reducers: Arc::new([]), wraps }
    }

    /// The source's name (its file, or a description).
    pub fn name(&self) -> &Path {
        self.levels[0].source().name()
    }

    /// Georeferencing of the full-resolution level.
    pub fn georef(&self) -> &Georef {
        &self.georef
    }

    /// Full-resolution pixel reader.
    pub fn base(&self) -> &Blocks {
        &self.levels[0]
    }

    /// Width and height at full resolution.
    pub fn size(&self) -> (usize, usize) {
        self.levels[0].size()
    }

    /// A lat/lon box that contains all of the data.
    pub fn bounds(&self) -> Sector {
        self.bounds
    }

    /// The overview level used for `grid`: the coarsest whose pixels are no
    /// larger than the grid spacing and, around the globe, that wraps (its
    /// columns divide the base's evenly). Depends on the spacing alone, so
    /// every tile of a level reads the same overview, at the seam or not.
    pub fn level_for(&self, grid: &SampleGrid) -> usize {
        let spacing = grid.lon.step_deg().min(grid.lat.step_deg());
        let ratio = spacing / self.georef.pixel_deg();
        let mut level = if ratio < 2.0 { 0 } else { (ratio.log2().floor() as usize).min(self.levels.len() - 1) };
        while level > 0 && self.wraps && !self.extent(level).wraps {
            level -= 1;
        }
        level
    }

    /// The column coordinate, in overview `level`, of column `c` of `grid`
    /// (a geographic source).
    fn column(&self, grid: &SampleGrid, c: i64, level: usize) -> f64 {
        let (g, (scale, shift)) = (&self.georef, level_map(level));
        ((self.lon_into_source(grid.on_globe(c, 0).0) - g.x0) / g.dx - shift) / scale
    }

    /// True if a sample that grids `a` and `b` share (nested lattices of two
    /// levels) reads the same pixels with the same weights on both: the same
    /// overview, and positions computed per sample (geographic sources), not
    /// interpolated on a projection mesh whose nodes follow each grid's
    /// spacing.
    pub fn samples_alike(&self, a: &SampleGrid, b: &SampleGrid) -> bool {
        self.georef.crs.is_geographic() && self.level_for(a) == self.level_for(b)
    }

    /// Evaluates band `band` at every sample of `grid`; NaN where the source
    /// has no data.
    pub fn sample(&self, grid: &SampleGrid, band: usize, kind: Resampling) -> Result<Raster<f32>, SourceError> {
        Ok(match self.read(grid, kind, band + 1)? {
            Some(footprint) => footprint.resample(band, kind),
            None => Raster::filled(grid.width(), grid.height(), f32::NAN),
        })
    }

    /// Reads the source pixels (the first `bands` bands, from the overview
    /// that suits the grid) that `kind` needs to evaluate the grid; `None`
    /// when the grid misses the data.
    pub fn read(&self, grid: &SampleGrid, kind: Resampling, bands: usize) -> Result<Option<Footprint>, SourceError> {
        if !self.may_cover(grid) {
            return Ok(None);
        }
        let level = self.level_for(grid);
        let coords = self.pixel_coords(grid, level);
        let extent = self.extent(level);
        let Some(window) = coords.footprint(&extent, kind) else {
            return Ok(None);
        };
        let bands = match extent.wraps {
            true => read_around(&self.levels[level], window, bands)?,
            false => self.levels[level].read_bands(window, bands)?,
        };
        let offsets =
            (0..bands.len()).map(|b| pyramid::decimated_offset_px(pyramid::reducer_of(&self.reducers, b), level));
        Ok(Some(Footprint { window, extent, coords, offsets: offsets.collect(), bands }))
    }

    /// True unless the grid certainly misses the data (a cheap test on boxes,
    /// longitudes taken modulo 360° as the samples are; grids that wrap past
    /// a pole are never rejected).
    pub fn may_cover(&self, grid: &SampleGrid) -> bool {
        let (w0, w1) = (grid.lon.coord(0), grid.lon.coord(grid.width() - 1));
        let (n0, s0) = (grid.lat.coord(0), grid.lat.coord(grid.height() - 1));
        let past_a_pole = n0 > 90.0 || s0 < -90.0;
        let (pad_lon, pad_lat) = (grid.lon.step_deg(), grid.lat.step_deg());
        let sector =
            Sector { min_lat: s0 - pad_lat, max_lat: n0 + pad_lat, min_lon: w0 - pad_lon, max_lon: w1 + pad_lon };
        past_a_pole || sector.meets_on_globe(&self.bounds)
    }

    fn extent(&self, level: usize) -> Extent {
        let (w, h) = self.levels[level].size();
        let (base_w, base_h) = self.size();
        let base = Extent::new(base_w, base_h, self.georef.overhang);
        // Around the globe every longitude has data, point samples too.
        let x_range = match self.wraps {
            true => Extent::new(base_w, base_h, 0.5).x_range,
            false => base.x_range,
        };
        let (scale, shift) = level_map(level);
        // An overview wraps where its columns divide the base's evenly: its
        // columns are read modulo its width, any coordinate has data.
        let wraps = self.wraps && w as f64 * scale == base_w as f64;
        Extent {
            width: w,
            height: h,
            x_range: match wraps {
                true => (f64::NEG_INFINITY, f64::INFINITY),
                false => ((x_range.0 - shift) / scale, (x_range.1 - shift) / scale),
            },
            y_range: ((base.y_range.0 - shift) / scale, (base.y_range.1 - shift) / scale),
            wraps,
        }
    }

    /// Source pixel coordinates (of overview `level`) of every grid sample.
    pub fn pixel_coords(&self, grid: &SampleGrid, level: usize) -> PixelCoords {
        let (scale, shift) = level_map(level);
        let g = &self.georef;
        let to_level = |p: f64| (p - shift) / scale;
        if g.crs.is_geographic() && !grid_crosses_pole(grid) {
            let mut x: Vec<f64> = (0..grid.width() as i64).map(|c| self.column(grid, c, level)).collect();
            if self.extent(level).wraps {
                unwrap_periodic(x.iter_mut(), self.levels[level].size().0 as f64);
            }
            let y = (0..grid.height() as i64).map(|r| to_level((grid.on_globe(0, r).1 - g.y0) / g.dy));
            return PixelCoords::Separable { x, y: y.collect() };
        }
        // Rows past a pole read the opposite meridian: a mesh cell across the
        // pole would interpolate nonsense, so project every sample there.
        let m = if grid_crosses_pole(grid) { 1 } else { mesh_step(grid) };
        // Samples beyond the source's reach are not projected (far from a
        // UTM zone that is most of the cost of a world-wide request).
        let reach = self.reach(grid, scale);
        let pixel = |(lon, lat): (f64, f64)| -> (f64, f64) {
            let lon = self.lon_into_source(lon);
            let reached = reach.turns().iter().any(|r| r.contains(lon, lat));
            let projected = if reached { g.crs.from_lon_lat(lon, lat) } else { None };
            match projected {
                Some((x, y)) => (to_level((x - g.x0) / g.dx), to_level((y - g.y0) / g.dy)),
                None => (f64::NAN, f64::NAN),
            }
        };
        let first = (grid.lon.first, grid.lat.first);
        let mut mesh = Mesh::new(m, first, (grid.width(), grid.height()), |c, r| pixel(grid.on_globe(c, r)));
        // Around the globe, positions jump a period at the seam: a mesh cell
        // across it would interpolate through every column between.
        let period = self.extent(level).wraps.then(|| self.levels[level].size().0 as f64);
        if let Some(period) = period {
            mesh.unwrap_x(period);
        }
        if mesh.is_finite() {
            return PixelCoords::Mesh(mesh);
        }
        // A corner failed: project the samples whose positions it spoils.
        let mut xy = vec![(0.0, 0.0); grid.width() * grid.height()];
        xy.par_chunks_mut(grid.width().max(1)).enumerate().for_each(|(r, row)| {
            mesh.row(r, row);
            for (c, out) in row.iter_mut().enumerate() {
                if out.0.is_nan() {
                    *out = pixel(grid.on_globe(c as i64, r as i64));
                }
            }
        });
        if let Some(period) = period {
            unwrap_rows(&mut xy, grid.width(), period);
        }
        PixelCoords::Dense { width: grid.width(), xy }
    }

    /// The box outside which a sample of `grid` reads nothing from overview
    /// `scale`: the source's bounds grown by a sample of the grid and two
    /// pixels of the overview (wider in longitude away from the equator).
    fn reach(&self, grid: &SampleGrid, scale: f64) -> Sector {
        let b = &self.bounds;
        let pad = 2.0 * scale * self.georef.pixel_deg();
        let widest = b.min_lat.abs().max(b.max_lat.abs()).min(89.0).to_radians().cos();
        b.grown(grid.lat.step_deg() + pad, grid.lon.step_deg() + pad / widest)
    }

    /// Moves a longitude by ±360° when that puts it inside the source.
    fn lon_into_source(&self, lon: f64) -> f64 {
        if !self.georef.crs.is_geographic() {
            return lon;
        }
        [lon, lon + 360.0, lon - 360.0]
            .into_iter()
            .find(|l| (self.bounds.min_lon..=self.bounds.max_lon).contains(l))
            .unwrap_or(lon)
    }
}

/// The source pixels under a grid, ready to be resampled onto it.
pub struct Footprint {
    /// Pixels of every band over `window`.
    pub bands: Vec<Raster<f32>>,
    /// Where the pixels are in the source level.
    pub window: Window,
    extent: Extent,
    coords: PixelCoords,
    /// Per decimated band (classes), where its pixels lie from where
    /// `coords` place them, in pixels: its overviews hold their blocks'
    /// north-west pixels.
    offsets: Vec<Option<f64>>,
}

impl Footprint {
    /// Band `band` evaluated at every grid sample with `kind` (whose support
    /// must not exceed the one the footprint was read for); a decimated band
    /// (classes, never interpolated) nearest whatever `kind`, from the pixel
    /// that lies nearest (up to half a pixel past the one `coords` name,
    /// within any footprint's support).
    pub fn resample(&self, band: usize, kind: Resampling) -> Raster<f32> {
        let shifted;
        let (coords, extent, kind) = match self.offsets[band] {
            None => (&self.coords, &self.extent, kind),
            Some(offset) => {
                let extent = Extent {
                    x_range: (self.extent.x_range.0 - offset, self.extent.x_range.1 - offset),
                    y_range: (self.extent.y_range.0 - offset, self.extent.y_range.1 - offset),
                    ..self.extent
                };
                shifted = (self.coords.shifted(-offset), extent);
                (&shifted.0, &shifted.1, Resampling::Nearest)
            }
        };
        resample::resample(&self.bands[band], self.window, extent, coords, kind)
    }
}

impl std::fmt::Debug for GeoRaster {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let (w, h) = self.size();
        write!(f, "GeoRaster({}, {w}×{h}, {:?})", self.name().display(), self.georef.crs)
    }
}

/// How near 360° a geographic source's width must be to wrap, pixels (a
/// pixel size written to ten digits, summed over 43,200 columns, is off by
/// 2·10⁻⁴ of a pixel).
const WRAP_TOLERANCE_PX: f64 = 1e-3;

/// Whether a source of `width` columns goes once around the globe, so that
/// its last column borders its first (area pixels or point samples;
/// geographic, or a projection whose x follows longitude alone, such as
/// Web Mercator).
fn around_the_globe(g: &Georef, width: usize) -> bool {
    let dx = g.dx.abs();
    g.crs.period_x().is_some_and(|period| (width as f64 * dx - period).abs() < WRAP_TOLERANCE_PX * dx)
}

/// `window` of `blocks`, whose columns repeat every width: the columns
/// past either edge are read a period away.
fn read_around(blocks: &Blocks, window: Window, bands: usize) -> Result<Vec<Raster<f32>>, SourceError> {
    let period = blocks.size().0 as i64;
    let mut pieces = Vec::new();
    let mut x = window.x;
    while x < window.x_end() && period > 0 {
        let end = ((x.div_euclid(period) + 1) * period).min(window.x_end());
        let piece = Window::new(x.rem_euclid(period), window.y, (end - x) as usize, window.height);
        pieces.push(blocks.read_bands(piece, bands)?);
        x = end;
    }
    let band = |b: usize| {
        let mut data = Vec::with_capacity(window.area());
        for y in 0..window.height {
            pieces.iter().for_each(|p| data.extend_from_slice(p[b].row(y)));
        }
        Raster::from_vec(window.width, window.height, data).ok_or_else(|| SourceError::Malformed {
            path: blocks.source().name().to_path_buf(),
            problem: "its columns read around the globe do not fill the window".into(),
        })
    };
    (0..pieces.first().map_or(0, Vec::len)).map(band).collect()
}

fn grid_crosses_pole(grid: &SampleGrid) -> bool {
    grid.lat.coord(0) > 90.0 || grid.lat.coord(grid.height() - 1) < -90.0
}

/// Mesh step: a power of two, at most 16, with cells of at most `MESH_CELL_M`.
/// Uses the latitude spacing only, so it is constant per level.
fn mesh_step(grid: &SampleGrid) -> i64 {
    let spacing_m = grid.lat.step_deg() * METRES_PER_DEGREE;
    let mut m = 16;
    while m > 1 && m as f64 * spacing_m > MESH_CELL_M {
        m /= 2;
    }
    m
}

/// The lat/lon box of a source, from its boundary densely sampled: the
/// data's own extent for a geographic source, a box that contains it for a
/// projected one (to the pole, over every longitude, where the source holds
/// a pole: its boundary does not pass there).
fn lon_lat_bounds(g: &Georef, (w, h): (usize, usize), wraps: bool) -> Sector {
    // Around the globe, point samples reach half a step either way too.
    let ox = if wraps { 0.5 } else { g.overhang };
    let (xa, xb) = (g.x0 - ox * g.dx, g.x0 + (w as f64 - 1.0 + ox) * g.dx);
    let (ya, yb) = (g.y0 - g.overhang * g.dy, g.y0 + (h as f64 - 1.0 + g.overhang) * g.dy);
    let mut lons = Vec::new();
    let (mut min_lat, mut max_lat) = (f64::MAX, f64::MIN);
    const STEPS: usize = 64;
    for i in 0..=STEPS {
        let f = i as f64 / STEPS as f64;
        let edge =
            [(xa + f * (xb - xa), ya), (xa + f * (xb - xa), yb), (xa, ya + f * (yb - ya)), (xb, ya + f * (yb - ya))];
        for (lon, lat) in edge.into_iter().filter_map(|(x, y)| g.crs.to_lon_lat(x, y)) {
            if lon.is_finite() && lat.is_finite() {
                lons.push(lon);
                (min_lat, max_lat) = (min_lat.min(lat), max_lat.max(lat));
            }
        }
    }
    let (min_lon, max_lon) = lon_range(g, &lons, ((xa + xb) / 2.0, (ya + yb) / 2.0)).unwrap_or((f64::MAX, f64::MIN));
    // Projected edges bulge between boundary samples: pad by a pixel. A
    // geographic source's edges are its meridians and parallels, exact.
    let pad = if g.crs.is_geographic() { 0.0 } else { g.pixel_deg() };
    let s = Sector { min_lat: min_lat - pad, max_lat: max_lat + pad, min_lon: min_lon - pad, max_lon: max_lon + pad };
    to_the_poles(s, g, ((xa, xb), (ya, yb)))
}

/// The longitudes a source spans from those of its boundary, `lons`: a
/// geographic source's own (they may pass 180°); for a projected one, on
/// the globe, the arc they enclose ([`enclosed_arc`]) around the
/// longitude of its box's `centre`. None without a longitude.
fn lon_range(g: &Georef, lons: &[f64], (x, y): (f64, f64)) -> Option<(f64, f64)> {
    let (first, rest) = lons.split_first()?;
    if g.crs.is_geographic() {
        return Some(rest.iter().fold((*first, *first), |(lo, hi), &l| (lo.min(l), hi.max(l))));
    }
    let centre = g.crs.to_lon_lat(x, y).map(|(lon, _)| lon);
    Some(enclosed_arc(lons.to_vec(), centre))
}

/// The circle of longitudes (`lons` in −180…180) less the widest gap
/// between neighbours, as `(west, east)` with `east` past 180° where it
/// crosses the antimeridian. Every longitude where that gap is not clearly
/// the outside: under twice the next widest (boundary samples so sparse
/// the gaps tell nothing), or not holding `centre`, the longitude of a
/// point inside, where one is known.
fn enclosed_arc(mut lons: Vec<f64>, centre: Option<f64>) -> (f64, f64) {
    const WORLD: (f64, f64) = (-180.0, 180.0);
    lons.sort_by(f64::total_cmp);
    let (Some(&first), Some(&last)) = (lons.first(), lons.last()) else { return WORLD };
    // (width, west of the arc after it), the wrap from last to first too.
    let mut gaps: Vec<(f64, f64)> = lons.windows(2).map(|p| (p[1] - p[0], p[1])).collect();
    gaps.push((first + 360.0 - last, first));
    gaps.sort_by(|a, b| b.0.total_cmp(&a.0));
    let (widest, west) = gaps[0];
    let next = gaps.get(1).map_or(0.0, |g| g.0);
    let east = west + 360.0 - widest;
    let holds = |c: f64| [c, c + 360.0].iter().any(|c| (west..=east).contains(c));
    match widest > 2.0 * next && centre.is_none_or(holds) {
        true => (west, east),
        false => WORLD,
    }
}

/// `s` reaching each pole that the projected source's box of `(x, y)`
/// ranges holds, over every longitude.
fn to_the_poles(s: Sector, g: &Georef, ((xa, xb), (ya, yb)): ((f64, f64), (f64, f64))) -> Sector {
    let inside = |(x, y): (f64, f64)| (xa.min(xb)..=xa.max(xb)).contains(&x) && (ya.min(yb)..=ya.max(yb)).contains(&y);
    let holds = |pole: f64| !g.crs.is_geographic() && g.crs.from_lon_lat(0.0, pole).is_some_and(inside);
    match (holds(90.0), holds(-90.0)) {
        (false, false) => s,
        (north, south) => Sector {
            min_lat: if south { -90.0 } else { s.min_lat },
            max_lat: if north { 90.0 } else { s.max_lat },
            min_lon: -180.0,
            max_lon: 180.0,
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::{Axis, BBox};
    use crate::source::memory::MemorySource;

    #[test]
    fn pixel_sizes_are_in_metres_whatever_the_crs_unit() {
        let georef = |code: u32, size: f64| Georef {
            crs: Arc::new(Crs::from_epsg(code).unwrap()),
            x0: 0.0,
            y0: 0.0,
            dx: size,
            dy: -size,
            overhang: 0.5,
        };
        // California zone 5 in US survey feet: 98.425 ft is 30 m.
        let feet = georef(2229, 98.425);
        assert!((feet.pixel_m() - 30.0).abs() < 0.01, "{}", feet.pixel_m());
        assert!((feet.pixel_deg() * METRES_PER_DEGREE - 30.0).abs() < 0.01);
        assert_eq!(georef(32632, 30.0).pixel_m(), 30.0);
        assert!((georef(4326, 1.0 / 3600.0).pixel_m() - METRES_PER_DEGREE / 3600.0).abs() < 1e-9);
    }

    /// 200 × 200 pixels of 30 m in UTM 32N, north-west corner near 10.0° E, 46.4° N.
    fn utm_raster() -> GeoRaster {
        let cache = BlockCache::new(1 << 20);
        let r = Raster::filled(200, 200, 1.0f32);
        let blocks = Blocks::new(Arc::new(MemorySource::new("<utm>", vec![r]).unwrap()), &cache);
        let crs = Arc::new(Crs::from_epsg(32632).unwrap());
        let georef = Georef { crs, x0: 577_000.0, y0: 5_140_000.0, dx: 30.0, dy: -30.0, overhang: 0.5 };
        GeoRaster::new(blocks, georef, &[Reducer::Mean], &cache)
    }

    fn coords(raster: &GeoRaster, bbox: &str, w: usize, h: usize) -> Vec<(f64, f64)> {
        let grid = BBox::parse(bbox).unwrap().area_grid(w, h).unwrap();
        let pc = raster.pixel_coords(&grid, 0);
        let mut buf = Vec::new();
        (0..h).flat_map(|r| pc.row(r, &mut buf).to_vec()).collect()
    }

    #[test]
    fn samples_beyond_the_sources_reach_are_not_projected_and_the_rest_are() {
        let raster = utm_raster();
        // World-wide: only the samples near the raster have coordinates.
        let world = coords(&raster, "-180,-90,180,90", 720, 360);
        let near = world.iter().filter(|p| p.0.is_finite()).count();
        assert!(near > 0 && near <= 16, "{near} of {} samples projected", world.len());
        // Around the raster's edge: the same coordinates as projecting each sample.
        let (bbox, (w, h)) = ("9.95,46.3,10.2,46.45", (120usize, 90usize));
        let grid = BBox::parse(bbox).unwrap().area_grid(w, h).unwrap();
        let g = &raster.georef;
        for (i, &(x, y)) in coords(&raster, bbox, w, h).iter().enumerate() {
            let (lon, lat) = grid.on_globe((i % w) as i64, (i / w) as i64);
            let (e, n) = g.crs.from_lon_lat(lon, lat).unwrap();
            let inside = (-2.0..202.0).contains(&((e - g.x0) / g.dx)) && (-2.0..202.0).contains(&((n - g.y0) / g.dy));
            if inside {
                assert!((x - (e - g.x0) / g.dx).abs() < 0.01 && (y - (n - g.y0) / g.dy).abs() < 0.01, "sample {i}");
            }
        }
    }

    /// `w × h` pixels of 1 in `crs`, with the first pixel's centre at `(x0, y0)`.
    fn ones(code: u32, (x0, y0): (f64, f64), (w, h): (usize, usize), size: f64) -> GeoRaster {
        let cache = BlockCache::new(1 << 20);
        let blocks =
            Blocks::new(Arc::new(MemorySource::new("<ones>", vec![Raster::filled(w, h, 1.0f32)]).unwrap()), &cache);
        let crs = Arc::new(Crs::from_epsg(code).unwrap());
        let georef = Georef { crs, x0, y0, dx: size, dy: -size, overhang: 0.5 };
        GeoRaster::new(blocks, georef, &[Reducer::Mean], &cache)
    }

    /// The share of `bbox`'s `w × h` samples with data.
    fn covered(raster: &GeoRaster, bbox: &str, (w, h): (usize, usize)) -> f64 {
        let grid = BBox::parse(bbox).unwrap().area_grid(w, h).unwrap();
        let r = raster.sample(&grid, 0, Resampling::Bilinear).unwrap();
        r.data().iter().filter(|v| !v.is_nan()).count() as f64 / r.data().len() as f64
    }

    #[test]
    fn a_projected_source_around_a_pole_reaches_it_at_every_longitude() {
        // Regression: 100 km of polar stereographic centred on the South
        // Pole had bounds from its boundary alone, S −89.55°, and read
        // nothing closer to the pole.
        let raster = ones(3031, (-49_500.0, 49_500.0), (100, 100), 1000.0);
        let b = raster.bounds();
        assert_eq!((b.min_lat, b.min_lon, b.max_lon), (-90.0, -180.0, 180.0));
        assert!(b.max_lat < -89.3, "the corners, 71 km from the pole: {b:?}");
        assert_eq!(covered(&raster, "-180,-90,180,-89.7", (36, 8)), 1.0);
    }

    #[test]
    fn geographic_sources_past_the_antimeridian_are_read_across_it() {
        // Regression: a file of 180.5…181.5° E had bounds there and no grid
        // met it; one of 179.5…180.5° E was not read west of 180°.
        let east = ones(4326, (180.505, -16.005), (100, 100), 0.01);
        assert!((east.bounds().min_lon + 179.5).abs() < 1e-9, "{:?}", east.bounds());
        assert_eq!(covered(&east, "-179.4,-16.9,-178.6,-16.1", (8, 8)), 1.0);
        let across = ones(4326, (179.505, -16.005), (100, 100), 0.01);
        assert_eq!(covered(&across, "-179.9,-16.9,-179.6,-16.1", (8, 8)), 1.0);
        assert_eq!(covered(&across, "179.6,-16.9,179.9,-16.1", (8, 8)), 1.0);
    }

    #[test]
    fn a_source_around_the_globe_is_read_across_its_seam() {
        // Regression: a 1° world's columns were clamped half a pixel either
        // side of 180°, a step of the whole range there.
        let cache = BlockCache::new(1 << 20);
        let world = |dx: f64, overhang: f64| {
            let columns = Raster::from_fn(360, 180, |x, _| x as f32);
            let blocks = Blocks::new(Arc::new(MemorySource::new("<world>", vec![columns]).unwrap()), &cache);
            let crs = Arc::new(Crs::from_epsg(4326).unwrap());
            let georef = Georef { crs, x0: -179.5, y0: 89.5, dx, dy: -1.0, overhang };
            GeoRaster::new(blocks, georef, &[Reducer::Mean], &cache)
        };
        let sample = |world: &GeoRaster, bbox: &str, w: usize, kind: Resampling| {
            let grid = BBox::parse(bbox).unwrap().area_grid(w, 1).unwrap();
            world.sample(&grid, 0, kind).unwrap().data().to_vec()
        };
        // Between the last column (359 at 179.5°) and the first (0 at
        // 180.5°), from either side of 180°; point samples as area pixels,
        // and pixels whose size was written to ten digits.
        let expected = [0.875, 0.625, 0.375, 0.125].map(|f| 359.0 * f);
        for (dx, overhang) in [(1.0, 0.5), (1.0, 0.0), (0.999_999_996, 0.5)] {
            let world = world(dx, overhang);
            for bbox in ["179.5,0,180.5,1", "-180.5,0,-179.5,1"] {
                let got = sample(&world, bbox, 4, Resampling::Bilinear);
                assert!(got.iter().zip(expected).all(|(g, e)| (g - e).abs() < 1e-2), "{dx} {overhang} {bbox}: {got:?}");
            }
        }
        let world = world(1.0, 0.5);
        let at = |bbox: &str, w: usize, kind: Resampling| sample(&world, bbox, w, kind);
        // Only the columns either side of the seam are read, not the 360
        // between them.
        for bbox in ["179.5,0,180.5,1", "-180.5,0,-179.5,1", "179.9,0,180.1,1"] {
            let grid = BBox::parse(bbox).unwrap().area_grid(4, 1).unwrap();
            let read = world.read(&grid, Resampling::Bicubic, 1).unwrap().unwrap();
            assert!(read.window.width <= 6, "{bbox}: {:?}", read.window);
        }
        // A grid past the South Pole reads the opposite meridian (column
        // 190 is 10.5° E), and across the seam (its window starts at
        // column −1).
        let grid = SampleGrid { lon: Axis::degrees(-179.8, 190.3, 0, 2), lat: Axis::degrees(-88.5, -1.0, 0, 4) };
        let past = world.sample(&grid, 0, Resampling::Bilinear).unwrap();
        assert_eq!([past.get(1, 0), past.get(1, 3)], [190.0, 10.0], "{:?}", past.data());
        assert!((past.get(0, 0) - 359.0 * 0.3).abs() < 1e-3, "{:?}", past.data());
        // Nearest and bicubic reach across too, and coarser overviews
        // (columns of their means) meet in the middle at 180°.
        assert_eq!(at("179.5,0,180.5,1", 4, Resampling::Nearest), [359.0, 359.0, 0.0, 0.0]);
        let cubic = at("179.98,0,180.02,1", 2, Resampling::Bicubic);
        assert!((cubic[0] - cubic[1]).abs() < 15.0 && cubic.iter().all(|v| (100.0..260.0).contains(v)), "{cubic:?}");
        for step in [4.0, 16.0] {
            let seam = at(&format!("{},0,{},{step}", 180.0 - 1.5 * step, 180.0 + 1.5 * step), 3, Resampling::Bilinear);
            assert!((seam[1] - 179.5).abs() < 1e-3, "{step}° samples: {seam:?}");
        }
    }

    #[test]
    fn every_grid_of_a_spacing_reads_one_overview_that_wraps() {
        // 1350 columns: overview 1 (675) wraps, overview 2 (338) does not.
        // Regression: a grid at the seam read overview 1 and one away from it
        // overview 2, so neighbouring tiles differed on their shared samples.
        let cache = BlockCache::new(1 << 22);
        let waves = Raster::from_fn(1350, 675, |x, y| 1000.0 * ((0.37 * x as f32).sin() * (0.23 * y as f32).cos()));
        let blocks = Blocks::new(Arc::new(MemorySource::new("<world>", vec![waves]).unwrap()), &cache);
        let crs = Arc::new(Crs::from_epsg(4326).unwrap());
        let step = 360.0 / 1350.0;
        let georef = Georef { crs, x0: -180.0 + step / 2.0, y0: 90.0 - step / 2.0, dx: step, dy: -step, overhang: 0.5 };
        let world = GeoRaster::new(blocks, georef, &[Reducer::Mean], &cache);
        let grid = |w: f64, e: f64| BBox { west: w, south: -1.8, east: e, north: 1.8 }.area_grid(3, 3).unwrap();
        let (seam, away) = (grid(178.2, 181.8), grid(8.2, 11.8));
        assert_eq!((world.level_for(&seam), world.level_for(&away)), (1, 1));
        // Tiles of 36° with 33 samples (4.2 base pixels apart): the one at
        // 180° and its western neighbour share their edge samples exactly.
        let tiles = crate::grid::TileGrid::new(36.0, 33).unwrap();
        let [west, east] = [8, 9].map(|col| {
            world.sample(&tiles.tile_samples(crate::grid::TileId::new(0, 2, col), 0), 0, Resampling::Bilinear).unwrap()
        });
        assert!((0..33).all(|r| west.get(32, r).to_bits() == east.get(0, r).to_bits()));
    }

    #[test]
    fn a_web_mercator_world_is_read_across_its_seam() {
        // Regression: a projection mesh cell across 180° interpolated from
        // x = +half the world to −half, so its samples read the middle of
        // the world, and the window spanned every column.
        let cache = BlockCache::new(1 << 22);
        let n = 1024;
        let columns = Raster::from_fn(n, n, |x, _| x as f32);
        let blocks = Blocks::new(Arc::new(MemorySource::new("<mercator>", vec![columns]).unwrap()), &cache);
        let half = crate::grid::mercator::HALF_WORLD_M;
        let res = 2.0 * half / n as f64;
        let crs = Arc::new(Crs::from_epsg(3857).unwrap());
        let georef = Georef { crs, x0: -half + 0.5 * res, y0: half - 0.5 * res, dx: res, dy: -res, overhang: 0.5 };
        let world = GeoRaster::new(blocks, georef, &[Reducer::Mean], &cache);
        let grid = BBox { west: 179.99, south: -0.005, east: 180.01, north: 0.005 }.area_grid(201, 11).unwrap();
        assert!(mesh_step(&grid) > 1);
        let read = world.read(&grid, Resampling::Bilinear, 1).unwrap().unwrap();
        assert!(read.window.width <= 4, "{:?}", read.window);
        // Between the last column (1023) and the first (0), either side of 180°.
        let got = world.sample(&grid, 0, Resampling::Bilinear).unwrap();
        for c in 0..201 {
            let lon = grid.lon.coord(c);
            let x = (lon + 180.0) / 360.0 * n as f64 - 0.5;
            let expected = 1023.0 * (1024.0 - x);
            assert!((f64::from(got.get(c, 5)) - expected).abs() < 0.5, "{lon}: {} vs {expected}", got.get(c, 5));
        }
    }

    #[test]
    fn a_decimated_band_is_read_where_its_pixels_lie() {
        // Regression: an overview pixel of a decimated band (classes) holds
        // its block's north-west pixel, and was read as if it lay at the
        // block's centre: coarse samples took their class from up to half an
        // overview pixel away.
        let cache = BlockCache::new(1 << 24);
        let columns = Raster::from_fn(8192, 16, |x, _| x as f32);
        let blocks = Blocks::new(Arc::new(MemorySource::new("<classes>", vec![columns]).unwrap()), &cache);
        let crs = Arc::new(Crs::from_epsg(4326).unwrap());
        let georef = Georef { crs, x0: 0.0005, y0: 0.0155, dx: 0.001, dy: -0.001, overhang: 0.5 };
        let classes = GeoRaster::new(blocks, georef, &[Reducer::Decimate], &cache);
        // Samples 16.1 pixels apart (overview 4), at base columns 507.9, 524
        // and 540.1: the nearest decimated pixels are columns 512, 528, 544.
        let grid = BBox { west: 0.5245 - 1.5 * 0.0161, south: 0.0, east: 0.5245 + 1.5 * 0.0161, north: 0.0161 }
            .area_grid(3, 1)
            .unwrap();
        assert_eq!(classes.level_for(&grid), 4);
        for kind in [Resampling::Nearest, Resampling::Bilinear, Resampling::Bicubic] {
            let got = classes.sample(&grid, 0, kind).unwrap();
            assert_eq!(got.data(), [512.0, 528.0, 544.0], "{kind:?}: classes are never interpolated");
        }
    }

    #[test]
    fn a_projected_source_across_the_antimeridian_has_bounds_across_it() {
        // Regression: 120 km of UTM zone 60 S across 180° had bounds of
        // every longitude, so a seed planned thousands of empty tiles.
        let raster = ones(32760, (760_500.0, 8_290_500.0), (120, 120), 1000.0);
        let b = raster.bounds();
        assert!(b.min_lon > 179.0 && b.min_lon < 179.5 && b.max_lon > 180.4 && b.max_lon < 181.0, "{b:?}");
        assert_eq!(covered(&raster, "179.7,-16.2,179.9,-16.0", (8, 8)), 1.0);
        assert_eq!(covered(&raster, "-179.9,-16.2,-179.7,-16.0", (8, 8)), 1.0);
        assert_eq!(covered(&raster, "-179.0,-16.2,-178.8,-16.0", (8, 8)), 0.0);
        assert_eq!(enclosed_arc(vec![170.0, -170.0, 175.0], Some(-175.0)), (170.0, 190.0));
        assert_eq!(enclosed_arc(vec![170.0, -170.0, 175.0], Some(0.0)), (-180.0, 180.0), "the centre is outside");
        assert_eq!(enclosed_arc(vec![-10.0, 10.0], None), (-10.0, 10.0));
        assert_eq!(enclosed_arc(vec![-120.0, 0.0, 120.0], None), (-180.0, 180.0), "no gap is the outside");
        assert_eq!(enclosed_arc(Vec::new(), None), (-180.0, 180.0));
    }

    #[test]
    fn a_projected_source_wider_than_half_the_globe_keeps_its_longitudes() {
        // Regression (in review): Web Mercator over 100° W…100° E, whose
        // outside (160°) is less than half the globe, had every longitude.
        let m = 111_319.490_793_273_6;
        let raster = ones(3857, (-100.0 * m + 0.05 * m, 1_000_000.0), (2000, 100), 0.1 * m);
        let b = raster.bounds();
        assert!((b.min_lon + 100.0).abs() < 0.2 && (b.max_lon - 100.0).abs() < 0.2, "{b:?}");
    }
}
