//! The exact CPU ray caster: the ground truth the GPU and its accelerated
//! variants are measured against (`../shared/DESIGN.md`, "Client").
//!
//! Every pixel's ray is intersected in `f64` with every tile's
//! piecewise-bilinear surface ([`super::raycast`]): a 2-D walk over 16-cell
//! blocks, then over the cells of each block the ray dips into, skipping
//! those whose maximum (the mipmap's) it passes above, and solving the
//! ray–patch quadratic exactly in each remaining cell. No step size, no
//! iteration limit: a ray misses only if it misses the surface.

use super::camera::Camera;
use super::raycast::{self, Fade, SKY, TileView};
use super::tile::TileData;
use glam::{DVec2, DVec3};
use rayon::prelude::*;

/// Rendered buffers, row 0 at the top.
#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    /// Width, pixels.
    pub width: u32,
    /// Height, pixels.
    pub height: u32,
    /// sRGB colour with alpha 255.
    pub colour: Vec<[u8; 4]>,
    /// Distance along the view axis of the surface, metres (0: no hit).
    pub view_z_m: Vec<f32>,
}

impl Image {
    /// Whether pixel `k` shows the surface.
    pub fn hit(&self, k: usize) -> bool {
        self.view_z_m[k] > 0.0
    }
}

/// What the reference needs to know about lighting and fading.
#[derive(Clone, Copy, Debug)]
pub struct Lighting {
    /// Unit direction to the sun, ECEF; `None` turns the sun off.
    pub sun_ecef: Option<DVec3>,
    /// Shadow samples per hit.
    pub shadow_steps: u32,
    /// Canopy fade.
    pub fade: Fade,
}

/// A hit: ray parameter (metres), sample position and local height.
#[derive(Clone, Copy, Debug)]
pub struct Hit {
    /// Distance along the ray, metres.
    pub t_m: f64,
    /// Sample coordinates.
    pub sample: DVec2,
    /// Local height.
    pub z_m: f64,
}

/// Renders `tiles` from `camera`.
pub fn render(camera: &Camera, tiles: &[TileData], lighting: &Lighting) -> Image {
    render_with_steps(camera, tiles, lighting, &vec![lighting.shadow_steps; tiles.len()])
}

/// Renders `tiles` from `camera`, tile `k` with `shadow_steps[k]` shadow
/// samples per hit (the renderer's per-tile quality; missing entries take
/// the lighting's).
pub fn render_with_steps(camera: &Camera, tiles: &[TileData], lighting: &Lighting, shadow_steps: &[u32]) -> Image {
    let views: Vec<TileView> = tiles
        .iter()
        .enumerate()
        .map(|(k, t)| TileView {
            shadow_steps: shadow_steps.get(k).copied().unwrap_or(lighting.shadow_steps),
            ..view_of(camera, t, lighting)
        })
        .collect();
    let (w, h) = (camera.width_px, camera.height_px);
    let pixels: Vec<([u8; 4], f32)> = (0..w * h)
        .into_par_iter()
        .map(|k| {
            let dir = camera.ray_dir(k % w, k / w);
            let t_near = camera.near_m / dir.dot(camera.forward());
            let best = views
                .iter()
                .filter_map(|v| {
                    let o = v.tile.frame.to_local(camera.position_ecef);
                    let d = v.tile.frame.basis.transpose() * dir;
                    intersect(v, o, d, t_near, f64::INFINITY).map(|hit| (hit, v, d))
                })
                .min_by(|a, b| a.0.t_m.total_cmp(&b.0.t_m));
            match best {
                Some((hit, v, d)) => {
                    let c = raycast::shade(v, hit.sample, hit.z_m, d);
                    (rgba(c), (hit.t_m * dir.dot(camera.forward())) as f32)
                }
                None => (rgba(SKY), 0.0),
            }
        })
        .collect();
    Image {
        width: w,
        height: h,
        colour: pixels.iter().map(|p| p.0).collect(),
        view_z_m: pixels.iter().map(|p| p.1).collect(),
    }
}

/// A tile's view for this camera.
pub fn view_of<'a>(camera: &Camera, tile: &'a TileData, lighting: &Lighting) -> TileView<'a> {
    let to_local = tile.frame.basis.transpose();
    TileView {
        tile,
        camera_m: tile.frame.to_local(camera.position_ecef),
        sun: lighting.sun_ecef.map(|s| to_local * s),
        fade: lighting.fade,
        shadow_steps: lighting.shadow_steps,
    }
}

/// Colour channels in [0, 1] to RGBA bytes.
pub fn rgba(c: [f64; 3]) -> [u8; 4] {
    let b = c.map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u8);
    [b[0], b[1], b[2], 255]
}

