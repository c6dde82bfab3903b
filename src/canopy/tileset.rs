//! A set of edge-compatible canopy tiles (Wang tiles, Cohen et al. 2003, as
//! dissertation 6.3 proposes "for large areas"): every tile has a colour on
//! each edge, and two tiles may touch along an edge when their colours there
//! agree. The set is complete — one tile or more for every combination of
//! north, east, south and west colours — so a tile can be chosen for any
//! cell from colours hashed per edge, and the canopy never repeats.
//!
//! Tiles are square, `tile_px` (a power of two) texels of `cell_m` metres;
//! each has a box-filtered mip chain down to one texel, for sampling at
//! coarse spacings. On disk the tiles are an atlas, `colours²` tiles across,
//! in the order of [`Layout::index`].
//!
//! Invariant: every texel is a finite height ≥ 0.

use super::stats::HeightStats;
use std::ops::RangeInclusive;

/// First word of an atlas's tag.
const TAG: &str = "sylva-canopy-proxy";
use crate::raster::{Raster, Window};

/// Edge colours of a tile, north, east, south and west, and its variant.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Edges {
    /// North edge colour.
    pub n: usize,
    /// East edge colour.
    pub e: usize,
    /// South edge colour.
    pub s: usize,
    /// West edge colour.
    pub w: usize,
    /// Which of the tiles with these colours.
    pub variant: usize,
}

/// The layout of a tile set.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Layout {
    /// Texels per tile side (a power of two).
    pub tile_px: usize,
    /// Colours per edge.
    pub colours: usize,
    /// Tiles per colour combination.
    pub variants: usize,
    /// Texel side, metres.
    pub cell_m: f64,
}

impl Layout {
    /// Number of tiles: `colours⁴ · variants`.
    pub fn count(&self) -> usize {
        self.colours.pow(4) * self.variants
    }

    /// Tiles across the atlas.
    pub fn atlas_columns(&self) -> usize {
        self.colours * self.colours
    }

    /// Texels across and down the atlas.
    pub fn atlas_size(&self) -> (usize, usize) {
        let rows = self.count().div_ceil(self.atlas_columns());
        (self.atlas_columns() * self.tile_px, rows * self.tile_px)
    }

    /// Side of a tile, metres.
    pub fn tile_m(&self) -> f64 {
        self.tile_px as f64 * self.cell_m
    }

    /// Texels per tile side, a power of two within: from 8, the smallest
    /// side that holds [`super::wang::WangParams`]'s 2-texel borders and an
    /// interior, to 4096 (the 2¹² that `WangParams::tile_px_for` picks at
    /// most).
    pub const TILE_PX: RangeInclusive<usize> = 8..=4096;
    /// Colours per edge (4: 256 combinations).
    pub const COLOURS: RangeInclusive<usize> = 1..=4;
    /// Tiles per colour combination.
    pub const VARIANTS: RangeInclusive<usize> = 1..=8;

    /// An error unless `tile_px` is a power of two in [`Layout::TILE_PX`].
    pub fn check_tile_px(tile_px: usize) -> Result<(), String> {
        let (min, max) = Layout::TILE_PX.into_inner();
        match tile_px.is_power_of_two() && Layout::TILE_PX.contains(&tile_px) {
            true => Ok(()),
            false => Err(format!("tiles must be a power of two from {min} to {max} texels across, not {tile_px}")),
        }
    }

    /// An error unless the layout is usable.
    pub fn check(&self) -> Result<(), String> {
        Layout::check_tile_px(self.tile_px)?;
        if !Layout::COLOURS.contains(&self.colours) || !Layout::VARIANTS.contains(&self.variants) {
            return Err(format!(
                "{} colours and {} variants: colours must be in {:?} and variants in {:?}",
                self.colours,
                self.variants,
                Layout::COLOURS,
                Layout::VARIANTS
            ));
        }
        if !(self.cell_m > 0.0 && self.cell_m.is_finite()) {
            return Err(format!("texel size {} m is not a positive number", self.cell_m));
        }
        Ok(())
    }

    /// The layout as the tag stored with an atlas (its GeoTIFF
    /// ImageDescription).
    pub fn tag(&self) -> String {
        format!(
            "{TAG} tile_px={} colours={} variants={} cell_m={}",
            self.tile_px, self.colours, self.variants, self.cell_m
        )
    }

    /// The layout a tag describes.
    pub fn parse_tag(text: &str) -> Result<Layout, String> {
        let mut words = text.trim_matches(char::from(0)).split_whitespace();
        if words.next() != Some(TAG) {
            return Err(format!("not a Sylva canopy proxy (its description does not start with {TAG:?})"));
        }
        let mut layout = Layout { tile_px: 0, colours: 0, variants: 0, cell_m: 0.0 };
        for word in words {
            let (key, value) = word.split_once('=').ok_or_else(|| format!("bad layout entry {word:?}"))?;
            let bad = |_| format!("bad value in {word:?}");
            match key {
                "tile_px" => layout.tile_px = value.parse().map_err(bad)?,
                "colours" => layout.colours = value.parse().map_err(bad)?,
                "variants" => layout.variants = value.parse().map_err(bad)?,
                "cell_m" => layout.cell_m = value.parse().map_err(|_| format!("bad value in {word:?}"))?,
                _ => return Err(format!("unknown layout entry {word:?}")),
            }
        }
        layout.check().map(|_| layout)
    }

