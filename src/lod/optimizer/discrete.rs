//! The discrete half of the optimiser: a forest of LOD hierarchies (one
//! quadtree of tiles, or several trees side by side as in 001 §3.2) and its
//! increments after Mason and Blake: replacing a node by its children adds
//! `Δb = Σ b(children) − b(node)` for `Δc = Σ c(children) − c(node)`.
//!
//! Greedy increments are half-optimal only if the value `Δb/Δc` never grows
//! down the hierarchy (001 §3.1: "if the value of children is less than the
//! value of the parent node"). Real trees break that (a distant parent whose
//! split uncovers one near child), so the increments are made convex first:
//! bottom-up, a node's increment absorbs the best increments that become
//! available after it while they are worth more than the group so far
//! (Horn's algorithm for tree-constrained ratios, with leftist heaps). After
//! this, every group is worth at least as much as any group it makes
//! available, so the greedy order is the order of the fractional (LP)
//! optimum, which gives the half-optimality bound and the upper bound the
//! optimiser reports.
//!
//! Invariants: parents come before their children in the node list (so the
//! forest has no cycles); every node belongs to exactly one group, headed by
//! itself or an ancestor; a group's members form a connected subtree below
//! its head, listed parents first.

use super::LodError;

/// One discrete representation: a node of a LOD hierarchy.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Node {
    /// The coarser representation this one refines (index into the node
    /// list; it must come earlier), or `None` for a root.
    pub parent: Option<u32>,
    /// Benefit of drawing this node (see [`crate::lod::model::tile_benefit`]).
    pub benefit: f64,
    /// Predicted cost of drawing it, ms.
    pub cost_ms: f64,
}

/// "No node".
pub(crate) const NONE: u32 = u32::MAX;

/// A forest of LOD hierarchies with children lists.
#[derive(Clone, Debug, Default)]
pub struct Forest {
    nodes: Vec<Node>,
    roots: Vec<u32>,
    /// Children of node `i`: `children[offsets[i]..offsets[i + 1]]`.
    offsets: Vec<u32>,
    children: Vec<u32>,
}

impl Forest {
    /// Checks and indexes `nodes`. Non-finite or negative benefits count as
    /// 0, negative costs as 0, NaN costs as infinite (never affordable).
    pub fn new(mut nodes: Vec<Node>) -> Result<Forest, LodError> {
        if nodes.len() >= NONE as usize {
            return Err(LodError::TooManyNodes(nodes.len()));
        }
        let mut counts = vec![0u32; nodes.len() + 1];
        for (i, n) in nodes.iter().enumerate() {
            if let Some(p) = n.parent {
                if p as usize >= i {
                    return Err(LodError::ParentAfterChild { node: i as u32, parent: p });
                }
                counts[p as usize] += 1;
            }
        }
        for n in &mut nodes {
            n.benefit = if n.benefit.is_finite() { n.benefit.max(0.0) } else { 0.0 };
            n.cost_ms = if n.cost_ms.is_nan() { f64::INFINITY } else { n.cost_ms.max(0.0) };
        }
        let mut offsets = Vec::with_capacity(nodes.len() + 1);
        let mut acc = 0u32;
        for c in &counts {
            offsets.push(acc);
            acc += c;
        }
        let mut fill = offsets.clone();
        let mut children = vec![0u32; acc as usize];
        let mut roots = Vec::new();
        for (i, n) in nodes.iter().enumerate() {
            match n.parent {
                Some(p) => {
                    children[fill[p as usize] as usize] = i as u32;
                    fill[p as usize] += 1;
                }
                None => roots.push(i as u32),
            }
        }
        Ok(Forest { nodes, roots, offsets, children })
    }

    /// Number of nodes.
    pub fn len(&self) -> usize {
        self.nodes.len()
    }

    /// Whether the forest is empty.
    pub fn is_empty(&self) -> bool {
        self.nodes.is_empty()
    }

