//! The quadtree walk of a seed: which tiles, in which order, and which shard
//! seeds each.
//!
//! The walk, over any of the [`Pyramid`]s, starts at the level-0 tiles the
//! coverage meets and descends depth first, children in row-major order
//! (World Wind's from the south-west, the quadtree sets' from the
//! north-west), pruning subtrees outside the coverage; tiles outside the level range are
//! passed through, not seeded. Counting a subtree wholly inside the coverage
//! is a closed form (4^k tiles k levels down), so a dry run costs the
//! boundary only.
//!
//! Shards: the subtrees at a *split level* (the coarsest with at least
//! [`SUBTREES_PER_SHARD`] per shard) are dealt to the shards in walk order
//! in runs of about equal tile counts, so every shard descends into whole
//! subtrees (and can build parents from their children); the few tiles above
//! the split level are dealt by a hash of their address. Every process
//! computes the same split from the same job, so shards are disjoint and
//! together complete.

use super::coverage::{Coverage, Relation};
use super::pyramid::Pyramid;
use crate::grid::TileId;
use std::collections::HashMap;
use std::ops::RangeInclusive;

/// Subtrees per shard at the split level: enough to even out their sizes.
pub const SUBTREES_PER_SHARD: u64 = 16;

/// Shard `index` of `count` (0-based).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Shard {
    /// This shard.
    pub index: u32,
    /// How many.
    pub count: u32,
}

impl Shard {
    /// The whole job.
    pub const ALL: Shard = Shard { index: 0, count: 1 };

    /// This shard's lines of a tile list: every `count`-th from the
    /// `index`-th.
    pub fn of_list<T>(self, lines: Vec<T>) -> Vec<T> {
        lines.into_iter().skip(self.index as usize).step_by(self.count as usize).collect()
    }
}

/// A tile and how it lies against the coverage.
pub type Node = (TileId, Relation);

/// The tiles of a job and their owners.
#[derive(Debug)]
pub struct Walk {
    pyramid: Pyramid,
    coverage: Coverage,
    levels: RangeInclusive<u32>,
    shard: Shard,
    /// The split level and the shard of each subtree there.
    split: Option<(u32, HashMap<TileId, u32>)>,
}

impl Walk {
    /// The walk of `levels` over `coverage` in `pyramid`, for `shard`.
    pub fn new(pyramid: Pyramid, coverage: Coverage, levels: RangeInclusive<u32>, shard: Shard) -> Walk {
        let mut walk = Walk { pyramid, coverage, levels, shard, split: None };
        if shard.count > 1 {
            walk.split = Some(walk.deal());
        }
        walk
    }

    /// The levels seeded.
    pub fn levels(&self) -> RangeInclusive<u32> {
        self.levels.clone()
    }

    /// Level-0 tiles the coverage meets.
    pub fn roots(&self) -> Vec<Node> {
        let (rows, cols) = self.pyramid.level0();
        let all = (0..rows).flat_map(|r| (0..cols).map(move |c| TileId::new(0, r, c)));
        all.filter_map(|t| self.node(t)).filter(|&(t, _)| self.enters(t)).collect()
    }

    /// The children of a node to descend into (none below the last level).
    pub fn children(&self, (tile, relation): Node) -> Vec<Node> {
        if tile.level >= *self.levels.end() {
            return Vec::new();
        }
        let kids = tile.children().into_iter();
        match relation {
            Relation::Inside => kids.map(|t| (t, Relation::Inside)).filter(|&(t, _)| self.enters(t)).collect(),
            _ => kids.filter_map(|t| self.node(t)).filter(|&(t, _)| self.enters(t)).collect(),
        }
    }

    /// True if this shard seeds `tile` (in the level range, and its own).
    pub fn seeds(&self, tile: TileId) -> bool {
        self.levels.contains(&tile.level) && self.owner(tile).is_none_or(|s| s == self.shard.index)
    }

    /// Tiles this shard seeds per level (index 0 = the first level).
    pub fn count_per_level(&self) -> Vec<u64> {
        let mut counts = vec![0; self.levels.clone().count()];
        for root in self.roots() {
            self.tally(root, &mut counts, true);
        }
        counts
    }

    /// Tiles per level left to seed when the subtrees `finished` (disjoint,
    /// as a resumed job's progress file holds them) are skipped.
    pub fn count_left(&self, finished: &[TileId]) -> Vec<u64> {
        let mut done = vec![0; self.levels.clone().count()];
        for node in finished.iter().filter(|t| t.level <= *self.levels.end()).filter_map(|&t| self.node(t)) {
            self.tally(node, &mut done, true);
        }
        self.count_per_level().iter().zip(done).map(|(all, done)| all.saturating_sub(done)).collect()
    }

