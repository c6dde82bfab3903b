//! Stage 1 on the source's own pixels: the vegetation cover map and the
//! land-cover classes, as one derived two-band raster (band 0: cover in
//! [0, 1]; band 1: surface class id).
//!
//! Three rules (`../shared/DESIGN.md` stage 1):
//! - **map**: an RGB topographic map or orthophoto; each pixel takes the
//!   nearest colour key within tolerance (L*a*b*), forest keys give a mask of
//!   1, then a morphological close (dilations then erosions, any order and
//!   radius, dissertation Figure 6.3) bridges contour lines and paths, then an
//!   optional blur softens the edges; water pixels keep cover 0;
//! - **classes**: a classified raster and a table class → (surface, cover);
//! - **linear**: a canopy-cover percentage (or canopy height) scaled to
//!   [0, 1] between two values.
//!
//! With forest types (one canopy proxy each, dissertation 6.3: "several
//! distinct canopy proxies for different surfaces"), bands `2 + k` hold the
//! cover of type `k`'s forest (0 elsewhere; type 0 is forest of no named
//! type), so that cover = Σ band `2 + k`, and resampling each band
//! bilinearly blends the proxies where types meet.
//!
//! Working on native pixels makes the close's radius a fixed ground distance
//! (the width of the map's lines) at every tile level. Blocks are computed
//! with a margin of the close and blur radii, so they are exact.

use super::colorkey::{self, LabKey};
use super::surface::SurfaceType;
use crate::raster::morphology::{self, MorphOp};
use crate::raster::{Raster, Window, blur};
use crate::source::{BLOCK, Blocks, PixelSource, SourceError};
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// How land cover is derived from the input raster's pixels.
#[derive(Clone, Debug)]
pub enum Rule {
    /// Colour keys on an RGB map, then a close and a blur.
    Map {
        /// Compiled keys.
        keys: Vec<LabKey>,
        /// The close: e.g. D, D, E, E.
        ops: Vec<MorphOp>,
        /// Kernel radius of each pass (1 = 3×3).
        radius_px: usize,
        /// Gaussian blur radius (0 = none).
        blur_px: usize,
    },
    /// A class raster and its table.
    Classes(HashMap<i64, (SurfaceType, f32)>),
    /// Cover rises linearly from 0 at `zero_at` to 1 at `full_at`; samples
    /// with cover ≥ 0.5 are forest.
    Linear {
        /// Input value with cover 0.
        zero_at: f32,
        /// Input value with cover 1.
        full_at: f32,
    },
}

impl Rule {
    /// Extra input pixels needed around a block.
    fn margin(&self) -> usize {
        match self {
            Rule::Map { ops, radius_px, blur_px, .. } => morphology::sequence_margin(ops, *radius_px) + blur_px,
            _ => 0,
        }
    }
}

/// Which forest type each forest pixel is.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ForestTypes {
    /// Number of types, the unnamed type 0 included; 0 = no type bands.
    pub count: usize,
    /// Type of the forest pixels the table below does not name.
    pub default: u8,
    /// Types by class value (class rules).
    pub by_class: HashMap<i64, u8>,
}

impl ForestTypes {
    /// The type of a pixel of input value `v`.
    fn of(&self, v: f32) -> u8 {
        if v.is_nan() { self.default } else { self.by_class.get(&(v as i64)).copied().unwrap_or(self.default) }
    }
}

/// The derived land-cover raster over an input raster.
pub struct Landcover {
    name: PathBuf,
    input: Blocks,
    rule: Rule,
    types: ForestTypes,
}

impl Landcover {
    /// Land cover from `input` by `rule`, without forest types.
    pub fn new(input: Blocks, rule: Rule) -> Landcover {
        Landcover::with_types(input, rule, ForestTypes::default())
    }

    /// Land cover with one cover band per forest type.
    pub fn with_types(input: Blocks, rule: Rule, types: ForestTypes) -> Landcover {
        let name = PathBuf::from(format!("{} (land cover)", input.source().name().display()));
        Landcover { name, input, rule, types }
    }

    /// Cover of each type: `cover` where the pixel's type is `k`, else 0.
    fn type_bands(&self, input: &Raster<f32>, cover: &Raster<f32>) -> Vec<Raster<f32>> {
        let types = input.map(|v| self.types.of(v));
        (0..self.types.count).map(|k| cover.zip_map(&types, |c, t| if usize::from(t) == k { c } else { 0.0 })).collect()
    }
}

