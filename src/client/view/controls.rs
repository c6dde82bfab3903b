//! The viewer's camera controls, free of any window: keys held and mouse
//! motion move a geodetic pose the way terrain viewers do — forward along
//! the heading over the ground, sideways, up and down — at a speed that
//! grows with the height above the surface, so a valley floor and orbit
//! are both a few seconds of flight away. Given the surface under the eye
//! before each frame ([`clearance_m`](super::super::tile::clearance_m); the ellipsoid where no tile is
//! loaded), the eye is kept [`MIN_CLEARANCE_M`] above it.

use super::super::camera::Camera;
use super::super::globe::{self, Geodetic};
use crate::lod::predict::MotionLimits;
use glam::{DQuat, DVec3};

/// The longest step, seconds: a longer stall moves the eye no further.
pub const LONGEST_STEP_S: f64 = 0.5;
/// Closest the eye comes to the surface, metres: about a person's eye
/// above a tree top.
pub const MIN_CLEARANCE_M: f64 = 2.0;
/// Speed per metre of height above the surface, 1/s: the ground below
/// passes by at the same few degrees of view per second at any height.
const SPEED_PER_CLEARANCE: f64 = 0.5;
/// Slowest and fastest speeds at multiplier 1, m/s: a fast walk near the
/// canopy, and a continent in a minute from orbit.
const SPEED_RANGE_MPS: (f64, f64) = (5.0, 50_000.0);
/// Fastest speed whatever the setting, m/s: a step of a long frame stays a
/// few degrees of the globe.
const MAX_SPEED_MPS: f64 = 1.0e6;
/// Speed multiplier while the boost key is held.
const BOOST: f64 = 4.0;
/// Speed multiplier per mouse-wheel notch.
const WHEEL_STEP: f64 = 1.25;
/// The multiplier's bounds (about ±20 notches).
const MULTIPLIER_RANGE: (f64, f64) = (0.01, 100.0);
/// Turn rate of the arrow keys, degrees per second.
const KEY_TURN_DEGPS: f64 = 60.0;
/// Mouse look, degrees per pixel dragged: a drag across a 1280-pixel
/// window turns the view half round.
const MOUSE_DEG_PER_PX: f64 = 0.15;
/// A drag turns the view at most this fast, degrees per second; the rest of
/// a faster drag follows over the next frames (so the conservative camera's
/// turn rate bounds it).
const LOOK_DEGPS: f64 = 240.0;
/// Pitch stays within ± this, degrees (straight up or down has no heading).
const PITCH_LIMIT_DEG: f64 = 89.0;
/// Highest eye, metres above the ellipsoid (beyond geostationary orbit's
/// half).
const MAX_HEIGHT_M: f64 = 2.0e7;

/// Where the eye is and where it looks.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pose {
    /// Longitude, latitude and height above the ellipsoid.
    pub eye: Geodetic,
    /// Degrees clockwise from north.
    pub heading_deg: f64,
    /// Degrees above the horizon.
    pub pitch_deg: f64,
}

impl Pose {
    /// The camera of this pose.
    pub fn camera(&self, fov_y_deg: f64, size: (u32, u32)) -> Camera {
        Camera::looking(self.eye, self.heading_deg, self.pitch_deg, fov_y_deg, size)
    }
}

/// Movement keys held: each axis −1, 0 or +1.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Held {
    /// Backward (−1) or forward (+1) along the heading.
    pub forward: i8,
    /// Left (−1) or right (+1).
    pub right: i8,
    /// Down (−1) or up (+1).
    pub up: i8,
    /// Turn left (−1) or right (+1).
    pub turn: i8,
    /// Pitch down (−1) or up (+1).
    pub tilt: i8,
    /// Faster while held.
    pub boost: bool,
}

