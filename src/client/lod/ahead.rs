//! Where the next selection looks (001 §3.3 and §4.3): the flight's recent
//! cameras extrapolated linearly into the interval the selection will be
//! drawn in, and the conservative camera's cone around the current camera,
//! which culling uses instead of the current frustum.
//!
//! A selection started at `t` is drawn during `[t + τ, t + 2τ)`: one stage
//! selects while the previous cut is drawn ([`STAGES`]).

use super::super::camera::Camera;
use crate::lod::predict::{self, Cone, MotionLimits, PathPredictor, Pose};
use glam::{DMat3, DQuat};

/// Pipeline stages: selecting, then drawing.
pub const STAGES: u32 = 2;
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

/// The cameras a selection started at `t_s` from `current` is for (the
/// current one while nothing was observed), and the conservative cone.
pub fn ahead(predictor: &PathPredictor, current: &Camera, t_s: f64, look: &Lookahead) -> (Vec<Camera>, Cone) {
    let (from_s, to_s) = predict::target_interval(t_s, look.tau_s, STAGES);
    let mut cameras: Vec<Camera> =
        predictor.samples(from_s, to_s, SAMPLES).iter().map(|p| camera_at(current, p)).collect();
    if cameras.is_empty() {
        cameras.push(*current);
    }
    let half_diagonal_px = 0.5 * f64::from(current.width_px).hypot(f64::from(current.height_px));
    let fov_rad = 2.0 * (half_diagonal_px / current.focal_px()).atan();
    let cone = predict::conservative(&pose(current), fov_rad, look.tau_s, STAGES, &look.limits);
    (cameras, cone)
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

    #[test]
    fn poses_round_trip_and_cameras_are_extrapolated_along_the_path() {
        let c = camera(10.1);
        let back = camera_at(&c, &pose(&c));
        assert!((back.position_ecef - c.position_ecef).length() < 1e-9);
        assert!((back.rotation.z_axis - c.rotation.z_axis).length() < 1e-12);
        let mut predictor = PathPredictor::new(WINDOW);
        // Eastward at 0.001° of longitude (~77 m) per second.
        for k in 0..4 {
            predictor.observe(f64::from(k), pose(&camera(10.1 + 0.001 * f64::from(k))));
        }
        let (cameras, cone) = ahead(&predictor, &camera(10.103), 3.0, &LOOK);
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
    fn with_nothing_observed_the_current_camera_is_used() {
        let c = camera(10.2);
        let (cameras, _) = ahead(&PathPredictor::new(WINDOW), &c, 1.0, &LOOK);
        assert_eq!(cameras.len(), 1);
        assert_eq!(cameras[0].position_ecef, c.position_ecef);
    }
}
