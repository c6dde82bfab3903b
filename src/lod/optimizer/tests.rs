//! The optimiser against the exact optimum (brute force over the discrete
//! cuts, an independent numerical solution of the continuous part), on
//! random small instances, adversarial ones, and stiff and extreme ones.

use super::*;
use crate::lod::model::{Smooth, tile_benefit};
use crate::noise::{hash2, unit};
use proptest::prelude::*;

/// The exact continuous optimum for `budget_ms`, found numerically (nested
/// bisections on the slopes), independently of [`Levels`]' closed forms.
fn exact_continuous(vars: &[Continuous], smooth: Smooth, budget_ms: f64) -> f64 {
    let at = |lambda: f64| -> (f64, f64) {
        vars.iter().fold((0.0, 0.0), |(b, c), v| {
            let slope = |u: f64| v.weight * smooth.slope(u) / (v.capacity * v.cost_per_unit_ms);
            let u = if slope(1.0) >= lambda {
                1.0
            } else if slope(0.0) <= lambda {
                0.0
            } else {
                let (mut lo, mut hi) = (0.0, 1.0);
                for _ in 0..80 {
                    let mid = 0.5 * (lo + hi);
                    if slope(mid) > lambda { lo = mid } else { hi = mid }
                }
                lo
            };
            (b + v.weight * smooth.phi(u), c + v.cost_per_unit_ms * v.capacity * u)
        })
    };
    if at(0.0).1 <= budget_ms {
        return at(0.0).0;
    }
    let (mut lo, mut hi) = (1e-12f64, 1e12f64);
    for _ in 0..200 {
        let mid = (lo * hi).sqrt();
        if at(mid).1 <= budget_ms { hi = mid } else { lo = mid }
    }
    at(hi).0
}

/// The best total over every cut of `forest` (the roots are forced).
fn exact(forest: &Forest, vars: &[Continuous], smooth: Smooth, budget_ms: f64) -> f64 {
    let mut split = vec![false; forest.len()];
    let mut best = f64::NEG_INFINITY;
    enumerate(forest, 0, &mut split, &mut |split| {
        let (b, c) = drawn_sums(forest, split);
        if c <= budget_ms {
            best = best.max(b + exact_continuous(vars, smooth, budget_ms - c));
        }
    });
    best
}

/// Calls `visit` with every split set closed under ancestors.
fn enumerate(forest: &Forest, i: usize, split: &mut Vec<bool>, visit: &mut dyn FnMut(&[bool])) {
    if i == forest.len() {
        visit(split);
        return;
    }
    let eligible =
        !forest.children(i as u32).is_empty() && forest.node(i as u32).parent.is_none_or(|p| split[p as usize]);
    enumerate(forest, i + 1, split, visit);
    if eligible {
        split[i] = true;
        enumerate(forest, i + 1, split, visit);
        split[i] = false;
    }
}

/// A random small tile forest: one or two roots, children splitting their
/// parent's screen size unevenly (perspective), tile-model benefits, costs
/// around one unit per tile with ±50 % spread, and up to four tree groups.
fn tile_instance(seed: u64) -> (Forest, Vec<Continuous>, f64) {
    let h = |a: i64, b: i64| hash2(a, b, seed);
    let mut nodes = Vec::new();
    let mut sizes = Vec::new();
    let roots = 1 + (h(0, 0) % 2) as usize;
    for r in 0..roots {
        nodes.push(Node { parent: None, benefit: 0.0, cost_ms: 0.0 });
        sizes.push(2e4 + 2e5 * unit(h(1, r as i64), 0));
    }
    let mut i = 0;
    while i < nodes.len() && nodes.len() < 22 {
        let depth = depth_of(&nodes, i);
        if depth < 2 && unit(h(2, i as i64), 0) < 0.7 {
            let shares: Vec<f64> = (0..4).map(|k| 0.2 + unit(h(3, i as i64), k)).collect();
            let total: f64 = shares.iter().sum();
            for s in shares {
                nodes.push(Node { parent: Some(i as u32), benefit: 0.0, cost_ms: 0.0 });
                sizes.push(sizes[i] * s / total);
            }
        }
        i += 1;
    }
    for (k, n) in nodes.iter_mut().enumerate() {
        n.benefit = tile_benefit(sizes[k], 64, Smooth::default());
        n.cost_ms = 0.5 + unit(h(4, k as i64), 0);
    }
    let vars = (0..(h(5, 0) % 5) as i64)
        .map(|k| Continuous {
            weight: 1e3 + 2e4 * unit(h(6, k), 0),
            capacity: 64.0 * (1.0 + unit(h(6, k), 1)),
            cost_per_unit_ms: 0.01 + 0.05 * unit(h(6, k), 2),
        })
        .collect();
    let forest = Forest::new(nodes).unwrap();
    let all: f64 = (0..forest.len() as u32).map(|i| forest.node(i).cost_ms).sum();
    let roots_cost: f64 = forest.roots().iter().map(|&r| forest.node(r).cost_ms).sum();
    let budget = roots_cost + (all - roots_cost) * unit(h(7, 0), 0);
    (forest, vars, budget)
}

