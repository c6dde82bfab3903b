//! The camera: an ECEF position and orientation in `f64`, a pinhole with a
//! vertical field of view, and what the GPU needs from it — a reversed-Z
//! infinite projection and, per tile, a camera-relative model-view matrix
//! computed in `f64` and only then rounded to `f32`, so deep zoom does not
//! jitter.
//!
//! Camera space follows wgpu/GL: x right, y up, the camera looks down −z.
//! Depth is `near / distance along the view axis` (1 at the near plane, 0 at
//! infinity), which keeps float depth precise from millimetres to orbit.

use super::frame::TileFrame;
use super::globe::{self, Geodetic};
use glam::{DMat3, DMat4, DVec3, Mat4};

/// A pinhole camera on the globe.
#[derive(Clone, Copy, Debug)]
pub struct Camera {
    /// Eye position, ECEF metres.
    pub position_ecef: DVec3,
    /// Camera → ECEF rotation: columns right, up, back (the view is −back).
    pub rotation: DMat3,
    /// Vertical field of view, radians.
    pub fov_y_rad: f64,
    /// Image width, pixels.
    pub width_px: u32,
    /// Image height, pixels.
    pub height_px: u32,
    /// Near plane distance, metres.
    pub near_m: f64,
}

impl Camera {
    /// A camera at `eye` looking along `heading_deg` (clockwise from north)
    /// and `pitch_deg` (above the horizon; −90 looks straight down).
    pub fn looking(eye: Geodetic, heading_deg: f64, pitch_deg: f64, fov_y_deg: f64, size: (u32, u32)) -> Camera {
        let enu = globe::enu_basis(eye.lon_deg, eye.lat_deg);
        let (sh, ch) = heading_deg.to_radians().sin_cos();
        let (sp, cp) = pitch_deg.to_radians().sin_cos();
        let forward = enu * DVec3::new(cp * sh, cp * ch, sp);
        let right = enu * DVec3::new(ch, -sh, 0.0);
        let up = right.cross(forward);
        Camera {
            position_ecef: eye.to_ecef(),
            rotation: DMat3::from_cols(right, up, -forward),
            fov_y_rad: fov_y_deg.to_radians(),
            width_px: size.0.max(1),
            height_px: size.1.max(1),
            near_m: NEAR_M,
        }
    }

    /// The unit view direction, ECEF.
    pub fn forward(&self) -> DVec3 {
        -self.rotation.z_axis
    }

    /// Focal length in pixels (vertical).
    pub fn focal_px(&self) -> f64 {
        self.height_px as f64 / 2.0 / (self.fov_y_rad / 2.0).tan()
    }

    /// The unit direction (ECEF) of the ray through the centre of pixel
    /// `(x, y)`, row 0 at the top.
    pub fn ray_dir(&self, x: u32, y: u32) -> DVec3 {
        let f = self.focal_px();
        let cx = x as f64 + 0.5 - self.width_px as f64 / 2.0;
        let cy = self.height_px as f64 / 2.0 - (y as f64 + 0.5);
        (self.rotation * DVec3::new(cx / f, cy / f, -1.0)).normalize()
    }

    /// The reversed-Z infinite perspective projection.
    pub fn projection(&self) -> Mat4 {
        let f = 1.0 / (self.fov_y_rad / 2.0).tan();
        let aspect = self.width_px as f64 / self.height_px as f64;
        let m = DMat4::from_cols_array(&[
            f / aspect,
            0.0,
            0.0,
            0.0, //
            0.0,
            f,
            0.0,
            0.0, //
            0.0,
            0.0,
            0.0,
            -1.0, //
            0.0,
            0.0,
            self.near_m,
            0.0,
        ]);
        m.as_mat4()
    }

    /// Tile-local → camera-space transform, built in `f64` from the
    /// difference of two ECEF positions before rounding.
    pub fn model_view(&self, frame: &TileFrame) -> Mat4 {
        let to_cam = self.rotation.transpose();
        let rot = to_cam * frame.basis;
        let t = to_cam * (frame.origin_ecef - self.position_ecef);
        DMat4::from_cols(rot.x_axis.extend(0.0), rot.y_axis.extend(0.0), rot.z_axis.extend(0.0), t.extend(1.0))
            .as_mat4()
    }

