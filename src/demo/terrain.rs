//! The ground of Val Selva: one continuous height function of position, and
//! the water features that belong to the shape of the land (the lake, the
//! river and the side streams).
//!
//! Positions are metres in a local east/north frame centred on the region
//! (an equirectangular projection at the centre latitude; over 20 km its scale
//! error is below 0.1 %, and nothing needs it to match a real projection).
//!
//! The shape, from large to small:
//! - a glacial main valley winding west to east along a sine-bent centre line,
//!   U-shaped across (flat floor, walls steepening to about 40°), its floor
//!   falling from 1,230 m in the east to the lake at 900 m and on to 870 m in
//!   the west;
//! - a lake basin carved into the floor: inside it the ground is clamped to
//!   the lake level, so the lake is exactly flat and its shore is the 900 m
//!   line of the dry terrain;
//! - five side valleys branching off north and south, their floors rising at
//!   8 % and steepening towards their heads, each with a stream;
//! - a mountain mass of ridged multifractal noise (sharp crests, smooth
//!   troughs, domain-warped so that ridges wander), summits to about 3,500 m;
//! - a limestone cliff band of up to 300 m on the north side of the upper
//!   valley.
//!
//! Invariant: [`ground`] is a pure function of its arguments, continuous in
//! height (no steps beyond the cliff's 70 m-wide ramp), and costs a few
//! hundred nanoseconds.

use crate::geo::METRES_PER_DEGREE;
use crate::noise::{self, ridged};

/// Longitude of the frame's origin (the centre of [`super::BBOX`]), degrees.
pub const CENTRE_LON_DEG: f64 = 10.125;
/// Latitude of the frame's origin, degrees.
pub const CENTRE_LAT_DEG: f64 = 46.375;
/// Surface of the lake, metres.
pub const LAKE_LEVEL_M: f64 = 900.0;
/// Half the river's width, metres: 24 m of water is 2–3 map pixels of 10 m.
pub const RIVER_HALF_WIDTH_M: f64 = 12.0;

const SEED: u64 = 0x5E1A_7A11_E700;

/// Main valley centre line `y = Y0 + TILT·x + BEND·sin(x / BEND_LEN)`: an
/// S-bend through the region, from y ≈ −3.3 km at the west edge to +1.7 km
/// at the east edge, the lake in its southern loop.
const VALLEY_Y0_M: f64 = -800.0;
const VALLEY_TILT: f64 = 0.15;
const VALLEY_BEND_M: f64 = 1400.0;
const VALLEY_BEND_LEN_M: f64 = 4200.0;

/// Half-width of the main valley's flat floor and the width over which its
/// walls rise (the wall profile reaches 78 % of the mountain height one
/// `WALL` beyond the floor).
const FLOOR_HALF_WIDTH_M: f64 = 400.0;
const WALL_M: f64 = 1900.0;

/// Lake basin: an ellipse in valley coordinates, centred at along = −3 km.
const LAKE_CENTRE_ALONG_M: f64 = -3000.0;
const LAKE_HALF_LENGTH_M: f64 = 3200.0;
const LAKE_HALF_WIDTH_M: f64 = 1100.0;
const LAKE_DEPTH_M: f64 = 160.0;
/// The floor beside the basin is this far above the lake, more than the
/// floor noise (±1.5 m) can take away, so the basin's rim is always dry and
/// the clamped height is continuous there.
const FLOOR_AT_LAKE_M: f64 = LAKE_LEVEL_M + 3.0;

/// A side valley: its centre line leaves the main valley at `x_m` and runs
/// `side` (+1 north, −1 south), wandering by ±350 m.
struct SideValley {
    x_m: f64,
    side: f64,
    lean: f64,
    phase: f64,
}

const SIDE_VALLEYS: [SideValley; 5] = [
    SideValley { x_m: -7200.0, side: 1.0, lean: 0.15, phase: 0.0 },
    SideValley { x_m: 400.0, side: 1.0, lean: -0.1, phase: 1.7 },
    SideValley { x_m: 8600.0, side: 1.0, lean: 0.05, phase: 3.1 },
    SideValley { x_m: -4300.0, side: -1.0, lean: -0.2, phase: 4.4 },
    SideValley { x_m: 4200.0, side: -1.0, lean: 0.12, phase: 2.2 },
];

/// Everything known about the ground at one point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ground {
    /// Height of the ground or the lake surface, metres.
    pub height_m: f64,
    /// Depth of the lake here, metres: positive under water, negative (the
    /// dry ground's height above the lake, at least 1 m) elsewhere. Its zero
    /// line is the shore.
    pub lake_m: f64,
    /// Signed distance across the valley from the river's centre line, metres.
    pub river_m: f64,
    /// Signed distance from the nearest side stream, metres; `f64::INFINITY`
    /// where there is none.
    pub stream_m: f64,
    /// Position along the main valley (west → east), metres.
    pub along_m: f64,
    /// Signed distance across the main valley from its centre line (north
    /// positive), metres.
    pub across_m: f64,
}

/// Local frame metres per degree of longitude (at the centre latitude).
pub fn metres_per_lon_deg() -> f64 {
    METRES_PER_DEGREE * CENTRE_LAT_DEG.to_radians().cos()
}

