//! A tileable, non-repeating canopy proxy from a canopy height model: a
//! complete set of Wang tiles (dissertation 6.3: "for large areas, we propose
//! a tileable, non-repeating solution such as Wang tiles \[CSHD03\]"). The set
//! with one colour is a single periodic tile.
//!
//! Each tile blends four fields of the CHM ([`super::quilt`] chooses where
//! they come from):
//! - its **interior**, a window of its own drawn by a hash (in one of eight
//!   orientations);
//! - the **edge strips** of its four edge colours: one strip per colour,
//!   anchored to the edge line, so the tiles on both sides of an edge read
//!   the same strip, continuing across the line;
//! - the **corner patch**, one for the whole set, anchored to the corner
//!   points, where four tiles meet.
//!
//! With `a(d)` = smoothstep((d − ½) / border) of a texel's distance `d` to the
//! nearest vertical edge (and likewise `b` for horizontal edges), the weights
//! are `a·b` (interior), `a·(1 − b)` (horizontal strip), `(1 − a)·b`
//! (vertical strip) and `(1 − a)(1 − b)` (corner): a partition of unity that
//! is symmetric about every edge and gives the interior no weight on an edge
//! texel, so tiles whose colours agree continue each other exactly. Fields
//! are blended variance-preserving in Gaussian space ([`super::blend`]) and,
//! last, the heights of the whole set are mapped through one monotone curve
//! onto the CHM's height distribution (histogram matching, Heeger and Bergen
//! 1995): window choices shift the distribution a little, and a monotone map
//! of every texel by the same curve keeps edges matched and continuous.
//!
//! Blending doubles the sparse extremes of a texture where two fields
//! overlap (both fields' pits show), which draws the tile grid as dark lines;
//! `sylva canopy` therefore builds tiles from the pit-filled CHM
//! ([`super::chm::fill_pits`]) and matches their heights to the CHM's.

use super::blend::{Gaussian, blend, smoothstep};
use super::quilt::{Anchor, Source};
use super::stats;
use super::tileset::{Edges, Layout, TileSet};
use crate::raster::Raster;
use thiserror::Error;

/// How a tile set is made.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WangParams {
    /// Texels per tile side (a power of two).
    pub tile_px: usize,
    /// Width of the blend along edges, texels.
    pub border_px: usize,
    /// Colours per edge (1: one periodic tile).
    pub colours: usize,
    /// Tiles per colour combination.
    pub variants: usize,
    /// Seed of the interiors' placement.
    pub seed: u64,
}

impl WangParams {
    /// The default tile for a CHM of `w × h` cells of `cell_m`: about 64 m
    /// (a power of two of texels; the dissertation's proxy covered 500 m,
    /// a 64 m tile leaves room for several disjoint windows in a 200 m
    /// scan), at most half the CHM's shorter side.
    pub fn tile_px_for(cell_m: f64, w: usize, h: usize) -> usize {
        let wanted = ((64.0 / cell_m).max(8.0).log2().round() as u32).clamp(3, 12);
        let fits = ((w.min(h) / 2).max(8).ilog2()).max(3);
        1 << wanted.min(fits)
    }

    /// Tiles of `tile_px` texels with a border of 1/8 of a tile (8 m of a
    /// 64 m tile). A cross-fade over `b` texels adds a slope of about
    /// `(h₁ − h₂) / b` across it, which shading draws as lines along the
    /// edges: at 1/16 the tile grid showed in `--preview`, at 1/8 it does
    /// not, and three quarters of a tile are still its interior alone. Two colours (16 tiles) are Cohen et al.'s
    /// smallest set without visible repetition.
    pub fn new(tile_px: usize, colours: usize, variants: usize) -> WangParams {
        WangParams { tile_px, border_px: (tile_px / 8).max(2), colours, variants, seed: 0x5EED_CA40_F1E5 }
    }
}

/// Why a CHM gives no tile set.
#[derive(Debug, Error, PartialEq)]
pub enum WangError {
    /// No window of the CHM is large enough.
    #[error(
        "no {need}×{need} window of the canopy height model ({w}×{h} cells) has data everywhere; use smaller tiles or a finer resolution"
    )]
    TooSmall {
        /// Cells needed across.
        need: usize,
        /// CHM columns.
        w: usize,
        /// CHM rows.
        h: usize,
    },
    /// The parameters make no valid set.
    #[error("{0}")]
    Layout(String),
}

