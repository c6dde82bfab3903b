//! The continuous half of the optimiser (000 §3.4 and Figure 1): smooth-LOD
//! variables `x ∈ [0, capacity]` with the smoothed square-root benefit of
//! [`crate::lod::model::Smooth`] and a linear cost, and the line search that
//! raises them "as long as this is preferable over the discrete step".
//!
//! The paper moves all variables along one straight search direction (the
//! barrier-penalised gradient) and stops where the directional slope
//! `d b̃_c / d cost` equals the best discrete slope `slope_d`, then repeats.
//! Because every benefit here is separable and concave and every cost linear,
//! the point that search converges to is known in closed form: each variable
//! sits where its own benefit-per-millisecond slope equals one common level
//! `μ` (or at a bound). So the line search runs over that level instead: a
//! step lowers `μ` to `max(slope_d, μ_budget)`, where `μ_budget` spends the
//! remaining budget exactly. This is the limit of the paper's iteration (its
//! Figure 1 point Q for every variable at once), costs O(log m) per step
//! with prefix sums over the sorted breakpoints, and the slope `μ` is
//! directly comparable with the discrete increments' benefit/cost ratios.
//!
//! Invariants: `cost(μ)` is non-increasing and `benefit(μ)` non-increasing in
//! `μ`; the level a budget search returns never spends more than the budget;
//! no input (zero weight, zero cost, `s = 0`, infinite values) yields NaN.

use crate::lod::model::Smooth;

/// One continuous variable: a smooth-LOD object, or a group of objects that
/// hierarchical splitting tied to one resolution (000 §3.5).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Continuous {
    /// Benefit at full resolution (`x = capacity`); benefit at `x` is
    /// `weight · φ(x / capacity)` with the smoothed square root `φ`.
    pub weight: f64,
    /// Units at full resolution (e.g. splats); `x ∈ [0, capacity]`.
    pub capacity: f64,
    /// Predicted cost of one unit, milliseconds.
    pub cost_per_unit_ms: f64,
}

/// How one variable behaves on the slope-level curve.
#[derive(Clone, Copy, Debug)]
enum Kind {
    /// No benefit or no capacity: stays at 0.
    Inert,
    /// No cost: at full resolution from the start.
    Free,
    /// Starts above 0 below level `start`, reaches full resolution at `full`;
    /// in between `u = (a/μ)² − s`.
    Priced { a: f64, start: f64, full: f64 },
}

impl Kind {
    /// The start level of a priced variable (0 otherwise).
    fn start(self) -> f64 {
        match self {
            Kind::Priced { start, .. } => start,
            _ => 0.0,
        }
    }

    /// The full-resolution level of a priced variable (0 otherwise).
    fn full(self) -> f64 {
        match self {
            Kind::Priced { full, .. } => full,
            _ => 0.0,
        }
    }
}

/// A sum kept as an unevaluated pair `hi + lo` (Knuth's two-sum), so that
/// differences of prefix sums do not lose the small interior terms to the
/// large saturated ones.
#[derive(Clone, Copy, Debug, Default)]
struct Exact {
    hi: f64,
    lo: f64,
}

impl Exact {
    fn add(self, x: f64) -> Exact {
        let s = self.hi + x;
        let bb = s - self.hi;
        let err = (self.hi - (s - bb)) + (x - bb);
        Exact { hi: s, lo: self.lo + err }
    }
    fn plus(self, o: Exact) -> Exact {
        let e = self.add(o.hi);
        Exact { hi: e.hi, lo: e.lo + o.lo }
    }
    fn minus(self, o: Exact) -> f64 {
        let e = self.add(-o.hi);
        e.hi + (e.lo - o.lo)
    }
    fn value(self) -> f64 {
        self.hi + self.lo
    }
}

/// Sums of one set of variables, for the closed forms of cost and benefit.
#[derive(Clone, Copy, Debug, Default)]
struct Sums {
    /// Σ c·cap (cost at full resolution).
    p: Exact,
    /// Σ c·cap·a².
    pa2: Exact,
    /// Σ weight·a.
    wa: Exact,
    /// Σ weight.
    w: Exact,
}

/// Plain sums of a set: the difference of two prefix sums.
#[derive(Clone, Copy, Debug)]
struct Plain {
    p: f64,
    pa2: f64,
    wa: f64,
    w: f64,
}

