//! The hybrid octree of hierarchical z-buffer visibility: an octree over boxes with the hybrid
//! redistribution of straddling primitives.
//!
//! # References
//! - C. Georges, *Obscuration Culling on Parallel Graphics Architectures*, UNC TR95-017 (1995),
//!   §3.1, after N. Greene, M. Kass, G. Miller, *Hierarchical Z-Buffer Visibility* (SIGGRAPH 1993).
//!
//! Built top-down (§3.1): a cell whose primitive count exceeds the leaf size, and which is not
//! at the depth limit, is split into eight equal octants by the three axis-aligned planes that
//! bisect it ([`super::cell`]). A primitive wholly inside one octant goes to that child. A
//! primitive that straddles a splitting plane stays at the cell ("associated with the cube
//! itself") unless it is *small* compared to the cell (its largest extent at most
//! `small_fraction` × the cell's side): then it goes to every child it overlaps and is flagged
//! [`HybridOctree::is_shared`], so that a renderer draws it once per frame (a frame stamp)
//! although several nodes hold it.
//!
//! Primitives are boxes in one object space: the triangles of a mesh, or the instances of a
//! group (an instance whose prototype has its own octree is a primitive with a transform; the
//! renderer descends into the prototype's octree when the instance is reached).
//!
//! Each node keeps two boxes: `bounds`, the union of the boxes of every primitive in its
//! subtree (tighter than the cell, and containing the shared primitives whole), which is what
//! culling tests; and `own_bounds`, the union of its own primitives only. Nodes are stored
//! depth-first in one flat array; a node's primitives are one contiguous range of
//! [`HybridOctree::indices`].
//!
//! Cost: O(n · depth) to build. Redistribution can duplicate small primitives; the duplicates
//! are bounded (a primitive is copied only while the cell is at least `1 / small_fraction`
//! times its size, and the total is capped at [`MAX_DUPLICATION`] × n, past which straddling
//! primitives stay at their cell).

use super::cell::{self, child_min, octant_of, stops_splitting, OctreeConfigError};
use occult_core::{Aabb, Vec3};

/// Hard cap on index entries per primitive (duplicates from redistribution included).
pub const MAX_DUPLICATION: usize = 4;

/// How to build a [`HybridOctree`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HybridOctreeConfig {
    /// A cell with at most this many primitives is a leaf (≥ 1).
    pub leaf_size: usize,
    /// Levels at most, the root being level 1 (1..=[`cell::MAX_OCTREE_DEPTH`]).
    pub max_depth: u32,
    /// A straddling primitive whose largest extent is at most this fraction of the cell's side
    /// is passed to every child it overlaps; 0 keeps every straddler at its cell (§3.1's
    /// "associate with the parent" strategy alone). In [0, 1].
    pub small_fraction: f32,
}

impl HybridOctreeConfig {
    /// Checks the leaf size, the depth in levels, then the fraction, by the rules of
    /// [`super::cell`] (the build calls it first; nothing is clamped).
    ///
    /// # Errors
    /// [`OctreeConfigError`] naming `leaf_size`, `max_depth` or `small_fraction` and the value
    /// out of range.
    pub fn validate(&self) -> Result<(), OctreeConfigError> {
        cell::check_leaf_size("leaf_size", self.leaf_size)?;
        cell::check_depth("max_depth", self.max_depth, 1)?;
        cell::check_fraction("small_fraction", self.small_fraction, 0.0, 1.0)
    }
}

impl Default for HybridOctreeConfig {
    fn default() -> Self {
        Self {
            leaf_size: 64,
            max_depth: 12,
            small_fraction: 0.25,
        }
    }
}

/// Marks an absent child.
pub const NO_CHILD: u32 = u32::MAX;

