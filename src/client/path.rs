//! Camera paths for flyovers: keyframes in a TOML file (position on the
//! globe, heading, pitch, time), interpolated to any number of frames —
//! positions by a uniform Catmull–Rom spline, headings
//! the short way round, pitch linearly — and the sun.
//!
//! ```toml
//! fov_deg = 60
//! sun = { azimuth_deg = 135.0, elevation_deg = 35.0 }   # omit for no sun
//! [[key]]
//! t = 0.0
//! lon = 10.05
//! lat = 46.33
//! height_m = 1800.0      # above the WGS84 ellipsoid
//! heading_deg = 45.0     # clockwise from north
//! pitch_deg = -10.0      # above the horizon
//! ```

use super::camera::Camera;
use super::globe::{self, Geodetic};
use crate::lod::predict::MotionLimits;
use glam::DVec3;
use serde::Deserialize;
use std::path::Path;

/// A keyframe.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Key {
    /// Time, seconds.
    pub t: f64,
    /// Longitude, degrees.
    pub lon: f64,
    /// Latitude, degrees.
    pub lat: f64,
    /// Height above the ellipsoid, metres.
    pub height_m: f64,
    /// Heading, degrees clockwise from north.
    pub heading_deg: f64,
    /// Pitch, degrees above the horizon.
    pub pitch_deg: f64,
}

/// The sun's direction from the path's first keyframe.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Sun {
    /// Azimuth, degrees clockwise from north.
    pub azimuth_deg: f64,
    /// Elevation above the horizon, degrees.
    pub elevation_deg: f64,
}

impl Sun {
    /// Unit direction to the sun (ECEF) as seen at `lon`, `lat` (degrees).
    pub fn ecef(&self, lon: f64, lat: f64) -> DVec3 {
        let (sa, ca) = self.azimuth_deg.to_radians().sin_cos();
        let (se, ce) = self.elevation_deg.to_radians().sin_cos();
        globe::enu_basis(lon, lat) * DVec3::new(sa * ce, ca * ce, se)
    }
}

/// A camera path.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct CameraPath {
    /// Vertical field of view, degrees.
    #[serde(default = "default_fov")]
    pub fov_deg: f64,
    /// The sun, if any.
    pub sun: Option<Sun>,
    /// Keyframes in time order.
    pub key: Vec<Key>,
}

fn default_fov() -> f64 {
    60.0
}

/// Why a path file is unusable.
#[derive(Debug, thiserror::Error)]
pub enum PathError {
    /// It cannot be read.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// The failure.
        source: std::io::Error,
    },
    /// It is not a valid path.
    #[error("{path}: {reason}")]
    Invalid {
        /// The file.
        path: String,
        /// What is wrong.
        reason: String,
    },
}

