//! # occult-spatial
//!
//! Spatial hierarchies over scene elements, one per renderer that needs one:
//!
//! | structure | module | used by |
//! | --- | --- | --- |
//! | [`Bvh`]: bounding volume hierarchy over boxes | `bvh` | `frustum`, `nbuffer` |
//! | [`RayOctree`] and fat-ray traversal ([`traverse`]) | [`octree::ray`], [`raycast`] | `lzb` |
//! | [`RayBvh`]: 8-wide BVH over triangles, fat-ray traversal ([`traverse_bvh`]) | [`bvh8`] | `lzb` (`caster=bvh`) |
//! | [`HybridOctree`]: hybrid redistribution of straddlers | [`octree::hybrid`] | `hzb` |
//! | [`SampleOctree`] and [`DistributionTree`]: distribution lists | [`octree::sample`] | `rzb` |
//! | uniform and nested grids | [`grid`] | `oqgrid` |
//!
//! The three octrees share their cell arithmetic, their depth limit and their configuration
//! rules ([`octree::cell`]); [`octree`] says how they differ. All are flat node arrays with
//! `u32` indices.
//!
//! ```
//! use occult_core::{Aabb, Vec3};
//! use occult_spatial::Bvh;
//! let boxes: Vec<Aabb> = (0..100).map(|i| Aabb::new(Vec3::splat(i as f32), Vec3::splat(i as f32 + 0.5))).collect();
//! let bvh = Bvh::build(&boxes, 4);
//! assert_eq!(bvh.primitive_indices().len(), 100);
//! assert!(bvh.nodes()[0].bounds.contains_point(Vec3::splat(99.5)));
//! ```
#![deny(missing_docs)]

mod bvh;
pub mod bvh8;
pub mod grid;
pub mod octree;
pub mod packet;
pub mod raycast;

pub use bvh::{Bvh, BvhNode};
pub use bvh8::{
    traverse_bvh, traverse_bvh_from, traverse_bvh_scalar, RayBvh, RayBvhConfig, RayBvhError, RayBvhNode, MAX_BVH_LEAF,
};
pub use octree::{
    DistributionTree, HybridOctree, HybridOctreeConfig, HybridOctreeNode, OctreeConfigError, RayOctree,
    RayOctreeConfig, RayOctreeError, RayOctreeNode, SampleOctree, SampleOctreeConfig, SampleOctreeNode,
    MAX_OCTREE_DEPTH,
};
pub use packet::{traverse_bvh_packet, traverse_bvh_packet_scalar, RayPacket, PACKET};
pub use raycast::{
    intersect8_packet, intersect8_packet_scalar, prefetch_triangles, traverse, traverse_scalar, Candidates8, FatRay,
    LeafTriangle, ShearedRay, TraversalCounters,
};
