//! Noise in point clouds: birds, haze and multipath returns, which would
//! become spikes or pits in a canopy height model.
//!
//! The rule: a point is dropped when it is classified as noise (ASPRS classes
//! 7, low noise, and 18, high noise), or when it is *isolated*: the 3 × 3 × 3
//! block of [`VOXEL_M`] voxels around it holds at most [`ISOLATED`] other
//! points. These are the defaults of LAStools' `lasnoise` (step 4 m,
//! isolated 5); a bird 20 m above the canopy has an empty 12 m cube around
//! it, while a canopy or ground return has dozens of neighbours even in a
//! 1 point/m² cloud.
//!
//! Invariant: the result depends only on the points, not on their order.

use std::collections::HashMap;

/// Side of the voxels, metres.
pub const VOXEL_M: f64 = 4.0;

/// Most other points in the 27 voxels around an isolated point.
pub const ISOLATED: u32 = 5;

/// ASPRS classes of noise.
pub const NOISE_CLASSES: [u8; 2] = [7, 18];

/// Why points were dropped.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Dropped {
    /// Classified as noise.
    pub noise_class: usize,
    /// Isolated in space.
    pub isolated: usize,
}

impl std::fmt::Display for Dropped {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{} classified as noise, {} isolated", self.noise_class, self.isolated)
    }
}

/// Which points to keep (`true`) by the rule above, and how many were dropped.
pub fn keep(x: &[f64], y: &[f64], z: &[f64], class: &[u8]) -> (Vec<bool>, Dropped) {
    let mut keep: Vec<bool> = class.iter().map(|c| !NOISE_CLASSES.contains(c)).collect();
    let mut dropped = Dropped { noise_class: keep.iter().filter(|&&k| !k).count(), isolated: 0 };
    let voxel = |i: usize| {
        let v = |a: f64| (a / VOXEL_M).floor() as i64;
        (v(x[i]), v(y[i]), v(z[i]))
    };
    let mut counts: HashMap<(i64, i64, i64), u32> = HashMap::new();
    for i in (0..z.len()).filter(|&i| keep[i]) {
        *counts.entry(voxel(i)).or_default() += 1;
    }
    // Only a point whose own voxel holds at most ISOLATED others can be isolated.
    let candidates: Vec<usize> =
        (0..z.len()).filter(|&i| keep[i] && counts.get(&voxel(i)).is_none_or(|&n| n <= ISOLATED + 1)).collect();
    for i in candidates {
        let (a, b, c) = voxel(i);
        let mut around = 0u32;
        for da in -1..=1 {
            for db in -1..=1 {
                for dc in -1..=1 {
                    around += counts.get(&(a + da, b + db, c + dc)).copied().unwrap_or(0);
                }
            }
        }
        if around - 1 <= ISOLATED {
            keep[i] = false;
            dropped.isolated += 1;
        }
    }
    (keep, dropped)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn birds_and_noise_classes_go_and_the_canopy_stays() {
        // A 10 × 10 m canopy at 20 m, 4 points per m², a bird at 45 m, a noise point.
        let (mut x, mut y, mut z, mut class) = (vec![], vec![], vec![], vec![]);
        for i in 0..400 {
            x.push(1000.0 + (i % 20) as f64 * 0.5);
            y.push(2000.0 + (i / 20) as f64 * 0.5);
            z.push(20.0 + (i % 7) as f64 * 0.3);
            class.push(1);
        }
        for (px, pz, c) in [(1005.0, 45.0, 1), (1003.0, 21.0, 7)] {
            x.push(px);
            y.push(2005.0);
            z.push(pz);
            class.push(c);
        }
        let (keep, dropped) = keep(&x, &y, &z, &class);
        assert_eq!(dropped, Dropped { noise_class: 1, isolated: 1 });
        assert!(keep[..400].iter().all(|&k| k));
        assert!(!keep[400] && !keep[401]);
    }
}
