//! Where the camera will be (001 §3.3 and §4.3): linear path prediction and
//! the conservative camera, pure math over poses (glam `DVec3`/`DQuat`,
//! metres in a local frame; the camera looks down −Z with +Y up).
//!
//! Selection started at `t` is drawn during `[t + (s−1)τ, t + sτ)` with `s`
//! pipeline stages (2 without geomorphing, 3 with it). Its benefit is the
//! mean over cameras predicted for that interval plus `λ` times the benefit
//! for the conservative camera ([`blend`]); its cost is the largest
//! predicted. Prediction is linear (001: quadratic fits oscillate when
//! extrapolated): a least-squares line through the last few positions,
//! view directions and up vectors.
//!
//! The conservative camera contains every view cone reachable within `sτ`
//! at speed ≤ `θ` and turn rate ≤ `ω`: field of view `fov + 2sτω`, apex
//! `sτθ / sin(fov/2 + sτω)` behind the eye (001 Figure 3). Beyond a
//! half-angle of 90° the union of reachable cones is no longer a cone, and
//! the conservative camera sees everything.
//!
//! Invariant: predictions are finite unit-quaternion poses for any input
//! (no samples: none; one sample, or all at one time: that pose).

use glam::{DQuat, DVec3};
use std::collections::VecDeque;

/// A camera pose.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pose {
    /// Eye position, metres.
    pub position_m: DVec3,
    /// Orientation (camera −Z is the view direction, +Y up).
    pub orientation: DQuat,
}

impl Pose {
    /// The view direction.
    pub fn forward(&self) -> DVec3 {
        self.orientation * DVec3::NEG_Z
    }

    /// The up vector.
    pub fn up(&self) -> DVec3 {
        self.orientation * DVec3::Y
    }

    /// The pose at `position_m` looking along `forward` with `up` roughly
    /// up (falls back to any perpendicular up when they are parallel).
    pub fn looking(position_m: DVec3, forward: DVec3, up: DVec3) -> Pose {
        let f = forward.try_normalize().unwrap_or(DVec3::NEG_Z);
        let side = f.cross(up).try_normalize().unwrap_or_else(|| f.any_orthonormal_vector());
        let u = side.cross(f);
        let orientation = DQuat::from_mat3(&glam::DMat3::from_cols(side, u, -f)).normalize();
        Pose { position_m, orientation }
    }
}

/// Linear extrapolation of recent poses.
#[derive(Clone, Debug)]
pub struct PathPredictor {
    window: usize,
    samples: VecDeque<(f64, Pose)>,
}

impl PathPredictor {
    /// Fits lines through the last `window` poses (at least 2).
    pub fn new(window: usize) -> PathPredictor {
        PathPredictor { window: window.max(2), samples: VecDeque::new() }
    }

    /// Records the pose at time `t_s` (non-finite times are ignored).
    pub fn observe(&mut self, t_s: f64, pose: Pose) {
        if !t_s.is_finite() || !pose.position_m.is_finite() || !pose.orientation.is_finite() {
            return;
        }
        self.samples.push_back((t_s, pose));
        while self.samples.len() > self.window {
            self.samples.pop_front();
        }
    }

    /// The predicted pose at `t_s`.
    pub fn predict(&self, t_s: f64) -> Option<Pose> {
        let (t0, last) = *self.samples.back()?;
        let fit = |f: &dyn Fn(&Pose) -> DVec3| -> DVec3 {
            let n = self.samples.len() as f64;
            let mean_t = self.samples.iter().map(|s| s.0 - t0).sum::<f64>() / n;
            let mean_v = self.samples.iter().map(|s| f(&s.1)).sum::<DVec3>() / n;
            let var: f64 = self.samples.iter().map(|s| (s.0 - t0 - mean_t).powi(2)).sum();
            if var.partial_cmp(&1e-18) != Some(std::cmp::Ordering::Greater) || !t_s.is_finite() {
                return f(&last);
            }
            let cov: DVec3 = self.samples.iter().map(|s| (s.0 - t0 - mean_t) * (f(&s.1) - mean_v)).sum();
            mean_v + cov / var * (t_s - t0 - mean_t)
        };
        let position = fit(&|p: &Pose| p.position_m);
        let forward = fit(&|p: &Pose| p.forward());
        let up = fit(&|p: &Pose| p.up());
        let pose = Pose::looking(position, forward, up);
        Some(if pose.position_m.is_finite() && pose.orientation.is_finite() { pose } else { last })
    }

    /// `k` predicted poses spread over `[from_s, to_s)` (interval midpoints).
    pub fn samples(&self, from_s: f64, to_s: f64, k: usize) -> Vec<Pose> {
        (0..k).filter_map(|i| self.predict(from_s + (to_s - from_s) * (i as f64 + 0.5) / k as f64)).collect()
    }
}

/// The interval the selection started at `t_s` is drawn in, with `stages`
/// pipeline stages of `tau_s` seconds.
pub fn target_interval(t_s: f64, tau_s: f64, stages: u32) -> (f64, f64) {
    let s = f64::from(stages.max(1));
    (t_s + (s - 1.0) * tau_s, t_s + s * tau_s)
}

