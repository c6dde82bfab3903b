//! The landforms of Val Selva, as functions of a position in the local frame
//! (metres east and north of the region's centre). [`super::terrain`] samples
//! them on its node lattice; nothing else calls them.
//!
//! From large to small:
//! - a glacial main valley winding west to east along a sine-bent centre line,
//!   U-shaped across (flat floor, walls steepening to about 40°), its floor
//!   falling from 1,230 m in the east to the lake at 900 m and on to 870 m in
//!   the west;
//! - five side valleys branching off north and south, their floors rising at
//!   8 % and steepening towards their heads, each with a stream;
//! - a mountain mass of domain-warped ridged multifractal noise (sharp crests,
//!   smooth troughs, ridges that wander), summits near 2,900 m;
//! - a cliff band of up to 300 m on the north side of the upper valley;
//! - gullies down every flank ([`super::relief`]);
//! - a lake basin carved into the floor (the terrain clamps it to the lake
//!   level).
//!
//! Invariant: pure, continuous functions (the cliff is a 70 m-wide ramp, not
//! a step).

use super::relief;
use crate::noise::{self, ridged};

/// Surface of the lake, metres.
pub const LAKE_LEVEL_M: f64 = 900.0;

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
/// `side` (+1 north, −1 south), leaning by `lean` and wandering by ±350 m.
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
const SIDE_WALL_M: f64 = 1200.0;
const SIDE_FLOOR_HALF_WIDTH_M: f64 = 120.0;
/// Beyond three walls from its centre line a side valley carves nothing
/// (its profile is within 1.5e-6 of 1 there).
const SIDE_REACH_M: f64 = 3.0 * SIDE_WALL_M;
/// Streams run from this far up their side valley down to the river.
const STREAM_LENGTH_M: f64 = 6000.0;
/// `stream_m` where no stream is near: finite, so it can be interpolated.
pub const NO_STREAM_M: f64 = 1.0e6;

/// The land before gullies and lake: valley floor, walls, mountains, cliff.
pub struct Shape {
    /// Height, metres.
    pub dry_m: f64,
    /// Position along the main valley (west → east), metres.
    pub along_m: f64,
    /// Signed distance across the main valley (north positive), metres.
    pub across_m: f64,
}

/// The shape at `(x, y)`.
pub fn shape(x: f64, y: f64) -> Shape {
    let (along, across) = valley_coords(x, y);
    let floor = floor_m(x, y, along, across);
    let mountains = side_valleys(x, y, across, mountain_relief_m(x, y));
    Shape {
        dry_m: floor + wall_profile(across) * mountains + cliff_m(x, along, across),
        along_m: along,
        across_m: across,
    }
}

