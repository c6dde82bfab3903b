//! Individual trees near the camera as point splats (000 §4–5, dissertation
//! §8.4): trees on a jittered grid inside the forest cover, in groups of at
//! most 64, each group with a splat budget (its continuous variable).
//!
//! **World-anchored.** Grid cell `(i, j)` covers `[i s, (i+1) s) × [j s,
//! (j+1) s)` in world metres; its tree (at most one) sits at a hashed offset
//! inside the cell and exists iff a hashed number is below the cover there,
//! so the tree density follows the cover and a tree's position, size and
//! rank depend only on its cell and the seed — never on which tiles are
//! loaded or in what order. A group is a block of 8 × 8 cells (≤ 64 trees).
//!
//! **Partial budgets** (000 §5.4): a group whose budget is below one splat
//! per tree draws only that many trees, those of lowest hashed rank, so
//! raising the budget adds trees and never removes one; above, splats are
//! shared evenly.
//!
//! **Blending into the canopy**: trees are the canopy's near-field
//! representation. Over a band around the splat range, splat opacity goes
//! from 1 to 0 while the ray-cast canopy's displacement scale goes from 0 to
//! 1 ([`canopy_blend`]), the two always summing to 1, so trees neither pop
//! out of nor double the canopy. Where a budget leaves trees undrawn the
//! client lets the canopy give way only by the share drawn
//! (`client::raycast::TreeBlend`).

use super::split::Item;
use crate::noise::{hash2, unit};
use glam::{DVec2, DVec3};

/// Cells a group spans on a side (8 × 8 = 64 trees at most).
pub const GROUP_CELLS: i64 = 8;

/// The tree field's parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TreeField {
    /// Grid spacing, metres (one tree per cell at full cover).
    pub spacing_m: f64,
    /// Seed of the hashes.
    pub seed: u64,
    /// Splats of a tree at full resolution.
    pub splats_per_tree: u32,
}

/// One tree.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Tree {
    /// Position, world metres (x east, y north).
    pub position_m: DVec2,
    /// Size factor in [0.7, 1.3) (scales the crown and its splats).
    pub scale: f64,
    /// Drawing order within partial budgets (lower first).
    pub rank: u16,
    /// Its lattice cell `(i, j)`.
    pub cell: (i64, i64),
}

/// A group of at most 64 trees: the 8 × 8 cells of block `(gi, gj)`.
#[derive(Clone, Debug, PartialEq)]
pub struct Group {
    /// Block index.
    pub block: (i64, i64),
    /// Its trees, by rank.
    pub trees: Vec<Tree>,
}

impl TreeField {
    /// The tree of cell `(i, j)`, if the cover there grows one.
    pub fn tree(&self, i: i64, j: i64, cover: &dyn Fn(DVec2) -> f64) -> Option<Tree> {
        let h = hash2(i, j, self.seed);
        let s = self.spacing_m;
        let position_m = DVec2::new((i as f64 + unit(h, 0)) * s, (j as f64 + unit(h, 1)) * s);
        let c = cover(position_m);
        (unit(h, 2) < if c.is_finite() { c } else { 0.0 }).then(|| Tree {
            position_m,
            scale: 0.7 + 0.6 * unit(h, 3),
            rank: (hash2(j, i, self.seed ^ 0x5EED) & 0xFFFF) as u16,
            cell: (i, j),
        })
    }

    /// The group of block `(gi, gj)` (empty where there is no forest).
    pub fn group(&self, gi: i64, gj: i64, cover: &dyn Fn(DVec2) -> f64) -> Group {
        let mut trees: Vec<Tree> = (0..GROUP_CELLS * GROUP_CELLS)
            .filter_map(|k| self.tree(gi * GROUP_CELLS + k % GROUP_CELLS, gj * GROUP_CELLS + k / GROUP_CELLS, cover))
            .collect();
        trees.sort_by_key(|t| t.rank);
        Group { block: (gi, gj), trees }
    }

    /// Side of a group, metres.
    pub fn group_side_m(&self) -> f64 {
        self.spacing_m * GROUP_CELLS as f64
    }

    /// The non-empty groups whose blocks meet the box `[min_m, max_m]`.
    pub fn groups_in(&self, min_m: DVec2, max_m: DVec2, cover: &dyn Fn(DVec2) -> f64) -> Vec<Group> {
        let side = self.group_side_m();
        if !crate::lod::positive(side) || !min_m.is_finite() || !max_m.is_finite() {
            return Vec::new();
        }
        let (lo, hi) = ((min_m / side).floor(), (max_m / side).floor());
        let mut out = Vec::new();
        for gj in lo.y as i64..=hi.y as i64 {
            for gi in lo.x as i64..=hi.x as i64 {
                let g = self.group(gi, gj, cover);
                if !g.trees.is_empty() {
                    out.push(g);
                }
            }
        }
        out
    }

    /// The group as the variable-splitting hierarchy sees it, at ground
    /// height `height_m`.
    pub fn item(&self, group: &Group, height_m: f64) -> Item {
        let side = self.group_side_m();
        let corner = DVec2::new(group.block.0 as f64, group.block.1 as f64) * side;
        let center = corner + DVec2::splat(side / 2.0);
        Item {
            center_m: DVec3::new(center.x, center.y, height_m),
            radius_m: side * std::f64::consts::FRAC_1_SQRT_2,
            trees: group.trees.len() as u32,
            capacity: (group.trees.len() as u64 * u64::from(self.splats_per_tree)) as f64,
        }
    }
}

