//! Exchange steps after the greedy stops on the budget: Mason and Blake's
//! decrement step (undo an increment) alone, giving its time to the
//! continuous variables, or paired with an increment that did not fit. A greedy knapsack loses most when a few large increments remain
//! (a tile split that costs a fifth of the budget); trading the last small
//! increments for one of them recovers it. Each exchange strictly increases
//! the benefit and keeps the selection feasible, and there are at most
//! [`ROUNDS`] of them over [`CANDIDATES`]² pairs, so the work stays bounded;
//! the iteration and time limits stop them too (the time limit is looked at
//! before each decrement candidate's pairs).
//!
//! Invariant: only a split node with no split child is undone, so the
//! selection stays a cut of the hierarchy; what replaces it must still be
//! available afterwards (its parent split).

use super::{Entry, Run, Settings, Stop, late};
use std::time::Instant;

/// Exchanges per optimisation, at most.
const ROUNDS: usize = 8;

/// Recent applied and best dropped increments considered per round.
const CANDIDATES: usize = 8;

/// One exchange: undo the split of node `out`, apply the increments
/// `take` in order, set the continuous level `mu`.
struct Swap {
    out: u32,
    take: Vec<Entry>,
    mu: f64,
    gain: f64,
}

impl Run<'_> {
    /// Runs exchange rounds after a greedy stop; the greedy resumes after
    /// each exchange from the new state.
    pub(super) fn exchange(&mut self, settings: &Settings, mut stop: Stop) -> Stop {
        for _ in 0..ROUNDS {
            if stop != Stop::Budget || self.remaining_ms() < 0.0 {
                break;
            }
            if self.iterations >= settings.max_iterations || late(settings.deadline) {
                return Stop::Limit;
            }
            let Some(swap) = self.best_swap(settings.deadline) else { break };
            self.iterations += 1;
            self.undo(swap.out);
            for e in swap.take {
                self.apply(e, self.mu);
            }
            self.set_level(swap.mu);
            for e in std::mem::take(&mut self.dropped) {
                if self.available(&e) {
                    self.heap.push(e);
                }
            }
            stop = self.greedy(settings);
        }
        stop
    }

    /// The best exchange: for each decrement candidate, each dropped
    /// increment (or none) first, then greedily what still fits among the
    /// other dropped increments and those the first one makes available;
    /// the best found by the `deadline`, if it passes.
    fn best_swap(&self, deadline: Option<Instant>) -> Option<Swap> {
        let mut dropped: Vec<Entry> = self.dropped.iter().copied().filter(|e| self.available(e)).collect();
        dropped.sort_by(|a, b| b.cmp(a));
        dropped.truncate(CANDIDATES);
        let base = self.levels.benefit(self.mu);
        let mut best: Option<Swap> = None;
        for out in self.undoable().into_iter().take_while(|_| !late(deadline)) {
            let (hb, hc) = self.forest.increment(out).unwrap_or((0.0, 0.0));
            for first in dropped.iter().copied().map(Some).chain([None]) {
                let room = self.budget_ms - (self.cost_d - hc);
                let Some((take, room, gain)) = self.fill(out, first, &dropped, room) else { continue };
                let mu = self.levels.level_for_budget(room);
                let gain = gain - hb + self.levels.benefit(mu) - base;
                if gain > 1e-12 * (self.benefit_d + base).abs() && best.as_ref().is_none_or(|b| gain > b.gain) {
                    best = Some(Swap { out, take, mu, gain });
                }
            }
        }
        best
    }

    /// `first` (if it fits and does not hang below `out`), then the best of
    /// `others` and of what `first` makes available, each if it fits and
    /// gains more than the continuous variables would make of its time: the
    /// increments taken, the room left and the benefit gained; `None` if
    /// `first` does not fit or the room ends below 0 (undoing a split that
    /// saved time can cost more than the budget left).
    fn fill(&self, out: u32, first: Option<Entry>, others: &[Entry], mut room: f64) -> Option<(Vec<Entry>, f64, f64)> {
        let below_out = |e: &Entry| self.forest.node(e.node).parent == Some(out);
        let mut take = Vec::new();
        let mut gain = 0.0;
        let mut pool: Vec<Entry> = others.iter().copied().filter(|e| Some(*e) != first).collect();
        if let Some(f) = first {
            let (gb, gc) = self.delta(&f);
            if below_out(&f) || gc > room {
                return None;
            }
            room -= gc;
            gain += gb;
            take.push(f);
            let opened = self.members(&f).flat_map(|m| self.forest.children(m).iter().copied());
            let members: Vec<u32> = self.members(&f).collect();
            pool.extend(opened.filter(|c| !members.contains(c) && self.groups.heads[*c as usize]).map(|c| Entry {
                value: self.groups.value[c as usize],
                node: c,
                alone: false,
            }));
            pool.sort_by(|a, b| b.cmp(a));
        }
        // What the continuous variables would make of `room`.
        let continuous = |room: f64| self.levels.benefit(self.levels.level_for_budget(room));
        let mut now = continuous(room);
        for e in pool.into_iter().take(CANDIDATES) {
            let (gb, gc) = self.delta(&e);
            let clash = take.iter().any(|t: &Entry| t.node == e.node);
            if below_out(&e) || clash || gc > room {
                continue;
            }
            let after = continuous(room - gc);
            if gb + after > now {
                room -= gc;
                gain += gb;
                now = after;
                take.push(e);
            }
        }
        (room >= 0.0).then_some((take, room, gain))
    }

    /// The most recently split nodes with no split child (Mason and Blake's
    /// decrement candidates), at most [`CANDIDATES`].
    fn undoable(&self) -> Vec<u32> {
        let leaf = |v: u32| self.split[v as usize] && self.forest.children(v).iter().all(|&c| !self.split[c as usize]);
        self.applied.iter().rev().copied().filter(|&v| leaf(v)).take(CANDIDATES).collect()
    }

    /// Reverts the split of `v` (its children are drawn no more, it is).
    fn undo(&mut self, v: u32) {
        let (db, dc) = self.forest.increment(v).unwrap_or((0.0, 0.0));
        self.split[v as usize] = false;
        self.applied.retain(|&a| a != v);
        self.benefit_d -= db;
        self.cost_d -= dc;
    }
}