/// The first hit of the ray `o + t·d` (local metres, `d` unit) with the
/// tile's surface for `t ∈ [t_min, t_max]`.
pub fn intersect(view: &TileView, o: DVec3, d: DVec3, t_min: f64, t_max: f64) -> Option<Hit> {
    let tile = view.tile;
    let sp = tile.frame.spacing_m;
    let c = tile.frame.centre_index();
    // The ray in sample coordinates (per metre of t).
    let os = DVec3::new(o.x / sp.x + c, o.y / sp.y + c, o.z);
    let ds = DVec3::new(d.x / sp.x, d.y / sp.y, d.z);
    let n = tile.frame.samples as f64;
    let (lo, hi) = (DVec3::new(-1.0, -1.0, tile.range.min_m as f64), DVec3::new(n, n, tile.range.max_m as f64));
    let (t0, t1) = slab(os, ds, lo, hi)?;
    let (t0, t1) = (t0.max(t_min), t1.min(t_max));
    if t0 > t1 {
        return None;
    }
    let block_level = 4.min(tile.mip.levels() - 1);
    let block = (1usize << block_level) as f64;
    let cells = tile.frame.samples as i64 + 1;
    let blocks = (cells + (1 << block_level) - 1) >> block_level;
    let z = |t: f64| os.z + ds.z * t;
    walk(os.truncate(), ds.truncate(), t0, t1, block, blocks, |bx, by, ta, tb| {
        if z(ta).min(z(tb)) > tile.mip.bound(block_level, bx as usize, by as usize) as f64 {
            return None;
        }
        walk(os.truncate(), ds.truncate(), ta, tb, 1.0, cells, |mx, my, ua, ub| {
            if z(ua).min(z(ub)) > tile.mip.bound(0, mx as usize, my as usize) as f64 {
                return None;
            }
            let h = view.cell(mx - 1, my - 1)?;
            let s0 = os.truncate() + ds.truncate() * ua;
            let f = DVec2::new(s0.x - (mx - 1) as f64, s0.y - (my - 1) as f64);
            let tau = patch_hit(h, f, ds, z(ua), ub - ua)?;
            let t = ua + tau;
            Some(Hit { t_m: t, sample: os.truncate() + ds.truncate() * t, z_m: z(t) })
        })
    })
}

/// The ray's parameter interval inside the box `[lo, hi]`.
fn slab(o: DVec3, d: DVec3, lo: DVec3, hi: DVec3) -> Option<(f64, f64)> {
    let (mut t0, mut t1) = (f64::NEG_INFINITY, f64::INFINITY);
    for a in 0..3 {
        if d[a] == 0.0 {
            if o[a] < lo[a] || o[a] > hi[a] {
                return None;
            }
            continue;
        }
        let (ta, tb) = ((lo[a] - o[a]) / d[a], (hi[a] - o[a]) / d[a]);
        t0 = t0.max(ta.min(tb));
        t1 = t1.min(ta.max(tb));
    }
    (t0 <= t1).then_some((t0, t1))
}

/// Visits, in ray order, the cells of side `size` (cell `m` spans samples
/// `m·size − 1 .. (m+1)·size − 1`, `m < count` on both axes) that the 2-D
/// ray `o + t·d` crosses for `t ∈ [t0, t1]`, until `visit` returns a value.
fn walk<R>(
    o: DVec2,
    d: DVec2,
    t0: f64,
    t1: f64,
    size: f64,
    count: i64,
    mut visit: impl FnMut(i64, i64, f64, f64) -> Option<R>,
) -> Option<R> {
    let start = o + d * t0;
    let cell = |v: f64| (((v + 1.0) / size).floor() as i64).clamp(0, count - 1);
    let (mut cx, mut cy) = (cell(start.x), cell(start.y));
    let next = |c: i64, o: f64, d: f64| {
        if d > 0.0 {
            (((c + 1) as f64 * size - 1.0 - o) / d, 1)
        } else if d < 0.0 {
            ((c as f64 * size - 1.0 - o) / d, -1)
        } else {
            (f64::INFINITY, 0)
        }
    };
    let mut t = t0;
    while t <= t1 {
        let (tx, sx) = next(cx, o.x, d.x);
        let (ty, sy) = next(cy, o.y, d.y);
        let t_out = tx.min(ty).min(t1);
        if let Some(r) = visit(cx, cy, t, t_out) {
            return Some(r);
        }
        if t_out >= t1 {
            break;
        }
        if tx <= ty {
            cx += sx;
        } else {
            cy += sy;
        }
        if !(0..count).contains(&cx) || !(0..count).contains(&cy) {
            break;
        }
        t = t_out;
    }
    None
}

/// The first `τ ∈ [0, len]` where the ray, at fraction `f` of its cell and
/// height `z0` at `τ = 0`, moving `d` (cells and metres per metre), is at or
/// below the bilinear patch `h`: the smallest root of a quadratic.
pub fn patch_hit(h: [f64; 4], f: DVec2, d: DVec3, z0: f64, len: f64) -> Option<f64> {
    let e = h[0] - h[1] - h[2] + h[3];
    let (hx, hy) = (h[1] - h[0], h[2] - h[0]);
    let c = raycast::bilinear(h, f.x, f.y) - z0;
    if c >= 0.0 {
        return Some(0.0);
    }
    let b = hx * d.x + hy * d.y + e * (f.x * d.y + f.y * d.x) - d.z;
    let a = e * d.x * d.y;
    let g = |tau: f64| (a * tau + b) * tau + c;
    let root = smallest_root(a, b, c, len);
    match root {
        Some(tau) => Some(tau),
        // Rounding may hide a root that the end point shows.
        None if g(len) >= 0.0 => Some(len * -c / (g(len) - c)),
        None => None,
    }
}

