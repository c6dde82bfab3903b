//! How much of the screen a tile covers, for the LOD benefit and cost
//! models: the pixels its surface projects to (front-facing, in front of
//! the near plane, inside the image, not behind the horizon), and the
//! pixels the whole tile would cover at the density of its nearest point.
//!
//! The surface is approximated by a few lon/lat cells at one height (the
//! middle of the part of the tile's range below the eye), or for a tile
//! wholly above the eye by the cells of its box's floor and walls; each
//! cell is clipped against the near plane
//! in camera space, projected, clipped to the image and measured with the
//! shoelace formula. Cells facing away (the far side of a coarse tile on
//! the globe) and cells behind the horizon count nothing. Overlap between
//! tiles is not removed: the renderer casts rays on every hull fragment,
//! hidden or not (fragments write their depth, so no early depth test).

use super::super::camera::Camera;
use super::super::globe::Geodetic;
use super::super::quadtree::behind_horizon;
use crate::grid::Sector;
use glam::{DVec2, DVec3};

/// Cells per side of a tile's surface: coarse tiles curve with the globe
/// (a level-3 tile spans 4.5°, whose chord sags ~5 km at the middle), fine
/// ones are nearly flat.
fn cells_per_side(span_deg: f64) -> usize {
    if span_deg > 2.0 { 8 } else { 3 }
}

/// Vertices a clipped cell can have: 4, one more at the near plane, and at
/// most one more per image edge.
const MAX_VERTICES: usize = 12;

/// A small convex polygon.
#[derive(Clone, Copy)]
struct Polygon<T: Copy + Default> {
    v: [T; MAX_VERTICES],
    n: usize,
}

impl<T: Copy + Default> Polygon<T> {
    fn new() -> Self {
        Polygon { v: [T::default(); MAX_VERTICES], n: 0 }
    }

    fn push(&mut self, p: T) {
        if self.n < MAX_VERTICES {
            self.v[self.n] = p;
            self.n += 1;
        }
    }

    fn iter(&self) -> impl Iterator<Item = T> + '_ {
        self.v[..self.n].iter().copied()
    }

    /// Sutherland–Hodgman against the half-space `inside(p) ≥ 0`.
    fn clip(&self, inside: impl Fn(T) -> f64, lerp: impl Fn(T, T, f64) -> T) -> Self {
        let mut out = Polygon::new();
        for k in 0..self.n {
            let (a, b) = (self.v[k], self.v[(k + 1) % self.n]);
            let (da, db) = (inside(a), inside(b));
            if da >= 0.0 {
                out.push(a);
            }
            if (da >= 0.0) != (db >= 0.0) {
                out.push(lerp(a, b, da / (da - db)));
            }
        }
        out
    }
}

/// Pixels covered by the front-facing surface of `sector` at `height_m`
/// above the ellipsoid, seen from `camera`.
pub fn visible_px(camera: &Camera, sector: &Sector, height_m: f64) -> f64 {
    finite(sheet_px(camera, sector, height_m, Winding::Up))
}

/// Pixels covered by the side of `sector` at `height_m` that `winding`
/// names (its top, or its underside), where it faces the camera.
fn sheet_px(camera: &Camera, sector: &Sector, height_m: f64, winding: Winding) -> f64 {
    let m = cells_per_side(sector.max_lon - sector.min_lon);
    let lons = steps(sector.min_lon, sector.max_lon, m);
    let rows = steps(sector.min_lat, sector.max_lat, m).map(|lat| lons.clone().map(move |lon| (lon, lat, height_m)));
    grid_px(camera, &project(camera, rows.flatten()), m + 1, winding)
}

/// Pixels covered by the box of `sector` between `lo_m` and `hi_m` above
/// the ellipsoid, seen from `camera` below it: its floor seen from
/// underneath and the walls facing the camera, the silhouette of the
/// ground it holds. A tile wholly above a low camera (a flank rising from
/// a valley) faces the camera on its slopes, not on a plane at one height,
/// which from below faces away.
pub fn above_px(camera: &Camera, sector: &Sector, (lo_m, hi_m): (f64, f64)) -> f64 {
    let m = cells_per_side(sector.max_lon - sector.min_lon);
    let (lons, lats) = (steps(sector.min_lon, sector.max_lon, m), steps(sector.min_lat, sector.max_lat, m));
    let mut px = sheet_px(camera, sector, lo_m, Winding::Down);
    // Each wall a strip of cells, its foot along one edge (west to east,
    // south to north) and its top above; facing out of the box.
    let walls = [
        (sector.min_lat, false, Winding::Up),
        (sector.max_lat, false, Winding::Down),
        (sector.min_lon, true, Winding::Down),
        (sector.max_lon, true, Winding::Up),
    ];
    for (at, along_lat, winding) in walls {
        let edge = if along_lat { lats.clone() } else { lons.clone() };
        let point = move |t: f64, h: f64| if along_lat { (at, t, h) } else { (t, at, h) };
        let strip = [lo_m, hi_m].into_iter().flat_map(|h| edge.clone().map(move |t| point(t, h)));
        px += grid_px(camera, &project(camera, strip), m + 1, winding);
    }
    finite(px)
}

