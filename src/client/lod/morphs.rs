//! Geomorphing between tile levels in the client (001 §3.4 and §4.4). For
//! refinement, when a cut draws a tile in place of a coarser one drawn the
//! frame before, the tile's heights start on the coarser tile's surface
//! (bilinear between its samples, the surface the ray caster drew) and
//! glide to its own along a [`MorphTrack`] over `τ` (an upmorph, run
//! during the interval the selection is for), so no point of the surface
//! jumps at the switch.
//!
//! A morphing tile is drawn from a tile prepared once per morph ([`pair`],
//! kept in [`Pairs`] while the morph lasts): its own texels, and the
//! ancestor's surface resampled to them, which the GPU blends by the
//! frame's morph weight (`crate::lod::morph::morphed_height`); its bounds
//! enclose both surfaces. Nodata stays nodata; where only the ancestor has
//! none, the tile's own height is used; a morphing tile far enough to be
//! drawn plain (no rays, its relief below a pixel) shows its own ground.
//! [`blend`] prepares the surface of one weight as a tile of its own, for
//! the CPU reference.
//!
//! Coarsening is a downmorph, run *before* the switch (001's asymmetry):
//! the flight holds a cut that coarsens back for `τ` while the tiles it
//! replaces glide onto the surface of their coarser tile in it, and draws
//! it once a frame has shown them all there ([`Morphs::settled`]). A held
//! cut replaced by another moves only the tiles whose fate changed: those
//! the new one no longer coarsens glide back up to their own surface,
//! those only it coarsens start down from that frame.
//!
//! A refinement of a tile still morphing waits too: the flight holds the
//! cut until that morph is done ([`Morphs::refines_morphing`]), since a
//! finer tile starts from its drawn ancestor's own surface, which is the
//! surface drawn only then (001 §4.4 morphs through one level at a time);
//! so do tiles that arrive under a stand-in still morphing
//! ([`Morphs::hold_under_morphing`]).

use super::super::tile::{NODATA_M, TileData, TileError, TilePayload};
use crate::grid::{TileGrid, TileId};
use crate::lod::morph::{MorphTrack, morphed_height};
use std::collections::{HashMap, HashSet};
use std::sync::Arc;

/// A tile's level track and the coarser tile at its other end.
#[derive(Clone, Debug)]
struct Track {
    coarse: TileId,
    track: MorphTrack,
}

/// The morphs of a flight.
#[derive(Clone, Debug)]
pub struct Morphs {
    tau_s: f64,
    drawn: HashSet<TileId>,
    active: HashMap<TileId, Track>,
    settled: bool,
}

/// A tile of this frame's cut that is morphing.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Morphing {
    /// The tile drawn.
    pub tile: TileId,
    /// The coarser tile whose surface it morphs from or to.
    pub from: TileId,
    /// Weight of its own heights, in `[0, 1)`.
    pub weight: f64,
}

impl Morphs {
    /// Morphs of `tau_s` seconds.
    pub fn new(tau_s: f64) -> Morphs {
        Morphs { tau_s, drawn: HashSet::new(), active: HashMap::new(), settled: true }
    }

    /// The cut drawn at `t_s`: which of its tiles morph, and how far.
    /// `next`, the next cut, held until the tiles it coarsens have morphed
    /// down and those it refines have stopped morphing.
    pub fn update(&mut self, t_s: f64, cut: &[TileId], next: Option<&[TileId]>) -> Vec<Morphing> {
        for &id in cut.iter().filter(|id| !self.drawn.contains(id)) {
            if let Some(coarse) = ancestors(id).find(|a| self.drawn.contains(a)) {
                let mut track = MorphTrack::new(coarse.level as u8, self.tau_s);
                track.request(id.level as u8, t_s);
                self.active.insert(id, Track { coarse, track });
            }
        }
        self.drawn = cut.iter().copied().collect();
        self.settled = true;
        let next = next.unwrap_or_default();
        self.downmorph(cut, next, t_s);
        self.active.retain(|id, m| {
            m.track.prune(t_s);
            self.drawn.contains(id)
                && (m.track.level_at(t_s) < f64::from(id.level) || !m.track.transitions().is_empty())
        });
        self.settled &= !self.refines_morphing(next);
        let mut out: Vec<Morphing> = self
            .active
            .iter()
            .map(|(&tile, m)| {
                let coarse = f64::from(m.coarse.level);
                let weight = (m.track.level_at(t_s) - coarse) / (f64::from(tile.level) - coarse);
                Morphing { tile, from: m.coarse, weight: weight.clamp(0.0, 1.0) }
            })
            .filter(|m| m.weight < 1.0)
            .collect();
        out.sort_by_key(|m| m.tile);
        out
    }

