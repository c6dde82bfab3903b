//! The tree knapsack by dynamic programming, for the answers the greedy
//! cannot vouch for (worth less than `1 − ε` of the upper bound): Johnson
//! and Niemi's left-right programme over the splits in preorder, with
//! benefits rounded to a grain `K` (the usual knapsack approximation
//! scheme). The continuous variables take what each cut leaves; as their
//! benefit only grows with the time left, a cut no dearer than the best
//! one's and within `n·K` of its benefit is within `n·K` of the optimum.
//!
//! The splits a cut can take are the sets closed under ancestors. In
//! preorder, position `i` either takes its split (and goes on at `i + 1`,
//! its first child or the next node whose parent is already split) or
//! leaves it and its whole subtree (going on at `end[i]`). `F[i]`, the
//! states reachable from position `i` on, is then the merge of `F[i + 1]`
//! shifted by split `i`'s increment and `F[end[i]]`. Each list keeps, in
//! order of cost, only states that reach a higher multiple of `K` than
//! every cheaper one; a state dropped for one kept is at most `K` worse and
//! no dearer, and each of a cut's at most `n` positions drops it once at
//! most. So the best state is within `n·K` of the best cut, whatever the
//! signs of the increments, and with `K = ε·LB / n` for a lower bound `LB`
//! of the optimum it is at least `(1 − ε)` of it. A list holds at most one
//! state per multiple of `K` between its least and its most benefit; where
//! those lie within a constant of the optimum that is `O(n/ε)` states, and
//! the work `O(n²/ε)`. It stops at [`MAX_STATES`] or the deadline.
//!
//! Invariants: `F[j]` lives only while a position still reads it (its
//! predecessor and the nodes whose subtree ends before `j`: a path, so at
//! most the depth of the forest lists at once); taken splits are kept as
//! chains in one arena, shared by the states that extend them.

use super::discrete::Forest;
use super::{Run, drawn_sums};
use std::time::Instant;

/// One state: the increments taken from a position on, summed.
#[derive(Clone, Copy, Debug)]
pub(super) struct State {
    pub benefit: f64,
    pub cost_ms: f64,
    /// Head of its chain of taken splits in [`Frontier::taken`]'s arena.
    chain: u32,
}

/// The end of a chain.
const END: u32 = u32::MAX;

/// The states from position 0: every cut, up to rounding, by its cost.
pub(super) struct Frontier {
    pub states: Vec<State>,
    /// `(node, next)` links of the chains of taken splits.
    links: Vec<(u32, u32)>,
}

impl Frontier {
    /// The splits `state` takes.
    pub fn taken(&self, state: &State) -> impl Iterator<Item = u32> + '_ {
        let mut at = state.chain;
        std::iter::from_fn(move || {
            let (node, next) = *self.links.get(at as usize)?;
            at = next;
            Some(node)
        })
    }
}

/// What the programme may spend.
pub(super) struct Limits {
    /// The answer may fall short of the best cut by this much, at most
    /// (`n·K`; positive).
    pub slack: f64,
    /// Cost the increments may add to the roots', ms.
    pub room_ms: f64,
    /// States kept over the whole run, at most (their chain links are the
    /// memory it holds).
    pub max_states: usize,
    pub deadline: Option<Instant>,
}

/// The splits as items: those some cut within the budget takes, in preorder.
struct Items {
    nodes: Vec<u32>,
    /// Position after each item's subtree.
    end: Vec<u32>,
    /// `(Δb, Δc)` of each item's split.
    increment: Vec<(f64, f64)>,
}