/// Bounds on the camera's motion.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MotionLimits {
    /// Largest speed `θ`, m/s.
    pub max_speed_mps: f64,
    /// Largest turn rate `ω`, rad/s.
    pub max_turn_radps: f64,
}

/// A view cone: apex, axis and half-angle (with its sine and cosine, as the
/// tests against it run for every node a selection looks at).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Cone {
    apex_m: DVec3,
    axis: DVec3,
    half_angle_rad: f64,
    sin_half: f64,
    cos_half: f64,
}

impl Cone {
    /// The cone at `apex_m` (metres) around the unit `axis`, of
    /// `half_angle_rad` (π: everything).
    pub fn new(apex_m: DVec3, axis: DVec3, half_angle_rad: f64) -> Cone {
        let (sin_half, cos_half) = half_angle_rad.sin_cos();
        Cone { apex_m, axis, half_angle_rad, sin_half, cos_half }
    }

    /// Apex, metres.
    pub fn apex_m(&self) -> DVec3 {
        self.apex_m
    }

    /// Half-angle, radians.
    pub fn half_angle_rad(&self) -> f64 {
        self.half_angle_rad
    }

    /// Whether `point_m` is inside.
    pub fn contains(&self, point_m: DVec3) -> bool {
        let v = point_m - self.apex_m;
        let len = v.length();
        if self.half_angle_rad >= std::f64::consts::PI || len == 0.0 {
            return true;
        }
        v.dot(self.axis) >= len * self.cos_half - 1e-9 * len
    }

    /// Whether the sphere at `center_m` of `radius_m` meets the cone: the
    /// angle off the axis to its centre is at most the half-angle plus the
    /// angle the sphere subtends, `asin(r/d)`, compared by cosines.
    pub fn meets_sphere(&self, center_m: DVec3, radius_m: f64) -> bool {
        let v = center_m - self.apex_m;
        let d = v.length();
        if d <= radius_m || self.half_angle_rad >= std::f64::consts::PI {
            return true;
        }
        let s = radius_m.max(0.0) / d;
        // half + asin(s) reaches π: the cone and the sphere cover every direction.
        if self.cos_half <= 0.0 && s >= self.sin_half {
            return true;
        }
        v.dot(self.axis) >= d * (self.cos_half * (1.0 - s * s).sqrt() - self.sin_half * s)
    }
}

/// 001's conservative camera for `pose` with full field of view `fov_rad`
/// (the cone around the view frustum), after `stages · tau_s` seconds.
pub fn conservative(pose: &Pose, fov_rad: f64, tau_s: f64, stages: u32, limits: &MotionLimits) -> Cone {
    use std::f64::consts::{FRAC_PI_2, PI};
    let horizon = f64::from(stages.max(1)) * tau_s.max(0.0);
    let turn = horizon * limits.max_turn_radps.max(0.0);
    let reach = horizon * limits.max_speed_mps.max(0.0);
    let half = 0.5 * fov_rad.clamp(0.0, 2.0 * PI) + turn;
    // Wider than a half-space the union is no longer a cone: see everything.
    let half = if half.is_finite() && half <= FRAC_PI_2 { half } else { PI };
    let pull = if half >= PI { 0.0 } else { reach / half.sin().max(1e-12) };
    let apex = pose.position_m - pose.forward() * if pull.is_finite() { pull } else { 0.0 };
    Cone::new(apex, pose.forward(), half)
}