    /// Node `i`.
    pub fn node(&self, i: u32) -> &Node {
        &self.nodes[i as usize]
    }

    /// The roots (always drawn: the coarsest representation).
    pub fn roots(&self) -> &[u32] {
        &self.roots
    }

    /// Children of node `i`.
    pub fn children(&self, i: u32) -> &[u32] {
        let i = i as usize;
        &self.children[self.offsets[i] as usize..self.offsets[i + 1] as usize]
    }

    /// The increment of splitting node `i` alone: `(Δb, Δc)`, or `None` for
    /// a leaf.
    pub fn increment(&self, i: u32) -> Option<(f64, f64)> {
        let kids = self.children(i);
        if kids.is_empty() {
            return None;
        }
        let n = self.node(i);
        let (b, c) = kids.iter().fold((0.0, 0.0), |(b, c), &k| (b + self.node(k).benefit, c + self.node(k).cost_ms));
        Some((b - n.benefit, c - n.cost_ms))
    }

    /// Whether every node's cost is finite (a NaN cost counts as ∞).
    pub fn costs_finite(&self) -> bool {
        self.nodes.iter().all(|n| n.cost_ms.is_finite())
    }

    /// Per node: whether its split, or a split below it, adds benefit.
    fn adds_benefit(&self) -> Vec<bool> {
        let mut adds = vec![false; self.len()];
        for v in (0..self.len() as u32).rev() {
            let own = self.increment(v).is_some_and(|(db, _)| db > 0.0);
            adds[v as usize] = own || self.children(v).iter().any(|&c| adds[c as usize]);
        }
        adds
    }

    /// Per node: whether some cut within `budget_ms` splits it (its own
    /// children and every ancestor's drawn, the rest of the forest at its
    /// cheapest). A node no cut affords is never split, so the optimiser
    /// treats it as a leaf: the increments it would make available only
    /// mislead the greedy, whose groups would count benefit no feasible
    /// answer reaches.
    pub fn splittable(&self, budget_ms: f64) -> Vec<bool> {
        let (_, split) = self.cut_costs();
        (0..self.len()).map(|v| !self.children(v as u32).is_empty() && split[v].ms <= budget_ms).collect()
    }

    /// The most benefit of a cut within `budget_ms` that draws one node's
    /// children and the rest of the forest at its cheapest: a lower bound
    /// of the optimum.
    pub fn best_cheapest_cut(&self, budget_ms: f64) -> f64 {
        let (cheapest, split) = self.cut_costs();
        let mut best = f64::NEG_INFINITY;
        for v in (0..self.len() as u32).filter(|&v| !self.children(v).is_empty()) {
            let mut cut = split[v as usize];
            for &c in self.children(v) {
                cut = cut.minus(cheapest[c as usize]).plus(Drawing::of(self.node(c)));
            }
            if cut.ms <= budget_ms {
                best = best.max(cut.benefit);
            }
        }
        best
    }

    /// What the cheapest cut costs, ms.
    pub fn cheapest_cut_ms(&self) -> f64 {
        let (cheapest, _) = self.cut_costs();
        self.roots.iter().map(|&r| cheapest[r as usize].ms).sum()
    }

    /// Per node, the cheapest drawing of its subtree, and the cheapest cut
    /// splitting it (and so its ancestors): bottom-up, then top-down; both
    /// exact whatever the signs of the increments.
    fn cut_costs(&self) -> (Vec<Drawing>, Vec<Drawing>) {
        let mut cheapest: Vec<Drawing> = self.nodes.iter().map(Drawing::of).collect();
        // Per node, its children at their cheapest.
        let mut below = vec![Drawing::NONE; self.len()];
        for v in (0..self.len()).rev() {
            let kids = self.children(v as u32);
            below[v] = kids.iter().fold(Drawing::NONE, |d, &c| d.plus(cheapest[c as usize]));
            if !kids.is_empty() && below[v].ms < cheapest[v].ms {
                cheapest[v] = below[v];
            }
        }
        let all = self.roots.iter().fold(Drawing::NONE, |d, &r| d.plus(cheapest[r as usize]));
        // Never below its parent's, as a subtree's cheapest drawing is at
        // most its children's.
        let mut split = vec![Drawing::NONE; self.len()];
        for v in 0..self.len() as u32 {
            let above = self.node(v).parent.map_or(all, |p| split[p as usize]);
            split[v as usize] = above.minus(cheapest[v as usize]).plus(below[v as usize]);
        }
        (cheapest, split)
    }

