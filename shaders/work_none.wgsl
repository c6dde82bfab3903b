// Frames that do not count their rays' work: count_cast and count_shadow
// (work_count.wgsl) do nothing.

fn count_cast(draw: u32, pixel: vec2<u32>, fetches: u32, leaves: u32) {}

fn count_shadow(draw: u32, pixel: vec2<u32>, fetches: u32) {}
