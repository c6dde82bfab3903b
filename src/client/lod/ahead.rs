//! Where the next selection looks (001 §3.3 and §4.3): the flight's recent
//! cameras extrapolated linearly into the interval the selection will be
//! drawn in, and the conservative camera's cone around the current camera,
//! which culling uses instead of the current frustum.
//!
//! A selection started at `t` is drawn during `[t + τ, t + 2τ)`: one stage
//! selects while the previous cut is drawn. With geomorphing a cut that
//! coarsens is held a stage more while the tiles it replaces morph down,
//! so selections look to `[t + 2τ, t + 3τ)` ([`stages`], 001 §3.4).
//!
//! A predicted camera comes no nearer the ground than half the current
//! camera's height above it (the lowest ground known under each): linear
//! extrapolation of a dive passes under the ground, and a selection for a
//! camera that sees nothing drew one coarse tile for the frames after it.

use super::super::camera::Camera;
use super::super::globe::Geodetic;
use crate::lod::predict::{self, Cone, MotionLimits, PathPredictor, Pose};
use glam::{DMat3, DQuat};

/// Pipeline stages: selecting, morphing down with geomorphing, drawing.
pub fn stages(geomorph: bool) -> u32 {
    if geomorph { 3 } else { 2 }
}

/// Predicted cameras per selection (001 samples the interval).
pub const SAMPLES: usize = 3;
/// Poses the linear prediction is fitted to.
pub const WINDOW: usize = 4;

/// How far ahead selections look.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Lookahead {
    /// Time between selections `τ`, seconds of the flight.
    pub tau_s: f64,
    /// Bounds on the camera's motion, for the conservative camera.
    pub limits: MotionLimits,
}

/// The pose of `camera` (its rotation's columns are right, up, back).
pub fn pose(camera: &Camera) -> Pose {
    Pose { position_m: camera.position_ecef, orientation: DQuat::from_mat3(&camera.rotation).normalize() }
}

/// `template` moved to `pose`.
pub fn camera_at(template: &Camera, pose: &Pose) -> Camera {
    Camera { position_ecef: pose.position_m, rotation: DMat3::from_quat(pose.orientation), ..*template }
}

/// The lowest ground known at a longitude and latitude, degrees.
pub type Ground<'a> = &'a dyn Fn(f64, f64) -> Option<f64>;

/// The cameras a selection started at `t_s` from `current` is for (the
/// current one while nothing was observed), kept above `ground`, and the
/// conservative cone, with `stages` pipeline stages ([`stages`]).
pub fn ahead(
    predictor: &PathPredictor,
    current: &Camera,
    t_s: f64,
    stages: u32,
    look: &Lookahead,
    ground: Ground,
) -> (Vec<Camera>, Cone) {
    let (from_s, to_s) = predict::target_interval(t_s, look.tau_s, stages);
    let mut cameras: Vec<Camera> = predictor
        .samples(from_s, to_s, SAMPLES)
        .iter()
        .map(|p| above_ground(camera_at(current, p), current, ground))
        .collect();
    if cameras.is_empty() {
        cameras.push(*current);
    }
    let half_diagonal_px = 0.5 * f64::from(current.width_px).hypot(f64::from(current.height_px));
    let fov_rad = 2.0 * (half_diagonal_px / current.focal_px()).atan();
    let cone = predict::conservative(&pose(current), fov_rad, look.tau_s, stages, &look.limits);
    (cameras, cone)
}

