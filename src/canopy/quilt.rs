//! Choosing where in a canopy height model the pieces of Wang tiles come
//! from (image quilting after Efros and Freeman 2001, as Cohen et al. 2003
//! build Wang tiles): the corner patch and the edge strips are placed where
//! the canopy crosses their edge lines most smoothly, so no tile edge shows
//! a step; the interiors are placed where they best continue the strips
//! around them.
//!
//! Invariant: choices depend only on the CHM and the seed (scans in a fixed
//! order, candidates from a hash), so a proxy is reproducible.

use crate::noise::{hash2, unit};
use crate::raster::Raster;

/// A CHM with a summed table of its nodata cells, for fast window tests.
pub struct Source<'a> {
    chm: &'a Raster<f32>,
    /// `nodata[(r · (w + 1)) + c]`: nodata cells above and left of `(c, r)`.
    nodata: Vec<u32>,
}

/// Where a piece's texel `(0, 0)` lies in the CHM (row, column).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Anchor {
    /// Row.
    pub row: i64,
    /// Column.
    pub col: i64,
}

impl<'a> Source<'a> {
    /// The source over a CHM (NaN = outside the scan).
    pub fn new(chm: &'a Raster<f32>) -> Source<'a> {
        let (w, h) = (chm.width(), chm.height());
        let mut nodata = vec![0u32; (w + 1) * (h + 1)];
        for r in 0..h {
            let mut row_sum = 0;
            for c in 0..w {
                row_sum += u32::from(chm.get(c, r).is_nan());
                nodata[(r + 1) * (w + 1) + c + 1] = nodata[r * (w + 1) + c + 1] + row_sum;
            }
        }
        Source { chm, nodata }
    }

    /// Columns and rows.
    pub fn size(&self) -> (usize, usize) {
        (self.chm.width(), self.chm.height())
    }

    /// True when rows `row .. row + h` and columns `col .. col + w` are inside
    /// the CHM and have data.
    pub fn valid(&self, row: i64, col: i64, h: usize, w: usize) -> bool {
        let (cw, ch) = self.size();
        if row < 0 || col < 0 || row as usize + h > ch || col as usize + w > cw {
            return false;
        }
        let (r0, c0, stride) = (row as usize, col as usize, cw + 1);
        let at = |r: usize, c: usize| self.nodata[r * stride + c];
        at(r0 + h, c0 + w) + at(r0, c0) == at(r0, c0 + w) + at(r0 + h, c0)
    }

    /// The height at `(row, col)` (inside a valid window).
    #[inline]
    pub fn at(&self, row: i64, col: i64) -> f32 {
        self.chm.get(col as usize, row as usize)
    }

    /// Largest step across the line between rows `row − 1` and `row`, over
    /// columns `col .. col + len`.
    fn step_across_row(&self, row: i64, col: i64, len: usize) -> f32 {
        (0..len as i64).map(|i| (self.at(row, col + i) - self.at(row - 1, col + i)).abs()).fold(0.0, f32::max)
    }

    /// Largest step across the line between columns `col − 1` and `col`.
    fn step_across_column(&self, row: i64, col: i64, len: usize) -> f32 {
        (0..len as i64).map(|i| (self.at(row + i, col) - self.at(row + i, col - 1)).abs()).fold(0.0, f32::max)
    }

    /// The corner patch: texels within `margin` of a corner point whose two
    /// lines cross the canopy most smoothly.
    pub fn corner(&self, margin: usize) -> Option<Anchor> {
        let m = margin as i64;
        let span = 2 * margin;
        self.best(m, m, |a| {
            self.valid(a.row - m, a.col - m, span, span).then(|| {
                self.step_across_row(a.row, a.col - m, span).max(self.step_across_column(a.row - m, a.col, span))
            })
        })
    }

    /// An edge strip `len` texels long reaching `margin` texels to either
    /// side of its line (horizontal: the line lies between rows `row − 1`
    /// and `row`), away from the anchors `taken` when possible.
    pub fn strip(&self, horizontal: bool, len: usize, margin: usize, taken: &[Anchor]) -> Option<Anchor> {
        let m = margin as i64;
        let cost = |a: Anchor| {
            if horizontal {
                self.valid(a.row - m, a.col, 2 * margin, len).then(|| self.step_across_row(a.row, a.col, len))
            } else {
                self.valid(a.row, a.col - m, len, 2 * margin).then(|| self.step_across_column(a.row, a.col, len))
            }
        };
        // Different places for different colours: none within half a strip of another piece.
        let apart = |a: Anchor| {
            taken.iter().all(|t| (t.row - a.row).abs() >= len as i64 / 2 || (t.col - a.col).abs() >= len as i64 / 2)
        };
        let (r0, c0) = if horizontal { (m, 0) } else { (0, m) };
        self.best(r0, c0, |a| if apart(a) { cost(a) } else { None }).or_else(|| self.best(r0, c0, cost))
    }

    /// The anchor with the least cost, scanning every second row and column
    /// from `(row0, col0)`; ties go to the first.
    fn best(&self, row0: i64, col0: i64, cost: impl Fn(Anchor) -> Option<f32>) -> Option<Anchor> {
        let (w, h) = self.size();
        let mut best: Option<(f32, Anchor)> = None;
        for row in (row0..h as i64).step_by(2) {
            for col in (col0..w as i64).step_by(2) {
                let a = Anchor { row, col };
                if let Some(c) = cost(a).filter(|&c| best.is_none_or(|b| c < b.0)) {
                    best = Some((c, a));
                }
            }
        }
        best.map(|b| b.1)
    }

    /// Up to `n` windows of `size²` texels with data, drawn by a hash of
    /// `seed` and `key` (at most `8 n` draws).
    pub fn windows(&self, size: usize, n: usize, seed: u64, key: i64) -> Vec<Anchor> {
        let (w, h) = self.size();
        if w < size || h < size {
            return Vec::new();
        }
        (0..8 * n as i64)
            .map(|k| {
                let bits = hash2(key, k, seed);
                let pick = |u: f64, range: usize| ((u * (range + 1) as f64) as i64).min(range as i64);
                Anchor { row: pick(unit(bits, 0), h - size), col: pick(unit(bits, 1), w - size) }
            })
            .filter(|a| self.valid(a.row, a.col, size, size))
            .take(n)
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn strips_avoid_steps_and_windows_avoid_nodata() {
        // Heights jump by 10 m between every pair of rows but 20 and 21.
        let chm = Raster::from_fn(40, 40, |x, y| match (x >= 30 && y >= 30, y) {
            (true, _) => f32::NAN,
            (false, 21) => 0.0,
            _ => 10.0 * (y % 2) as f32,
        });
        let s = Source::new(&chm);
        assert!(s.valid(0, 0, 30, 40) && !s.valid(0, 0, 31, 31));
        let a = s.strip(true, 16, 3, &[]).unwrap();
        assert_eq!(a.row, 21, "{a:?}");
        for w in s.windows(12, 20, 7, 1) {
            assert!(s.valid(w.row, w.col, 12, 12));
        }
    }
}