    /// The index of the tile with these edges.
    pub fn index(&self, e: Edges) -> usize {
        let c = self.colours;
        (((e.n * c + e.e) * c + e.s) * c + e.w) * self.variants + e.variant
    }

    /// The edges of tile `i` (the inverse of [`Layout::index`]).
    pub fn edges(&self, i: usize) -> Edges {
        let c = self.colours;
        let (rest, variant) = (i / self.variants, i % self.variants);
        Edges { n: rest / (c * c * c), e: rest / (c * c) % c, s: rest / c % c, w: rest % c, variant }
    }
}

/// A complete set of edge-compatible tiles with their mip chains.
#[derive(Clone, Debug)]
pub struct TileSet {
    layout: Layout,
    /// `levels[k][i]`: tile `i` box-filtered to `tile_px >> k` texels.
    levels: Vec<Vec<Raster<f32>>>,
    stats: HeightStats,
}

impl TileSet {
    /// A set from its tiles (in [`Layout::index`] order); an error names what
    /// does not fit.
    pub fn new(layout: Layout, tiles: Vec<Raster<f32>>) -> Result<TileSet, String> {
        layout.check()?;
        if tiles.len() != layout.count() {
            return Err(format!("{} tiles, expected {}", tiles.len(), layout.count()));
        }
        let t = layout.tile_px;
        if let Some(bad) = tiles.iter().position(|r| (r.width(), r.height()) != (t, t)) {
            return Err(format!("tile {bad} is not {t}×{t}"));
        }
        if tiles.iter().any(|r| r.data().iter().any(|v| !(v.is_finite() && *v >= 0.0))) {
            return Err("heights must be finite and not negative (no nodata in a proxy)".into());
        }
        let stats = HeightStats::of(tiles.iter().flat_map(|r| r.data().iter().copied()));
        let mut levels = vec![tiles];
        while let Some(last) = levels.last().filter(|l| l[0].width() > 1) {
            let next = last.iter().map(halve).collect();
            levels.push(next);
        }
        Ok(TileSet { layout, levels, stats })
    }

    /// The set cut from an atlas.
    pub fn from_atlas(layout: Layout, atlas: &Raster<f32>) -> Result<TileSet, String> {
        layout.check()?;
        if (atlas.width(), atlas.height()) != layout.atlas_size() {
            let (w, h) = layout.atlas_size();
            return Err(format!("the atlas is {}×{}, expected {w}×{h}", atlas.width(), atlas.height()));
        }
        let t = layout.tile_px;
        let cols = layout.atlas_columns();
        let tiles = (0..layout.count())
            .map(|i| atlas.crop(Window::new(((i % cols) * t) as i64, ((i / cols) * t) as i64, t, t), 0.0))
            .collect();
        TileSet::new(layout, tiles)
    }

    /// All tiles in one raster, [`Layout::atlas_columns`] across; unused
    /// places are 0.
    pub fn atlas(&self) -> Raster<f32> {
        let (w, h) = self.layout.atlas_size();
        let mut atlas = Raster::filled(w, h, 0.0);
        let (t, cols) = (self.layout.tile_px, self.layout.atlas_columns());
        for (i, tile) in self.tiles().iter().enumerate() {
            atlas.paste(tile, Window::new(0, 0, t, t), (i % cols) * t, (i / cols) * t);
        }
        atlas
    }

    /// The layout.
    pub fn layout(&self) -> &Layout {
        &self.layout
    }

    /// The full-resolution tiles.
    pub fn tiles(&self) -> &[Raster<f32>] {
        &self.levels[0]
    }

    /// Tile `i` at mip level `k` (`tile_px >> k` texels across).
    #[inline]
    pub fn level(&self, k: usize, i: usize) -> &Raster<f32> {
        &self.levels[k][i]
    }

    /// Number of mip levels (level 0 is full resolution, the last one texel).
    pub fn levels(&self) -> usize {
        self.levels.len()
    }

    /// Height statistics of all texels.
    pub fn stats(&self) -> &HeightStats {
        &self.stats
    }
}

/// The 2 × 2 box filter.
fn halve(r: &Raster<f32>) -> Raster<f32> {
    Raster::from_fn(r.width() / 2, r.height() / 2, |x, y| {
        0.25 * (r.get(2 * x, 2 * y) + r.get(2 * x + 1, 2 * y) + r.get(2 * x, 2 * y + 1) + r.get(2 * x + 1, 2 * y + 1))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn indices_and_edges_round_trip_and_the_atlas_too() {
        let layout = Layout { tile_px: 8, colours: 2, variants: 2, cell_m: 0.5 };
        for i in 0..layout.count() {
            assert_eq!(layout.index(layout.edges(i)), i);
        }
        let tiles: Vec<_> = (0..32).map(|i| Raster::from_fn(8, 8, |x, y| (i * 64 + y * 8 + x) as f32)).collect();
        let set = TileSet::new(layout, tiles.clone()).unwrap();
        assert_eq!(set.levels(), 4);
        assert_eq!(set.level(3, 5).get(0, 0), tiles[5].data().iter().sum::<f32>() / 64.0);
        let back = TileSet::from_atlas(layout, &set.atlas()).unwrap();
        assert_eq!(back.tiles(), set.tiles());
        assert!(TileSet::new(layout, tiles[..31].to_vec()).is_err());
        assert_eq!(Layout::parse_tag(&layout.tag()), Ok(layout));
        assert!(Layout::parse_tag("sylva-canopy-proxy tile_px=12 colours=2 variants=1 cell_m=1").is_err());
    }
}
