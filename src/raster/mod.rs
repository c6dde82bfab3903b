//! In-memory rasters and the pure kernels that work on them.
//!
//! A [`Raster<T>`] is a row-major grid, row 0 at the north edge. Inside the
//! library `f32` rasters mark nodata with NaN; no kernel here turns valid input
//! into NaN.
//!
//! Invariant: nothing in `raster` does I/O or knows about coordinates; every
//! kernel is deterministic per output sample (the same inputs in the same order),
//! so a window computed inside a larger buffer is bitwise equal to the same
//! window computed alone with enough margin. The seamless-tile property rests on
//! this.

pub mod blur;
pub mod mesh;
pub mod morphology;
pub mod resample;

/// A rectangle of pixels: columns `x .. x + width`, rows `y .. y + height`.
/// The origin may be negative (a window reaching past a raster's edge).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Window {
    /// First column.
    pub x: i64,
    /// First row.
    pub y: i64,
    /// Number of columns.
    pub width: usize,
    /// Number of rows.
    pub height: usize,
}

impl Window {
    /// A window from its origin and size.
    pub fn new(x: i64, y: i64, width: usize, height: usize) -> Self {
        Window { x, y, width, height }
    }

    /// The same window grown by `margin` pixels on every side.
    pub fn grown(self, margin: usize) -> Self {
        let m = margin as i64;
        Window::new(self.x - m, self.y - m, self.width + 2 * margin, self.height + 2 * margin)
    }

    /// One past the last column.
    pub fn x_end(&self) -> i64 {
        self.x + self.width as i64
    }

    /// One past the last row.
    pub fn y_end(&self) -> i64 {
        self.y + self.height as i64
    }

    /// The overlap of two windows, if any.
    pub fn intersect(&self, other: &Window) -> Option<Window> {
        let x0 = self.x.max(other.x);
        let y0 = self.y.max(other.y);
        let x1 = self.x_end().min(other.x_end());
        let y1 = self.y_end().min(other.y_end());
        (x1 > x0 && y1 > y0).then(|| Window::new(x0, y0, (x1 - x0) as usize, (y1 - y0) as usize))
    }

    /// Number of pixels.
    pub fn area(&self) -> usize {
        self.width * self.height
    }
}

/// A row-major grid of samples, row 0 at the north.
#[derive(Clone, Debug, PartialEq)]
pub struct Raster<T> {
    width: usize,
    height: usize,
    data: Vec<T>,
}

impl<T: Copy> Raster<T> {
    /// A raster filled with one value.
    pub fn filled(width: usize, height: usize, value: T) -> Self {
        Raster { width, height, data: vec![value; width * height] }
    }

    /// A raster over existing row-major data; `None` if the length is wrong.
    pub fn from_vec(width: usize, height: usize, data: Vec<T>) -> Option<Self> {
        (data.len() == width * height).then_some(Raster { width, height, data })
    }

    /// A raster whose sample `(x, y)` is `f(x, y)`.
    pub fn from_fn(width: usize, height: usize, mut f: impl FnMut(usize, usize) -> T) -> Self {
        let mut data = Vec::with_capacity(width * height);
        for y in 0..height {
            for x in 0..width {
                data.push(f(x, y));
            }
        }
        Raster { width, height, data }
    }

    /// Like [`Raster::from_fn`], rows computed in parallel (on the current
    /// rayon pool). Each sample is still computed alone, so the result is
    /// the same as the sequential one.
    pub fn par_from_fn(width: usize, height: usize, f: impl Fn(usize, usize) -> T + Sync) -> Self
    where
        T: Send + Sync + Default,
    {
        use rayon::prelude::*;
        let mut data = vec![T::default(); width * height];
        if width > 0 {
            data.par_chunks_mut(width).enumerate().for_each(|(y, row)| {
                for (x, v) in row.iter_mut().enumerate() {
                    *v = f(x, y);
                }
            });
        }
        Raster { width, height, data }
    }

    /// Columns.
    pub fn width(&self) -> usize {
        self.width
    }

    /// Rows.
    pub fn height(&self) -> usize {
        self.height
    }

    /// All samples, row-major.
    pub fn data(&self) -> &[T] {
        &self.data
    }

    /// All samples, row-major, mutable.
    pub fn data_mut(&mut self) -> &mut [T] {
        &mut self.data
    }

    /// Consumes the raster, returning its samples.
    pub fn into_vec(self) -> Vec<T> {
        self.data
    }

    /// The sample at column `x`, row `y`.
    #[inline]
    pub fn get(&self, x: usize, y: usize) -> T {
        self.data[y * self.width + x]
    }

    /// Sets the sample at column `x`, row `y`.
    #[inline]
    pub fn set(&mut self, x: usize, y: usize, value: T) {
        self.data[y * self.width + x] = value;
    }

