//! Resampling kernels: nearest, bilinear and bicubic (Catmull–Rom) evaluation of
//! a raster at fractional pixel coordinates (stage b of Figure 6.1, "Elevation
//! Data Resampling"; the dissertation asks for bilinear "to preserve a smooth
//! surface").
//!
//! Pixel coordinates are centre-based: `(0.0, 0.0)` is the centre of pixel
//! `(0, 0)`. Samples outside the source's valid [`Extent`] are NaN; inside it the
//! kernel taps are clamped to the edge pixels, or read across the seam of a
//! raster around the globe ([`Extent::wraps`]). NaN taps with a weight
//! (more than 10⁻⁶ of a step from the sample) make the sample NaN (nodata
//! propagates).

use super::mesh::Mesh;
use super::{Raster, Window, floor_i64};
use rayon::prelude::*;

/// How to interpolate between source pixels.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, serde::Deserialize, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Resampling {
    /// The nearest pixel; for classes and surface types (never interpolated).
    Nearest,
    /// Bilinear: continuous, never overshoots.
    #[default]
    Bilinear,
    /// Catmull–Rom bicubic: C¹, may overshoot by a few percent of a step.
    Bicubic,
}

impl Resampling {
    /// Kernel taps on each side of the sample (for window sizing).
    pub fn support(self) -> i64 {
        match self {
            Resampling::Nearest => 1,
            Resampling::Bilinear => 1,
            Resampling::Bicubic => 2,
        }
    }
}

/// Pixels a sample may lie past a source's edge and still read it: a
/// sample placed on the data's edge (a GetMap of the region's bounds) lands
/// a rounding error either side of it (1e-11 pixels at rmnp's 0.002°
/// pixels), and would otherwise be no data on one side.
pub const EDGE_SLACK: f64 = 1e-6;

/// The pixels of a source and the region of pixel coordinates that holds data
/// (for area pixels `-0.5 ..= n - 0.5`, for point-registered samples
/// `0 ..= n - 1`; overviews have fractional bounds).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Extent {
    /// Width of the full source in pixels (taps are clamped to it).
    pub width: usize,
    /// Height of the full source in pixels.
    pub height: usize,
    /// Smallest and largest column coordinate with data.
    pub x_range: (f64, f64),
    /// Smallest and largest row coordinate with data.
    pub y_range: (f64, f64),
    /// Whether columns repeat every `width` (a geographic raster around the
    /// globe): a tap past an edge reads the column a period away, which the
    /// window read holds (its columns read modulo the width).
    pub wraps: bool,
}

impl Extent {
    /// A source of `width × height` pixels whose data reaches `overhang`
    /// past its outer pixel centres, and [`EDGE_SLACK`] more.
    pub fn new(width: usize, height: usize, overhang: f64) -> Extent {
        let reach = overhang + EDGE_SLACK;
        Extent {
            width,
            height,
            x_range: (-reach, width as f64 - 1.0 + reach),
            y_range: (-reach, height as f64 - 1.0 + reach),
            wraps: false,
        }
    }

    /// The column a kernel tap at column `x` reads: past an edge the edge
    /// column, or where the raster wraps the column itself (its window holds
    /// the columns a period away there).
    #[inline]
    pub fn tap_x(&self, x: i64) -> i64 {
        match self.wraps {
            true => x,
            false => x.clamp(0, self.width as i64 - 1),
        }
    }

    /// True if `(px, py)` lies where the source has data.
    #[inline]
    pub fn contains(&self, px: f64, py: f64) -> bool {
        self.contains_x(px) && self.contains_y(py)
    }

    /// True if column coordinate `px` lies where the source has data.
    #[inline]
    pub fn contains_x(&self, px: f64) -> bool {
        px >= self.x_range.0 && px <= self.x_range.1
    }

    /// True if row coordinate `py` lies where the source has data.
    #[inline]
    pub fn contains_y(&self, py: f64) -> bool {
        py >= self.y_range.0 && py <= self.y_range.1
    }
}

