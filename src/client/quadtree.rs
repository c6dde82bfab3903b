//! Which tiles to draw: the World Wind quadtree walked from level 0 over the
//! region, culled against the view frustum, refined while a tile's
//! screen-space error exceeds a threshold (the first LOD rule; the mixed
//! LOD optimiser refines it). This stateless walk serves single views and
//! regions too large for a flight's tile tree; flights keep their selection
//! across frames with the distance deferral table ([`super::sse`]), which
//! shares the culling below.
//!
//! Culling: a tile is dropped when its bounding box is outside a side plane
//! of the view frustum, or entirely behind the horizon (every corner hidden
//! by a sphere just inside the ellipsoid).
//!
//! A tile's error is its sample spacing plus its flat-frame error
//! ([`super::frame`]) — so coarse tiles seen from low altitude are refined
//! until the flat-tile approximation is invisible too — projected at the
//! nearest distance from the camera to the tile's bounding box.

use super::camera::Camera;
use super::frame::TileFrame;
use crate::grid::{BBox, Sector, TileGrid, TileId};
use glam::DVec3;

/// Heights assumed for a tile nobody has loaded yet (nor an ancestor):
/// from the Dead Sea shore to above Everest, metres.
pub const UNKNOWN_RANGE_M: (f64, f64) = (-500.0, 9000.0);

/// The refinement rule.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LodRule {
    /// Largest projected error, pixels.
    pub max_error_px: f64,
    /// Deepest level to refine to.
    pub max_level: u32,
}

/// A selected tile with what the selection learnt about it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Selected {
    /// The tile.
    pub id: TileId,
    /// Nearest distance from the camera, metres.
    pub distance_m: f64,
    /// Projected error, pixels.
    pub error_px: f64,
}

/// The tiles to draw, and how many nodes the selection touched.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Selection {
    /// Tiles, coarse to fine, none an ancestor of another.
    pub tiles: Vec<Selected>,
    /// Nodes touched: refinement tests plus visibility tests (a node the
    /// walk visits is tested for both at once).
    pub visited: usize,
    /// Refinement tests among them.
    pub evaluated: usize,
}

/// Selects tiles of `grid` over `bounds` for `camera`. `range(id)` gives
/// the absolute height range of a tile if known (from it or an ancestor).
pub fn select(
    grid: &TileGrid,
    bounds: &BBox,
    camera: &Camera,
    range: &dyn Fn(TileId) -> Option<(f64, f64)>,
    rule: &LodRule,
) -> Selection {
    let area = bounds.sector();
    let (rows, cols) = grid.tiles_on_level(0);
    let mut out = Selection::default();
    let mut stack: Vec<TileId> = (0..rows).flat_map(|r| (0..cols).map(move |c| TileId::new(0, r, c))).collect();
    let planes = camera.side_planes();
    while let Some(id) = stack.pop() {
        if !touches(grid, id, &area) {
            continue;
        }
        out.visited += 1;
        let (lo, hi) = range(id).unwrap_or(UNKNOWN_RANGE_M);
        let frame = TileFrame::new(grid, id);
        let (box_lo, box_hi) = local_box(&frame, lo, hi);
        if !visible(camera, &frame, &planes, box_lo, box_hi) {
            continue;
        }
        let cam = frame.to_local(camera.position_ecef);
        let distance_m = (cam.clamp(box_lo, box_hi) - cam).length();
        let error_m = frame.spacing_m.max_element() + frame.flat_error_m(lo.abs().max(hi.abs()));
        let error_px = error_m * camera.focal_px() / distance_m.max(camera.near_m);
        if error_px > rule.max_error_px && id.level < rule.max_level {
            stack.extend(id.children());
        } else {
            out.tiles.push(Selected { id, distance_m, error_px });
        }
    }
    out.tiles.sort_by_key(|s| (s.id.level, s.id.row, s.id.col));
    out.evaluated = out.visited;
    out
}

/// Whether tile `id` overlaps `area`, which may reach past ±180°.
pub fn touches(grid: &TileGrid, id: TileId, area: &Sector) -> bool {
    // Strictly, as point-registered edges ask: a tile whose edge lies on the
    // area's edge holds data there only on that edge; it is not needed.
    area.meets_on_globe(&grid.sector(id))
}