/// The controls' state: the pose, the keys held and the speed multiplier.
#[derive(Clone, Debug)]
pub struct Controls {
    /// The pose now.
    pub pose: Pose,
    /// Keys held.
    pub held: Held,
    multiplier: f64,
    /// Height above the surface under the eye, metres, as last measured.
    clearance_m: f64,
    /// Heading and pitch dragged and not yet turned, degrees.
    look_deg: (f64, f64),
}

impl Controls {
    /// Controls starting at `pose`, the surface assumed `clearance_m` below.
    pub fn new(pose: Pose, clearance_m: f64) -> Controls {
        Controls { pose, held: Held::default(), multiplier: 1.0, clearance_m, look_deg: (0.0, 0.0) }
    }

    /// The speed now, m/s.
    pub fn speed_mps(&self) -> f64 {
        (self.base_speed_mps() * if self.held.boost { BOOST } else { 1.0 }).min(MAX_SPEED_MPS)
    }

    /// The fastest the eye may move and turn at this speed setting,
    /// whatever keys are held and however fast the mouse drags: the bounds
    /// a conservative camera needs.
    pub fn limits(&self) -> MotionLimits {
        // The view turns by at most the heading's and the pitch's changes
        // together, each from keys and drag.
        let turn_degps = 2.0 * (KEY_TURN_DEGPS + LOOK_DEGPS);
        // 2 % more: a step over the globe, at the eye's height above the
        // ellipsoid, is a chord a little longer or shorter than the speed.
        let speed = (self.base_speed_mps() * BOOST).min(MAX_SPEED_MPS) * 1.02;
        MotionLimits { max_speed_mps: speed, max_turn_radps: turn_degps.to_radians() }
    }

    /// The speed without boost, m/s.
    fn base_speed_mps(&self) -> f64 {
        let (lo, hi) = SPEED_RANGE_MPS;
        (self.clearance_m * SPEED_PER_CLEARANCE).clamp(lo, hi) * self.multiplier
    }

    /// Height above the surface under the eye, as last measured, metres.
    pub fn clearance_m(&self) -> f64 {
        self.clearance_m
    }

    /// Mouse wheel: `notches` up speed up, down slow down.
    pub fn wheel(&mut self, notches: f64) {
        let (lo, hi) = MULTIPLIER_RANGE;
        self.multiplier = (self.multiplier * WHEEL_STEP.powf(notches)).clamp(lo, hi);
    }

    /// Mouse drag by `(dx, dy)` pixels: look around (turned by the next
    /// steps, at most `LOOK_DEGPS`).
    pub fn drag(&mut self, dx: f64, dy: f64) {
        self.look_deg.0 += dx * MOUSE_DEG_PER_PX;
        self.look_deg.1 -= dy * MOUSE_DEG_PER_PX;
    }

    /// Advances `dt_s` seconds with the keys held.
    pub fn step(&mut self, dt_s: f64) {
        let dt_s = dt_s.clamp(0.0, LONGEST_STEP_S);
        let h = self.held;
        let most = LOOK_DEGPS * dt_s;
        let look = (self.look_deg.0.clamp(-most, most), self.look_deg.1.clamp(-most, most));
        self.look_deg = (self.look_deg.0 - look.0, self.look_deg.1 - look.1);
        let keys = (f64::from(h.turn) * KEY_TURN_DEGPS * dt_s, f64::from(h.tilt) * KEY_TURN_DEGPS * dt_s);
        self.turn(keys.0 + look.0, keys.1 + look.1);
        let (sh, ch) = self.pose.heading_deg.to_radians().sin_cos();
        let east_north_up = DVec3::new(
            f64::from(h.forward) * sh + f64::from(h.right) * ch,
            f64::from(h.forward) * ch - f64::from(h.right) * sh,
            f64::from(h.up),
        );
        if east_north_up != DVec3::ZERO {
            let step = east_north_up.normalize() * self.speed_mps() * dt_s;
            self.translate(step);
        }
    }