/// Fractional source pixel coordinates of every output sample.
#[derive(Clone, Debug)]
pub enum PixelCoords {
    /// `px` depends only on the output column and `py` only on the row
    /// (sources in geographic coordinates, read on a lat/lon grid).
    Separable {
        /// Source x for each output column.
        x: Vec<f64>,
        /// Source y for each output row.
        y: Vec<f64>,
    },
    /// One coordinate pair per output sample, row-major.
    Dense {
        /// Output columns.
        width: usize,
        /// `(px, py)` per sample.
        xy: Vec<(f64, f64)>,
    },
    /// Interpolated on a projection mesh a row at a time when read (a grid's
    /// pairs would be 16 bytes per sample, written once and read twice).
    Mesh(Mesh),
}

impl PixelCoords {
    /// Every position moved by `d` pixels in x and in y.
    pub fn shifted(&self, d: f64) -> PixelCoords {
        match self {
            PixelCoords::Separable { x, y } => {
                PixelCoords::Separable { x: x.iter().map(|v| v + d).collect(), y: y.iter().map(|v| v + d).collect() }
            }
            PixelCoords::Dense { width, xy } => {
                PixelCoords::Dense { width: *width, xy: xy.iter().map(|&(x, y)| (x + d, y + d)).collect() }
            }
            PixelCoords::Mesh(mesh) => PixelCoords::Mesh(mesh.shifted(d)),
        }
    }

    /// Output width and height.
    pub fn shape(&self) -> (usize, usize) {
        match self {
            PixelCoords::Separable { x, y } => (x.len(), y.len()),
            PixelCoords::Dense { width, xy } => (*width, xy.len().checked_div(*width).unwrap_or(0)),
            PixelCoords::Mesh(mesh) => mesh.size(),
        }
    }

    /// The coordinates of output row `r`: stored ones, or computed into `buf`.
    pub fn row<'a>(&'a self, r: usize, buf: &'a mut Vec<(f64, f64)>) -> &'a [(f64, f64)] {
        match self {
            PixelCoords::Separable { x, y } => {
                buf.clear();
                buf.extend(x.iter().map(|&px| (px, y[r])));
                buf
            }
            PixelCoords::Dense { width, xy } => &xy[r * width..(r + 1) * width],
            PixelCoords::Mesh(mesh) => {
                buf.resize(mesh.size().0, (0.0, 0.0));
                mesh.row(r, buf);
                buf
            }
        }
    }

    /// The source pixels that `kind` reads for in-extent samples, clipped to the
    /// extent; `None` when no sample falls on the source.
    pub fn footprint(&self, extent: &Extent, kind: Resampling) -> Option<Window> {
        let (x0, y0, x1, y1) = match self {
            PixelCoords::Separable { x, y } => {
                let (x0, x1) = min_max(x.iter().copied().filter(|&v| extent.contains_x(v)))?;
                let (y0, y1) = min_max(y.iter().copied().filter(|&v| extent.contains_y(v)))?;
                (x0, y0, x1, y1)
            }
            PixelCoords::Dense { .. } => self.bounds_inside(extent)?,
            // The mesh's bounds clipped to the extent: a superset of the
            // in-extent samples' bounds, found from a sixteenth of the rows.
            PixelCoords::Mesh(mesh) => {
                let (x0, y0, x1, y1) = mesh.bounds()?;
                let (x0, x1) = (x0.max(extent.x_range.0), x1.min(extent.x_range.1));
                let (y0, y1) = (y0.max(extent.y_range.0), y1.min(extent.y_range.1));
                if x0 > x1 || y0 > y1 {
                    return None;
                }
                (x0, y0, x1, y1)
            }
        };
        let s = kind.support();
        let clamp_y = |v: i64| v.clamp(0, extent.height as i64 - 1);
        let (ax, ay) = (extent.tap_x(x0.floor() as i64 - s + 1), clamp_y(y0.floor() as i64 - s + 1));
        let (bx, by) = (extent.tap_x(x1.floor() as i64 + s), clamp_y(y1.floor() as i64 + s));
        Some(Window::new(ax, ay, (bx - ax + 1) as usize, (by - ay + 1) as usize))
    }

    /// Smallest and largest `px` and `py` of the samples inside `extent`.
    fn bounds_inside(&self, extent: &Extent) -> Option<(f64, f64, f64, f64)> {
        let mut buf = Vec::new();
        let mut b = (f64::MAX, f64::MAX, f64::MIN, f64::MIN);
        for r in 0..self.shape().1 {
            for &(px, py) in self.row(r, &mut buf).iter().filter(|&&(px, py)| extent.contains(px, py)) {
                b = (b.0.min(px), b.1.min(py), b.2.max(px), b.3.max(py));
            }
        }
        (b.0 <= b.2).then_some(b)
    }
}

