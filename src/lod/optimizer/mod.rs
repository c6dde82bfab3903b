//! The mixed discrete/continuous LOD optimiser of 000 §3.4 (dissertation
//! §8.3): maximise total benefit subject to predicted cost ≤ the budget `T`.
//!
//! Each iteration either applies the best discrete increment (a convexified
//! Mason–Blake group, [`discrete`]) or raises the continuous variables
//! ([`continuous`]), whichever has the higher benefit per millisecond: the
//! discrete slope `Δb/Δc` against the continuous slope `d b̃_c / d cost`.
//! A continuous step goes down its slope curve until its slope meets the
//! best discrete slope or the budget is spent (Figure 1's point Q). The loop
//! stops when the budget is spent, when everything is at full resolution,
//! or at an iteration or time limit; every state it passes through is
//! feasible, so any stop returns a feasible answer.
//!
//! Two additions make the answer certain rather than hoped for:
//! - **Within 5 % of the optimum.** Splits that no cut within the budget
//!   affords are never offered nor merged into a group
//!   ([`Forest::splittable`]). Where the greedy answer is worth less than
//!   `1 − ε` of the upper bound below (`ε` = 5 %), a dynamic programme over
//!   the cuts (module `knapsack`) finds one within `ε` of the optimum and the
//!   better of the two is kept; its best cut plus its rounding is a second
//!   upper bound. So the answer is at least 95 % of the optimum unless a
//!   limit stopped the search. The greedy alone falls far below that
//!   where a convexified group costs more than the budget though each of
//!   its splits fits (the fractional relaxation then prices the group's
//!   whole ratio, which no feasible answer reaches: 3 against 6.4 in
//!   `a_three_branch_fork_larger_than_the_budget_reaches_95_percent_of_the_optimum`),
//!   and in the knapsack trap (small increments taken first crowd out one
//!   large one).
//! - **An upper bound.** When the first group does not fit, its value
//!   (or the continuous level, if higher) prices a millisecond at `λ`:
//!   `λ·T` plus the best benefit less priced cost over the cuts (one
//!   bottom-up pass) and over the continuous curve bounds every feasible
//!   answer (Lagrangian duality; [`Selection::upper_bound`]), and so does
//!   every other price: the bound reported is the least found within 100×
//!   of these prices. Where no discrete increment left is worth more per ms
//!   than the blocked one, the greedy state lies on the path of the
//!   fractional optimum and the bound is that optimum's value; splits that
//!   lose both benefit and time, which the greedy never undoes, only make
//!   it less tight. The programme's bound is often the tighter one.
//!
//! The programme runs on most frames of a real flight (the greedy answer is
//! within 5 % of the Lagrangian bound on few of them); over rmnp it adds
//! about 0.05 ms to the optimiser's median (`docs/benchmarks.md`, "A
//! knapsack programme").
//!
//! If every cut costs more than the budget, the search runs under the
//! cheapest cut's cost instead, so its answer and its bound are those of
//! the cuts no dearer than that one (the bound of a budget no cut meets
//! would be meaningless), and the overrun is reported: the roots (the
//! coarsest representation) are drawn where they are the cheapest cut.
//! A greedy that starts from roots dearer than the budget stops at once,
//! and the knapsack programme looks for a cut within it.

pub mod continuous;
pub mod discrete;
mod exchange;
mod knapsack;
#[cfg(test)]
mod tests;

pub use continuous::{Continuous, Levels};
pub use discrete::{Forest, Node};

use super::model::Smooth;
use discrete::{Groups, ratio};
use std::collections::BinaryHeap;
use std::time::Instant;

/// How far from the greedy's own prices the tightest bound is looked for
/// ([`Run::least_bound`]), times either way.
const PRICE_SPAN: f64 = 100.0;
/// Golden-section steps of that search: the price found within 1.1 % of
/// the span's logarithm.
const PRICE_STEPS: usize = 14;

/// Bad optimiser input.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum LodError {
    /// More nodes than 32-bit indices address.
    #[error("{0} nodes is more than the optimiser indexes")]
    TooManyNodes(usize),
    /// A parent must come before its children.
    #[error("node {node} names parent {parent}, which does not come before it")]
    ParentAfterChild {
        /// The child.
        node: u32,
        /// Its parent.
        parent: u32,
    },
}

