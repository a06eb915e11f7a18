//! The ray octree of local z-buffering: an octree over primitives (triangles of a mesh, or
//! boxes of instances), flat and `u32`-indexed, that [`crate::traverse`] walks with fat rays.
//!
//! # References
//! - Han & Zeiger, "The Local Z-Buffering Rendering", §II.A: the octree of the preprocessing
//!   stage, terminated by a maximum depth and a maximum number of primitives per leaf, with the
//!   Akenine-Möller triangle–box overlap test deciding which octants a triangle goes to.
//! - Akenine-Möller, "Fast 3D Triangle-Box Overlap Testing", JGT 6(1), 2001
//!   ([`occult_core::tri_box_overlap`]).
//!
//! A primitive is referenced by every leaf it overlaps (no splitting), so a leaf's list is
//! complete: every point of a primitive lies in some leaf that references it (the overlap test
//! counts touching, and runs on the octant grown by a relative 10⁻⁵ against rounding). Each
//! node box is the octant of its parent ([`super::cell::child_bounds`]; the root box is the
//! primitives' bounds, not made cubic; an axis along which a node is flat is not split). A
//! node stops splitting at the maximum depth, at or below the leaf size, or when splitting
//! would not separate its primitives (every child would hold them all, or they would be
//! referenced more than 4 times each on average).
//!
//! Cost: O(references · depth) overlap tests to build; memory 32 bytes per node plus 4 bytes per
//! reference. Building refuses to exceed [`MAX_REFERENCES`] references in one tree.

use super::cell::{self, child_bounds, stops_splitting, OctreeConfigError};
use occult_core::{tri_box_overlap, Aabb, Vec3};

/// Most primitive references one octree may hold (about 1 GiB of lists).
pub const MAX_REFERENCES: usize = 1 << 28;
/// References allowed per primitive (plus [`REFERENCE_SLACK`]) before the build gives up: a
/// surface split into leaves far smaller than its triangles (large triangles, tiny leaf sizes,
/// deep trees) multiplies its references by up to 4 per level.
pub const REFERENCES_PER_PRIMITIVE: usize = 32;
/// Extra references allowed whatever the primitive count.
pub const REFERENCE_SLACK: usize = 1 << 16;

/// Marks an internal node in [`RayOctreeNode::count`].
const INTERNAL: u32 = u32::MAX;

/// Termination of the build (§II.A).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RayOctreeConfig {
    /// Deepest level (root = 0), 0..=[`cell::MAX_OCTREE_DEPTH`].
    pub max_depth: u32,
    /// A node with at most this many primitives is a leaf (≥ 1).
    pub max_leaf_size: usize,
}

impl RayOctreeConfig {
    /// Checks the leaf size, then the depth, by the rules of [`super::cell`] (the build calls
    /// it first).
    ///
    /// # Errors
    /// [`OctreeConfigError`] naming `max_leaf_size` or `max_depth` and the value out of range.
    pub fn validate(&self) -> Result<(), OctreeConfigError> {
        cell::check_leaf_size("max_leaf_size", self.max_leaf_size)?;
        cell::check_depth("max_depth", self.max_depth, 0)
    }
}

impl Default for RayOctreeConfig {
    /// The paper's setting for Octree-o: 150 triangles per leaf (§III.B.1); depth 12.
    fn default() -> Self {
        Self {
            max_depth: 12,
            max_leaf_size: 150,
        }
    }
}

/// Why a ray octree was not built.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum RayOctreeError {
    /// A configuration value out of range ([`RayOctreeConfig::validate`]).
    #[error(transparent)]
    BadConfig(#[from] OctreeConfigError),
    /// The tree would hold more than this many primitive references
    /// ([`REFERENCES_PER_PRIMITIVE`] per primitive plus [`REFERENCE_SLACK`], at most
    /// [`MAX_REFERENCES`]): raise the leaf size or lower the depth.
    #[error("octree would hold more than {0} primitive references (raise the leaf size or lower the depth)")]
    TooLarge(usize),
}

/// A node: its box, and either 8 children (`first..first + 8`) or a leaf list
/// (`primitives[first..first + count]`).
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(C)]
pub struct RayOctreeNode {
    /// The node's octant box.
    pub bounds: Aabb,
    /// First child (internal) or first list entry (leaf).
    pub first: u32,
    /// List length (leaf), or `u32::MAX` for an internal node.
    pub count: u32,
}

