//! The ray-casting model both ray casters implement — the CPU reference in
//! `f64` here and in [`super::reference`], the GPU in
//! `shaders/raycast.wgsl` — so that their images can be compared pixel by
//! pixel.
//!
//! - **Surface.** Per cell, the bilinear patch of its four corner samples
//!   `h = ground + f·(cem − ground)`, where `f ∈ [0, 1]` fades the canopy
//!   with distance ([`Fade`]; dissertation 6.4: "progressively reducing the
//!   vertical offset and thickness of the rendered vegetation according to
//!   the view distance"). `f` is evaluated per corner sample, from the
//!   distance of the sample's ground point to the camera, so neighbouring
//!   tiles agree on shared samples. Near the camera, where trees are drawn
//!   as point splats ([`super::trees`]), `f` also takes the canopy's share
//!   of the splat blend ([`TreeBlend`]), so the trees replace the canopy
//!   rather than stand in it.
//! - **Shadows** (6.4, "Illumination Calculation"): from the hit toward the
//!   sun (from the surface above it where the ray entered the tile's box
//!   through a side below the surface), `n` samples at horizontal distances
//!   growing linearly step by step up to the tile's halo; each sample below
//!   the surface adds an occlusion that shrinks with its index, so near
//!   occluders cast darker shadows. Occlusion ramps over [`SHADOW_SOFT_M`]
//!   of penetration (a soft edge).
//! - **Shading by surface type** (6.4, "Other Surface Types"): the map
//!   colour lit by ambient plus sun; forest tinted and lit mostly by its
//!   shadowing (the dissertation found diffuse-only canopies "plastic");
//!   water mixes in the sky by Fresnel's term, with a sun glint.
//!
//! Units: sample coordinates `(i, j)` east/north, heights and ray
//! parameters in local metres.

use super::tile::{NODATA_M, TileData};
use crate::cem::surface::SurfaceType;
use glam::{DVec2, DVec3};

/// Colour of rays that hit nothing.
pub const SKY: [f64; 3] = [0.62, 0.74, 0.88];
/// Light that reaches shadowed ground.
pub const AMBIENT: f64 = 0.4;
/// Occlusion of the first shadow sample fully under the surface; sample `k`
/// weighs `SHADOW_WEIGHT / k`.
pub const SHADOW_WEIGHT: f64 = 0.6;
/// Penetration below the surface over which a shadow sample goes from no
/// occlusion to full, metres.
pub const SHADOW_SOFT_M: f64 = 2.0;
/// Tint of lit canopy.
pub const CANOPY_TINT: [f64; 3] = [0.80, 0.92, 0.74];
/// Water is flat: where the surface normal leans further than this from
/// the vertical (cosine of 15°), a water class is a misclassified shadow
/// (dark north slopes key as lakes on Landsat images) and is shaded as
/// ground.
pub const WATER_MIN_NORMAL_Z: f64 = 0.966;

/// How rays find the surface.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Traversal {
    /// Exact hierarchical traversal of the maximum mipmap.
    Exact,
    /// The dissertation's fixed-step march with 4- and 32-sample safety
    /// zones, giving up after this many steps.
    Linear(u32),
}

/// The canopy fade: full canopy where a canopy of `canopy_ref_m` looks at
/// least `hi_px` tall, none below `lo_px`; and near the camera, the share
/// that trees drawn as splats leave to the canopy.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Fade {
    /// The camera's focal length, pixels.
    pub focal_px: f64,
    /// Reference canopy height, metres.
    pub canopy_ref_m: f64,
    /// Projected height below which the canopy is gone, pixels.
    pub lo_px: f64,
    /// Projected height above which the canopy is whole, pixels.
    pub hi_px: f64,
    /// Trees drawn as splats near the camera.
    pub trees: TreeBlend,
}

impl Fade {
    /// A fade that keeps the canopy whole at any distance.
    pub const NONE: Fade = Fade { focal_px: 1.0, canopy_ref_m: 1.0, lo_px: -2.0, hi_px: -1.0, trees: TreeBlend::NONE };