/// Local frame position of a point given in degrees.
pub fn local_m(lon_deg: f64, lat_deg: f64) -> (f64, f64) {
    ((lon_deg - CENTRE_LON_DEG) * metres_per_lon_deg(), (lat_deg - CENTRE_LAT_DEG) * METRES_PER_DEGREE)
}

/// Ground height at a point given in degrees, metres.
pub fn height_m(lon_deg: f64, lat_deg: f64) -> f64 {
    let (x, y) = local_m(lon_deg, lat_deg);
    ground(x, y).height_m
}

/// The ground at local position `(x_m, y_m)`.
pub fn ground(x_m: f64, y_m: f64) -> Ground {
    let (along, across) = valley_coords(x_m, y_m);
    let floor = floor_m(x_m, y_m, along, across);
    let mountains = side_valleys(x_m, y_m, across, mountain_relief_m(x_m, y_m));
    let dry = floor + wall_profile(across) * mountains + cliff_m(x_m, along, across);
    let basin = lake_basin_m(x_m, y_m, along, across);
    let raw = dry - basin;
    let (height_m, lake_m) =
        if basin > 0.0 { (raw.max(LAKE_LEVEL_M), LAKE_LEVEL_M - raw) } else { (raw, (LAKE_LEVEL_M - raw).min(-1.0)) };
    let river_m = across - river_offset_m(along);
    Ground {
        height_m,
        lake_m,
        river_m,
        stream_m: stream_m(x_m, y_m, across, river_m),
        along_m: along,
        across_m: across,
    }
}

/// (along, across) of a point: along is x, across is the vertical offset from
/// the centre line scaled by the line's cosine, a distance near the line.
fn valley_coords(x: f64, y: f64) -> (f64, f64) {
    let phase = x / VALLEY_BEND_LEN_M;
    let centre = VALLEY_Y0_M + VALLEY_TILT * x + VALLEY_BEND_M * phase.sin();
    let slope = VALLEY_TILT + VALLEY_BEND_M / VALLEY_BEND_LEN_M * phase.cos();
    (x, (y - centre) / (1.0 + slope * slope).sqrt())
}

/// Floor height: flat at the lake, rising upstream (2.2 % steepening
/// eastwards), falling 0.8 % downstream; a gentle rise towards the walls
/// (12 m at the floor's edge) so contours bend upstream as they cross it.
fn floor_m(x: f64, y: f64, along: f64, across: f64) -> f64 {
    let east = along - (LAKE_CENTRE_ALONG_M + LAKE_HALF_LENGTH_M);
    let west = (LAKE_CENTRE_ALONG_M - LAKE_HALF_LENGTH_M) - along;
    let long = if east > 0.0 {
        0.022 * east + 8.0e-7 * east * east
    } else if west > 0.0 {
        -0.008 * west
    } else {
        0.0
    };
    let t = (across / FLOOR_HALF_WIDTH_M).abs();
    let cross = if t < 1.0 { 12.0 * t * t } else { 12.0 + 24.0 * (t - 1.0) };
    FLOOR_AT_LAKE_M + long + cross + 1.5 * noise::at(x, y, 700.0, SEED + 1)
}

/// 0 on the valley floor, rising to 1 on the mountain mass: `1 − e^{−1.5 t²}`
/// of the distance past the floor edge in walls, steepest (≈ 40° with the
/// mountain relief) about 0.6 walls out.
fn wall_profile(across: f64) -> f64 {
    let t = (across.abs() - FLOOR_HALF_WIDTH_M).max(0.0) / WALL_M;
    1.0 - (-1.5 * t * t).exp()
}

/// Height of the mountain mass above the valley floor: a base varying over
/// 14 km plus domain-warped ridged noise (six octaves, 3.5 km down to 110 m,
/// the smallest detail a 1″ DEM shows).
fn mountain_relief_m(x: f64, y: f64) -> f64 {
    let wx = x + 700.0 * noise::at(x, y, 4000.0, SEED + 2);
    let wy = y + 700.0 * noise::at(x, y, 4000.0, SEED + 3);
    let base = 1000.0 + 180.0 * noise::at(x, y, 14_000.0, SEED + 4);
    base + 1200.0 * (ridged(wx, wy, 3500.0, 6, SEED + 10) - 0.35)
}

/// Carves the side valleys into the mountain relief: across a side valley the
/// relief blends from its floor (rising with distance from the main valley)
/// up to the mountains over 1.2 km.
fn side_valleys(x: f64, y: f64, across: f64, relief: f64) -> f64 {
    let mut out = relief;
    for v in &SIDE_VALLEYS {
        let up = v.side * across;
        if up <= 0.0 {
            continue;
        }
        let offset = side_offset_m(v, x, y);
        if offset.abs() > 3.0 * SIDE_WALL_M {
            continue;
        }
        // Floor rise: 8 % at the mouth, steepening into a head wall (the
        // quadratic term adds 430 m at 6 km).
        let a = (up - FLOOR_HALF_WIDTH_M).max(0.0);
        let rise = 0.08 * a + 1.2e-5 * a * a;
        let t = (offset.abs() - SIDE_FLOOR_HALF_WIDTH_M).max(0.0) / SIDE_WALL_M;
        let p = 1.0 - (-1.5 * t * t).exp();
        // Fades in over the first 800 m so the side valley opens into the main one.
        let on = smoothstep(up / 800.0);
        let carved = rise + p * (relief - rise);
        out = out.min(relief + on * (carved - relief));
    }
    out
}