fn min_max(values: impl Iterator<Item = f64>) -> Option<(f64, f64)> {
    values.fold(None, |acc, v| Some(acc.map_or((v, v), |(lo, hi): (f64, f64)| (lo.min(v), hi.max(v)))))
}

/// Evaluates `src` (which holds source pixels `window`) at every coordinate.
/// `window` must contain `coords.footprint(extent, kind)`.
pub fn resample(
    src: &Raster<f32>,
    window: Window,
    extent: &Extent,
    coords: &PixelCoords,
    kind: Resampling,
) -> Raster<f32> {
    let view = View { src, window, extent };
    match (kind, coords) {
        (Resampling::Bilinear, PixelCoords::Separable { x, y }) => view.bilinear_separable(x, y),
        (Resampling::Bilinear, _) => by_rows(coords, |xy, line| view.bilinear_row(xy, line)),
        (Resampling::Nearest, _) => by_rows(coords, per_sample(extent, |px, py| view.nearest(px, py))),
        (Resampling::Bicubic, _) => by_rows(coords, per_sample(extent, |px, py| view.bicubic(px, py))),
    }
}

/// The output rows in parallel, each from its row of coordinates; samples
/// the kernel leaves are NaN.
fn by_rows(coords: &PixelCoords, kernel: impl Fn(&[(f64, f64)], &mut [f32]) + Sync) -> Raster<f32> {
    let (w, h) = coords.shape();
    let mut out = Raster::filled(w, h, f32::NAN);
    out.data_mut().par_chunks_mut(w.max(1)).enumerate().for_each_init(Vec::new, |buf, (r, line)| {
        kernel(coords.row(r, buf), line);
    });
    out
}

/// A row kernel from a kernel of one in-extent sample.
fn per_sample(extent: &Extent, kernel: impl Fn(f64, f64) -> f32 + Sync) -> impl Fn(&[(f64, f64)], &mut [f32]) + Sync {
    move |xy, line| {
        for (o, &(px, py)) in line.iter_mut().zip(xy) {
            if extent.contains(px, py) {
                *o = kernel(px, py);
            }
        }
    }
}

/// Bilinear taps along one axis: the two clamped window indices and the
/// weight of the second, or `None` outside the extent.
fn taps(
    coords: &[f64],
    inside: impl Fn(f64) -> bool,
    clamp: impl Fn(i64) -> usize,
) -> Vec<Option<(usize, usize, f32)>> {
    coords
        .iter()
        .map(|&p| {
            let p0 = p.floor();
            inside(p).then(|| (clamp(p0 as i64), clamp(p0 as i64 + 1), (p - p0) as f32))
        })
        .collect()
}

/// Samples per run of the scattered bilinear kernel: a run inside the source
/// takes the fast path.
const RUN: usize = 64;

/// A source window seen in full-source pixel coordinates, with edge clamping.
struct View<'a> {
    src: &'a Raster<f32>,
    window: Window,
    extent: &'a Extent,
}