    /// The canopy factor at `distance_m` from the camera: the far fade
    /// times the canopy's share of the tree blend.
    pub fn factor(&self, distance_m: f64) -> f64 {
        self.far_factor(distance_m) * self.trees.canopy(distance_m)
    }

    /// The far fade alone, which never grows with distance (so the nearest
    /// distance bounds it over a tile).
    pub fn far_factor(&self, distance_m: f64) -> f64 {
        let px = self.canopy_ref_m * self.focal_px / distance_m.max(1e-9);
        smoothstep(self.lo_px, self.hi_px, px)
    }

    /// Whether the canopy is whole, unfaded, over distances from `near_m`
    /// to `far_m`: the far fade shrinks with distance, so the far end
    /// tells, and the trees' splats leave it whole ([`TreeBlend::canopy_whole`]).
    pub fn whole(&self, near_m: f64, far_m: f64) -> bool {
        self.far_factor(far_m) >= 1.0 && self.trees.canopy_whole(near_m, far_m)
    }

    /// The distance beyond which the canopy is gone.
    pub fn end_m(&self) -> f64 {
        if self.lo_px <= 0.0 { f64::INFINITY } else { self.canopy_ref_m * self.focal_px / self.lo_px }
    }
}

/// Knots of a [`TreeBlend`]'s drawn share, evenly spaced from the camera
/// to the end of its blend band.
pub const DRAWN_KNOTS: usize = 16;

/// Where trees drawn as point splats take over from the ray-cast canopy
/// (issue 7, 000 §5): splats inside `range_m − band_m / 2`, canopy beyond
/// `range_m + band_m / 2`, shares summing to 1 between
/// ([`crate::lod::splats::canopy_blend`]) where every tree is drawn.
///
/// Under a splat budget some trees get no splat: the canopy gives way only
/// by the share of trees drawn at each distance (`drawn`), so a sparse
/// stand of splats stands in a lowered canopy, not over bare ground. The
/// share is a function of distance alone, like the blend, so neighbouring
/// tiles agree on every shared sample.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TreeBlend {
    /// Distance of the middle of the blend band, metres (0: no trees).
    pub range_m: f64,
    /// Width of the band, metres.
    pub band_m: f64,
    /// Share of the trees in view that have a splat, at knot `k`'s
    /// distance `k · reach / (DRAWN_KNOTS − 1)` (reach: the band's end),
    /// linear between knots.
    pub drawn: [f64; DRAWN_KNOTS],
}

impl Default for TreeBlend {
    fn default() -> TreeBlend {
        TreeBlend::NONE
    }
}

impl TreeBlend {
    /// No trees: the canopy everywhere.
    pub const NONE: TreeBlend = TreeBlend::every_tree(0.0, 0.0);

    /// A blend over `band_m` around `range_m` in which every tree is drawn.
    pub const fn every_tree(range_m: f64, band_m: f64) -> TreeBlend {
        TreeBlend { range_m, band_m, drawn: [1.0; DRAWN_KNOTS] }
    }

    /// Splat opacity and canopy share at `distance_m` from the camera.
    pub fn shares(&self, distance_m: f64) -> (f64, f64) {
        if self.range_m > 0.0 {
            crate::lod::splats::canopy_blend(distance_m, self.range_m, self.band_m)
        } else {
            (0.0, 1.0)
        }
    }

    /// The canopy's share at `distance_m`: what the splats of the trees
    /// drawn there leave to it.
    pub fn canopy(&self, distance_m: f64) -> f64 {
        1.0 - self.drawn_at(distance_m) * self.shares(distance_m).0
    }

    /// Distance between knots of `drawn`, metres.
    pub fn knot_m(&self) -> f64 {
        (self.range_m + self.band_m / 2.0) / (DRAWN_KNOTS - 1) as f64
    }

    /// The share of trees drawn at `distance_m`.
    pub fn drawn_at(&self, distance_m: f64) -> f64 {
        let x = (distance_m / self.knot_m()).clamp(0.0, (DRAWN_KNOTS - 1) as f64);
        let x = if x.is_nan() { 0.0 } else { x };
        let k = (x as usize).min(DRAWN_KNOTS - 2);
        let t = x - k as f64;
        self.drawn[k] * (1.0 - t) + self.drawn[k + 1] * t
    }