    /// Depth-buffer value of a point at `distance_m` along the view axis.
    pub fn depth_of(&self, view_z_m: f64) -> f64 {
        self.near_m / view_z_m
    }

    /// Distance along the view axis of a depth-buffer value.
    pub fn view_z_of(&self, depth: f64) -> f64 {
        self.near_m / depth
    }

    /// Distance of an ECEF point along the view axis.
    pub fn view_z(&self, p_ecef: DVec3) -> f64 {
        (p_ecef - self.position_ecef).dot(self.forward())
    }

    /// The four side planes of the view frustum as inward normals through
    /// the eye (ECEF directions): a point `p` is outside a plane when
    /// `n · (p − eye) < 0`. The near plane is left out (a tile behind the
    /// eye is outside the side planes or touches the eye).
    pub fn side_planes(&self) -> [DVec3; 4] {
        let f = self.focal_px();
        let hx = self.width_px as f64 / 2.0 / f;
        let hy = self.height_px as f64 / 2.0 / f;
        let (r, u, back) = (self.rotation.x_axis, self.rotation.y_axis, self.rotation.z_axis);
        let fwd = -back;
        [
            (fwd + r * hx).cross(u).normalize() * -1.0,
            (fwd - r * hx).cross(u).normalize(),
            (fwd + u * hy).cross(r).normalize(),
            (fwd - u * hy).cross(r).normalize() * -1.0,
        ]
    }
}

/// The near plane, metres. Reversed-Z float depth (`near / z`) keeps a
/// relative precision of 2⁻²³ at any distance, so a near plane this close
/// costs nothing: a camera 1 cm above a level-22 tile still sees it.
pub const NEAR_M: f64 = 1e-3;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::TileGrid;

    fn cam() -> Camera {
        Camera::looking(Geodetic::new(10.2, 46.4, 3000.0), 30.0, -20.0, 60.0, (320, 200))
    }

    #[test]
    fn the_centre_ray_is_the_view_direction_and_heading_is_clockwise_from_north() {
        let c = Camera::looking(Geodetic::new(10.2, 46.4, 3000.0), 90.0, 0.0, 60.0, (320, 200));
        let enu = globe::enu_basis(10.2, 46.4);
        assert!((c.forward() - enu.x_axis).length() < 1e-12, "heading 90 looks east");
        let mid = (c.ray_dir(159, 99) + c.ray_dir(160, 100)).normalize();
        assert!((mid - c.forward()).length() < 1e-12);
    }

    #[test]
    fn projection_puts_pixel_rays_on_their_pixels() {
        let c = cam();
        let g = TileGrid::new(36.0, 513).unwrap();
        let frame = TileFrame::new(&g, g.tile_containing(10.2, 46.4, 10));
        let mvp = c.projection().as_dmat4() * c.model_view(&frame).as_dmat4();
        for (x, y) in [(0, 0), (319, 199), (100, 50)] {
            let p = c.position_ecef + c.ray_dir(x, y) * 2500.0;
            let clip = mvp * frame.to_local(p).extend(1.0);
            let ndc = clip.truncate() / clip.w;
            let px = ((ndc.x + 1.0) / 2.0 * 320.0, (1.0 - ndc.y) / 2.0 * 200.0);
            assert!((px.0 - (x as f64 + 0.5)).abs() < 1e-3 && (px.1 - (y as f64 + 0.5)).abs() < 1e-3, "{px:?}");
            assert!((ndc.z - c.depth_of(c.view_z(p))).abs() < 1e-6);
        }
    }

    #[test]
    fn side_planes_hug_the_view() {
        let c = cam();
        let planes = c.side_planes();
        for n in planes {
            assert!(n.dot(c.forward()) > 0.0);
            for (x, y) in [(0, 0), (319, 199), (0, 199), (319, 0)] {
                assert!(n.dot(c.ray_dir(x, y)) > 0.0);
            }
        }
        // A ray two pixels beyond each edge is outside.
        let f = c.focal_px();
        for (cx, cy) in [(162.0, 0.0), (-162.0, 0.0), (0.0, 102.0), (0.0, -102.0)] {
            let outside = c.rotation * DVec3::new(cx / f, cy / f, -1.0);
            assert!(planes.iter().any(|n| n.dot(outside) < 0.0), "({cx}, {cy})");
        }
    }
}