/// Gullies cut down the slope `(gx, gy)`: two octaves of stripes (520 m and
/// 230 m apart, 30 m and 12 m deep), fading in with the slope between 3°
/// and 30° so that the valley floor and the lake stay smooth. The deeper
/// octave adds lateral slopes of up to 2π·30/520 ≈ 0.36 (20°): V-notches in
/// the contours, as erosion leaves them.
pub fn gullies_m(x: f64, y: f64, gx: f64, gy: f64) -> f64 {
    let slope = (gx * gx + gy * gy).sqrt();
    let strength = smoothstep((slope - 0.05) / 0.53);
    if strength <= 0.0 {
        return 0.0;
    }
    let (dx, dy) = (-gx / slope, -gy / slope);
    let deep = relief::gullies(x, y, 520.0, dx, dy, SEED + 20);
    let fine = relief::gullies(x, y, 230.0, dx, dy, SEED + 21);
    strength * (30.0 * deep + 12.0 * fine)
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
/// 14 km plus domain-warped ridged noise (four octaves, 5 km down to 600 m;
/// finer relief comes from the gullies). The ridged sum has median 0.58, 95th
/// percentile 0.84 and maximum near 1 (measured over the region), so the mass
/// stands about 750 m above the floor (the forest belt), crests 1,200 m and
/// the highest summits 1,650 m above it: 2,900 m over the 1,230 m upper
/// floor. Troughs deeper than 200 m above the floor are flattened to 30 %
/// so the noise leaves no pits below the valleys.
fn mountain_relief_m(x: f64, y: f64) -> f64 {
    let wx = x + 900.0 * noise::at(x, y, 5000.0, SEED + 2);
    let wy = y + 900.0 * noise::at(x, y, 5000.0, SEED + 3);
    let base = 750.0 + 150.0 * noise::at(x, y, 14_000.0, SEED + 4);
    let relief = base + 1800.0 * (ridged(wx, wy, 5000.0, 4, SEED + 10) - 0.58);
    if relief < 200.0 { 200.0 + 0.3 * (relief - 200.0) } else { relief }
}

/// Carves the side valleys into the mountain relief: across a side valley the
/// relief blends from its floor (rising with distance from the main valley)
/// up to the mountains over 1.2 km.
fn side_valleys(x: f64, y: f64, across: f64, relief: f64) -> f64 {
    let mut out = relief;
    for v in &SIDE_VALLEYS {
        let up = v.side * across;
        // The wandering centre line is within |lean·y| + 350 m of x_m.
        if up <= 0.0 || (x - v.x_m).abs() - (v.lean * y).abs() - 350.0 > SIDE_REACH_M {
            continue;
        }
        let offset = side_offset_m(v, x, y);
        if offset.abs() > SIDE_REACH_M {
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
    if taper <= 0.0 || across < 700.0 {
        return 0.0;
    }
    let foot = 1300.0 + 250.0 * noise::at(x, 0.0, 1800.0, SEED + 5);
    300.0 * taper * smoothstep((across - foot) / 70.0 + 0.5)
}

/// How deep the basin is carved below the dry terrain: an ellipse in valley
/// coordinates whose outline is roughened by two octaves of noise (±30 %
/// over 1.2 km, ±12 % over 400 m), so the shore has bays and headlands.
pub fn lake_basin_m(x: f64, y: f64, along: f64, across: f64) -> f64 {
    let u = (along - LAKE_CENTRE_ALONG_M) / LAKE_HALF_LENGTH_M;
    let v = across / LAKE_HALF_WIDTH_M;
    let q = u * u + v * v;
    // Noise shrinks q by at most 42 %: 1/0.58 = 1.72 bounds where it can be below 1.
    if q >= 1.75 {
        return 0.0;
    }
    let rough = 0.3 * noise::at(x, y, 1200.0, SEED + 6) + 0.12 * noise::at(x, y, 400.0, SEED + 7);
    LAKE_DEPTH_M * (1.0 - q * (1.0 + rough)).max(0.0)
}

/// Signed distance from the river's centre line: the valley's across
/// coordinate less two sines of meanders (650 m and 270 m) that keep the
/// river within ±160 m of the valley centre, inside the flat floor.
pub fn river_m(along: f64, across: f64) -> f64 {
    across - (110.0 * (along / 650.0).sin() + 50.0 * (along / 270.0 + 1.3).sin())
}

/// Signed distance to the nearest side stream, or [`NO_STREAM_M`]. A
/// stream runs down the middle of its side valley from 6 km out to the river.
pub fn stream_m(x: f64, y: f64, across: f64, river_m: f64) -> f64 {
    let mut best = NO_STREAM_M;
    for v in &SIDE_VALLEYS {
        let up = v.side * across;
        if v.side * river_m <= 0.0 || up > STREAM_LENGTH_M {
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
pub(super) mod probe {
    //! Positions the terrain tests need.
    use super::*;

    /// A point on the lake's long axis, at its centre.
    pub fn lake_centre() -> (f64, f64) {
        let x = LAKE_CENTRE_ALONG_M;
        (x, VALLEY_Y0_M + VALLEY_TILT * x + VALLEY_BEND_M * (x / VALLEY_BEND_LEN_M).sin())
    }
}