const _: () = assert!(std::mem::size_of::<RayOctreeNode>() == 32);

impl RayOctreeNode {
    /// True for a leaf.
    #[inline]
    pub fn is_leaf(&self) -> bool {
        self.count != INTERNAL
    }
    /// The 8 children of an internal node; child `i` takes the upper half on axis `a` when bit
    /// `a` of `i` is set.
    #[inline]
    pub fn children(&self) -> std::ops::Range<u32> {
        self.first..self.first + 8
    }
    /// The list range of a leaf.
    #[inline]
    pub fn range(&self) -> std::ops::Range<usize> {
        self.first as usize..(self.first + self.count) as usize
    }
}

/// The ray octree (see the module doc).
#[derive(Clone, Debug, Default)]
pub struct RayOctree {
    nodes: Vec<RayOctreeNode>,
    /// Per node (internal nodes only meaningful): bit `i` set when child `i` is not an empty
    /// leaf; bit `8 + a` set when the node is not split along axis `a` (flat).
    split_info: Vec<u16>,
    primitives: Vec<u32>,
    leaf_count: usize,
    depth: u32,
}

impl RayOctree {
    /// An octree over the triangles `triangles` (indices into `positions`), overlap by the
    /// Akenine-Möller test. Empty for no triangles.
    ///
    /// # Errors
    /// [`RayOctreeError::BadConfig`] for a configuration out of range
    /// ([`RayOctreeConfig::validate`]); [`RayOctreeError::TooLarge`].
    pub fn build_triangles(
        positions: &[Vec3],
        triangles: &[[u32; 3]],
        config: RayOctreeConfig,
    ) -> Result<Self, RayOctreeError> {
        let corners = |t: u32| triangles[t as usize].map(|i| positions[i as usize]);
        let boxes: Vec<Aabb> = (0..triangles.len() as u32)
            .map(|t| Aabb::from_points(corners(t)))
            .collect();
        Self::build_with(&boxes, config, |t, b| tri_box_overlap(b, corners(t)))
    }

    /// An octree over boxes (overlap = boxes share a point).
    ///
    /// # Errors
    /// As [`RayOctree::build_triangles`].
    pub fn build_boxes(boxes: &[Aabb], config: RayOctreeConfig) -> Result<Self, RayOctreeError> {
        Self::build_with(boxes, config, |i, b| boxes[i as usize].overlaps(b))
    }

    /// An octree over primitives with bounds `boxes`; `overlaps(i, node_box)` refines the box
    /// test (called only when primitive `i`'s box overlaps `node_box`). Empty boxes are left out.
    ///
    /// # Errors
    /// As [`RayOctree::build_triangles`].
    pub fn build_with(
        boxes: &[Aabb],
        config: RayOctreeConfig,
        overlaps: impl Fn(u32, &Aabb) -> bool,
    ) -> Result<Self, RayOctreeError> {
        config.validate()?;
        if boxes.len() > u32::MAX as usize - 1 {
            return Err(RayOctreeError::TooLarge(MAX_REFERENCES));
        }
        let all: Vec<u32> = (0..boxes.len() as u32)
            .filter(|&i| !boxes[i as usize].is_empty())
            .collect();
        let bounds = all.iter().fold(Aabb::EMPTY, |b, &i| b.union(boxes[i as usize]));
        let mut tree = RayOctree::default();
        if all.is_empty() {
            return Ok(tree);
        }
        tree.nodes.push(RayOctreeNode {
            bounds,
            first: 0,
            count: 0,
        });
        let budget = (all.len().saturating_mul(REFERENCES_PER_PRIMITIVE) + REFERENCE_SLACK).min(MAX_REFERENCES);
        let mut builder = Builder {
            budget,
            boxes,
            overlaps: &overlaps,
            config,
            tree: &mut tree,
        };
        builder.split(0, all, 0)?;
        tree.split_info = tree
            .nodes
            .iter()
            .map(|n| {
                if n.is_leaf() {
                    return 0;
                }
                let kids = &tree.nodes[n.children().start as usize..n.children().end as usize];
                let occupied = (0..8).filter(|&i| !(kids[i].is_leaf() && kids[i].count == 0));
                let flat = (0..3).filter(|&a| kids[1 << a].bounds.is_empty());
                occupied.fold(0u16, |m, i| m | 1 << i) | flat.fold(0u16, |m, a| m | 1 << (8 + a))
            })
            .collect();
        Ok(tree)
    }