    /// Whether the canopy is whole everywhere from `near_m` to `far_m`:
    /// no splat is seen there (their opacity never grows with distance), or
    /// no tree there is drawn.
    pub fn canopy_whole(&self, near_m: f64, far_m: f64) -> bool {
        let inside = |k: usize| {
            let d = k as f64 * self.knot_m();
            d > near_m && d < far_m
        };
        let knots = (0..DRAWN_KNOTS).filter(|&k| inside(k)).map(|k| self.drawn[k]);
        let most = knots.chain([self.drawn_at(near_m), self.drawn_at(far_m)]).fold(0.0, f64::max);
        self.shares(near_m).0 <= 0.0 || most <= 0.0
    }

    /// This blend with the share of trees drawn by distance measured from
    /// `trees`: each tree in view as its distance and whether it has a
    /// splat. Knots with no tree near them take their neighbours' share
    /// (linear between, constant beyond); with no tree at all, every tree
    /// counts as drawn.
    pub fn with_drawn(self, trees: impl IntoIterator<Item = (f64, bool)>) -> TreeBlend {
        let (mut drawn, mut weight) = ([0.0; DRAWN_KNOTS], [0.0; DRAWN_KNOTS]);
        let knot_m = self.knot_m();
        for (distance_m, is_drawn) in trees {
            let x = distance_m / knot_m;
            if !(0.0..=(DRAWN_KNOTS - 1) as f64).contains(&x) {
                continue;
            }
            let k = (x as usize).min(DRAWN_KNOTS - 2);
            let t = x - k as f64;
            for (k, w) in [(k, 1.0 - t), (k + 1, t)] {
                weight[k] += w;
                drawn[k] += w * f64::from(u8::from(is_drawn));
            }
        }
        let known: Vec<(usize, f64)> =
            (0..DRAWN_KNOTS).filter(|&k| weight[k] > 1e-9).map(|k| (k, drawn[k] / weight[k])).collect();
        TreeBlend { drawn: std::array::from_fn(|k| fill(&known, k)), ..self }
    }
}

/// The value at knot `k` from the knots `known` (by index, with values):
/// its own, linear between the nearest known on either side, constant
/// beyond the outermost, 1 with none.
fn fill(known: &[(usize, f64)], k: usize) -> f64 {
    let after = known.partition_point(|&(i, _)| i < k);
    match (after.checked_sub(1).map(|i| known[i]), known.get(after)) {
        (_, Some(&(i, v))) if i == k => v,
        (Some((i0, v0)), Some(&(i1, v1))) => v0 + (v1 - v0) * (k - i0) as f64 / (i1 - i0) as f64,
        (Some((_, v)), None) | (None, Some(&(_, v))) => v,
        (None, None) => 1.0,
    }
}

/// Below this projected error (pixels) a tile needs no ray casting: its
/// canopy is faded out and its terrain mesh departs from the ground by
/// less than half a pixel.
pub const PLAIN_ERROR_PX: f64 = 0.5;

/// Whether a tile whose nearest point is `near_m` away, whose terrain mesh
/// departs from its ground by `mesh_error_m` and whose flat frame
/// misplaces it by up to `flat_error_m` is drawn plain, without rays (the
/// renderer's rule, which the LOD cost model predicts too): where its
/// canopy is faded out and its mesh is good to half a pixel, or where the
/// flat frame rays are cast in misplaces it visibly (half a pixel) and
/// more than the mesh, at its true place on the ellipsoid, departs from
/// the truth (coarse tiles at high latitudes, which a small GPU cache may
/// hold a view to). Under [`Fade::NONE`] every tile is ray cast.
pub fn plain(fade: &Fade, near_m: f64, (mesh_error_m, flat_error_m): (f64, f64)) -> bool {
    let px = |m: f64| m * fade.focal_px / near_m.max(1e-9);
    let faded = fade.far_factor(near_m) <= 0.0 && px(mesh_error_m) < PLAIN_ERROR_PX;
    let misplaced = flat_error_m > mesh_error_m && px(flat_error_m) >= PLAIN_ERROR_PX;
    fade.end_m().is_finite() && (faded || misplaced)
}