impl PixelSource for Landcover {
    fn name(&self) -> &Path {
        &self.name
    }

    fn size(&self) -> (usize, usize) {
        self.input.size()
    }

    fn bands(&self) -> usize {
        2 + self.types.count
    }

    fn block_size(&self) -> (usize, usize) {
        (BLOCK, BLOCK)
    }

    fn read_block(&self, bx: usize, by: usize) -> Result<Vec<Raster<f32>>, SourceError> {
        let block = self.block_window(bx, by)?;
        let margin = self.rule.margin();
        let input = self.input.read(block.grown(margin))?;
        let (cover, classes) = match &self.rule {
            Rule::Map { keys, ops, radius_px, blur_px } => from_map(&input, keys, ops, *radius_px, *blur_px),
            Rule::Classes(table) => from_classes(&input[0], table),
            Rule::Linear { zero_at, full_at } => from_linear(&input[0], *zero_at, *full_at),
        };
        let inner = Window::new(margin as i64, margin as i64, block.width, block.height);
        let mut bands = vec![cover.crop(inner, 0.0), classes.crop(inner, f32::NAN)];
        bands.extend(self.type_bands(&input[0], &cover).iter().map(|b| b.crop(inner, 0.0)));
        Ok(bands)
    }
}

fn from_map(
    rgb: &[Raster<f32>],
    keys: &[LabKey],
    ops: &[MorphOp],
    radius: usize,
    blur_px: usize,
) -> (Raster<f32>, Raster<f32>) {
    let band = |b: usize, x: usize, y: usize| rgb.get(b).map_or(f32::NAN, |r| r.get(x, y));
    let (w, h) = (rgb[0].width(), rgb[0].height());
    // Maps and 8-bit images repeat colours: remember recent classifications.
    let mut memo = ColourMemo::new();
    let classes = Raster::from_fn(w, h, |x, y| {
        let rgb = [band(0, x, y), band(1, x, y), band(2, x, y)];
        memo.class(rgb, || colorkey::classify(rgb, keys).map_or(SurfaceType::Plain as u8 as f32, |s| s as u8 as f32))
    });
    let mask = classes.map(|c| if c == SurfaceType::Forest as u8 as f32 { 1.0 } else { 0.0 });
    let closed = morphology::apply_sequence(&mask, ops, radius);
    let mut cover = blur::gaussian(&closed, blur_px);
    for (c, class) in cover.data_mut().iter_mut().zip(classes.data()) {
        if *class == SurfaceType::Water as u8 as f32 {
            *c = 0.0;
        }
    }
    (cover, classes)
}

/// Classes of recently seen colours: a direct-mapped table of 4096 slots
/// (hashing every pixel with SipHash in a `HashMap` was 5 % of `sylva bench
/// pipeline`, measured with perf).
struct ColourMemo {
    slots: Vec<([u32; 3], f32)>,
}

impl ColourMemo {
    const BITS: u32 = 12;
    /// Bits of no colour (the values are f32 bits; this is a NaN no decoder writes).
    const EMPTY: [u32; 3] = [u32::MAX; 3];

    fn new() -> ColourMemo {
        ColourMemo { slots: vec![(Self::EMPTY, 0.0); 1 << Self::BITS] }
    }

    /// The class of `rgb`, from the table or from `classify`.
    #[inline]
    fn class(&mut self, rgb: [f32; 3], classify: impl FnOnce() -> f32) -> f32 {
        let key = rgb.map(f32::to_bits);
        let mix =
            (key[0].wrapping_mul(0x9E37_79B1) ^ key[1].wrapping_mul(0x85EB_CA77) ^ key[2].wrapping_mul(0xC2B2_AE3D))
                .wrapping_mul(0x27D4_EB2F);
        let slot = &mut self.slots[(mix >> (32 - Self::BITS)) as usize];
        if slot.0 != key {
            *slot = (key, classify());
        }
        slot.1
    }
}

fn from_classes(values: &Raster<f32>, table: &HashMap<i64, (SurfaceType, f32)>) -> (Raster<f32>, Raster<f32>) {
    let lookup = |v: f32| if v.is_nan() { None } else { table.get(&(v as i64)) };
    let cover = values.map(|v| lookup(v).map_or(0.0, |e| e.1));
    let classes = values.map(|v| if v.is_nan() { f32::NAN } else { lookup(v).map_or(0.0, |e| e.0 as u8 as f32) });
    (cover, classes)
}

