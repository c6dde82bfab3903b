//! A tile's hull: the coarse, closed mesh whose fragments start the rays
//! (dissertation 6.4, "Choice of Rendering Primitives").
//!
//! The top is a `(K + 1)²` vertex grid over the cast range (samples −1 to N)
//! with quads of ~16 samples. Each top vertex carries two hull heights — the
//! maximum ground and the maximum CEM over the cells of the quads around
//! it. The vertex shader places the hull
//! at `ground_max + f·(cem_max − ground_max)` for a canopy fade `f ∈ [0, 1]`,
//! which bounds `ground + f·canopy` over those cells (a convex combination
//! of two bounds); triangles interpolate vertices that all bound their quad,
//! so the hull never dips below the surface. Vertical skirts down to below
//! the lowest ground and a bottom face close it: a ray that meets the
//! surface inside the tile first crosses a front face of the hull, and a
//! camera inside sees its back faces.
//!
//! Faces wind counter-clockwise seen from outside.

use crate::raster::Raster;

/// Samples per hull quad side (about; quads split the cast range evenly).
pub const QUAD_SAMPLES: usize = 16;

/// One hull vertex, as the GPU reads it.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct HullVertex {
    /// Sample coordinates `(i, j)`, east and north.
    pub sample: [f32; 2],
    /// Hull heights: maximum ground, maximum CEM (local metres).
    pub hull_m: [f32; 2],
}

/// The mesh of one tile.
#[derive(Clone, Debug)]
pub struct Hull {
    /// Vertices: the top grid, then the bottom ring.
    pub vertices: Vec<HullVertex>,
    /// Triangles.
    pub indices: Vec<u32>,
    /// Quads per side of the top grid, `K`.
    pub quads: usize,
    /// Height of the skirts' lower edge and the bottom face (local metres).
    pub bottom_m: f32,
}

impl Hull {
    /// The hull of a tile's cast range: `cem` holds the highest CEM, `ground`
    /// the highest and the lowest ground each sample takes (the same raster
    /// twice unless the tile morphs between two surfaces), samples −1 ..= N
    /// on both axes, row 0 at the south, NaN for nodata.
    pub fn build(cem: &Raster<f32>, ground: (&Raster<f32>, &Raster<f32>)) -> Hull {
        let (dem, lowest) = ground;
        let cells = cem.width() - 1;
        let k = cells.div_ceil(QUAD_SAMPLES).max(1);
        let pos: Vec<f64> = (0..=k).map(|a| a as f64 * cells as f64 / k as f64).collect();
        let bottom_m = lowest.min_max().map_or(0.0, |(lo, _)| lo - 1.0);
        let quad_max = |layer: &Raster<f32>, a: usize, b: usize| {
            let (x0, x1) = (pos[a].floor() as usize, (pos[a + 1].ceil() as usize).min(cells));
            let (y0, y1) = (pos[b].floor() as usize, (pos[b + 1].ceil() as usize).min(cells));
            (y0..=y1).flat_map(|y| layer.row(y)[x0..=x1].iter().copied()).fold(f32::NAN, f32::max)
        };
        let around = |layer: &Raster<f32>, a: usize, b: usize| {
            let m = around_vertex(k, a, b, |qa, qb| quad_max(layer, qa, qb));
            if m.is_nan() { bottom_m } else { m }
        };
        let top = (0..=k).flat_map(|b| (0..=k).map(move |a| (a, b))).map(|(a, b)| HullVertex {
            sample: [(pos[a] - 1.0) as f32, (pos[b] - 1.0) as f32],
            hull_m: [around(dem, a, b), around(cem, a, b).max(around(dem, a, b))],
        });
        closed(top.collect(), k, bottom_m)
    }

    /// The side of its largest quad, in samples.
    pub fn quad_samples(&self) -> f32 {
        let row = &self.vertices[..=self.quads];
        row.windows(2).map(|w| w[1].sample[0] - w[0].sample[0]).fold(0.0, f32::max)
    }