/// Knots of the histogram-matching curve.
const KNOTS: usize = 256;

/// The tile set made from `chm` (texels of `cell_m`; NaN = outside the
/// scan), its heights matched to the distribution of `target` (sorted; the
/// CHM's own, or that of the CHM it was smoothed from).
pub fn build(chm: &Raster<f32>, target: &[f32], cell_m: f64, p: &WangParams) -> Result<TileSet, WangError> {
    let layout = Layout { tile_px: p.tile_px, colours: p.colours, variants: p.variants, cell_m };
    layout.check().map_err(WangError::Layout)?;
    if p.border_px == 0 || 2 * p.border_px + 2 > p.tile_px {
        return Err(WangError::Layout(format!(
            "a border of {} texels does not fit a {}-texel tile",
            p.border_px, p.tile_px
        )));
    }
    let source = Source::new(chm);
    let too_small = || WangError::TooSmall { need: p.tile_px + 2 * p.border_px + 2, w: chm.width(), h: chm.height() };
    let pieces = Pieces::choose(&source, p).ok_or_else(too_small)?;
    let sorted = stats::sorted(chm.data().iter().copied());
    let gauss = Gaussian::new(sorted);
    let normal = chm.map(|h| if h.is_nan() { h } else { gauss.forward(h) });
    let weights = Weights::new(p.tile_px, p.border_px);
    let mut tiles = Vec::with_capacity(layout.count());
    for i in 0..layout.count() {
        let (anchor, orientation) = source.window(p.tile_px, p.seed, i as i64).ok_or_else(too_small)?;
        let frame = pieces.frame(&normal, &weights, layout.edges(i));
        let tile = Raster::from_fn(p.tile_px, p.tile_px, |x, y| {
            let (ox, oy) = orient(orientation, x, y, p.tile_px);
            let inside = normal.get(anchor.col as usize + ox, anchor.row as usize + oy);
            let wi = weights.ramp[x] * weights.ramp[y];
            let g = if wi == 1.0 { inside } else { blend(&[(wi, inside), (1.0 - wi, frame.get(x, y))], 0.0) };
            gauss.back(g)
        });
        tiles.push(tile);
    }
    match_histogram(&mut tiles, target);
    TileSet::new(layout, tiles).map_err(WangError::Layout)
}

/// The pieces the tiles are cut from.
struct Pieces {
    tile_px: usize,
    corner: Anchor,
    horizontal: Vec<Anchor>,
    vertical: Vec<Anchor>,
}

impl Pieces {
    fn choose(source: &Source, p: &WangParams) -> Option<Pieces> {
        let margin = p.border_px + 1;
        let corner = source.corner(margin)?;
        let mut taken = vec![corner];
        let mut strips = |horizontal: bool| -> Option<Vec<Anchor>> {
            (0..p.colours)
                .map(|_| {
                    let a = source.strip(horizontal, p.tile_px, margin, &taken)?;
                    taken.push(a);
                    Some(a)
                })
                .collect()
        };
        let horizontal = strips(true)?;
        let vertical = strips(false)?;
        Some(Pieces { tile_px: p.tile_px, corner, horizontal, vertical })
    }

    /// The tile without its interior: at every texel the blend of the strips
    /// and the corner of `normal` (the CHM in Gaussian space) with their
    /// weights (NaN where the interior has all the weight).
    fn frame(&self, normal: &Raster<f32>, w: &Weights, e: Edges) -> Raster<f32> {
        let t = self.tile_px as i64;
        Raster::from_fn(self.tile_px, self.tile_px, |x, y| {
            let (a, b) = (w.ramp[x], w.ramp[y]);
            if a == 1.0 && b == 1.0 {
                return f32::NAN;
            }
            let (xi, yi) = (x as i64, y as i64);
            // Fields near the far edge are read from the strip's other side.
            let (top, left) = (yi < t / 2, xi < t / 2);
            let (oy, ox) = (if top { 0 } else { -t }, if left { 0 } else { -t });
            // Only fields with weight are read: the others may lie outside the CHM.
            let read = |weight: f32, a: Anchor, dy: i64, dx: i64| {
                let (row, col) = (a.row + yi + dy, a.col + xi + dx);
                (weight, if weight > 0.0 { normal.get(col as usize, row as usize) } else { 0.0 })
            };
            let h = read(a * (1.0 - b), self.horizontal[if top { e.n } else { e.s }], oy, 0);
            let v = read((1.0 - a) * b, self.vertical[if left { e.w } else { e.e }], 0, ox);
            let k = read((1.0 - a) * (1.0 - b), self.corner, oy, ox);
            blend(&[h, v, k], 0.0)
        })
    }
}