impl CameraPath {
    /// Reads and checks a path file.
    pub fn load(path: &Path) -> Result<CameraPath, PathError> {
        let name = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|source| PathError::Io { path: name.clone(), source })?;
        CameraPath::parse(&text).map_err(|reason| PathError::Invalid { path: name, reason })
    }

    /// Parses and checks a path.
    pub fn parse(text: &str) -> Result<CameraPath, String> {
        let path: CameraPath = toml::from_str(text).map_err(|e| e.to_string())?;
        if path.key.is_empty() {
            return Err("a path needs at least one [[key]]".into());
        }
        if !(1.0..=170.0).contains(&path.fov_deg) {
            return Err(format!("fov_deg {} is not within 1..170", path.fov_deg));
        }
        if let Some(sun) = &path.sun
            && !(sun.azimuth_deg.is_finite() && (-90.0..=90.0).contains(&sun.elevation_deg))
        {
            let (azimuth, elevation) = (sun.azimuth_deg, sun.elevation_deg);
            return Err(format!(
                "sun = {{ azimuth_deg = {azimuth}, elevation_deg = {elevation} }}: need a finite azimuth_deg and elevation_deg within -90..90"
            ));
        }
        for (k, key) in path.key.iter().enumerate() {
            key.check().map_err(|e| format!("key {}: {e}", k + 1))?;
            if k > 0 && key.t <= path.key[k - 1].t {
                return Err(format!("key {} is not later than the one before", k + 1));
            }
        }
        Ok(path)
    }

    /// The pose at time `t` (clamped to the keys' span); longitudes
    /// change the short way round, across the antimeridian too.
    pub fn at(&self, t: f64) -> Key {
        let keys = &self.key;
        let last = keys.len() - 1;
        let k = keys.iter().rposition(|key| key.t <= t).unwrap_or(0).min(last.saturating_sub(1));
        if last == 0 {
            return keys[0];
        }
        let (a, b) = (keys[k], keys[k + 1]);
        let u = ((t - a.t) / (b.t - a.t)).clamp(0.0, 1.0);
        let before = keys[k.saturating_sub(1)];
        let after = keys[(k + 2).min(last)];
        let spline = |f: fn(&Key) -> f64| catmull_rom(f(&before), f(&a), f(&b), f(&after), u);
        // Each longitude within half a turn of its neighbour's, from `a` on.
        let unwrap = |lon: f64, from: f64| from + (lon - from + 540.0).rem_euclid(360.0) - 180.0;
        let b_lon = unwrap(b.lon, a.lon);
        let lon = catmull_rom(unwrap(before.lon, a.lon), a.lon, b_lon, unwrap(after.lon, b_lon), u);
        let turn = (b.heading_deg - a.heading_deg + 540.0).rem_euclid(360.0) - 180.0;
        Key {
            t,
            lon: if lon > 180.0 {
                lon - 360.0
            } else if lon < -180.0 {
                lon + 360.0
            } else {
                lon
            },
            lat: spline(|k| k.lat).clamp(-90.0, 90.0),
            height_m: spline(|k| k.height_m),
            heading_deg: a.heading_deg + turn * u,
            pitch_deg: a.pitch_deg + (b.pitch_deg - a.pitch_deg) * u,
        }
    }

    /// Seconds from the first key to the last.
    pub fn duration_s(&self) -> f64 {
        self.key[self.key.len() - 1].t - self.key[0].t
    }

    /// The time of frame `index` of `frames`, spread evenly over the path.
    pub fn time(&self, index: usize, frames: usize) -> f64 {
        let first = self.key[0].t;
        if frames > 1 { first + self.duration_s() * index as f64 / (frames - 1) as f64 } else { first }
    }

    /// The camera of frame `index` of `frames`, spread evenly over the path.
    pub fn camera(&self, index: usize, frames: usize, size: (u32, u32)) -> Camera {
        self.camera_at(self.time(index, frames), size)
    }

    /// The fastest the camera moves (m/s) and turns its view (rad/s) over
    /// `steps` even steps of the path: the bounds the conservative camera
    /// of a flight along it needs.
    pub fn motion_limits(&self, steps: usize) -> MotionLimits {
        let steps = steps.max(1);
        let at = |i: usize| (self.time(i, steps + 1), self.camera_at(self.time(i, steps + 1), (1, 1)));
        let mut limits = MotionLimits { max_speed_mps: 0.0, max_turn_radps: 0.0 };
        for i in 0..steps {
            let ((t0, a), (t1, b)) = (at(i), at(i + 1));
            let dt = t1 - t0;
            if dt > 0.0 {
                let turn = a.forward().dot(b.forward()).clamp(-1.0, 1.0).acos();
                limits.max_speed_mps = limits.max_speed_mps.max((b.position_ecef - a.position_ecef).length() / dt);
                limits.max_turn_radps = limits.max_turn_radps.max(turn / dt);
            }
        }
        limits
    }

    fn camera_at(&self, t: f64, size: (u32, u32)) -> Camera {
        let k = self.at(t);
        Camera::looking(Geodetic::new(k.lon, k.lat, k.height_m), k.heading_deg, k.pitch_deg, self.fov_deg, size)
    }

    /// Unit direction to the sun (ECEF), if the path has one.
    pub fn sun_ecef(&self) -> Option<DVec3> {
        let k = self.key[0];
        Some(self.sun?.ecef(k.lon, k.lat))
    }
}

/// Lowest camera height a path may ask for, metres (below the Dead Sea
/// shore, the lowest dry land, with room for a mine).
pub const LOWEST_M: f64 = -1_000.0;
/// Highest, metres (beyond the geostationary orbit).
pub const HIGHEST_M: f64 = 100_000_000.0;

/// Largest key time, seconds (about 30 years).
const MAX_T_S: f64 = 1e9;
/// Largest key heading, degrees (a path may turn many times).
const MAX_HEADING_DEG: f64 = 1e6;

impl Key {
    /// Checks each value: the message names the field, what it must be and
    /// what it is.
    fn check(&self) -> Result<(), String> {
        // Times and headings bounded so that differences and the spline's
        // sums of them stay finite.
        let fields = [
            ("t", self.t, -MAX_T_S, MAX_T_S),
            ("lon", self.lon, -180.0, 180.0),
            ("lat", self.lat, -90.0, 90.0),
            ("height_m", self.height_m, LOWEST_M, HIGHEST_M),
            ("heading_deg", self.heading_deg, -MAX_HEADING_DEG, MAX_HEADING_DEG),
            ("pitch_deg", self.pitch_deg, -90.0, 90.0),
        ];
        for (name, value, lo, hi) in fields {
            if !(value.is_finite() && (lo..=hi).contains(&value)) {
                return Err(format!("{name} = {value}: must be within {lo}..{hi}"));
            }
        }
        Ok(())
    }
}