const SIDE_WALL_M: f64 = 1200.0;
const SIDE_FLOOR_HALF_WIDTH_M: f64 = 120.0;

/// Signed east–west offset from a side valley's centre line, metres.
fn side_offset_m(v: &SideValley, x: f64, y: f64) -> f64 {
    let centre = v.x_m + v.lean * y.abs() + 350.0 * (y / 1700.0 + v.phase).sin();
    x - centre
}

/// The cliff band: up to 300 m over a 70 m-wide ramp (≈ 77°) on the north
/// side of the upper valley, its foot wandering ±250 m around 1.3 km from the
/// valley centre, tapering out over 1.5 km at both ends.
fn cliff_m(x: f64, along: f64, across: f64) -> f64 {
    let taper = smoothstep((along - 1500.0) / 1500.0) * smoothstep((8500.0 - along) / 1500.0);
    if taper <= 0.0 {
        return 0.0;
    }
    let foot = 1300.0 + 250.0 * noise::at(x, 0.0, 1800.0, SEED + 5);
    300.0 * taper * smoothstep((across - foot) / 70.0 + 0.5)
}

/// How deep the basin is carved below the dry terrain: an ellipse in valley
/// coordinates whose outline is roughened by noise (±25 % over 900 m), so the
/// shore has bays and headlands.
fn lake_basin_m(x: f64, y: f64, along: f64, across: f64) -> f64 {
    let u = (along - LAKE_CENTRE_ALONG_M) / LAKE_HALF_LENGTH_M;
    let v = across / LAKE_HALF_WIDTH_M;
    let q = u * u + v * v;
    if q >= 1.6 {
        return 0.0;
    }
    let q = q * (1.0 + 0.25 * noise::at(x, y, 900.0, SEED + 6));
    LAKE_DEPTH_M * (1.0 - q).max(0.0)
}

/// The river's meanders: two sines (650 m and 270 m) that keep it within
/// ±160 m of the valley centre, inside the flat floor.
fn river_offset_m(along: f64) -> f64 {
    110.0 * (along / 650.0).sin() + 50.0 * (along / 270.0 + 1.3).sin()
}

/// Signed distance to the nearest side stream. A stream runs down the middle
/// of each side valley from 6 km out to the river.
fn stream_m(x: f64, y: f64, across: f64, river_m: f64) -> f64 {
    let mut best = f64::INFINITY;
    for v in &SIDE_VALLEYS {
        let up = v.side * across;
        let beyond_river = v.side * river_m > 0.0;
        if !beyond_river || up > 6000.0 {
            continue;
        }
        let offset = side_offset_m(v, x, y);
        if offset.abs() < best.abs() {
            best = offset;
        }
    }
    best
}

/// `3t² − 2t³` on `t` clamped to `[0, 1]`.
fn smoothstep(t: f64) -> f64 {
    let t = t.clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_lake_is_flat_and_its_shore_is_continuous() {
        let (along, y) = (LAKE_CENTRE_ALONG_M, VALLEY_Y0_M + VALLEY_TILT * LAKE_CENTRE_ALONG_M);
        let centre_y = y + VALLEY_BEND_M * (LAKE_CENTRE_ALONG_M / VALLEY_BEND_LEN_M).sin();
        let g = ground(along, centre_y);
        assert_eq!(g.height_m, LAKE_LEVEL_M);
        assert!(g.lake_m > 50.0, "{g:?}");
        // Walk north out of the lake: heights never jump by more than a cliff allows.
        let mut prev = g.height_m;
        for i in 1..4000 {
            let h = ground(along, centre_y + i as f64).height_m;
            assert!((h - prev).abs() < 5.0, "step at {i}: {prev} → {h}");
            prev = h;
        }
    }

    #[test]
    fn heights_span_an_alpine_range() {
        let (mut lo, mut hi) = (f64::MAX, f64::MIN);
        for j in 0..200 {
            for i in 0..200 {
                let h = ground(-10_000.0 + i as f64 * 100.0, -9_000.0 + j as f64 * 90.0).height_m;
                lo = lo.min(h);
                hi = hi.max(h);
            }
        }
        assert!((820.0..=900.0).contains(&lo) && (2800.0..=3700.0).contains(&hi), "{lo} {hi}");
    }

    #[test]
    fn the_frame_is_centred_on_the_region() {
        assert_eq!(local_m(CENTRE_LON_DEG, CENTRE_LAT_DEG), (0.0, 0.0));
        let (x, y) = local_m(10.25, 46.45);
        assert!((x - 9_600.0).abs() < 50.0 && (y - 8_340.0).abs() < 10.0, "{x} {y}");
    }
}