/// What the optimiser may spend.
#[derive(Clone, Copy, Debug)]
pub struct Settings {
    /// Frame budget `T`, ms (NaN or negative: 0).
    pub budget_ms: f64,
    /// The benefit curve of the continuous variables.
    pub smooth: Smooth,
    /// Iterations before it stops (each applies one increment or one
    /// continuous step).
    pub max_iterations: usize,
    /// Wall-clock time at which it stops (its own time limit).
    pub deadline: Option<Instant>,
}

impl Settings {
    /// `budget_ms` with no limit but the natural one (at most two
    /// iterations per node, plus one).
    pub fn budget(budget_ms: f64) -> Settings {
        Settings { budget_ms, smooth: Smooth::default(), max_iterations: usize::MAX, deadline: None }
    }
}

/// Why the optimiser stopped.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stop {
    /// The next increment did not fit (or the continuous budget is spent).
    Budget,
    /// Everything that adds benefit was taken.
    FullResolution,
    /// The iteration or time limit.
    Limit,
}

/// The optimiser's answer.
#[derive(Clone, Debug)]
pub struct Selection {
    /// Per node: whether it is replaced by its children.
    pub split: Vec<bool>,
    /// Per continuous variable: its resolution `x ∈ [0, capacity]`.
    pub resolutions: Vec<f64>,
    /// Total benefit.
    pub benefit: f64,
    /// Total predicted cost, ms.
    pub cost_ms: f64,
    /// Predicted cost beyond the budget (only when every cut exceeds it).
    pub overrun_ms: f64,
    /// No selection within the budget (or, when every cut overruns it, no
    /// dearer than the cheapest cut) has more benefit than this.
    pub upper_bound: f64,
    /// The continuous slope level at the end: benefit per ms of the last
    /// unit; ∞ when no continuous variable got any, 0 when all are at full
    /// resolution (or there are none).
    pub level: f64,
    /// Why it stopped.
    pub stop: Stop,
    /// Iterations run.
    pub iterations: usize,
    /// Which search gave the answer.
    pub answer: Answer,
}

/// Which search gave the optimiser's answer.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Answer {
    /// The greedy increments and exchanges.
    Greedy,
    /// The tree knapsack programme (module `knapsack`), run where the
    /// greedy's answer is below 95 % of the upper bound.
    Knapsack,
}

impl Selection {
    /// The nodes drawn: not split, and a root or a child of a split node.
    pub fn drawn<'a>(&'a self, forest: &'a Forest) -> impl Iterator<Item = u32> + 'a {
        drawn(forest, &self.split)
    }
}

/// The nodes a split vector draws.
fn drawn<'a>(forest: &'a Forest, split: &'a [bool]) -> impl Iterator<Item = u32> + 'a {
    (0..forest.len() as u32)
        .filter(move |&i| !split[i as usize] && forest.node(i).parent.is_none_or(|p| split[p as usize]))
}

/// Benefit and cost of the nodes a split vector draws, summed afresh.
fn drawn_sums(forest: &Forest, split: &[bool]) -> (f64, f64) {
    drawn(forest, split).fold((0.0, 0.0), |(b, c), i| (b + forest.node(i).benefit, c + forest.node(i).cost_ms))
}

/// Whether `deadline` has passed.
fn late(deadline: Option<Instant>) -> bool {
    deadline.is_some_and(|d| Instant::now() >= d)
}

/// Maximises benefit under the budget over the nodes of `forest` and the
/// `continuous` variables.
pub fn optimize(forest: &Forest, continuous: &[Continuous], settings: &Settings) -> Selection {
    let mut run = Run::new(forest, Levels::new(continuous, settings.smooth), settings);
    let stop = run.greedy(settings);
    let stop = run.exchange(settings, stop);
    run.finish(stop, settings.deadline)
}

/// A heap entry: a group (or, after it was blocked, its head alone).
#[derive(Clone, Copy, Debug)]
struct Entry {
    value: f64,
    node: u32,
    alone: bool,
}

impl PartialEq for Entry {
    fn eq(&self, o: &Entry) -> bool {
        self.cmp(o).is_eq()
    }
}
impl Eq for Entry {}
impl PartialOrd for Entry {
    fn partial_cmp(&self, o: &Entry) -> Option<std::cmp::Ordering> {
        Some(self.cmp(o))
    }
}
impl Ord for Entry {
    /// Higher value first; ties to the lower node index.
    fn cmp(&self, o: &Entry) -> std::cmp::Ordering {
        self.value.total_cmp(&o.value).then(o.node.cmp(&self.node))
    }
}