/// A node of the hybrid octree.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HybridOctreeNode {
    /// Union of the boxes of every primitive in the subtree.
    pub bounds: Aabb,
    /// Union of the boxes of this node's own primitives (empty when it has none).
    pub own_bounds: Aabb,
    /// Centre of the cell (the point where its splitting planes meet).
    pub center: Vec3,
    /// Children by octant (bit 0: +x, bit 1: +y, bit 2: +z half); [`NO_CHILD`] when empty.
    pub children: [u32; 8],
    /// First entry of this node's own primitives in [`HybridOctree::indices`].
    pub first: u32,
    /// Number of this node's own primitives.
    pub count: u32,
    /// Primitive entries in the whole subtree (duplicates counted): the work below it.
    pub subtree_count: u32,
}

const _: () = assert!(std::mem::size_of::<HybridOctreeNode>() == 104);

impl HybridOctreeNode {
    /// The range of this node's own primitives in [`HybridOctree::indices`].
    #[inline]
    pub fn range(&self) -> std::ops::Range<usize> {
        self.first as usize..(self.first + self.count) as usize
    }
    /// True when no child exists.
    #[inline]
    pub fn is_leaf(&self) -> bool {
        self.children.iter().all(|&c| c == NO_CHILD)
    }
}

/// The octree: flat nodes (root at 0, none when there are no primitives), own-primitive lists.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct HybridOctree {
    nodes: Vec<HybridOctreeNode>,
    indices: Vec<u32>,
    shared: Vec<bool>,
}

struct Builder<'a> {
    boxes: &'a [Aabb],
    config: HybridOctreeConfig,
    nodes: Vec<HybridOctreeNode>,
    indices: Vec<u32>,
    shared: Vec<bool>,
    /// Index entries still allowed beyond one per primitive.
    duplicate_budget: usize,
}

impl HybridOctree {
    /// Builds over `boxes` (one per primitive, in one object space). Empty boxes (primitives with
    /// no points) stay at the root.
    ///
    /// # Errors
    /// [`OctreeConfigError`] for a configuration out of range ([`HybridOctreeConfig::validate`]).
    ///
    /// # Panics
    /// If there are more than `u32::MAX / MAX_DUPLICATION` boxes (meshes index with `u32`).
    pub fn build(boxes: &[Aabb], config: &HybridOctreeConfig) -> Result<Self, OctreeConfigError> {
        assert!(
            boxes.len() <= (u32::MAX as usize) / MAX_DUPLICATION,
            "too many primitives for a u32 octree"
        );
        config.validate()?;
        if boxes.is_empty() {
            return Ok(Self::default());
        }
        let mut b = Builder {
            boxes,
            config: *config,
            nodes: Vec::new(),
            indices: Vec::with_capacity(boxes.len()),
            shared: vec![false; boxes.len()],
            duplicate_budget: boxes.len() * (MAX_DUPLICATION - 1),
        };
        let all = boxes.iter().fold(Aabb::EMPTY, |a, x| a.union(*x));
        let (root_cell_min, side) = if all.is_empty() {
            (Vec3::ZERO, 0.0)
        } else {
            // A cube around the bounds (§3.1: octree cells are cubes).
            let side = all.size().max_element();
            (all.center() - Vec3::splat(0.5 * side), side)
        };
        let (empty, prims): (Vec<u32>, Vec<u32>) = (0..boxes.len() as u32).partition(|&i| boxes[i as usize].is_empty());
        b.node(root_cell_min, side, prims, 1, &empty);
        Ok(Self {
            nodes: b.nodes,
            indices: b.indices,
            shared: b.shared,
        })
    }

    /// The nodes, root first (empty for no primitives).
    pub fn nodes(&self) -> &[HybridOctreeNode] {
        &self.nodes
    }

    /// Own-primitive lists of all nodes, concatenated (see [`HybridOctreeNode::range`]).
    pub fn indices(&self) -> &[u32] {
        &self.indices
    }

    /// The own primitives of node `node_index`.
    #[inline]
    pub fn node_primitives(&self, node_index: u32) -> &[u32] {
        &self.indices[self.nodes[node_index as usize].range()]
    }

