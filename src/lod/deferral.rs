//! The distance deferral table (004 §V, Table I): threshold refinement whose
//! per-frame work follows the viewpoint's motion, not the number of nodes.
//!
//! A node `v` (sphere centre `p`, radius `r`, geometric error `ξ`) is
//! refined iff `max(0, ‖p − e‖ − r) ≤ ξ μ` — 004's priority
//! `κ = (‖p − e‖ − r)/ξ ≤ μ` written as a distance, which also covers
//! `ξ = 0`. Both sides of the test move by at most the distance the eye
//! moves (bounded variation, 004 Eq. 3), so after an evaluation the node's
//! status cannot change before the eye has travelled `slack = |‖p − e‖ −
//! (r + ξ μ)|` along its path (Eq. 6). The node is parked in a circular
//! table of buckets at an offset proportional to its slack; each frame the
//! head advances by `1 + ⌊(|T| − 1) · moved / d_T⌋` buckets and only the
//! nodes in the buckets passed are evaluated again. Two tables hold the
//! simplification candidates (refined, no refined child) and the refinement
//! candidates (unrefined, parent refined); a change cascades within the
//! frame to the nodes it makes candidates.
//!
//! Exactness: the head passes a node's bucket no later than the frame in
//! which the eye's accumulated path exceeds its slack, because each frame
//! advances strictly more than `(|T| − 1) · moved / d_T` buckets, and slacks
//! are shaved by a rounding margin first. So the refined set equals a full
//! top-down evaluation in every frame (tested along flyovers), provided the
//! hierarchy is monotone (children's spheres inside the parent's, errors
//! non-increasing downwards). View-frustum culling breaks bounded variation
//! (004 §V-D) and is applied to the refined set afterwards.
//!
//! Invariant: every candidate has exactly one live entry in one table;
//! removal bumps the node's stamp, which invalidates its old entry.

use super::quadtree::TileQuadtree;
use glam::DVec3;

/// What the deferral table needs of a hierarchy.
pub trait Hierarchy {
    /// Number of nodes (ids are `0..len`).
    fn len(&self) -> usize;
    /// Whether there are no nodes.
    fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// The roots (always drawn).
    fn roots(&self) -> impl Iterator<Item = u32> + '_;
    /// The parent of `v`.
    fn parent(&self, v: u32) -> Option<u32>;
    /// The children of `v`.
    fn children(&self, v: u32) -> impl Iterator<Item = u32> + '_;
    /// Bounding sphere (centre, radius) and geometric error of `v`, metres.
    fn bound(&self, v: u32) -> (DVec3, f64, f64);
}

impl Hierarchy for TileQuadtree {
    fn len(&self) -> usize {
        self.nodes.len()
    }
    fn roots(&self) -> impl Iterator<Item = u32> + '_ {
        (0..self.nodes.len().min(1) as u32).filter(|&v| self.nodes[v as usize].parent.is_none())
    }
    fn parent(&self, v: u32) -> Option<u32> {
        self.nodes[v as usize].parent
    }
    fn children(&self, v: u32) -> impl Iterator<Item = u32> + '_ {
        self.nodes[v as usize].children()
    }
    fn bound(&self, v: u32) -> (DVec3, f64, f64) {
        let n = &self.nodes[v as usize];
        (n.center_m, n.radius_m, n.error_m)
    }
}

/// Whether `v` is refined at `eye` with threshold `mu`, and how far the eye
/// may travel before that can change (metres, shaved by a rounding margin).
fn test<H: Hierarchy>(h: &H, v: u32, mu: f64, eye: DVec3) -> (bool, f64) {
    let (p, r, xi) = h.bound(v);
    let d = p.distance(eye);
    let reach = r + xi.max(0.0) * mu;
    let margin = 1e-9 * (1.0 + p.abs().max_element() + eye.abs().max_element() + reach);
    (d <= reach, ((d - reach).abs() - margin).max(0.0))
}

/// A circular table of buckets of `(node, stamp)` (004 Table I).
#[derive(Clone, Debug)]
pub struct DeferralTable {
    buckets: Vec<Vec<(u32, u32)>>,
    head: usize,
    range_m: f64,
}

impl DeferralTable {
    /// `buckets` buckets (at least 2) spanning `range_m` metres of travel.
    pub fn new(buckets: usize, range_m: f64) -> DeferralTable {
        DeferralTable { buckets: vec![Vec::new(); buckets.max(2)], head: 0, range_m: range_m.max(f64::MIN_POSITIVE) }
    }

