//! Trees near the camera as point splats (issue 7 item 2; 000 §5,
//! dissertation §8.4): individual trees on the world-anchored jittered
//! lattice of [`crate::lod::splats`], grown on the drawn tiles where their
//! surface class is forest, grouped by lattice block (≤ 64 trees), each
//! group drawn with a splat budget.
//!
//! - **Lattice.** Cell `(i, j)` spans `spacing` metres of latitude on both
//!   axes, measured in degrees (`METRES_PER_DEGREE`), so a tree's place
//!   depends only on its cell and the seed, never on the tile it is read
//!   from; the cover is scaled by `cos(latitude)` to keep the density per
//!   square metre where cells narrow. A tile grows the trees whose position
//!   lies in its own sector (half-open), so neighbours never grow one twice.
//! - **A tree** stands on the tile's ground (the ray caster's bilinear
//!   surface) and is as tall as the tile's canopy there (CEM − ground), so
//!   its crown never rises above the canopy it replaces; its colour is the
//!   map's there. Its crown is an ellipsoid under the top.
//! - **Splats** of a tree (`n` of them) are discs scattered in the crown,
//!   each so large that together they cover it twice; a tree of one splat
//!   is one disc the size of its crown, so lowering a budget coarsens trees
//!   and never leaves holes. Within a group a budget goes to trees by rank
//!   ([`distribute`]). Without a budget each tree gets as many splats as
//!   its projected crown asks ([`SPLAT_PX`] apart), up to the field's full
//!   count.
//! - **Blend.** A splat's opacity is the tree's share of the
//!   [`TreeBlend`] at its distance, the canopy's share goes to the ray
//!   caster: the two sum to one, so trees fade in where the canopy fades out.
//!   Under a budget that leaves trees without a splat, the canopy gives way
//!   only by the share of trees drawn at that distance ([`Drawn::blend`]),
//!   so sparse splats stand in a lowered canopy, not over bare ground.

use super::camera::Camera;
use super::lod::budget::TreeItem;
use super::raycast::{Fade, TreeBlend, texel_index};
use super::tile::{NODATA_M, TileData};
use crate::cem::surface::SurfaceType;
use crate::geo::METRES_PER_DEGREE;
use crate::lod::splats::{TreeField, distribute};
use crate::lod::split::Item;
use crate::noise::{hash2, unit};
use glam::{DVec2, DVec3};
use std::collections::HashMap;

/// Trees lower than this grow no splats (the canopy there is scrub), metres.
pub const MIN_TREE_M: f64 = 2.0;
/// Projected distance between splats a tree's crown asks for without a
/// budget, pixels.
pub const SPLAT_PX: f64 = 3.0;

/// How trees are grown and where they are drawn.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TreeSettings {
    /// The lattice: spacing, seed, splats of a tree at full resolution.
    pub field: TreeField,
    /// The tree range ends where the lattice spacing looks this small,
    /// pixels.
    pub spacing_px: f64,
    /// Width of the blend band as a fraction of the range.
    pub band: f64,
}

impl Default for TreeSettings {
    fn default() -> TreeSettings {
        TreeSettings {
            field: TreeField { spacing_m: 7.0, seed: 0x7EE5, splats_per_tree: 24 },
            spacing_px: 4.0,
            band: 0.3,
        }
    }
}

impl TreeSettings {
    /// The blend for a camera of focal length `focal_px`.
    pub fn blend(&self, focal_px: f64) -> TreeBlend {
        let range_m = focal_px * self.field.spacing_m / self.spacing_px.max(1e-9);
        if !range_m.is_finite() || range_m <= 0.0 {
            return TreeBlend::NONE;
        }
        TreeBlend::every_tree(range_m, self.band.clamp(0.0, 1.9) * range_m)
    }
}

/// The canopy fade for a camera of focal length `focal_px`: the far fade,
/// `(reference height m, low px, high px)`, and with `trees` their blend.
pub fn canopy_fade((canopy_ref_m, lo_px, hi_px): (f64, f64, f64), trees: Option<&TreeSettings>, focal_px: f64) -> Fade {
    let trees = trees.map_or(TreeBlend::NONE, |t| t.blend(focal_px));
    Fade { focal_px, canopy_ref_m, lo_px, hi_px, trees }
}