impl View<'_> {
    #[inline]
    fn tap(&self, x: i64, y: i64) -> f32 {
        let x = self.extent.tap_x(x) - self.window.x;
        let y = y.clamp(0, self.extent.height as i64 - 1) - self.window.y;
        self.src.get(x as usize, y as usize)
    }

    fn nearest(&self, px: f64, py: f64) -> f32 {
        self.tap(floor_i64(px + 0.5), floor_i64(py + 0.5))
    }

    /// Bilinear over a separable grid: taps computed once per row and
    /// column, the same arithmetic as [`View::bilinear`] (so both paths agree
    /// bitwise).
    fn bilinear_separable(&self, x: &[f64], y: &[f64]) -> Raster<f32> {
        let clamp_x = |i: i64| (self.extent.tap_x(i) - self.window.x) as usize;
        let clamp_y = |i: i64| (i.clamp(0, self.extent.height as i64 - 1) - self.window.y) as usize;
        let cols = taps(x, |p| self.extent.contains_x(p), clamp_x);
        let rows = taps(y, |p| self.extent.contains_y(p), clamp_y);
        let mut out = Raster::filled(x.len(), y.len(), f32::NAN);
        out.data_mut().par_chunks_mut(x.len().max(1)).zip(rows.par_iter()).for_each(|(line, row)| {
            let Some((y0, y1, fy)) = *row else { return };
            let (r0, r1) = (self.src.row(y0), self.src.row(y1));
            for (o, col) in line.iter_mut().zip(&cols) {
                if let Some((x0, x1, fx)) = *col {
                    let top = lerp(r0[x0], r0[x1], fx);
                    *o = lerp(top, lerp(r1[x0], r1[x1], fx), fy);
                }
            }
        });
        out
    }

    /// Bilinear at the scattered coordinates of one output row; the same
    /// arithmetic as the separable path. Every tap is read (the footprint
    /// holds them all). Runs of samples whose taps all lie inside the source
    /// take a kernel without extent tests or clamping.
    fn bilinear_row(&self, xy: &[(f64, f64)], line: &mut [f32]) {
        // Inside the extent, at or right of the first pixel and left of the
        // last (an overview's extent may end before its last pixel).
        let e = self.extent;
        let (x_lo, x_hi, x_last) = (e.x_range.0.max(0.0), e.x_range.1, (e.width - 1) as f64);
        let (y_lo, y_hi, y_last) = (e.y_range.0.max(0.0), e.y_range.1, (e.height - 1) as f64);
        let inside = |p: f64, lo: f64, hi: f64, last: f64| (p >= lo) & (p <= hi) & (p < last);
        // False for NaN coordinates, which the clamped kernel handles.
        let interior = |xy: &[(f64, f64)]| {
            xy.iter().fold(true, |ok, &(px, py)| ok & inside(px, x_lo, x_hi, x_last) & inside(py, y_lo, y_hi, y_last))
        };
        for (xy, line) in xy.chunks(RUN).zip(line.chunks_mut(RUN)) {
            match interior(xy) {
                true => self.bilinear_interior(xy, line),
                false => self.bilinear_clamped(xy, line),
            }
        }
    }

    /// [`View::bilinear_row`] on at most [`RUN`] samples where every sample
    /// and its taps are inside the source: `floor` is truncation and no tap
    /// is clamped. Three passes (positions to indices and weights, the
    /// gather, the blend) so that the first and last are vectorized.
    fn bilinear_interior(&self, xy: &[(f64, f64)], line: &mut [f32]) {
        let (stride, data) = (self.src.width(), self.src.data());
        // A wrapping source's window may start a column or two west of 0.
        let origin = (self.window.y as usize * stride).wrapping_add_signed(self.window.x as isize);
        let (mut index, mut fx, mut fy) = ([0usize; RUN], [0f32; RUN], [0f32; RUN]);
        let mut taps = [[0f32; 4]; RUN];
        let n = xy.len();
        for (i, &(px, py)) in xy.iter().enumerate() {
            let (x0, y0) = (px as u32, py as u32);
            fx[i] = (px - f64::from(x0)) as f32;
            fy[i] = (py - f64::from(y0)) as f32;
            index[i] = (y0 as usize * stride + x0 as usize).wrapping_sub(origin);
        }
        for (t, &top) in taps[..n].iter_mut().zip(&index[..n]) {
            let (r0, r1) = (&data[top..top + 2], &data[top + stride..top + stride + 2]);
            *t = [r0[0], r0[1], r1[0], r1[1]];
        }
        for (((o, t), &fx), &fy) in line.iter_mut().zip(&taps[..n]).zip(&fx[..n]).zip(&fy[..n]) {
            *o = lerp(lerp(t[0], t[1], fx), lerp(t[2], t[3], fx), fy);
        }
    }

    /// [`View::bilinear_row`] with extent tests and edge clamping.
    fn bilinear_clamped(&self, xy: &[(f64, f64)], line: &mut [f32]) {
        let h = self.extent.height as i64 - 1;
        let (ox, oy) = (self.window.x, self.window.y);
        let (stride, data) = (self.src.width(), self.src.data());
        for (o, &(px, py)) in line.iter_mut().zip(xy) {
            if !self.extent.contains(px, py) {
                continue;
            }
            let (x0, y0) = (floor_i64(px), floor_i64(py));
            let (fx, fy) = ((px - x0 as f64) as f32, (py - y0 as f64) as f32);
            let column = |x: i64| (self.extent.tap_x(x) - ox) as usize;
            let (xa, xb) = (column(x0), column(x0 + 1));
            let (ya, yb) = ((y0.clamp(0, h) - oy) as usize * stride, ((y0 + 1).clamp(0, h) - oy) as usize * stride);
            let top = lerp(data[ya + xa], data[ya + xb], fx);
            *o = lerp(top, lerp(data[yb + xa], data[yb + xb], fx), fy);
        }
    }

    fn bicubic(&self, px: f64, py: f64) -> f32 {
        let (x0, y0) = (px.floor(), py.floor());
        let wx = catmull_rom((px - x0) as f32);
        let wy = catmull_rom((py - y0) as f32);
        let (x0, y0) = (x0 as i64, y0 as i64);
        let mut sum = 0.0f32;
        for (j, &wyj) in wy.iter().enumerate() {
            let mut row = 0.0f32;
            for (i, &wxi) in wx.iter().enumerate() {
                if wxi != 0.0 {
                    row += wxi * self.tap(x0 - 1 + i as i64, y0 - 1 + j as i64);
                }
            }
            if wyj != 0.0 {
                sum += wyj * row;
            }
        }
        sum
    }
}

