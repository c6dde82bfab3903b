//! Tests of [`super`]: timing (asymmetry, collapse, completion in τ) and
//! vertex continuity on a synthetic height pyramid.

use super::*;
use proptest::prelude::*;

const TAU: f64 = 0.5;

/// Ground height at a point of the unit square (smooth plus ridges).
fn ground(x: f64, y: f64) -> f64 {
    100.0 * (3.1 * x).sin() * (2.3 * y).cos() + 20.0 * (17.0 * x + 5.0 * y).sin().abs()
}

/// Level `l`'s surface: bilinear between samples on a (2^l + 1)² grid.
fn surface(l: u8, x: f64, y: f64) -> f64 {
    let n = f64::from(1u32 << l);
    let (fx, fy) = ((x * n).min(n - 1e-12), (y * n).min(n - 1e-12));
    let (i, j) = (fx.floor(), fy.floor());
    let (u, v) = (fx - i, fy - j);
    let h = |a: f64, b: f64| ground(a / n, b / n);
    (1.0 - v) * ((1.0 - u) * h(i, j) + u * h(i + 1.0, j)) + v * ((1.0 - u) * h(i, j + 1.0) + u * h(i + 1.0, j + 1.0))
}

/// What the renderer shows at `(x, y)` with the mesh of level `mesh` morphed
/// by `weight`: bilinear between that mesh's morphed vertices.
fn drawn(mesh: u8, weight: f64, x: f64, y: f64) -> f64 {
    let n = f64::from(1u32 << mesh);
    let (fx, fy) = ((x * n).min(n - 1e-12), (y * n).min(n - 1e-12));
    let (i, j) = (fx.floor(), fy.floor());
    let (u, v) = (fx - i, fy - j);
    let vertex = |a: f64, b: f64| {
        let (px, py) = (a / n, b / n);
        let coarse = if mesh == 0 { ground(px, py) } else { surface(mesh - 1, px, py) };
        morphed_height(coarse, ground(px, py), weight)
    };
    (1.0 - v) * ((1.0 - u) * vertex(i, j) + u * vertex(i + 1.0, j))
        + v * ((1.0 - u) * vertex(i, j + 1.0) + u * vertex(i + 1.0, j + 1.0))
}

fn at_level(level: f64, x: f64, y: f64) -> f64 {
    let (mesh, weight) = mesh_and_weight(level);
    drawn(mesh, weight, x, y)
}

const PROBES: [(f64, f64); 5] = [(0.13, 0.71), (0.5, 0.5), (0.37, 0.09), (0.91, 0.42), (0.777, 0.333)];

/// The largest change between consecutive levels anywhere on the probes.
fn level_step_m() -> f64 {
    (1..8u8).flat_map(|l| PROBES.map(|(x, y)| (surface(l, x, y) - surface(l - 1, x, y)).abs())).fold(0.0, f64::max)
}

#[test]
fn downmorph_ends_when_the_target_begins_upmorph_starts_then() {
    let mut down = MorphTrack::new(5, TAU);
    down.request(3, 2.0);
    assert_eq!(down.transitions(), &[Transition { start_s: 2.0 - TAU, from: 5.0, to: 3.0 }]);
    assert_eq!(down.level_at(2.0 - TAU), 5.0);
    assert_eq!(down.level_at(2.0), 3.0, "coarse level in place when the target interval begins");
    let mut up = MorphTrack::new(3, TAU);
    up.request(5, 2.0);
    assert_eq!(up.transitions(), &[Transition { start_s: 2.0, from: 3.0, to: 5.0 }]);
    assert_eq!(up.level_at(2.0), 3.0, "the finer level is not drawn before its interval");
    assert_eq!(up.level_at(2.0 + TAU), 5.0, "and is reached within τ");
    let mid = up.level_at(2.0 + TAU / 2.0);
    assert!(mid > 3.0 && mid < 5.0);
}

#[test]
fn an_upmorph_overridden_by_a_downmorph_collapses_into_one() {
    // Selection 1 (target [2, 2.5)) asks 4 → 6: an upmorph over [2, 2.5).
    // Selection 2 (target [2.5, 3)) asks 3: its downmorph falls in [2, 2.5)
    // too, so one morph 4 → 3 runs over that interval (001 Figure 7b).
    let mut track = MorphTrack::new(4, TAU);
    track.request(6, 2.0);
    track.request(3, 2.0 + TAU);
    assert_eq!(track.transitions(), &[Transition { start_s: 2.0, from: 4.0, to: 3.0 }]);
    assert_eq!(track.level_at(2.0 + TAU), 3.0);
    // Asking back for the level it started from cancels the morph.
    let mut back = MorphTrack::new(4, TAU);
    back.request(6, 2.0);
    back.request(4, 2.0 + TAU);
    assert!(back.transitions().is_empty());
}

#[test]
fn monotone_sequences_chain() {
    let mut track = MorphTrack::new(2, TAU);
    track.request(4, 1.0);
    track.request(7, 1.0 + TAU);
    assert_eq!(track.level_at(1.0 + TAU), 4.0);
    assert_eq!(track.level_at(1.0 + 2.0 * TAU), 7.0);
    track.prune(1.0 + 2.0 * TAU);
    assert!(track.transitions().is_empty());
    assert_eq!(track.level_at(0.0), 7.0);
}