/// Splat budgets of tree groups, by lattice block.
pub type TreeBudgets = HashMap<(i64, i64), f64>;

/// One splat as the GPU reads it, in its tile's frame.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct Splat {
    /// Centre, tile-local metres.
    pub centre: [f32; 3],
    /// Radius, metres.
    pub radius: f32,
    /// sRGB colour; alpha: opacity.
    pub colour: [u8; 4],
}

/// A tree grown on a drawn tile.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlacedTree {
    /// Index of its tile in the frame's tiles.
    pub tile: usize,
    /// Its foot, in the tile's frame (local metres).
    pub foot: DVec3,
    /// Height, metres.
    pub height_m: f64,
    /// Crown size factor.
    pub scale: f64,
    /// Drawing order within partial budgets (lower first).
    pub rank: u16,
    /// Its lattice cell's hash: the splats' positions.
    pub hash: u64,
    /// Map colour, channels in [0, 1].
    pub colour: [f64; 3],
    /// Distance from the camera to the middle of its trunk, metres.
    pub distance_m: f64,
}

/// The trees of one lattice block near the camera, by rank.
#[derive(Clone, Debug, PartialEq)]
pub struct TreeGroup {
    /// Block index on the lattice.
    pub block: (i64, i64),
    /// Its trees on the drawn tiles, by rank.
    pub trees: Vec<PlacedTree>,
}

/// The groups with a tree in view within the blend's reach of `camera`,
/// grown on `tiles` (the frame's tiles, so a tree's tile index is its
/// index there).
pub fn groups_near(settings: &TreeSettings, tiles: &[&TileData], camera: &Camera, blend: &TreeBlend) -> Vec<TreeGroup> {
    if blend.range_m <= 0.0 {
        return Vec::new();
    }
    let reach_m = blend.range_m + blend.band_m / 2.0;
    let mut blocks: HashMap<(i64, i64), Vec<PlacedTree>> = HashMap::new();
    for (k, tile) in tiles.iter().enumerate() {
        for (block, tree) in grow(&settings.field, tile, k, camera, reach_m) {
            blocks.entry(block).or_default().push(tree);
        }
    }
    let mut groups: Vec<TreeGroup> = blocks
        .into_iter()
        .map(|(block, mut trees)| {
            trees.sort_by_key(|t| (t.rank, t.hash));
            TreeGroup { block, trees }
        })
        .collect();
    groups.sort_by_key(|g| g.block);
    groups
}

/// The trees of `tile` (index `k`) within `reach_m` of the camera and
/// inside its view, with their blocks.
fn grow(field: &TreeField, tile: &TileData, k: usize, camera: &Camera, reach_m: f64) -> Vec<((i64, i64), PlacedTree)> {
    let eye = tile.frame.to_local(camera.position_ecef);
    if eye.z - f64::from(tile.range.max_m) > reach_m {
        return Vec::new();
    }
    let lattice = Lattice::of(tile);
    let Some((lo, hi)) = lattice.window(tile, eye, reach_m) else { return Vec::new() };
    let cover = |p: DVec2| lattice.cover(tile, p);
    let planes = camera.side_planes();
    let in_view = |middle: DVec3, radius: f64| {
        let offset = tile.frame.to_ecef(middle) - camera.position_ecef;
        planes.iter().all(|n| n.dot(offset) >= -radius)
    };
    let mut out = Vec::new();
    for group in field.groups_in(lo, hi, &cover) {
        for t in &group.trees {
            let s = lattice.sample(t.position_m);
            let Some((ground, cem)) = surface(tile, s) else { continue };
            let height_m = cem - ground;
            let foot = tile.frame.local_xy(s.x, s.y).extend(ground);
            let middle = foot + DVec3::Z * (height_m / 2.0);
            let distance_m = middle.distance(eye);
            if height_m < MIN_TREE_M || distance_m > reach_m || !in_view(middle, height_m + field.spacing_m) {
                continue;
            }
            let tree = PlacedTree {
                tile: k,
                foot,
                height_m,
                scale: t.scale,
                rank: t.rank,
                hash: hash2(t.cell.0, t.cell.1, field.seed ^ 0x5B1A7),
                colour: colour(tile, s),
                distance_m,
            };
            out.push((group.block, tree));
        }
    }
    out
}

