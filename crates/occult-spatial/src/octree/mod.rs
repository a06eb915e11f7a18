//! The three octrees, each named for what it is and for the renderer that needs it.
//!
//! | octree | module | renderer | paper | what a node holds |
//! | --- | --- | --- | --- | --- |
//! | [`RayOctree`] | [`ray`] | `lzb` | Han & Zeiger §II.A | flat nodes of 32 bytes; every primitive in every leaf it overlaps (tri–box test); walked by fat rays ([`crate::traverse`]) |
//! | [`HybridOctree`] | [`hybrid`] | `hzb` | Georges §3.1 | cubic cells; a straddler stays at its cell unless small, then goes to every child it overlaps |
//! | [`SampleOctree`] | [`sample`] | `rzb` | Wand et al. §5.3.1 | shortcuts and extended boxes; sections of one distribution list, per area class |
//!
//! They differ where their papers do: what a primitive is (a triangle tested exactly, or a
//! box), where a primitive that crosses a splitting plane goes (every overlapped leaf, the cell
//! itself or its children, the smallest extended box that holds it), how the root cell is made
//! (the primitives' bounds, a cube around them, a cube at their minimum) and what a node stores
//! for its renderer. They share, in [`cell`], what is the same in all three:
//!
//! - the arithmetic of a cell: octant of a point, bounds and minimum corner of a child, with one
//!   bit convention (bit `a` of an octant index set: the upper half on axis `a`);
//! - the stopping rule (leaf size or depth limit) and one depth limit, [`MAX_OCTREE_DEPTH`];
//! - one validation rule: every configuration has a `validate` method, called first by its
//!   build, that checks each field by the rules of [`cell`] and returns an
//!   [`OctreeConfigError`] naming the field and the value. No value is clamped.
//!
//! Depth units: [`RayOctreeConfig::max_depth`] and [`SampleOctreeConfig::max_depth`] count
//! halvings below the root (root 0); [`HybridOctreeConfig::max_depth`] counts levels with the
//! root as level 1, as the hierarchical z-buffer's `depth` parameter always has. Each is
//! bounded by [`MAX_OCTREE_DEPTH`].

pub mod cell;
pub mod hybrid;
pub mod ray;
pub mod sample;

pub use cell::{OctreeConfigError, MAX_OCTREE_DEPTH};
pub use hybrid::{HybridOctree, HybridOctreeConfig, HybridOctreeNode};
pub use ray::{RayOctree, RayOctreeConfig, RayOctreeError, RayOctreeNode};
pub use sample::{DistributionTree, SampleOctree, SampleOctreeConfig, SampleOctreeNode, Sums};
