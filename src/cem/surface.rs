//! Stage 4: the surface-type channel, one class id per sample, which the
//! renderer uses to pick a shading model (dissertation 6.4, "Other Surface
//! Types": plain map colour, canopy tint, water reflection).
//!
//! Never interpolated: each sample takes the class of the nearest land-cover
//! pixel, except that samples whose (interpolated) cover is at least one half
//! are forest, so surface and canopy agree.

use serde::{Deserialize, Serialize};

/// Surface classes. The numeric values are the wire format.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Deserialize, Serialize)]
#[serde(rename_all = "lowercase")]
#[repr(u8)]
pub enum SurfaceType {
    /// Open land: plain map colour.
    Plain = 0,
    /// Tree canopy.
    Forest = 1,
    /// Lakes and rivers.
    Water = 2,
    /// Bare rock and scree.
    Rock = 3,
    /// Snow and glaciers.
    Ice = 4,
    /// Buildings and roads.
    Built = 5,
}

/// Class id of samples without elevation data.
pub const NODATA: u8 = 255;

/// Cover at and above which a sample is forest.
pub const FOREST_COVER: f32 = 0.5;

impl SurfaceType {
    /// Every class, by id.
    pub const ALL: [SurfaceType; 6] = {
        use SurfaceType::*;
        [Plain, Forest, Water, Rock, Ice, Built]
    };

    /// The class with this id, if any.
    pub fn from_id(id: u8) -> Option<SurfaceType> {
        SurfaceType::ALL.into_iter().find(|s| *s as u8 == id)
    }

    /// The name used in configuration files.
    pub fn name(self) -> &'static str {
        match self {
            SurfaceType::Plain => "plain",
            SurfaceType::Forest => "forest",
            SurfaceType::Water => "water",
            SurfaceType::Rock => "rock",
            SurfaceType::Ice => "ice",
            SurfaceType::Built => "built",
        }
    }
}

/// The class of one sample from its nearest land-cover class (`f32` id or
/// NaN), its cover and whether the ground has data.
#[inline]
pub fn classify(nearest: f32, cover: f32, ground_valid: bool) -> u8 {
    if !ground_valid {
        return NODATA;
    }
    if cover >= FOREST_COVER {
        return SurfaceType::Forest as u8;
    }
    match SurfaceType::from_id(if nearest.is_nan() { 0 } else { nearest as u8 }) {
        // Forest pixels whose cover the blur took below one half are open.
        Some(SurfaceType::Forest) | None => SurfaceType::Plain as u8,
        Some(s) => s as u8,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cover_decides_forest_and_nodata_wins() {
        assert_eq!(classify(2.0, 0.7, true), SurfaceType::Forest as u8);
        assert_eq!(classify(2.0, 0.2, true), SurfaceType::Water as u8);
        assert_eq!(classify(1.0, 0.2, true), SurfaceType::Plain as u8);
        assert_eq!(classify(f32::NAN, 0.0, true), SurfaceType::Plain as u8);
        assert_eq!(classify(3.0, 1.0, false), NODATA);
        assert_eq!(SurfaceType::from_id(5), Some(SurfaceType::Built));
        assert_eq!(SurfaceType::from_id(6), None);
    }
}