/// A tile's samples on the lattice's metres.
struct Lattice {
    /// South-west sample, lattice metres.
    origin_m: DVec2,
    /// Lattice metres per sample, east and north.
    step_m: DVec2,
    /// Samples per side.
    samples: f64,
}

impl Lattice {
    fn of(tile: &TileData) -> Lattice {
        let s = tile.frame.sector;
        let per = (tile.frame.samples.max(2) - 1) as f64;
        Lattice {
            origin_m: DVec2::new(s.min_lon, s.min_lat) * METRES_PER_DEGREE,
            step_m: DVec2::new(s.max_lon - s.min_lon, s.max_lat - s.min_lat) * METRES_PER_DEGREE / per,
            samples: tile.frame.samples as f64,
        }
    }

    /// Sample coordinates of a lattice point.
    fn sample(&self, p_m: DVec2) -> DVec2 {
        (p_m - self.origin_m) / self.step_m
    }

    /// The lattice box of the tile's sector within `reach_m` of the eye
    /// (local metres), if any.
    fn window(&self, tile: &TileData, eye: DVec3, reach_m: f64) -> Option<(DVec2, DVec2)> {
        let s = tile.frame.sample_of(eye.truncate());
        let spacing = tile.frame.spacing_m;
        let r = DVec2::new(reach_m / spacing.x, reach_m / spacing.y);
        let last = DVec2::splat(self.samples - 1.0);
        let (lo, hi) = ((s - r).max(DVec2::ZERO), (s + r).min(last));
        (lo.cmple(hi).all() && lo.is_finite() && hi.is_finite())
            .then(|| (self.origin_m + lo * self.step_m, self.origin_m + hi * self.step_m))
    }

    /// Forest cover at a lattice point: the bilinear share of forest among
    /// the four samples around it, times `cos(latitude)`; 0 outside the
    /// tile's sector (its east and north edges belong to the neighbours).
    fn cover(&self, tile: &TileData, p_m: DVec2) -> f64 {
        let s = self.sample(p_m);
        let last = self.samples - 1.0;
        if !(s.x >= 0.0 && s.y >= 0.0 && s.x < last && s.y < last) {
            return 0.0;
        }
        let (c, f) = (s.floor(), s - s.floor());
        let forest = |i: f64, j: f64| {
            let id = tile.surface[texel_index(tile, i as i64, j as i64)];
            if id == SurfaceType::Forest as u8 { 1.0 } else { 0.0 }
        };
        let share = super::raycast::bilinear(
            [forest(c.x, c.y), forest(c.x + 1.0, c.y), forest(c.x, c.y + 1.0), forest(c.x + 1.0, c.y + 1.0)],
            f.x,
            f.y,
        );
        share * (p_m.y / METRES_PER_DEGREE).to_radians().cos()
    }
}

/// Ground and CEM (local metres) at fractional sample `s`, where all four
/// samples around it have data.
fn surface(tile: &TileData, s: DVec2) -> Option<(f64, f64)> {
    let (c, f) = (s.floor(), s - s.floor());
    let (i, j) = (c.x as i64, c.y as i64);
    let t = [tile.texel(i, j), tile.texel(i + 1, j), tile.texel(i, j + 1), tile.texel(i + 1, j + 1)];
    if t.iter().any(|t| t[0] <= NODATA_M) {
        return None;
    }
    let layer = |k: usize| super::raycast::bilinear(t.map(|t| t[k] as f64), f.x, f.y);
    Some((layer(1), layer(0)))
}

/// Samples either side of a tree searched for its colour: near first,
/// then farther where the near samples hold no green.
const COLOUR_REACH: [i64; 2] = [2, 6];

/// The map colour of a tree at sample `s`: the greenest sample near it
/// (contour lines and paths drawn through a forest on a map sheet colour
/// no tree).
fn colour(tile: &TileData, s: DVec2) -> [f64; 3] {
    let greenness = |c: &[u8; 4]| i32::from(c[1]) - i32::from(c[0].max(c[2]));
    let mut best = [0u8; 4];
    for reach in COLOUR_REACH {
        best = greenest(tile, s, reach, greenness);
        if greenness(&best) > 0 {
            break;
        }
    }
    [0, 1, 2].map(|k| f64::from(best[k]) / 255.0)
}