/// Splats per tree for a group of `trees` trees (by rank) given a budget of
/// `budget` splats, at most `max_per_tree` each.
pub fn distribute(budget: f64, trees: usize, max_per_tree: u32) -> impl Iterator<Item = u32> {
    let total = if budget.is_finite() { budget.max(0.0).floor() } else { 0.0 };
    let total = total.min((trees as f64) * f64::from(max_per_tree)) as u64;
    let n = trees.max(1) as u64;
    let (each, extra) = (total / n, total % n);
    (0..trees as u64).map(move |k| (each + u64::from(k < extra)) as u32)
}

/// Splat opacity and canopy displacement scale at `distance_m`: splats only
/// inside `splat_range_m − band_m / 2`, canopy only beyond
/// `splat_range_m + band_m / 2`, a smoothstep between; they sum to 1.
pub fn canopy_blend(distance_m: f64, splat_range_m: f64, band_m: f64) -> (f64, f64) {
    let band = band_m.max(1e-9);
    let t = ((distance_m - (splat_range_m - band / 2.0)) / band).clamp(0.0, 1.0);
    let t = if t.is_nan() { 1.0 } else { t };
    let canopy = t * t * (3.0 - 2.0 * t);
    (1.0 - canopy, canopy)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    const FIELD: TreeField = TreeField { spacing_m: 6.0, seed: 42, splats_per_tree: 32 };

    /// Forest west of x = 0, a 30 % stand between 0 and 600 m, none beyond.
    fn cover(p: DVec2) -> f64 {
        if p.x < 0.0 {
            1.0
        } else if p.x < 600.0 {
            0.3
        } else {
            0.0
        }
    }

    #[test]
    fn groups_hold_at_most_64_trees_inside_their_block() {
        for g in FIELD.groups_in(DVec2::new(-300.0, -300.0), DVec2::new(700.0, 300.0), &cover) {
            assert!(!g.trees.is_empty() && g.trees.len() <= 64);
            let side = FIELD.group_side_m();
            let lo = DVec2::new(g.block.0 as f64, g.block.1 as f64) * side;
            for t in &g.trees {
                assert!(t.position_m.cmpge(lo).all() && t.position_m.cmplt(lo + side).all());
                assert!(cover(t.position_m) > 0.0, "trees only inside the forest");
            }
            assert!(g.trees.windows(2).all(|w| w[0].rank <= w[1].rank));
        }
    }

    #[test]
    fn density_follows_cover() {
        let count = |x0: f64| {
            FIELD
                .groups_in(DVec2::new(x0, 0.0), DVec2::new(x0 + 480.0, 480.0), &cover)
                .iter()
                .map(|g| g.trees.len())
                .sum::<usize>()
        };
        // Each window meets 11 × 11 blocks of 8 × 8 cells.
        let cells = (11.0f64 * 8.0).powi(2);
        let full = count(-1000.0) as f64 / cells;
        let thin = count(60.0) as f64 / cells;
        assert!(full > 0.97, "{full}");
        assert!((thin - 0.3).abs() < 0.03, "{thin}");
        assert_eq!(count(700.0), 0);
    }

    proptest! {
        #[test]
        fn trees_depend_only_on_world_position(x0 in -500.0f64..500.0, y0 in -500.0f64..500.0, dx in 0.0f64..200.0) {
            // Two overlapping windows (two tiles, loaded in either order)
            // agree on every group they share.
            let a = FIELD.groups_in(DVec2::new(x0, y0), DVec2::new(x0 + 200.0, y0 + 100.0), &cover);
            let b = FIELD.groups_in(DVec2::new(x0 + dx, y0), DVec2::new(x0 + dx + 200.0, y0 + 100.0), &cover);
            for g in &a {
                if let Some(h) = b.iter().find(|h| h.block == g.block) {
                    prop_assert_eq!(g, h);
                }
            }
        }

        #[test]
        fn budgets_add_trees_and_never_remove_one(trees in 1usize..64, b in 0.0f64..4000.0, more in 0.0f64..100.0) {
            let lo: Vec<u32> = distribute(b, trees, 32).collect();
            let hi: Vec<u32> = distribute(b + more, trees, 32).collect();
            prop_assert!(lo.iter().zip(&hi).all(|(l, h)| l <= h));
            prop_assert_eq!(lo.iter().map(|&x| u64::from(x)).sum::<u64>(), (b.floor() as u64).min(trees as u64 * 32));
            if b < trees as f64 {
                prop_assert_eq!(lo.iter().filter(|&&x| x > 0).count(), b.floor() as usize, "a fraction of the group");
            }
        }

        #[test]
        fn splats_and_canopy_always_sum_to_one(d in -10.0f64..2000.0, range in 0.0f64..1000.0, band in 0.0f64..300.0) {
            let (s, c) = canopy_blend(d, range, band);
            prop_assert!((s + c - 1.0).abs() < 1e-12 && (0.0..=1.0).contains(&s));
        }
    }

    #[test]
    fn blend_ends_and_odd_inputs() {
        assert_eq!(canopy_blend(0.0, 500.0, 100.0), (1.0, 0.0));
        assert_eq!(canopy_blend(600.0, 500.0, 100.0), (0.0, 1.0));
        assert_eq!(canopy_blend(f64::NAN, 500.0, 100.0), (0.0, 1.0));
        assert_eq!(distribute(f64::NAN, 5, 8).sum::<u32>(), 0);
        assert!(FIELD.groups_in(DVec2::NAN, DVec2::ONE, &cover).is_empty());
        assert!(FIELD.tree(3, 4, &|_| f64::NAN).is_none());
    }
}