    /// The same hull with quads `factor` times as large (the last row and
    /// column of quads take what is left): a corner bounds the larger quads
    /// around it by the highest of their vertices, each of which already
    /// bounds the quads around it, so the coarse hull still encloses the
    /// surface. For rasterisers that pay per triangle (software ones shade
    /// whole pixel blocks along every triangle's edges).
    pub fn coarsened(&self, factor: usize) -> Hull {
        if factor <= 1 {
            return self.clone();
        }
        let k = self.quads;
        let mut lines: Vec<usize> = (0..k).step_by(factor).collect();
        lines.push(k);
        let kc = lines.len() - 1;
        let fine = |a: usize, b: usize| self.vertices[b * (k + 1) + a];
        let quad_max = |layer: usize, qa: usize, qb: usize| {
            let rows = lines[qb]..=lines[qb + 1];
            rows.flat_map(|b| (lines[qa]..=lines[qa + 1]).map(move |a| (a, b)))
                .map(|(a, b)| fine(a, b).hull_m[layer])
                .fold(f32::NAN, f32::max)
        };
        let top = (0..=kc).flat_map(|cb| (0..=kc).map(move |ca| (ca, cb))).map(|(ca, cb)| HullVertex {
            sample: fine(lines[ca], lines[cb]).sample,
            hull_m: [0, 1].map(|layer| around_vertex(kc, ca, cb, |qa, qb| quad_max(layer, qa, qb))),
        });
        closed(top.collect(), kc, self.bottom_m)
    }
}

/// The highest `quad_max` of the quads of a `k × k` grid around top vertex
/// `(a, b)` (up to four); NaN if none has data.
fn around_vertex(k: usize, a: usize, b: usize, quad_max: impl Fn(usize, usize) -> f32) -> f32 {
    [(a.wrapping_sub(1), b.wrapping_sub(1)), (a, b.wrapping_sub(1)), (a.wrapping_sub(1), b), (a, b)]
        .into_iter()
        .filter(|&(qa, qb)| qa < k && qb < k)
        .map(|(qa, qb)| quad_max(qa, qb))
        .fold(f32::NAN, f32::max)
}

/// A hull from its `(k + 1)²` top grid: skirts down to `bottom_m` and the
/// bottom face close it.
fn closed(mut vertices: Vec<HullVertex>, k: usize, bottom_m: f32) -> Hull {
    let ring = ring(k);
    let top_count = vertices.len() as u32;
    vertices.reserve(ring.len());
    for &(a, b) in &ring {
        let v = vertices[b * (k + 1) + a];
        vertices.push(HullVertex { sample: v.sample, hull_m: [bottom_m; 2] });
    }
    let indices = indices(k, &ring, top_count, true);
    Hull { vertices, indices, quads: k, bottom_m }
}

/// Top-grid positions `(a, b)` around the boundary, counter-clockwise seen
/// from above, starting at the south-west corner.
pub(super) fn ring(k: usize) -> Vec<(usize, usize)> {
    let south = (0..k).map(|a| (a, 0));
    let east = (0..k).map(|b| (k, b));
    let north = (0..k).map(|a| (k - a, k));
    let west = (0..k).map(|b| (0, k - b));
    south.chain(east).chain(north).chain(west).collect()
}