impl Sums {
    fn of(p: f64, pa2: f64, wa: f64, w: f64) -> Sums {
        let e = |x| Exact::default().add(x);
        Sums { p: e(p), pa2: e(pa2), wa: e(wa), w: e(w) }
    }
    fn plus(self, o: Sums) -> Sums {
        Sums { p: self.p.plus(o.p), pa2: self.pa2.plus(o.pa2), wa: self.wa.plus(o.wa), w: self.w.plus(o.w) }
    }
    fn minus(self, o: Sums) -> Plain {
        Plain { p: self.p.minus(o.p), pa2: self.pa2.minus(o.pa2), wa: self.wa.minus(o.wa), w: self.w.minus(o.w) }
    }
    fn plain(self) -> Plain {
        Plain { p: self.p.value(), pa2: self.pa2.value(), wa: self.wa.value(), w: self.w.value() }
    }
}

/// The continuous variables prepared for level queries: breakpoints sorted
/// with prefix sums, so cost and benefit at a level take two binary searches.
/// A variable's start and full-resolution levels are its `a` times constants
/// of the shape, so one order (by `a`, descending) sorts both, and one
/// prefix sum serves both.
#[derive(Clone, Debug)]
pub struct Levels {
    shape: Smooth,
    kinds: Vec<Kind>,
    vars: Vec<Continuous>,
    /// Start levels, descending (∞ with `s = 0`).
    starts: Vec<f64>,
    /// Full-resolution levels, descending, in the same order.
    fulls: Vec<f64>,
    /// Prefix sums in that order (`sums[k]`: the first k).
    sums: Vec<Sums>,
    /// Benefit of the free variables.
    free_benefit: f64,
    /// Cost of everything at full resolution.
    total_cost_ms: f64,
    /// The highest start level (the first slope on offer).
    top_start: f64,
}

impl Levels {
    /// Prepares `vars` (O(m log m)).
    pub fn new(vars: &[Continuous], shape: Smooth) -> Levels {
        let kinds: Vec<Kind> = vars.iter().map(|v| kind(v, shape)).collect();
        let free_benefit =
            vars.iter().zip(&kinds).filter(|(_, k)| matches!(k, Kind::Free)).map(|(v, _)| v.weight).sum();
        let mut priced: Vec<(f64, u32)> = kinds
            .iter()
            .enumerate()
            .filter_map(|(i, k)| match *k {
                Kind::Priced { a, .. } => Some((a, i as u32)),
                _ => None,
            })
            .collect();
        // `a` is finite and positive: its bits order it as integers do.
        priced.sort_unstable_by_key(|&(a, _)| std::cmp::Reverse(a.to_bits()));
        let mut sums = Vec::with_capacity(priced.len() + 1);
        let mut acc = Sums::default();
        sums.push(acc);
        for &(a, i) in &priced {
            let v = &vars[i as usize];
            let p = v.cost_per_unit_ms * v.capacity;
            acc = acc.plus(Sums::of(p, p * a * a, v.weight * a, v.weight));
            sums.push(acc);
        }
        // Division by a positive constant keeps the order of `a`.
        let starts: Vec<f64> = priced.iter().map(|&(_, i)| kinds[i as usize].start()).collect();
        let fulls: Vec<f64> = priced.iter().map(|&(_, i)| kinds[i as usize].full()).collect();
        let total_cost_ms = sums.last().map_or(0.0, |s| s.p.value());
        let top_start = starts.first().copied().unwrap_or(0.0);
        Levels { shape, kinds, vars: vars.to_vec(), starts, fulls, sums, free_benefit, total_cost_ms, top_start }
    }

    /// Number of variables.
    pub fn len(&self) -> usize {
        self.vars.len()
    }

    /// Whether there are no variables.
    pub fn is_empty(&self) -> bool {
        self.vars.is_empty()
    }

    /// Interior and saturated sums at level `mu`.
    fn sums(&self, mu: f64) -> (Plain, Plain) {
        let started = self.starts.partition_point(|&s| s > mu);
        let full = self.fulls.partition_point(|&f| f >= mu);
        let sat = self.sums[full];
        (self.sums[started].minus(sat), sat.plain())
    }

    /// Predicted cost at level `mu` (ms); `mu = ∞`: nothing drawn.
    pub fn cost_ms(&self, mu: f64) -> f64 {
        if mu == f64::INFINITY {
            return 0.0;
        }
        if mu <= 0.0 {
            return self.total_cost_ms;
        }
        let (int, sat) = self.sums(mu);
        let interior = int.pa2 / (mu * mu) - self.shape.s * int.p;
        (sat.p + interior.max(0.0)).min(self.total_cost_ms)
    }