fn depth_of(nodes: &[Node], mut i: usize) -> usize {
    let mut d = 0;
    while let Some(p) = nodes[i].parent {
        i = p as usize;
        d += 1;
    }
    d
}

/// A forest from `(parent, benefit, cost_ms)` rows.
fn forest_of(rows: &[(Option<u32>, f64, f64)]) -> Forest {
    Forest::new(rows.iter().map(|&(parent, benefit, cost_ms)| Node { parent, benefit, cost_ms }).collect()).unwrap()
}

/// Cases per property (and fixed seeds of the random instances): 300, or
/// `SYLVA_LOD_CASES` for a longer search.
fn cases() -> u32 {
    std::env::var("SYLVA_LOD_CASES").ok().and_then(|v| v.parse().ok()).unwrap_or(300)
}

/// Whether `benefit` is within the knapsack programme's share of `best`.
fn within_epsilon(benefit: f64, best: f64) -> bool {
    benefit >= (1.0 - super::knapsack::EPSILON) * best * (1.0 - 1e-12)
}

fn feasible(sel: &Selection, budget_ms: f64) -> bool {
    sel.cost_ms <= budget_ms * (1.0 + 1e-9) + 1e-12
}

/// Ratio of the optimiser's benefit to the exact optimum on instance
/// `seed`, after checking feasibility and the upper bound.
fn quality(seed: u64) -> f64 {
    let (forest, vars, budget) = tile_instance(seed);
    let sel = optimize(&forest, &vars, &Settings::budget(budget));
    let best = exact(&forest, &vars, Smooth::default(), budget);
    assert!(feasible(&sel, budget), "seed {seed}: {} > {budget}", sel.cost_ms);
    assert!(sel.benefit <= best * (1.0 + 1e-9) + 1e-9, "seed {seed}");
    assert!(sel.upper_bound >= best * (1.0 - 1e-9), "seed {seed}: bound {} < {best}", sel.upper_bound);
    sel.benefit / best
}

#[test]
fn random_small_instances_reach_95_percent_of_the_optimum() {
    // Fixed seeds, so the test cannot flake; `lod_quality_survey` runs more.
    for seed in 0..cases() {
        let q = quality(u64::from(seed));
        assert!(within_epsilon(q, 1.0), "seed {seed}: {q}");
    }
}