/// `camera` raised where it is nearer the ground than half of `current`'s
/// height above it (see the module doc), never above `current`; as it is
/// where the ground under either is unknown, or `current` is not above the
/// lowest ground known under it (a coarse tile's lowest sample may lie
/// above a narrow valley's floor).
fn above_ground(camera: Camera, current: &Camera, ground: Ground) -> Camera {
    let (now, at) = (Geodetic::from_ecef(current.position_ecef), Geodetic::from_ecef(camera.position_ecef));
    let (Some(below_now), Some(below)) = (ground(now.lon_deg, now.lat_deg), ground(at.lon_deg, at.lat_deg)) else {
        return camera;
    };
    if now.height_m.partial_cmp(&below_now) != Some(std::cmp::Ordering::Greater) {
        return camera;
    }
    let lowest_m = (below + 0.5 * (now.height_m - below_now)).min(now.height_m);
    match at.height_m < lowest_m {
        true => Camera { position_ecef: Geodetic::new(at.lon_deg, at.lat_deg, lowest_m).to_ecef(), ..camera },
        false => camera,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::client::globe::Geodetic;

    const LOOK: Lookahead =
        Lookahead { tau_s: 0.5, limits: MotionLimits { max_speed_mps: 100.0, max_turn_radps: 0.2 } };

    fn camera(lon: f64) -> Camera {
        Camera::looking(Geodetic::new(lon, 46.35, 1500.0), 90.0, -10.0, 60.0, (160, 120))
    }

    /// Seen over 0 to 3 s flying east at 0.001° of longitude (~77 m) per
    /// second.
    fn eastward() -> PathPredictor {
        let mut predictor = PathPredictor::new(WINDOW);
        for k in 0..4 {
            predictor.observe(f64::from(k), pose(&camera(10.1 + 0.001 * f64::from(k))));
        }
        predictor
    }

    #[test]
    fn poses_round_trip_and_cameras_are_extrapolated_along_the_path() {
        let c = camera(10.1);
        let back = camera_at(&c, &pose(&c));
        assert!((back.position_ecef - c.position_ecef).length() < 1e-9);
        assert!((back.rotation.z_axis - c.rotation.z_axis).length() < 1e-12);
        let predictor = eastward();
        let (cameras, cone) = ahead(&predictor, &camera(10.103), 3.0, stages(false), &LOOK, &|_, _| Some(500.0));
        assert_eq!(cameras.len(), SAMPLES);
        // Drawn during [3.5, 4) s: the middle sample is at 3.75 s.
        let expected = camera(10.10375).position_ecef;
        assert!(
            (cameras[1].position_ecef - expected).length() < 1.0,
            "{}",
            (cameras[1].position_ecef - expected).length()
        );
        // The cone holds the current view and what lies just beside it.
        assert!(cone.half_angle_rad() > 0.5 * 60f64.to_radians());
        assert!(cone.contains(camera(10.103).position_ecef + camera(10.103).forward() * 1000.0));
    }

    #[test]
    fn geomorphing_selections_look_a_stage_further() {
        // A coarsening cut is held τ while its tiles morph down: selected
        // at 3 s, it is drawn during [4, 4.5) s, the middle sample at 4.25 s.
        let ahead_by = |n| ahead(&eastward(), &camera(10.103), 3.0, n, &LOOK, &|_, _| Some(500.0));
        let (cameras, cone) = ahead_by(stages(true));
        let off = (cameras[1].position_ecef - camera(10.10425).position_ecef).length();
        assert!(off < 1.0, "{off} m");
        assert!(cone.half_angle_rad() > ahead_by(stages(false)).1.half_angle_rad());
    }

    #[test]
    fn with_nothing_observed_the_current_camera_is_used() {
        let c = camera(10.2);
        let (cameras, _) = ahead(&PathPredictor::new(WINDOW), &c, 1.0, stages(false), &LOOK, &|_, _| None);
        assert_eq!(cameras.len(), 1);
        assert_eq!(cameras[0].position_ecef, c.position_ecef);
    }

    #[test]
    fn a_dive_is_predicted_no_nearer_the_ground_than_half_its_height_above_it() {
        // Down at 3,000 m/s: 1,000 m above the ground (500 m) at 3 s, under
        // it when drawn (3.5 to 4 s) as extrapolated.
        let dive =
            |t: f64| Camera::looking(Geodetic::new(10.1, 46.35, 10_500.0 - 3000.0 * t), 0.0, -60.0, 60.0, (160, 120));
        let mut predictor = PathPredictor::new(WINDOW);
        for k in 0..4 {
            predictor.observe(f64::from(k), pose(&dive(f64::from(k))));
        }
        let height = |c: &Camera| Geodetic::from_ecef(c.position_ecef).height_m;
        let (free, _) = ahead(&predictor, &dive(3.0), 3.0, stages(false), &LOOK, &|_, _| None);
        assert!(height(&free[1]) < 500.0, "unknown ground: as extrapolated, {}", height(&free[1]));
        let (kept, _) = ahead(&predictor, &dive(3.0), 3.0, stages(false), &LOOK, &|_, _| Some(500.0));
        for (k, c) in kept.iter().enumerate() {
            let h = height(c);
            assert!(h >= 500.0 + 0.5 * 1000.0 - 1e-6, "camera {k} at {h} m");
            assert!((c.rotation.z_axis - dive(3.0).rotation.z_axis).length() < 1e-9, "still looking the same way");
        }
        // A camera predicted above that is not moved.
        let (slow, _) = ahead(&predictor, &dive(3.0), 3.0, stages(false), &LOOK, &|_, _| Some(-100_000.0));
        assert_eq!(slow[1].position_ecef, free[1].position_ecef);
        // The ground under each counts, and the floor never lifts a camera
        // above the current one: flying east and down at 3,000 m/s from
        // 500 m above the ground (1,000 m) to where it is 1,500 m high,
        // the predictions are raised to the current camera's 1,500 m, not
        // to 1,500 + 250 m.
        let step = |lon: f64, _: f64| Some(if lon < 10.1 { 1000.0 } else { 1500.0 });
        let at = |lon: f64, h: f64| Camera::looking(Geodetic::new(lon, 46.35, h), 90.0, -30.0, 60.0, (160, 120));
        let mut east = PathPredictor::new(WINDOW);
        for k in 0..4 {
            let t = f64::from(k);
            east.observe(t, pose(&at(10.0985 + 0.0005 * t, 10_500.0 - 3000.0 * t)));
        }
        let (capped, _) = ahead(&east, &at(10.0999, 1500.0), 3.0, stages(false), &LOOK, &step);
        for c in &capped {
            let g = Geodetic::from_ecef(c.position_ecef);
            assert!(g.lon_deg > 10.1 && (g.height_m - 1500.0).abs() < 1e-6, "{g:?}");
        }
        // A camera below the lowest ground known under it: left as predicted.
        let (under, _) = ahead(&predictor, &dive(3.0), 3.0, stages(false), &LOOK, &|_, _| Some(1600.0));
        assert_eq!(under[1].position_ecef, free[1].position_ecef);
    }
}