impl Items {
    fn new(forest: &Forest, splittable: &[bool], room_ms: f64) -> Items {
        // A node that costs ∞ (a NaN cost) counts as dearer than any cut
        // without it and the whole room, so increments stay finite and no
        // cut that draws it fits.
        let finite_ms: f64 = (0..forest.len() as u32).map(|v| forest.node(v).cost_ms).filter(|c| c.is_finite()).sum();
        let dear_ms = 2.0 * (finite_ms + room_ms.abs()) + 1.0;
        let cost = |v: u32| forest.node(v).cost_ms.min(dear_ms);
        let increment = |v: u32| {
            let kids = forest.children(v).iter();
            let benefit: f64 = kids.clone().map(|&c| forest.node(c).benefit).sum();
            (benefit - forest.node(v).benefit, kids.map(|&c| cost(c)).sum::<f64>() - cost(v))
        };
        let mut items = Items { nodes: vec![], end: vec![], increment: vec![] };
        let mut position = vec![u32::MAX; forest.len()];
        let mut stack: Vec<u32> = forest.roots().iter().rev().copied().collect();
        while let Some(v) = stack.pop() {
            if splittable[v as usize] {
                position[v as usize] = items.nodes.len() as u32;
                items.nodes.push(v);
                items.increment.push(increment(v));
                stack.extend(forest.children(v).iter().rev());
            }
        }
        // Subtree sizes, children after their parents: an item's parent is
        // an item, as the walk goes down only from items.
        let mut size = vec![1u32; items.nodes.len()];
        for i in (0..items.nodes.len()).rev() {
            if let Some(p) = forest.node(items.nodes[i]).parent {
                size[position[p as usize] as usize] += size[i];
            }
        }
        items.end = size.iter().enumerate().map(|(i, s)| i as u32 + s).collect();
        items
    }

    /// How many positions read `F[j]`, for each `j`.
    fn readers(&self) -> Vec<u32> {
        let mut readers = vec![0u32; self.nodes.len() + 1];
        for (i, &e) in self.end.iter().enumerate() {
            readers[i + 1] += 1;
            readers[e as usize] += 1;
        }
        readers
    }
}

/// Every cut's benefit and cost above the roots', up to `limits.slack` of
/// benefit, over the splits `splittable` marks; `None` past the limits.
pub(super) fn frontier(forest: &Forest, splittable: &[bool], limits: &Limits) -> Option<Frontier> {
    let items = Items::new(forest, splittable, limits.room_ms);
    let n = items.nodes.len();
    let grain = limits.slack / n.max(1) as f64;
    if !grain.is_normal() || !limits.room_ms.is_finite() {
        return None;
    }
    // Later splits may save time: a state this much over the room may
    // still come back within it.
    let savings: f64 = items.increment.iter().map(|&(_, dc)| (-dc).max(0.0)).sum();
    let ceiling = limits.room_ms + savings;
    let mut readers = items.readers();
    // Freed lists are left empty.
    let mut lists: Vec<Vec<State>> = vec![vec![]; n + 1];
    lists[n] = vec![State { benefit: 0.0, cost_ms: 0.0, chain: END }];
    let mut links = vec![];
    let mut kept = 1;
    for i in (0..n).rev() {
        if super::late(limits.deadline) || kept > limits.max_states {
            return None;
        }
        let (db, dc) = items.increment[i];
        let end = items.end[i] as usize;
        let (taken, left) = (&lists[i + 1], &lists[end]);
        let mut merged = Vec::with_capacity(taken.len() + left.len());
        let shifted = taken.iter().map(|s| (State { benefit: s.benefit + db, cost_ms: s.cost_ms + dc, ..*s }, true));
        let stayed = left.iter().map(|&s| (s, false));
        for (mut state, take) in by_cost(shifted, stayed) {
            if state.cost_ms > ceiling || !rises(&merged, state.benefit, grain) {
                continue;
            }
            if take {
                links.push((items.nodes[i], state.chain));
                state.chain = links.len() as u32 - 1;
            }
            merged.push(state);
        }
        kept += merged.len();
        for j in [i + 1, end] {
            readers[j] -= 1;
            if readers[j] == 0 {
                lists[j] = vec![];
            }
        }
        lists[i] = merged;
    }
    Some(Frontier { states: std::mem::take(&mut lists[0]), links })
}

/// Whether a state worth `benefit` reaches a higher multiple of `grain`
/// than the last (cheaper) state kept.
fn rises(kept: &[State], benefit: f64, grain: f64) -> bool {
    kept.last().is_none_or(|last| (benefit / grain).floor() > (last.benefit / grain).floor())
}

/// Merges two lists sorted by cost into one sorted by cost.
fn by_cost<I, J>(a: I, b: J) -> impl Iterator<Item = (State, bool)>
where
    I: Iterator<Item = (State, bool)>,
    J: Iterator<Item = (State, bool)>,
{
    let (mut a, mut b) = (a.peekable(), b.peekable());
    std::iter::from_fn(move || match (a.peek(), b.peek()) {
        (Some(x), Some(y)) if x.0.cost_ms <= y.0.cost_ms => a.next(),
        (Some(_), None) => a.next(),
        _ => b.next(),
    })
}