/// The optimiser's state.
struct Run<'a> {
    forest: &'a Forest,
    groups: Groups,
    levels: Levels,
    /// The budget searched: the one asked, or the cheapest cut's cost if
    /// more.
    budget_ms: f64,
    /// The budget asked (not negative), which an overrun is measured from.
    asked_ms: f64,
    split: Vec<bool>,
    heap: BinaryHeap<Entry>,
    benefit_d: f64,
    cost_d: f64,
    /// Continuous slope level and its cost.
    mu: f64,
    cost_c: f64,
    continuous_done: bool,
    /// The bound at the moment the first group did not fit.
    first_block: Option<f64>,
    /// Nodes split, in order, and increments dropped for not fitting.
    applied: Vec<u32>,
    dropped: Vec<Entry>,
    iterations: usize,
}

impl<'a> Run<'a> {
    fn new(forest: &'a Forest, levels: Levels, settings: &Settings) -> Run<'a> {
        let asked_ms = if settings.budget_ms > 0.0 { settings.budget_ms } else { 0.0 };
        // Some cut within the budget unless the roots overrun it.
        let roots_ms: f64 = forest.roots().iter().map(|&r| forest.node(r).cost_ms).sum();
        let floor_ms = if roots_ms > asked_ms { forest.cheapest_cut_ms() } else { asked_ms };
        let budget_ms = if floor_ms.is_finite() { asked_ms.max(floor_ms) } else { asked_ms };
        let mut run = Run {
            forest,
            groups: Groups::new(forest, budget_ms),
            levels,
            budget_ms,
            asked_ms,
            split: vec![false; forest.len()],
            heap: BinaryHeap::new(),
            benefit_d: 0.0,
            cost_d: 0.0,
            mu: f64::INFINITY,
            cost_c: 0.0,
            continuous_done: false,
            first_block: None,
            applied: Vec::new(),
            dropped: Vec::new(),
            iterations: 0,
        };
        for &r in forest.roots() {
            run.benefit_d += forest.node(r).benefit;
            run.cost_d += forest.node(r).cost_ms;
            run.offer(r);
        }
        run
    }

    /// Makes the group headed by `v` available, if it has one.
    fn offer(&mut self, v: u32) {
        if self.groups.heads[v as usize] {
            self.heap.push(Entry { value: self.groups.value[v as usize], node: v, alone: false });
        }
    }

    fn remaining_ms(&self) -> f64 {
        self.budget_ms - self.cost_d - self.cost_c
    }

    fn delta(&self, e: &Entry) -> (f64, f64) {
        let v = e.node as usize;
        match e.alone {
            true => self.forest.increment(e.node).unwrap_or((0.0, 0.0)),
            false => (self.groups.db[v], self.groups.dc[v]),
        }
    }

    fn greedy(&mut self, settings: &Settings) -> Stop {
        if self.remaining_ms() < 0.0 {
            return Stop::Budget;
        }
        loop {
            if self.iterations >= settings.max_iterations || self.past(settings.deadline) {
                return Stop::Limit;
            }
            self.iterations += 1;
            let top = self.best_fitting();
            let slope_c = self.continuous_slope();
            match (top, slope_c) {
                (None, None) => return self.why_done(),
                (Some((e, mu)), None) => self.take(e, mu),
                (Some((e, mu)), Some(s)) if e.value >= s => self.take(e, mu),
                (e, Some(s)) => self.continuous_step(e.map_or(0.0, |(e, _)| e.value), s),
            }
        }
    }

    fn past(&self, deadline: Option<Instant>) -> bool {
        // Instant::now costs ~20 ns: look every 64 iterations.
        self.iterations.is_multiple_of(64) && late(deadline)
    }

    /// Full resolution, unless something was blocked, ruled out, or left
    /// to the continuous variables, or a node costs ∞ (its increments are
    /// worth nothing to the greedy, though splitting it may be worth much).
    fn why_done(&self) -> Stop {
        let saturated = self.levels.slope(self.mu).is_none();
        let priced = self.forest.costs_finite();
        match self.first_block.is_none() && !self.groups.pruned && saturated && priced {
            true => Stop::FullResolution,
            false => Stop::Budget,
        }
    }

    /// The best available increment that adds benefit and fits, with the
    /// continuous level it needs: the current one, or a higher one that
    /// frees the room (continuous variables are divisible, so they give way
    /// to a discrete step that is worth more than what they lose). Blocked
    /// groups are dropped; their head alone is offered instead. Entries an
    /// exchange made stale (applied since, or below an undone split) are
    /// discarded.
    fn best_fitting(&mut self) -> Option<(Entry, f64)> {
        while let Some(e) = self.heap.peek().copied() {
            if !self.available(&e) {
                self.heap.pop();
                continue;
            }
            let (db, dc) = self.delta(&e);
            if !crate::lod::positive(e.value) || !(db > 0.0 || dc < 0.0) {
                self.heap.clear();
                return None;
            }
            if dc <= self.remaining_ms() {
                return Some((e, self.mu));
            }
            if self.first_block.is_none() {
                self.first_block = Some(self.bound_now(e.value));
            }
            if let Some(mu) = self.squeeze(db, dc) {
                return Some((e, mu));
            }
            self.heap.pop();
            self.dropped.push(e);
            self.offer_alone(e);
        }
        None
    }

    /// The continuous level that makes room for an increment `(db, dc)`, if
    /// the exchange gains benefit.
    fn squeeze(&self, db: f64, dc: f64) -> Option<f64> {
        let room = self.budget_ms - self.cost_d - dc;
        if !crate::lod::non_negative(room) || !crate::lod::positive(self.cost_c) {
            return None;
        }
        // Compared with the continuous variables taking all that is left.
        let without = self.levels.level_for_budget(self.budget_ms - self.cost_d);
        let mu = self.levels.level_for_budget(room);
        let gain = db - (self.levels.benefit(without) - self.levels.benefit(mu));
        (gain > 0.0).then_some(mu)
    }

    /// The better bound ([`Run::bound_at`]) of two prices: that of the
    /// discrete increment worth `value` per ms, and the continuous level
    /// the budget left allows. When no increment left is worth more than
    /// `value`, the greedy state lies on the fractional optimum's path and
    /// the higher of the two gives that optimum's value.
    fn bound_now(&self, value: f64) -> f64 {
        let level = self.levels.level_for_budget(self.budget_ms - self.cost_d);
        let (a, b) = (value.max(0.0), level);
        self.bound_at(a).min(self.bound_at(b)).min(self.least_bound(if a.is_finite() { a.min(b) } else { b }))
    }

    /// The least [`Run::bound_at`] over prices within [`PRICE_SPAN`] times
    /// `lambda` either way: every price bounds, and `bound_at` is convex in
    /// the price (so unimodal in its logarithm), so a golden-section search
    /// finds the tightest near the greedy's own prices, which alone can
    /// bound loosely where increments are far from convex. ∞ for a price
    /// that is not positive and finite.
    fn least_bound(&self, lambda: f64) -> f64 {
        if !(lambda.is_finite() && lambda > 0.0) {
            return f64::INFINITY;
        }
        let at = |t: f64| self.bound_at(t.exp());
        let golden = (5f64.sqrt() - 1.0) / 2.0;
        let (mut lo, mut hi) = (lambda.ln() - PRICE_SPAN.ln(), lambda.ln() + PRICE_SPAN.ln());
        let (mut a, mut b) = (hi - golden * (hi - lo), lo + golden * (hi - lo));
        let (mut fa, mut fb) = (at(a), at(b));
        for _ in 0..PRICE_STEPS {
            if fa <= fb {
                (hi, b, fb) = (b, a, fa);
                a = hi - golden * (hi - lo);
                fa = at(a);
            } else {
                (lo, a, fa) = (a, b, fb);
                b = lo + golden * (hi - lo);
                fb = at(b);
            }
        }
        fa.min(fb)
    }

    /// No feasible answer beats `λ·T` plus the best `b − λ·c` of the cuts
    /// and of the continuous variables, for any price `λ ≥ 0` per ms
    /// (Lagrangian duality, whatever the signs of the increments); ∞ for
    /// an infinite price or a NaN sum.
    fn bound_at(&self, lambda: f64) -> f64 {
        let spend = |ms: f64| if lambda == 0.0 { 0.0 } else { lambda * ms };
        let continuous = self.levels.benefit(lambda) - spend(self.levels.cost_ms(lambda));
        let bound = spend(self.budget_ms) + self.forest.best_priced(lambda) + continuous;
        if lambda.is_finite() && !bound.is_nan() { bound } else { f64::INFINITY }
    }

    /// A blocked group's head alone, if that is worth something: offered
    /// if it fits (with the continuous variables giving way, if need be),
    /// kept for the exchange steps otherwise.
    fn offer_alone(&mut self, e: Entry) {
        if let (false, Some((db, dc))) = (e.alone, self.forest.increment(e.node)) {
            let alone = Entry { value: ratio(db, dc), node: e.node, alone: true };
            if alone.value > 0.0 && dc <= self.budget_ms - self.cost_d {
                self.heap.push(alone);
            } else if alone.value > 0.0 {
                // Perhaps after an exchange.
                self.dropped.push(alone);
            }
        }
    }

    /// Whether `e` can still be applied: its head is unsplit and its parent
    /// split (or it is a root).
    fn available(&self, e: &Entry) -> bool {
        !self.split[e.node as usize] && self.forest.node(e.node).parent.is_none_or(|p| self.split[p as usize])
    }

    fn continuous_slope(&self) -> Option<f64> {
        if self.continuous_done || !crate::lod::positive(self.remaining_ms()) {
            return None;
        }
        self.levels.slope(self.mu)
    }

    /// Takes the top of the heap.
    fn take(&mut self, e: Entry, mu: f64) {
        self.heap.pop();
        self.apply(e, mu);
    }

    /// Applies increment `e` with the continuous variables at level `mu`
    /// and offers what it makes available.
    fn apply(&mut self, e: Entry, mu: f64) {
        self.set_level(mu);
        let (db, dc) = self.delta(&e);
        self.benefit_d += db;
        self.cost_d += dc;
        let members: Vec<u32> = self.members(&e).collect();
        for &m in &members {
            self.split[m as usize] = true;
        }
        self.applied.extend(&members);
        for &m in &members {
            for i in 0..self.forest.children(m).len() {
                let c = self.forest.children(m)[i];
                if !self.split[c as usize] {
                    self.offer(c);
                }
            }
        }
    }

    fn set_level(&mut self, mu: f64) {
        if mu != self.mu {
            self.mu = mu;
            self.cost_c = self.levels.cost_ms(mu);
        }
    }

    /// The nodes an entry splits: its head alone, or its whole group.
    fn members(&self, e: &Entry) -> impl Iterator<Item = u32> + '_ {
        let group = (!e.alone).then(|| self.groups.members(e.node).skip(1));
        std::iter::once(e.node).chain(group.into_iter().flatten())
    }