fn greenest(tile: &TileData, s: DVec2, reach: i64, greenness: impl Fn(&[u8; 4]) -> i32) -> [u8; 4] {
    let (i, j) = (s.x.round() as i64, s.y.round() as i64);
    let offsets = -reach..=reach;
    offsets
        .clone()
        .flat_map(|dj| offsets.clone().map(move |di| (i + di, j + dj)))
        .map(|(i, j)| tile.colour[texel_index(tile, i, j)])
        .max_by_key(|c| greenness(c))
        .unwrap_or_default()
}

/// What [`splats`] drew.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Drawn {
    /// Splats.
    pub splats: usize,
    /// Trees with a splat.
    pub trees: usize,
    /// Groups with a splat.
    pub groups: usize,
    /// Pixels the splats' quads cover, overlaps counted: the fragments
    /// the rasteriser shades (`Crown::fill_px`).
    pub fill_px: f64,
    /// The blend with the share of trees drawn by distance: what the ray
    /// caster's canopy gives way to.
    pub blend: TreeBlend,
}

/// Splats of each group: `budgets` gives a group's splat budget by block
/// (a block without one gets none), or with `None` every tree gets what
/// its projected crown asks for. Appended to `out[tile]`, which must hold
/// a list per frame tile.
pub fn splats(
    settings: &TreeSettings,
    groups: &[TreeGroup],
    budgets: Option<&TreeBudgets>,
    (blend, focal_px): (&TreeBlend, f64),
    out: &mut [Vec<Splat>],
) -> Drawn {
    let field = &settings.field;
    let mut drawn = Drawn::default();
    let mut seen = Vec::new();
    for g in groups {
        let before = drawn.splats;
        let counts: Vec<u32> = match budgets {
            Some(b) => {
                distribute(b.get(&g.block).copied().unwrap_or(0.0), g.trees.len(), field.splats_per_tree).collect()
            }
            None => g.trees.iter().map(|t| wanted(field, t, focal_px)).collect(),
        };
        for (t, &n) in g.trees.iter().zip(&counts) {
            let opacity = blend.shares(t.distance_m).0;
            seen.push((t.distance_m, n > 0));
            if opacity <= 0.0 || n == 0 {
                continue;
            }
            let crown = Crown::of(field, t);
            out[t.tile].extend((0..n).map(|k| crown.splat(t, k, n, opacity)));
            drawn.fill_px += crown.fill_px(n, t.distance_m, focal_px);
            drawn.splats += n as usize;
            drawn.trees += 1;
        }
        drawn.groups += usize::from(drawn.splats > before);
    }
    drawn.blend = blend.with_drawn(seen);
    drawn
}

impl TreeGroup {
    /// The group as the LOD selection sees it from one camera (focal
    /// length `focal_px`; the trees' distances are from it), its trees on
    /// `tiles`.
    pub fn item(&self, tiles: &[&TileData], field: &TreeField, focal_px: f64) -> TreeItem {
        let middles: Vec<(DVec3, f64)> = self
            .trees
            .iter()
            .map(|t| (tiles[t.tile].frame.to_ecef(t.foot + DVec3::Z * (t.height_m / 2.0)), t.height_m))
            .collect();
        let centre = middles.iter().map(|m| m.0).sum::<DVec3>() / middles.len().max(1) as f64;
        let radius_m = middles.iter().map(|(p, h)| p.distance(centre) + h / 2.0 + field.spacing_m).fold(0.0, f64::max);
        let group = Item {
            center_m: centre,
            radius_m,
            trees: self.trees.len() as u32,
            capacity: (self.trees.len() as u64 * u64::from(field.splats_per_tree)) as f64,
        };
        let full = field.splats_per_tree.max(1);
        let fill_px = self.trees.iter().map(|t| Crown::of(field, t).fill_px(full, t.distance_m, focal_px)).sum();
        TreeItem { block: self.block, group, share: 1.0, fill_px }
    }
}

/// Splats a tree's projected crown asks for: one per [`SPLAT_PX`] of its
/// diameter squared, at least one, at most the field's full count.
pub fn wanted(field: &TreeField, tree: &PlacedTree, focal_px: f64) -> u32 {
    let crown_px = 2.0 * Crown::of(field, tree).radius_m * focal_px / tree.distance_m.max(1e-6);
    let n = (crown_px / SPLAT_PX).powi(2).ceil();
    if n.is_finite() { (n as u32).clamp(1, field.splats_per_tree.max(1)) } else { 1 }
}