fn from_linear(values: &Raster<f32>, zero_at: f32, full_at: f32) -> (Raster<f32>, Raster<f32>) {
    let cover = values.map(|v| if v.is_nan() { 0.0 } else { ((v - zero_at) / (full_at - zero_at)).clamp(0.0, 1.0) });
    let classes = cover.map(|c| if c >= super::surface::FOREST_COVER { 1.0 } else { 0.0 });
    (cover, classes)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cem::colorkey::ColorKey;

    #[test]
    fn map_rule_keys_closes_and_keeps_water_open() {
        // Forest green with a one-pixel brown contour at x = 5 and a water pixel at (2, 2).
        let (w, h) = (12, 8);
        let color = |x: usize, y: usize| -> [f32; 3] {
            if (x, y) == (2, 2) {
                [160.0, 205.0, 240.0]
            } else if x == 5 {
                [180.0, 120.0, 60.0]
            } else {
                [197.0, 227.0, 165.0]
            }
        };
        let rgb: Vec<Raster<f32>> = (0..3).map(|b| Raster::from_fn(w, h, |x, y| color(x, y)[b])).collect();
        let keys: Vec<LabKey> = [("#c5e3a5", SurfaceType::Forest), ("#a0cdf0", SurfaceType::Water)]
            .iter()
            .map(|(c, s)| ColorKey { color: c.to_string(), tolerance: 10.0, surface: *s }.compile().unwrap())
            .collect();
        let ops = MorphOp::parse_sequence("DE").unwrap();
        let (cover, classes) = from_map(&rgb, &keys, &ops, 1, 0);
        assert_eq!(cover.get(5, 4), 1.0, "the contour is bridged");
        assert_eq!(cover.get(2, 2), 0.0, "water stays open");
        assert_eq!(classes.get(2, 2), SurfaceType::Water as u8 as f32);
        assert_eq!(classes.get(5, 4), SurfaceType::Plain as u8 as f32);
    }

    #[test]
    fn class_and_linear_rules() {
        let table = HashMap::from([(165, (SurfaceType::Forest, 1.0)), (98, (SurfaceType::Water, 0.0))]);
        let v = Raster::from_vec(4, 1, vec![165.0, 98.0, 102.0, f32::NAN]).unwrap();
        let (cover, classes) = from_classes(&v, &table);
        assert_eq!(cover.data(), &[1.0, 0.0, 0.0, 0.0]);
        assert_eq!(&classes.data()[..3], &[1.0, 2.0, 0.0]);
        assert!(classes.get(3, 0).is_nan());
        let pct = Raster::from_vec(3, 1, vec![0.0, 71.0, f32::NAN]).unwrap();
        let (cover, classes) = from_linear(&pct, 0.0, 100.0);
        assert_eq!(cover.data(), &[0.0, 0.71, 0.0]);
        assert_eq!(classes.data(), &[0.0, 1.0, 0.0]);
    }

    #[test]
    fn type_bands_split_the_cover_by_class() {
        use crate::source::memory::MemorySource;
        let values = Raster::from_vec(4, 1, vec![165.0, 183.0, 98.0, 161.0]).unwrap();
        let table = HashMap::from([
            (161, (SurfaceType::Forest, 1.0)),
            (165, (SurfaceType::Forest, 1.0)),
            (183, (SurfaceType::Forest, 0.5)),
            (98, (SurfaceType::Water, 0.0)),
        ]);
        let types = ForestTypes { count: 3, default: 1, by_class: HashMap::from([(183, 2)]) };
        let cache = crate::source::BlockCache::new(1 << 20);
        let input = Blocks::new(std::sync::Arc::new(MemorySource::new("t", vec![values]).unwrap()), &cache);
        let lc = Landcover::with_types(input, Rule::Classes(table), types);
        let b = lc.read_block(0, 0).unwrap();
        assert_eq!(b.len(), 5);
        assert_eq!(b[2].data(), &[0.0, 0.0, 0.0, 0.0]);
        assert_eq!(b[3].data(), &[1.0, 0.0, 0.0, 1.0]);
        assert_eq!(b[4].data(), &[0.0, 0.5, 0.0, 0.0]);
    }
}