    fn node(&self, tile: TileId) -> Option<Node> {
        let relation = self.coverage.relation(&self.pyramid.footprint(tile));
        (relation != Relation::Outside).then_some((tile, relation))
    }

    /// True if the walk of this shard goes into `tile`'s subtree.
    fn enters(&self, tile: TileId) -> bool {
        match &self.split {
            Some((level, _)) if tile.level >= *level => self.owner(tile) == Some(self.shard.index),
            _ => true,
        }
    }

    /// The shard that seeds `tile`, if the job is sharded.
    fn owner(&self, tile: TileId) -> Option<u32> {
        let (level, owners) = self.split.as_ref()?;
        let n = u64::from(self.shard.count);
        if tile.level < *level {
            let h = crate::cache::digest(tile.to_string().as_bytes());
            return Some((h % n) as u32);
        }
        let up = tile.level - level;
        owners.get(&TileId::new(*level, tile.row >> up, tile.col >> up)).copied()
    }

    /// Adds the tiles of a subtree to `counts`; `mine` restricts to this shard.
    fn tally(&self, (tile, relation): Node, counts: &mut [u64], mine: bool) {
        let (first, last) = (*self.levels.start(), *self.levels.end());
        if mine && !self.enters(tile) {
            return;
        }
        if relation == Relation::Inside && (!mine || self.split.as_ref().is_none_or(|(l, _)| tile.level >= *l)) {
            // 4^k tiles k levels down.
            for level in tile.level.max(first)..=last {
                counts[(level - first) as usize] += 1u64 << (2 * (level - tile.level)).min(62);
            }
            return;
        }
        if tile.level >= first && (!mine || self.seeds(tile)) {
            counts[(tile.level - first) as usize] += 1;
        }
        if tile.level < last {
            for child in tile.children().into_iter().filter_map(|t| self.node(t)) {
                self.tally(child, counts, mine);
            }
        }
    }

    /// Chooses the split level and deals its subtrees to the shards.
    fn deal(&self) -> (u32, HashMap<TileId, u32>) {
        let want = SUBTREES_PER_SHARD * u64::from(self.shard.count);
        let mut frontier = self.roots();
        while (frontier.len() as u64) < want && frontier.first().is_some_and(|(t, _)| t.level < *self.levels.end()) {
            frontier = frontier.iter().flat_map(|&n| self.kids_in_coverage(n)).collect();
        }
        let level = frontier.first().map_or(0, |(t, _)| t.level);
        let sizes: Vec<u64> = frontier
            .iter()
            .map(|&n| {
                let mut counts = vec![0; self.levels.clone().count()];
                self.tally(n, &mut counts, false);
                counts.iter().sum::<u64>().max(1)
            })
            .collect();
        let total: u64 = sizes.iter().sum();
        let n = u64::from(self.shard.count);
        let mut before = 0u64;
        let owners = frontier
            .iter()
            .zip(&sizes)
            .map(|(&(t, _), &size)| {
                // The shard whose share holds the subtree's middle tile.
                let middle = before + size / 2;
                before += size;
                (t, ((u128::from(middle) * u128::from(n) / u128::from(total)) as u32).min(self.shard.count - 1))
            })
            .collect();
        (level, owners)
    }