    /// One row.
    pub fn row(&self, y: usize) -> &[T] {
        &self.data[y * self.width..(y + 1) * self.width]
    }

    /// One row, mutable.
    pub fn row_mut(&mut self, y: usize) -> &mut [T] {
        &mut self.data[y * self.width..(y + 1) * self.width]
    }

    /// Copies `window` (in this raster's pixel coordinates) out; pixels outside
    /// the raster take `outside`.
    ///
    /// Built row by row, each sample written once (no fill, then copy).
    pub fn crop(&self, window: Window, outside: T) -> Raster<T> {
        let own = Window::new(0, 0, self.width, self.height);
        let Some(common) = own.intersect(&window) else {
            return Raster::filled(window.width, window.height, outside);
        };
        let (x0, x1) = (common.x as usize, common.x_end() as usize);
        let right = (window.x_end() - common.x_end()) as usize;
        let mut data = Vec::with_capacity(window.area());
        for y in window.y..window.y_end() {
            if (common.y..common.y_end()).contains(&y) {
                data.resize(data.len() + (common.x - window.x) as usize, outside);
                data.extend_from_slice(&self.row(y as usize)[x0..x1]);
                data.resize(data.len() + right, outside);
            } else {
                data.resize(data.len() + window.width, outside);
            }
        }
        Raster { width: window.width, height: window.height, data }
    }

    /// Copies `src_window` of `src` into this raster with its corner at `(x, y)`.
    pub fn paste(&mut self, src: &Raster<T>, src_window: Window, x: usize, y: usize) {
        for row in 0..src_window.height {
            let sy = src_window.y as usize + row;
            let sx = src_window.x as usize;
            let from = &src.row(sy)[sx..sx + src_window.width];
            self.row_mut(y + row)[x..x + src_window.width].copy_from_slice(from);
        }
    }

    /// A new raster from pairs of samples of two rasters of the same size.
    pub fn zip_map<U: Copy, V: Copy>(&self, other: &Raster<U>, f: impl Fn(T, U) -> V) -> Raster<V> {
        debug_assert_eq!((self.width, self.height), (other.width, other.height));
        Raster {
            width: self.width,
            height: self.height,
            data: self.data.iter().zip(&other.data).map(|(&a, &b)| f(a, b)).collect(),
        }
    }

    /// A new raster with `f` applied to every sample.
    pub fn map<U: Copy>(&self, f: impl Fn(T) -> U) -> Raster<U> {
        Raster { width: self.width, height: self.height, data: self.data.iter().map(|&v| f(v)).collect() }
    }
}

impl Raster<f32> {
    /// True when every sample is nodata (NaN).
    pub fn all_nodata(&self) -> bool {
        self.data.iter().all(|v| v.is_nan())
    }

    /// Smallest and largest valid sample, or `None` when all are nodata.
    pub fn min_max(&self) -> Option<(f32, f32)> {
        self.data.iter().filter(|v| !v.is_nan()).fold(None, |acc, &v| match acc {
            None => Some((v, v)),
            Some((lo, hi)) => Some((lo.min(v), hi.max(v))),
        })
    }
}

/// `⌊x⌋` as an integer, for |x| < 2⁶³: one truncating conversion and a
/// compare (`x.floor() as i64` adds the saturation checks of `as`, a few
/// instructions per sample in the per-sample loops).
#[inline]
pub fn floor_i64(x: f64) -> i64 {
    let t = x as i64;
    t - i64::from(t as f64 > x)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn floor_i64_is_floor() {
        for x in [-2.5, -2.0, -1e-12, 0.0, 0.3, 1.0, 7.999, -7.999, 1e12 + 0.5] {
            assert_eq!(floor_i64(x), x.floor() as i64, "{x}");
        }
    }

    #[test]
    fn crop_pads_outside_with_the_given_value() {
        let r = Raster::from_fn(3, 2, |x, y| (y * 3 + x) as f32);
        let c = r.crop(Window::new(-1, 1, 3, 2), -1.0);
        assert_eq!(c.data(), &[-1.0, 3.0, 4.0, -1.0, -1.0, -1.0]);
    }

    #[test]
    fn intersect_of_disjoint_windows_is_none() {
        let a = Window::new(0, 0, 2, 2);
        assert_eq!(a.intersect(&Window::new(2, 0, 2, 2)), None);
        assert_eq!(a.intersect(&Window::new(1, 1, 5, 5)), Some(Window::new(1, 1, 1, 1)));
    }

    #[test]
    fn min_max_skips_nodata() {
        let r = Raster::from_vec(3, 1, vec![f32::NAN, 2.0, -1.0]).unwrap();
        assert_eq!(r.min_max(), Some((-1.0, 2.0)));
        assert!(Raster::filled(2, 2, f32::NAN).all_nodata());
    }
}
