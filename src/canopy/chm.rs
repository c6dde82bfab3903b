//! A canopy height model (CHM) from a point cloud: the highest return above
//! ground in every cell (dissertation 6.6: the LiDAR scan "converted to an
//! elevation map with 0.5m resolution").
//!
//! Steps: noise and isolated points are dropped ([`super::outliers`]);
//! heights above ground are the points' z when the cloud is normalised, else z
//! minus the ground TIN ([`super::ground`]); each cell takes the highest
//! height that falls in it (negative heights count as 0); empty cells within
//! [`ChmOptions::fill_max_m`] of data are filled, pass by pass, with the mean
//! of their filled 8-neighbours, so gaps between returns close and the area
//! outside the scan stays nodata (NaN).
//!
//! Invariant: no smoothing and no pit filling, so a cell's height is a height
//! that was measured there, or (voids) an average of its neighbours.

use super::grid::MetricGrid;
use super::ground::{self, GROUND_CLASS, Ground};
use super::outliers::{self, Dropped};
use crate::raster::Raster;
use crate::source::las::PointCloud;
use thiserror::Error;

/// How a CHM is made.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ChmOptions {
    /// Cell side, metres.
    pub cell_m: f64,
    /// Empty cells farther than this from any return stay nodata, metres.
    pub fill_max_m: f64,
}

impl Default for ChmOptions {
    fn default() -> Self {
        // 0.5 m as the dissertation's proxy; voids up to 5 m from data are
        // gaps between returns (a 0.5 pt/m² cloud leaves 1.4 m between them),
        // farther ones are outside the scan.
        ChmOptions { cell_m: crate::lidar::DEFAULT_CELL_M, fill_max_m: 5.0 }
    }
}

/// Why a cloud gives no CHM.
#[derive(Debug, Error, PartialEq)]
pub enum ChmError {
    /// Heights are elevations and there is nothing to subtract.
    #[error(
        "z is elevation, not height above ground (the cloud is not normalised), and there are no ground returns (class 2) to build a ground model from"
    )]
    NoGround,
    /// Every point was noise or outside the ground model.
    #[error("no points are left after removing noise ({0})")]
    NoPoints(Dropped),
    /// The grid is unusable.
    #[error("{0}")]
    Grid(String),
    /// The cells are far finer than the points are dense: most would be
    /// empty, filled by interpolation passes that grow with the fineness.
    #[error(
        "{cells} cells of {cell_m} m for {points} points would leave most cells empty; use a resolution of {coarser:.2} m or coarser (about one point per cell)"
    )]
    TooFine {
        /// The grid's cells.
        cells: usize,
        /// Their side, metres.
        cell_m: f64,
        /// Points in the grid.
        points: usize,
        /// A cell side with about one point per cell, metres.
        coarser: f64,
    },
}

/// Most cells per point over the cloud's box: a CHM of airborne LiDAR (a
/// few points per m²) has about one per cell at the usual 0.5 m; far
/// beyond that the cells are mostly interpolated, at a cost that grows with
/// their number (the box may be mostly empty: a corridor, two plots apart).
const MAX_CELLS_PER_POINT: usize = 64;

/// A canopy height model and how it was made.
#[derive(Clone, Debug)]
pub struct Chm {
    /// Where the cells are.
    pub grid: MetricGrid,
    /// Height above ground, metres; NaN outside the scan.
    pub heights: Raster<f32>,
    /// The ground model at the cell centres (clouds that were not
    /// normalised); NaN outside the ground returns' hull.
    pub ground: Option<Raster<f32>>,
    /// Whether z was already height above ground.
    pub normalised: bool,
    /// Points dropped as noise.
    pub dropped: Dropped,
    /// Points outside the ground model's hull (not normalised clouds).
    pub off_ground: usize,
    /// Points that made the CHM.
    pub points: usize,
    /// Empty cells that were filled.
    pub filled: usize,
}

