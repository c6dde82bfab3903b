//! Positions interpolated on a mesh of control points: the pixel coordinates
//! of a projected source on a lat/lon grid, projected exactly every `m`
//! lattice samples and interpolated bilinearly between (the projection mesh
//! of `source::georaster`).
//!
//! Control points sit at global lattice indices that are multiples of `m`,
//! and a sample's position depends only on its global lattice index and the
//! control points around it, so every grid that holds a sample gives it the
//! same position, bit for bit. Positions are computed a row at a time when
//! they are read, never stored for a whole grid. Around the globe, control
//! points' x are first made continuous across the seam ([`unwrap_rows`]):
//! a grid across it may place a shared sample a whole period (and a
//! rounding) away from another grid, the same pixel read modulo the period.

/// Control points every `m` lattice samples over a grid of `width × height`
/// samples whose first sample has global lattice index `first`.
#[derive(Clone, Debug)]
pub struct Mesh {
    m: i64,
    first: (i64, i64),
    size: (usize, usize),
    /// Global mesh index of the first control column and row.
    k0: (i64, i64),
    cols: usize,
    points: Vec<(f64, f64)>,
}

impl Mesh {
    /// A mesh of step `m` (a power of two) over `size` samples from global
    /// lattice index `first`; `point(c, r)` is the exact position at grid
    /// offset `(c, r)` (which may lie outside the grid).
    pub fn new(m: i64, first: (i64, i64), size: (usize, usize), point: impl Fn(i64, i64) -> (f64, f64)) -> Mesh {
        debug_assert!(m > 0 && m & (m - 1) == 0, "mesh step {m} is not a power of two");
        let last = |first: i64, len: usize| first + len as i64 - 1;
        let kx0 = first.0.div_euclid(m);
        let kx1 = last(first.0, size.0).div_euclid(m) + 1;
        let ky0 = first.1.div_euclid(m);
        let ky1 = last(first.1, size.1).div_euclid(m) + 1;
        let cols = (kx1 - kx0 + 1) as usize;
        let mut points = Vec::with_capacity(cols * (ky1 - ky0 + 1) as usize);
        for ky in ky0..=ky1 {
            for kx in kx0..=kx1 {
                points.push(point(kx * m - first.0, ky * m - first.1));
            }
        }
        Mesh { m, first, size, k0: (kx0, ky0), cols, points }
    }

    /// Makes the control points' x continuous where x repeats every
    /// `period` (a source around the globe; [`unwrap_rows`]).
    pub fn unwrap_x(&mut self, period: f64) {
        unwrap_rows(&mut self.points, self.cols, period);
    }

    /// The mesh with every position moved by `d` in x and in y.
    pub fn shifted(&self, d: f64) -> Mesh {
        let points = self.points.iter().map(|&(x, y)| (x + d, y + d)).collect();
        Mesh { m: self.m, first: self.first, size: self.size, k0: self.k0, cols: self.cols, points }
    }

    /// Width and height of the grid in samples.
    pub fn size(&self) -> (usize, usize) {
        self.size
    }

    /// True when every control point is finite (so is every position).
    pub fn is_finite(&self) -> bool {
        self.points.iter().all(|p| p.0.is_finite() && p.1.is_finite())
    }

    /// The smallest and largest x and y of every position on the grid:
    /// `(x0, y0, x1, y1)`, NaN positions ignored, `None` if all are NaN.
    /// Positions in a mesh cell are bilinear in the sample index, so the
    /// extremes over the part of a cell inside the grid lie at that part's
    /// corners, which are on the grid's first and last rows or on control
    /// rows: only those rows are evaluated.
    pub fn bounds(&self) -> Option<(f64, f64, f64, f64)> {
        let (w, h) = self.size;
        let on_control_line = |r: &usize| (self.first.1 + *r as i64) & (self.m - 1) == 0;
        let rows = (0..h).filter(|r| *r == 0 || *r + 1 == h || on_control_line(r));
        let mut line = vec![(0.0, 0.0); w];
        let mut b = (f64::MAX, f64::MAX, f64::MIN, f64::MIN);
        for r in rows {
            self.row(r, &mut line);
            for &(x, y) in line.iter().filter(|p| !p.0.is_nan() && !p.1.is_nan()) {
                b = (b.0.min(x), b.1.min(y), b.2.max(x), b.3.max(y));
            }
        }
        (b.0 <= b.2).then_some(b)
    }