    /// Total benefit at level `mu`.
    pub fn benefit(&self, mu: f64) -> f64 {
        if mu == f64::INFINITY {
            return self.free_benefit;
        }
        if mu <= 0.0 {
            return self.free_benefit + self.sums.last().map_or(0.0, |s| s.w.value());
        }
        let (int, sat) = self.sums(mu);
        let interior = (int.wa / mu - self.shape.s.sqrt() * int.w) / self.shape.norm();
        self.free_benefit + sat.w + interior.max(0.0)
    }

    /// The slope on offer at level `mu`: the benefit per millisecond of the
    /// next unit, or `None` when everything is at full resolution.
    pub fn slope(&self, mu: f64) -> Option<f64> {
        (self.cost_ms(mu) < self.total_cost_ms).then(|| mu.min(self.top_start))
    }

    /// The lowest level whose cost fits in `budget_ms` (all variables at
    /// full resolution gives 0; no budget gives ∞). `cost_ms` of the answer
    /// never exceeds the budget.
    pub fn level_for_budget(&self, budget_ms: f64) -> f64 {
        if !crate::lod::positive(budget_ms) {
            return f64::INFINITY;
        }
        if self.total_cost_ms <= budget_ms {
            return 0.0;
        }
        // Bracket: `hi` fits, `lo` does not.
        // With s = 0 nothing has a finite start level: begin at twice the
        // highest full-resolution level and climb.
        let first = match self.top_start.is_finite() {
            true => self.top_start,
            false => 2.0 * self.fulls.first().copied().unwrap_or(1.0),
        };
        let mut hi = first.clamp(f64::MIN_POSITIVE, f64::MAX / 4.0);
        while self.cost_ms(hi) > budget_ms && hi < f64::MAX / 4.0 {
            hi *= 4.0;
        }
        if self.cost_ms(hi) > budget_ms {
            return f64::INFINITY;
        }
        let mut lo = hi;
        while self.cost_ms(lo) <= budget_ms && lo > f64::MIN_POSITIVE * 4.0 {
            lo /= 4.0;
        }
        // Bisection in log space until the bracket is 1e-12 relative.
        for _ in 0..200 {
            if hi <= lo * (1.0 + 1e-12) {
                break;
            }
            let mid = lo.sqrt() * hi.sqrt();
            if self.cost_ms(mid) <= budget_ms {
                hi = mid;
            } else {
                lo = mid;
            }
        }
        hi
    }

    /// The resolution of every variable at level `mu`, in input order.
    pub fn resolutions(&self, mu: f64) -> Vec<f64> {
        self.vars.iter().zip(&self.kinds).map(|(v, k)| v.capacity * self.fraction(*k, mu)).collect()
    }

    /// Relative resolution `u ∈ [0, 1]` of one variable at level `mu`.
    fn fraction(&self, kind: Kind, mu: f64) -> f64 {
        match kind {
            Kind::Inert => 0.0,
            Kind::Free => 1.0,
            Kind::Priced { a, start, full } => {
                if mu >= start {
                    0.0
                } else if mu <= full {
                    1.0
                } else {
                    ((a / mu).powi(2) - self.shape.s).clamp(0.0, 1.0)
                }
            }
        }
    }
}