impl Chm {
    /// Where most cells had no point of their own and were filled: a
    /// cell side with about one point per cell, metres (to warn of a CHM
    /// that is mostly interpolated, short of [`ChmError::TooFine`]).
    pub fn mostly_filled(&self) -> Option<f64> {
        let cells = self.grid.width * self.grid.height;
        (2 * self.filled > cells && self.points > 0)
            .then(|| self.grid.cell_m * (cells as f64 / self.points as f64).sqrt())
    }
}

/// The CHM of `cloud` on `grid`, or on the grid of `options.cell_m` cells
/// that covers the cloud.
pub fn build(cloud: &PointCloud, grid: Option<MetricGrid>, options: &ChmOptions) -> Result<Chm, ChmError> {
    let (x, y, z) = (&cloud.x, &cloud.y, &cloud.z);
    let (keep, dropped) = outliers::keep(x, y, z, &cloud.class);
    let kept: Vec<usize> = (0..z.len()).filter(|&i| keep[i]).collect();
    if kept.is_empty() {
        return Err(ChmError::NoPoints(dropped));
    }
    let ground_idx: Vec<usize> = kept.iter().copied().filter(|&i| cloud.class[i] == GROUND_CLASS).collect();
    let ground_z: Vec<f64> = ground_idx.iter().map(|&i| z[i]).collect();
    let kept_z: Vec<f64> = kept.iter().map(|&i| z[i]).collect();
    let normalised = ground::is_normalised(&ground_z, &kept_z).ok_or(ChmError::NoGround)?;
    let model = match normalised {
        true => None,
        false => Some(Ground::new(x, y, z, &ground_idx).ok_or(ChmError::NoGround)?),
    };
    let heights: Vec<(usize, f64)> = kept
        .iter()
        .filter_map(|&i| match &model {
            Some(g) => g.height(x[i], y[i]).map(|h| (i, z[i] - h)),
            None => Some((i, z[i])),
        })
        .collect();
    if heights.is_empty() {
        return Err(ChmError::NoPoints(dropped));
    }
    let grid = match grid {
        Some(g) => g.check().map(|_| g),
        None => covering(x, y, &heights, options.cell_m),
    }
    .map_err(ChmError::Grid)?;
    dense_enough(&grid, heights.len())?;
    let mut raster = highest(&grid, x, y, &heights);
    let filled = fill_voids(&mut raster, (options.fill_max_m / grid.cell_m).ceil() as usize);
    let ground = model.map(|g| {
        Raster::from_fn(grid.width, grid.height, |c, r| {
            let (cx, cy) = grid.centre(c, r);
            g.height(cx, cy).map_or(f32::NAN, |h| h as f32)
        })
    });
    Ok(Chm {
        grid,
        heights: raster,
        ground,
        normalised,
        dropped,
        off_ground: kept.len() - heights.len(),
        points: heights.len(),
        filled,
    })
}

/// An error when `grid` has more than [`MAX_CELLS_PER_POINT`] cells per
/// point.
fn dense_enough(grid: &MetricGrid, points: usize) -> Result<(), ChmError> {
    let cells = grid.width * grid.height;
    match cells <= points.saturating_mul(MAX_CELLS_PER_POINT) {
        true => Ok(()),
        false => Err(ChmError::TooFine {
            cells,
            cell_m: grid.cell_m,
            points,
            coarser: grid.cell_m * (cells as f64 / points as f64).sqrt(),
        }),
    }
}

fn covering(x: &[f64], y: &[f64], points: &[(usize, f64)], cell_m: f64) -> Result<MetricGrid, String> {
    let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for &(i, _) in points {
        (x0, x1, y0, y1) = (x0.min(x[i]), x1.max(x[i]), y0.min(y[i]), y1.max(y[i]));
    }
    MetricGrid::covering(x0, x1, y0, y1, cell_m)
}