    /// Replaces the box of every leaf but the root by `tight(leaf, its primitives)`, which
    /// must hold every point of those primitives that lies in the leaf's octant (for example
    /// their bounds clipped to it): rays and culling then test that box instead. Internal nodes
    /// keep their octants, from which [`crate::traverse`] derives their children's.
    pub fn tighten_leaves(&mut self, mut tight: impl FnMut(&RayOctreeNode, &[u32]) -> Aabb) {
        for n in self.nodes.iter_mut().skip(1) {
            if n.is_leaf() {
                n.bounds = tight(n, &self.primitives[n.range()]);
            }
        }
    }

    /// All nodes; node 0 is the root (absent for an empty tree).
    #[inline]
    pub fn nodes(&self) -> &[RayOctreeNode] {
        &self.nodes
    }
    /// Per node: bit `i` (0..8) set when child `i` of an internal node is not an empty leaf,
    /// bit `8 + a` set when the node is not split along axis `a` (its lower children span the
    /// whole axis, its upper ones are empty). 0 for leaves.
    #[inline]
    pub fn split_info(&self) -> &[u16] {
        &self.split_info
    }
    /// The concatenated leaf lists.
    #[inline]
    pub fn primitives(&self) -> &[u32] {
        &self.primitives
    }
    /// The list of leaf `node_index`.
    #[inline]
    pub fn leaf_primitives(&self, node_index: u32) -> &[u32] {
        &self.primitives[self.nodes[node_index as usize].range()]
    }
    /// True when the tree holds nothing.
    pub fn is_empty(&self) -> bool {
        self.nodes.is_empty()
    }
    /// Root box (empty for an empty tree).
    pub fn bounds(&self) -> Aabb {
        self.nodes.first().map_or(Aabb::EMPTY, |n| n.bounds)
    }
    /// Leaves (including empty ones).
    pub fn leaf_count(&self) -> usize {
        self.leaf_count
    }
    /// Deepest level reached.
    pub fn depth(&self) -> u32 {
        self.depth
    }
    /// Bytes held.
    pub fn memory_bytes(&self) -> usize {
        self.nodes.capacity() * std::mem::size_of::<RayOctreeNode>()
            + self.split_info.capacity() * 2
            + self.primitives.capacity() * 4
    }

    /// Reorders each leaf's list by `key`, largest first (ties by index): with triangle areas as
    /// keys the list begins with the leaf's local occluders (Octree-o, §III.B.1).
    pub fn sort_leaves_by_key_descending(&mut self, key: impl Fn(u32) -> f32) {
        for n in &self.nodes {
            if n.is_leaf() {
                self.primitives[n.range()].sort_by(|&a, &b| key(b).total_cmp(&key(a)).then(a.cmp(&b)));
            }
        }
    }
}

/// The maximum corner of the lower children of a node with box `b` (the split point of
/// [`child_bounds`]): the centre, except on the axes flagged in bits 0..3 of `flat`, which are
/// not split and which the lower children span whole. The build and [`crate::traverse`] derive
/// children from it alike, so the traversal's boxes are the stored ones.
#[inline]
pub(crate) fn lower_max(b: &Aabb, flat: u16) -> Vec3 {
    cell::select(flat as usize & 7, b.center(), b.max)
}

struct Builder<'a, F> {
    budget: usize,
    boxes: &'a [Aabb],
    overlaps: &'a F,
    config: RayOctreeConfig,
    tree: &'a mut RayOctree,
}