fn smoothstep(lo: f64, hi: f64, x: f64) -> f64 {
    let t = ((x - lo) / (hi - lo)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// Everything about one tile and one frame that the casters need.
#[derive(Clone, Copy, Debug)]
pub struct TileView<'a> {
    /// The tile.
    pub tile: &'a TileData,
    /// Camera position in the tile's frame, metres.
    pub camera_m: DVec3,
    /// Unit direction to the sun in the tile's frame, if the sun is on.
    pub sun: Option<DVec3>,
    /// Canopy fade.
    pub fade: Fade,
    /// Shadow samples per hit (0: none).
    pub shadow_steps: u32,
}

impl TileView<'_> {
    /// Local position of sample `(i, j)` at height `z`.
    pub fn local(&self, i: f64, j: f64, z: f64) -> DVec3 {
        self.tile.frame.local_xy(i, j).extend(z)
    }

    /// Surface height at sample `(i, j)` with the canopy faded, or `None`
    /// for nodata.
    pub fn corner(&self, i: i64, j: i64) -> Option<f64> {
        let [cem, dem, ..] = self.tile.texel(i, j);
        if cem <= NODATA_M {
            return None;
        }
        let (cem, dem) = (cem as f64, dem as f64);
        let f = self.fade.factor((self.local(i as f64, j as f64, dem) - self.camera_m).length());
        Some(dem + f * (cem - dem))
    }

    /// The four corners of cell `(ci, cj)`: `[h00, h10, h01, h11]`.
    pub fn cell(&self, ci: i64, cj: i64) -> Option<[f64; 4]> {
        Some([self.corner(ci, cj)?, self.corner(ci + 1, cj)?, self.corner(ci, cj + 1)?, self.corner(ci + 1, cj + 1)?])
    }

    /// Bilinear surface height at fractional sample `(si, sj)`, if its
    /// cell is inside the texels and has data.
    pub fn height(&self, s: DVec2) -> Option<f64> {
        let (ci, cj) = (s.x.floor() as i64, s.y.floor() as i64);
        let b = self.tile.halo as i64;
        let last = self.tile.size as i64 - b - 2;
        if ci < -b || cj < -b || ci > last || cj > last {
            return None;
        }
        let h = self.cell(ci, cj)?;
        Some(bilinear(h, s.x - ci as f64, s.y - cj as f64))
    }
}

/// Bilinear interpolation of `[h00, h10, h01, h11]` at `(fx, fy)`.
pub fn bilinear(h: [f64; 4], fx: f64, fy: f64) -> f64 {
    let south = h[0] + (h[1] - h[0]) * fx;
    let north = h[2] + (h[3] - h[2]) * fx;
    south + (north - south) * fy
}

/// The colour of a hit at sample `s`, local height `z`, seen along the unit
/// local direction `dir`.
pub fn shade(view: &TileView, s: DVec2, z: f64, dir: DVec3) -> [f64; 3] {
    let tile = view.tile;
    let n1 = tile.frame.samples as i64 - 1;
    let (ci, cj) = ((s.x.floor() as i64).clamp(-1, n1), (s.y.floor() as i64).clamp(-1, n1));
    let (fx, fy) = (s.x - ci as f64, s.y - cj as f64);
    let corners = view.cell(ci, cj).unwrap_or([z; 4]);
    let base = colour(tile, ci, cj, fx, fy);
    let class = tile.surface[texel_index(tile, (s.x + 0.5).floor() as i64, (s.y + 0.5).floor() as i64)];
    let normal = normal(corners, fx, fy, tile.frame.spacing_m);
    let Some(sun) = view.sun else {
        let flat_water = class == SurfaceType::Water as u8 && normal.z >= WATER_MIN_NORMAL_Z;
        return if flat_water { water(base, dir, None, 1.0) } else { base };
    };
    // The shadow ray leaves from the surface, never from under it: a ray
    // that enters the cast range through a side below the surface (through
    // the crack between two flat frames, metres deep near a pole) is shaded
    // as the surface above that point, and so is its light. Elsewhere a hit
    // is on the surface and this changes nothing.
    let shadow = shadow(view, s, z.max(bilinear(corners, fx, fy)), sun);
    let lambert = normal.dot(sun).max(0.0);
    let lit = |k: f64| AMBIENT + (1.0 - AMBIENT) * k;
    match SurfaceType::from_id(class) {
        Some(SurfaceType::Forest) => {
            let l = lit(shadow * (0.6 + 0.4 * lambert));
            [0, 1, 2].map(|c| base[c] * CANOPY_TINT[c] * l)
        }
        Some(SurfaceType::Water) if normal.z >= WATER_MIN_NORMAL_Z => {
            water(base.map(|c| c * lit(shadow * lambert)), dir, Some(sun), shadow)
        }
        _ => base.map(|c| c * lit(shadow * lambert)),
    }
}

