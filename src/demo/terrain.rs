//! The ground of Val Selva: one continuous height function of position, and
//! the water that belongs to the shape of the land (the lake, the river and
//! the side streams).
//!
//! Positions are metres in a local east/north frame: WGS 84 / UTM 32N
//! (the map sheet's own projection, conformal, so landforms keep their
//! shapes) less an origin near the region's centre. The origin is a multiple
//! of the node spacing, like the sheet's corner, so the sheet's pixel corners
//! fall on quarter nodes and the map interpolates with four fixed weight sets
//! ([`Patch::sub_grid`]). The landforms themselves are in `super::shape`.
//!
//! The terrain is defined on a world-anchored lattice of nodes [`NODE_M`]
//! apart: each node holds the shape, gullies cut down the shape's slope (the
//! slope taken from the neighbouring nodes) and the lake basin; between nodes
//! heights are interpolated bicubically (Catmull–Rom, so C¹: contours stay
//! smooth) and the other fields bilinearly. Why a lattice: a node costs about
//! 1 µs, mostly the mountain noise, and the gullies need the slope, which a
//! point function would have to get from two more evaluations. A [`Patch`]
//! evaluates each node once for a whole block (a 256² map block needs 4,900
//! nodes for its 67,000 pixel corners).
//!
//! Invariant: a node's values depend only on its indices, and interpolation
//! only on the 4 × 4 nodes around the point, so [`ground`] and every patch
//! that contains a point give it bitwise the same values; heights are
//! continuous; the lake is exactly flat at [`LAKE_LEVEL_M`].

use super::shape::{self, NO_STREAM_M};
use crate::raster::floor_i64;
use crate::source::Crs;

pub use super::shape::LAKE_LEVEL_M;

/// The frame's projection: WGS 84 / UTM zone 32N.
pub const FRAME_EPSG: u32 = 32632;
/// The frame's origin in UTM 32N, metres: the region's centre (10.125° E,
/// 46.375° N is E 586,520.7, N 5,136,328.8) rounded to whole nodes.
pub const ORIGIN_E_M: f64 = 586_520.0;
/// Northing of the frame's origin, metres.
pub const ORIGIN_N_M: f64 = 5_136_320.0;
/// Half the river's width, metres: 24 m of water is 2–3 map pixels of 10 m.
pub const RIVER_HALF_WIDTH_M: f64 = 12.0;
/// Node spacing, metres. The finest landform, the 230 m gullies, gets
/// almost six nodes per wavelength, where Catmull–Rom is within 3 % of the
/// sine; the 1″ DEM's pixels (21 m × 31 m) are of the same order.
pub const NODE_M: f64 = 40.0;

/// Everything known about the ground at one point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ground {
    /// Height of the ground or the lake surface, metres.
    pub height_m: f64,
    /// Depth of the lake here, metres: positive under water, negative (at
    /// most −1) on dry ground. Its zero line is the shore.
    pub lake_m: f64,
    /// Signed distance across the valley from the river's centre line, metres.
    pub river_m: f64,
    /// Signed distance from the nearest side stream, metres; 10⁶ where
    /// there is none.
    pub stream_m: f64,
    /// Position along the main valley (west → east), metres.
    pub along_m: f64,
    /// Signed distance across the main valley from its centre line (north
    /// positive), metres.
    pub across_m: f64,
}

/// Local frame position of a UTM 32N position.
pub fn local_from_utm(e_m: f64, n_m: f64) -> (f64, f64) {
    (e_m - ORIGIN_E_M, n_m - ORIGIN_N_M)
}

/// Ground height at a point given in degrees, metres; `utm` is
/// [`FRAME_EPSG`]. `None` where the projection fails.
pub fn height_at(utm: &Crs, lon_deg: f64, lat_deg: f64) -> Option<f64> {
    let (e, n) = utm.from_lon_lat(lon_deg, lat_deg)?;
    let (x, y) = local_from_utm(e, n);
    Some(ground(x, y).height_m)
}

/// The ground at local position `(x_m, y_m)` (about 40 µs: it evaluates the
/// 36 nodes around the point; use a [`Patch`] for many points).
pub fn ground(x_m: f64, y_m: f64) -> Ground {
    Patch::covering(x_m, y_m, x_m, y_m).ground(x_m, y_m)
}