    /// Records the height above the surface just measured under the eye
    /// (`None`: no surface there, so the ellipsoid is the ground) and lifts
    /// the eye to [`MIN_CLEARANCE_M`] above it if it is lower.
    pub fn ground(&mut self, clearance_m: Option<f64>) {
        let clearance_m = clearance_m.unwrap_or(self.pose.eye.height_m);
        if clearance_m < MIN_CLEARANCE_M {
            self.pose.eye.height_m += MIN_CLEARANCE_M - clearance_m;
        }
        self.clearance_m = clearance_m.max(MIN_CLEARANCE_M);
    }

    fn turn(&mut self, heading_deg: f64, pitch_deg: f64) {
        self.pose.heading_deg = (self.pose.heading_deg + heading_deg).rem_euclid(360.0);
        self.pose.pitch_deg = (self.pose.pitch_deg + pitch_deg).clamp(-PITCH_LIMIT_DEG, PITCH_LIMIT_DEG);
    }

    /// Moves the eye by `enu` metres (east, north, up) at its position:
    /// over the globe along the great circle the horizontal part points
    /// along (however long the step), then up, keeping the heading's
    /// direction — north turns as the eye moves, so the direction it looked
    /// is carried along the circle and its heading read at the new place.
    fn translate(&mut self, enu: DVec3) {
        let eye = self.pose.eye;
        let basis = globe::enu_basis(eye.lon_deg, eye.lat_deg);
        let (p, horizontal) = (eye.to_ecef(), basis * DVec3::new(enu.x, enu.y, 0.0));
        let (sh, ch) = self.pose.heading_deg.to_radians().sin_cos();
        let mut ahead = basis * DVec3::new(sh, ch, 0.0);
        let mut moved = p;
        if horizontal.length() > 0.0 {
            let turn =
                DQuat::from_axis_angle(basis.z_axis.cross(horizontal).normalize(), horizontal.length() / p.length());
            (moved, ahead) = (turn * p, turn * ahead);
        }
        let moved = Geodetic::from_ecef(moved);
        let local = globe::enu_basis(moved.lon_deg, moved.lat_deg).transpose() * ahead;
        self.pose.heading_deg = local.x.atan2(local.y).to_degrees().rem_euclid(360.0);
        let height_m = (eye.height_m + enu.z).min(MAX_HEIGHT_M);
        self.pose.eye = Geodetic::new(moved.lon_deg, moved.lat_deg, height_m);
    }
}

#[cfg(test)]
mod tests {
    use super::super::super::tile::TileData;
    use super::super::super::tile::clearance_m;
    use super::*;
    use std::sync::Arc;

    fn controls(height_m: f64, clearance_m: f64) -> Controls {
        let pose = Pose { eye: Geodetic::new(10.0, 46.0, height_m), heading_deg: 90.0, pitch_deg: -10.0 };
        Controls::new(pose, clearance_m)
    }

    fn moved_m(a: Geodetic, b: Geodetic) -> f64 {
        (a.to_ecef() - b.to_ecef()).length()
    }

    #[test]
    fn forward_moves_along_the_heading_at_a_speed_set_by_the_clearance() {
        for clearance in [100.0, 1000.0] {
            let mut c = controls(2000.0, clearance);
            let start = c.pose.eye;
            c.held.forward = 1;
            c.step(0.1);
            let expected = clearance * SPEED_PER_CLEARANCE * 0.1;
            assert!((moved_m(start, c.pose.eye) - expected).abs() < 1e-3 * expected, "{clearance}");
            // Heading 90°: east, level.
            assert!(c.pose.eye.lon_deg > start.lon_deg);
            assert!((c.pose.eye.lat_deg - start.lat_deg).abs() < 1e-7);
            assert!((c.pose.eye.height_m - start.height_m).abs() < 1e-3);
        }
    }