/// `SYLVA_LOD_CASES=100000 cargo test --release --lib lod_quality_survey
/// -- --ignored --nocapture`: the distribution behind docs/benchmarks.md.
#[test]
#[ignore]
fn lod_quality_survey() {
    let mut q: Vec<f64> = (0..cases()).map(|s| quality(u64::from(s) + (1 << 40))).collect();
    q.sort_by(f64::total_cmp);
    let below = q.iter().filter(|&&x| x < 0.95).count();
    let at = |f: f64| q[((q.len() - 1) as f64 * f) as usize];
    println!("{} instances: min {:.4}, 1 % {:.4}, median {:.4}, below 95 %: {below}", q.len(), q[0], at(0.01), at(0.5));
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(cases()))]

    #[test]
    fn adversarial_instances_reach_95_percent_of_the_optimum(
        small in prop::collection::vec((0.1f64..10.0, 0.1f64..5.0), 1..5),
        big_cost in 5.0f64..100.0,
        big_ratio in 0.2f64..1.0,
        dud in 0.0f64..0.05,
        fork in prop::collection::vec((0.3f64..0.8, 0.2f64..3.0), 0..3),
    ) {
        // Small increments worth slightly more per ms than one big one that
        // fills the whole budget (the knapsack trap), a non-convex chain (a
        // split worth almost nothing that opens a valuable one), and a fork:
        // a split worth nothing that opens branches each of which fits with
        // it, while their convexified group together may not.
        let mut nodes = vec![];
        let root = |nodes: &mut Vec<Node>| { nodes.push(Node { parent: None, benefit: 0.0, cost_ms: 0.0 }); nodes.len() as u32 - 1 };
        for (b, c) in &small {
            let r = root(&mut nodes);
            nodes.push(Node { parent: Some(r), benefit: *b * (1.0 + big_ratio), cost_ms: *c * *b });
        }
        let r = root(&mut nodes);
        nodes.push(Node { parent: Some(r), benefit: big_ratio * big_cost, cost_ms: big_cost });
        let r = root(&mut nodes);
        nodes.push(Node { parent: Some(r), benefit: dud, cost_ms: 1.0 });
        let mid = nodes.len() as u32 - 1;
        nodes.push(Node { parent: Some(mid), benefit: 50.0 * big_ratio, cost_ms: 2.0 });
        let budget = big_cost;
        let head = root(&mut nodes);
        let stem_ms = 0.05 * budget / fork.len().max(1) as f64;
        for (share, value) in &fork {
            nodes.push(Node { parent: Some(head), benefit: 0.0, cost_ms: stem_ms });
            let stem = nodes.len() as u32 - 1;
            for _ in 0..2 {
                nodes.push(Node { parent: Some(stem), benefit: value * share * budget / 2.0, cost_ms: share * budget / 2.0 });
            }
        }
        let forest = Forest::new(nodes).unwrap();
        let sel = optimize(&forest, &[], &Settings::budget(budget));
        let best = exact(&forest, &[], Smooth::default(), budget);
        prop_assert!(feasible(&sel, budget));
        prop_assert!(within_epsilon(sel.benefit, best), "{} against {best}", sel.benefit);
        prop_assert!(sel.upper_bound >= best * (1.0 - 1e-9));
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(cases()))]

    /// Forks of three or more branches, each a zero-benefit stem whose
    /// split opens one or two tiles, behind a zero-benefit chain, beside
    /// small increments worth more per ms. Their convexified group can
    /// exceed the budget while each branch fits; the optimum then mixes
    /// branches with the small increments, and the greedy alone fell to
    /// 0.42 of it in fuzzing.
    #[test]
    fn forks_of_three_or_more_branches_reach_95_percent_of_the_optimum(
        small in prop::collection::vec((0.5f64..4.0, 1.0f64..3.0), 1..3),
        chain in prop::collection::vec(0.0f64..1.0, 0..2),
        branches in prop::collection::vec((0.0f64..1.5, prop::collection::vec((0.5f64..7.0, 0.3f64..0.6), 1..3)), 3..5),
    ) {
        let mut rows = vec![];
        for (c, value) in &small {
            rows.push((None, 0.0, 0.0));
            rows.push((Some(rows.len() as u32 - 1), c * value, *c));
        }
        rows.push((None, 0.0, 0.0));
        for c in &chain {
            rows.push((Some(rows.len() as u32 - 1), 0.0, *c));
        }
        let head = rows.len() as u32 - 1;
        let mut stems = vec![];
        for (stem_ms, _) in &branches {
            rows.push((Some(head), 0.0, *stem_ms));
            stems.push(rows.len() as u32 - 1);
        }
        for (stem, (_, tiles)) in stems.iter().zip(&branches) {
            for (c, value) in tiles {
                rows.push((Some(*stem), c * value, *c));
            }
        }
        let forest = forest_of(&rows);
        let sel = optimize(&forest, &[], &Settings::budget(10.0));
        let best = exact(&forest, &[], Smooth::default(), 10.0);
        prop_assert!(feasible(&sel, 10.0));
        prop_assert!(within_epsilon(sel.benefit, best), "{} against {best}", sel.benefit);
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(cases()))]

    /// The programme's frontier: each state's splits sum to the state, and
    /// every cut within the budget has a state no dearer and at most the
    /// slack worse.
    #[test]
    fn the_knapsack_frontier_covers_every_cut(seed in 0u64..1 << 40, share in 1e-3f64..0.3) {
        let (forest, _, budget) = tile_instance(seed);
        let slack = share * (0..forest.len() as u32).map(|v| forest.node(v).benefit).sum::<f64>();
        let roots = drawn_sums(&forest, &vec![false; forest.len()]);
        let limits = knapsack::Limits { slack, room_ms: budget - roots.1, max_states: usize::MAX, deadline: None };
        let frontier = knapsack::frontier(&forest, &forest.splittable(budget), &limits).unwrap();
        for state in &frontier.states {
            let mut split = vec![false; forest.len()];
            frontier.taken(state).for_each(|v| split[v as usize] = true);
            let (b, c) = drawn_sums(&forest, &split);
            prop_assert!((b - roots.0 - state.benefit).abs() < 1e-9 && (c - roots.1 - state.cost_ms).abs() < 1e-9);
        }
        let mut uncovered = 0;
        enumerate(&forest, 0, &mut vec![false; forest.len()], &mut |split| {
            let (b, c) = drawn_sums(&forest, split);
            let covered = |s: &knapsack::State| {
                roots.1 + s.cost_ms <= c + 1e-9 && roots.0 + s.benefit >= b - slack - 1e-9
            };
            if c <= budget && !frontier.states.iter().any(covered) {
                uncovered += 1;
            }
        });
        prop_assert_eq!(uncovered, 0);
    }
}

