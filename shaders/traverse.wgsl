// The two ways a view ray finds the surface, selectable per frame (the
// ray-casting pipelines are specialised by it, LINEAR):
//
// - exact: hierarchical traversal of the maximum mipmap. Integer cell
//   stepping on each level; a cell the ray passes above (its lowest point
//   over the cell is above the cell's bound) is skipped whole, then the walk
//   climbs a level when it leaves its parent; a cell the ray may enter is
//   descended into; on level 0 the cell's corners bound it and its bilinear
//   patch is intersected exactly.
//   Bounds are conservative, so no hit is ever skipped, at any angle.
//   The walk over the upper levels and the leaf tests are two loops (Aila
//   and Laine's "while-while" traversal): lanes of a SIMD group then run one
//   kind of step at a time instead of every lane paying for both — on
//   lavapipe 0.80-0.92x the frame time of one loop with a branch per step.
// - linear: the dissertation's fixed-step march (6.4) with its 4- and
//   32-sample safety zones, giving up after a fixed number of steps.
//
// Rays are in sample space: origin o, direction d per metre of the ray
// parameter t (samples east/north, metres up). Both return t or NO_HIT.

const START_LEVEL: i32 = 2;
const MAX_ITERATIONS: u32 = 8192u;

// A ray's constants for cell stepping: the inverse direction, which side of
// a cell it leaves by (1 toward +x/+y, 0 toward -x/-y), and the step to the
// next cell per axis.
struct Stepper {
    inverse: vec2<f32>,
    far_side: vec2<f32>,
    moving: vec2<bool>,
    step: vec2<i32>,
};

fn stepper(d: vec2<f32>) -> Stepper {
    let moving = d != vec2<f32>(0.0);
    let far_side = select(vec2<f32>(0.0), vec2<f32>(1.0), d > vec2<f32>(0.0));
    return Stepper(1.0 / select(vec2<f32>(1.0), d, moving), far_side, moving, vec2<i32>(sign(d)));
}

// The ray parameter where the ray leaves cell `cell` of side `size` (cell m
// spans samples m*size - 1 .. (m+1)*size - 1), per axis.
fn cell_exit(cell: vec2<i32>, size: f32, o: vec2<f32>, s: Stepper) -> vec2<f32> {
    let side = (vec2<f32>(cell) + s.far_side) * size - 1.0;
    return select(vec2<f32>(1.0e30), (side - o) * s.inverse, s.moving);
}

// The lowest height of the ray o + t d over t in [a, b].
fn lowest(o: vec3<f32>, d: vec3<f32>, a: f32, b: f32) -> f32 {
    return min(o.z + d.z * a, o.z + d.z * b);
}

fn cell_of(p: vec2<f32>, size: f32, lo: vec2<i32>, hi: vec2<i32>) -> vec2<i32> {
    return clamp(vec2<i32>(floor((p + 1.0) / size)), lo, hi);
}

// Where a walk stands: its level and cell, and the ray parameter where it
// entered the cell.
struct Walk {
    level: i32,
    cell: vec2<i32>,
    t: f32,
};

// Moves the walk to the next cell along the ray, which it enters at `t_out`,
// climbing a level when it leaves its parent; false when it leaves the tile.
fn advance(w: ptr<function, Walk>, exits: vec2<f32>, t_out: f32, s: Stepper) -> bool {
    (*w).t = t_out;
    let old = (*w).cell;
    var cell = old;
    if exits.x <= exits.y { cell.x += s.step.x; } else { cell.y += s.step.y; }
    if any(cell < vec2<i32>(0)) || any(cell >= mip_cells((*w).level)) {
        return false;
    }
    if (*w).level < tile.index.w && any((cell >> vec2<u32>(1u)) != (old >> vec2<u32>(1u))) {
        (*w).level += 1;
        cell = cell >> vec2<u32>(1u);
    }
    (*w).cell = cell;
    return true;
}

fn traverse_exact(o: vec3<f32>, d: vec3<f32>, t0: f32, t1: f32) -> f32 {
    let start = min(START_LEVEL, tile.index.w);
    let stepping = stepper(d.xy);
    let first = cell_of(o.xy + d.xy * t0, f32(1 << u32(start)), vec2<i32>(0), mip_cells(start) - 1);
    var w = Walk(start, first, t0);
    var it = 0u;
    while it < MAX_ITERATIONS {
        // Down the upper levels to the next leaf the ray may enter.
        while w.level > 0 && it < MAX_ITERATIONS {
            it++;
            let size = f32(1 << u32(w.level));
            let exits = cell_exit(w.cell, size, o.xy, stepping);
            let t_out = min(min(exits.x, exits.y), t1);
            view_fetches += 1u;
            if lowest(o, d, w.t, t_out) <= mip_bound(w.level, w.cell) {
                w.level -= 1;
                let child = w.cell * 2;
                w.cell = cell_of(o.xy + d.xy * w.t, size / 2.0, child, child + 1);
            } else if t_out >= t1 || !advance(&w, exits, t_out, stepping) {
                return NO_HIT;
            }
        }
        // The leaf.
        it++;
        let exits = cell_exit(w.cell, 1.0, o.xy, stepping);
        let t_out = min(min(exits.x, exits.y), t1);
        // A leaf's bound is the highest of its corners: read them at once.
        let h = cell_heights(w.cell.x - 1, w.cell.y - 1, &view_fetches);
        leaf_cells += 1u;
        if has_data(h) && lowest(o, d, w.t, t_out) <= max(max(h.x, h.y), max(h.z, h.w)) {
            let p = o.xy + d.xy * w.t;
            let tau = patch_hit(h, p - vec2<f32>(w.cell - 1), d, o.z + d.z * w.t, t_out - w.t);
            if tau != NO_HIT {
                return w.t + tau;
            }
        }
        if t_out >= t1 || !advance(&w, exits, t_out, stepping) {
            return NO_HIT;
        }
    }
    return NO_HIT;
}

fn traverse_linear(o: vec3<f32>, d: vec3<f32>, t0: f32, t1: f32, steps: u32) -> f32 {
    let per_m = length(d.xy);
    // One sample horizontally per base step; a zone of radius r is left after
    // r - 0.5 samples from anywhere in the current texel.
    let unit = 1.0 / max(per_m, 1.0e-9);
    var t = t0;
    for (var k = 0u; k < steps; k++) {
        let p = o + d * t;
        let s = vec2<i32>(floor(p.xy + 0.5));
        let zones = texel(s.x, s.y).zw;
        view_fetches += 1u;
        let far = min(t + 31.5 * unit, t1);
        let near = min(t + 3.5 * unit, t1);
        if min(p.z, o.z + d.z * far) > zones.y {
            t = far;
        } else if min(p.z, o.z + d.z * near) > zones.x {
            t = near;
        } else {
            let next = min(t + unit, t1);
            let q = o + d * next;
            let h = height_at(q.xy, &view_fetches);
            if h >= q.z {
                // Between the last point above and this one below.
                let h0 = height_at(p.xy, &view_fetches);
                let g0 = select(max(p.z - h0, 0.0), 0.0, h0 <= NODATA_BELOW);
                return t + (next - t) * g0 / max(g0 + (h - q.z), 1.0e-12);
            }
            t = next;
        }
        if t >= t1 {
            return NO_HIT;
        }
    }
    return NO_HIT;
}
