//! # occult-spatial
//!
//! Spatial hierarchies over scene elements: a bounding volume hierarchy ([`Bvh`]) over boxes
//! (triangles of a mesh, instances of a group), with flat node arrays and `u32` indices.
//! Octrees, uniform and nested grids, traversal orders and ray traversal join it as the
//! renderers that need them arrive.
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
pub mod grid;
pub mod octree;
pub mod octree_hybrid;
pub mod raycast;
pub mod sample_octree;

pub use bvh::{Bvh, BvhNode};
pub use octree::{Octree, OctreeConfig, OctreeError, OctreeNode};
pub use octree_hybrid::HybridOctree;
pub use raycast::{prefetch_triangles, traverse, traverse_scalar, FatRay, LeafTriangle, ShearedRay, TraversalCounters};
