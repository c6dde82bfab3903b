//! What to seed: a box, or polygons with holes read from GeoJSON (lon/lat,
//! WGS84), and how a tile's sector relates to it — outside (the whole
//! subtree is pruned), inside (the whole subtree is seeded without further
//! tests), or on the boundary (its children are tested).
//!
//! A sector is on the boundary when a ring's edge meets it; otherwise it is
//! wholly inside or wholly outside, decided by its centre (even–odd rule over
//! a polygon's rings, so holes are outside). Touching a boundary counts as
//! meeting it, so tiles along the edge are seeded rather than missed.

use crate::grid::{BBox, Sector};
use std::path::Path;
use thiserror::Error;

/// A coverage that cannot be used.
#[derive(Debug, Error)]
#[error("{path}: {message}")]
pub struct CoverageError {
    /// The file.
    pub path: String,
    /// What is wrong.
    pub message: String,
}

/// Where a sector lies against the coverage.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Relation {
    /// No overlap: prune.
    Outside,
    /// The boundary crosses or touches it: look at the children.
    Boundary,
    /// Wholly covered.
    Inside,
}

/// A ring: a closed polygon boundary, lon/lat, with its bounding sector.
#[derive(Clone, Debug)]
pub struct Ring {
    points: Vec<(f64, f64)>,
    bounds: Sector,
}

/// The area to seed.
#[derive(Clone, Debug)]
pub enum Coverage {
    /// A box.
    Box(BBox),
    /// Polygons (outer ring first, then holes).
    Polygons(Vec<Vec<Ring>>),
    /// An area's part within a box (polygons within the region's bounds).
    Within(Box<Coverage>, BBox),
}

impl Coverage {
    /// Reads Polygon or MultiPolygon geometries (bare, in Features or a
    /// FeatureCollection) from a GeoJSON file.
    pub fn from_geojson(path: &Path) -> Result<Coverage, CoverageError> {
        let fail = |message: String| CoverageError { path: path.display().to_string(), message };
        let text = std::fs::read_to_string(path).map_err(|e| fail(format!("cannot read: {e}")))?;
        let json: geojson::GeoJson = text.parse().map_err(|e| fail(format!("not GeoJSON: {e}")))?;
        let geometries: Vec<geojson::Geometry> = match json {
            geojson::GeoJson::Geometry(g) => vec![g],
            geojson::GeoJson::Feature(f) => f.geometry.into_iter().collect(),
            geojson::GeoJson::FeatureCollection(c) => c.features.into_iter().filter_map(|f| f.geometry).collect(),
        };
        let mut polygons = Vec::new();
        for g in geometries {
            match g.value {
                geojson::Value::Polygon(p) => polygons.push(rings(&p).map_err(fail)?),
                geojson::Value::MultiPolygon(ps) => {
                    for p in &ps {
                        polygons.push(rings(p).map_err(fail)?);
                    }
                }
                other => {
                    return Err(fail(format!(
                        "{} geometries cannot be seeded; give Polygons or MultiPolygons",
                        other.type_name()
                    )));
                }
            }
        }
        if polygons.is_empty() {
            return Err(fail("no Polygon or MultiPolygon in the file".into()));
        }
        Ok(Coverage::Polygons(polygons))
    }

    /// How `sector` lies against the coverage.
    pub fn relation(&self, sector: &Sector) -> Relation {
        match self {
            Coverage::Box(b) => box_relation(b, sector),
            Coverage::Within(area, b) => match (box_relation(b, sector), area.relation(sector)) {
                (Relation::Outside, _) | (_, Relation::Outside) => Relation::Outside,
                (Relation::Inside, Relation::Inside) => Relation::Inside,
                _ => Relation::Boundary,
            },
            // Positions past ±180° meet the sector turned a world.
            Coverage::Polygons(polygons) => {
                let relations = sector.turns().map(|s| polygons_relation(polygons, &s));
                let any = |r: Relation| relations.contains(&r);
                if any(Relation::Boundary) {
                    Relation::Boundary
                } else if any(Relation::Inside) {
                    Relation::Inside
                } else {
                    Relation::Outside
                }
            }
        }
    }
}

/// How `sector` lies against `polygons`, longitudes as they are.
fn polygons_relation(polygons: &[Vec<Ring>], sector: &Sector) -> Relation {
    let hits = |ring: &Ring| ring.bounds.intersects_or_touches(sector) && ring_meets(ring, sector);
    if polygons.iter().flatten().any(hits) {
        return Relation::Boundary;
    }
    let centre = (0.5 * (sector.min_lon + sector.max_lon), 0.5 * (sector.min_lat + sector.max_lat));
    if polygons.iter().any(|p| p.iter().filter(|r| contains(r, centre)).count() % 2 == 1) {
        Relation::Inside
    } else {
        Relation::Outside
    }
}

