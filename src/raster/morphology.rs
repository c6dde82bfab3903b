//! Grey-scale morphology with square kernels of any radius: dilation (running
//! maximum), erosion (running minimum), and sequences of them such as the
//! dissertation's close (section 6.3, Figure 6.3: "dilation followed by erosion").
//!
//! Each pass is separable (a `1×(2r+1)` then a `(2r+1)×1` kernel). Rows use
//! log-doubling (vectorized elementwise steps, `log₂ k` of them); columns use
//! the van Herk / Gil–Werman scheme on whole rows (three sweeps whatever the
//! radius). The same kernel is the safety-zone maximum of section 6.4 (the
//! "maximum over 4- and 32-sample neighbourhoods").
//!
//! NaN is the identity of `f32::max` and `f32::min`, so nodata samples are
//! ignored and the buffer is padded with NaN: a window that holds only nodata
//! stays nodata. Samples closer than the radius to the buffer edge see only the
//! buffer; callers give the input a margin of the radius and crop it away.

use super::Raster;
use rayon::prelude::*;

/// One morphological pass.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Deserialize, serde::Serialize)]
pub enum MorphOp {
    /// Running maximum over the square kernel.
    Dilate,
    /// Running minimum over the square kernel.
    Erode,
}

impl MorphOp {
    /// Parses a sequence such as `"DDEE"` (footnote 6 of the dissertation: the
    /// order matters, `DDEE` ≠ `DEDE`).
    pub fn parse_sequence(text: &str) -> Option<Vec<MorphOp>> {
        text.chars()
            .map(|c| match c.to_ascii_uppercase() {
                'D' => Some(MorphOp::Dilate),
                'E' => Some(MorphOp::Erode),
                _ => None,
            })
            .collect()
    }
}

/// Maximum over the `(2r+1)²` square around each sample.
pub fn dilate(src: &Raster<f32>, radius: usize) -> Raster<f32> {
    separable(src, radius, radius, f32::max)
}

/// Minimum over the `(2r+1)²` square around each sample.
pub fn erode(src: &Raster<f32>, radius: usize) -> Raster<f32> {
    separable(src, radius, radius, f32::min)
}

/// [`dilate`] where the square fits the buffer only (`radius` samples in
/// from every edge): `(w − 2r) × (h − 2r)` samples, sample `(x, y)` the
/// maximum around source sample `(x + r, y + r)`. No work is spent on the
/// margin that a caller would crop away.
pub fn dilate_inner(src: &Raster<f32>, radius: usize) -> Raster<f32> {
    separable(src, radius, 0, f32::max)
}

/// Applies `ops` in order, each with a square kernel of `radius`.
pub fn apply_sequence(src: &Raster<f32>, ops: &[MorphOp], radius: usize) -> Raster<f32> {
    let mut out = src.clone();
    for op in ops {
        out = match op {
            MorphOp::Dilate => dilate(&out, radius),
            MorphOp::Erode => erode(&out, radius),
        };
    }
    out
}

/// The margin a sequence needs so that cropped output is exact.
pub fn sequence_margin(ops: &[MorphOp], radius: usize) -> usize {
    ops.len() * radius
}

/// The running extreme over squares of `radius` on `src` padded with `pad`
/// NaN samples per side (`pad` ≤ `radius`): the output is `2 (radius − pad)`
/// samples smaller than `src` in each direction.
fn separable(
    src: &Raster<f32>,
    radius: usize,
    pad: usize,
    op: impl Fn(f32, f32) -> f32 + Copy + Send + Sync,
) -> Raster<f32> {
    if radius == 0 {
        return src.clone();
    }
    let shrink = 2 * (radius - pad);
    let mut horizontal = Raster::filled(src.width().saturating_sub(shrink), src.height(), f32::NAN);
    let w = horizontal.width().max(1);
    horizontal
        .data_mut()
        .par_chunks_mut(w)
        .enumerate()
        .for_each_init(|| Lines::new(src.width(), radius, pad), |line, (y, row)| line.run(src.row(y), row, op));
    vertical(&horizontal, radius, pad, op)
}

