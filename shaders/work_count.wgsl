// Counting every ray cast's work (render/work.rs), in the modules of frames
// that count it; work_none.wgsl stands in elsewhere, so that no other
// pipeline holds the atomics (on lavapipe, frames with them present but
// switched off by an override constant were still 10-20 % slower).

// Every ray cast's work, per draw (render/work.rs): rays, view-ray fetches,
// leaf cells, shadow-ray fetches, each a 64-bit count (low word, then high
// word), each draw's counters in WORK_SPREAD places (one per pixel of an
// 8 x 4 block) so that a wave does not queue on one.
@group(0) @binding(6) var<storage, read_write> work: array<atomic<u32>>;
const WORK_SPREAD: u32 = 32u;

// The first word of draw `draw`'s counters in the place of `pixel`.
fn work_place(draw: u32, pixel: vec2<u32>) -> u32 {
    return (draw * WORK_SPREAD + ((pixel.x & 7u) | ((pixel.y & 3u) << 3u))) * 8u;
}

// Adds `v` to the 64-bit count at word `k`: the add that wraps the low word
// carries one into the high word.
fn count_wide(k: u32, v: u32) {
    let before = atomicAdd(&work[k], v);
    if (before > 0xffffffffu - v) {
        atomicAdd(&work[k + 1u], 1u);
    }
}

// Counts one ray cast through draw `draw` (0-based) for `pixel`, which took
// `fetches` and read `leaves` leaf cells.
fn count_cast(draw: u32, pixel: vec2<u32>, fetches: u32, leaves: u32) {
    let w = work_place(draw, pixel);
    count_wide(w, 1u);
    count_wide(w + 2u, fetches);
    count_wide(w + 4u, leaves);
}

// Counts the fetches of a shadow ray cast from a hit on draw `draw`.
fn count_shadow(draw: u32, pixel: vec2<u32>, fetches: u32) {
    count_wide(work_place(draw, pixel) + 6u, fetches);
}