impl<F: Fn(u32, &Aabb) -> bool> Builder<'_, F> {
    fn make_leaf(&mut self, node: usize, list: &[u32]) -> Result<(), RayOctreeError> {
        if self.tree.primitives.len() + list.len() > self.budget {
            return Err(RayOctreeError::TooLarge(self.budget));
        }
        let n = &mut self.tree.nodes[node];
        n.first = self.tree.primitives.len() as u32;
        n.count = list.len() as u32;
        self.tree.primitives.extend_from_slice(list);
        self.tree.leaf_count += 1;
        Ok(())
    }

    fn split(&mut self, node: usize, list: Vec<u32>, depth: u32) -> Result<(), RayOctreeError> {
        self.tree.depth = self.tree.depth.max(depth);
        if stops_splitting(list.len(), self.config.max_leaf_size, depth, self.config.max_depth) {
            return self.make_leaf(node, &list);
        }
        let b = self.tree.nodes[node].bounds;
        // An axis along which the node is flat (a planar mesh) is not split: its upper children
        // are empty, instead of two copies of everything, and its lower ones span it whole.
        let flat = (b.size() - Vec3::splat(b.size().max_element() * 1e-3)).cmple(Vec3::ZERO);
        let split = lower_max(&b, flat.bitmask() as u16);
        let child_box = |i: usize| {
            if i & flat.bitmask() as usize != 0 {
                return Aabb::EMPTY;
            }
            child_bounds(&b, split, i)
        };
        let lists: Vec<Vec<u32>> = (0..8)
            .map(|i| {
                // The overlap test runs on the octant grown by a relative 1e-5: the separating
                // axis test rounds, and would drop triangles lying on the octant's face (a roof
                // at the mesh's top, a floor on a split plane) from every leaf.
                let cb = child_box(i);
                if cb.is_empty() {
                    return Vec::new();
                }
                let grow =
                    Vec3::splat(b.size().max_element() * 1e-5 + b.min.abs().max(b.max.abs()).max_element() * 1e-6);
                let cb = Aabb::new(cb.min - grow, cb.max + grow);
                list.iter()
                    .copied()
                    .filter(|&p| self.boxes[p as usize].overlaps(&cb) && (self.overlaps)(p, &cb))
                    .collect()
            })
            .collect();
        // No progress: every child would hold the whole list (primitives meeting in a point),
        // or primitives are large against the node (each in more than 4 of the 8 children on
        // average: overlapping boxes, big triangles), so splitting multiplies references
        // without separating them.
        let references: usize = lists.iter().map(Vec::len).sum();
        if lists.iter().all(|l| l.len() == list.len()) || references > 4 * list.len() {
            return self.make_leaf(node, &list);
        }
        drop(list);
        let first = self.tree.nodes.len();
        self.tree.nodes[node].first = first as u32;
        self.tree.nodes[node].count = INTERNAL;
        for i in 0..8 {
            self.tree.nodes.push(RayOctreeNode {
                bounds: child_box(i),
                first: 0,
                count: 0,
            });
        }
        for (i, l) in lists.into_iter().enumerate() {
            self.split(first + i, l, depth + 1)?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::super::cell::MAX_OCTREE_DEPTH;
    use super::*;

    fn grid_mesh(n: usize) -> (Vec<Vec3>, Vec<[u32; 3]>) {
        let mut p = Vec::new();
        let mut t = Vec::new();
        for j in 0..=n {
            for i in 0..=n {
                p.push(Vec3::new(i as f32, ((i * 7 + j * 3) % 5) as f32 * 0.1, j as f32));
            }
        }
        let w = (n + 1) as u32;
        for j in 0..n as u32 {
            for i in 0..n as u32 {
                let a = j * w + i;
                t.push([a, a + 1, a + w + 1]);
                t.push([a, a + w + 1, a + w]);
            }
        }
        (p, t)
    }

    #[test]
    fn every_triangle_is_in_a_leaf_and_leaves_respect_the_limits() {
        let (p, t) = grid_mesh(40);
        let cfg = RayOctreeConfig {
            max_depth: 8,
            max_leaf_size: 16,
        };
        let o = RayOctree::build_triangles(&p, &t, cfg).expect("a 40x40 grid mesh builds within the limits");
        let mut seen = vec![false; t.len()];
        for (i, n) in o.nodes().iter().enumerate() {
            if n.is_leaf() {
                for &q in o.leaf_primitives(i as u32) {
                    seen[q as usize] = true;
                    let g = Vec3::splat(1e-3);
                    let grown = Aabb::new(n.bounds.min - g, n.bounds.max + g);
                    assert!(tri_box_overlap(&grown, t[q as usize].map(|v| p[v as usize])));
                }
                assert!(n.count as usize <= cfg.max_leaf_size || o.depth() == cfg.max_depth);
            }
        }
        assert!(seen.iter().all(|&s| s));
        assert!(o.depth() <= 8);
    }

    #[test]
    fn empty_degenerate_and_bad_configs() {
        let o = RayOctree::build_triangles(&[], &[], RayOctreeConfig::default()).expect("an empty input builds");
        assert!(o.is_empty());
        let bad = RayOctreeConfig {
            max_depth: 3,
            max_leaf_size: 0,
        };
        assert!(matches!(
            RayOctree::build_boxes(&[], bad),
            Err(RayOctreeError::BadConfig(_))
        ));
        let deep = RayOctreeConfig {
            max_depth: MAX_OCTREE_DEPTH + 1,
            max_leaf_size: 1,
        };
        assert!(RayOctree::build_boxes(&[], deep).is_err());
        // Many triangles meeting in one point: no progress, one leaf, no endless split.
        let p = vec![Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::Z];
        let t = vec![[0, 1, 2], [0, 2, 3], [0, 3, 1], [0, 1, 3]];
        let cfg = RayOctreeConfig {
            max_depth: 5,
            max_leaf_size: 1,
        };
        let o = RayOctree::build_triangles(&p, &t, cfg).expect("triangles meeting in one point build one leaf");
        assert!(o.leaf_count() >= 1);
        // The same split to depth 20: stopped early or refused by the reference budget, never
        // an unbounded build.
        let deep = RayOctreeConfig {
            max_depth: 20,
            max_leaf_size: 1,
        };
        match RayOctree::build_triangles(&p, &t, deep) {
            Ok(o) => assert!(o.primitives().len() <= 4 * REFERENCES_PER_PRIMITIVE + REFERENCE_SLACK),
            Err(e) => assert!(matches!(e, RayOctreeError::TooLarge(_))),
        }
        // A flat mesh is not split along its flat axis.
        let (gp, gt) = grid_mesh(30);
        let flat: Vec<Vec3> = gp.iter().map(|v| Vec3::new(v.x, 0.0, v.z)).collect();
        let o = RayOctree::build_triangles(
            &flat,
            &gt,
            RayOctreeConfig {
                max_depth: 8,
                max_leaf_size: 4,
            },
        )
        .expect("a flat grid mesh builds");
        for n in o.nodes().iter().filter(|n| !n.is_leaf()) {
            for c in n.children().filter(|c| (c - n.first) & 2 != 0) {
                let child = &o.nodes()[c as usize];
                assert!(child.is_leaf() && child.count == 0);
            }
        }
        // A zero-area (collinear) triangle still lands somewhere.
        let o = RayOctree::build_triangles(&[Vec3::ZERO, Vec3::X, Vec3::X * 2.0], &[[0, 1, 2]], cfg)
            .expect("a collinear triangle builds");
        assert_eq!(o.primitives(), &[0]);
    }

    /// A roof on the top face of the bounds, at a coordinate where the centre/half-extent form
    /// of the separating axis test rounds past the face: it must still be in a leaf that holds
    /// its points.
    #[test]
    fn triangles_on_faces_of_the_bounds_are_kept() {
        let mut p = vec![
            Vec3::new(-3.75, 47.8, 4.25),
            Vec3::new(3.75, 47.8, -4.25),
            Vec3::new(-3.75, 47.8, -4.25),
        ];
        let mut t = vec![[0, 1, 2]];
        for i in 0..200u32 {
            let x = (i % 20) as f32 - 10.0;
            let z = (i / 20) as f32 - 5.0;
            p.extend([
                Vec3::new(x, 0.0, z),
                Vec3::new(x + 0.5, 0.0, z),
                Vec3::new(x, 0.3, z + 0.5),
            ]);
            t.push([3 * i + 3, 3 * i + 4, 3 * i + 5]);
        }
        let o = RayOctree::build_triangles(
            &p,
            &t,
            RayOctreeConfig {
                max_depth: 8,
                max_leaf_size: 4,
            },
        )
        .expect("a triangle soup builds");
        let centroid = (p[0] + p[1] + p[2]) / 3.0;
        let holds =
            o.nodes().iter().enumerate().any(|(i, n)| {
                n.is_leaf() && n.bounds.contains_point(centroid) && o.leaf_primitives(i as u32).contains(&0)
            });
        assert!(holds);
    }

    #[test]
    fn leaves_sorted_by_key() {
        let (p, t) = grid_mesh(10);
        let mut o = RayOctree::build_triangles(&p, &t, RayOctreeConfig::default()).expect("a 10x10 grid mesh builds");
        o.sort_leaves_by_key_descending(|i| i as f32);
        for (i, n) in o.nodes().iter().enumerate() {
            if n.is_leaf() {
                let l = o.leaf_primitives(i as u32);
                assert!(l.windows(2).all(|w| w[0] > w[1]));
            }
        }
    }
}