/// Index of texel `(i, j)` (sample indices, halo included), clamped to
/// the texels.
pub(super) fn texel_index(tile: &TileData, i: i64, j: i64) -> usize {
    let b = tile.halo as i64;
    let last = tile.size as i64 - 1;
    ((j + b).clamp(0, last) * tile.size as i64 + (i + b).clamp(0, last)) as usize
}

/// Bilinear map colour in cell `(ci, cj)`, channels in [0, 1].
fn colour(tile: &TileData, ci: i64, cj: i64, fx: f64, fy: f64) -> [f64; 3] {
    let c = |i: i64, j: i64| tile.colour[texel_index(tile, i, j)].map(|v| v as f64 / 255.0);
    let (c00, c10, c01, c11) = (c(ci, cj), c(ci + 1, cj), c(ci, cj + 1), c(ci + 1, cj + 1));
    [0, 1, 2].map(|k| bilinear([c00[k], c10[k], c01[k], c11[k]], fx, fy))
}

/// The bilinear patch's unit normal at `(fx, fy)`.
fn normal(h: [f64; 4], fx: f64, fy: f64, spacing_m: DVec2) -> DVec3 {
    let dx = ((h[1] - h[0]) * (1.0 - fy) + (h[3] - h[2]) * fy) / spacing_m.x;
    let dy = ((h[2] - h[0]) * (1.0 - fx) + (h[3] - h[1]) * fx) / spacing_m.y;
    DVec3::new(-dx, -dy, 1.0).normalize()
}

/// Water: the lit map colour mixed with the sky by Fresnel, plus a glint.
fn water(base: [f64; 3], dir: DVec3, sun: Option<DVec3>, shadow: f64) -> [f64; 3] {
    let cos = (-dir.z).clamp(0.0, 1.0);
    let fresnel = 0.02 + 0.98 * (1.0 - cos).powi(5);
    let glint = sun.map_or(0.0, |l| DVec3::new(dir.x, dir.y, -dir.z).dot(l).max(0.0).powi(64) * 0.8 * shadow);
    [0, 1, 2].map(|c| base[c] * 0.8 * (1.0 - fresnel) + SKY[c] * fresnel + glint)
}