/// What a node holds: the dry height before the lake is clamped, and the
/// fields interpolated bilinearly.
#[derive(Clone, Copy, Debug)]
struct Node {
    raw_m: f64,
    basin_m: f64,
    river_m: f64,
    stream_m: f64,
    along_m: f64,
    across_m: f64,
}

/// The nodes under a rectangle of the local frame.
pub struct Patch {
    i0: i64,
    j0: i64,
    cols: usize,
    nodes: Vec<Node>,
    /// Whether any node is in the lake basin (most patches are not, and
    /// skip its interpolation).
    basin: bool,
}

impl Patch {
    /// The nodes that points in `[x0, x1] × [y0, y1]` interpolate from.
    pub fn covering(x0_m: f64, y0_m: f64, x1_m: f64, y1_m: f64) -> Patch {
        // Catmull–Rom at t ∈ [i, i + 1) reads nodes i − 1 … i + 2.
        let (i0, i1) = (floor_i64(x0_m / NODE_M) - 1, floor_i64(x1_m / NODE_M) + 2);
        let (j0, j1) = (floor_i64(y0_m / NODE_M) - 1, floor_i64(y1_m / NODE_M) + 2);
        let (cols, rows) = ((i1 - i0 + 1) as usize, (j1 - j0 + 1) as usize);
        // Shapes with one more node on every side, for the slopes.
        let scols = cols + 2;
        let mut shapes = Vec::with_capacity(scols * (rows + 2));
        for j in j0 - 1..=j1 + 1 {
            for i in i0 - 1..=i1 + 1 {
                shapes.push(shape::shape(i as f64 * NODE_M, j as f64 * NODE_M));
            }
        }
        let mut nodes = Vec::with_capacity(cols * rows);
        for r in 0..rows {
            for c in 0..cols {
                let at = |dc: usize, dr: usize| &shapes[(r + dr) * scols + c + dc];
                let here = at(1, 1);
                let gx = (at(2, 1).dry_m - at(0, 1).dry_m) / (2.0 * NODE_M);
                let gy = (at(1, 2).dry_m - at(1, 0).dry_m) / (2.0 * NODE_M);
                let (x, y) = ((i0 + c as i64) as f64 * NODE_M, (j0 + r as i64) as f64 * NODE_M);
                nodes.push(node(x, y, here, gx, gy));
            }
        }
        let basin = nodes.iter().any(|n| n.basin_m > 0.0);
        Patch { i0, j0, cols, nodes, basin }
    }

    /// The ground at `(x_m, y_m)`, which must lie in the rectangle the patch
    /// was made for.
    pub fn ground(&self, x_m: f64, y_m: f64) -> Ground {
        let (c, wx) = self.weights(x_m / NODE_M, self.i0);
        let (r, wy) = self.weights(y_m / NODE_M, self.j0);
        let (raw, basin) = self.cubic(c, r, &wx, &wy);
        let (tx, ty) = (x_m / NODE_M - (self.i0 + c as i64 + 1) as f64, y_m / NODE_M - (self.j0 + r as i64 + 1) as f64);
        let corner = |dc: usize, dr: usize| &self.nodes[(r + 1 + dr) * self.cols + c + 1 + dc];
        let (a, b, d, e) = (corner(0, 0), corner(1, 0), corner(0, 1), corner(1, 1));
        let lerp = |f: fn(&Node) -> f64| {
            let top = f(a) + tx * (f(b) - f(a));
            let bottom = f(d) + tx * (f(e) - f(d));
            top + ty * (bottom - top)
        };
        let (height_m, lake_m) = clamp_lake(raw, basin);
        Ground {
            height_m,
            lake_m,
            river_m: lerp(|n| n.river_m),
            stream_m: lerp(|n| n.stream_m),
            along_m: lerp(|n| n.along_m),
            across_m: lerp(|n| n.across_m),
        }
    }