    fn kids_in_coverage(&self, (tile, _): Node) -> Vec<Node> {
        tile.children().into_iter().filter_map(|t| self.node(t)).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::quad::TileSet;
    use crate::grid::{BBox, TileGrid};

    fn walk(levels: RangeInclusive<u32>, shard: Shard) -> Walk {
        let bbox = BBox { west: 10.0, south: 46.3, east: 10.25, north: 46.45 };
        Walk::new(Pyramid::WorldWind(TileGrid::new(36.0, 513).unwrap()), Coverage::Box(bbox), levels, shard)
    }

    /// Every tile the walk reaches, in order, and whether it is seeded.
    fn visit(w: &Walk, node: Node, out: &mut Vec<TileId>) {
        for child in w.children(node) {
            visit(w, child, out);
        }
        if w.seeds(node.0) {
            out.push(node.0);
        }
    }

    fn seeded(w: &Walk) -> Vec<TileId> {
        let mut out = Vec::new();
        for root in w.roots() {
            visit(w, root, &mut out);
        }
        out
    }

    #[test]
    fn counts_match_the_walk_and_children_come_before_parents() {
        let w = walk(3..=11, Shard::ALL);
        let tiles = seeded(&w);
        let counts = w.count_per_level();
        assert_eq!(counts.iter().sum::<u64>(), tiles.len() as u64);
        for level in 3..=11 {
            assert_eq!(counts[(level - 3) as usize], tiles.iter().filter(|t| t.level == level).count() as u64);
        }
        let position: HashMap<TileId, usize> = tiles.iter().enumerate().map(|(i, &t)| (t, i)).collect();
        for (i, t) in tiles.iter().enumerate() {
            for c in t.children() {
                assert!(position.get(&c).is_none_or(|&j| j < i), "{c} after its parent {t}");
            }
        }
    }

    #[test]
    fn tiles_left_are_those_outside_the_finished_subtrees() {
        let w = walk(3..=11, Shard::ALL);
        let tiles = seeded(&w);
        let inside = |t: TileId, root: TileId| std::iter::successors(Some(t), |t| t.parent()).any(|a| a == root);
        // Two finished subtrees: one deep inside, one at the walk's top
        // elsewhere (and one below the walk's levels, which changes nothing).
        let deep = tiles.iter().find(|t| t.level == 8).copied().unwrap();
        let top = tiles.iter().copied().filter(|&t| !inside(deep, t)).min_by_key(|t| t.level).unwrap();
        assert!(top.level < 8, "{top}");
        let left: Vec<_> = tiles.iter().filter(|&&t| !inside(t, top) && !inside(t, deep)).collect();
        let counts = w.count_left(&[top, deep, TileId::new(12, 0, 0)]);
        for level in 3..=11 {
            assert_eq!(
                counts[(level - 3) as usize],
                left.iter().filter(|t| t.level == level).count() as u64,
                "level {level}"
            );
        }
        assert!(counts.iter().sum::<u64>() < w.count_per_level().iter().sum::<u64>());
    }

    #[test]
    fn shards_are_disjoint_complete_and_balanced() {
        let all = seeded(&walk(2..=11, Shard::ALL));
        let mut union = Vec::new();
        let mut sizes = Vec::new();
        for index in 0..4 {
            let w = walk(2..=11, Shard { index, count: 4 });
            let mine = seeded(&w);
            assert_eq!(w.count_per_level().iter().sum::<u64>(), mine.len() as u64);
            sizes.push(mine.len());
            union.extend(mine);
        }
        let n = union.len();
        union.sort();
        union.dedup();
        assert_eq!(union.len(), n, "a tile in two shards");
        let mut expected = all.clone();
        expected.sort();
        assert_eq!(union, expected);
        let (lo, hi) = (*sizes.iter().min().unwrap(), *sizes.iter().max().unwrap());
        assert!(hi as f64 <= 1.3 * lo as f64, "unbalanced: {sizes:?}");
    }

    #[test]
    fn a_quadtree_sets_walk_is_its_tiles_over_the_box() {
        let bbox = BBox { west: 10.0, south: 46.3, east: 10.25, north: 46.45 };
        for set in TileSet::ALL {
            let w = Walk::new(Pyramid::Quad(set), Coverage::Box(bbox), 0..=13, Shard::ALL);
            let tiles = seeded(&w);
            for z in 0..=13 {
                let ((c0, r0), (c1, r1)) = set.tiles_over(&bbox, z);
                let mut expected: Vec<TileId> =
                    (r0..=r1).flat_map(|r| (c0..=c1).map(move |c| TileId::new(z, r, c))).collect();
                let mut walked: Vec<TileId> = tiles.iter().copied().filter(|t| t.level == z).collect();
                expected.sort();
                walked.sort();
                assert_eq!(walked, expected, "{set:?} zoom {z}");
            }
            assert_eq!(w.count_per_level().iter().sum::<u64>(), tiles.len() as u64);
        }
        // A box ending on tile edges (zoom 3's 22.5° columns and rows of the
        // geographic set) takes no tile beyond them.
        let edges = BBox { west: 0.0, south: 45.0, east: 22.5, north: 67.5 };
        let w = Walk::new(Pyramid::Quad(TileSet::Crs84), Coverage::Box(edges), 3..=3, Shard::ALL);
        assert_eq!(seeded(&w), vec![TileId::new(3, 1, 8)]);
    }
}
