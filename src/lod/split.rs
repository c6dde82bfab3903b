//! Hierarchical splitting of continuous variables (000 §3.5 and Appendix A,
//! dissertation §8.3 "Continuous Variable Hierarchy" and Algorithm 3).
//!
//! Tree groups sit in a static quadtree ([`ObjectTree`]). Instead of one
//! variable per group, a frame ties all groups below a node to one
//! resolution, `x_i = x · capacity_i / capacity` (Eq. 8.16), whenever the
//! benefit that tie loses is small. Appendix A bounds that loss for `X`
//! units over `n` objects in the worst case (all weight in one object) by
//! `W √(X/cap) (1 − 1/√n)`; that bound is near `W √(X/cap)` for any large
//! node, so it never lets one merge. Algorithm 3 already evaluates the
//! children and their Lagrange shares, so the estimate here uses their
//! actual weights instead: the square-root optimum `√X √(Σ W_i²/cap_i)`
//! against the tie `√X Σ W_i / √(Σ cap_i)`. A node whose estimate is below
//! its share of the threshold becomes one variable; otherwise `X` is shared
//! among the children as that Lagrange solution does (`X_i ∝ W_i² / cap_i`)
//! and the children are examined in turn. Culled
//! nodes (the view returns `None`) are skipped with everything below them.
//!
//! The dissertation states the shares two ways that disagree (`θ/4` per
//! level in §8.3, `ε / 2^(d_max − d)` in Algorithm 3); here a node's share
//! is proportional to its weight, `θ_rel · W · φ(X_root / cap_root)`: its
//! part of the benefit the whole budget buys. Shares over any cut of the
//! tree then sum to at most `θ_rel` times that benefit, so the estimated
//! loss is at most that fraction (estimated: `X_i` is itself an estimate,
//! as the dissertation notes). A node merges when its allocated relative
//! resolution is below about `θ_rel²` times the average, so groups that
//! get few splats — far away, small on screen — merge first. The work per frame is the
//! number of nodes visited, which follows the screen, not the number of
//! trees.
//!
//! Invariants: every visible group lies below exactly one variable; nodes
//! cover contiguous ranges of groups (Morton order), so a variable's groups
//! are a slice.

use super::model::Smooth;
use super::optimizer::Continuous;
use glam::DVec3;

/// One tree group as the hierarchy sees it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Item {
    /// Centre of the group, metres (world frame).
    pub center_m: DVec3,
    /// Radius of a sphere around all its trees, metres.
    pub radius_m: f64,
    /// Trees in the group (at most 64).
    pub trees: u32,
    /// Units (splats) at full resolution.
    pub capacity: f64,
}

/// A node of the object quadtree.
#[derive(Clone, Debug, PartialEq)]
pub struct ObjectNode {
    /// Bounding sphere centre, metres.
    pub center_m: DVec3,
    /// Bounding sphere radius, metres.
    pub radius_m: f64,
    /// Groups below, as a range of indices into [`ObjectTree::order`].
    pub first: u32,
    /// Number of groups below.
    pub groups: u32,
    /// Trees below.
    pub trees: u64,
    /// Units at full resolution below.
    pub capacity: f64,
    /// Children (node indices), up to four.
    pub children: Vec<u32>,
}

/// A static quadtree over tree groups; node 0 is the root.
#[derive(Clone, Debug)]
pub struct ObjectTree {
    /// The nodes, parents before children.
    pub nodes: Vec<ObjectNode>,
    /// Group indices (into the items given to [`ObjectTree::build`]) in
    /// Morton order: node `n` holds `order[n.first .. n.first + n.groups]`.
    pub order: Vec<u32>,
}

/// Depth limit of the object quadtree (2^20 cells a side).
const MAX_DEPTH: u32 = 20;

impl ObjectTree {
    /// Builds the quadtree over `items` by their horizontal position (x, y).
    pub fn build(items: &[Item]) -> ObjectTree {
        let (lo, hi) = items.iter().fold((DVec3::splat(f64::MAX), DVec3::splat(f64::MIN)), |(lo, hi), it| {
            (lo.min(it.center_m), hi.max(it.center_m))
        });
        let side = (hi.x - lo.x).max(hi.y - lo.y).max(1e-9);
        let cells = f64::from(1u32 << MAX_DEPTH);
        let cell = |v: f64| ((v / side * cells).floor().clamp(0.0, cells - 1.0)) as u64;
        let mut keyed: Vec<(u64, u32)> = items
            .iter()
            .enumerate()
            .map(|(i, it)| (morton(cell(it.center_m.x - lo.x), cell(it.center_m.y - lo.y)), i as u32))
            .collect();
        keyed.sort_unstable();
        let mut tree = ObjectTree { nodes: Vec::new(), order: keyed.iter().map(|k| k.1).collect() };
        if !items.is_empty() {
            tree.grow(items, &keyed, 0, keyed.len(), 0);
        }
        tree
    }

