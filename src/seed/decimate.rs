//! Parents from their finished children. A parent tile's sample `i` is its
//! children's sample `2i` (the lattices nest), so where a layer has one value
//! at a shared sample on both levels ([`crate::cem::alike_across`]) the
//! parent is its four children's even samples, bit for bit — no sources read,
//! no pipeline run. Each finished child keeps only its halved samples until
//! its parent is done.

use crate::cem::LayerSamples;
use crate::raster::Raster;

/// Every second sample of a tile in both directions (a child's share of its parent).
pub fn half(samples: &LayerSamples) -> LayerSamples {
    fn every_second<T: Copy>(r: &Raster<T>) -> Raster<T> {
        Raster::from_fn(r.width().div_ceil(2), r.height().div_ceil(2), |x, y| r.get(2 * x, 2 * y))
    }
    match samples {
        LayerSamples::Float(r) => LayerSamples::Float(every_second(r)),
        LayerSamples::Class(r) => LayerSamples::Class(every_second(r)),
    }
}

/// The parent from the halves of its children in [`crate::grid::TileId::children`]
/// order (south-west, south-east, north-west, north-east); `None` if they
/// are not four square halves of one size and type.
pub fn assemble(halves: [&LayerSamples; 4]) -> Option<LayerSamples> {
    match halves {
        [LayerSamples::Float(a), LayerSamples::Float(b), LayerSamples::Float(c), LayerSamples::Float(d)] => {
            join([a, b, c, d]).map(LayerSamples::Float)
        }
        [LayerSamples::Class(a), LayerSamples::Class(b), LayerSamples::Class(c), LayerSamples::Class(d)] => {
            join([a, b, c, d]).map(LayerSamples::Class)
        }
        _ => None,
    }
}

/// Four `h × h` quarters sharing their inner edges → `(2h − 1)²` (row 0 north).
fn join<T: Copy>(quarters: [&Raster<T>; 4]) -> Option<Raster<T>> {
    let h = quarters[0].width();
    if h < 2 || quarters.iter().any(|q| q.width() != h || q.height() != h) {
        return None;
    }
    let m = h - 1;
    Some(Raster::from_fn(2 * h - 1, 2 * h - 1, |x, y| {
        let (east, ix) = if x < m { (0, x) } else { (1, x - m) };
        let (north, iy) = if y < m { (2, y) } else { (0, y - m) };
        quarters[north + east].get(ix, iy)
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_parent_is_its_childrens_even_samples() {
        // A 9 × 9 "parent" field on a 17 × 17 child lattice: value = global index.
        let value = |gx: usize, gy: usize| (gy * 100 + gx) as f32;
        // Child (north, east) covers global samples [8·east, 8·east + 8] × rows from the north.
        let child = |north: usize, east: usize| {
            LayerSamples::Float(Raster::from_fn(9, 9, |x, y| value(8 * east + x, 8 * (1 - north) + y)))
        };
        let kids = [child(0, 0), child(0, 1), child(1, 0), child(1, 1)];
        let halves: Vec<LayerSamples> = kids.iter().map(half).collect();
        let Some(LayerSamples::Float(parent)) = assemble([&halves[0], &halves[1], &halves[2], &halves[3]]) else {
            panic!()
        };
        assert_eq!((parent.width(), parent.height()), (9, 9));
        for y in 0..9 {
            for x in 0..9 {
                assert_eq!(parent.get(x, y), value(2 * x, 2 * y), "({x}, {y})");
            }
        }
        let class = LayerSamples::Class(Raster::filled(5, 5, 1u8));
        assert!(assemble([&halves[0], &halves[1], &halves[2], &class]).is_none());
    }
}