/// The programme's answer is within this share of the optimum, and it
/// runs where the greedy's is not within it of the upper bound.
pub(super) const EPSILON: f64 = 0.05;

/// States the programme keeps at most (24 bytes each while their list
/// lives, and 8 bytes of chain link for each taken split): some 25 ms of
/// work on this machine's cores.
const MAX_STATES: usize = 1 << 20;

impl Run<'_> {
    /// Runs the programme for an answer worth `benefit` and adopts its best
    /// cut (with the continuous variables spending what it leaves) if that
    /// is better. Returns whether it was, and the bound the programme
    /// proves: its best total plus its slack. `None` past its limits, or
    /// where nothing is worth anything.
    pub(super) fn knapsack(&mut self, benefit: f64, deadline: Option<Instant>) -> Option<(bool, f64)> {
        // The optimum is at least the answer, and at least any cut that
        // fits.
        let lower = benefit.max(self.forest.best_cheapest_cut(self.budget_ms));
        if !(lower > 0.0 && lower.is_finite()) {
            return None;
        }
        let roots = drawn_sums(self.forest, &vec![false; self.forest.len()]);
        let limits =
            Limits { slack: EPSILON * lower, room_ms: self.budget_ms - roots.1, max_states: MAX_STATES, deadline };
        let frontier = frontier(self.forest, &self.groups.heads, &limits)?;
        let (state, total) = self.best_state(&frontier, roots, deadline)?;
        let mut split = vec![false; self.forest.len()];
        for v in frontier.taken(&state) {
            split[v as usize] = true;
        }
        Some((self.adopt_if_better(split), total * (1.0 + 1e-12) + limits.slack))
    }

    /// Takes `split`, with the continuous variables spending what it
    /// leaves, if that fits and beats the current answer (or that answer,
    /// the roots alone, does not fit).
    fn adopt_if_better(&mut self, split: Vec<bool>) -> bool {
        let (current, current_ms) = drawn_sums(self.forest, &self.split);
        let current = current + self.levels.benefit(self.mu);
        let (benefit_d, cost_d) = drawn_sums(self.forest, &split);
        let mu = self.levels.level_for_budget(self.budget_ms - cost_d);
        let beats = benefit_d + self.levels.benefit(mu) > current || current_ms > self.budget_ms;
        let better = cost_d <= self.budget_ms && beats;
        if better {
            self.split = split;
            self.mu = mu;
        }
        better
    }

    /// The state of `frontier` within the budget whose total (with the
    /// roots' benefit and cost `roots`), with the
    /// continuous variables spending what it leaves, is highest. States
    /// are looked at from the most beneficial down, while the continuous
    /// variables' most could still lift one above the best so far; a state
    /// is worked out only where the last level worked out does not rule it
    /// out (at level `μ` the continuous benefit of `R` ms is at most
    /// `b(μ) + μ·(R − c(μ))`, by duality).
    fn best_state(&self, frontier: &Frontier, roots: (f64, f64), deadline: Option<Instant>) -> Option<(State, f64)> {
        let (roots_benefit, roots_ms) = roots;
        let room = |s: &State| self.budget_ms - roots_ms - s.cost_ms;
        let fits = frontier.states.partition_point(|s| room(s) >= 0.0);
        let most = self.levels.benefit(self.levels.level_for_budget(room(frontier.states.first()?)));
        let mut best: Option<(State, f64)> = None;
        let mut level = f64::INFINITY;
        for (k, s) in frontier.states[..fits].iter().rev().enumerate() {
            if k % 64 == 63 && super::late(deadline) {
                return None;
            }
            let reach = |continuous: f64| roots_benefit + s.benefit + continuous;
            if let Some((_, t)) = best {
                if reach(most) <= t {
                    break;
                }
                if level.is_finite() && reach(self.dual(level, room(s))) <= t {
                    continue;
                }
            }
            level = self.levels.level_for_budget(room(s));
            let total = reach(self.levels.benefit(level));
            if best.is_none_or(|(_, t)| total > t) {
                best = Some((*s, total));
            }
        }
        best
    }

    /// The most benefit the continuous variables reach with `room_ms`,
    /// bounded at level `mu` (finite): `b(μ) + μ·(room − c(μ))`.
    fn dual(&self, mu: f64, room_ms: f64) -> f64 {
        self.levels.benefit(mu) + mu * (room_ms - self.levels.cost_ms(mu))
    }
}