/// A sector meeting the box only along an edge is outside: its samples on
/// that edge are the inside neighbour's too, and the client never draws it.
/// Longitudes are taken modulo 360° (a box may reach past ±180°).
fn box_relation(b: &BBox, s: &Sector) -> Relation {
    let turned = b.sector().turns();
    let holds = |b: &Sector| {
        b.min_lon <= s.min_lon && s.max_lon <= b.max_lon && b.min_lat <= s.min_lat && s.max_lat <= b.max_lat
    };
    if turned.iter().any(holds) {
        Relation::Inside
    } else if turned.iter().any(|b| b.intersects(s)) {
        Relation::Boundary
    } else {
        Relation::Outside
    }
}

/// A GeoJSON polygon's rings, each checked.
fn rings(polygon: &[Vec<Vec<f64>>]) -> Result<Vec<Ring>, String> {
    if polygon.is_empty() {
        return Err("a Polygon without rings".into());
    }
    polygon
        .iter()
        .map(|ring| {
            let points: Vec<(f64, f64)> = ring
                .iter()
                .map(|p| match p[..] {
                    [lon, lat, ..] if lon.is_finite() && lat.is_finite() && (-90.0..=90.0).contains(&lat) => {
                        Ok((lon, lat))
                    }
                    _ => Err(format!("bad position {p:?}: expected [lon, lat] in degrees")),
                })
                .collect::<Result<_, _>>()?;
            if points.len() < 4 || points.first() != points.last() {
                return Err("a ring needs at least four positions, the last equal to the first".into());
            }
            let (lons, lats) = (points.iter().map(|p| p.0), points.iter().map(|p| p.1));
            let bounds = Sector {
                min_lon: lons.clone().fold(f64::INFINITY, f64::min),
                max_lon: lons.fold(f64::NEG_INFINITY, f64::max),
                min_lat: lats.clone().fold(f64::INFINITY, f64::min),
                max_lat: lats.fold(f64::NEG_INFINITY, f64::max),
            };
            Ok(Ring { points, bounds })
        })
        .collect()
}

impl Sector {
    /// True if the two sectors overlap or share an edge or corner.
    fn intersects_or_touches(&self, other: &Sector) -> bool {
        self.min_lat <= other.max_lat
            && other.min_lat <= self.max_lat
            && self.min_lon <= other.max_lon
            && other.min_lon <= self.max_lon
    }
}

/// True if an edge of the ring meets the (closed) sector.
fn ring_meets(ring: &Ring, s: &Sector) -> bool {
    ring.points.windows(2).any(|e| segment_meets(e[0], e[1], s))
}

/// Liang–Barsky: does the segment from `a` to `b` meet the closed sector?
fn segment_meets(a: (f64, f64), b: (f64, f64), s: &Sector) -> bool {
    let (dx, dy) = (b.0 - a.0, b.1 - a.1);
    let (mut t0, mut t1) = (0.0f64, 1.0f64);
    for (p, q) in [(-dx, a.0 - s.min_lon), (dx, s.max_lon - a.0), (-dy, a.1 - s.min_lat), (dy, s.max_lat - a.1)] {
        if p == 0.0 {
            if q < 0.0 {
                return false;
            }
        } else {
            let t = q / p;
            if p < 0.0 {
                t0 = t0.max(t);
            } else {
                t1 = t1.min(t);
            }
            if t0 > t1 {
                return false;
            }
        }
    }
    true
}

