//! The flight's screen-space error selection (`sylva fly --lod sse`): with
//! the distance deferral table it selects exactly the tiles full
//! re-evaluation selects, in every frame of the recorded flyovers, with a
//! small fraction of the refinement tests and fewer nodes touched in all
//! (counted). Path, camera and tile tree only: no
//! GPU.

use crate::common;
use std::sync::Arc;
use sylva::bench::lod_sse::{Flight, Pace, compare, paths_of};
use sylva::client::path::CameraPath;
use sylva::client::source::RegionSource;
use sylva::client::sse::SseSelector;
use sylva::region::Region;

/// The paths flown in their own time (20–30 s) at 60 frames a second.
const PACE: Pace = Pace::PerSecond(60.0);

/// Refinement tests and nodes touched over every path of `prefix`,
/// deferred and full, after checking every frame's selection.
fn flights(region: Region, prefix: &str) -> ((usize, usize), (usize, usize)) {
    let source = RegionSource::new(Arc::new(region));
    let tree = SseSelector::for_source(&source, 13).unwrap().expect("the tree fits").tree().clone();
    let (mut evaluated, mut touched) = ((0, 0), (0, 0));
    let paths = paths_of(&common::repo().join("config/paths"), prefix).unwrap();
    assert_eq!(paths.len(), 3, "valley, horizon and dive over {prefix}");
    for file in paths {
        let path = CameraPath::load(&file).unwrap();
        let flight = Flight { frames: PACE.frames(&path), size: (640, 480), max_error_px: 2.0 };
        let counts = compare(&tree, &path, &flight).unwrap_or_else(|e| panic!("{}: {e}", file.display()));
        for c in counts {
            evaluated = (evaluated.0 + c.evaluated.0, evaluated.1 + c.evaluated.1);
            touched = (touched.0 + c.touched.0, touched.1 + c.touched.1);
        }
    }
    eprintln!("{prefix}: refinement tests {evaluated:?}, nodes touched {touched:?} (deferred, full)");
    (evaluated, touched)
}

fn assert_far_fewer(((ed, ef), (td, tf)): ((usize, usize), (usize, usize))) {
    assert!(ed * 100 <= ef * REFINE_PERCENT, "refinement tests: deferred {ed} vs full {ef}");
    assert!(td * 100 <= tf * TOUCHED_PERCENT, "nodes touched: deferred {td} vs full {tf}");
}

/// Bounds on deferred work as a percentage of full re-evaluation: the
/// issue's 5 % for refinement tests (measured on 2026-12-02: 1.8 % demo,
/// 1.2 % rmnp over the three paths); nodes touched 50 % and 49 %: culling
/// tests the refined tree near the eye every frame, deferred or not.
const REFINE_PERCENT: usize = 5;
const TOUCHED_PERCENT: usize = 60;

#[test]
fn deferred_sse_selection_equals_full_re_evaluation_over_the_demo() {
    assert_far_fewer(flights(common::demo(), "demo"));
}

#[test]
fn deferred_sse_selection_equals_full_re_evaluation_over_rmnp() {
    common::data("rmnp");
    assert_far_fewer(flights(common::region("examples/rmnp.toml"), "rmnp"));
}
