//! Culling after refinement (004 §V-D): view-frustum and horizon culling
//! break bounded variation, so the deferral table refines by distance alone
//! and the tiles to draw are taken from its refined set here, every frame.
//!
//! The walk goes down the refined nodes from the roots and tests bounding
//! spheres: a sphere outside a side plane of the frustum, or wholly hidden
//! by the occluder sphere of [`super::quadtree`], drops its subtree; one
//! wholly inside the side planes and wholly before the horizon plane is not
//! tested again below (its subtree is only listed). A tile still straddling
//! a plane or the horizon gets the old per-tile box test
//! ([`super::quadtree::visible`]), so the tiles drawn are those the box test
//! keeps. Tests are counted: with the refinement tests they are the nodes a
//! frame touched.

use super::camera::Camera;
use super::frame::TileFrame;
use super::quadtree::{OCCLUDER_RADIUS_M, Selected, local_box, visible};
use super::tiletree::TileTree;
use glam::DVec3;

/// Where a sphere lies against the view.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Seen {
    Outside,
    Straddling,
    Inside,
}

/// The tiles to draw for `camera` from the nodes flagged in `refined`, none
/// deeper than `max_level`, coarse to fine, and the visibility tests made.
pub fn drawn(tree: &TileTree, refined: &[bool], camera: &Camera, max_level: u32) -> (Vec<Selected>, usize) {
    let planes = camera.side_planes();
    let eye = camera.position_ecef;
    let mut stack: Vec<(u32, bool)> = (0..tree.nodes.len() as u32)
        .take_while(|&v| tree.nodes[v as usize].parent.is_none())
        .map(|v| (v, false))
        .collect();
    let (mut tiles, mut tests) = (Vec::new(), 0);
    while let Some((v, known_inside)) = stack.pop() {
        let n = &tree.nodes[v as usize];
        let seen = if known_inside {
            Seen::Inside
        } else {
            tests += 1;
            sphere_seen(eye, &planes, n.centre_ecef, n.radius_m)
        };
        if seen == Seen::Outside {
            continue;
        }
        if refined[v as usize] && n.children > 0 && n.id.level < max_level {
            stack.extend(tree.child_range(v).map(|c| (c, seen == Seen::Inside)));
            continue;
        }
        if seen == Seen::Straddling {
            tests += 1;
            let frame = TileFrame::new(&tree.grid, n.id);
            let (lo, hi) = local_box(&frame, n.heights_m.0, n.heights_m.1);
            if !visible(camera, &frame, &planes, lo, hi) {
                continue;
            }
        }
        let distance_m = (n.centre_ecef.distance(eye) - n.radius_m).max(0.0);
        let error_px = n.error_m * camera.focal_px() / distance_m.max(camera.near_m);
        tiles.push(Selected { id: n.id, distance_m, error_px });
    }
    tiles.sort_by_key(|s| (s.id.level, s.id.row, s.id.col));
    (tiles, tests)
}

/// The sphere `(c, r)` against the side planes (unit normals through the
/// eye, pointing in) and the horizon.
fn sphere_seen(eye: DVec3, planes: &[DVec3; 4], c: DVec3, r: f64) -> Seen {
    let side: Vec<f64> = planes.iter().map(|n| n.dot(c - eye)).collect();
    if side.iter().any(|&s| s < -r) || hidden(eye, c, r) {
        return Seen::Outside;
    }
    let inside = side.iter().all(|&s| s >= r) && before_horizon(eye, c, r);
    if inside { Seen::Inside } else { Seen::Straddling }
}

/// Whether the sphere lies wholly on the eye's side of the horizon plane
/// (the plane of the occluder's tangent points seen from the eye): every
/// point there outside the occluder is in sight.
fn before_horizon(eye: DVec3, c: DVec3, r: f64) -> bool {
    let e = eye.length();
    e > OCCLUDER_RADIUS_M && c.dot(eye / e) - r >= OCCLUDER_RADIUS_M * OCCLUDER_RADIUS_M / e
}

/// Whether the occluder hides the whole sphere: it lies beyond the horizon
/// plane and inside the cone of sight lines tangent to the occluder, so
/// every sight line to it enters the occluder first.
fn hidden(eye: DVec3, c: DVec3, r: f64) -> bool {
    let e = eye.length();
    let to = c - eye;
    let d = to.length();
    if e <= OCCLUDER_RADIUS_M || d <= r || c.dot(eye / e) + r >= OCCLUDER_RADIUS_M * OCCLUDER_RADIUS_M / e {
        return false;
    }
    let off_axis = (to.dot(-eye) / (d * e)).clamp(-1.0, 1.0).acos();
    off_axis + (r / d).asin() <= (OCCLUDER_RADIUS_M / e).asin()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::client::globe::Geodetic;

    #[test]
    fn the_horizon_hides_the_far_side_and_shows_the_near_one() {
        let eye = Geodetic::new(0.0, 0.0, 2_000_000.0).to_ecef();
        let near = Geodetic::new(1.0, 0.0, 500.0).to_ecef();
        let far = Geodetic::new(170.0, 0.0, 500.0).to_ecef();
        assert!(before_horizon(eye, near, 1000.0) && !hidden(eye, near, 1000.0));
        assert!(hidden(eye, far, 1000.0) && !before_horizon(eye, far, 1000.0));
        // A point far above the limb is in sight beyond the horizon plane.
        let high = Geodetic::new(100.0, 0.0, 30_000_000.0).to_ecef();
        assert!(!hidden(eye, high, 1000.0) && !before_horizon(eye, high, 1000.0));
    }

    #[test]
    fn spheres_sort_against_the_frustum() {
        let camera = Camera::looking(Geodetic::new(10.0, 46.0, 3000.0), 0.0, -30.0, 60.0, (640, 480));
        let (eye, planes) = (camera.position_ecef, camera.side_planes());
        let ahead = eye + camera.forward() * 5000.0;
        assert_eq!(sphere_seen(eye, &planes, ahead, 100.0), Seen::Inside);
        assert_eq!(sphere_seen(eye, &planes, eye - camera.forward() * 5000.0, 100.0), Seen::Outside);
        assert_eq!(sphere_seen(eye, &planes, ahead, 10_000.0), Seen::Straddling);
    }
}