    /// Whether the downmorphs of the last cut drawn were all complete and
    /// no tile the next cut refines was morphing (the next cut may be
    /// drawn: its coarse tiles lie where they ended, its fine ones start
    /// from their ancestors' own surfaces).
    pub fn settled(&self) -> bool {
        self.settled
    }

    /// `cut` with each tile not drawn last whose nearest drawn ancestor is
    /// still morphing replaced by that ancestor (once, in the place of the
    /// first tile it replaces; the cut as it is when none is). A finer tile starts
    /// from its ancestor's own surface, drawn only when the ancestor's
    /// morph is done: a tile that arrives under a stand-in still morphing
    /// (the ancestor drawn while it loaded) waits that long, `τ` unless a
    /// held cut sends the ancestor back up or down meanwhile.
    pub fn hold_under_morphing(&self, cut: &[TileId]) -> Vec<TileId> {
        let held = |id: TileId| {
            let drawn = (!self.drawn.contains(&id)).then(|| ancestors(id).find(|a| self.drawn.contains(a)));
            drawn.flatten().filter(|a| self.active.contains_key(a)).unwrap_or(id)
        };
        let mut seen = HashSet::new();
        cut.iter().map(|&id| held(id)).filter(|&id| seen.insert(id)).collect()
    }

    /// Whether `next` refines a tile that is morphing.
    pub fn refines_morphing(&self, next: &[TileId]) -> bool {
        let refined: HashSet<TileId> = next.iter().flat_map(|&id| ancestors(id)).collect();
        self.active.keys().any(|id| refined.contains(id))
    }

    /// Sends each tile of `cut` that `next` coarsens down to its ancestor
    /// there, and each heading down that `next` no longer coarsens (the
    /// held cut was replaced) back up to its own level.
    fn downmorph(&mut self, cut: &[TileId], next: &[TileId], t_s: f64) {
        let next: HashSet<TileId> = next.iter().copied().collect();
        for &id in cut {
            match ancestors(id).find(|a| next.contains(a)) {
                Some(coarse) => self.coarsen(id, coarse, t_s),
                None => self.restore(id, t_s),
            }
        }
    }

    /// `id` reaches `coarse`'s level within `τ` of the first frame that asks
    /// (001: before the switch; an upmorph in the same interval collapses
    /// with it); asked again, its morph goes on. A tile blends with one
    /// coarser surface at a time: morphing with another ancestor's, it
    /// first returns to its own (the held cut waits).
    fn coarsen(&mut self, id: TileId, coarse: TileId, t_s: f64) {
        if self.active.get(&id).is_some_and(|m| m.coarse != coarse) {
            self.restore(id, t_s);
            self.settled = false;
            return;
        }
        let tau_s = self.tau_s;
        let m =
            self.active.entry(id).or_insert_with(|| Track { coarse, track: MorphTrack::new(id.level as u8, tau_s) });
        m.coarse = coarse;
        m.track.request(coarse.level as u8, t_s + tau_s);
        self.settled &= m.track.level_at(t_s) <= f64::from(coarse.level);
    }

    /// `id` back up to its own level over `τ` from `t_s`, if it is heading
    /// down.
    fn restore(&mut self, id: TileId, t_s: f64) {
        if let Some(m) = self.active.get_mut(&id)
            && m.track.target() < f64::from(id.level)
        {
            m.track.request(id.level as u8, t_s);
        }
    }
}