#[test]
fn a_split_no_cut_affords_does_not_hide_the_rest_of_its_group() {
    // Splitting 1 opens a tile worth 57 that no cut within 3 ms draws; it
    // was merged into the root's group, which blocked, and the split of 2
    // (6 for 1 ms) was never taken: 0 against 6.
    let forest = forest_of(&[
        (None, 0.0, 0.0),
        (Some(0), 0.0, 0.0),
        (Some(0), 0.0, 0.0),
        (Some(1), 57.0, 4.0),
        (Some(2), 6.0, 1.0),
    ]);
    let sel = optimize(&forest, &[], &Settings::budget(3.0));
    assert_eq!(sel.benefit, 6.0, "{:?}", sel.split);
    assert!(!sel.split[1]);
}

#[test]
fn a_split_ruled_out_that_adds_nothing_leaves_full_resolution() {
    // Splitting 1 costs more than the budget: the answer is at full
    // resolution where that split adds nothing, and stopped by the budget
    // where it adds something.
    let stop = |child_benefit: f64| {
        let forest = forest_of(&[(None, 0.0, 0.0), (Some(0), 1.0, 1.0), (Some(1), child_benefit, 9.0)]);
        optimize(&forest, &[], &Settings::budget(3.0)).stop
    };
    assert_eq!(stop(0.5), Stop::FullResolution);
    assert_eq!(stop(2.0), Stop::Budget);
}

#[test]
fn a_three_branch_fork_larger_than_the_budget_reaches_95_percent_of_the_optimum() {
    // Splitting 2 opens three stems; its group {2, 4, 5} (5 for 11 ms) is
    // larger than the budget. The greedy takes 0's split (3 for 2 ms) and
    // is blocked by the group; the best parts of the group with their
    // ancestors are worth 3 at most, and 3's split (0.4 for 1 ms, left out
    // of the group) is in none. The optimum splits 0, 2, 3 and 4 (6.4 for
    // 10 ms); the greedy's answer was 3.
    let forest = forest_of(&[
        (None, 0.0, 0.0),
        (Some(0), 3.0, 2.0),
        (None, 0.0, 0.0),
        (Some(2), 0.0, 0.0),
        (Some(2), 0.0, 0.0),
        (Some(2), 0.0, 1.0),
        (Some(3), 0.4, 1.0),
        (Some(4), 1.0, 3.0),
        (Some(4), 2.0, 3.0),
        (Some(5), 2.0, 5.0),
    ]);
    let sel = optimize(&forest, &[], &Settings::budget(10.0));
    let best = exact(&forest, &[], Smooth::default(), 10.0);
    assert!(within_epsilon(sel.benefit, best), "{} against {best}", sel.benefit);
    assert_eq!(sel.answer, Answer::Knapsack);
}

#[test]
fn convexified_increments_see_past_a_worthless_split() {
    // Splitting the root is worth 0.1 for 1 ms, but opens a split worth 100
    // for 1 ms; a plain greedy would spend the budget on the two roots worth
    // 1 per ms instead.
    let mut nodes = vec![Node { parent: None, benefit: 0.0, cost_ms: 0.0 }];
    nodes.push(Node { parent: Some(0), benefit: 0.1, cost_ms: 1.0 });
    nodes.push(Node { parent: Some(1), benefit: 100.1, cost_ms: 2.0 });
    for _ in 0..2 {
        nodes.push(Node { parent: None, benefit: 0.0, cost_ms: 0.0 });
        let r = nodes.len() as u32 - 1;
        nodes.push(Node { parent: Some(r), benefit: 1.0, cost_ms: 1.0 });
    }
    let forest = Forest::new(nodes).unwrap();
    let sel = optimize(&forest, &[], &Settings::budget(2.0));
    assert_eq!(sel.benefit, 100.1);
    assert!(sel.split[0] && sel.split[1]);
}