    /// Adds the node over `keyed[start..end]` at `depth` and its subtree;
    /// returns its index.
    fn grow(&mut self, items: &[Item], keyed: &[(u64, u32)], start: usize, end: usize, depth: u32) -> u32 {
        let index = self.nodes.len() as u32;
        self.nodes.push(bound(items, &self.order[start..end], start as u32));
        if end - start > 1 && depth < MAX_DEPTH {
            let shift = 2 * (MAX_DEPTH - depth - 1);
            let mut a = start;
            while a < end {
                let quadrant = (keyed[a].0 >> shift) & 3;
                let b = a + keyed[a..end].partition_point(|k| (k.0 >> shift) & 3 == quadrant);
                let child = self.grow(items, keyed, a, b, depth + 1);
                self.nodes[index as usize].children.push(child);
                a = b;
            }
        }
        index
    }
}

/// Interleaves the bits of x and y (x in the even bits).
fn morton(x: u64, y: u64) -> u64 {
    let spread = |mut v: u64| {
        v &= 0xFFFF_FFFF;
        v = (v | (v << 16)) & 0x0000_FFFF_0000_FFFF;
        v = (v | (v << 8)) & 0x00FF_00FF_00FF_00FF;
        v = (v | (v << 4)) & 0x0F0F_0F0F_0F0F_0F0F;
        v = (v | (v << 2)) & 0x3333_3333_3333_3333;
        (v | (v << 1)) & 0x5555_5555_5555_5555
    };
    spread(x) | (spread(y) << 1)
}

/// The node over the groups `ids` (which start at `first` in the order).
fn bound(items: &[Item], ids: &[u32], first: u32) -> ObjectNode {
    let n = ids.len().max(1) as f64;
    let center_m = ids.iter().map(|&i| items[i as usize].center_m).sum::<DVec3>() / n;
    let radius_m = ids
        .iter()
        .map(|&i| items[i as usize].center_m.distance(center_m) + items[i as usize].radius_m)
        .fold(0.0, f64::max);
    ObjectNode {
        center_m,
        radius_m,
        first,
        groups: ids.len() as u32,
        trees: ids.iter().map(|&i| u64::from(items[i as usize].trees)).sum(),
        capacity: ids.iter().map(|&i| items[i as usize].capacity).sum(),
        children: Vec::new(),
    }
}

/// Settings of one splitting pass.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SplitSettings {
    /// Acceptable estimated loss, as a fraction of the benefit the budget
    /// buys (each variable's share in proportion to its weight).
    pub loss_fraction: f64,
    /// Predicted ms per unit (splat).
    pub cost_per_unit_ms: f64,
    /// Budget the continuous variables could get at most, ms (bounds `X`).
    pub budget_ms: f64,
    /// The benefit curve.
    pub smooth: Smooth,
}

/// One variable of the split: a node whose groups share one resolution.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Variable {
    /// The object-tree node.
    pub node: u32,
    /// The optimiser's view of it.
    pub continuous: Continuous,
}

/// What a pass did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SplitStats {
    /// Nodes whose view was evaluated.
    pub visited: usize,
    /// Estimated benefit lost by tying groups together (sum of the bounds
    /// of the variables made).
    pub estimated_loss: f64,
}

/// Splits the tree into variables for this frame. `weight` gives a node's
/// full-resolution benefit from the current view (see
/// [`super::model::group_weight`]), or `None` if it is culled.
pub fn split(
    tree: &ObjectTree,
    weight: &mut dyn FnMut(&ObjectNode) -> Option<f64>,
    settings: &SplitSettings,
    out: &mut Vec<Variable>,
) -> SplitStats {
    let mut stats = SplitStats::default();
    let Some(root) = tree.nodes.first() else { return stats };
    stats.visited += 1;
    let Some(w) = weight(root).filter(|w| *w > 0.0) else { return stats };
    let units = if settings.cost_per_unit_ms > 0.0 { settings.budget_ms / settings.cost_per_unit_ms } else { f64::MAX };
    let x = units.clamp(0.0, root.capacity);
    let ratio = settings.smooth.phi(x / root.capacity.max(f64::MIN_POSITIVE));
    let mut pass = Pass { tree, settings, ratio, weight, out, stats };
    pass.visit(0, w, x);
    pass.stats
}

