//! A bounding volume hierarchy over boxes, built by median splits.
//!
//! Built top-down: each node splits its primitives at the median centroid along the longest
//! axis of the centroids' bounds (O(n log n), no surface-area heuristic: it serves frustum
//! and occlusion culling, where balanced, spatially compact leaves matter more than ray cost).
//! Nodes are stored depth-first in one flat array: a node's first child follows it, and its
//! primitives (leaf) or subtree primitives (inner) form one contiguous range of
//! [`Bvh::primitive_indices`].

use occult_core::{Aabb, Vec3};

/// A node: bounds, its range of primitive indices, and (inner nodes) its second child.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BvhNode {
    /// Bounds of everything below.
    pub bounds: Aabb,
    /// First entry of this subtree in [`Bvh::primitive_indices`].
    pub first: u32,
    /// Entries of this subtree in [`Bvh::primitive_indices`].
    pub count: u32,
    /// Index of the second child; 0 for a leaf (the first child is always `self + 1`).
    pub second_child: u32,
}

const _: () = assert!(std::mem::size_of::<BvhNode>() == 36);

impl BvhNode {
    /// True for a leaf.
    #[inline]
    pub fn is_leaf(&self) -> bool {
        self.second_child == 0
    }
    /// The range of primitive-index entries below this node.
    #[inline]
    pub fn range(&self) -> std::ops::Range<usize> {
        self.first as usize..(self.first + self.count) as usize
    }
}

/// The hierarchy.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Bvh {
    nodes: Vec<BvhNode>,
    indices: Vec<u32>,
}

impl Bvh {
    /// Builds over `boxes` with at most `leaf_size` primitives per leaf (at least 1). Empty
    /// boxes are kept (they never pass a culling test). No nodes for no boxes.
    ///
    /// # Panics
    /// If there are more than `u32::MAX` boxes (a programmer error; meshes index with `u32`).
    pub fn build(boxes: &[Aabb], leaf_size: usize) -> Self {
        assert!(boxes.len() <= u32::MAX as usize, "too many primitives for a u32 BVH");
        let leaf_size = leaf_size.max(1);
        let mut indices: Vec<u32> = (0..boxes.len() as u32).collect();
        let centroids: Vec<Vec3> = boxes
            .iter()
            .map(|b| if b.is_empty() { Vec3::ZERO } else { b.center() })
            .collect();
        let mut nodes = Vec::with_capacity(2 * boxes.len() / leaf_size + 1);
        if !boxes.is_empty() {
            build_node(boxes, &centroids, &mut indices, 0, leaf_size, &mut nodes);
        }
        Self { nodes, indices }
    }

    /// Nodes, root first (empty for no primitives).
    #[inline]
    pub fn nodes(&self) -> &[BvhNode] {
        &self.nodes
    }
    /// Primitive indices in leaf order.
    #[inline]
    pub fn primitive_indices(&self) -> &[u32] {
        &self.indices
    }
    /// Bytes held.
    pub fn memory_bytes(&self) -> usize {
        self.nodes.len() * std::mem::size_of::<BvhNode>() + self.indices.len() * 4
    }
}

fn build_node(
    boxes: &[Aabb],
    centroids: &[Vec3],
    indices: &mut [u32],
    first: u32,
    leaf_size: usize,
    nodes: &mut Vec<BvhNode>,
) {
    let bounds = indices.iter().fold(Aabb::EMPTY, |b, &i| b.union(boxes[i as usize]));
    let me = nodes.len();
    nodes.push(BvhNode {
        bounds,
        first,
        count: indices.len() as u32,
        second_child: 0,
    });
    if indices.len() <= leaf_size {
        return;
    }
    let cb = Aabb::from_points(indices.iter().map(|&i| centroids[i as usize]));
    let axis = cb.size().max_position();
    let mid = indices.len() / 2;
    indices.select_nth_unstable_by(mid, |&a, &b| {
        centroids[a as usize][axis]
            .total_cmp(&centroids[b as usize][axis])
            .then(a.cmp(&b))
    });
    let (left, right) = indices.split_at_mut(mid);
    build_node(boxes, centroids, left, first, leaf_size, nodes);
    let second = nodes.len() as u32;
    nodes[me].second_child = second;
    build_node(boxes, centroids, right, first + mid as u32, leaf_size, nodes);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn empty_and_single() {
        assert!(Bvh::build(&[], 4).nodes().is_empty());
        let b = Bvh::build(&[Aabb::new(Vec3::ZERO, Vec3::ONE)], 4);
        assert_eq!(b.nodes().len(), 1);
        assert!(b.nodes()[0].is_leaf());
    }

    #[test]
    fn every_primitive_in_exactly_one_leaf_and_bounds_nest() {
        let boxes: Vec<Aabb> = (0..1000)
            .map(|i| {
                let p = Vec3::new((i * 7 % 31) as f32, (i * 13 % 17) as f32, (i % 11) as f32);
                Aabb::new(p, p + 0.5)
            })
            .collect();
        let bvh = Bvh::build(&boxes, 8);
        let mut seen = vec![0; boxes.len()];
        for (k, n) in bvh.nodes().iter().enumerate() {
            for &i in &bvh.primitive_indices()[n.range()] {
                assert!(n.bounds.overlaps(&boxes[i as usize]));
                assert_eq!(n.bounds.union(boxes[i as usize]), n.bounds);
            }
            if n.is_leaf() {
                assert!(n.count <= 8);
                for &i in &bvh.primitive_indices()[n.range()] {
                    seen[i as usize] += 1;
                }
            } else {
                let (l, r) = (bvh.nodes()[k + 1], bvh.nodes()[n.second_child as usize]);
                assert_eq!(l.count + r.count, n.count);
                assert_eq!(l.first, n.first);
                assert_eq!(r.first, n.first + l.count);
            }
        }
        assert!(seen.iter().all(|&s| s == 1));
    }
}