    /// The most `Σ (benefit − λ·cost)` over the nodes a cut can draw, for a
    /// price `λ ≥ 0` per ms: bottom-up, each node keeps the better of itself
    /// and its children's best. With `λ·T` added it bounds the benefit of
    /// every cut within budget `T`, whatever the signs of the increments.
    pub fn best_priced(&self, lambda: f64) -> f64 {
        let priced = |n: &Node| if lambda == 0.0 { n.benefit } else { n.benefit - lambda * n.cost_ms };
        let mut best = vec![0.0; self.len()];
        for v in (0..self.len()).rev() {
            let kids = self.children(v as u32);
            let own = priced(&self.nodes[v]);
            best[v] = match kids.is_empty() {
                true => own,
                false => own.max(kids.iter().map(|&c| best[c as usize]).sum()),
            };
        }
        self.roots.iter().map(|&r| best[r as usize]).sum()
    }
}

/// The cost and benefit of drawing some nodes.
#[derive(Clone, Copy, Debug)]
struct Drawing {
    ms: f64,
    benefit: f64,
}

impl Drawing {
    const NONE: Drawing = Drawing { ms: 0.0, benefit: 0.0 };

    fn of(node: &Node) -> Drawing {
        Drawing { ms: node.cost_ms, benefit: node.benefit }
    }

    fn plus(self, o: Drawing) -> Drawing {
        Drawing { ms: self.ms + o.ms, benefit: self.benefit + o.benefit }
    }

    fn minus(self, o: Drawing) -> Drawing {
        Drawing { ms: self.ms - o.ms, benefit: self.benefit - o.benefit }
    }
}

/// Value of an increment, total over all signs: free gains are worth +∞,
/// losses that save nothing −∞.
pub(crate) fn ratio(db: f64, dc: f64) -> f64 {
    if dc > 0.0 {
        if dc.is_finite() { db / dc } else { 0.0 }
    } else if db > 0.0 || (db == 0.0 && dc < 0.0) {
        f64::INFINITY
    } else if db == 0.0 {
        0.0
    } else {
        f64::NEG_INFINITY
    }
}

/// The convexified increments: one group per node with children.
#[derive(Clone, Debug)]
pub(crate) struct Groups {
    /// Group sums, valid for group heads.
    pub db: Vec<f64>,
    pub dc: Vec<f64>,
    /// `ratio(db, dc)` of the group headed by the node.
    pub value: Vec<f64>,
    /// Members of the group headed by `v`: `v`, `next[v]`, … up to `tail[v]`.
    pub next: Vec<u32>,
    pub tail: Vec<u32>,
    /// Whether the node heads a group: it has children and some cut within
    /// the budget splits it ([`Forest::splittable`]).
    pub heads: Vec<bool>,
    /// Whether the budget rules out a split that, or a split below which,
    /// adds benefit (so the optimiser cannot reach full resolution).
    pub pruned: bool,
}

