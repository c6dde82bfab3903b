//! Choosing where in a canopy height model the pieces of Wang tiles come
//! from. The corner patch and the edge strips (the pieces tiles share) are
//! placed, as image quilting (Efros and Freeman 2001) places its patches, by
//! how well they join: among the places where the canopy crosses the edge
//! line with no step above [`Source::smooth_step`] (the CHM's 90th
//! percentile), the one whose mean height is nearest the CHM's, so that
//! shared pieces are not all drawn from gaps, which are smooth too; failing
//! that, the smoothest place. Interiors are windows drawn by a hash.
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
    /// The same for the sum of heights.
    sum: Vec<f64>,
    mean: f32,
    /// Steps between neighbours up to this are smooth (the 90th percentile).
    smooth_step: f32,
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
        let mut sum = vec![0f64; (w + 1) * (h + 1)];
        for r in 0..h {
            let (mut row_nodata, mut row_sum) = (0, 0.0);
            for c in 0..w {
                let v = chm.get(c, r);
                row_nodata += u32::from(v.is_nan());
                row_sum += if v.is_nan() { 0.0 } else { f64::from(v) };
                let (at, above) = ((r + 1) * (w + 1) + c + 1, r * (w + 1) + c + 1);
                nodata[at] = nodata[above] + row_nodata;
                sum[at] = sum[above] + row_sum;
            }
        }
        let valid = (w * h) as f64 - f64::from(nodata[(w + 1) * (h + 1) - 1]);
        let mean = (sum[(w + 1) * (h + 1) - 1] / valid.max(1.0)) as f32;
        let steps =
            super::stats::sorted((1..w).flat_map(|c| (0..h).map(move |r| (chm.get(c, r) - chm.get(c - 1, r)).abs())));
        let smooth_step = super::stats::sorted_quantile(&steps, 0.9);
        Source { chm, nodata, sum, mean, smooth_step }
    }

    /// Mean height of the valid cells.
    pub fn mean(&self) -> f32 {
        self.mean
    }

    /// The sum over rows `row .. row + h`, columns `col .. col + w` of a
    /// summed table (the window must be inside).
    fn window_sum<T: Copy + std::ops::Add<Output = T> + std::ops::Sub<Output = T>>(
        &self,
        table: &[T],
        row: i64,
        col: i64,
        h: usize,
        w: usize,
    ) -> T {
        let (r0, c0, stride) = (row as usize, col as usize, self.chm.width() + 1);
        let at = |r: usize, c: usize| table[r * stride + c];
        at(r0 + h, c0 + w) + at(r0, c0) - at(r0, c0 + w) - at(r0 + h, c0)
    }

    /// How far the window's mean height is from the CHM's (the window must
    /// be valid).
    fn unrepresentative(&self, row: i64, col: i64, h: usize, w: usize) -> f32 {
        ((self.window_sum(&self.sum, row, col, h, w) / (h * w) as f64) as f32 - self.mean).abs()
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
        self.window_sum(&self.nodata, row, col, h, w) == 0
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

    /// The corner patch: texels within `margin` of a corner point, placed
    /// by the rule above (steps across both of its lines).
    pub fn corner(&self, margin: usize) -> Option<Anchor> {
        let (m, span) = (margin as i64, 2 * margin);
        self.place(m, m, |a| {
            self.valid(a.row - m, a.col - m, span, span).then(|| {
                let step =
                    self.step_across_row(a.row, a.col - m, span).max(self.step_across_column(a.row - m, a.col, span));
                (step, self.unrepresentative(a.row - m, a.col - m, span, span))
            })
        })
    }

    /// An edge strip `len` texels long reaching `margin` texels to either
    /// side of its line (horizontal: the line lies between rows `row − 1`
    /// and `row`), placed by the rule above, and away from the anchors
    /// `taken` when possible.
    pub fn strip(&self, horizontal: bool, len: usize, margin: usize, taken: &[Anchor]) -> Option<Anchor> {
        let m = margin as i64;
        let (r0, c0, h, w) = if horizontal { (-m, 0, 2 * margin, len) } else { (0, -m, len, 2 * margin) };
        let cost = |a: Anchor| {
            self.valid(a.row + r0, a.col + c0, h, w).then(|| {
                let step = if horizontal {
                    self.step_across_row(a.row, a.col, len)
                } else {
                    self.step_across_column(a.row, a.col, len)
                };
                (step, self.unrepresentative(a.row + r0, a.col + c0, h, w))
            })
        };
        // Different places for different colours: none within half a strip of another piece.
        let half = len as i64 / 2;
        let apart = |a: Anchor| taken.iter().all(|t| (t.row - a.row).abs() >= half || (t.col - a.col).abs() >= half);
        self.place(-r0, -c0, |a| if apart(a) { cost(a) } else { None }).or_else(|| self.place(-r0, -c0, cost))
    }

    /// The place of least unrepresentativeness among the smooth ones, else
    /// the one of least step; `cost` gives (step, unrepresentativeness).
    fn place(&self, row0: i64, col0: i64, cost: impl Fn(Anchor) -> Option<(f32, f32)>) -> Option<Anchor> {
        let smooth = |a: Anchor| cost(a).filter(|c| c.0 <= self.smooth_step).map(|c| c.1);
        self.best(row0, col0, smooth).or_else(|| self.best(row0, col0, |a| cost(a).map(|c| c.0)))
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

    /// The `key`-th window of `size²` texels with data drawn by a hash of
    /// `seed` (at most 64 draws), and an orientation (0–7).
    pub fn window(&self, size: usize, seed: u64, key: i64) -> Option<(Anchor, usize)> {
        let (w, h) = self.size();
        if w < size || h < size {
            return None;
        }
        (0..64)
            .map(|k| {
                let bits = hash2(key, k, seed);
                let pick = |u: f64, range: usize| ((u * (range + 1) as f64) as i64).min(range as i64);
                (
                    Anchor { row: pick(unit(bits, 0), h - size), col: pick(unit(bits, 1), w - size) },
                    (bits >> 61) as usize,
                )
            })
            .find(|(a, _)| self.valid(a.row, a.col, size, size))
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
        for key in 0..20 {
            let (w, o) = s.window(12, 7, key).unwrap();
            assert!(s.valid(w.row, w.col, 12, 12) && o < 8);
        }
    }
}