/// The highest height per cell (at least 0); NaN where no point fell.
fn highest(grid: &MetricGrid, x: &[f64], y: &[f64], heights: &[(usize, f64)]) -> Raster<f32> {
    let mut r = Raster::filled(grid.width, grid.height, f32::NEG_INFINITY);
    for &(i, h) in heights {
        if let Some((c, row)) = grid.cell_of(x[i], y[i]) {
            let v = r.get(c, row).max(h as f32);
            r.set(c, row, v);
        }
    }
    r.data_mut().iter_mut().for_each(|v| *v = if *v == f32::NEG_INFINITY { f32::NAN } else { v.max(0.0) });
    r
}

/// Fills NaN cells with the mean of their valid 8-neighbours, `passes` times
/// (each pass reads the previous one's values, so the result does not depend
/// on the scan order); returns how many cells were filled.
pub fn fill_voids(r: &mut Raster<f32>, passes: usize) -> usize {
    let (w, h) = (r.width(), r.height());
    let mut filled = 0;
    for _ in 0..passes {
        let mut updates = Vec::new();
        for row in 0..h {
            for col in (0..w).filter(|&c| r.get(c, row).is_nan()) {
                let (mut sum, mut n) = (0.0f64, 0u32);
                for (dc, dr) in NEIGHBOURS {
                    let (c, rr) = (col as i64 + dc, row as i64 + dr);
                    if c >= 0 && rr >= 0 && (c as usize) < w && (rr as usize) < h {
                        let v = r.get(c as usize, rr as usize);
                        if !v.is_nan() {
                            sum += f64::from(v);
                            n += 1;
                        }
                    }
                }
                if n > 0 {
                    updates.push((col, row, (sum / f64::from(n)) as f32));
                }
            }
        }
        if updates.is_empty() {
            break;
        }
        filled += updates.len();
        for (c, row, v) in updates {
            r.set(c, row, v);
        }
    }
    filled
}

/// Cells more than `depth_m` below the median of their valid 8-neighbours,
/// set to that median (one pass, reading the input only). Pits are cells
/// where only a lower return fell between crowns' returns — at 0.5 m and
/// 10 points per m² a tenth of the cells — speckle of the sampling rather
/// than gaps in the canopy (Ben-Arie et al. 2009 fill them the same way).
pub fn fill_pits(r: &Raster<f32>, depth_m: f32) -> Raster<f32> {
    let (w, h) = (r.width(), r.height());
    Raster::from_fn(w, h, |col, row| {
        let v = r.get(col, row);
        let mut around: Vec<f32> = NEIGHBOURS
            .iter()
            .map(|&(dc, dr)| (col as i64 + dc, row as i64 + dr))
            .filter(|&(c, rr)| c >= 0 && rr >= 0 && (c as usize) < w && (rr as usize) < h)
            .map(|(c, rr)| r.get(c as usize, rr as usize))
            .filter(|x| !x.is_nan())
            .collect();
        if v.is_nan() || around.len() < 3 {
            return v;
        }
        let mid = around.len() / 2;
        let median = *around.select_nth_unstable_by(mid, f32::total_cmp).1;
        if v < median - depth_m { median } else { v }
    })
}

/// The 8-neighbourhood.
const NEIGHBOURS: [(i64, i64); 8] = [(-1, -1), (0, -1), (1, -1), (-1, 0), (1, 0), (-1, 1), (0, 1), (1, 1)];

#[cfg(test)]
mod tests {
    use super::*;

    fn cloud(points: &[(f64, f64, f64, u8)]) -> PointCloud {
        PointCloud {
            x: points.iter().map(|p| p.0).collect(),
            y: points.iter().map(|p| p.1).collect(),
            z: points.iter().map(|p| p.2).collect(),
            class: points.iter().map(|p| p.3).collect(),
            epsg: 2193,
            files: vec!["test.laz".into()],
        }
    }