impl Groups {
    /// Horn's merging, bottom-up (children have higher indices), over the
    /// nodes some cut within `budget_ms` splits.
    pub fn new(forest: &Forest, budget_ms: f64) -> Groups {
        let n = forest.len();
        let heads = forest.splittable(budget_ms);
        let adds = forest.adds_benefit();
        let pruned = (0..n).any(|v| !heads[v] && adds[v]);
        let mut g = Groups {
            db: vec![0.0; n],
            dc: vec![0.0; n],
            value: vec![f64::NEG_INFINITY; n],
            next: vec![NONE; n],
            tail: (0..n as u32).collect(),
            heads,
            pruned,
        };
        let mut heap = Leftist::new(n);
        for v in (0..n as u32).rev() {
            let Some((mut db, mut dc)) = forest.increment(v).filter(|_| g.heads[v as usize]) else { continue };
            let mut candidates = NONE;
            for &c in forest.children(v) {
                if g.heads[c as usize] {
                    candidates = heap.meld(candidates, c, &g.value);
                }
            }
            while candidates != NONE && g.value[candidates as usize] > ratio(db, dc) {
                let u = candidates;
                let (rest, frontier) = heap.pop(u, &g.value);
                candidates = heap.meld(rest, frontier, &g.value);
                db += g.db[u as usize];
                dc += g.dc[u as usize];
                let t = g.tail[v as usize];
                g.next[t as usize] = u;
                g.tail[v as usize] = g.tail[u as usize];
            }
            g.db[v as usize] = db;
            g.dc[v as usize] = dc;
            g.value[v as usize] = ratio(db, dc);
            // What v's group leaves available stays in the heap under v.
            heap.stash(v, candidates);
        }
        g
    }

    /// Members of the group headed by `v`, parents first.
    pub fn members(&self, v: u32) -> impl Iterator<Item = u32> + '_ {
        let tail = self.tail[v as usize];
        let mut cur = Some(v);
        std::iter::from_fn(move || {
            let m = cur?;
            cur = (m != tail).then(|| self.next[m as usize]).filter(|&x| x != NONE);
            Some(m)
        })
    }
}

/// Leftist max-heaps over node indices in one arena (each node in at most
/// one heap at a time), keyed by a slice of values; ties go to the lower
/// index, so the result does not depend on meld order.
struct Leftist {
    left: Vec<u32>,
    right: Vec<u32>,
    rank: Vec<u32>,
    /// The heap a popped head left behind (its residual frontier).
    stash: Vec<u32>,
}

impl Leftist {
    fn new(n: usize) -> Leftist {
        Leftist { left: vec![NONE; n], right: vec![NONE; n], rank: vec![1; n], stash: vec![NONE; n] }
    }

    fn rank(&self, h: u32) -> u32 {
        if h == NONE { 0 } else { self.rank[h as usize] }
    }

    fn above(a: u32, b: u32, key: &[f64]) -> bool {
        let (ka, kb) = (key[a as usize], key[b as usize]);
        ka > kb || (ka == kb && a < b)
    }

    /// Melds two heaps (recursion depth ≤ the two right spines, O(log n)).
    fn meld(&mut self, a: u32, b: u32, key: &[f64]) -> u32 {
        if a == NONE {
            return b;
        }
        if b == NONE {
            return a;
        }
        let (a, b) = if Self::above(a, b, key) { (a, b) } else { (b, a) };
        let r = self.meld(self.right[a as usize], b, key);
        let ai = a as usize;
        self.right[ai] = r;
        if self.rank(self.left[ai]) < self.rank(r) {
            self.right[ai] = self.left[ai];
            self.left[ai] = r;
        }
        self.rank[ai] = self.rank(self.right[ai]) + 1;
        a
    }

    /// Removes the root `h`: returns (the rest of the heap, what `h` stashed).
    fn pop(&mut self, h: u32, key: &[f64]) -> (u32, u32) {
        let hi = h as usize;
        let (l, r) = (self.left[hi], self.right[hi]);
        self.left[hi] = NONE;
        self.right[hi] = NONE;
        self.rank[hi] = 1;
        (self.meld(l, r, key), std::mem::replace(&mut self.stash[hi], NONE))
    }

    fn stash(&mut self, v: u32, heap: u32) {
        self.stash[v as usize] = heap;
    }
}