/// Light reaching a hit through the terrain toward the sun, in [0, 1].
pub fn shadow(view: &TileView, s: DVec2, z: f64, sun: DVec3) -> f64 {
    let tile = view.tile;
    let per_m = DVec2::new(sun.x / tile.frame.spacing_m.x, sun.y / tile.frame.spacing_m.y);
    let horizontal = per_m.length();
    let n = view.shadow_steps;
    if n == 0 || horizontal < 1e-9 {
        return 1.0;
    }
    let reach = tile.halo as f64;
    let s0 = 2.0 * reach / (n as f64 * (n as f64 + 1.0));
    let top = tile.range.texels_max_m as f64;
    let mut occlusion = 0.0;
    for k in 1..=n {
        let kf = k as f64;
        let t = s0 * kf * (kf + 1.0) / 2.0 / horizontal;
        let (q, zq) = (s + per_m * t, z + sun.z * t);
        if zq > top {
            break;
        }
        if let Some(h) = view.height(q) {
            occlusion += SHADOW_WEIGHT / kf * ((h - zq) / SHADOW_SOFT_M).clamp(0.0, 1.0);
        }
    }
    (1.0 - occlusion).clamp(0.0, 1.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tiles_are_drawn_plain_where_rays_would_show_less_truth() {
        let fade = Fade { focal_px: 1000.0, canopy_ref_m: 30.0, lo_px: 0.5, hi_px: 2.0, trees: TreeBlend::NONE };
        // Past the fade (60 km here) with a mesh good to half a pixel.
        assert!(plain(&fade, 70_000.0, (10.0, 0.0)) && !plain(&fade, 50_000.0, (10.0, 0.0)));
        assert!(!plain(&fade, 70_000.0, (50.0, 0.0)), "a mesh a pixel off");
        // A flat frame misplacing the tile visibly, by more than its mesh.
        assert!(plain(&fade, 10_000.0, (2.0, 20.0)));
        // Regression: a flat frame's tenth of a pixel, more than a fine mesh's
        // error, drew tiles inside the fade without canopy or shadows (the
        // demo valley's far tiles: PSNR 43 → 24 dB against the reference).
        assert!(!plain(&fade, 20_000.0, (1.0, 2.0)));
        assert!(!plain(&Fade::NONE, 10_000.0, (2.0, 20.0)), "without a fade every tile is ray cast");
    }

    /// Trees over 0–400 m, a band 100 m wide: knots every 30 m.
    const TREES: TreeBlend = TreeBlend::every_tree(400.0, 100.0);

    #[test]
    fn the_canopy_gives_way_by_the_share_of_trees_drawn() {
        let fade = Fade { trees: TREES, ..Fade::NONE };
        assert_eq!(fade.factor(10.0), 0.0, "every tree drawn: no canopy under the splats");
        // Every other tree drawn near the camera, none beyond 200 m.
        let trees = (0..400).map(|k| (f64::from(k), k < 200 && k % 2 == 0));
        let partial = Fade { trees: TREES.with_drawn(trees), ..Fade::NONE };
        assert!((partial.factor(60.0) - 0.5).abs() < 1e-9, "{}", partial.factor(60.0));
        assert_eq!(partial.factor(300.0), 1.0, "no tree drawn: the canopy whole");
        // The canopy grows toward the band's end wherever trees are drawn.
        let none = Fade { trees: TREES.with_drawn((0..400).map(|k| (f64::from(k), false))), ..Fade::NONE };
        assert!((0..500).all(|d| none.factor(f64::from(d)) == 1.0), "no splats: the canopy everywhere");
        let unseen = TREES.with_drawn([]);
        assert_eq!(unseen, TREES, "no tree in view: as if every tree were drawn");
    }

    #[test]
    fn knots_without_trees_take_their_neighbours_share() {
        // Trees only at 60 m (all drawn) and at 180 m (none drawn).
        let blend = TREES.with_drawn([(60.0, true), (180.0, false)]);
        let at = |d: f64| blend.drawn_at(d);
        assert_eq!((at(0.0), at(60.0), at(180.0), at(450.0)), (1.0, 1.0, 0.0, 0.0));
        assert!((at(120.0) - 0.5).abs() < 1e-12, "{}", at(120.0));
        assert!(at(f64::NAN).is_finite() && TreeBlend::NONE.canopy(f64::NAN) == 1.0);
    }

    #[test]
    fn the_canopy_is_whole_only_where_no_splat_stands() {
        // Trees drawn only between 100 and 200 m.
        let blend = TREES.with_drawn((0..400).map(|k| (f64::from(k), (100..200).contains(&k))));
        let fade = Fade { trees: blend, ..Fade::NONE };
        assert!(fade.whole(0.0, 50.0) && fade.whole(250.0, 1000.0) && fade.whole(460.0, 1e6));
        assert!(!fade.whole(0.0, 1000.0), "the drawn trees lie between the ends");
        for (near, far) in [(0.0, 1000.0), (40.0, 300.0), (140.0, 150.0)] {
            let lowered = (0..=100).map(|k| near + (far - near) * f64::from(k) / 100.0).any(|d| fade.factor(d) < 1.0);
            assert_eq!(fade.whole(near, far), !lowered, "{near}..{far}");
        }
    }
}