/// The blend weights of a tile's texels.
struct Weights {
    /// `a(d)` of every column (and row).
    ramp: Vec<f32>,
}

impl Weights {
    fn new(tile_px: usize, border_px: usize) -> Weights {
        let ramp = (0..tile_px)
            .map(|x| {
                let d = (x as f64 + 0.5).min(tile_px as f64 - x as f64 - 0.5);
                smoothstep((d - 0.5) / border_px as f64) as f32
            })
            .collect();
        Weights { ramp }
    }
}

/// Texel `(x, y)` of a `t`-texel window in orientation `o` (the eight
/// symmetries of the square).
fn orient(o: usize, x: usize, y: usize, t: usize) -> (usize, usize) {
    let (x, y) = if o >= 4 { (y, x) } else { (x, y) };
    match o % 4 {
        0 => (x, y),
        1 => (t - 1 - x, y),
        2 => (x, t - 1 - y),
        _ => (t - 1 - x, t - 1 - y),
    }
}

/// Maps every texel through the monotone piecewise-linear curve that takes
/// the tiles' height quantiles to the CHM's (`target`, sorted).
fn match_histogram(tiles: &mut [Raster<f32>], target: &[f32]) {
    let own = stats::sorted(tiles.iter().flat_map(|t| t.data().iter().copied()));
    let mut knots: Vec<(f32, f32)> = Vec::with_capacity(KNOTS + 1);
    for k in 0..=KNOTS {
        let q = k as f64 / KNOTS as f64;
        let (from, to) = (stats::sorted_quantile(&own, q), stats::sorted_quantile(target, q));
        if knots.last().is_none_or(|l| from > l.0) {
            knots.push((from, to));
        }
    }
    let map = |v: f32| {
        let i = knots.partition_point(|k| k.0 <= v);
        match (i.checked_sub(1).map(|j| knots[j]), knots.get(i)) {
            (Some(a), Some(b)) => a.1 + (b.1 - a.1) * (v - a.0) / (b.0 - a.0),
            (Some(a), None) => a.1,
            (None, Some(b)) => b.1,
            (None, None) => v,
        }
    };
    for t in tiles {
        t.data_mut().iter_mut().for_each(|v| *v = map(*v));
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::noise::fbm;

    /// A synthetic canopy: fractal noise between 0 and 30 m.
    fn canopy(w: usize, h: usize) -> Raster<f32> {
        Raster::from_fn(w, h, |x, y| (15.0 + 15.0 * fbm(x as f64, y as f64, 6.0, 4, 3)) as f32)
    }

    #[test]
    fn tiles_whose_colours_agree_continue_each_other() {
        let p = WangParams { tile_px: 32, border_px: 4, colours: 2, variants: 1, seed: 1 };
        let chm = canopy(160, 120);
        let set = build(&chm, &stats::sorted(chm.data().iter().copied()), 0.5, &p).unwrap();
        let l = *set.layout();
        for (i, a) in set.tiles().iter().enumerate() {
            for (j, b) in set.tiles().iter().enumerate() {
                let (ea, eb) = (l.edges(i), l.edges(j));
                // b south of a: rows 31 of a and 0 of b are neighbours in one strip.
                if ea.s == eb.n {
                    for x in 0..32 {
                        assert!((a.get(x, 31) - b.get(x, 0)).abs() < 8.0, "{i} above {j} at {x}");
                    }
                }
            }
        }
        assert!(orient(5, 1, 2, 32) == (29, 1));
    }

    #[test]
    fn a_chm_too_small_for_a_tile_is_refused() {
        let p = WangParams { tile_px: 64, border_px: 4, colours: 1, variants: 1, seed: 1 };
        let (chm, target) = (canopy(50, 50), [0.0, 30.0]);
        assert!(matches!(build(&chm, &target, 0.5, &p), Err(WangError::TooSmall { .. })));
        assert!(matches!(build(&chm, &target, 0.5, &WangParams { tile_px: 48, ..p }), Err(WangError::Layout(_))));
    }
}