/// The strict ancestors of `id`, nearest first.
fn ancestors(id: TileId) -> impl Iterator<Item = TileId> {
    std::iter::successors(id.parent(), |p| p.parent())
}

/// The tiles prepared to draw morphs, by the serials of the tile and of
/// the coarser one: each is prepared once and kept while its morph lasts
/// (dropped on the first frame that does not ask for it).
#[derive(Default)]
pub struct Pairs {
    last: HashMap<(u64, u64), Arc<TileData>>,
    this: HashMap<(u64, u64), Arc<TileData>>,
}

impl Pairs {
    /// Starts a frame: the pairs the last one did not ask for are dropped.
    pub fn next_frame(&mut self) {
        self.last = std::mem::take(&mut self.this);
    }

    /// `tile` drawn morphing with `from` ([`pair`]).
    pub fn get(&mut self, grid: &TileGrid, tile: &TileData, from: &TileData) -> Arc<TileData> {
        let key = (tile.serial, from.serial);
        let prepared = match self.last.remove(&key).or_else(|| self.this.get(&key).cloned()) {
            Some(p) => p,
            None => Arc::new(pair(grid, tile, from)),
        };
        self.this.insert(key, prepared.clone());
        prepared
    }
}

/// `tile` drawn morphing from or to `from`'s surface, on `grid`: prepared
/// once per morph, its weight given per draw (the GPU blends the two
/// surfaces, [`TileData::morphing`]).
pub fn pair(grid: &TileGrid, tile: &TileData, from: &TileData) -> TileData {
    let drops = tile.frame.drops_m(tile.halo);
    let local: Vec<[f32; 2]> =
        coarse_surface(grid, tile, from).iter().zip(&drops).map(|(h, d)| h.map(|v| (v + d) as f32)).collect();
    tile.morphing(&local, from.range.heights_m)
}

/// `tile` with its heights moved from `from`'s surface toward its own by
/// `weight`, prepared on `grid` as a tile of its own: what [`pair`] draws
/// at that weight (the CPU reference renders it).
pub fn blend(grid: &TileGrid, tile: &TileData, from: &TileData, weight: f64) -> Result<TileData, TileError> {
    let own = Heights::of(tile);
    let coarse = coarse_surface(grid, tile, from);
    let size = tile.size;
    // Payload order: row 0 at the north.
    let mut payload = TilePayload {
        id: tile.id(),
        halo: tile.halo,
        cem: vec![f32::NAN; size * size],
        dem: vec![f32::NAN; size * size],
        surface: vec![0; size * size],
        colour: vec![[0; 4]; size * size],
    };
    for y in 0..size {
        for x in 0..size {
            let k = (size - 1 - y) * size + x;
            for layer in 0..2 {
                let mine = own.at(layer, x, y);
                let theirs = coarse[y * size + x][layer];
                let v = if theirs.is_nan() { mine } else { morphed_height(theirs, mine, weight) };
                [&mut payload.cem, &mut payload.dem][layer][k] = v as f32;
            }
            payload.surface[k] = tile.surface[y * size + x];
            payload.colour[k] = tile.colour[y * size + x];
        }
    }
    TileData::prepare(grid, payload)
}

/// `from`'s CEM and ground at each texel of `tile` (halo included, rows
/// south-up), metres above the ellipsoid, NaN where it has none: bilinear
/// between its samples, the surface the ray caster drew.
fn coarse_surface(grid: &TileGrid, tile: &TileData, from: &TileData) -> Vec<[f64; 2]> {
    let coarse = Heights::of(from);
    let sector = grid.sector(tile.id());
    let outer = grid.sector(from.id());
    let n = f64::from(grid.samples() - 1);
    let (step_lon, step_lat) = ((sector.max_lon - sector.min_lon) / n, (sector.max_lat - sector.min_lat) / n);
    let (outer_lon, outer_lat) = ((outer.max_lon - outer.min_lon) / n, (outer.max_lat - outer.min_lat) / n);
    let b = tile.halo as f64;
    (0..tile.size * tile.size)
        .map(|k| {
            let (x, y) = ((k % tile.size) as f64, (k / tile.size) as f64);
            let fx = (sector.min_lon + (x - b) * step_lon - outer.min_lon) / outer_lon;
            let fy = (sector.min_lat + (y - b) * step_lat - outer.min_lat) / outer_lat;
            [0, 1].map(|layer| coarse.bilinear(layer, fx, fy))
        })
        .collect()
}