    /// True when primitive `primitive_index` is held by more than one node (§3.1: a small
    /// straddler passed to every child it overlaps; draw it once per frame).
    #[inline]
    pub fn is_shared(&self, primitive_index: u32) -> bool {
        self.shared[primitive_index as usize]
    }

    /// Number of primitives it was built over.
    pub fn primitive_count(&self) -> usize {
        self.shared.len()
    }

    /// Number of primitives held by several nodes.
    pub fn shared_count(&self) -> usize {
        self.shared.iter().filter(|&&s| s).count()
    }

    /// The children of `node_index` in front-to-back order for an eye at `eye` (object space):
    /// the octant holding the eye first, the opposite last (exact for the cells, a heuristic
    /// for the tight bounds). Returns the array and how many of its entries are valid.
    pub fn children_front_to_back(&self, node_index: u32, eye: Vec3) -> ([u32; 8], usize) {
        let n = &self.nodes[node_index as usize];
        let mask = octant_of(n.center, eye);
        let mut out = [NO_CHILD; 8];
        let mut k = 0;
        // Octants in order of the number of planes separating them from the eye's octant.
        for bits in [0usize, 1, 2, 4, 3, 5, 6, 7] {
            let c = n.children[bits ^ mask];
            if c != NO_CHILD {
                out[k] = c;
                k += 1;
            }
        }
        (out, k)
    }

    /// Bytes held.
    pub fn memory_bytes(&self) -> usize {
        self.nodes.capacity() * std::mem::size_of::<HybridOctreeNode>()
            + self.indices.capacity() * 4
            + self.shared.capacity()
    }
}