/// `m + 1` values evenly from `a` to `b`.
fn steps(a: f64, b: f64, m: usize) -> impl Iterator<Item = f64> + Clone {
    (0..=m).map(move |k| a + (b - a) * k as f64 / m as f64)
}

/// Points (lon, lat, height) in camera space, each with whether it lies
/// behind the horizon.
fn project(camera: &Camera, points: impl Iterator<Item = (f64, f64, f64)>) -> Vec<(DVec3, bool)> {
    let eye = camera.position_ecef;
    let to_camera = camera.rotation.transpose();
    points
        .map(|(lon, lat, h)| {
            let to = Geodetic::new(lon, lat, h).to_ecef() - eye;
            (to_camera * to, behind_horizon(eye, to))
        })
        .collect()
}

/// Which way a grid of points faces: `Up` when its rows run along the
/// first axis counter-clockwise seen from outside (the top of a sheet
/// seen from above), `Down` the other side.
#[derive(Clone, Copy)]
enum Winding {
    Up,
    Down,
}

/// Pixels covered by the front-facing cells of a grid of camera-space
/// points, `cols` per row; cells wholly behind the horizon count nothing.
fn grid_px(camera: &Camera, points: &[(DVec3, bool)], cols: usize, winding: Winding) -> f64 {
    let rows = points.len() / cols;
    let mut total = 0.0;
    for j in 0..rows.saturating_sub(1) {
        for i in 0..cols - 1 {
            let mut corners = [j * cols + i, j * cols + i + 1, (j + 1) * cols + i + 1, (j + 1) * cols + i];
            if corners.iter().all(|&k| points[k].1) {
                continue;
            }
            if let Winding::Down = winding {
                corners.reverse();
            }
            let mut cell = Polygon::new();
            for k in corners {
                cell.push(points[k].0);
            }
            total += projected_area(camera, &cell);
        }
    }
    total
}

/// `px`, or 0 where it is not finite.
fn finite(px: f64) -> f64 {
    if px.is_finite() { px } else { 0.0 }
}

/// The signed image area of a camera-space polygon (counter-clockwise
/// seen from the camera: positive), clipped to the near plane and the
/// image; 0 when it faces away.
fn projected_area(camera: &Camera, cell: &Polygon<DVec3>) -> f64 {
    let near = camera.near_m.max(1e-3);
    let front = cell.clip(|p| -p.z - near, |a, b, t| a + (b - a) * t);
    if front.n < 3 {
        return 0.0;
    }
    let f = camera.focal_px();
    let (w, h) = (f64::from(camera.width_px), f64::from(camera.height_px));
    // Image coordinates with y up, so the orientation is the camera's.
    let mut image: Polygon<DVec2> = Polygon::new();
    for p in front.iter() {
        image.push(DVec2::new(0.5 * w + f * p.x / -p.z, 0.5 * h + f * p.y / -p.z));
    }
    let lerp = |a: DVec2, b: DVec2, t: f64| a + (b - a) * t;
    let image = image.clip(|p| p.x, lerp).clip(|p| w - p.x, lerp).clip(|p| p.y, lerp).clip(|p| h - p.y, lerp);
    let mut twice = 0.0;
    for k in 0..image.n {
        let (a, b) = (image.v[k], image.v[(k + 1) % image.n]);
        twice += a.x * b.y - b.x * a.y;
    }
    (0.5 * twice).max(0.0)
}