    /// The ground at the grid points `x = (qx0 + k)·NODE_M / 4`,
    /// `y = (qy0 − l)·NODE_M / 4` for `k < w`, `l < h` (quarter nodes, rows
    /// running south, as the sheet's pixel corners are), handed to
    /// `each(k, l, ground)` row by row. Separable: each node row is
    /// interpolated along x once for all columns, then each column along y,
    /// with the same operations in the same order as [`Patch::ground`], so
    /// the values are bitwise the same, at a fifth of the cost.
    pub fn sub_grid(&self, qx0: i64, qy0: i64, w: usize, h: usize, mut each: impl FnMut(usize, usize, &Ground)) {
        let quarter = |q: i64| q as f64 * NODE_M / 4.0 / NODE_M;
        let columns: Vec<(usize, [f64; 4], f64)> = (0..w as i64)
            .map(|k| {
                let t = quarter(qx0 + k);
                let (c, wx) = self.weights(t, self.i0);
                (c, wx, t - (self.i0 + c as i64 + 1) as f64)
            })
            .collect();
        let rows = self.nodes.len() / self.cols;
        // Node rows interpolated along x: raw, basin, river, stream, along, across.
        let mut along_x = vec![[0.0f64; 6]; rows * w];
        for r in 0..rows {
            let row = &self.nodes[r * self.cols..][..self.cols];
            for (k, (c, wx, tx)) in columns.iter().enumerate() {
                let n = &row[*c..][..4];
                let cubic =
                    |f: fn(&Node) -> f64| wx[0] * f(&n[0]) + wx[1] * f(&n[1]) + wx[2] * f(&n[2]) + wx[3] * f(&n[3]);
                let lerp = |f: fn(&Node) -> f64| f(&n[1]) + tx * (f(&n[2]) - f(&n[1]));
                along_x[r * w + k] = [
                    cubic(|n| n.raw_m),
                    if self.basin { cubic(|n| n.basin_m) } else { 0.0 },
                    lerp(|n| n.river_m),
                    lerp(|n| n.stream_m),
                    lerp(|n| n.along_m),
                    lerp(|n| n.across_m),
                ];
            }
        }
        for l in 0..h {
            let t = quarter(qy0 - l as i64);
            let (r, wy) = self.weights(t, self.j0);
            let ty = t - (self.j0 + r as i64 + 1) as f64;
            for k in 0..w {
                let v = |dr: usize| &along_x[(r + dr) * w + k];
                let (mut raw, mut basin) = (0.0, 0.0);
                for (dr, wyk) in wy.iter().enumerate() {
                    raw += wyk * v(dr)[0];
                    basin += wyk * v(dr)[1];
                }
                let lerp = |f: usize| v(1)[f] + ty * (v(2)[f] - v(1)[f]);
                let (height_m, lake_m) = clamp_lake(raw, basin);
                let g = Ground {
                    height_m,
                    lake_m,
                    river_m: lerp(2),
                    stream_m: lerp(3),
                    along_m: lerp(4),
                    across_m: lerp(5),
                };
                each(k, l, &g);
            }
        }
    }

    /// Height only (what the DEM needs), metres.
    pub fn height_m(&self, x_m: f64, y_m: f64) -> f64 {
        let (c, wx) = self.weights(x_m / NODE_M, self.i0);
        let (r, wy) = self.weights(y_m / NODE_M, self.j0);
        let (raw, basin) = self.cubic(c, r, &wx, &wy);
        clamp_lake(raw, basin).0
    }

    /// Raw height and basin depth, bicubic over the 4 × 4 nodes from `(c, r)`.
    fn cubic(&self, c: usize, r: usize, wx: &[f64; 4], wy: &[f64; 4]) -> (f64, f64) {
        let cubic = |f: fn(&Node) -> f64| {
            let mut sum = 0.0;
            for (k, wyk) in wy.iter().enumerate() {
                let row = &self.nodes[(r + k) * self.cols + c..][..4];
                sum += wyk * (wx[0] * f(&row[0]) + wx[1] * f(&row[1]) + wx[2] * f(&row[2]) + wx[3] * f(&row[3]));
            }
            sum
        };
        (cubic(|n| n.raw_m), if self.basin { cubic(|n| n.basin_m) } else { 0.0 })
    }

    /// First of the four nodes along one axis (relative to the patch) and
    /// their Catmull–Rom weights at lattice coordinate `t`.
    fn weights(&self, t: f64, first: i64) -> (usize, [f64; 4]) {
        let i = floor_i64(t);
        let f = t - i as f64;
        let (f2, f3) = (f * f, f * f * f);
        let w = [
            0.5 * (-f3 + 2.0 * f2 - f),
            0.5 * (3.0 * f3 - 5.0 * f2 + 2.0),
            0.5 * (-3.0 * f3 + 4.0 * f2 + f),
            0.5 * (f3 - f2),
        ];
        ((i - 1 - first) as usize, w)
    }
}