/// The smallest root in `[0, len]` of `a·τ² + b·τ + c` with `c < 0`.
fn smallest_root(a: f64, b: f64, c: f64, len: f64) -> Option<f64> {
    let inside = |r: f64| (0.0..=len).contains(&r).then_some(r);
    // Linear where the quadratic term is negligible over the cell.
    if (a * len).abs() <= 1e-12 * b.abs().max(1e-300) {
        return if b > 0.0 { inside(-c / b) } else { None };
    }
    let disc = b * b - 4.0 * a * c;
    if disc < 0.0 {
        return None;
    }
    let q = -0.5 * (b + b.signum() * disc.sqrt());
    let (r1, r2) = (q / a, if q != 0.0 { c / q } else { f64::INFINITY });
    let (lo, hi) = (r1.min(r2), r1.max(r2));
    inside(lo).or_else(|| inside(hi))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn patch_hits_are_exact() {
        // A plane h = 10 + 2x (per cell), ray going down from z = 20.
        let h = [10.0, 12.0, 10.0, 12.0];
        let d = DVec3::new(0.5, 0.0, -1.0).normalize();
        let tau = patch_hit(h, DVec2::ZERO, d, 20.0, 10.0).unwrap();
        let (x, z) = (d.x * tau, 20.0 + d.z * tau);
        assert!((z - (10.0 + 2.0 * x)).abs() < 1e-12);
        // A saddle: the ray passes above the low diagonal.
        let saddle = [0.0, 10.0, 10.0, 0.0];
        let diag = DVec3::new(1.0, 1.0, 0.0).normalize();
        assert!(patch_hit(saddle, DVec2::ZERO, diag, 0.5, 2f64.sqrt()).is_some(), "starts below the first corner");
        assert!(
            patch_hit(saddle, DVec2::new(0.0, 0.0), diag, 5.1, 1.4).is_none(),
            "above the saddle's top (5 at the centre)"
        );
    }

    #[test]
    fn the_walk_visits_every_cell_in_order() {
        let mut seen = Vec::new();
        walk(DVec2::new(-0.5, -0.5), DVec2::new(1.0, 0.5), 0.0, 10.0, 1.0, 20, |x, y, a: f64, b: f64| {
            seen.push((x, y, a, b));
            None::<()>
        });
        assert_eq!(seen.first().map(|s| (s.0, s.1)), Some((0, 0)));
        for w in seen.windows(2) {
            assert_eq!(w[0].3, w[1].2, "contiguous");
            assert_eq!((w[1].0 - w[0].0) + (w[1].1 - w[0].1), 1, "4-connected");
        }
        assert_eq!(seen.last().map(|s| s.3), Some(10.0));
    }
}

/// How an image departs from the reference.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Departure {
    /// Pixels compared.
    pub pixels: usize,
    /// Pixels the reference hits and the image does not.
    pub misses: usize,
    /// Pixels the image hits and the reference does not.
    pub extras: usize,
    /// Root-mean-square relative depth error over pixels both hit.
    pub depth_rms_rel: f64,
    /// Largest relative depth error over pixels both hit.
    pub depth_max_rel: f64,
    /// Colour PSNR over pixels both hit, dB (infinite when identical).
    pub psnr_db: f64,
}

impl Departure {
    /// Share of pixels whose hit differs.
    pub fn mismatch_share(&self) -> f64 {
        (self.misses + self.extras) as f64 / self.pixels.max(1) as f64
    }
}

/// Compares an image (colour, view distance per pixel, 0 = no hit) with the
/// reference.
pub fn compare(colour: &[[u8; 4]], view_z_m: &[f32], reference: &Image) -> Departure {
    let mut d = Departure { pixels: reference.view_z_m.len(), ..Default::default() };
    let (mut sq_depth, mut sq_colour, mut both) = (0.0, 0.0, 0usize);
    for (k, &z_ref) in reference.view_z_m.iter().enumerate() {
        let z = view_z_m.get(k).copied().unwrap_or(0.0);
        match (z_ref > 0.0, z > 0.0) {
            (true, false) => d.misses += 1,
            (false, true) => d.extras += 1,
            (false, false) => {}
            (true, true) => {
                both += 1;
                let rel = ((z - z_ref) / z_ref).abs() as f64;
                sq_depth += rel * rel;
                d.depth_max_rel = d.depth_max_rel.max(rel);
                let (a, b) = (colour.get(k).copied().unwrap_or([0; 4]), reference.colour[k]);
                sq_colour += (0..3).map(|c| (a[c] as f64 - b[c] as f64).powi(2)).sum::<f64>() / 3.0;
            }
        }
    }
    let n = both.max(1) as f64;
    d.depth_rms_rel = (sq_depth / n).sqrt();
    let mse = sq_colour / n;
    d.psnr_db = if mse == 0.0 { f64::INFINITY } else { 10.0 * (255.0f64 * 255.0 / mse).log10() };
    d
}
