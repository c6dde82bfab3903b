//! Cesium's `heightmap-1.0` terrain tiles (what CesiumJS's
//! `CesiumTerrainProvider` reads): the tile's samples as little-endian
//! `u16`, row 0 north, `h = v / 5 − 1000` metres (0.2 m steps, −1000 to
//! 12,107 m, clamped), then one byte saying which of the four children
//! exist, then the water mask: one byte (0: no water, 255: all water) or a
//! square of bytes over the tile's area, row 0 north (255 water, 0 land).
//! Cesium needs a height everywhere in a tile it has: nodata is 0 m, the
//! ellipsoid.

use crate::raster::Raster;

/// Metres per step.
const STEP_M: f64 = 0.2;

/// Height of value 0, metres.
const OFFSET_M: f64 = -1000.0;

/// Which children of a tile exist: a bit per child (Cesium's
/// `childTileMask`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Children(pub u8);

impl Children {
    /// The south-west child.
    pub const SOUTH_WEST: u8 = 1;
    /// The south-east child.
    pub const SOUTH_EAST: u8 = 2;
    /// The north-west child.
    pub const NORTH_WEST: u8 = 4;
    /// The north-east child.
    pub const NORTH_EAST: u8 = 8;
}

/// Encodes a tile's heights, which children it has and its water mask.
pub fn encode(heights: &Raster<f32>, children: Children, water: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(2 * heights.data().len() + 1 + water.len());
    for &h in heights.data() {
        out.extend_from_slice(&value(h).to_le_bytes());
    }
    out.push(children.0);
    out.extend_from_slice(water);
    out
}

/// The value of one height (nodata: 0 m).
pub fn value(h: f32) -> u16 {
    let h = if h.is_nan() { 0.0 } else { f64::from(h) };
    ((h - OFFSET_M) / STEP_M).round().clamp(0.0, f64::from(u16::MAX)) as u16
}

/// The height of one value, metres.
pub fn height(v: u16) -> f64 {
    f64::from(v) * STEP_M + OFFSET_M
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn heights_round_trip_within_half_a_step_and_nodata_is_the_ellipsoid() {
        for h in [-430.25f32, 0.0, 1234.567, 8850.0] {
            let back = height(value(h));
            assert!((back - f64::from(h)).abs() <= 0.1 + 1e-9, "{h} -> {back}");
        }
        assert_eq!(height(value(f32::NAN)), 0.0);
        assert_eq!((value(-2000.0), value(20_000.0)), (0, u16::MAX));
    }

    #[test]
    fn samples_run_row_by_row_from_the_north_then_the_masks() {
        let heights = Raster::from_vec(2, 2, vec![0.0, 1.0, 2.0, f32::NAN]).unwrap();
        let bytes = encode(&heights, Children(Children::NORTH_WEST | Children::SOUTH_EAST), &[0, 255, 255, 0]);
        let values: Vec<u16> = bytes[..8].chunks(2).map(|b| u16::from_le_bytes([b[0], b[1]])).collect();
        assert_eq!(values, [5000, 5005, 5010, 5000]);
        assert_eq!(&bytes[8..], [6, 0, 255, 255, 0]);
    }
}