    /// `⌊(|T| − 1) · clamp(l / d_T, 0, 1)⌋`.
    fn steps(&self, l_m: f64) -> usize {
        let f = if l_m.is_nan() { 0.0 } else { (l_m / self.range_m).clamp(0.0, 1.0) };
        ((self.buckets.len() - 1) as f64 * f) as usize
    }

    /// UPDATE-TABLE: advances the head for `moved_m` of travel and moves
    /// the entries of the buckets passed into `out`.
    pub fn advance(&mut self, moved_m: f64, out: &mut Vec<(u32, u32)>) {
        let n = self.buckets.len();
        let k = 1 + self.steps(moved_m);
        for i in 0..k {
            out.append(&mut self.buckets[(self.head + i) % n]);
        }
        self.head = (self.head + k) % n;
    }

    /// PUSH-TABLE: parks `node` until about `slack_m` of travel.
    pub fn push(&mut self, node: u32, stamp: u32, slack_m: f64) {
        let i = (self.head + self.steps(slack_m)) % self.buckets.len();
        self.buckets[i].push((node, stamp));
    }
}

/// Threshold refinement with deferred re-evaluation.
#[derive(Clone, Debug)]
pub struct ThresholdRefiner {
    mu: f64,
    inner: DeferralTable,
    outer: DeferralTable,
    refined: Vec<bool>,
    stamp: Vec<u32>,
    eye: Option<DVec3>,
}

impl ThresholdRefiner {
    /// A refiner for `nodes` nodes with threshold `mu` (refine within
    /// `r + ξ μ`), tables of `buckets` buckets over `range_m` of travel.
    pub fn new(nodes: usize, mu: f64, buckets: usize, range_m: f64) -> ThresholdRefiner {
        ThresholdRefiner {
            mu: if mu.is_finite() { mu.max(0.0) } else { 0.0 },
            inner: DeferralTable::new(buckets, range_m),
            outer: DeferralTable::new(buckets, range_m),
            refined: vec![false; nodes],
            stamp: vec![0; nodes],
            eye: None,
        }
    }

    /// Per node: whether it is refined (replaced by its children).
    pub fn refined(&self) -> &[bool] {
        &self.refined
    }

    /// Moves the eye; returns the number of nodes evaluated. The first call
    /// evaluates from scratch.
    pub fn update<H: Hierarchy>(&mut self, h: &H, eye: DVec3) -> usize {
        let Some(last) = self.eye.replace(eye) else { return self.start(h, eye) };
        let moved = last.distance(eye);
        let mut due = Vec::new();
        self.inner.advance(moved, &mut due);
        let mut simplify: Vec<u32> = self.live(&due);
        due.clear();
        self.outer.advance(moved, &mut due);
        let mut refine: Vec<u32> = self.live(&due);
        let mut evaluated = 0;
        while let Some(v) = simplify.pop() {
            if self.refined[v as usize] && !self.has_refined_child(h, v) {
                evaluated += 1;
                self.recheck_refined(h, v, eye, &mut simplify);
            }
        }
        while let Some(v) = refine.pop() {
            if !self.refined[v as usize] && h.parent(v).is_none_or(|p| self.refined[p as usize]) {
                evaluated += 1;
                self.recheck_unrefined(h, v, eye, &mut refine);
            }
        }
        evaluated
    }

    fn live(&self, due: &[(u32, u32)]) -> Vec<u32> {
        due.iter().filter(|(v, s)| self.stamp[*v as usize] == *s).map(|(v, _)| *v).collect()
    }

    fn has_refined_child<H: Hierarchy>(&self, h: &H, v: u32) -> bool {
        h.children(v).any(|c| self.refined[c as usize])
    }

    fn forget(&mut self, v: u32) {
        self.stamp[v as usize] = self.stamp[v as usize].wrapping_add(1);
    }

    /// A simplification candidate: stays refined, or is merged (its
    /// children stop being candidates; it and perhaps its parent become).
    fn recheck_refined<H: Hierarchy>(&mut self, h: &H, v: u32, eye: DVec3, simplify: &mut Vec<u32>) {
        let (keep, slack) = test(h, v, self.mu, eye);
        if keep {
            self.inner.push(v, self.stamp[v as usize], slack);
            return;
        }
        self.refined[v as usize] = false;
        self.forget(v);
        for c in h.children(v).collect::<Vec<_>>() {
            self.forget(c);
        }
        self.outer.push(v, self.stamp[v as usize], slack);
        if let Some(p) = h.parent(v).filter(|&p| !self.has_refined_child(h, p)) {
            simplify.push(p);
        }
    }