/// Scratch space for the running extreme along one line, by doubling: after
/// step `j` a buffer holds the extreme over `2ʲ` consecutive samples, and the
/// window of `k = 2r + 1` is the extreme of two overlapping power-of-two spans.
/// Each step is an elementwise operation on shifted slices, which the
/// compiler vectorizes (van Herk's prefix scans along a row cannot be).
struct Lines {
    a: Vec<f32>,
    b: Vec<f32>,
    radius: usize,
    pad: usize,
}

impl Lines {
    fn new(len: usize, radius: usize, pad: usize) -> Self {
        Lines { a: vec![f32::NAN; len + 2 * pad], b: vec![f32::NAN; len + 2 * pad], radius, pad }
    }

    /// `dst[i] = op` over `padded[i ..= i + 2r]`, where `padded` is `src`
    /// with `pad` NaN samples on each side.
    fn run(&mut self, src: &[f32], dst: &mut [f32], op: impl Fn(f32, f32) -> f32 + Copy + Send + Sync) {
        let (p, k) = (self.pad, 2 * self.radius + 1);
        let n = src.len() + 2 * p;
        if n < k {
            return;
        }
        self.a[..n].fill(f32::NAN);
        self.a[p..p + src.len()].copy_from_slice(src);
        let mut span = 1;
        while 2 * span <= k {
            let len = n - span;
            for ((out, &x), &y) in self.b[..len].iter_mut().zip(&self.a[..len]).zip(&self.a[span..n]) {
                *out = op(x, y);
            }
            std::mem::swap(&mut self.a, &mut self.b);
            span *= 2;
        }
        // Output i covers padded[i ..= i + 2r] = spans at i and i + k − span.
        let shift = k - span;
        for ((out, &x), &y) in dst.iter_mut().zip(&self.a[..]).zip(&self.a[shift..]) {
            *out = op(x, y);
        }
    }
}

/// The vertical pass, done on whole rows so that the inner loops are
/// contiguous; `src` is padded with `pad` NaN rows above and below.
fn vertical(
    src: &Raster<f32>,
    radius: usize,
    pad: usize,
    op: impl Fn(f32, f32) -> f32 + Copy + Send + Sync,
) -> Raster<f32> {
    let (w, h, k) = (src.width(), src.height(), 2 * radius + 1);
    let mut out = Raster::filled(w, (h + 2 * pad).saturating_sub(2 * radius), f32::NAN);
    if out.data().is_empty() {
        return out;
    }
    let rows = (h + 2 * pad).div_ceil(k) * k;
    // Padded row p holds source row p - pad (NaN outside).
    let padded_row = |p: usize| -> Option<&[f32]> { p.checked_sub(pad).filter(|&y| y < h).map(|y| src.row(y)) };
    let mut forward = vec![f32::NAN; rows * w];
    let mut backward = vec![f32::NAN; rows * w];
    // Blocks of k rows are independent.
    forward.par_chunks_mut(k * w).zip(backward.par_chunks_mut(k * w)).enumerate().for_each(|(block, (fwd, bwd))| {
        let s = block * k;
        for i in 0..k {
            let (done, rest) = fwd.split_at_mut(i * w);
            combine_row(&mut rest[..w], (i > 0).then(|| &done[(i - 1) * w..]), padded_row(s + i), op);
        }
        for i in (0..k).rev() {
            let (head, tail) = bwd.split_at_mut((i + 1) * w);
            combine_row(&mut head[i * w..], (i + 1 < k).then(|| &tail[..w]), padded_row(s + i), op);
        }
    });
    out.data_mut().par_chunks_mut(w.max(1)).enumerate().for_each(|(y, row)| {
        let b = &backward[y * w..(y + 1) * w];
        let f = &forward[(y + 2 * radius) * w..(y + 2 * radius + 1) * w];
        for ((o, &bv), &fv) in row.iter_mut().zip(b).zip(f) {
            *o = op(bv, fv);
        }
    });
    out
}