/// Fractions of a pixel this close to a pixel's centre count as on it: a
/// sample placed on a source pixel (a GetMap on the source's own grid) lands
/// a rounding error either side of it, and a nodata neighbour must not take
/// its value away. The most it moves a sample is 10⁻⁶ of a step.
const ON_PIXEL: f32 = 1e-6;

/// `a + t (b - a)`; `a` when `t` is within [`ON_PIXEL`] of 0 and `b` within
/// it of 1, whatever the other is, so that a NaN neighbour with no weight
/// does not poison a hit on a pixel. All are computed and one selected: no
/// branch in the kernels' loops.
#[inline]
fn lerp(a: f32, b: f32, t: f32) -> f32 {
    let v = a + t * (b - a);
    let v = if t >= 1.0 - ON_PIXEL { b } else { v };
    if t <= ON_PIXEL { a } else { v }
}

/// Catmull–Rom weights (Keys, a = −0.5) for taps at −1, 0, 1, 2; on a
/// pixel (within [`ON_PIXEL`]) that pixel's alone.
fn catmull_rom(t: f32) -> [f32; 4] {
    if t <= ON_PIXEL {
        return [0.0, 1.0, 0.0, 0.0];
    }
    if t >= 1.0 - ON_PIXEL {
        return [0.0, 0.0, 1.0, 0.0];
    }
    let (t2, t3) = (t * t, t * t * t);
    [0.5 * (-t3 + 2.0 * t2 - t), 0.5 * (3.0 * t3 - 5.0 * t2 + 2.0), 0.5 * (-3.0 * t3 + 4.0 * t2 + t), 0.5 * (t3 - t2)]
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ramp() -> Raster<f32> {
        Raster::from_fn(5, 4, |x, y| (2 * x + 3 * y) as f32)
    }

    fn eval(kind: Resampling, px: f64, py: f64) -> f32 {
        let src = ramp();
        let extent = Extent::new(5, 4, 0.5);
        let coords = PixelCoords::Dense { width: 1, xy: vec![(px, py)] };
        resample(&src, Window::new(0, 0, 5, 4), &extent, &coords, kind).get(0, 0)
    }

    #[test]
    fn linear_ramps_are_reproduced_exactly_inside() {
        for kind in [Resampling::Bilinear, Resampling::Bicubic] {
            assert!((eval(kind, 1.25, 1.5) - (2.5 + 4.5)).abs() < 1e-5, "{kind:?}");
        }
        assert_eq!(eval(Resampling::Nearest, 1.6, 0.4), 4.0);
    }

    #[test]
    fn outside_the_extent_is_nodata_and_the_overhang_clamps() {
        assert!(eval(Resampling::Bilinear, -0.6, 0.0).is_nan());
        assert_eq!(eval(Resampling::Bilinear, -0.5, 0.0), 0.0);
        assert_eq!(eval(Resampling::Bilinear, 4.5, 3.0), 8.0 + 9.0);
    }

    #[test]
    fn a_nodata_neighbour_with_zero_weight_does_not_spread() {
        let mut src = ramp();
        src.set(2, 1, f32::NAN);
        let extent = Extent::new(5, 4, 0.5);
        let exact = PixelCoords::Dense { width: 2, xy: vec![(1.0, 1.0), (1.5, 1.0)] };
        let out = resample(&src, Window::new(0, 0, 5, 4), &extent, &exact, Resampling::Bilinear);
        assert_eq!(out.get(0, 0), 5.0);
        assert!(out.get(1, 0).is_nan());
    }

    #[test]
    fn a_sample_a_rounding_error_off_a_pixel_beside_nodata_keeps_its_value() {
        // Regression: a GetMap on the source's own grid lost the valid pixels
        // on either side of a void (their neighbour in the void had a weight
        // of 1e-11 or so).
        let mut src = ramp();
        src.set(2, 1, f32::NAN);
        let extent = Extent::new(5, 4, 0.5);
        let near = vec![(1.0 + 1e-9, 1.0), (3.0 - 1e-9, 1.0), (1.0, 2.0 - 1e-9), (1.5, 1.0)];
        for kind in [Resampling::Bilinear, Resampling::Bicubic] {
            let coords = PixelCoords::Dense { width: 4, xy: near.clone() };
            let out = resample(&src, Window::new(0, 0, 5, 4), &extent, &coords, kind);
            assert_eq!([out.get(0, 0), out.get(1, 0), out.get(2, 0)], [5.0, 9.0, 8.0], "{kind:?}");
            assert!(out.get(3, 0).is_nan(), "{kind:?}: half a pixel from the void");
        }
        // The separable path: the same.
        let coords = PixelCoords::Separable { x: vec![1.0 + 1e-9, 3.0 - 1e-9], y: vec![1.0 - 1e-9] };
        let out = resample(&src, Window::new(0, 0, 5, 4), &extent, &coords, Resampling::Bilinear);
        assert_eq!([out.get(0, 0), out.get(1, 0)], [5.0, 9.0]);
    }

    #[test]
    fn footprint_covers_the_kernel_support_and_clips_to_the_source() {
        let extent = Extent::new(100, 100, 0.5);
        let coords = PixelCoords::Separable { x: vec![10.2, 20.7], y: vec![5.5, -3.0] };
        let win = coords.footprint(&extent, Resampling::Bicubic).unwrap();
        assert_eq!(win, Window::new(9, 4, 14, 4));
        let none = PixelCoords::Separable { x: vec![-5.0], y: vec![1.0] };
        assert_eq!(none.footprint(&extent, Resampling::Bilinear), None);
    }

    proptest::proptest! {
        /// The scattered-row kernel (runs inside the source and runs at its
        /// edges) agrees bitwise with the separable one, NaN pixels, the
        /// overhang and an overview's short extent included.
        #[test]
        fn scattered_rows_equal_the_separable_path(
            x0 in -3.0f64..10.0, dx in 0.05f64..0.9, y0 in -3.0f64..6.0, dy in 0.05f64..0.9,
            nan_at in 0usize..240, short in 0.0f64..0.9,
        ) {
            let mut src = Raster::from_fn(20, 12, |x, y| ((x * 7 + y * 13) % 11) as f32 * 1.5 - y as f32);
            src.set(nan_at % 20, nan_at / 20, f32::NAN);
            let extent =
                Extent { width: 20, height: 12, x_range: (-0.5, 19.0 - short), y_range: (-0.5, 11.5), wraps: false };
            let x: Vec<f64> = (0..150).map(|i| x0 + dx * i as f64).collect();
            let y: Vec<f64> = (0..9).map(|j| y0 + dy * j as f64).collect();
            let xy = y.iter().flat_map(|&py| x.iter().map(move |&px| (px, py))).collect();
            let dense = PixelCoords::Dense { width: x.len(), xy };
            let separable = PixelCoords::Separable { x, y };
            let window = Window::new(0, 0, 20, 12);
            let a = resample(&src, window, &extent, &separable, Resampling::Bilinear);
            let b = resample(&src, window, &extent, &dense, Resampling::Bilinear);
            let bits = |r: &Raster<f32>| r.data().iter().map(|v| v.to_bits()).collect::<Vec<_>>();
            proptest::prop_assert_eq!(bits(&a), bits(&b));
        }
    }
}