/// A tile's CEM and ground above the ellipsoid (NaN for nodata), rows
/// south-up, with its halo.
struct Heights {
    halo: usize,
    size: usize,
    layers: [Vec<f64>; 2],
}

impl Heights {
    fn of(tile: &TileData) -> Heights {
        let drops = tile.frame.drops_m(tile.halo);
        let layer = |c: usize| -> Vec<f64> {
            tile.texels
                .iter()
                .zip(&drops)
                .map(|(t, d)| if t[c] <= NODATA_M { f64::NAN } else { f64::from(t[c]) - d })
                .collect()
        };
        Heights { halo: tile.halo, size: tile.size, layers: [layer(0), layer(1)] }
    }

    /// At texel `(x, y)` (halo included).
    fn at(&self, layer: usize, x: usize, y: usize) -> f64 {
        self.layers[layer][y * self.size + x]
    }

    /// Bilinear at sample index `(i, j)` (east, north; 0 at the sector's
    /// south-west corner), clamped to the texels.
    fn bilinear(&self, layer: usize, i: f64, j: f64) -> f64 {
        let top = (self.size - 1) as f64;
        let (x, y) = ((i + self.halo as f64).clamp(0.0, top), (j + self.halo as f64).clamp(0.0, top));
        let (x0, y0) = ((x.floor() as usize).min(self.size - 2), (y.floor() as usize).min(self.size - 2));
        let (u, v) = (x - x0 as f64, y - y0 as f64);
        let h = |dx: usize, dy: usize| self.at(layer, x0 + dx, y0 + dy);
        (h(0, 0) * (1.0 - u) + h(1, 0) * u) * (1.0 - v) + (h(0, 1) * (1.0 - u) + h(1, 1) * u) * v
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const HALO: usize = 2;

    /// Heights that curve within a tile, so a child's own samples leave
    /// its parent's bilinear surface.
    fn f(lon: f64, lat: f64) -> f64 {
        1000.0 + 300.0 * (lon * 500.0).sin() * (lat * 400.0).cos()
    }

    fn grid() -> TileGrid {
        TileGrid::new(36.0, 17).unwrap()
    }

    /// The sample positions (lon, lat) of `id`, south-up rows, halo included.
    fn positions(id: TileId) -> Vec<(f64, f64)> {
        let s = grid().sector(id);
        let size = 17 + 2 * HALO;
        let step = ((s.max_lon - s.min_lon) / 16.0, (s.max_lat - s.min_lat) / 16.0);
        let at = |k: usize| k as f64 - HALO as f64;
        (0..size)
            .flat_map(|y| (0..size).map(move |x| (s.min_lon + at(x) * step.0, s.min_lat + at(y) * step.1)))
            .collect()
    }

    fn tile(id: TileId) -> TileData {
        let size = 17 + 2 * HALO;
        let p = positions(id);
        let north_up = |k: usize| (size - 1 - k / size) * size + k % size;
        let cem: Vec<f32> = (0..size * size).map(|k| f(p[north_up(k)].0, p[north_up(k)].1) as f32).collect();
        let payload = TilePayload {
            id,
            halo: HALO,
            dem: cem.iter().map(|h| h - 10.0).collect(),
            cem,
            surface: vec![1; size * size],
            colour: vec![[90, 120, 60, 255]; size * size],
        };
        TileData::prepare(&grid(), payload).unwrap()
    }

    /// The parent's surface at `(lon, lat)`: bilinear between its samples.
    fn parent_surface(parent: TileId, lon: f64, lat: f64) -> f64 {
        let s = grid().sector(parent);
        let (i, j) = (
            (lon - s.min_lon) / ((s.max_lon - s.min_lon) / 16.0),
            (lat - s.min_lat) / ((s.max_lat - s.min_lat) / 16.0),
        );
        let (i0, j0) = (i.floor(), j.floor());
        let lattice = |a: f64, b: f64| {
            f(s.min_lon + a * (s.max_lon - s.min_lon) / 16.0, s.min_lat + b * (s.max_lat - s.min_lat) / 16.0)
        };
        let (u, v) = (i - i0, j - j0);
        (lattice(i0, j0) * (1.0 - u) + lattice(i0 + 1.0, j0) * u) * (1.0 - v)
            + (lattice(i0, j0 + 1.0) * (1.0 - u) + lattice(i0 + 1.0, j0 + 1.0) * u) * v
    }

    #[test]
    fn a_morphing_tile_starts_on_its_parents_surface_and_ends_on_its_own() {
        let child_id = grid().tile_containing(10.1, 46.35, 10);
        let parent_id = child_id.parent().unwrap();
        let (child, parent) = (tile(child_id), tile(parent_id));
        let p = positions(child_id);
        let size = 17 + 2 * HALO;
        let inner = |k: &usize| (HALO..size - HALO).contains(&(k % size)) && (HALO..size - HALO).contains(&(k / size));
        let mut left_parent = 0.0f64;
        for (w, want) in [(0.0, 0.0), (0.5, 0.5), (1.0, 1.0)] {
            let blended = Heights::of(&blend(&grid(), &child, &parent, w).unwrap());
            for k in (0..size * size).filter(inner) {
                let (lon, lat) = p[k];
                let (coarse, own) = (parent_surface(parent_id, lon, lat), f(lon, lat));
                let expected = coarse + want * (own - coarse);
                let got = blended.at(0, k % size, k / size);
                assert!((got - expected).abs() < 0.01, "w {w} at {k}: {got} vs {expected}");
                assert!((blended.at(1, k % size, k / size) - (expected - 10.0)).abs() < 0.01);
                left_parent = left_parent.max((own - coarse).abs());
            }
        }
        assert!(left_parent > 1.0, "the child's own samples leave the parent's surface: {left_parent}");
    }

    #[test]
    fn a_refined_tile_morphs_from_the_switch_frame_and_is_done_in_tau() {
        let child = grid().tile_containing(10.1, 46.35, 10);
        let (parent, grandparent) = (child.parent().unwrap(), child.parent().unwrap().parent().unwrap());
        let children: Vec<TileId> = parent.children().to_vec();
        let mut m = Morphs::new(1.0);
        assert!(m.update(0.0, &[grandparent], None).is_empty());
        // Two levels at once: every child morphs from the grandparent.
        let at_switch = m.update(0.25, &children, None);
        assert_eq!(at_switch.len(), 4);
        assert!(at_switch.iter().all(|x| x.from == grandparent && x.weight == 0.0), "{at_switch:?}");
        let halfway = m.update(0.75, &children, None);
        assert!(halfway.iter().all(|x| (x.weight - 0.5).abs() < 1e-12), "{halfway:?}");
        assert!(m.update(1.25, &children, None).is_empty(), "done after τ");
        // A tile with no coarser one drawn before does not morph.
        let far = grid().tile_containing(12.0, 47.0, 8);
        assert!(m.update(1.5, &[far], None).is_empty());
    }

    #[test]
    fn tiles_arriving_under_a_morphing_stand_in_wait_for_its_morph() {
        // Regression: the selection refined the grandparent to the
        // grandchildren; the parent stood in while they loaded, morphing
        // from the grandparent. Grandchildren loaded mid-morph started from
        // the parent's own surface while it was drawn blended: a jump of
        // (1 − w)·Δ.
        let child = grid().tile_containing(10.1, 46.35, 10);
        let (parent, grandparent) = (child.parent().unwrap(), child.parent().unwrap().parent().unwrap());
        let children = parent.children().to_vec();
        let mut m = Morphs::new(1.0);
        m.update(0.0, &[grandparent], None);
        assert_eq!(m.hold_under_morphing(&children), children, "nothing morphs: as selected");
        m.update(0.25, &[parent], None);
        assert_eq!(m.hold_under_morphing(&children), vec![parent], "the stand-in morphs: held");
        let elsewhere = TileId::new(10, 0, 0);
        assert_eq!(m.hold_under_morphing(&[elsewhere, parent]), vec![elsewhere, parent]);
        m.update(1.25, &[parent], None);
        assert_eq!(m.hold_under_morphing(&children), children, "its morph done: drawn, from its own surface");
        let arrived = m.update(1.3, &children, None);
        assert!(arrived.iter().all(|x| x.from == parent && x.weight == 0.0), "{arrived:?}");
    }

    #[test]
    fn coarsened_tiles_reach_the_coarser_surface_before_the_switch() {
        let child = grid().tile_containing(10.1, 46.35, 10);
        let parent = child.parent().unwrap();
        let children = parent.children().to_vec();
        let mut m = Morphs::new(1.0);
        m.update(0.0, &children, None);
        assert!(m.settled());
        // The next cut coarsens back to the parent, offered at 0.5 s: the
        // children glide onto its surface over [0.5, 1.5] s.
        let next = [parent];
        assert!(m.update(0.5, &children, Some(&next)).is_empty(), "not started");
        assert!(!m.settled());
        let halfway = m.update(1.0, &children, Some(&next));
        assert_eq!(halfway.len(), 4);
        assert!(halfway.iter().all(|x| x.from == parent && (x.weight - 0.5).abs() < 1e-12), "{halfway:?}");
        let done = m.update(1.5, &children, Some(&next));
        assert!(done.iter().all(|x| x.weight == 0.0) && done.len() == 4, "on the parent's surface: {done:?}");
        assert!(m.settled());
        // The switch: the parent is drawn with its own heights, which is
        // where the children ended (blend at weight 0 is its surface).
        assert!(m.update(1.6, &next, None).is_empty());
    }

    #[test]
    fn a_refinement_undone_in_its_interval_collapses_into_one_morph() {
        let child = grid().tile_containing(10.1, 46.35, 10);
        let parent = child.parent().unwrap();
        let children = parent.children().to_vec();
        let mut m = Morphs::new(1.0);
        m.update(0.0, &[parent], None);
        let up = m.update(0.5, &children, None);
        assert!(up.iter().all(|x| x.weight == 0.0));
        // The next cut, offered at once, coarsens back: the upmorph over
        // [0.5, 1.5] and the downmorph there become one, staying on the
        // parent's surface; no weight ever leaves it.
        let next = [parent];
        for t in [0.5, 0.8, 1.2, 1.5] {
            let w = m.update(t, &children, Some(&next));
            assert!(w.len() == 4 && w.iter().all(|x| x.weight == 0.0), "{t}: {w:?}");
        }
        assert!(m.settled());
    }

    /// Four tiles of level 10, their parent, a sibling of the parent and
    /// that sibling's children.
    fn family() -> (Vec<TileId>, TileId, TileId, Vec<TileId>) {
        let parent = grid().tile_containing(10.1, 46.35, 10).parent().unwrap();
        let sibling = parent.parent().unwrap().children().into_iter().find(|&t| t != parent).unwrap();
        (parent.children().to_vec(), parent, sibling, sibling.children().to_vec())
    }

    /// Whether `morphing` is `tiles` at `weight`.
    fn at(morphing: &[Morphing], tiles: &[TileId], weight: f64) -> bool {
        let mut drawn: Vec<TileId> = morphing.iter().map(|m| m.tile).collect();
        let mut tiles = tiles.to_vec();
        drawn.sort();
        tiles.sort();
        drawn == tiles && morphing.iter().all(|m| (m.weight - weight).abs() < 1e-12)
    }

    #[test]
    fn tiles_a_replaced_held_cut_no_longer_coarsens_glide_back_up() {
        // Regression: they stayed on the parent's surface for good.
        let (children, parent, ..) = family();
        let mut m = Morphs::new(1.0);
        m.update(0.0, &children, None);
        m.update(0.5, &children, Some(&[parent]));
        // Halfway down, the held cut is replaced by one keeping them.
        let back = m.update(1.0, &children, Some(&children));
        assert!(at(&back, &children, 0.5), "{back:?}");
        let back = m.update(1.5, &children, Some(&children));
        assert!(at(&back, &children, 0.75) && m.settled(), "{back:?}");
        assert!(m.update(2.0, &children, None).is_empty(), "back on their own surface");
    }

    #[test]
    fn tiles_only_a_replacing_held_cut_coarsens_start_down_then() {
        // Regression: their downmorph began when the first held cut came,
        // so they jumped from their own surface to weight 0.3.
        let (children, parent, sibling, nephews) = family();
        let cut = [children.as_slice(), &nephews].concat();
        let (first, second) = ([&[parent][..], &nephews].concat(), [parent, sibling]);
        let mut m = Morphs::new(1.0);
        m.update(0.0, &cut, None);
        m.update(0.5, &cut, Some(&first));
        let morphing = m.update(1.2, &cut, Some(&second));
        assert!(at(&morphing, &children, 0.3), "{morphing:?}");
        let (theirs, mine): (Vec<Morphing>, Vec<Morphing>) =
            m.update(1.7, &cut, Some(&second)).into_iter().partition(|x| x.tile.parent() == Some(sibling));
        assert!(at(&theirs, &nephews, 0.5) && at(&mine, &children, 0.0) && !m.settled(), "{theirs:?}");
        assert!(at(&m.update(2.2, &cut, Some(&second)), &cut, 0.0) && m.settled());
    }

    #[test]
    fn a_cut_refining_a_tile_still_morphing_waits_for_it() {
        // Regression: grandchildren drawn while their parent morphed up
        // from its own parent started from the parent's own surface, not
        // the one drawn (a jump of 1 − w times their difference).
        let (children, parent, ..) = family();
        let grandchildren = children[0].children();
        let next = [&grandchildren[..], &children[1..]].concat();
        let mut m = Morphs::new(1.0);
        m.update(0.0, &[parent], None);
        m.update(0.25, &children, None);
        assert!(m.refines_morphing(&next));
        m.update(0.5, &children, Some(&next));
        assert!(!m.settled(), "held while the children morph up");
        m.update(1.25, &children, Some(&next));
        assert!(m.settled() && !m.refines_morphing(&next));
        let up = m.update(1.3, &next, None);
        assert!(at(&up, &grandchildren, 0.0) && up.iter().all(|x| x.from == children[0]), "{up:?}");
    }

    #[test]
    fn a_tile_keeps_the_coarser_surface_it_morphs_with() {
        // Regression: asked for another ancestor mid-morph, it blended with
        // that one's surface from the next frame (a jump).
        let (children, parent, ..) = family();
        let grandparent = parent.parent().unwrap();
        let mut m = Morphs::new(1.0);
        m.update(0.0, &children, None);
        m.update(0.5, &children, Some(&[parent]));
        let back = m.update(1.0, &children, Some(&[grandparent]));
        assert!(at(&back, &children, 0.5) && back.iter().all(|x| x.from == parent), "{back:?}");
        assert!(at(&m.update(1.5, &children, Some(&[grandparent])), &children, 0.75) && !m.settled());
        // Back on its own surface at 2 s, it starts down to the grandparent.
        for t in [2.0, 2.5] {
            assert!(m.update(t, &children, Some(&[grandparent])).is_empty());
        }
        let down = m.update(3.0, &children, Some(&[grandparent]));
        assert!(at(&down, &children, 0.5) && down.iter().all(|x| x.from == grandparent), "{down:?}");
        // Morphing up from the grandparent, coarsened to the parent.
        let mut m = Morphs::new(1.0);
        m.update(0.0, &[grandparent], None);
        m.update(0.25, &children, None);
        let up = m.update(0.5, &children, Some(&[parent]));
        assert!(up.iter().all(|x| x.from == grandparent) && !m.settled(), "{up:?}");
    }
}