/// `cur = op(previous, row)` elementwise, where a missing side is the identity (NaN).
fn combine_row(
    cur: &mut [f32],
    previous: Option<&[f32]>,
    row: Option<&[f32]>,
    op: impl Fn(f32, f32) -> f32 + Copy + Send + Sync,
) {
    match (previous, row) {
        (Some(p), Some(r)) => {
            for ((c, &pv), &rv) in cur.iter_mut().zip(p).zip(r) {
                *c = op(pv, rv);
            }
        }
        (Some(p), None) => cur.copy_from_slice(&p[..cur.len()]),
        (None, Some(r)) => cur.copy_from_slice(r),
        (None, None) => cur.fill(f32::NAN),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn brute(src: &Raster<f32>, radius: usize, op: impl Fn(f32, f32) -> f32 + Copy + Send + Sync) -> Raster<f32> {
        let r = radius as i64;
        Raster::from_fn(src.width(), src.height(), |x, y| {
            let mut acc = f32::NAN;
            for dy in -r..=r {
                for dx in -r..=r {
                    let (sx, sy) = (x as i64 + dx, y as i64 + dy);
                    if sx >= 0 && sy >= 0 && (sx as usize) < src.width() && (sy as usize) < src.height() {
                        acc = op(acc, src.get(sx as usize, sy as usize));
                    }
                }
            }
            acc
        })
    }

    fn same(a: &Raster<f32>, b: &Raster<f32>) -> bool {
        a.data().iter().zip(b.data()).all(|(x, y)| x == y || (x.is_nan() && y.is_nan()))
    }

    proptest! {
        #[test]
        fn dilate_and_erode_match_brute_force(
            w in 1usize..20, h in 1usize..20, radius in 0usize..6, seed in any::<u64>(), holes in 0u32..4,
        ) {
            let mut state = seed | 1;
            let src = Raster::from_fn(w, h, |_, _| {
                state ^= state << 13; state ^= state >> 7; state ^= state << 17;
                if (state % 10) < holes as u64 { f32::NAN } else { (state % 1000) as f32 }
            });
            prop_assert!(same(&dilate(&src, radius), &brute(&src, radius, f32::max)));
            prop_assert!(same(&erode(&src, radius), &brute(&src, radius, f32::min)));
            let inner = dilate_inner(&src, radius);
            prop_assert_eq!(
                (inner.width(), inner.height()),
                (w.saturating_sub(2 * radius), h.saturating_sub(2 * radius))
            );
            let window = super::super::Window::new(radius as i64, radius as i64, inner.width(), inner.height());
            prop_assert!(same(&inner, &dilate(&src, radius).crop(window, f32::NAN)));
        }
    }

    #[test]
    fn close_bridges_a_line_narrower_than_the_kernel() {
        // A forest (1) crossed by a one-pixel contour line (0).
        let src = Raster::from_fn(9, 9, |x, _| if x == 4 { 0.0 } else { 1.0 });
        let closed = apply_sequence(&src, &MorphOp::parse_sequence("DE").unwrap(), 1);
        assert!(closed.data().iter().all(|&v| v == 1.0));
    }

    #[test]
    fn sequence_order_matters_as_footnote_6_says() {
        let src = Raster::from_fn(12, 1, |x, _| [0., 1., 0., 0., 0., 1., 1., 0., 0., 0., 0., 1.][x]);
        let ddee = apply_sequence(&src, &MorphOp::parse_sequence("DDEE").unwrap(), 1);
        let dede = apply_sequence(&src, &MorphOp::parse_sequence("DEDE").unwrap(), 1);
        assert_ne!(ddee, dede);
        assert_eq!(MorphOp::parse_sequence("DX"), None);
    }
}
