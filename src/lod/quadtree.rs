//! A static quadtree of terrain tiles over a square region, in a local
//! metric frame: what the deferral table ([`super::deferral`]) and the
//! benchmarks refine. The client can build one per region from its tile
//! grid (World Wind tiles below one level-n tile form such a quadtree).
//!
//! Every node carries a bounding sphere and a geometric error `ξ` (metres
//! of height error if the node is drawn instead of its children), with the
//! two properties the deferral table needs (004 §IV-C): each child's sphere
//! lies inside its parent's, and `ξ` halves at each level. So the refinement
//! test "split if the eye is within `r + ξ μ` of the centre" is monotone:
//! a refined node's parent is refined.
//!
//! Invariants: parents come before children; node 0 is the root; children
//! of a node are consecutive.

use glam::{DVec2, DVec3};

/// "No node".
pub const NONE: u32 = u32::MAX;

/// One tile.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TileNode {
    /// Level below the root (0 = root).
    pub level: u8,
    /// The parent, `None` for the root.
    pub parent: Option<u32>,
    /// First of four consecutive children, or [`NONE`] for a leaf.
    pub first_child: u32,
    /// South-west corner of the tile, metres.
    pub min_m: DVec2,
    /// Side length, metres.
    pub size_m: f64,
    /// Bounding sphere centre, metres.
    pub center_m: DVec3,
    /// Bounding sphere radius (contains the children's spheres), metres.
    pub radius_m: f64,
    /// Geometric error `ξ`, metres.
    pub error_m: f64,
}

impl TileNode {
    /// The four children's indices, if any.
    pub fn children(&self) -> std::ops::Range<u32> {
        match self.first_child {
            NONE => 0..0,
            f => f..f + 4,
        }
    }
}

/// A complete quadtree of `depth + 1` levels over a square.
#[derive(Clone, Debug)]
pub struct TileQuadtree {
    /// Nodes in breadth-first order.
    pub nodes: Vec<TileNode>,
}

impl TileQuadtree {
    /// The quadtree over the square `[min, min + size]²` with `depth` levels
    /// below the root; `relief(min, max)` gives the lowest and highest ground
    /// in a box (metres); the root's error is `root_error_m`.
    pub fn square(
        min_m: DVec2,
        size_m: f64,
        depth: u8,
        root_error_m: f64,
        relief: &dyn Fn(DVec2, DVec2) -> (f64, f64),
    ) -> TileQuadtree {
        let mut nodes = vec![tile(min_m, size_m, 0, None, root_error_m, relief)];
        let mut i = 0;
        while i < nodes.len() {
            let n = nodes[i];
            if n.level < depth {
                nodes[i].first_child = nodes.len() as u32;
                let half = n.size_m / 2.0;
                for (dx, dy) in [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0)] {
                    let corner = n.min_m + DVec2::new(dx, dy) * half;
                    nodes.push(tile(corner, half, n.level + 1, Some(i as u32), n.error_m / 2.0, relief));
                }
            }
            i += 1;
        }
        // Grow radii bottom-up so that every child's sphere is inside its
        // parent's.
        for i in (0..nodes.len()).rev() {
            let n = nodes[i];
            for c in n.children() {
                let c = nodes[c as usize];
                let need = c.center_m.distance(n.center_m) + c.radius_m;
                nodes[i].radius_m = nodes[i].radius_m.max(need);
            }
        }
        TileQuadtree { nodes }
    }

    /// Number of nodes.
    pub fn len(&self) -> usize {
        self.nodes.len()
    }

    /// Whether there are no nodes (never, for a built tree).
    pub fn is_empty(&self) -> bool {
        self.nodes.is_empty()
    }
}

fn tile(
    min_m: DVec2,
    size_m: f64,
    level: u8,
    parent: Option<u32>,
    error_m: f64,
    relief: &dyn Fn(DVec2, DVec2) -> (f64, f64),
) -> TileNode {
    let (lo, hi) = relief(min_m, min_m + DVec2::splat(size_m));
    let center = min_m + DVec2::splat(size_m / 2.0);
    let half_diagonal = size_m * std::f64::consts::FRAC_1_SQRT_2;
    TileNode {
        level,
        parent,
        first_child: NONE,
        min_m,
        size_m,
        center_m: DVec3::new(center.x, center.y, 0.5 * (lo + hi)),
        radius_m: half_diagonal.hypot(0.5 * (hi - lo)),
        error_m,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn children_tile_their_parent_inside_its_sphere() {
        let relief = |a: DVec2, b: DVec2| (0.01 * a.x, 0.02 * b.y + 5.0);
        let t = TileQuadtree::square(DVec2::new(-500.0, 200.0), 1024.0, 4, 8.0, &relief);
        assert_eq!(t.len(), 1 + 4 + 16 + 64 + 256);
        for (i, n) in t.nodes.iter().enumerate() {
            let kids: Vec<&TileNode> = n.children().map(|c| &t.nodes[c as usize]).collect();
            if kids.is_empty() {
                assert_eq!(n.level, 4);
                continue;
            }
            let area: f64 = kids.iter().map(|k| k.size_m * k.size_m).sum();
            assert_eq!(area, n.size_m * n.size_m);
            for k in kids {
                assert_eq!(k.parent, Some(i as u32));
                assert!(k.center_m.distance(n.center_m) + k.radius_m <= n.radius_m * (1.0 + 1e-12));
                assert_eq!(k.error_m, n.error_m / 2.0);
                assert!(k.min_m.cmpge(n.min_m).all() && (k.min_m + k.size_m).cmple(n.min_m + n.size_m).all());
            }
        }
    }
}