/// A tree's crown: an ellipsoid under its top.
struct Crown {
    /// Centre, local metres.
    centre: DVec3,
    /// Horizontal semi-axis, metres.
    radius_m: f64,
    /// Vertical semi-axis, metres.
    half_height_m: f64,
}

impl Crown {
    fn of(field: &TreeField, t: &PlacedTree) -> Crown {
        let half_height_m = 0.4 * t.height_m;
        let radius_m = (0.22 * t.height_m * t.scale).clamp(0.8, 0.75 * field.spacing_m);
        Crown { centre: t.foot + DVec3::Z * (t.height_m - half_height_m), radius_m, half_height_m }
    }

    /// The radius of each of `n` splats: together they cover the crown's
    /// silhouette twice, none larger than the crown.
    fn splat_radius_m(&self, n: u32) -> f64 {
        (2.0 * self.radius_m * self.half_height_m / f64::from(n.max(1)))
            .sqrt()
            .min(self.half_height_m.max(self.radius_m))
    }

    /// Pixels the quads of `n` splats cover at `distance_m` from a camera
    /// of focal length `focal_px`, overlaps counted: about the same for
    /// any `n` (twice the crown's silhouette, a little less for one splat,
    /// which the crown's size caps).
    fn fill_px(&self, n: u32, distance_m: f64, focal_px: f64) -> f64 {
        let side_px = 2.0 * self.splat_radius_m(n) * focal_px / distance_m.max(1.0);
        f64::from(n) * side_px * side_px
    }

