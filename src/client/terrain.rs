//! A tile's terrain mesh: the ground on a coarse grid over the tile's own
//! samples (0 to N−1), every vertex carrying the offset from its flat-frame
//! place to its true place on the ellipsoid (the tile frame's trapezoid and
//! tilt undone), with skirts. Neighbouring meshes therefore meet exactly —
//! across tile levels, the antimeridian and at the poles — up to the skirts'
//! usual T-junction duty.
//!
//! It is drawn texture-mapped where no ray is cast, and, lowered below the
//! surface by the flat-frame error and without its skirts (which would
//! stand beside the tile), under ray-cast tiles whose flat frame may leave
//! a crack (`render::uniforms::needs_filler`: their rectangle misplaces the
//! true trapezoidal tile by half the one-cell overlap or more — coarse tiles
//! at high latitudes, and always at the poles): there the crack shows this
//! mesh instead of the sky. As a filler it is drawn only in a band beside
//! the tile's edge, where cracks open (`render::uniforms`).

use super::frame::TileFrame;
use super::hull::{self, QUAD_SAMPLES};
use crate::raster::Raster;
use glam::DVec3;

/// One terrain vertex, as the GPU reads it.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct TerrainVertex {
    /// Sample coordinates `(i, j)`, east and north.
    pub sample: [f32; 2],
    /// Ground height in the flat frame (local metres).
    pub height_m: f32,
    /// From the flat-frame point to the true point, local metres.
    pub offset_m: [f32; 3],
}

/// The terrain mesh of one tile.
#[derive(Clone, Debug)]
pub struct TerrainMesh {
    /// Vertices: the grid, then the skirts' lower ring.
    pub vertices: Vec<TerrainVertex>,
    /// Triangles: the grid's first, then the skirts'.
    pub indices: Vec<u32>,
    /// How many indices the grid has (the skirts' follow).
    pub grid_indices: usize,
    /// Largest vertical distance between a ground sample and the mesh.
    pub mesh_error_m: f32,
}

impl TerrainMesh {
    /// The mesh of the ground `dem` (the tile's `N²` samples, row 0 at the
    /// south, local metres of `frame`, NaN for nodata).
    pub fn build(frame: &TileFrame, dem: &Raster<f32>) -> TerrainMesh {
        let cells = dem.width() - 1;
        let k = cells.div_ceil(QUAD_SAMPLES).max(1);
        let pos: Vec<f64> = (0..=k).map(|a| a as f64 * cells as f64 / k as f64).collect();
        let low = dem.min_max().map_or(0.0, |(lo, _)| lo);
        let heights: Vec<f32> = (0..=k)
            .flat_map(|b| (0..=k).map(move |a| (a, b)))
            .map(|(a, b)| Some(bilinear(dem, pos[a], pos[b])).filter(|h| h.is_finite()).unwrap_or(low))
            .collect();
        let mesh_error_m = mesh_error(dem, &heights, &pos, k);
        let skirt_m = (4.0 * mesh_error_m as f64).max(0.01 * cells as f64 * frame.spacing_m.max_element());
        let mut vertices: Vec<TerrainVertex> = heights
            .iter()
            .enumerate()
            .map(|(n, &h)| vertex(frame, pos[n % (k + 1)], pos[n / (k + 1)], h as f64))
            .collect();
        let ring = hull::ring(k);
        let top_count = vertices.len() as u32;
        for &(a, b) in &ring {
            let h = heights[b * (k + 1) + a] as f64 - skirt_m;
            vertices.push(vertex(frame, pos[a], pos[b], h));
        }
        let indices = hull::indices(k, &ring, top_count, false);
        TerrainMesh { vertices, indices, grid_indices: 6 * k * k, mesh_error_m }
    }
}

/// The vertex at sample `(i, j)` and flat-frame height `z`.
fn vertex(frame: &TileFrame, i: f64, j: f64, z: f64) -> TerrainVertex {
    let flat = frame.local_xy(i, j).extend(z);
    let ellipsoid = frame.ellipsoid_local(i, j);
    // Heights are along the local normal; the flat frame put them along the
    // centre's up, over the ellipsoid point's drop.
    let height = z - ellipsoid.z;
    let truth = ellipsoid + frame.normal_local(i, j) * height;
    let offset: DVec3 = truth - flat;
    TerrainVertex { sample: [i as f32, j as f32], height_m: z as f32, offset_m: offset.as_vec3().to_array() }
}