#[test]
fn the_knapsack_takes_the_part_of_a_group_that_fits() {
    // Splitting 0 opens 1 and 2, each of whose splits fits with it (6.5 ms)
    // but not both (12 ms). The greedy takes 7's split first and is blocked
    // by the group {0, 2, 1}: 0.9. The optimum splits 0, 2 and 7 (10.92);
    // one branch is as good up to the programme's rounding.
    let forest = forest_of(&[
        (None, 0.0, 0.0),
        (Some(0), 0.0, 0.5),
        (Some(0), 0.0, 0.5),
        (Some(1), 5.0, 3.0),
        (Some(1), 5.0, 3.0),
        (Some(2), 5.01, 3.0),
        (Some(2), 5.01, 3.0),
        (None, 0.0, 0.0),
        (Some(7), 0.9, 0.5),
    ]);
    let sel = optimize(&forest, &[], &Settings::budget(10.0));
    assert_eq!(sel.answer, Answer::Knapsack);
    assert!(sel.benefit >= 10.9, "{} {:?}", sel.benefit, sel.split);
    assert!(sel.split[0] && sel.split[1] != sel.split[2] && sel.split[7]);
    assert!(sel.upper_bound >= 10.92 && sel.upper_bound <= 10.92 / (1.0 - 0.05) + 1e-9, "{}", sel.upper_bound);
}

#[test]
fn the_knapsack_programme_rescues_the_knapsack_trap() {
    // Three small increments worth 2 per ms come first; the big one worth 1
    // per ms no longer fits, and no single exchange makes room for it.
    let mut nodes = vec![];
    for (b, c) in [(2.0, 1.0), (2.0, 1.0), (2.0, 1.0), (100.0, 100.0)] {
        nodes.push(Node { parent: None, benefit: 0.0, cost_ms: 0.0 });
        nodes.push(Node { parent: Some(nodes.len() as u32 - 1), benefit: b, cost_ms: c });
    }
    let forest = Forest::new(nodes).unwrap();
    let sel = optimize(&forest, &[], &Settings::budget(100.0));
    assert_eq!(sel.answer, Answer::Knapsack);
    assert_eq!(sel.benefit, 100.0);
}

#[test]
fn a_split_whose_children_no_cut_draws_does_not_coarsen_the_programme() {
    // The knapsack trap beside a root whose child (worth 1e6) costs more
    // than the budget, though a cut splitting both is free: counted as a
    // lower bound of the optimum, its benefit made the programme's rounding
    // too coarse to tell 6 from 100.
    let mut rows = vec![];
    for (b, c) in [(2.0, 1.0), (2.0, 1.0), (2.0, 1.0), (100.0, 100.0)] {
        rows.push((None, 0.0, 0.0));
        rows.push((Some(rows.len() as u32 - 1), b, c));
    }
    rows.extend([(None, 0.0, 0.0), (Some(8), 1e6, 1e7), (Some(9), 0.0, 0.0)]);
    let sel = optimize(&forest_of(&rows), &[], &Settings::budget(100.0));
    assert_eq!(sel.benefit, 100.0, "{:?}", sel.split);
}

#[test]
fn a_node_of_unknown_cost_is_split_past_and_bounded() {
    // Node 1 costs ∞ (or NaN): no cut may draw it, but splitting it draws
    // a child worth 10 for 1 ms. The greedy saw an increment worth nothing
    // and stopped at "full resolution" with a bound of 0; the programme's
    // sums went NaN.
    for dear in [f64::INFINITY, f64::NAN] {
        let forest = forest_of(&[(None, 0.0, 0.0), (Some(0), 0.0, dear), (Some(1), 10.0, 1.0)]);
        let sel = optimize(&forest, &[], &Settings::budget(5.0));
        assert_eq!((sel.benefit, sel.cost_ms), (10.0, 1.0), "{dear}: {:?}", sel.split);
        assert!(sel.upper_bound >= 10.0 && sel.stop == Stop::Budget, "{dear}: {sel:?}");
    }
}

/// One root with four children of cost 1 and the given continuous variables.
fn small_scene(vars_cost: f64) -> (Forest, Vec<Continuous>) {
    let mut nodes = vec![Node { parent: None, benefit: 10.0, cost_ms: 1.0 }];
    for k in 0..4 {
        nodes.push(Node { parent: Some(0), benefit: 5.0 + f64::from(k), cost_ms: 1.0 });
    }
    let vars = (0..3)
        .map(|k| Continuous { weight: 20.0 * f64::from(k + 1), capacity: 64.0, cost_per_unit_ms: vars_cost })
        .collect();
    (Forest::new(nodes).unwrap(), vars)
}