    #[test]
    fn keys_turn_and_pitch_within_limits_and_the_wheel_scales_speed() {
        let mut c = controls(2000.0, 500.0);
        c.held.turn = 1;
        c.step(0.5);
        c.step(0.5);
        assert!((c.pose.heading_deg - 150.0).abs() < 1e-9);
        // A long stall is taken as half a second.
        c.step(10.0);
        assert!((c.pose.heading_deg - 180.0).abs() < 1e-9);
        c.held.turn = -1;
        c.step(0.5);
        c.held = Held { tilt: 1, ..Held::default() };
        for _ in 0..10 {
            c.step(0.5);
        }
        assert_eq!(c.pose.pitch_deg, PITCH_LIMIT_DEG);
        c.held = Held::default();
        c.drag(-200.0, 0.0);
        c.step(0.5);
        assert!((c.pose.heading_deg - 120.0).abs() < 1e-9);
        // A fast drag turns at most LOOK_DEGPS, the rest on later steps.
        c.drag(-1000.0, 0.0);
        c.step(0.5);
        assert!((c.pose.heading_deg - 0.0).abs() < 1e-9);
        c.step(0.5);
        assert!((c.pose.heading_deg - 330.0).abs() < 1e-9);
        let base = c.speed_mps();
        c.wheel(2.0);
        assert!((c.speed_mps() / base - WHEEL_STEP * WHEEL_STEP).abs() < 1e-12);
        c.wheel(-1000.0);
        assert!((c.speed_mps() / base - MULTIPLIER_RANGE.0).abs() < 1e-12);
    }

    #[test]
    fn the_eye_is_lifted_above_the_surface_and_down_stops_there() {
        let mut c = controls(1500.0, 10.0);
        c.held.up = -1;
        c.step(0.5);
        // The surface now 3 m above the eye: lifted to the minimum.
        let before = c.pose.eye.height_m;
        c.ground(Some(-3.0));
        assert!((c.pose.eye.height_m - before - 3.0 - MIN_CLEARANCE_M).abs() < 1e-9);
        assert_eq!(c.clearance_m(), MIN_CLEARANCE_M);
        // Down again: at the slowest speed for a frame, then held there.
        let surface_m = c.pose.eye.height_m - MIN_CLEARANCE_M;
        for _ in 0..20 {
            c.step(0.05);
            let clearance = c.pose.eye.height_m - surface_m;
            c.ground(Some(clearance));
            assert!(c.pose.eye.height_m - surface_m >= MIN_CLEARANCE_M - 1e-9);
        }
        // No surface known: the ellipsoid is the ground.
        let mut c = controls(100.0, 100.0);
        c.pose.eye.height_m = -400.0;
        c.ground(None);
        assert_eq!(c.pose.eye.height_m, MIN_CLEARANCE_M);
    }

    #[test]
    fn limits_bound_every_motion_the_keys_and_mouse_can_make() {
        for (height_m, notches, dt) in [(3000.0, 0.0, 0.05), (100_000.0, 40.0, 0.05), (100_000.0, 40.0, 0.5)] {
            let mut c = controls(height_m, height_m - 1000.0);
            c.wheel(notches);
            let limits = c.limits();
            c.held = Held { forward: 1, right: 1, up: 1, turn: 1, tilt: -1, boost: true };
            c.drag(1e6, 1e6);
            for _ in 0..5 {
                let start = c.pose;
                c.step(dt);
                let speed = moved_m(start.eye, c.pose.eye) / dt;
                assert!(speed <= limits.max_speed_mps, "{speed} > {limits:?}");
                // Near the bound: keys and the speed setting reach it.
                assert!(speed >= 0.95 * limits.max_speed_mps, "{speed} < {limits:?}");
                let turn = start.camera(60.0, (4, 3)).forward().angle_between(c.pose.camera(60.0, (4, 3)).forward());
                assert!(turn / dt <= limits.max_turn_radps, "{turn}");
            }
        }
    }

