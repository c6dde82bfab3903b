//! Choosing where in a canopy height model the pieces of Wang tiles come
//! from. The corner patch and the edge strips (the pieces tiles share) are
//! placed, as image quilting (Efros and Freeman 2001) places its patches, by
//! how well they join: among the places where the canopy crosses the edge
//! line with no step above 0.75 × the 99th percentile of the CHM's steps
//! between neighbours, the one whose heights (mean and spread, of the piece
//! and of each row along its line) and mean steps (across the line, and
//! along each row) are nearest the CHM's. A piece is seen along every edge of its colour, so it
//! must look like the forest, not like a gap or a filled void, which are
//! smoother; failing that, the smoothest place. Interiors are
//! windows drawn by a hash.
//!
//! Invariant: choices depend only on the CHM and the seed (scans in a fixed
//! order, candidates from a hash), so a proxy is reproducible.

use crate::noise::{hash2, unit};
use crate::raster::Raster;

/// A CHM with a summed table of its nodata cells, for fast window tests.
pub struct Source<'a> {
    chm: &'a Raster<f32>,
    /// Summed tables (`(w + 1) × (h + 1)`, entry `(c, r)` sums the cells
    /// above and left of `(c, r)`) of nodata cells, heights, squared
    /// heights, and steps to the cell above and to the cell on the left.
    nodata: Vec<f64>,
    sum: Vec<f64>,
    sum2: Vec<f64>,
    step_up: Vec<f64>,
    step_left: Vec<f64>,
    mean: f64,
    deviation: f64,
    /// Steps between neighbours up to this are smooth.
    smooth_step: f32,
    /// The mean step between neighbours.
    mean_step: f64,
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
        let value = |c: usize, r: usize| f64::from(chm.get(c, r));
        let valid = |v: f64| if v.is_nan() { 0.0 } else { v };
        let nodata = summed(w, h, |c, r| f64::from(u8::from(chm.get(c, r).is_nan())));
        let sum = summed(w, h, |c, r| valid(value(c, r)));
        let sum2 = summed(w, h, |c, r| valid(value(c, r)).powi(2));
        let step_up = summed(w, h, |c, r| if r == 0 { 0.0 } else { valid((value(c, r) - value(c, r - 1)).abs()) });
        let step_left = summed(w, h, |c, r| if c == 0 { 0.0 } else { valid((value(c, r) - value(c - 1, r)).abs()) });
        let last = (w + 1) * (h + 1) - 1;
        let cells = ((w * h) as f64 - nodata[last]).max(1.0);
        let mean = sum[last] / cells;
        let deviation = (sum2[last] / cells - mean * mean).max(0.0).sqrt();
        let across = (1..w).flat_map(|c| (0..h).map(move |r| (chm.get(c, r) - chm.get(c - 1, r)).abs()));
        let down = (0..w).flat_map(|c| (1..h).map(move |r| (chm.get(c, r) - chm.get(c, r - 1)).abs()));
        let steps = super::stats::sorted(across.chain(down));
        // Tiles are remapped to the raw CHM's heights at the end, which
        // stretches steps; with 0.9 Topography's edges came out at 8.4 m
        // against a p99 of 7.9 m inside its tiles, with 0.75 at 7.2 m.
        let smooth_step = 0.75 * super::stats::sorted_quantile(&steps, 0.99);
        let mean_step = steps.iter().map(|&d| f64::from(d)).sum::<f64>() / steps.len().max(1) as f64;
        Source { chm, nodata, sum, sum2, step_up, step_left, mean, deviation, smooth_step, mean_step }
    }

    /// The sum over rows `row .. row + h`, columns `col .. col + w` of a
    /// summed table (the window must be inside).
    fn window_sum(&self, table: &[f64], row: i64, col: i64, h: usize, w: usize) -> f64 {
        let (r0, c0, stride) = (row as usize, col as usize, self.chm.width() + 1);
        let at = |r: usize, c: usize| table[r * stride + c];
        at(r0 + h, c0 + w) + at(r0, c0) - at(r0, c0 + w) - at(r0 + h, c0)
    }

    /// How far the window's mean and standard deviation of heights are
    /// from the CHM's, metres (the window must be valid).
    fn unrepresentative(&self, row: i64, col: i64, h: usize, w: usize) -> f32 {
        let n = (h * w) as f64;
        let mean = self.window_sum(&self.sum, row, col, h, w) / n;
        let deviation = (self.window_sum(&self.sum2, row, col, h, w) / n - mean * mean).max(0.0).sqrt();
        ((mean - self.mean).abs() + (deviation - self.deviation).abs()) as f32
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
        self.window_sum(&self.nodata, row, col, h, w) == 0.0
    }

    /// The height at `(row, col)` (inside a valid window).
    #[inline]
    pub fn at(&self, row: i64, col: i64) -> f32 {
        self.chm.get(col as usize, row as usize)
    }

    /// The largest and the mean step across a line: horizontal, between
    /// rows `row − 1` and `row` over columns `col .. col + len`; vertical,
    /// between columns `col − 1` and `col` over rows `row .. row + len`.
    fn steps_across(&self, horizontal: bool, row: i64, col: i64, len: usize) -> (f32, f32) {
        let step = |i: i64| match horizontal {
            true => (self.at(row, col + i) - self.at(row - 1, col + i)).abs(),
            false => (self.at(row + i, col) - self.at(row + i, col - 1)).abs(),
        };
        let (max, sum) = (0..len as i64).map(step).fold((0.0f32, 0.0f32), |(m, s), d| (m.max(d), s + d));
        (max, sum / len as f32)
    }

    /// Cost of a line: its largest step, and how far its heights (the two
    /// rows or columns along it) and its mean step are from the CHM's.
    fn line(&self, horizontal: bool, row: i64, col: i64, len: usize) -> (f32, f32) {
        let (max, mean) = self.steps_across(horizontal, row, col, len);
        let heights = match horizontal {
            true => self.unrepresentative(row - 1, col, 2, len),
            false => self.unrepresentative(row, col - 1, len, 2),
        };
        (max, heights + (f64::from(mean) - self.mean_step).abs() as f32)
    }

    /// The corner patch: texels within `margin` of a corner point, placed
    /// by the rule above (both of its lines).
    pub fn corner(&self, margin: usize) -> Option<Anchor> {
        let (m, span) = (margin as i64, 2 * margin);
        self.place(m, m, |a| {
            self.valid(a.row - m, a.col - m, span, span).then(|| {
                let (h, v) = (self.line(true, a.row, a.col - m, span), self.line(false, a.row - m, a.col, span));
                (h.0.max(v.0), h.1 + v.1 + self.unrepresentative(a.row - m, a.col - m, span, span))
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
        // Every row (column) along the strip is seen along every edge of its
        // colour: the least representative one counts, so no track or gap
        // along the strip becomes a grid of lines.
        let worst_line = |a: Anchor| {
            let n = (len - 1) as f64;
            (-m..m)
                .map(|d| {
                    let (heights, along) = match horizontal {
                        true => (
                            self.unrepresentative(a.row + d, a.col, 1, len),
                            self.window_sum(&self.step_left, a.row + d, a.col + 1, 1, len - 1),
                        ),
                        false => (
                            self.unrepresentative(a.row, a.col + d, len, 1),
                            self.window_sum(&self.step_up, a.row + 1, a.col + d, len - 1, 1),
                        ),
                    };
                    heights + (along / n - self.mean_step).abs() as f32
                })
                .fold(0.0f32, f32::max)
        };
        let cost = |a: Anchor| {
            self.valid(a.row + r0, a.col + c0, h, w).then(|| {
                let (max, line) = self.line(horizontal, a.row, a.col, len);
                (max, line + worst_line(a))
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

/// The summed table of `f` over a `w × h` grid.
fn summed(w: usize, h: usize, f: impl Fn(usize, usize) -> f64) -> Vec<f64> {
    let mut table = vec![0f64; (w + 1) * (h + 1)];
    for r in 0..h {
        let mut row = 0.0;
        for c in 0..w {
            row += f(c, r);
            table[(r + 1) * (w + 1) + c + 1] = table[r * (w + 1) + c + 1] + row;
        }
    }
    table
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