#[test]
fn vertices_move_continuously_through_every_switch() {
    // Up two levels, down three (collapsing), up four; frames every τ/7.
    let mut track = MorphTrack::new(2, TAU);
    let mut popping = vec![(0.0, 2.0)];
    for (k, level) in [4u8, 1, 5, 5, 2].into_iter().enumerate() {
        let target = 1.0 + k as f64 * TAU;
        track.request(level, target);
        popping.push((target, f64::from(level)));
    }
    let step = level_step_m();
    let mut switches = 0;
    let (mut last_mesh, mut last_level, mut last) = (2u8, 2.0, PROBES.map(|(x, y)| at_level(2.0, x, y)));
    let (mut worst_pop, mut worst_morph): (f64, f64) = (0.0, 0.0);
    for f in 1..=100 {
        let t = f as f64 * TAU / 7.0;
        let level = track.level_at(t);
        let now = PROBES.map(|(x, y)| at_level(level, x, y));
        let moved = now.iter().zip(&last).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
        assert!(moved <= step * (level - last_level).abs() * 1.000_001 + 1e-9, "frame {f}: {moved} m");
        worst_morph = worst_morph.max(moved);
        let mesh = mesh_and_weight(level).0;
        switches += usize::from(mesh != last_mesh);
        // The same frames without morphing pop by whole levels.
        let before = popping.iter().rev().find(|(s, _)| *s <= t - TAU / 7.0).map_or(2.0, |p| p.1);
        let after = popping.iter().rev().find(|(s, _)| *s <= t).map_or(2.0, |p| p.1);
        let pop =
            PROBES.iter().map(|&(x, y)| (at_level(after, x, y) - at_level(before, x, y)).abs()).fold(0.0, f64::max);
        worst_pop = worst_pop.max(pop);
        (last_mesh, last_level, last) = (mesh, level, now);
    }
    assert!(switches >= 8, "{switches} mesh switches");
    assert!(worst_pop > 2.0 * worst_morph, "without morphing the surface jumps {worst_pop} m, with {worst_morph} m");
}

proptest! {
    #[test]
    fn switching_meshes_at_an_integer_level_moves_nothing(level in 0u8..7, x in 0.0f64..1.0, y in 0.0f64..1.0) {
        // Mesh `level` fully morphed and mesh `level + 1` not morphed at all
        // draw the same surface.
        let a = drawn(level, 1.0, x, y);
        let b = drawn(level + 1, 0.0, x, y);
        prop_assert!((a - b).abs() <= 1e-9 * (1.0 + a.abs()));
    }

    #[test]
    fn every_morph_completes_in_tau(from in 0u8..12, to in 0u8..12, target in 0.0f64..100.0) {
        let mut track = MorphTrack::new(from, TAU);
        track.request(to, target);
        prop_assert_eq!(track.level_at(target), if to < from { f64::from(to) } else { f64::from(from) });
        prop_assert_eq!(track.level_at(target + TAU), f64::from(to));
        prop_assert_eq!(track.level_at(target + 100.0), f64::from(to));
        prop_assert!(track.transitions().iter().all(|t| t.from != t.to));
    }
}

#[test]
fn odd_inputs_stay_finite() {
    for tau in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        let mut t = MorphTrack::new(3, tau);
        t.request(5, 1.0);
        assert!(t.level_at(1.0).is_finite() && t.level_at(2.0) == 5.0);
    }
    assert_eq!(mesh_and_weight(f64::NAN), (0, 1.0));
    assert_eq!(mesh_and_weight(3.0), (3, 1.0));
    assert_eq!(mesh_and_weight(2.25), (3, 0.25));
}

/// The largest change of the track's level between frames 1 ms apart.
fn largest_step(track: &MorphTrack) -> f64 {
    let level = |f: i32| track.level_at(f64::from(f) * 1e-3);
    (0..20_000).map(|f| (level(f + 1) - level(f)).abs()).fold(0.0, f64::max)
}

#[test]
fn a_request_during_a_morph_continues_from_where_it_is() {
    // The next selection's target comes `gap` after the last (jitter): the
    // morph in progress was dropped and the level jumped to where it would
    // have been, going on up, on down, or turning back (the collapse).
    for (start, first, second, gap) in [(4, 5, 6, 0.8), (6, 4, 2, 0.8), (4, 6, 3, 1.2)] {
        let mut track = MorphTrack::new(start, TAU);
        track.request(first, 5.0);
        track.request(second, 5.0 + gap * TAU);
        // Four levels in τ are the steepest these morphs may go.
        let step = largest_step(&track);
        assert!(step <= 4.0 * 1e-3 / TAU, "{start} → {first} → {second}: {step} in 1 ms, {:?}", track.transitions());
        assert_eq!(track.level_at(5.0 + (gap + 1.0) * TAU), f64::from(second));
    }
}