    /// A 20 × 20 m stand: ground returns every metre on a slope, canopy
    /// returns 15 m above it.
    fn stand(normalised: bool) -> PointCloud {
        let mut pts = Vec::new();
        for i in 0..400 {
            let (x, y) = (100.25 + (i % 20) as f64, 200.25 + (i / 20) as f64);
            let g = |x: f64| if normalised { 0.0 } else { 500.0 + 0.5 * x };
            pts.push((x, y, g(x), 2));
            pts.push((x + 0.25, y, g(x + 0.25) + 15.0, 1));
        }
        cloud(&pts)
    }

    #[test]
    fn heights_are_above_the_ground_model_or_taken_as_they_are() {
        for normalised in [true, false] {
            let chm = build(&stand(normalised), None, &ChmOptions { cell_m: 1.0, fill_max_m: 0.0 }).unwrap();
            assert_eq!(chm.normalised, normalised);
            assert_eq!((chm.grid.width, chm.grid.height), (20, 20));
            let inner: Vec<f32> =
                (1..19).flat_map(|r| (0..19).map(move |c| (c, r))).map(|(c, r)| chm.heights.get(c, r)).collect();
            assert!(inner.iter().all(|&h| (h - 15.0).abs() < 1e-3), "{inner:?}");
            assert_eq!(chm.ground.is_some(), !normalised);
        }
    }

    #[test]
    fn cells_far_finer_than_the_points_are_refused_naming_a_resolution() {
        // Regression: 0.01 m cells for a plot of airborne LiDAR ran for
        // minutes at 5 GB, filling empty cells pass after pass.
        // The stand: 800 points over 20 × 20 m, one per 0.7 m square.
        let options = |cell_m| ChmOptions { cell_m, fill_max_m: 5.0 };
        let Err(err) = build(&stand(true), None, &options(0.05)) else { panic!("0.05 m cells were accepted") };
        let ChmError::TooFine { coarser, .. } = err else { panic!("{err}") };
        assert!((0.65..0.75).contains(&coarser), "about one point per cell: {coarser}");
        assert!(err.to_string().contains(&format!("use a resolution of {coarser:.2} m")), "{err}");
        let fine = build(&stand(true), None, &options(0.1)).expect("47 cells per point");
        let coarser = fine.mostly_filled().expect("mostly filled: a warning");
        assert!((0.65..0.75).contains(&coarser), "about one point per cell: {coarser}");
        assert_eq!(build(&stand(true), None, &options(1.0)).unwrap().mostly_filled(), None);
    }

    #[test]
    fn elevations_without_ground_returns_are_refused() {
        let mut c = stand(false);
        c.class.iter_mut().for_each(|k| *k = 1);
        assert_eq!(build(&c, None, &ChmOptions::default()).unwrap_err(), ChmError::NoGround);
    }

    #[test]
    fn voids_near_data_are_filled_and_far_ones_stay_nodata() {
        let mut r = Raster::from_fn(7, 1, |x, _| if x == 0 { 10.0 } else { f32::NAN });
        r.set(2, 0, 20.0);
        assert_eq!(fill_voids(&mut r, 2), 3);
        assert_eq!(&r.data()[..5], &[10.0, 15.0, 20.0, 20.0, 20.0]);
        assert!(r.get(5, 0).is_nan() && r.get(6, 0).is_nan());
    }

    #[test]
    fn pits_are_filled_and_gaps_stay() {
        // A one-cell pit in a 20 m canopy, and a 3-cell-wide gap.
        let r = Raster::from_fn(9, 5, |x, y| if (x, y) == (2, 2) || (5..8).contains(&x) { 0.0 } else { 20.0 });
        let f = fill_pits(&r, 2.0);
        assert_eq!(f.get(2, 2), 20.0);
        assert_eq!((f.get(6, 2), f.get(5, 2)), (0.0, 0.0));
    }
}