fn catmull_rom(p0: f64, p1: f64, p2: f64, p3: f64, u: f64) -> f64 {
    let (u2, u3) = (u * u, u * u * u);
    0.5 * (2.0 * p1 + (p2 - p0) * u + (2.0 * p0 - 5.0 * p1 + 4.0 * p2 - p3) * u2 + (3.0 * p1 - p0 - 3.0 * p2 + p3) * u3)
}

#[cfg(test)]
mod tests {
    use super::*;

    const PATH: &str = r#"
fov_deg = 50
sun = { azimuth_deg = 90.0, elevation_deg = 30.0 }
[[key]]
t = 0.0
lon = 10.0
lat = 46.0
height_m = 1000.0
heading_deg = 350.0
pitch_deg = -10.0
[[key]]
t = 2.0
lon = 10.2
lat = 46.1
height_m = 3000.0
heading_deg = 10.0
pitch_deg = -30.0
"#;

    #[test]
    fn motion_limits_bound_the_steps_of_the_path() {
        let p = CameraPath::parse(PATH).unwrap();
        let limits = p.motion_limits(40);
        // ~19 km and 2 km up in 2 s, turning 20° of heading and 20° of pitch.
        let chord = (p.camera(1, 2, (1, 1)).position_ecef - p.camera(0, 2, (1, 1)).position_ecef).length();
        assert!(limits.max_speed_mps >= chord / 2.0 && limits.max_speed_mps < 2.0 * chord / 2.0, "{limits:?}");
        let turn = p.camera(0, 2, (1, 1)).forward().angle_between(p.camera(1, 2, (1, 1)).forward());
        assert!(limits.max_turn_radps >= turn / 2.0 && limits.max_turn_radps < 3.0 * turn / 2.0, "{limits:?}");
    }

    #[test]
    fn keys_are_met_and_headings_turn_the_short_way() {
        let p = CameraPath::parse(PATH).unwrap();
        assert_eq!(p.at(0.0), p.key[0]);
        let end = p.at(2.0);
        assert!((end.lon - 10.2).abs() < 1e-12 && (end.height_m - 3000.0).abs() < 1e-9);
        let mid = p.at(1.0);
        assert!((mid.heading_deg - 360.0).abs() < 1e-9, "through north, not south: {}", mid.heading_deg);
        let sun = p.sun_ecef().unwrap();
        let east = globe::enu_basis(10.0, 46.0).x_axis;
        assert!((sun.dot(east) - 30f64.to_radians().cos()).abs() < 1e-12);
    }

    #[test]
    fn bad_paths_say_what_is_wrong() {
        assert!(CameraPath::parse("fov_deg = 60").unwrap_err().contains("key"));
        let backwards = PATH.replace("t = 2.0", "t = -1.0");
        assert!(CameraPath::parse(&backwards).unwrap_err().contains("not later"));
        let typo = PATH.replace("pitch_deg = -30.0", "pitch = -30.0");
        assert!(CameraPath::parse(&typo).is_err());
        let dark = PATH.replace("elevation_deg = 30.0", "elevation_deg = nan");
        let e = CameraPath::parse(&dark).unwrap_err();
        assert!(e.contains("elevation_deg = NaN }") && !e.contains("Sun {"), "as the file writes it: {e}");
        // Each value by name, its range and what it was.
        for (from, to, needle) in [
            ("lat = 46.0", "lat = 95.0", "key 1: lat = 95: must be within -90..90"),
            ("lon = 10.2", "lon = 500.0", "key 2: lon = 500: must be within -180..180"),
            ("height_m = 1000.0", "height_m = -5000.0", "key 1: height_m = -5000: must be within -1000..100000000"),
            ("t = 0.0", "t = inf", "key 1: t = inf: must be within -1000000000..1000000000"),
            // Regression: keys at ±1.7e308 s made the time step overflow.
            ("t = 0.0", "t = -1.7e308", "key 1: t = -170000000000000000"),
        ] {
            let e = CameraPath::parse(&PATH.replace(from, to)).unwrap_err();
            assert!(e.contains(needle), "{e}");
        }
    }

    #[test]
    fn longitudes_change_the_short_way_across_the_antimeridian() {
        let p = CameraPath::parse(&PATH.replace("lon = 10.0", "lon = 179.9").replace("lon = 10.2", "lon = -179.9"))
            .unwrap();
        let mid = p.at(1.0).lon;
        assert!(mid.abs() > 179.9 && mid.abs() <= 180.0, "over the antimeridian, not round the world: {mid}");
        assert_eq!(p.at(0.0).lon, 179.9);
        assert!((p.at(2.0).lon - -179.9).abs() < 1e-9, "keys are met: {}", p.at(2.0).lon);
        assert!(p.at(1.5).lon < -179.9, "{}", p.at(1.5).lon);
    }
}