/// The tile's bounding box in its flat frame: the cast range grown by the
/// flat-frame error, from the lowest ellipsoid drop below the lowest height
/// to the highest height.
pub fn local_box(frame: &TileFrame, lo_m: f64, hi_m: f64) -> (DVec3, DVec3) {
    let n = frame.samples as f64;
    let slack = frame.flat_error_m(lo_m.abs().max(hi_m.abs()));
    let corner_drop = [(-1.0, -1.0), (n, -1.0), (-1.0, n), (n, n)]
        .iter()
        .map(|&(i, j)| frame.ellipsoid_local(i, j).z)
        .fold(0.0, f64::min);
    let a = frame.local_xy(-1.0, -1.0);
    let b = frame.local_xy(n, n);
    (
        DVec3::new(a.x - slack, a.y - slack, lo_m + corner_drop - slack),
        DVec3::new(b.x + slack, b.y + slack, hi_m + slack),
    )
}

/// A sphere inside the ellipsoid and below any ground (the polar radius
/// less 11 km): what it hides, the Earth hides.
pub const OCCLUDER_RADIUS_M: f64 = 6_356_752.0 - 11_000.0;

/// False when the box is entirely outside one side plane of the frustum or
/// entirely behind the horizon.
pub fn visible(camera: &Camera, frame: &TileFrame, planes: &[DVec3; 4], lo: DVec3, hi: DVec3) -> bool {
    let corners: [DVec3; 8] = std::array::from_fn(|k| {
        let local = DVec3::new([lo.x, hi.x][k & 1], [lo.y, hi.y][(k >> 1) & 1], [lo.z, hi.z][k >> 2]);
        frame.to_ecef(local) - camera.position_ecef
    });
    let in_frustum = planes.iter().all(|n| corners.iter().any(|c| n.dot(*c) >= 0.0));
    in_frustum && !corners.iter().all(|&c| behind_horizon(camera.position_ecef, c))
}

/// Whether the sight line from `eye` to `eye + to` passes through the
/// occluding sphere.
pub fn behind_horizon(eye: DVec3, to: DVec3) -> bool {
    let t = (-eye.dot(to) / to.length_squared()).clamp(0.0, 1.0);
    (eye + to * t).length() < OCCLUDER_RADIUS_M
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::client::globe::Geodetic;

    fn grid() -> TileGrid {
        TileGrid::new(36.0, 513).unwrap()
    }

    fn demo_box() -> BBox {
        BBox { west: 10.0, south: 46.3, east: 10.25, north: 46.45 }
    }

    fn select_from(eye: Geodetic, heading: f64, pitch: f64) -> Selection {
        let camera = Camera::looking(eye, heading, pitch, 60.0, (640, 480));
        select(&grid(), &demo_box(), &camera, &|_| Some((500.0, 3500.0)), &LodRule { max_error_px: 1.5, max_level: 14 })
    }

    #[test]
    fn tiles_cover_the_view_without_overlap_and_refine_near_the_camera() {
        let s = select_from(Geodetic::new(10.1, 46.32, 2500.0), 10.0, -15.0);
        assert!(!s.tiles.is_empty());
        for (k, a) in s.tiles.iter().enumerate() {
            for b in &s.tiles[k + 1..] {
                let (hi, lo) = if a.id.level >= b.id.level { (a.id, b.id) } else { (b.id, a.id) };
                let shift = hi.level - lo.level;
                assert!(!(hi.row >> shift == lo.row && hi.col >> shift == lo.col), "{lo:?} contains {hi:?}");
            }
        }
        let nearest = s.tiles.iter().min_by(|a, b| a.distance_m.total_cmp(&b.distance_m)).unwrap();
        let farthest = s.tiles.iter().max_by(|a, b| a.distance_m.total_cmp(&b.distance_m)).unwrap();
        assert!(nearest.id.level > farthest.id.level, "{nearest:?} {farthest:?}");
        for t in &s.tiles {
            assert!(t.error_px <= 1.5 || t.id.level == 14, "{t:?}");
        }
    }

    #[test]
    fn the_far_side_of_the_globe_is_culled() {
        let camera = Camera::looking(Geodetic::new(10.0, 0.0, 2_000_000.0), 0.0, -90.0, 60.0, (640, 480));
        let world = BBox::WORLD;
        let s =
            select(&grid(), &world, &camera, &|_| Some((0.0, 1000.0)), &LodRule { max_error_px: 2.0, max_level: 8 });
        assert!(!s.tiles.is_empty());
        for t in &s.tiles {
            let sector = grid().sector(t.id);
            assert!(sector.max_lon > -80.0 && sector.min_lon < 100.0, "{t:?} is on the far side");
        }
    }

    #[test]
    fn looking_away_selects_less_than_looking_at() {
        let at = select_from(Geodetic::new(10.1, 46.3, 3000.0), 0.0, -20.0);
        let away = select_from(Geodetic::new(10.1, 46.3, 3000.0), 180.0, 10.0);
        assert!(away.tiles.len() < at.tiles.len() / 2, "{} vs {}", away.tiles.len(), at.tiles.len());
    }
}