/// 001's estimated benefit: the mean over the predicted cameras plus `λ`
/// times the conservative camera's.
pub fn blend(predicted: &[f64], conservative: f64, lambda: f64) -> f64 {
    let finite = |x: f64| if x.is_finite() { x } else { 0.0 };
    let mean = if predicted.is_empty() {
        0.0
    } else {
        predicted.iter().map(|&b| finite(b)).sum::<f64>() / predicted.len() as f64
    };
    mean + finite(lambda).max(0.0) * finite(conservative)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn pose(p: DVec3, f: DVec3) -> Pose {
        Pose::looking(p, f, DVec3::Z)
    }

    proptest! {
        #[test]
        fn a_sphere_meets_the_cone_as_the_angles_say(
            (x, y, z) in (-1.0f64..1.0, -1.0f64..1.0, -1.0f64..1.0),
            distance in 1.0f64..1000.0,
            radius in 0.0f64..500.0,
            half in 0.01f64..3.1,
        ) {
            let dir = DVec3::new(x, y, z);
            prop_assume!(dir.length() > 1e-3);
            let cone = Cone::new(DVec3::new(5.0, -3.0, 2.0), DVec3::new(0.6, 0.0, 0.8), half);
            let center = cone.apex_m() + dir.normalize() * distance;
            let off_axis = dir.normalize().dot(DVec3::new(0.6, 0.0, 0.8)).clamp(-1.0, 1.0).acos();
            let by_angles = distance <= radius || off_axis - (radius / distance).min(1.0).asin() <= half;
            let margin = off_axis - (radius / distance).min(1.0).asin() - half;
            prop_assume!(distance <= radius || margin.abs() > 1e-9);
            prop_assert_eq!(cone.meets_sphere(center, radius), by_angles);
        }
    }

    #[test]
    fn a_straight_flight_is_extrapolated_exactly() {
        let mut pred = PathPredictor::new(5);
        for k in 0..8 {
            let t = f64::from(k) * 0.05;
            pred.observe(t, pose(DVec3::new(100.0 * t, 3.0, 500.0 - 10.0 * t), DVec3::new(1.0, 0.0, -0.2)));
        }
        let p = pred.predict(1.35).unwrap();
        assert!(p.position_m.distance(DVec3::new(135.0, 3.0, 486.5)) < 1e-9);
        assert!(p.forward().angle_between(DVec3::new(1.0, 0.0, -0.2)) < 1e-9);
        assert_eq!(pred.samples(1.0, 1.5, 4).len(), 4);
    }

    #[test]
    fn a_turn_is_extrapolated_linearly_and_stays_a_pose() {
        let mut pred = PathPredictor::new(4);
        for k in 0..4 {
            let a = f64::from(k) * 0.1;
            pred.observe(f64::from(k), pose(DVec3::ZERO, DVec3::new(a.cos(), a.sin(), 0.0)));
        }
        let p = pred.predict(10.0).unwrap();
        assert!((p.orientation.length() - 1.0).abs() < 1e-12);
        assert!(p.forward().y > 0.5, "keeps turning the same way");
    }

    #[test]
    fn degenerate_histories() {
        let mut pred = PathPredictor::new(3);
        assert!(pred.predict(1.0).is_none());
        let p = pose(DVec3::ONE, DVec3::X);
        pred.observe(2.0, p);
        pred.observe(2.0, p);
        pred.observe(f64::NAN, pose(DVec3::ZERO, DVec3::Y));
        assert_eq!(pred.predict(9.0), Some(p));
        assert!(pred.predict(f64::INFINITY).is_some_and(|q| q.position_m.is_finite()));
        let up = Pose::looking(DVec3::ZERO, DVec3::Z, DVec3::Z);
        assert!(up.orientation.is_finite() && up.forward().distance(DVec3::Z) < 1e-12);
    }

    proptest! {
        #[test]
        fn the_conservative_camera_holds_every_reachable_view(
            fov in 0.3f64..2.0, tau in 0.05f64..1.0, stages in 2u32..4,
            speed in 0.0f64..300.0, turn in 0.0f64..1.5,
            heading in 0.0f64..6.3, pitch in -1.2f64..1.2,
            moved in (0.0f64..1.0, -1.0f64..1.0, -1.0f64..1.0, -1.0f64..1.0),
            rot in (0.0f64..1.0, -1.0f64..1.0, -1.0f64..1.0, -1.0f64..1.0),
            point in (0.0f64..1.0, 0.0f64..6.3, 1.0f64..20_000.0),
        ) {
            let limits = MotionLimits { max_speed_mps: speed, max_turn_radps: turn };
            let dir = DVec3::new(pitch.cos() * heading.cos(), pitch.cos() * heading.sin(), pitch.sin());
            let now = pose(DVec3::new(10.0, -20.0, 300.0), dir);
            let cone = conservative(&now, fov, tau, stages, &limits);
            let horizon = f64::from(stages) * tau;
            // A camera reachable within the horizon...
            let offset = DVec3::new(moved.1, moved.2, moved.3).try_normalize().unwrap_or(DVec3::X) * moved.0 * speed * horizon;
            let axis = DVec3::new(rot.1, rot.2, rot.3).try_normalize().unwrap_or(DVec3::Y);
            let turned = DQuat::from_axis_angle(axis, rot.0 * turn * horizon) * dir;
            // ... and a point in its view cone.
            let side = turned.any_orthonormal_vector();
            let ray = DQuat::from_axis_angle(turned, point.1) * (DQuat::from_axis_angle(side, point.0 * fov / 2.0) * turned);
            let p = now.position_m + offset + ray * point.2;
            prop_assert!(cone.contains(p), "{p:?} outside {cone:?}");
        }
    }

    #[test]
    fn wide_or_fast_cameras_see_everything_or_stay_finite() {
        let now = pose(DVec3::ZERO, DVec3::X);
        let fast = MotionLimits { max_speed_mps: 1e9, max_turn_radps: 100.0 };
        let c = conservative(&now, 1.0, 1.0, 3, &fast);
        assert_eq!(c.half_angle_rad(), std::f64::consts::PI);
        assert!(c.contains(DVec3::new(-1e6, 0.0, 0.0)));
        let none =
            conservative(&now, f64::NAN, f64::NAN, 3, &MotionLimits { max_speed_mps: f64::NAN, max_turn_radps: 0.0 });
        assert!(none.apex_m().is_finite() && none.half_angle_rad().is_finite());
        assert_eq!(blend(&[1.0, 3.0, f64::NAN], 4.0, 0.5), 4.0 / 3.0 + 2.0);
        assert_eq!(blend(&[], 4.0, 0.25), 1.0);
    }
}