/// Classifies a variable and computes its breakpoints: the slope per ms is
/// `weight φ'(u) / (capacity · c) = a / √(u + s)` with
/// `a = weight / (2 · norm · capacity · c)`.
fn kind(v: &Continuous, shape: Smooth) -> Kind {
    let usable = |x: f64| x.is_finite() && x > 0.0;
    if !usable(v.weight) || !usable(v.capacity) {
        return Kind::Inert;
    }
    if !crate::lod::positive(v.cost_per_unit_ms) {
        return Kind::Free;
    }
    if !v.cost_per_unit_ms.is_finite() {
        return Kind::Inert;
    }
    let a = v.weight / (2.0 * shape.norm() * v.capacity * v.cost_per_unit_ms);
    if !usable(a) {
        return Kind::Inert;
    }
    let start = if shape.s > 0.0 { a / shape.s.sqrt() } else { f64::INFINITY };
    Kind::Priced { a, start, full: a / (1.0 + shape.s).sqrt() }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn var(weight: f64, capacity: f64, cost: f64) -> Continuous {
        Continuous { weight, capacity, cost_per_unit_ms: cost }
    }

    /// Direct per-variable sums, for comparison with the prefix-sum forms.
    fn direct(levels: &Levels, mu: f64) -> (f64, f64) {
        let x = levels.resolutions(mu);
        let cost = levels.vars.iter().zip(&x).map(|(v, x)| v.cost_per_unit_ms.max(0.0) * x).sum();
        let benefit = levels.vars.iter().zip(&x).map(|(v, x)| v.weight * levels.shape.phi(x / v.capacity)).sum();
        (cost, benefit)
    }

    proptest! {
        #[test]
        fn closed_forms_match_direct_sums(
            vars in prop::collection::vec((0.01f64..100.0, 1.0f64..64.0, 0.001f64..1.0), 1..30),
            s in 0.0f64..0.2,
            log_mu in -6.0f64..6.0,
        ) {
            let vars: Vec<_> = vars.into_iter().map(|(w, c, k)| var(w, c, k)).collect();
            let levels = Levels::new(&vars, Smooth { s });
            let mu = 10f64.powf(log_mu);
            let (cost, benefit) = direct(&levels, mu);
            prop_assert!((levels.cost_ms(mu) - cost).abs() <= 1e-9 * (1.0 + cost));
            prop_assert!((levels.benefit(mu) - benefit).abs() <= 1e-9 * (1.0 + benefit));
        }

        #[test]
        fn budget_level_spends_at_most_the_budget_and_nearly_all_of_it(
            vars in prop::collection::vec((0.01f64..100.0, 1.0f64..64.0, 0.001f64..1.0), 1..30),
            s in 0.0f64..0.2,
            share in 0.0f64..1.2,
        ) {
            let vars: Vec<_> = vars.into_iter().map(|(w, c, k)| var(w, c, k)).collect();
            let levels = Levels::new(&vars, Smooth { s });
            let budget = share * levels.total_cost_ms;
            let mu = levels.level_for_budget(budget);
            let spent = levels.cost_ms(mu);
            prop_assert!(spent <= budget);
            prop_assert!(spent >= budget.min(levels.total_cost_ms) * (1.0 - 1e-9) - 1e-12);
        }

        #[test]
        fn equal_slopes_at_a_level(
            vars in prop::collection::vec((0.01f64..100.0, 1.0f64..64.0, 0.001f64..1.0), 2..10),
            log_mu in -2.0f64..2.0,
        ) {
            // KKT: interior variables have benefit slope per ms equal to μ.
            let shape = Smooth { s: 0.01 };
            let vars: Vec<_> = vars.into_iter().map(|(w, c, k)| var(w, c, k)).collect();
            let levels = Levels::new(&vars, shape);
            let mu = 10f64.powf(log_mu);
            for (v, x) in vars.iter().zip(levels.resolutions(mu)) {
                let u = x / v.capacity;
                let slope = v.weight * shape.slope(u) / (v.capacity * v.cost_per_unit_ms);
                if u > 0.0 && u < 1.0 {
                    prop_assert!((slope - mu).abs() <= 1e-9 * mu);
                } else if u == 0.0 {
                    prop_assert!(slope <= mu * (1.0 + 1e-12));
                } else {
                    prop_assert!(slope >= mu * (1.0 - 1e-12));
                }
            }
        }
    }

    #[test]
    fn degenerate_variables_never_make_nan() {
        let vars = [
            var(0.0, 10.0, 1.0),
            var(5.0, 0.0, 1.0),
            var(5.0, 10.0, 0.0),
            var(f64::INFINITY, 10.0, 1.0),
            var(5.0, 10.0, f64::INFINITY),
            var(f64::NAN, 10.0, 1.0),
            var(3.0, 8.0, 0.5),
        ];
        for s in [0.0, 1e-12, 0.05] {
            let levels = Levels::new(&vars, Smooth { s });
            for mu in [0.0, 1e-300, 1e-3, 1.0, 1e300, f64::INFINITY] {
                assert!(levels.cost_ms(mu).is_finite() && levels.benefit(mu).is_finite(), "{s} {mu}");
                assert!(levels.resolutions(mu).iter().all(|x| x.is_finite()));
            }
            for budget in [-1.0, 0.0, 1e-9, 1.0, 1e9, f64::NAN] {
                let mu = levels.level_for_budget(budget);
                assert!(!mu.is_nan());
                assert!(levels.cost_ms(mu) <= budget.max(0.0) || budget.is_nan() && levels.cost_ms(mu) == 0.0);
            }
            // The free variable is at full resolution even with no budget.
            assert_eq!(levels.resolutions(f64::INFINITY)[2], 10.0);
        }
    }
}
