//! The metric grid of a canopy height model: square cells, north up, in the
//! point cloud's projected CRS (dissertation 6.6: "converted to an elevation
//! map with 0.5m resolution").
//!
//! Invariant: cell `(col, row)` covers `x ∈ [x0 + col·c, x0 + (col+1)·c)` and
//! `y ∈ (y0 − (row+1)·c, y0 − row·c]`; grids made by [`MetricGrid::covering`]
//! have their edges on multiples of the cell size, so clouds covering
//! neighbouring areas give grids whose cells line up.

/// Most cells a grid may have (1 GiB of `f32`).
pub const MAX_CELLS: usize = 1 << 28;

/// A north-up grid of square cells.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MetricGrid {
    /// West edge, metres.
    pub x0: f64,
    /// North edge, metres.
    pub y0: f64,
    /// Cell side, metres.
    pub cell_m: f64,
    /// Columns.
    pub width: usize,
    /// Rows.
    pub height: usize,
}

impl MetricGrid {
    /// The grid of `cell_m` cells on multiples of `cell_m` that covers the box
    /// `[x_min, x_max] × [y_min, y_max]`; an error when the cell size is not
    /// positive or the grid would be too large.
    pub fn covering(x_min: f64, x_max: f64, y_min: f64, y_max: f64, cell_m: f64) -> Result<MetricGrid, String> {
        if !(cell_m > 0.0 && cell_m.is_finite()) {
            return Err(format!("the cell size must be a positive number of metres, got {cell_m}"));
        }
        if !(x_min <= x_max && y_min <= y_max && x_min.is_finite() && y_max.is_finite()) {
            return Err("the points have no finite extent".into());
        }
        let x0 = (x_min / cell_m).floor() * cell_m;
        let y0 = (y_max / cell_m).floor() * cell_m + cell_m;
        let width = ((x_max - x0) / cell_m).floor() as usize + 1;
        let height = ((y0 - y_min) / cell_m).ceil().max(1.0) as usize;
        let grid = MetricGrid { x0, y0, cell_m, width, height };
        grid.check()?;
        Ok(grid)
    }

    /// An error when the grid is empty or larger than [`MAX_CELLS`].
    pub fn check(&self) -> Result<(), String> {
        match self.width.checked_mul(self.height) {
            Some(n) if n > 0 && n <= MAX_CELLS => Ok(()),
            _ => Err(format!(
                "a {}×{} grid of {} m cells is empty or larger than {MAX_CELLS} cells; use a coarser resolution",
                self.width, self.height, self.cell_m
            )),
        }
    }

    /// The cell holding `(x, y)`, if inside.
    #[inline]
    pub fn cell_of(&self, x: f64, y: f64) -> Option<(usize, usize)> {
        let col = ((x - self.x0) / self.cell_m).floor();
        let row = ((self.y0 - y) / self.cell_m).floor();
        let inside = col >= 0.0 && row >= 0.0 && (col as usize) < self.width && (row as usize) < self.height;
        inside.then_some((col as usize, row as usize))
    }

    /// The centre of cell `(col, row)`.
    pub fn centre(&self, col: usize, row: usize) -> (f64, f64) {
        (self.x0 + (col as f64 + 0.5) * self.cell_m, self.y0 - (row as f64 + 0.5) * self.cell_m)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn covering_grids_snap_to_the_cell_size_and_hold_every_point() {
        let g = MetricGrid::covering(100.2, 110.0, 50.1, 60.0, 0.5).unwrap();
        assert_eq!((g.x0, g.y0), (100.0, 60.5));
        for (x, y) in [(100.2, 50.1), (110.0, 60.0), (105.0, 55.0)] {
            assert!(g.cell_of(x, y).is_some(), "{x} {y}");
        }
        assert_eq!(g.cell_of(99.99, 55.0), None);
        assert_eq!(g.cell_of(100.0, 60.5), Some((0, 0)));
        assert!(MetricGrid::covering(0.0, 1e7, 0.0, 1e7, 0.1).is_err());
        assert!(MetricGrid::covering(0.0, 1.0, 0.0, 1.0, 0.0).is_err());
    }
}
