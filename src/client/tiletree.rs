//! The region's World Wind tiles down to the deepest level, with static
//! bounds: what the distance deferral table ([`crate::lod::deferral`])
//! refines for the client's screen-space error rule ([`super::sse`]).
//!
//! A node's bounds come from heights known before the flight (a
//! [`super::envelope::HeightEnvelope`], or any function of the sector), not
//! from the tiles loaded so far, so they never change during a flight:
//! - the sphere holds the tile's culling box ([`super::quadtree::local_box`]:
//!   cast range, flat-frame error, heights from the lowest ellipsoid drop
//!   up), in ECEF;
//! - the error `ξ` is the old rule's: the sample spacing plus the flat-frame
//!   error at the tile's heights.
//!
//! Both are then made monotone bottom-up (004 §IV-C): a parent's sphere is
//! grown to hold its children's, and its `ξ` raised to theirs, so "refine
//! within `r + ξ μ`" holding for a child holds for its parent.
//!
//! Invariants: parents come before children; the roots (level-0 tiles) come
//! first; a node's children are consecutive; only tiles that overlap the
//! region are nodes.

use super::frame::TileFrame;
use super::quadtree::{UNKNOWN_RANGE_M, local_box, touches};
use crate::grid::{BBox, Sector, TileGrid, TileId};
use crate::lod::deferral::Hierarchy;
use glam::DVec3;

/// Nodes a tree may have: about 100 bytes each, so 2²⁰ nodes are about
/// 100 MiB — a region of ~1°×1° down to level 16 on 36° / 513-sample tiles.
pub const MAX_NODES: usize = 1 << 20;

/// One tile with its static bounds.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TreeNode {
    /// The tile.
    pub id: TileId,
    /// Its parent, `None` for a root.
    pub parent: Option<u32>,
    /// First child (children are consecutive).
    pub first_child: u32,
    /// Number of children (0 for a leaf).
    pub children: u8,
    /// Lowest and highest surface assumed, metres above the ellipsoid.
    pub heights_m: (f64, f64),
    /// Bounding sphere centre, ECEF metres.
    pub centre_ecef: DVec3,
    /// Bounding sphere radius (holds the children's spheres), metres.
    pub radius_m: f64,
    /// Geometric error `ξ` (at least the children's), metres.
    pub error_m: f64,
}

/// The tree.
#[derive(Clone, Debug)]
pub struct TileTree {
    /// The tile grid.
    pub grid: TileGrid,
    /// Nodes, breadth first.
    pub nodes: Vec<TreeNode>,
}

/// The region's tree would exceed [`MAX_NODES`].
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
#[error("the region's tile tree to level {max_level} has more than {MAX_NODES} tiles")]
pub struct TooLarge {
    /// The deepest level asked for.
    pub max_level: u32,
}

impl TileTree {
    /// The tiles of `grid` over `bounds` down to `max_level`; `heights`
    /// gives a sector's lowest and highest surface if known (else the
    /// parent's range is used, and [`UNKNOWN_RANGE_M`] at the roots).
    pub fn build(
        grid: &TileGrid,
        bounds: &BBox,
        max_level: u32,
        heights: &dyn Fn(&Sector) -> Option<(f64, f64)>,
    ) -> Result<TileTree, TooLarge> {
        let mut tree = TileTree { grid: *grid, nodes: structure(grid, bounds, max_level)? };
        for v in 0..tree.nodes.len() {
            let n = tree.nodes[v];
            let inherited = n.parent.map_or(UNKNOWN_RANGE_M, |p| tree.nodes[p as usize].heights_m);
            let range = heights(&grid.sector(n.id)).unwrap_or(inherited);
            tree.nodes[v] = bounded(grid, n, range);
        }
        tree.make_monotone();
        Ok(tree)
    }

    /// Grows parents' spheres around their children's and raises their
    /// errors to their children's, children first.
    fn make_monotone(&mut self) {
        for v in (0..self.nodes.len()).rev() {
            let n = self.nodes[v];
            let Some(p) = n.parent else { continue };
            let parent = &mut self.nodes[p as usize];
            parent.radius_m = parent.radius_m.max(parent.centre_ecef.distance(n.centre_ecef) + n.radius_m);
            parent.error_m = parent.error_m.max(n.error_m);
        }
    }

    /// The children of node `v`.
    pub fn child_range(&self, v: u32) -> std::ops::Range<u32> {
        let n = &self.nodes[v as usize];
        n.first_child..n.first_child + u32::from(n.children)
    }
}

/// The nodes without bounds: level-0 tiles over the region, then children
/// that overlap it, breadth first.
fn structure(grid: &TileGrid, bounds: &BBox, max_level: u32) -> Result<Vec<TreeNode>, TooLarge> {
    let area = bounds.sector();
    let (rows, cols) = grid.tiles_on_level(0);
    let node = |id, parent| TreeNode {
        id,
        parent,
        first_child: 0,
        children: 0,
        heights_m: UNKNOWN_RANGE_M,
        centre_ecef: DVec3::ZERO,
        radius_m: 0.0,
        error_m: 0.0,
    };
    let mut nodes: Vec<TreeNode> = (0..rows)
        .flat_map(|r| (0..cols).map(move |c| TileId::new(0, r, c)))
        .filter(|&id| touches(grid, id, &area))
        .map(|id| node(id, None))
        .collect();
    let mut v = 0;
    while v < nodes.len() {
        let id = nodes[v].id;
        if id.level < max_level {
            let first = nodes.len();
            let kids = id.children().into_iter().filter(|&c| touches(grid, c, &area));
            nodes.extend(kids.map(|c| node(c, Some(v as u32))));
            nodes[v].first_child = first as u32;
            nodes[v].children = (nodes.len() - first) as u8;
            if nodes.len() > MAX_NODES {
                return Err(TooLarge { max_level });
            }
        }
        v += 1;
    }
    Ok(nodes)
}