    #[test]
    fn clearance_is_the_height_above_the_demo_surface() {
        let region = Arc::new(crate::config::load(None).unwrap());
        let source = crate::client::source::RegionSource::new(region.clone());
        let b = region.bounds;
        let (lon, lat) = (0.5 * (b.west + b.east), 0.5 * (b.south + b.north));
        let id = region.tiles.tile_containing(lon, lat, 11);
        let payload = crate::client::source::TileSource::fetch(&source, id, 4).unwrap().unwrap();
        let tile = Arc::new(TileData::prepare(&region.tiles, payload).unwrap());
        let range = tile.range.heights_m;
        let tiles = [tile];
        let high = clearance_m(Geodetic::new(lon, lat, 5000.0), &tiles).unwrap();
        assert!(high <= 5000.0 - range.0 + 1e-6 && high >= 5000.0 - range.1 - 1e-6, "{high} over {range:?}");
        // Exact: 100 m lower is 100 m closer, and below the surface negative.
        let lower = clearance_m(Geodetic::new(lon, lat, 4900.0), &tiles).unwrap();
        assert!((high - lower - 100.0).abs() < 1e-6, "{high} {lower}");
        let surface_m = 5000.0 - high;
        let under = clearance_m(Geodetic::new(lon, lat, surface_m - 30.0), &tiles).unwrap();
        assert!((under + 30.0).abs() < 1e-6, "{under}");
        // Beside the tile: no surface.
        assert_eq!(clearance_m(Geodetic::new(lon + 5.0, lat, 5000.0), &tiles), None);
        // Over a fine tile and a coarse one (a stand-in), the higher surface.
        let coarse = crate::client::source::TileSource::fetch(&source, region.tiles.tile_containing(lon, lat, 8), 4)
            .unwrap()
            .unwrap();
        let coarse = Arc::new(TileData::prepare(&region.tiles, coarse).unwrap());
        let eye = Geodetic::new(lon, lat, 5000.0);
        let alone = clearance_m(eye, std::slice::from_ref(&coarse)).unwrap();
        assert_ne!(alone, high, "the levels' surfaces differ here");
        let both = clearance_m(eye, &[tiles[0].clone(), coarse]).unwrap();
        assert_eq!(both, alone.min(high));
    }

    #[test]
    fn flying_north_over_the_pole_comes_down_the_other_side_heading_south() {
        let pose = Pose { eye: Geodetic::new(10.0, 89.95, 5000.0), heading_deg: 0.0, pitch_deg: 0.0 };
        let mut c = Controls::new(pose, 5000.0);
        c.held.forward = 1;
        // 2,500 m/s for 5 s: 12.5 km, past the pole 5.6 km away.
        for _ in 0..50 {
            c.step(0.1);
        }
        let eye = c.pose.eye;
        assert!((eye.lon_deg - -170.0).abs() < 1e-3, "{eye:?}");
        assert!((eye.lat_deg - (90.0 - (12_500.0 - 5_580.0) / 111_700.0)).abs() < 2e-3, "{eye:?}");
        assert!((c.pose.heading_deg - 180.0).abs() < 1e-3, "{}", c.pose.heading_deg);
        assert!((eye.height_m - 5000.0).abs() < 50.0, "{}", eye.height_m);
    }

    #[test]
    fn flying_east_over_the_antimeridian_keeps_the_track() {
        let pose = Pose { eye: Geodetic::new(179.99, 0.0, 5000.0), heading_deg: 90.0, pitch_deg: 0.0 };
        let mut c = Controls::new(pose, 5000.0);
        c.held.forward = 1;
        for _ in 0..10 {
            c.step(0.1);
        }
        let eye = c.pose.eye;
        assert!(eye.lon_deg < -179.98 && eye.lat_deg.abs() < 1e-9, "{eye:?}");
        assert!((c.pose.heading_deg - 90.0).abs() < 1e-9);
    }
}