/// Bilinear value of a raster at fractional position `(x, y)`.
fn bilinear(r: &Raster<f32>, x: f64, y: f64) -> f32 {
    let (x0, y0) = ((x.floor() as usize).min(r.width() - 2), (y.floor() as usize).min(r.height() - 2));
    let (fx, fy) = ((x - x0 as f64) as f32, (y - y0 as f64) as f32);
    let south = r.get(x0, y0) * (1.0 - fx) + r.get(x0 + 1, y0) * fx;
    let north = r.get(x0, y0 + 1) * (1.0 - fx) + r.get(x0 + 1, y0 + 1) * fx;
    south * (1.0 - fy) + north * fy
}

/// The largest gap between ground samples and the triangulated mesh
/// (quads split along their south-west to north-east diagonal).
fn mesh_error(dem: &Raster<f32>, heights: &[f32], pos: &[f64], k: usize) -> f32 {
    let h = |a: usize, b: usize| heights[b * (k + 1) + a];
    let quad = |v: usize| (1..k).take_while(|&q| v as f64 > pos[q]).count();
    let mut worst: f32 = 0.0;
    for y in 0..dem.height() {
        let b = quad(y);
        let v = ((y as f64 - pos[b]) / (pos[b + 1] - pos[b])) as f32;
        for (x, &g) in dem.row(y).iter().enumerate() {
            let a = quad(x);
            let u = ((x as f64 - pos[a]) / (pos[a + 1] - pos[a])) as f32;
            let (v00, v10, v11, v01) = (h(a, b), h(a + 1, b), h(a + 1, b + 1), h(a, b + 1));
            let mesh =
                if u >= v { v00 + u * (v10 - v00) + v * (v11 - v10) } else { v00 + v * (v01 - v00) + u * (v11 - v01) };
            if g.is_finite() {
                worst = worst.max((g - mesh).abs());
            }
        }
    }
    worst
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::{TileGrid, TileId};

    fn ground(grid: &TileGrid, id: TileId, f: impl Fn(f64, f64) -> f64) -> (TileFrame, Raster<f32>) {
        let frame = TileFrame::new(grid, id);
        let n = grid.samples() as usize;
        let drops = frame.drops_m(0);
        let s = grid.tile_samples(id, 0);
        let dem = Raster::from_fn(n, n, |x, y| {
            let (lon, lat) = s.lon_lat(x, n - 1 - y);
            (f(lon, lat) + drops[y * n + x]) as f32
        });
        (frame, dem)
    }

    #[test]
    fn neighbours_meet_exactly_even_at_the_pole() {
        let grid = TileGrid::new(36.0, 33).unwrap();
        let hills = |lon: f64, lat: f64| 500.0 + 300.0 * (lon * 3.0).sin() * (lat * 5.0).cos();
        // Two polar tiles side by side, and a pair at mid latitude.
        let (rows, _) = grid.tiles_on_level(3);
        for (a, b) in [
            (TileId::new(3, rows - 1, 10), TileId::new(3, rows - 1, 11)),
            (TileId::new(9, 700, 1000), TileId::new(9, 700, 1001)),
        ] {
            let (fa, da) = ground(&grid, a, hills);
            let (fb, db) = ground(&grid, b, hills);
            let (ma, mb) = (TerrainMesh::build(&fa, &da), TerrainMesh::build(&fb, &db));
            // (K + 1)² grid vertices, then the 4K of the skirts' ring.
            let k = (2..64).find(|k1| k1 * k1 + 4 * (k1 - 1) == ma.vertices.len()).expect("grid size");
            let world = |f: &TileFrame, v: &TerrainVertex| {
                let flat = f.local_xy(v.sample[0] as f64, v.sample[1] as f64).extend(v.height_m as f64);
                f.to_ecef(flat + DVec3::from_array(v.offset_m.map(f64::from)))
            };
            // a's east edge is b's west edge.
            for row in 0..k {
                let pa = world(&fa, &ma.vertices[row * k + (k - 1)]);
                let pb = world(&fb, &mb.vertices[row * k]);
                assert!((pa - pb).length() < 0.05, "{a:?}/{b:?} row {row}: {} m apart", (pa - pb).length());
            }
        }
    }

    #[test]
    fn a_flat_tile_has_no_mesh_error_and_a_bumpy_one_reports_it() {
        let flat = Raster::filled(65, 65, 500.0f32);
        let heights = vec![500.0f32; 25];
        let pos: Vec<f64> = (0..=4).map(|a| a as f64 * 16.0).collect();
        assert_eq!(mesh_error(&flat, &heights, &pos, 4), 0.0);
        let bumpy = Raster::from_fn(65, 65, |x, y| (x as f32 * 0.7).sin() * 30.0 + (y as f32 * 0.3).cos() * 50.0);
        let e = mesh_error(&bumpy, &heights, &pos, 4);
        assert!(e > 400.0, "{e}");
    }
}