impl Builder<'_> {
    /// Builds the node for the cell at `cell_min` of side `side` holding `prims` (plus `extra`,
    /// which always stays at this node); returns its index.
    fn node(&mut self, cell_min: Vec3, side: f32, prims: Vec<u32>, level: u32, extra: &[u32]) -> u32 {
        let index = self.nodes.len() as u32;
        let center = cell_min + Vec3::splat(0.5 * side);
        self.nodes.push(HybridOctreeNode {
            bounds: Aabb::EMPTY,
            own_bounds: Aabb::EMPTY,
            center,
            children: [NO_CHILD; 8],
            first: 0,
            count: 0,
            subtree_count: 0,
        });
        let mut own: Vec<u32> = extra.to_vec();
        let mut parts: [Vec<u32>; 8] = Default::default();
        if stops_splitting(prims.len(), self.config.leaf_size, level, self.config.max_depth) || side <= 0.0 {
            own.extend_from_slice(&prims);
        } else {
            let small = self.config.small_fraction * side;
            for &p in &prims {
                let b = &self.boxes[p as usize];
                // Per axis: bit set in `lo` when the box reaches the low half, in `hi` the high.
                let mut lo = [false; 3];
                let mut hi = [false; 3];
                for a in 0..3 {
                    lo[a] = b.min[a] < center[a];
                    hi[a] = b.max[a] >= center[a];
                }
                let touches = |o: usize| (0..3).all(|a| if o >> a & 1 != 0 { hi[a] } else { lo[a] });
                let octant_count = (0..8).filter(|&o| touches(o)).count();
                if octant_count == 1 {
                    let o = (0..8).find(|&o| touches(o)).unwrap_or(0); // exactly one exists
                    parts[o].push(p);
                } else if b.size().max_element() <= small && self.duplicate_budget >= octant_count - 1 {
                    // §3.1 hybrid: a small straddler goes to every child it overlaps.
                    self.duplicate_budget -= octant_count - 1;
                    self.shared[p as usize] = true;
                    for (o, part) in parts.iter_mut().enumerate() {
                        if touches(o) {
                            part.push(p);
                        }
                    }
                } else {
                    // §3.1: a large straddler stays with the cube itself.
                    own.push(p);
                }
            }
        }
        drop(prims);
        let first = self.indices.len() as u32;
        let mut own_bounds = Aabb::EMPTY;
        for &p in &own {
            own_bounds = own_bounds.union(self.boxes[p as usize]);
        }
        self.indices.extend_from_slice(&own);
        let mut bounds = own_bounds;
        let mut subtree_count = own.len() as u32;
        let half = 0.5 * side;
        for (o, part) in parts.into_iter().enumerate() {
            if part.is_empty() {
                continue;
            }
            // The centre is `cell_min + half` to the bit: the upper octants start there.
            let c = self.node(child_min(cell_min, center, o), half, part, level + 1, &[]);
            let cn = self.nodes[c as usize];
            bounds = bounds.union(cn.bounds);
            subtree_count += cn.subtree_count;
            self.nodes[index as usize].children[o] = c;
        }
        let n = &mut self.nodes[index as usize];
        n.bounds = bounds;
        n.own_bounds = own_bounds;
        n.first = first;
        n.count = own.len() as u32;
        n.subtree_count = subtree_count;
        index
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid_boxes(n: usize, size: f32) -> Vec<Aabb> {
        let mut v = Vec::new();
        for i in 0..n {
            let p = Vec3::new((i % 17) as f32, ((i / 17) % 13) as f32, (i / 221) as f32) * 1.3;
            v.push(Aabb::new(p, p + Vec3::splat(size)));
        }
        v
    }

    /// Every primitive is held at least once, unshared ones exactly once, each by nodes whose
    /// bounds contain it; subtree bounds contain the children's; counts add up.
    fn check(t: &HybridOctree, boxes: &[Aabb], config: &HybridOctreeConfig) {
        let mut held = vec![0usize; boxes.len()];
        for (i, n) in t.nodes().iter().enumerate() {
            let mut sub = n.count;
            for &p in t.node_primitives(i as u32) {
                held[p as usize] += 1;
                let b = boxes[p as usize];
                if !b.is_empty() {
                    assert!(n.own_bounds.union(b) == n.own_bounds);
                    assert!(n.bounds.union(b) == n.bounds);
                }
            }
            for &c in n.children.iter().filter(|&&c| c != NO_CHILD) {
                assert!(c as usize > i);
                let cn = &t.nodes()[c as usize];
                assert!(n.bounds.union(cn.bounds) == n.bounds);
                sub += cn.subtree_count;
            }
            assert_eq!(sub, n.subtree_count);
            if !n.is_leaf() {
                // Inner nodes keep only straddlers (never more than all of their primitives).
                assert!(n.count as usize <= boxes.len());
            }
        }
        for (p, &h) in held.iter().enumerate() {
            assert!(h >= 1, "primitive {p} lost");
            if !t.is_shared(p as u32) {
                assert_eq!(h, 1, "unshared primitive {p} held {h} times");
            }
        }
        let total: usize = held.iter().sum();
        assert!(total <= boxes.len() * MAX_DUPLICATION);
        let depth = depth_of(t, 0);
        assert!(depth <= config.max_depth);
    }

    /// The octree of `boxes` with that configuration, checked by [`check`].
    fn build_checked(boxes: &[Aabb], leaf_size: usize, max_depth: u32, small_fraction: f32) -> HybridOctree {
        let config = HybridOctreeConfig {
            leaf_size,
            max_depth,
            small_fraction,
        };
        let t = HybridOctree::build(boxes, &config).expect("a valid configuration builds");
        check(&t, boxes, &config);
        t
    }

    fn depth_of(t: &HybridOctree, n: u32) -> u32 {
        1 + t.nodes()[n as usize]
            .children
            .iter()
            .filter(|&&c| c != NO_CHILD)
            .map(|&c| depth_of(t, c))
            .max()
            .unwrap_or(0)
    }

    #[test]
    fn empty_input_has_no_nodes() {
        let t = HybridOctree::build(&[], &HybridOctreeConfig::default()).expect("an empty input builds");
        assert!(t.nodes().is_empty());
        assert!(t.indices().is_empty());
    }

    #[test]
    fn small_input_is_one_leaf() {
        let boxes = grid_boxes(10, 0.5);
        let t = HybridOctree::build(&boxes, &HybridOctreeConfig::default()).expect("ten boxes build");
        assert_eq!(t.nodes().len(), 1);
        assert!(t.nodes()[0].is_leaf());
        assert_eq!(t.nodes()[0].count, 10);
    }

    #[test]
    fn subdivides_and_holds_everything() {
        for small in [0.0, 0.1, 0.25, 1.0] {
            for leaf in [1, 4, 64] {
                for size in [0.1, 1.0, 3.0] {
                    let t = build_checked(&grid_boxes(1000, size), leaf, 8, small);
                    if leaf < 1000 {
                        assert!(t.nodes().len() > 1);
                    }
                    if small == 0.0 {
                        assert_eq!(t.shared_count(), 0);
                    }
                }
            }
        }
    }

    #[test]
    fn small_straddlers_are_redistributed_large_ones_stay() {
        // Two clusters, and one tiny and one huge box across the x = centre plane.
        let mut boxes = grid_boxes(200, 0.2);
        let c = boxes.iter().fold(Aabb::EMPTY, |a, b| a.union(*b)).center();
        let tiny = boxes.len() as u32;
        boxes.push(Aabb::new(c - Vec3::splat(0.01), c + Vec3::splat(0.01)));
        let huge = boxes.len() as u32;
        boxes.push(Aabb::new(c - Vec3::splat(5.0), c + Vec3::splat(5.0)));
        let t = build_checked(&boxes, 8, 6, 0.25);
        assert!(t.is_shared(tiny));
        assert!(!t.is_shared(huge));
        assert!(t.node_primitives(0).contains(&huge));
        assert!(!t.node_primitives(0).contains(&tiny));
    }

    #[test]
    fn degenerate_boxes_terminate() {
        // All primitives at one point (zero size, on every splitting plane), and empty boxes.
        let mut boxes = vec![Aabb::new(Vec3::ONE, Vec3::ONE); 500];
        boxes.push(Aabb::EMPTY);
        let t = build_checked(&boxes, 1, 32, 1.0);
        assert!(t.node_primitives(0).contains(&500));
        // Depth 1 is a single leaf.
        let t = build_checked(&grid_boxes(300, 0.3), 1, 1, 0.5);
        assert_eq!(t.nodes().len(), 1);
    }

    /// Values the build used to clamp are errors naming the field; the deepest limit builds.
    #[test]
    fn bad_configs_are_errors() {
        let boxes = grid_boxes(50, 0.5);
        let d = HybridOctreeConfig::default();
        for (bad, field) in [
            (HybridOctreeConfig { leaf_size: 0, ..d }, "leaf_size"),
            (HybridOctreeConfig { max_depth: 0, ..d }, "max_depth"),
            (
                HybridOctreeConfig {
                    max_depth: cell::MAX_OCTREE_DEPTH + 1,
                    ..d
                },
                "max_depth",
            ),
            (
                HybridOctreeConfig {
                    small_fraction: -0.1,
                    ..d
                },
                "small_fraction",
            ),
            (
                HybridOctreeConfig {
                    small_fraction: f32::NAN,
                    ..d
                },
                "small_fraction",
            ),
        ] {
            assert_eq!(HybridOctree::build(&boxes, &bad).unwrap_err().field, field);
            assert_eq!(HybridOctree::build(&[], &bad).unwrap_err().field, field);
        }
        build_checked(&boxes, 1, cell::MAX_OCTREE_DEPTH, 1.0);
    }

    #[test]
    fn children_order_starts_at_the_eye() {
        let boxes = grid_boxes(2000, 0.2);
        let t = HybridOctree::build(&boxes, &HybridOctreeConfig::default()).expect("2000 boxes build");
        let root = &t.nodes()[0];
        let eye = root.center + Vec3::new(-100.0, -100.0, -100.0);
        let (order, k) = t.children_front_to_back(0, eye);
        assert!(k > 1);
        assert_eq!(order[0], root.children[0]);
        let d = |c: u32| t.nodes()[c as usize].center.distance(eye);
        assert!(d(order[0]) <= d(order[k - 1]));
    }
}