#[test]
fn infinite_slopes_at_zero_resolution() {
    let (forest, vars) = small_scene(0.01);
    let settings = Settings { smooth: Smooth { s: 0.0 }, ..Settings::budget(4.0) };
    let sel = optimize(&forest, &vars, &settings);
    assert!(sel.benefit.is_finite() && sel.cost_ms <= 4.0 + 1e-12);
    assert!(sel.resolutions.iter().all(|x| x.is_finite() && *x > 0.0), "{:?}", sel.resolutions);
    let best = exact(&forest, &vars, settings.smooth, 4.0);
    assert!(sel.benefit >= 0.95 * best, "{} vs {best}", sel.benefit);
}

#[test]
fn everything_at_its_bounds_when_the_budget_allows() {
    let (forest, vars) = small_scene(0.01);
    let sel = optimize(&forest, &vars, &Settings::budget(1e6));
    assert_eq!(sel.stop, Stop::FullResolution);
    assert!(sel.split[0]);
    assert_eq!(sel.resolutions, vec![64.0; 3]);
    assert_eq!(sel.upper_bound, sel.benefit);
}

#[test]
fn zero_cost_items_are_taken_with_no_budget_left() {
    let mut nodes = vec![Node { parent: None, benefit: 1.0, cost_ms: 3.0 }];
    nodes.push(Node { parent: Some(0), benefit: 4.0, cost_ms: 1.5 });
    nodes.push(Node { parent: Some(0), benefit: 4.0, cost_ms: 1.5 });
    let forest = Forest::new(nodes).unwrap();
    let vars = [Continuous { weight: 7.0, capacity: 10.0, cost_per_unit_ms: 0.0 }];
    let sel = optimize(&forest, &vars, &Settings::budget(3.0));
    assert!(sel.split[0], "a split that costs nothing extra is taken");
    assert_eq!(sel.resolutions, vec![10.0]);
    assert_eq!(sel.benefit, 15.0);
}

#[test]
fn a_budget_below_the_coarsest_still_draws_it_and_reports_the_overrun() {
    let (forest, vars) = small_scene(0.01);
    for budget in [0.25, 0.0, -5.0, f64::NAN] {
        let sel = optimize(&forest, &vars, &Settings::budget(budget));
        assert_eq!(sel.drawn(&forest).collect::<Vec<_>>(), vec![0]);
        assert_eq!(sel.cost_ms, 1.0);
        assert!((sel.overrun_ms - (1.0 - budget.max(0.0))).abs() < 1e-12 || budget.is_nan(), "{budget}");
        assert!(sel.overrun_ms > 0.0);
        assert_eq!(sel.resolutions, vec![0.0; 3]);
        assert_eq!(sel.stop, Stop::Budget);
        // Nothing no dearer than the roots is worth much more: the bound is
        // theirs, not that of a budget no cut meets (146).
        assert!(sel.benefit >= 0.95 * sel.upper_bound, "{budget}: bound {}", sel.upper_bound);
    }
}

#[test]
fn a_cut_within_the_budget_is_found_below_roots_that_overrun_it() {
    // Regression: searched under the roots' cost, the greedy spent what a
    // split below them freed and overran a budget that a cut meets.
    let mut nodes = vec![Node { parent: None, benefit: 10.0, cost_ms: 2.0 }];
    nodes.extend((0..4).map(|_| Node { parent: Some(0), benefit: 4.0, cost_ms: 0.3 }));
    for child in 1..=4 {
        nodes.extend((0..4).map(|_| Node { parent: Some(child), benefit: 1.5, cost_ms: 0.2 }));
    }
    let forest = Forest::new(nodes).unwrap();
    let vars = [Continuous { weight: 5.0, capacity: 10.0, cost_per_unit_ms: 0.1 }];
    for vars in [&[][..], &vars[..]] {
        let sel = optimize(&forest, vars, &Settings::budget(1.5));
        assert!(sel.overrun_ms == 0.0 && sel.cost_ms <= 1.5 + 1e-12, "{sel:?}");
        assert!(sel.benefit >= 0.95 * exact(&forest, vars, Smooth::default(), 1.5), "{sel:?}");
    }
    // Roots worth more than any cut that fits are not kept for it.
    let mut nodes = vec![Node { parent: None, benefit: 100.0, cost_ms: 2.0 }];
    nodes.extend((0..4).map(|_| Node { parent: Some(0), benefit: 24.75, cost_ms: 0.25 }));
    let forest = Forest::new(nodes).unwrap();
    let sel = optimize(&forest, &[], &Settings::budget(1.5));
    assert_eq!((sel.drawn(&forest).count(), sel.overrun_ms), (4, 0.0), "{sel:?}");
}