    /// Lowers the continuous level to the discrete slope or to where the
    /// budget is spent, whichever is higher.
    fn continuous_step(&mut self, slope_d: f64, slope_c: f64) {
        let target = slope_d.max(self.levels.level_for_budget(self.budget_ms - self.cost_d));
        if target >= slope_c.min(self.mu) {
            // No progress is possible at this precision.
            self.continuous_done = true;
            return;
        }
        self.mu = target;
        self.cost_c = self.levels.cost_ms(target);
    }

    fn finish(mut self, stop: Stop, deadline: Option<Instant>) -> Selection {
        let (benefit_d, cost_d) = drawn_sums(self.forest, &self.split);
        let benefit = benefit_d + self.levels.benefit(self.mu);
        let mut upper_bound = match (stop, self.first_block) {
            (_, Some(bound)) => bound.max(benefit),
            (Stop::FullResolution, None) => benefit,
            _ => self.open_bound(benefit),
        };
        let mut answer = Answer::Greedy;
        let fits = cost_d + self.levels.cost_ms(self.mu) <= self.budget_ms;
        let vouched = fits && benefit >= (1.0 - knapsack::EPSILON) * upper_bound;
        if stop != Stop::Limit
            && !vouched
            && let Some((better, bound)) = self.knapsack(benefit, deadline)
        {
            upper_bound = upper_bound.min(bound);
            if better {
                answer = Answer::Knapsack;
            }
        }
        let (benefit_d, cost_d) = drawn_sums(self.forest, &self.split);
        let benefit = benefit_d + self.levels.benefit(self.mu);
        let cost_ms = cost_d + self.levels.cost_ms(self.mu);
        Selection {
            resolutions: self.levels.resolutions(self.mu),
            split: self.split,
            benefit,
            cost_ms,
            overrun_ms: (cost_ms - self.asked_ms).max(0.0),
            upper_bound: upper_bound.max(benefit),
            level: self.mu,
            stop,
            iterations: self.iterations,
            answer,
        }
    }

    /// The bound when stopped early with nothing blocked yet.
    fn open_bound(&mut self, benefit: f64) -> f64 {
        let discrete = self.heap.peek().map_or(0.0, |e| e.value);
        self.bound_now(discrete).max(benefit)
    }
}