/// Pixels a tile of `area_m2` would cover if all of it were `near_m` away,
/// facing the camera: the density its samples are seen at, at its nearest.
pub fn full_px(camera: &Camera, area_m2: f64, near_m: f64) -> f64 {
    let f = camera.focal_px();
    let d = near_m.max(camera.near_m).max(1e-3);
    let px = area_m2 * f * f / (d * d);
    if px.is_finite() { px } else { f64::MAX }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::TileGrid;

    fn camera(height_m: f64, pitch_deg: f64) -> Camera {
        Camera::looking(Geodetic::new(10.1, 46.3, height_m), 0.0, pitch_deg, 60.0, (320, 240))
    }

    #[test]
    fn a_tile_filling_the_view_covers_the_image() {
        // Straight down from 3 km onto a level-9 tile (~8 km across).
        let grid = TileGrid::new(36.0, 513).unwrap();
        let id = grid.tile_containing(10.1, 46.3, 9);
        let sector = grid.sector(id);
        let c = Camera::looking(
            Geodetic::new((sector.min_lon + sector.max_lon) / 2.0, (sector.min_lat + sector.max_lat) / 2.0, 3000.0),
            0.0,
            -90.0,
            60.0,
            (320, 240),
        );
        let px = visible_px(&c, &sector, 0.0);
        assert!((px - 320.0 * 240.0).abs() < 1.0, "{px}");
        // From below the surface it faces away.
        assert_eq!(visible_px(&c, &sector, 5000.0), 0.0);
    }

    #[test]
    fn a_tile_above_the_camera_shows_its_floor_and_the_walls_facing_it() {
        let grid = TileGrid::new(36.0, 513).unwrap();
        let s = grid.sector(grid.tile_containing(10.1, 46.3, 12));
        let mid_lon = (s.min_lon + s.max_lon) / 2.0;
        // Straight up from under the middle: the floor fills the view; a
        // plane at one height faces away.
        let mid = Geodetic::new(mid_lon, (s.min_lat + s.max_lat) / 2.0, 0.0);
        let up = Camera::looking(mid, 0.0, 90.0, 60.0, (320, 240));
        let px = above_px(&up, &s, (300.0, 400.0));
        assert!((px - 320.0 * 240.0).abs() < 1.0, "{px}");
        assert_eq!(visible_px(&up, &s, 300.0), 0.0);
        // Level, 1 km south of the tile, 200 m below its floor: the south
        // wall up to the image's top and the floor behind it, a trapezoid
        // (the side walls face away).
        let eye = Geodetic::new(mid_lon, s.min_lat - 1000.0 / 111_160.0, 1000.0);
        let level = Camera::looking(eye, 0.0, 0.0, 60.0, (320, 240));
        let at = |lon: f64, lat: f64| (Geodetic::new(lon, lat, 1000.0).to_ecef() - eye.to_ecef()).length();
        let (near, far) = (at(mid_lon, s.min_lat), at(mid_lon, s.max_lat));
        let half_width = 0.5
            * (Geodetic::new(s.max_lon, s.min_lat, 0.0).to_ecef() - Geodetic::new(s.min_lon, s.min_lat, 0.0).to_ecef())
                .length();
        let f = level.focal_px();
        let wall = 2.0 * half_width / near * f * (120.0 - 200.0 / near * f);
        let floor = (200.0 / near - 200.0 / far) * f * (half_width / near + half_width / far) * f;
        let px = above_px(&level, &s, (1200.0, 2200.0));
        assert!((px / (wall + floor) - 1.0).abs() < 0.03, "{px} against {}", wall + floor);
        assert_eq!(visible_px(&level, &s, 1700.0), 0.0);
    }

    #[test]
    fn area_falls_with_the_square_of_distance() {
        // A level-12 tile (~1 km) seen 45° down its middle from 4.2 and 8.5 km.
        let grid = TileGrid::new(36.0, 513).unwrap();
        let sector = grid.sector(grid.tile_containing(10.1, 46.45, 12));
        let mid = (sector.min_lat + sector.max_lat) / 2.0;
        let lon = (sector.min_lon + sector.max_lon) / 2.0;
        let from = |h: f64| {
            let c = Camera::looking(Geodetic::new(lon, mid - h / 111_200.0, h), 0.0, -45.0, 60.0, (320, 240));
            visible_px(&c, &sector, 0.0)
        };
        let (near, far) = (from(3000.0), from(6000.0));
        assert!(near > 1000.0 && (near / far - 4.0).abs() < 0.5, "{near} {far}");
    }

    #[test]
    fn the_far_side_and_the_view_behind_count_nothing() {
        let grid = TileGrid::new(36.0, 513).unwrap();
        let behind = grid.sector(grid.tile_containing(10.1, 46.2, 12));
        assert_eq!(visible_px(&camera(2000.0, -10.0), &behind, 0.0), 0.0, "behind the camera");
        let antipode = Sector { min_lat: -50.0, max_lat: -40.0, min_lon: -175.0, max_lon: -165.0 };
        let orbit = Camera::looking(Geodetic::new(10.0, 46.0, 2e7), 0.0, -90.0, 60.0, (320, 240));
        assert_eq!(visible_px(&orbit, &antipode, 0.0), 0.0);
        assert!(full_px(&orbit, 1e6, 0.0).is_finite());
    }
}