/// The node's own sphere and error for heights `range`.
fn bounded(grid: &TileGrid, n: TreeNode, (lo, hi): (f64, f64)) -> TreeNode {
    let frame = TileFrame::new(grid, n.id);
    let (a, b) = local_box(&frame, lo, hi);
    let corners: [DVec3; 8] = std::array::from_fn(|k| {
        frame.to_ecef(DVec3::new([a.x, b.x][k & 1], [a.y, b.y][(k >> 1) & 1], [a.z, b.z][k >> 2]))
    });
    let (min, max) = corners.iter().fold((corners[0], corners[0]), |(l, h), &c| (l.min(c), h.max(c)));
    let centre = 0.5 * (min + max);
    let radius = corners.iter().map(|c| c.distance(centre)).fold(0.0, f64::max);
    let error_m = frame.spacing_m.max_element() + frame.flat_error_m(lo.abs().max(hi.abs()));
    TreeNode { heights_m: (lo, hi), centre_ecef: centre, radius_m: radius, error_m, ..n }
}

impl Hierarchy for TileTree {
    fn len(&self) -> usize {
        self.nodes.len()
    }
    fn roots(&self) -> impl Iterator<Item = u32> + '_ {
        (0..self.nodes.len() as u32).take_while(|&v| self.nodes[v as usize].parent.is_none())
    }
    fn parent(&self, v: u32) -> Option<u32> {
        self.nodes[v as usize].parent
    }
    fn children(&self, v: u32) -> impl Iterator<Item = u32> + '_ {
        self.child_range(v)
    }
    fn bound(&self, v: u32) -> (DVec3, f64, f64) {
        let n = &self.nodes[v as usize];
        (n.centre_ecef, n.radius_m, n.error_m)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn demo_tree(max_level: u32) -> TileTree {
        let grid = TileGrid::new(36.0, 513).unwrap();
        let bounds = BBox { west: 10.0, south: 46.3, east: 10.25, north: 46.45 };
        TileTree::build(&grid, &bounds, max_level, &|s| Some((500.0 + 100.0 * s.min_lon.fract(), 3500.0))).unwrap()
    }

    #[test]
    fn children_overlap_the_region_and_nest_inside_their_parent() {
        let tree = demo_tree(12);
        assert!(tree.nodes.iter().any(|n| n.id.level == 12));
        for (v, n) in tree.nodes.iter().enumerate() {
            for c in tree.child_range(v as u32) {
                let c = &tree.nodes[c as usize];
                assert_eq!(c.parent, Some(v as u32));
                assert_eq!(c.id.parent(), Some(n.id));
                assert!(c.centre_ecef.distance(n.centre_ecef) + c.radius_m <= n.radius_m * (1.0 + 1e-12));
                assert!(c.error_m <= n.error_m);
            }
            assert_eq!(n.children == 0, n.id.level == 12, "{n:?}");
        }
        assert_eq!(tree.roots().count(), 1);
    }

    #[test]
    fn a_sphere_holds_its_tile_at_every_assumed_height() {
        let tree = demo_tree(9);
        for n in &tree.nodes {
            let s = tree.grid.sector(n.id);
            for (lon, lat) in [(s.min_lon, s.min_lat), (s.max_lon, s.max_lat), (s.min_lon, s.max_lat)] {
                for h in [n.heights_m.0, n.heights_m.1] {
                    let p = super::super::globe::Geodetic::new(lon, lat, h).to_ecef();
                    assert!(p.distance(n.centre_ecef) <= n.radius_m, "{n:?}");
                }
            }
        }
    }

    #[test]
    fn a_region_across_the_antimeridian_has_nodes_on_both_sides() {
        let grid = TileGrid::new(36.0, 513).unwrap();
        let across = BBox { west: 179.5, south: -17.0, east: 180.5, north: -16.0 };
        let tree = TileTree::build(&grid, &across, 6, &|_| None).unwrap();
        let at = |level: u32, east: bool| {
            let on = |n: &&TreeNode| n.id.level == level && (grid.sector(n.id).min_lon < 0.0) == east;
            tree.nodes.iter().filter(on).count()
        };
        assert_eq!((at(0, false), at(0, true)), (1, 1), "a root each side");
        assert_eq!(at(6, false), at(6, true), "as many tiles each side");
    }

    #[test]
    fn a_tree_past_the_cap_is_refused() {
        let grid = TileGrid::new(36.0, 513).unwrap();
        let world = BBox::WORLD;
        assert_eq!(TileTree::build(&grid, &world, 12, &|_| None).unwrap_err(), TooLarge { max_level: 12 });
    }
}