/// Triangles of a `(k + 1)²` top grid, the skirts down to the ring of
/// vertices from `top_count` on, and, if asked, the bottom face.
pub(super) fn indices(k: usize, ring: &[(usize, usize)], top_count: u32, bottom: bool) -> Vec<u32> {
    let top = |a: usize, b: usize| (b * (k + 1) + a) as u32;
    let mut out = Vec::with_capacity(6 * (k * k + ring.len() + 1));
    for b in 0..k {
        for a in 0..k {
            let (v00, v10, v11, v01) = (top(a, b), top(a + 1, b), top(a + 1, b + 1), top(a, b + 1));
            out.extend([v00, v10, v11, v00, v11, v01]);
        }
    }
    let n = ring.len();
    for p in 0..n {
        let q = (p + 1) % n;
        let (tp, tq) = (top(ring[p].0, ring[p].1), top(ring[q].0, ring[q].1));
        let (bp, bq) = (top_count + p as u32, top_count + q as u32);
        out.extend([tp, bp, bq, tp, bq, tq]);
    }
    if bottom {
        // The bottom face, seen from below.
        let corner = |c: usize| top_count + (c * k) as u32;
        out.extend([corner(0), corner(2), corner(1), corner(0), corner(3), corner(2)]);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    fn bumpy(n: usize) -> (Raster<f32>, Raster<f32>) {
        let dem = Raster::from_fn(n, n, |x, y| (x as f32 * 0.7).sin() * 30.0 + (y as f32 * 0.3).cos() * 50.0);
        let cem = Raster::from_fn(n, n, |x, y| dem.get(x, y) + if (x / 5 + y / 7) % 2 == 0 { 25.0 } else { 0.0 });
        (cem, dem)
    }

    fn position(v: &HullVertex, f: f32) -> Vec3 {
        Vec3::new(v.sample[0], v.sample[1], v.hull_m[0] + f * (v.hull_m[1] - v.hull_m[0]))
    }

    /// The hull of a bumpy 67² tile (5 quads a side), and coarsened by 3
    /// (2 quads a side, the second narrower).
    fn hulls() -> ((Raster<f32>, Raster<f32>), [Hull; 2]) {
        let (cem, dem) = bumpy(67);
        let hull = Hull::build(&cem, (&dem, &dem));
        let coarse = hull.coarsened(3);
        assert_eq!((hull.quads, coarse.quads), (5, 2));
        assert!((hull.quad_samples() - 13.2).abs() < 1e-4 && (coarse.quad_samples() - 39.6).abs() < 1e-4);
        ((cem, dem), [hull, coarse])
    }

    #[test]
    fn faces_point_outward() {
        for hull in hulls().1 {
            let centre = Vec3::new(32.0, 32.0, hull.bottom_m + 1.0);
            for t in hull.indices.chunks(3) {
                let [p, q, r] = [0, 1, 2].map(|i| position(&hull.vertices[t[i] as usize], 1.0));
                let normal = (q - p).cross(r - p);
                let mid = (p + q + r) / 3.0;
                assert!(normal.dot(mid - centre) > 0.0, "triangle {t:?} faces inward");
            }
        }
    }

    #[test]
    fn the_hull_bounds_the_surface_for_any_fade() {
        let ((cem, dem), hulls) = hulls();
        for hull in hulls {
            bounds_the_surface(&hull, &cem, &dem);
        }
    }

    fn bounds_the_surface(hull: &Hull, cem: &Raster<f32>, dem: &Raster<f32>) {
        let k = hull.quads;
        for f in [0.0f32, 0.3, 1.0] {
            for t in hull.indices.chunks(3).take(2 * k * k) {
                let [p, q, r] = [0, 1, 2].map(|i| position(&hull.vertices[t[i] as usize], f));
                // Every sample under the triangle lies below it.
                for y in 0..cem.height() {
                    for x in 0..cem.width() {
                        let s = Vec3::new(x as f32 - 1.0, y as f32 - 1.0, 0.0);
                        if let Some(z) = plane_z(p, q, r, s) {
                            let surface = dem.get(x, y) + f * (cem.get(x, y) - dem.get(x, y));
                            assert!(z >= surface - 1e-3, "hull {z} under surface {surface} at {x},{y}");
                        }
                    }
                }
            }
        }
    }

    /// The triangle's height above `s` if `s` is inside it.
    fn plane_z(p: Vec3, q: Vec3, r: Vec3, s: Vec3) -> Option<f32> {
        let d = (q.x - p.x) * (r.y - p.y) - (r.x - p.x) * (q.y - p.y);
        let u = ((s.x - p.x) * (r.y - p.y) - (r.x - p.x) * (s.y - p.y)) / d;
        let v = ((q.x - p.x) * (s.y - p.y) - (s.x - p.x) * (q.y - p.y)) / d;
        (u >= -1e-6 && v >= -1e-6 && u + v <= 1.0 + 1e-6).then_some(p.z + u * (q.z - p.z) + v * (r.z - p.z))
    }
}
