//! The two quadtrees of 256-pixel tiles that web and GIS clients read (OGC
//! Two Dimensional Tile Matrix Set names): `WebMercatorQuad`, the XYZ tiles
//! of MapLibre and Terrarium (EPSG:3857, one tile at zoom 0), and
//! `WorldCRS84Quad`, the geographic tiles of WMTS clients working in
//! longitude and latitude and of Cesium's geographic scheme (two tiles of
//! 180° at zoom 0, down to ±90°: poles included). Both count rows from the
//! north and columns from the antimeridian; a tile's pixels are areas, its
//! samples their centres, so neighbours meet on an edge and share none.

use super::mercator::{HALF_WORLD_M, MercatorBox, to_mercator};
use super::{BBox, GridError, SampleGrid};

/// Pixels per tile side.
pub const SIDE: usize = 256;

/// Deepest zoom addressable (tile indices stay exact in `f64`).
pub const MAX_ZOOM: u32 = 30;

/// A tile matrix set.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum TileSet {
    /// Web Mercator, `2^z × 2^z` tiles.
    WebMercator,
    /// Longitude and latitude, `2^(z+1)` columns × `2^z` rows.
    Crs84,
}

impl TileSet {
    /// Both sets.
    pub const ALL: [TileSet; 2] = [TileSet::WebMercator, TileSet::Crs84];

    /// The set's identifier.
    pub fn name(self) -> &'static str {
        match self {
            TileSet::WebMercator => "WebMercatorQuad",
            TileSet::Crs84 => "WorldCRS84Quad",
        }
    }

    /// The set named `name` (any case).
    pub fn parse(name: &str) -> Option<TileSet> {
        TileSet::ALL.into_iter().find(|s| s.name().eq_ignore_ascii_case(name.trim()))
    }

    /// Columns and rows of zoom `z`.
    pub fn matrix(self, z: u32) -> (u64, u64) {
        debug_assert!(z <= MAX_ZOOM, "zoom {z}");
        let n = 1u64 << z.min(MAX_ZOOM);
        match self {
            TileSet::WebMercator => (n, n),
            TileSet::Crs84 => (2 * n, n),
        }
    }

    /// An error unless tile `(z, col, row)` exists (rows counted from
    /// either edge).
    pub fn check(self, z: u32, col: u64, row: u64) -> Result<(), GridError> {
        let (cols, rows) = self.matrix(z.min(MAX_ZOOM));
        if z > MAX_ZOOM || col >= cols || row >= rows {
            return Err(GridError::NoSuchTile { level: z, row, col, rows, cols });
        }
        Ok(())
    }

    /// The pixel centres of tile `(z, col, row)`, or an error if it does not
    /// exist.
    pub fn tile_grid(self, z: u32, col: u64, row: u64) -> Result<SampleGrid, GridError> {
        self.check(z, col, row)?;
        match self {
            TileSet::WebMercator => MercatorBox::of_tile(z, col, row)?.area_grid(SIDE, SIDE),
            TileSet::Crs84 => geographic_box(z, col, row).area_grid(SIDE, SIDE),
        }
    }

    /// A tile's side along the equator at zoom 0, metres (on Web Mercator's
    /// sphere, the scale the standard's denominators are on).
    fn equator_tile_m(self) -> f64 {
        match self {
            TileSet::WebMercator => 2.0 * HALF_WORLD_M,
            TileSet::Crs84 => HALF_WORLD_M,
        }
    }

    /// The standard scale denominator of zoom `z` (pixels of 0.28 mm).
    pub fn scale_denominator(self, z: u32) -> f64 {
        self.equator_tile_m() / SIDE as f64 / 0.000_28 / 2f64.powi(z as i32)
    }

    /// A pixel's size at zoom 0 and latitude `lat` (degrees), metres: its
    /// north–south side, the larger (a Web Mercator pixel is square on the
    /// ground, a geographic one narrows east–west away from the equator).
    pub fn pixel_m(self, lat: f64) -> f64 {
        let at_equator = self.equator_tile_m() / SIDE as f64;
        match self {
            TileSet::WebMercator => at_equator * lat.to_radians().cos(),
            TileSet::Crs84 => at_equator,
        }
    }

    /// A pixel's width at zoom 0, degrees of longitude.
    pub fn pixel_deg(self) -> f64 {
        360.0 / self.matrix(0).0 as f64 / SIDE as f64
    }

    /// The first and last (column, row) of zoom `z`'s tiles over `b` (within
    /// ±180° and, for Web Mercator, its latitudes); a box ending on a tile's
    /// edge does not reach into the next tile.
    pub fn tiles_over(self, b: &BBox, z: u32) -> ((u64, u64), (u64, u64)) {
        let (cols, rows) = self.matrix(z);
        // Fractional indices of the north-west and south-east corners.
        let ((x0, y0), (x1, y1)) = match self {
            TileSet::WebMercator => {
                let index = |m: f64| (m + HALF_WORLD_M) / (2.0 * HALF_WORLD_M) * cols as f64;
                let ((mx0, my0), (mx1, my1)) = (to_mercator(b.west, b.north), to_mercator(b.east, b.south));
                ((index(mx0), index(-my0)), (index(mx1), index(-my1)))
            }
            TileSet::Crs84 => {
                let size = 180.0 / rows as f64;
                let (col, row) = (|lon: f64| (lon + 180.0) / size, |lat: f64| (90.0 - lat) / size);
                ((col(b.west), row(b.north)), (col(b.east), row(b.south)))
            }
        };
        let first = |f: f64, n: u64| (f.floor().max(0.0) as u64).min(n - 1);
        let last = |f: f64, n: u64| ((f.ceil() - 1.0).max(0.0) as u64).min(n - 1);
        let (c0, r0) = (first(x0, cols), first(y0, rows));
        let (c1, r1) = (last(x1, cols).max(c0), last(y1, rows).max(r0));
        ((c0, r0), (c1, r1))
    }
}

