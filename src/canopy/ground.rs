//! Heights above ground for a point cloud: taken as they are when the cloud
//! is already normalised, otherwise measured against a ground model, the
//! Delaunay triangulation (TIN) of the ground returns (ASPRS class 2),
//! interpolated linearly in its triangles (as lidR's `tin()`).
//!
//! The normalisation rule: a cloud with at least [`MIN_GROUND`] ground
//! returns is normalised when their median |z| is under 0.5 m and their 95th
//! percentile |z| under 2 m (ground returns of a normalised cloud sit at 0);
//! a cloud with fewer is normalised when its lowest 1 % of points lie within
//! 2 m of 0, and otherwise cannot be used.
//!
//! Invariant: one TIN over all files of a cloud, so the ground model (and
//! with it the heights) is continuous across the files' seams.

use spade::{DelaunayTriangulation, FloatTriangulation, HasPosition, Point2, Triangulation};

/// Fewest ground returns that make a ground model.
pub const MIN_GROUND: usize = 10;

/// ASPRS class of ground returns.
pub const GROUND_CLASS: u8 = 2;

/// A ground return, relative to the model's origin.
#[derive(Clone, Copy, Debug)]
struct GroundPoint {
    position: Point2<f64>,
    z: f64,
}

impl HasPosition for GroundPoint {
    type Scalar = f64;
    fn position(&self) -> Point2<f64> {
        self.position
    }
}

/// The ground model: a TIN of the ground returns.
pub struct Ground {
    tin: DelaunayTriangulation<GroundPoint>,
    origin: (f64, f64),
}

impl Ground {
    /// The TIN of the points `indices` of `(x, y, z)`; `None` with fewer than
    /// [`MIN_GROUND`] usable points.
    pub fn new(x: &[f64], y: &[f64], z: &[f64], indices: &[usize]) -> Option<Ground> {
        let &first = indices.first()?;
        // Coordinates relative to a point of the cloud keep full precision.
        let origin = (x[first], y[first]);
        let points: Vec<GroundPoint> = indices
            .iter()
            .filter(|&&i| x[i].is_finite() && y[i].is_finite() && z[i].is_finite())
            .map(|&i| GroundPoint { position: Point2::new(x[i] - origin.0, y[i] - origin.1), z: z[i] })
            .collect();
        if points.len() < MIN_GROUND {
            return None;
        }
        let tin = DelaunayTriangulation::bulk_load(points).ok()?;
        (tin.num_inner_faces() > 0).then_some(Ground { tin, origin })
    }

    /// The ground height at `(x, y)`; `None` outside the ground returns'
    /// convex hull.
    pub fn height(&self, x: f64, y: f64) -> Option<f64> {
        let p = Point2::new(x - self.origin.0, y - self.origin.1);
        self.tin.barycentric().interpolate(|v| v.data().z, p)
    }
}

/// Whether a cloud is normalised by the rule above: `ground_z` are the
/// heights of its ground returns, `all_z` of all its points; `None` when it
/// is not normalised and has no ground model.
pub fn is_normalised(ground_z: &[f64], all_z: &[f64]) -> Option<bool> {
    if ground_z.len() >= MIN_GROUND {
        let abs: Vec<f64> = ground_z.iter().map(|z| z.abs()).collect();
        return Some(quantile(&abs, 0.5) < 0.5 && quantile(&abs, 0.95) < 2.0);
    }
    (!all_z.is_empty() && quantile(all_z, 0.01).abs() < 2.0).then_some(true)
}

/// The `q` quantile of `values` (nearest rank); NaN for none.
pub fn quantile(values: &[f64], q: f64) -> f64 {
    let mut v: Vec<f64> = values.iter().copied().filter(|v| !v.is_nan()).collect();
    if v.is_empty() {
        return f64::NAN;
    }
    let k = ((q.clamp(0.0, 1.0) * (v.len() - 1) as f64).round() as usize).min(v.len() - 1);
    *v.select_nth_unstable_by(k, f64::total_cmp).1
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_tin_reproduces_a_plane_and_ends_at_the_hull() {
        // Ground on the plane z = 300 + 0.1 x − 0.05 y, sampled on a jittered grid.
        let (mut x, mut y, mut z) = (vec![], vec![], vec![]);
        for i in 0..400 {
            let (px, py) = (5e5 + (i % 20) as f64 * 2.0 + 0.3 * ((i * 7) % 3) as f64, 6e6 + (i / 20) as f64 * 2.0);
            x.push(px);
            y.push(py);
            z.push(300.0 + 0.1 * (px - 5e5) - 0.05 * (py - 6e6));
        }
        let idx: Vec<usize> = (0..400).collect();
        let g = Ground::new(&x, &y, &z, &idx).unwrap();
        let h = g.height(5e5 + 17.3, 6e6 + 21.1).unwrap();
        assert!((h - (300.0 + 1.73 - 1.055)).abs() < 1e-9, "{h}");
        assert_eq!(g.height(5e5 - 10.0, 6e6), None);
        assert!(Ground::new(&x, &y, &z, &idx[..5]).is_none());
    }

    #[test]
    fn normalisation_is_recognised_by_the_ground_returns() {
        assert_eq!(is_normalised(&[0.0; 20], &[0.0, 20.0]), Some(true));
        assert_eq!(is_normalised(&[805.0; 20], &[805.0, 830.0]), Some(false));
        assert_eq!(is_normalised(&[], &[0.1, 5.0, 30.0]), Some(true));
        assert_eq!(is_normalised(&[], &[325.0, 360.0]), None);
    }
}