#[test]
fn a_cut_cheaper_than_the_roots_is_drawn_when_they_overrun() {
    // Four children cheaper together than their parent and worth more.
    let mut nodes = vec![Node { parent: None, benefit: 10.0, cost_ms: 2.0 }];
    nodes.extend((0..4).map(|_| Node { parent: Some(0), benefit: 4.0, cost_ms: 0.3 }));
    let forest = Forest::new(nodes).unwrap();
    let sel = optimize(&forest, &[], &Settings::budget(1.0));
    assert_eq!(sel.drawn(&forest).collect::<Vec<_>>(), vec![1, 2, 3, 4]);
    assert!((sel.cost_ms - 1.2).abs() < 1e-12 && (sel.overrun_ms - 0.2).abs() < 1e-12, "{sel:?}");
    assert!(sel.upper_bound >= 16.0 && sel.benefit >= 0.95 * sel.upper_bound, "{sel:?}");
}

#[test]
fn a_million_continuous_objects() {
    let vars: Vec<Continuous> = (0..1_000_000i64)
        .map(|k| {
            let h = hash2(k, 1, 2);
            Continuous {
                weight: if k % 97 == 0 { 0.0 } else { 1e-3 + unit(h, 0) },
                capacity: 1.0 + 63.0 * unit(h, 1),
                cost_per_unit_ms: if k % 101 == 0 { 0.0 } else { 1e-5 * (0.1 + unit(h, 2)) },
            }
        })
        .collect();
    let (forest, _) = small_scene(0.0);
    for s in [0.0, 1.0 / 64.0] {
        let settings = Settings { smooth: Smooth { s }, ..Settings::budget(50.0) };
        let sel = optimize(&forest, &vars, &settings);
        assert!(
            feasible(&sel, 50.0) && sel.cost_ms > 49.9,
            "{:?}",
            (sel.cost_ms, sel.level, sel.stop, sel.iterations, &sel.split)
        );
        assert!(sel.benefit.is_finite() && sel.upper_bound >= sel.benefit);
        assert!(sel.resolutions.iter().zip(&vars).all(|(x, v)| x.is_finite() && *x >= 0.0 && *x <= v.capacity));
        assert!(sel.iterations <= 2 * forest.len() + 2, "{}", sel.iterations);
    }
}

#[test]
fn limits_stop_it_with_a_feasible_answer() {
    let (forest, vars, budget) = tile_instance(7);
    for max_iterations in [0, 1, 2, 3] {
        let sel = optimize(&forest, &vars, &Settings { max_iterations, ..Settings::budget(budget) });
        assert!(sel.iterations <= max_iterations && feasible(&sel, budget));
        assert_eq!(sel.stop, Stop::Limit);
        assert!(sel.upper_bound >= exact(&forest, &vars, Smooth::default(), budget) * (1.0 - 1e-9));
    }
    let past = Instant::now();
    let sel = optimize(&forest, &vars, &Settings { deadline: Some(past), ..Settings::budget(budget) });
    assert!(feasible(&sel, budget) && sel.iterations <= 64);
}

#[test]
fn parents_must_come_first() {
    let nodes =
        vec![Node { parent: Some(1), benefit: 1.0, cost_ms: 1.0 }, Node { parent: None, benefit: 1.0, cost_ms: 1.0 }];
    assert_eq!(Forest::new(nodes).unwrap_err(), LodError::ParentAfterChild { node: 0, parent: 1 });
    let looped = vec![Node { parent: Some(0), benefit: 1.0, cost_ms: 1.0 }];
    assert!(Forest::new(looped).is_err());
}

/// An instance on which an exchange undoes 0's split and takes 1's, then
/// 3's, which 1 opens.
fn exchanging_instance() -> (Forest, f64) {
    let forest = forest_of(&[
        (None, 0.5469239471139316, 0.4594792327275998),
        (None, 0.16176975419084982, 0.27292652428633873),
        (Some(0), 1.3367224309052932, 0.6029250822155918),
        (Some(1), 0.5817401614372553, 1.2681007491879956),
        (Some(3), 0.8489283481992361, 0.5133750205103131),
        (Some(3), 0.7376661422780353, 1.569053386010419),
        (Some(4), 2.1237040983072286, 1.0662633101850394),
        (Some(5), 0.8639932277557765, 0.4339855238299229),
    ]);
    // At 1.78 ms (where it was found) no cut affords 4's split and the
    // greedy needs no exchange.
    (forest, 2.0)
}