    /// A refinement candidate: stays unrefined, or is split (its parent
    /// stops being a candidate; its children become).
    fn recheck_unrefined<H: Hierarchy>(&mut self, h: &H, v: u32, eye: DVec3, refine: &mut Vec<u32>) {
        let (split, slack) = test(h, v, self.mu, eye);
        if !split {
            self.outer.push(v, self.stamp[v as usize], slack);
            return;
        }
        self.refined[v as usize] = true;
        self.forget(v);
        if let Some(p) = h.parent(v) {
            self.forget(p);
        }
        self.inner.push(v, self.stamp[v as usize], slack);
        refine.extend(h.children(v));
    }

    /// First frame: the refinement candidates are the roots; splitting
    /// cascades down as in any frame.
    fn start<H: Hierarchy>(&mut self, h: &H, eye: DVec3) -> usize {
        let mut refine: Vec<u32> = h.roots().collect();
        let mut evaluated = 0;
        while let Some(v) = refine.pop() {
            evaluated += 1;
            self.recheck_unrefined(h, v, eye, &mut refine);
        }
        evaluated
    }
}

/// Full top-down evaluation (the reference): fills `refined` and returns
/// the number of nodes evaluated.
pub fn full_refinement<H: Hierarchy>(h: &H, mu: f64, eye: DVec3, refined: &mut [bool]) -> usize {
    refined.fill(false);
    let mut stack: Vec<u32> = h.roots().collect();
    let mut evaluated = 0;
    while let Some(v) = stack.pop() {
        evaluated += 1;
        if test(h, v, mu, eye).0 {
            refined[v as usize] = true;
            stack.extend(h.children(v));
        }
    }
    evaluated
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec2;
    use proptest::prelude::*;

    /// 20.48 km square, 9 levels (87,381 tiles), up to 60 m of relief.
    pub(crate) fn region() -> TileQuadtree {
        let relief = |a: DVec2, b: DVec2| (0.0, 60.0 * ((a.x + b.y) / 20_480.0).fract());
        TileQuadtree::square(DVec2::ZERO, 20_480.0, 8, 400.0, &relief)
    }

    /// A smooth recorded flyover: `frames` eye positions 150–250 m up,
    /// moving 10–40 m a frame.
    pub(crate) fn flyover(frames: usize) -> Vec<DVec3> {
        (0..frames)
            .map(|k| {
                let t = k as f64;
                DVec3::new(
                    10_240.0 + 7_000.0 * (t / 400.0).sin(),
                    10_240.0 + 6_000.0 * (t / 290.0 + 1.0).sin(),
                    200.0 + 50.0 * (t / 60.0).sin(),
                )
            })
            .collect()
    }

    fn check(path: &[DVec3], mu: f64) -> (usize, usize) {
        let tree = region();
        let mut deferred = ThresholdRefiner::new(tree.len(), mu, 1024, 2_000.0);
        let mut full = vec![false; tree.len()];
        let (mut touched, mut reference) = (0, 0);
        for (k, &eye) in path.iter().enumerate() {
            let n = deferred.update(&tree, eye);
            let f = full_refinement(&tree, mu, eye, &mut full);
            if k > 0 {
                touched += n;
                reference += f;
            }
            assert!(deferred.refined() == full.as_slice(), "frame {k} differs");
        }
        (touched, reference)
    }

    #[test]
    fn deferred_refinement_equals_full_evaluation_along_a_flyover() {
        let (touched, reference) = check(&flyover(600), 200.0);
        assert!(reference > 600 * 1_000, "{reference} evaluations: the flyover refines");
        assert!(touched * 10 < reference, "deferred {touched} vs full {reference}");
    }

    #[test]
    fn jumps_and_standing_still_stay_exact() {
        let mut path = flyover(50);
        path.extend([DVec3::new(100.0, 100.0, 180.0), DVec3::new(20_000.0, 19_000.0, 400.0)]);
        path.extend(std::iter::repeat_n(DVec3::new(20_000.0, 19_000.0, 400.0), 5));
        path.extend(flyover(80).into_iter().rev());
        check(&path, 200.0);
        check(&path, 0.0);
    }

    proptest! {
        #[test]
        fn an_entry_comes_due_before_its_slack_is_travelled(
            slack in 0.0f64..3000.0,
            moves in prop::collection::vec(0.0f64..500.0, 1..60),
        ) {
            let mut table = DeferralTable::new(64, 1000.0);
            table.push(7, 0, slack);
            let mut travelled = 0.0;
            let mut out = Vec::new();
            for m in moves {
                travelled += m;
                table.advance(m, &mut out);
                if !out.is_empty() {
                    break;
                }
                prop_assert!(travelled < slack, "still parked after {travelled} m of {slack} m");
            }
        }
    }
}