    /// Interpolated positions of row `r`'s samples into `out` (one per
    /// column; NaN where a corner is NaN): first between the control rows
    /// above and below, then along the row.
    pub fn row(&self, r: usize, out: &mut [(f64, f64)]) {
        // m is a power of two: shifts and masks are floor division and
        // remainder, and k / m is exact as k · (1/m).
        let shift = self.m.trailing_zeros();
        let inv = 1.0 / self.m as f64;
        let gy = self.first.1 + r as i64;
        let u = (gy & (self.m - 1)) as f64 * inv;
        let top = ((gy >> shift) - self.k0.1) as usize * self.cols;
        let (upper, lower) = (&self.points[top..top + self.cols], &self.points[top + self.cols..top + 2 * self.cols]);
        let column = upper.iter().zip(lower).map(|(a, c)| (lerp(a.0, c.0, u), lerp(a.1, c.1, u)));
        // Samples between two control columns: from the first sample's
        // offset in its cell to the cell's end, then whole cells.
        let mut cells = column.clone().zip(column.skip(1));
        let mut t0 = self.first.0 & (self.m - 1);
        let mut rest = out;
        while !rest.is_empty() {
            let Some((a, b)) = cells.next() else { break };
            let n = ((self.m - t0) as usize).min(rest.len());
            let (cell, tail) = rest.split_at_mut(n);
            for (i, o) in cell.iter_mut().enumerate() {
                let t = (t0 + i as i64) as f64 * inv;
                *o = (lerp(a.0, b.0, t), lerp(a.1, b.1, t));
            }
            (rest, t0) = (tail, 0);
        }
    }
}

#[inline]
fn lerp(a: f64, b: f64, t: f64) -> f64 {
    (1.0 - t) * a + t * b
}

/// Makes the x of `points`, rows of `cols`, continuous where x repeats
/// every `period`: down the first column, then along each row
/// ([`unwrap_periodic`]).
pub fn unwrap_rows(points: &mut [(f64, f64)], cols: usize, period: f64) {
    unwrap_periodic(points.iter_mut().step_by(cols.max(1)).map(|p| &mut p.0), period);
    for row in points.chunks_mut(cols.max(1)) {
        unwrap_periodic(row.iter_mut().map(|p| &mut p.0), period);
    }
}

/// Values that repeat every `period` made continuous, each moved by whole
/// periods to within half a period of the last finite one before it (NaN
/// skipped): a grid across the seam of a source around the globe then reads
/// the columns either side of it, not every column between.
pub fn unwrap_periodic<'a>(values: impl Iterator<Item = &'a mut f64>, period: f64) {
    let mut last: Option<f64> = None;
    for x in values {
        if let Some(to) = last {
            let turns = ((*x - to) / period).round();
            if turns.is_finite() {
                *x -= turns * period;
            }
        }
        if x.is_finite() {
            last = Some(*x);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn affine_positions_are_reproduced_and_independent_of_the_grid() {
        let exact = |gx: i64, gy: i64| (0.5 * gx as f64 + 3.0, -0.25 * gy as f64 + 0.125 * gx as f64);
        let big = Mesh::new(8, (-13, 5), (40, 30), |c, r| exact(c - 13, r + 5));
        let small = Mesh::new(8, (-2, 11), (7, 4), |c, r| exact(c - 2, r + 11));
        let (mut a, mut b) = (vec![(0.0, 0.0); 40], vec![(0.0, 0.0); 7]);
        for r in 0..4 {
            big.row(r + 6, &mut a);
            small.row(r, &mut b);
            assert_eq!(&a[11..18], &b[..], "row {r}");
            for (c, p) in b.iter().enumerate() {
                assert_eq!(*p, exact(c as i64 - 2, r as i64 + 11));
            }
        }
        assert!(big.is_finite());
        assert!(!Mesh::new(4, (0, 0), (3, 3), |c, _| (if c > 0 { f64::NAN } else { 0.0 }, 0.0)).is_finite());
    }

    #[test]
    fn bounds_are_those_of_every_position() {
        // A curved mapping, a grid starting and ending inside mesh cells.
        let warp = |gx: i64, gy: i64| {
            let (x, y) = (gx as f64, gy as f64);
            (x + 0.02 * y * y - 0.3 * (0.2 * x).sin() * y, y - 0.01 * x * x + (0.1 * y).cos() * x)
        };
        for (first, size) in [((-13, 5), (40, 30)), ((3, -7), (5, 33)), ((0, 0), (17, 1))] {
            let mesh = Mesh::new(8, first, size, |c, r| warp(c + first.0, r + first.1));
            let mut line = vec![(0.0, 0.0); size.0];
            let mut hull = (f64::MAX, f64::MAX, f64::MIN, f64::MIN);
            for r in 0..size.1 {
                mesh.row(r, &mut line);
                for &(x, y) in &line {
                    hull = (hull.0.min(x), hull.1.min(y), hull.2.max(x), hull.3.max(y));
                }
            }
            assert_eq!(mesh.bounds(), Some(hull), "grid from {first:?}, {size:?}");
        }
    }
}