#[test]
fn a_group_an_exchange_opens_and_takes_is_not_applied_again() {
    // 3 was also offered to the heap when 1 was applied, and the greedy
    // then applied it a second time (1.96 ms).
    let (forest, budget) = exchanging_instance();
    let sel = optimize(&forest, &[], &Settings::budget(budget));
    assert!(feasible(&sel, budget), "{} > {budget}", sel.cost_ms);
    assert!(sel.benefit >= 0.5 * exact(&forest, &[], Smooth::default(), budget));
}

#[test]
fn an_exchange_does_not_undo_a_time_saving_split_it_has_no_room_for() {
    // Splitting 5 alone loses benefit and saves time (its group, with 9,
    // gains both). After one exchange undid 9's split, the next undid 5's
    // for its benefit, with no room for the 1.04 ms it gives back: 6.35 ms.
    let forest = forest_of(&[
        (None, 0.5851299370361258, 0.47309685978665866),
        (None, 0.6839380336061618, 0.5710193633597809),
        (None, 1.7899956308758627, 0.6247585212177713),
        (Some(0), 7.370040280666403, 1.3685399049836142),
        (Some(1), 4.044751054770041, 2.198444939206387),
        (Some(1), 6.934983655611227, 1.3676147203138025),
        (Some(3), 3.7434715758584893, 1.247473546092847),
        (Some(4), 8.041393502244938, 1.1378757086353264),
        (Some(4), 6.069064726873882, 1.8487094979353411),
        (Some(5), 0.4457231528448069, 0.32517901530743215),
        (Some(8), 2.8613000269441646, 1.198497453871937),
        (Some(8), 1.6195173435890775, 0.498613071990929),
        (Some(8), 2.0322689652331083, 2.0419718257228485),
        (Some(9), 7.196220958217331, 0.9381779598777502),
    ]);
    let budget = 5.742489373228253;
    let sel = optimize(&forest, &[], &Settings::budget(budget));
    assert!(feasible(&sel, budget), "{} > {budget}", sel.cost_ms);
}

#[test]
fn the_upper_bound_holds_over_splits_that_lose_benefit_and_time() {
    // Splitting 3 loses 0.09 and saves 1.39 ms: worth taking at the
    // blocked increment's price, which the bound (taking the greedy state
    // as the priced optimum) ignored: 35.61 against an optimum of 36.31.
    let forest = forest_of(&[
        (None, 0.4855541374602559, 0.21583095789062995),
        (None, 0.5884380367406195, 0.8257138213341695),
        (None, 0.820421825619613, 0.23975813614699898),
        (Some(1), 1.6971566956812223, 2.125050372709926),
        (Some(1), 0.0, 0.21849293149924193),
        (Some(2), 1.2136351781802501, 0.6022533208440644),
        (Some(2), 7.4636824105304855, 0.4737245049499453),
        (Some(2), 1.0000070518454207, 0.4501866962571282),
        (Some(3), 1.6092752765397966, 0.7336049449645659),
        (Some(5), 3.9889756283478595, 1.0304022434832723),
        (Some(6), 6.340796135139665, 0.30121634309649364),
        (Some(6), 7.737582704100543, 1.0976876689376627),
        (Some(6), 8.41863347217658, 1.0069205589353185),
        (Some(7), 3.9282680215342625, 1.6194125176203016),
        (Some(7), 0.0, 2.045175559362718),
        (Some(7), 3.8004633073745464, 1.431957109224565),
    ]);
    let budget = 10.016351883840867;
    let sel = optimize(&forest, &[], &Settings::budget(budget));
    let best = exact(&forest, &[], Smooth::default(), budget);
    assert!(sel.upper_bound >= best * (1.0 - 1e-9), "bound {} < {best}", sel.upper_bound);
}

#[test]
fn exchanges_stop_at_the_limits() {
    let (forest, budget) = exchanging_instance();
    let free = Settings::budget(budget);
    // The greedy to its budget stop, then the exchanges under `settings`:
    // their stop, and whether they changed the split.
    let exchange = |settings: &Settings| {
        let mut run = Run::new(&forest, Levels::new(&[], free.smooth), &free);
        assert_eq!(run.greedy(&free), Stop::Budget);
        let split = run.split.clone();
        (run.exchange(settings, Stop::Budget), split != run.split)
    };
    assert_eq!(exchange(&free), (Stop::Budget, true), "an exchange is made");
    assert_eq!(exchange(&Settings { deadline: Some(Instant::now()), ..free }), (Stop::Limit, false));
    assert_eq!(exchange(&Settings { max_iterations: 1, ..free }), (Stop::Limit, false));
}