    /// Splat `k` of `n`: spread over the crown as far as `n` allows (one
    /// splat sits at the centre), sized so that the splats cover the
    /// crown's silhouette twice, darker low in the crown.
    fn splat(&self, t: &PlacedTree, k: u32, n: u32, opacity: f64) -> Splat {
        let h = hash2(t.hash as i64, i64::from(k), 0x5E1A7);
        let z = 2.0 * unit(h, 0) - 1.0;
        let phi = std::f64::consts::TAU * unit(h, 1);
        let r = (1.0 - z * z).sqrt();
        let spread = 0.7 * (1.0 - 1.0 / f64::from(n)).sqrt();
        let offset = DVec3::new(r * phi.cos() * self.radius_m, r * phi.sin() * self.radius_m, z * self.half_height_m);
        let centre = self.centre + offset * spread;
        let radius = self.splat_radius_m(n);
        let shade = (0.7 + 0.3 * (z * spread + 1.0) / 2.0) * (0.9 + 0.2 * unit(h, 2));
        let byte = |v: f64| (v.clamp(0.0, 1.0) * 255.0).round() as u8;
        let [r, g, b] = t.colour.map(|c| byte(c * shade));
        Splat { centre: centre.as_vec3().to_array(), radius: radius as f32, colour: [r, g, b, byte(opacity)] }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::client::globe::Geodetic;
    use crate::client::tile::TilePayload;
    use crate::grid::{TileGrid, TileId};

    const FOREST: u8 = SurfaceType::Forest as u8;

    /// A tile of ground `f(lon, lat)` with a 20 m canopy where `forest`.
    fn tile(grid: &TileGrid, id: TileId, forest: &dyn Fn(f64, f64) -> bool) -> TileData {
        let samples = grid.tile_samples(id, 2);
        let mut p = TilePayload { id, halo: 2, cem: vec![], dem: vec![], surface: vec![], colour: vec![] };
        for y in 0..samples.height() {
            for x in 0..samples.width() {
                let (lon, lat) = samples.lon_lat(x, y);
                let ground = 1000.0 + 300.0 * (lon - 10.0) + 200.0 * (lat - 46.0);
                let f = forest(lon, lat);
                p.dem.push(ground as f32);
                p.cem.push((ground + if f { 20.0 } else { 0.0 }) as f32);
                p.surface.push(if f { FOREST } else { 0 });
                p.colour.push(if f { [60, 120, 50, 255] } else { [200, 190, 150, 255] });
            }
        }
        TileData::prepare(grid, p).unwrap()
    }

    fn grid() -> TileGrid {
        TileGrid::new(36.0, 65).unwrap()
    }

    /// A camera ~310 m above the middle of `id`, looking down on all of it.
    fn above(grid: &TileGrid, id: TileId) -> Camera {
        let s = grid.sector(id);
        let eye = Geodetic::new((s.min_lon + s.max_lon) / 2.0, (s.min_lat + s.max_lat) / 2.0, 1400.0);
        Camera::looking(eye, 0.0, -90.0, 60.0, (320, 240))
    }

    const WIDE: TreeBlend = TreeBlend::every_tree(5000.0, 100.0);

    fn trees_of(groups: &[TreeGroup], tiles: &[&TileData]) -> Vec<(u64, DVec3)> {
        let mut out: Vec<(u64, DVec3)> =
            groups.iter().flat_map(|g| g.trees.iter().map(|t| (t.hash, tiles[t.tile].frame.to_ecef(t.foot)))).collect();
        out.sort_by_key(|t| t.0);
        out
    }

    #[test]
    fn trees_are_world_anchored_across_tiles_and_levels() {
        let grid = grid();
        let parent = grid.tile_containing(10.1, 46.3, 14);
        let camera = above(&grid, parent);
        let settings = TreeSettings::default();
        let all = |_: f64, _: f64| true;
        let coarse = tile(&grid, parent, &all);
        let fine: Vec<TileData> = parent.children().iter().map(|&c| tile(&grid, c, &all)).collect();
        let fine_refs: Vec<&TileData> = fine.iter().collect();
        let a = trees_of(&groups_near(&settings, &[&coarse], &camera, &WIDE), &[&coarse]);
        let b = trees_of(&groups_near(&settings, &fine_refs, &camera, &WIDE), &fine_refs);
        // The sector is ~240 m square at 7 m spacing: about a thousand trees.
        assert!(a.len() > 800, "{}", a.len());
        assert_eq!(a.len(), b.len(), "four children grow their parent's trees, none twice");
        for ((ha, pa), (hb, pb)) in a.iter().zip(&b) {
            // Placed in different flat frames, which depart from the
            // ellipsoid by centimetres over these tiles.
            assert_eq!(ha, hb);
            assert!(pa.distance(*pb) < 0.05, "{pa} vs {pb}");
        }
    }

    #[test]
    fn trees_grow_in_the_forest_only_and_never_above_its_canopy() {
        let grid = grid();
        let id = grid.tile_containing(10.1, 46.3, 14);
        let s = grid.sector(id);
        let mid = (s.min_lon + s.max_lon) / 2.0;
        let west = move |lon: f64, _: f64| lon < mid;
        let t = tile(&grid, id, &west);
        let camera = above(&grid, id);
        let settings = TreeSettings::default();
        let groups = groups_near(&settings, &[&t], &camera, &WIDE);
        let trees: Vec<&PlacedTree> = groups.iter().flat_map(|g| &g.trees).collect();
        let mid_x = t.frame.local_xy(t.frame.sample_of(DVec2::ZERO).x, 0.0).x;
        // Half the ~240 m square at one tree per (7 m)² × cos(46.3°).
        let area = (s.max_lon - s.min_lon) / 2.0 * (s.max_lat - s.min_lat) * METRES_PER_DEGREE.powi(2);
        let expected = area * 46.3f64.to_radians().cos() / 49.0;
        assert!((trees.len() as f64 / expected - 1.0).abs() < 0.15, "{} trees, {expected:.0} expected", trees.len());
        let east_edge = t.frame.local_xy((t.frame.samples - 1) as f64 / 2.0 + 1.0, 0.0).x;
        assert!(trees.iter().all(|t| t.foot.x < east_edge.max(mid_x)), "no tree east of the forest's last sample");
        assert!(groups.iter().all(|g| !g.trees.is_empty() && g.trees.len() <= 64));
        for g in &groups {
            let mut out = vec![Vec::new()];
            splats(&settings, std::slice::from_ref(g), None, (&WIDE, camera.focal_px()), &mut out);
            for (splat, tree) in out[0].iter().zip(g.trees.iter().flat_map(|t| std::iter::repeat_n(t, 24))) {
                let z = f64::from(splat.centre[2]);
                assert!(z <= tree.foot.z + tree.height_m + 1e-3, "a splat above its tree's top");
            }
            for splat in &out[0] {
                let s = t.frame.sample_of(DVec2::new(f64::from(splat.centre[0]), f64::from(splat.centre[1])));
                let (ground, _) = surface(&t, s).unwrap();
                assert!(f64::from(splat.centre[2]) >= ground, "a splat under the ground");
            }
        }
    }

    #[test]
    fn budgets_and_screen_size_set_the_splats() {
        let grid = grid();
        let id = grid.tile_containing(10.1, 46.3, 14);
        let t = tile(&grid, id, &|_, _| true);
        let camera = above(&grid, id);
        let settings = TreeSettings::default();
        let groups = groups_near(&settings, &[&t], &camera, &WIDE);
        let g = &groups[0];
        let count = |budget: Option<f64>| {
            let budgets = budget.map(|b| HashMap::from([(g.block, b)]));
            let mut out = vec![Vec::new()];
            splats(&settings, std::slice::from_ref(g), budgets.as_ref(), (&WIDE, camera.focal_px()), &mut out)
        };
        let (n, full) = (g.trees.len(), g.trees.len() * 24);
        let drawn = |d: Drawn| (d.splats, d.trees, d.groups);
        assert_eq!(drawn(count(Some(0.0))), (0, 0, 0));
        assert_eq!(drawn(count(Some(5.0))), (5, 5, 1), "a small budget draws the first trees by rank, one splat each");
        assert_eq!(drawn(count(Some(1e9))), (full, n, 1));
        // The canopy gives way by the share of trees drawn.
        let share = |budget: f64| count(Some(budget)).blend.drawn.iter().sum::<f64>() / 16.0;
        assert_eq!((share(0.0), share(1e9)), (0.0, 1.0));
        assert!((share(n as f64 / 2.0) - 0.5).abs() < 0.2, "{}", share(n as f64 / 2.0));
        // The quads cover about as much at a splat per tree as at 24, a
        // share of that below; the selection's item foresees the full fill.
        let fill = |b: f64| count(Some(b)).fill_px;
        let (one_each, whole) = (fill(n as f64), fill(1e9));
        assert!(whole > 0.0 && (0.6..=1.0).contains(&(one_each / whole)), "{one_each} {whole}");
        assert!(fill(0.0) == 0.0 && fill(5.0) < one_each * 10.0 / n as f64, "{} {one_each}", fill(5.0));
        let item = g.item(&[&t], &settings.field, camera.focal_px());
        assert!((item.fill_px - whole).abs() <= 1e-9 * whole, "{} {whole}", item.fill_px);
        // By screen size: near trees get more splats than far ones.
        let tree = g.trees[0];
        let far = PlacedTree { distance_m: tree.distance_m * 100.0, ..tree };
        let (near_n, far_n) = (wanted(&settings.field, &tree, 1000.0), wanted(&settings.field, &far, 1000.0));
        assert!(near_n > far_n && far_n >= 1 && near_n <= 24, "{near_n} {far_n}");
    }

    #[test]
    fn splats_fade_out_across_the_band_and_none_grow_beyond() {
        let grid = grid();
        let id = grid.tile_containing(10.1, 46.3, 14);
        let t = tile(&grid, id, &|_, _| true);
        let camera = above(&grid, id);
        let settings = TreeSettings::default();
        // The camera is ~310 m above the trees, the tile's corners ~350 m.
        let blend = TreeBlend::every_tree(335.0, 30.0);
        let groups = groups_near(&settings, &[&t], &camera, &blend);
        let trees: Vec<&PlacedTree> = groups.iter().flat_map(|g| &g.trees).collect();
        assert!(!trees.is_empty() && trees.iter().all(|t| t.distance_m <= 350.0));
        let mut out = vec![Vec::new()];
        splats(&settings, &groups, None, (&blend, camera.focal_px()), &mut out);
        let alphas: Vec<u8> = out[0].iter().map(|s| s.colour[3]).collect();
        assert!(alphas.contains(&255) && alphas.iter().any(|&a| a < 255), "opaque near, fading in the band");
        assert!(groups_near(&settings, &[&t], &camera, &TreeBlend::NONE).is_empty());
    }
}