/// A node's values from its shape and the shape's slope.
fn node(x: f64, y: f64, here: &shape::Shape, gx: f64, gy: f64) -> Node {
    let (along, across) = (here.along_m, here.across_m);
    let basin_m = shape::lake_basin_m(x, y, along, across);
    let river_m = shape::river_m(along, across);
    Node {
        raw_m: here.dry_m + shape::gullies_m(x, y, gx, gy) - basin_m,
        basin_m,
        river_m,
        stream_m: shape::stream_m(x, y, across, river_m),
        along_m: along,
        across_m: across,
    }
}

/// Inside the basin the ground is the lake wherever it would be below the
/// lake level. Outside it, the dry ground is at least 1 m above the lake
/// (the basin's rim is kept above it), so both branches meet continuously.
fn clamp_lake(raw_m: f64, basin_m: f64) -> (f64, f64) {
    if basin_m > 0.0 {
        (raw_m.max(LAKE_LEVEL_M), LAKE_LEVEL_M - raw_m)
    } else {
        (raw_m, (LAKE_LEVEL_M - raw_m).min(-1.0))
    }
}

/// True when `stream_m` names a stream (not the no-stream marker).
pub fn has_stream(stream_m: f64) -> bool {
    stream_m.abs() < 0.5 * NO_STREAM_M
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_lake_is_flat_and_heights_are_continuous() {
        let (x, y) = shape::probe::lake_centre();
        let patch = Patch::covering(x, y, x, y + 4000.0);
        let g = patch.ground(x, y);
        assert_eq!(g.height_m, LAKE_LEVEL_M);
        assert!(g.lake_m > 50.0, "{g:?}");
        // Walk north out of the lake and up the wall: no jumps.
        let mut prev = g.height_m;
        for i in 1..4000 {
            let h = patch.ground(x, y + i as f64).height_m;
            assert!((h - prev).abs() < 5.0, "step at {i}: {prev} → {h}");
            prev = h;
        }
        assert!(prev > 1500.0, "{prev}");
    }

    #[test]
    fn patches_agree_with_each_other_bitwise() {
        let a = Patch::covering(-1000.0, -1000.0, 1000.0, 1000.0);
        let b = Patch::covering(-40.0, 300.0, 2000.0, 2000.0);
        for k in 0..500 {
            let (x, y) = (-40.0 + k as f64 * 2.07, 300.0 + k as f64 * 1.31);
            assert_eq!(a.ground(x, y), b.ground(x, y));
        }
        assert_eq!(a.ground(123.4, 567.8), ground(123.4, 567.8));
    }

    #[test]
    fn nodes_are_interpolated_exactly_at_nodes() {
        let p = Patch::covering(0.0, 0.0, 200.0, 200.0);
        let n = p.nodes[3 * p.cols + 2];
        let (x, y) = ((p.i0 + 2) as f64 * NODE_M, (p.j0 + 3) as f64 * NODE_M);
        assert_eq!(p.ground(x, y).height_m, clamp_lake(n.raw_m, n.basin_m).0);
    }

    #[test]
    fn the_sub_grid_is_the_point_interpolation() {
        let (qx0, qy0, w, h) = (-37, 901, 40, 30);
        let q = |v: i64| v as f64 * NODE_M / 4.0;
        let p = Patch::covering(q(qx0), q(qy0 - h as i64), q(qx0 + w as i64), q(qy0));
        let mut n = 0;
        p.sub_grid(qx0, qy0, w, h, |k, l, g| {
            assert_eq!(*g, p.ground(q(qx0 + k as i64), q(qy0 - l as i64)), "({k}, {l})");
            n += 1;
        });
        assert_eq!(n, w * h);
    }

    #[test]
    fn the_frame_is_centred_on_the_region() {
        let utm = Crs::from_epsg(FRAME_EPSG).unwrap();
        let (e, n) = utm.from_lon_lat(10.125, 46.375).unwrap();
        let (x, y) = local_from_utm(e, n);
        assert!(x.abs() < NODE_M && y.abs() < NODE_M, "{x} {y}");
        const { assert!(ORIGIN_E_M % NODE_M == 0.0 && ORIGIN_N_M % NODE_M == 0.0) };
        assert!(height_at(&utm, 10.125, 46.375).is_some_and(|h| (800.0..3000.0).contains(&h)));
    }
}