/// The box of geographic tile `(z, col, row)` (rows from the north; the
/// tile is assumed to exist). Edges are multiples of a power of two: exact,
/// so neighbours' samples lie on one lattice.
pub fn geographic_box(z: u32, col: u64, row: u64) -> BBox {
    let size = 180.0 / TileSet::Crs84.matrix(z).1 as f64;
    let west = -180.0 + col as f64 * size;
    let north = 90.0 - row as f64 * size;
    BBox { west, south: north - size, east: west + size, north }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn geographic_tiles_halve_the_world_and_neighbours_share_a_lattice() {
        let west = TileSet::Crs84.tile_grid(0, 0, 0).unwrap();
        let (lon, lat) = (west.lon.coord(0), west.lat.coord(0));
        let half_px = 180.0 / 256.0 / 2.0;
        assert_eq!((lon, lat), (-180.0 + half_px, 90.0 - half_px));
        assert_eq!(west.lat.coord(255), -90.0 + half_px);
        assert_eq!(west.lon.coord(255), -half_px);
        // Tile 5/12/40 and its east neighbour: pixel centres one step apart
        // across the edge, bitwise on one lattice.
        let (a, b) = (TileSet::Crs84.tile_grid(5, 40, 12).unwrap(), TileSet::Crs84.tile_grid(5, 41, 12).unwrap());
        assert_eq!(b.lon.coord(0) - a.lon.coord(255), a.lon.step_deg());
        assert_eq!(a.lat.coords(), b.lat.coords());
        assert_eq!(TileSet::Crs84.matrix(3), (16, 8));
        assert!(TileSet::Crs84.tile_grid(3, 16, 0).is_err());
        assert!(TileSet::Crs84.tile_grid(3, 15, 8).is_err());
        assert!(TileSet::Crs84.tile_grid(3, 15, 7).is_ok());
        assert!(TileSet::WebMercator.tile_grid(3, 8, 0).is_err());
        assert!(TileSet::Crs84.tile_grid(31, 0, 0).is_err());
    }

    #[test]
    fn scales_are_the_standards() {
        // OGC 2D Tile Matrix Set, Annex D: WebMercatorQuad and WorldCRS84Quad.
        let close = |a: f64, b: f64| (a - b).abs() < 1e-12 * b;
        assert!(close(TileSet::WebMercator.scale_denominator(0), 559_082_264.028_717_8));
        assert!(close(TileSet::Crs84.scale_denominator(0), 279_541_132.014_358_9));
        assert!(close(TileSet::Crs84.scale_denominator(3), 34_942_641.501_794_87));
        assert!((TileSet::Crs84.pixel_m(60.0) - 78_271.517).abs() < 1e-3);
        assert!((TileSet::WebMercator.pixel_m(60.0) - 156_543.034 / 2.0).abs() < 1e-3);
        assert_eq!(TileSet::Crs84.pixel_deg(), 180.0 / 256.0);
        assert_eq!(TileSet::WebMercator.pixel_deg(), 360.0 / 256.0);
        assert_eq!(TileSet::parse("worldcrs84quad"), Some(TileSet::Crs84));
        assert_eq!(TileSet::parse("GoogleCRS84Quad"), None);
    }

    #[test]
    fn a_box_ending_on_a_tile_edge_does_not_reach_into_the_next_tile() {
        // Zoom 1 of Web Mercator: the four quarters of the world; a box of the
        // north-west one.
        let nw = BBox { west: -180.0, south: 0.0, east: 0.0, north: 85.0 };
        assert_eq!(TileSet::WebMercator.tiles_over(&nw, 1), ((0, 0), (0, 0)));
        assert_eq!(TileSet::WebMercator.tiles_over(&nw, 2), ((0, 0), (1, 1)));
        // Geographic zoom 1: 90° tiles, the box in the first two columns of row 0.
        assert_eq!(TileSet::Crs84.tiles_over(&nw, 1), ((0, 0), (1, 0)));
        let inside = BBox { west: 10.0, south: 46.3, east: 10.25, north: 46.45 };
        assert_eq!(TileSet::WebMercator.tiles_over(&inside, 1), ((1, 0), (1, 0)));
        assert_eq!(TileSet::Crs84.tiles_over(&inside, 0), ((1, 0), (1, 0)));
        // The south pole's tiles: the last row.
        let pole = BBox { west: -180.0, south: -90.0, east: 180.0, north: -80.0 };
        assert_eq!(TileSet::Crs84.tiles_over(&pole, 2), ((0, 3), (7, 3)));
    }
}