/// One splitting pass: where its variables go and what it counted.
struct Pass<'a> {
    tree: &'a ObjectTree,
    settings: &'a SplitSettings,
    /// Benefit the budget buys per unit of full-resolution weight, over
    /// the whole tree: `φ(X_root / capacity_root)`.
    ratio: f64,
    weight: &'a mut dyn FnMut(&ObjectNode) -> Option<f64>,
    out: &'a mut Vec<Variable>,
    stats: SplitStats,
}

impl Pass<'_> {
    /// Algorithm 3's `SplitVar` for node `n` with weight `w` and estimated
    /// units `x`.
    fn visit(&mut self, n: u32, w: f64, x: f64) {
        let tree = self.tree;
        let node = &tree.nodes[n as usize];
        // Up to four children: on the stack, as this runs for every node seen.
        let mut storage = [(0u32, 0.0, 0.0); 4];
        for (k, &c) in storage.iter_mut().zip(&node.children) {
            self.stats.visited += 1;
            let wc = (self.weight)(&tree.nodes[c as usize]).filter(|w| *w > 0.0).unwrap_or(0.0);
            *k = (c, wc, tree.nodes[c as usize].capacity.max(f64::MIN_POSITIVE));
        }
        let kids = &storage[..node.children.len().min(4)];
        let loss = self.loss_of_tying(kids, x);
        if kids.is_empty() || loss < self.settings.loss_fraction * w * self.ratio {
            self.stats.estimated_loss += loss;
            // The children's weights add up closer to the groups' than the
            // node's own sphere, whose projection overstates near nodes.
            let weight = if kids.is_empty() { w } else { kids.iter().map(|k| k.1).sum() };
            let continuous =
                Continuous { weight, capacity: node.capacity, cost_per_unit_ms: self.settings.cost_per_unit_ms };
            self.out.push(Variable { node: n, continuous });
            return;
        }
        let total: f64 = kids.iter().map(|k| k.1 * k.1 / k.2).sum();
        for &(c, wc, cap) in kids {
            if wc > 0.0 {
                let xc = if total > 0.0 { x * (wc * wc / cap) / total } else { 0.0 };
                self.visit(c, wc, xc.min(cap));
            }
        }
    }

    /// Benefit lost by tying the children `(node, weight, capacity)` to one
    /// relative resolution when they share `x` units: the Lagrange optimum
    /// of square-root benefits, `√x · √(Σ W_i² / cap_i)`, against the tie,
    /// `√x · Σ W_i / √(Σ cap_i)` (over the smoothing's `norm`). This is
    /// Appendix A's estimate with the children's actual weights in place of
    /// its worst case (all weight in one object), which would never let a
    /// large node merge.
    fn loss_of_tying(&self, kids: &[(u32, f64, f64)], x: f64) -> f64 {
        let spread: f64 = kids.iter().map(|k| k.1 * k.1 / k.2).sum();
        let (w, cap): (f64, f64) = kids.iter().fold((0.0, 0.0), |(w, c), k| (w + k.1, c + k.2));
        let loss = x.max(0.0).sqrt() * (spread.sqrt() - w / cap.max(f64::MIN_POSITIVE).sqrt());
        (loss / self.settings.smooth.norm()).max(0.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lod::optimizer::{Forest, Settings, optimize};

    /// `side²` groups of 62 trees on a 50 m grid (side 128: about a million
    /// trees), 64 splats a tree.
    fn forest_of_groups(side: u32) -> Vec<Item> {
        (0..side * side)
            .map(|i| Item {
                center_m: DVec3::new(f64::from(i % side) * 50.0, f64::from(i / side) * 50.0, 0.0),
                radius_m: 25.0,
                trees: 62,
                capacity: 62.0 * 64.0,
            })
            .collect()
    }

    /// Weight from the projected area seen from `eye` (1000 px focal
    /// length), nodes beyond `cull_x_m` culled.
    fn view(eye: DVec3, cull_x_m: f64) -> impl FnMut(&ObjectNode) -> Option<f64> {
        move |n: &ObjectNode| {
            if n.center_m.x - n.radius_m > cull_x_m {
                return None;
            }
            let d = (n.center_m.distance(eye) - n.radius_m).max(1.0);
            let px = std::f64::consts::PI * (n.radius_m * 1000.0 / d).powi(2);
            Some(crate::lod::model::group_weight(px, 64, 1.0) * n.trees as f64 / (64.0 * f64::from(n.groups)))
        }
    }

    fn settings(loss_fraction: f64) -> SplitSettings {
        SplitSettings { loss_fraction, cost_per_unit_ms: 2e-5, budget_ms: 8.0, smooth: Smooth::default() }
    }

    fn groups_of(tree: &ObjectTree, vars: &[Variable]) -> Vec<u32> {
        let mut g: Vec<u32> = vars
            .iter()
            .flat_map(|v| {
                let n = &tree.nodes[v.node as usize];
                tree.order[n.first as usize..(n.first + n.groups) as usize].iter().copied()
            })
            .collect();
        g.sort_unstable();
        g
    }

    #[test]
    fn no_threshold_gives_one_variable_per_group() {
        let items = forest_of_groups(16);
        let tree = ObjectTree::build(&items);
        let mut vars = Vec::new();
        split(&tree, &mut view(DVec3::new(0.0, 0.0, 300.0), f64::MAX), &settings(0.0), &mut vars);
        assert_eq!(vars.len(), items.len());
        assert_eq!(groups_of(&tree, &vars), (0..items.len() as u32).collect::<Vec<_>>());
    }

    #[test]
    fn variables_cover_each_visible_group_once() {
        let items = forest_of_groups(32);
        let tree = ObjectTree::build(&items);
        let mut vars = Vec::new();
        let cull = 700.0;
        split(&tree, &mut view(DVec3::new(100.0, 100.0, 300.0), cull), &settings(0.01), &mut vars);
        let covered = groups_of(&tree, &vars);
        let mut dedup = covered.clone();
        dedup.dedup();
        assert_eq!(dedup, covered, "no group twice");
        let near: Vec<u32> = (0..items.len() as u32).filter(|&i| items[i as usize].center_m.x + 25.0 <= cull).collect();
        assert!(near.iter().all(|g| covered.binary_search(g).is_ok()), "every group that cannot be culled is covered");
        assert!(vars.len() < items.len() / 4, "{} variables", vars.len());
    }

    #[test]
    fn a_million_trees_need_few_variables_and_lose_little() {
        let items = forest_of_groups(128);
        assert!(items.iter().map(|i| u64::from(i.trees)).sum::<u64>() >= 1_000_000);
        let tree = ObjectTree::build(&items);
        let eye = DVec3::new(3200.0, 3200.0, 200.0);
        let mut split_vars = Vec::new();
        let stats = split(&tree, &mut view(eye, f64::MAX), &settings(0.01), &mut split_vars);
        assert!(stats.visited < items.len() / 10, "{} nodes visited", stats.visited);
        let mut all = Vec::new();
        split(&tree, &mut view(eye, f64::MAX), &settings(0.0), &mut all);
        let forest = Forest::default();
        let solve = |vars: &[Variable]| {
            let c: Vec<Continuous> = vars.iter().map(|v| v.continuous).collect();
            optimize(&forest, &c, &Settings::budget(8.0)).benefit
        };
        let (tied, free) = (solve(&split_vars), solve(&all));
        assert!(tied >= 0.98 * free, "{tied} vs {free} with {} variables", split_vars.len());
        assert!(
            free - tied <= stats.estimated_loss + 1e-9 * free,
            "loss {} > estimate {}",
            free - tied,
            stats.estimated_loss
        );
    }

    #[test]
    fn empty_and_culled_trees_give_nothing() {
        let mut vars = Vec::new();
        let empty = ObjectTree::build(&[]);
        assert_eq!(split(&empty, &mut view(DVec3::ZERO, 0.0), &settings(0.01), &mut vars).visited, 0);
        let tree = ObjectTree::build(&forest_of_groups(4));
        split(&tree, &mut |_| None, &settings(0.01), &mut vars);
        assert!(vars.is_empty());
    }
}