/// Even–odd crossing test of a point against one ring.
fn contains(ring: &Ring, (x, y): (f64, f64)) -> bool {
    let mut inside = false;
    for e in ring.points.windows(2) {
        let ((x0, y0), (x1, y1)) = (e[0], e[1]);
        if (y0 > y) != (y1 > y) && x < x0 + (y - y0) / (y1 - y0) * (x1 - x0) {
            inside = !inside;
        }
    }
    inside
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn square_with_hole() -> Coverage {
        // A name per call: the tests run in parallel.
        static CALLS: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
        let n = CALLS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let path = std::env::temp_dir().join(format!("sylva-coverage-{}-{n}.geojson", std::process::id()));
        std::fs::write(
            &path,
            r#"{"type":"FeatureCollection","features":[{"type":"Feature","properties":{},"geometry":{"type":"Polygon","coordinates":[
                [[0,0],[10,0],[10,10],[0,10],[0,0]],
                [[4,4],[6,4],[6,6],[4,6],[4,4]]]}}]}"#,
        )
        .unwrap();
        let c = Coverage::from_geojson(&path).unwrap();
        std::fs::remove_file(path).unwrap();
        c
    }

    fn sector(w: f64, s: f64, e: f64, n: f64) -> Sector {
        Sector { min_lon: w, min_lat: s, max_lon: e, max_lat: n }
    }

    #[test]
    fn a_box_across_the_antimeridian_holds_tiles_on_both_sides() {
        // Regression: tiles west of 180° were outside a box of 179.5…180.5,
        // so seeding a region across the antimeridian made half of it.
        let fiji = Coverage::Box(BBox { west: 179.5, south: -17.0, east: 180.5, north: -16.0 });
        assert_eq!(fiji.relation(&sector(179.6, -16.9, 179.9, -16.1)), Relation::Inside);
        assert_eq!(fiji.relation(&sector(-180.0, -16.9, -179.6, -16.1)), Relation::Inside);
        assert_eq!(fiji.relation(&sector(-179.6, -16.9, -179.0, -16.1)), Relation::Boundary);
        assert_eq!(fiji.relation(&sector(-179.0, -16.9, -178.0, -16.1)), Relation::Outside);
    }

    #[test]
    fn sectors_inside_outside_on_the_boundary_and_in_holes() {
        let c = square_with_hole();
        assert_eq!(c.relation(&sector(1.0, 1.0, 2.0, 2.0)), Relation::Inside);
        assert_eq!(c.relation(&sector(4.5, 4.5, 5.5, 5.5)), Relation::Outside, "in the hole");
        assert_eq!(c.relation(&sector(3.0, 3.0, 5.0, 5.0)), Relation::Boundary, "across the hole's edge");
        assert_eq!(c.relation(&sector(-5.0, -5.0, 1.0, 1.0)), Relation::Boundary);
        assert_eq!(c.relation(&sector(20.0, 20.0, 30.0, 30.0)), Relation::Outside);
        assert_eq!(c.relation(&sector(-20.0, -20.0, 30.0, 30.0)), Relation::Boundary, "the polygon inside the sector");
    }

    #[test]
    fn bad_files_are_named_with_the_problem() {
        let dir = std::env::temp_dir().join(format!("sylva-coverage-bad-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        for (name, text, needle) in [
            ("a.geojson", "{nope", "not GeoJSON"),
            ("b.geojson", r#"{"type":"Point","coordinates":[1,2]}"#, "Point geometries cannot be seeded"),
            ("c.geojson", r#"{"type":"Polygon","coordinates":[[[0,0],[1,0],[0,0]]]}"#, "at least four positions"),
        ] {
            let path = dir.join(name);
            std::fs::write(&path, text).unwrap();
            let err = Coverage::from_geojson(&path).unwrap_err().to_string();
            assert!(err.contains(name) && err.contains(needle), "{err}");
        }
        std::fs::remove_dir_all(dir).unwrap();
    }

    #[test]
    fn polygons_past_the_antimeridian_hold_tiles_on_both_sides() {
        // Regression: a polygon of 179.8…180.2° E seeded the west side only.
        let dir = std::env::temp_dir().join(format!("sylva-coverage-across-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("across.geojson");
        let ring = "[[179.8,-16.6],[180.2,-16.6],[180.2,-16.4],[179.8,-16.4],[179.8,-16.6]]";
        std::fs::write(&path, format!(r#"{{"type":"Polygon","coordinates":[{ring}]}}"#)).unwrap();
        let c = Coverage::from_geojson(&path).unwrap();
        assert_eq!(c.relation(&sector(-179.95, -16.55, -179.85, -16.45)), Relation::Inside, "east of 180°");
        assert_eq!(c.relation(&sector(179.85, -16.55, 179.95, -16.45)), Relation::Inside, "west of 180°");
        assert_eq!(c.relation(&sector(-179.9, -16.55, -179.7, -16.45)), Relation::Boundary);
        assert_eq!(c.relation(&sector(-179.7, -16.55, -179.6, -16.45)), Relation::Outside);
        std::fs::remove_dir_all(dir).unwrap();
    }

    proptest! {
        /// Inside and outside are exact: every point of the sector agrees.
        #[test]
        fn relations_agree_with_points(w in -2.0..12.0f64, s in -2.0..12.0f64, size in 0.01..3.0f64) {
            let c = square_with_hole();
            let Coverage::Polygons(p) = &c else { unreachable!() };
            let sec = sector(w, s, w + size, s + size);
            let relation = c.relation(&sec);
            for i in 0..=8 {
                for j in 0..=8 {
                    let pt = (w + size * f64::from(i) / 8.0, s + size * f64::from(j) / 8.0);
                    let on_edge = [0.0, 4.0, 6.0, 10.0].iter().any(|&v| pt.0 == v || pt.1 == v);
                    let inside = p[0].iter().filter(|r| contains(r, pt)).count() % 2 == 1;
                    match relation {
                        Relation::Inside => prop_assert!(inside || on_edge),
                        Relation::Outside => prop_assert!(!inside || on_edge),
                        Relation::Boundary => {}
                    }
                }
            }
        }
    }
}
