//! # occult-core
//!
//! Geometry and the scene model shared by every layer of occult: math types (re-exported from
//! [`glam`]), [`Aabb`], [`Plane`], [`Frustum`], [`Camera`]/[`View`], [`Ray`], [`Mesh`], and the
//! instancing DAG [`Scene`], plus the two exact primitive tests the hierarchies need
//! ([`tri_box_overlap`], [`intersect_ray_triangle`]), and the one SIMD module ([`simd`]: the
//! instruction set detected once, the per-instruction-set kernel dispatch, lane types).
//!
//! ## Conventions (fixed here, once, for the whole engine)
//! - **Handedness**: right-handed world, `+y` up; a camera looks down its `-z` axis.
//! - **Matrices** are named `dst_from_src` (`clip_from_world`, `world_from_object`) and compose
//!   right to left: `clip_from_object = clip_from_world * world_from_object`.
//! - **Projection**: reversed-Z with an infinite far plane in clip space
//!   (`clip = (x, y, near, w)`, `w` = distance along the view axis), so the stored depth
//!   `z_ndc = near / w` is `1` at the near plane and falls towards `0` with distance. Greater
//!   depth is **nearer**. The far plane is applied per fragment (`z_ndc < near / far` is
//!   discarded) and by culling, never by clipping.
//! - **Item ids**: a triangle instance is named by its rank in the depth-first enumeration of the
//!   scene DAG ([`Scene::item_count`] in all); [`NO_ITEM`] means "no triangle".
//! - **Transform composition** is always done with [`compose`] walking down from the root, so
//!   every renderer produces bit-identical `world_from_object` matrices for the same instance.
//!
//! ```
//! use occult_core::{Camera, Mesh, SceneBuilder, View, Vec3};
//! # fn main() -> Result<(), occult_core::CoreError> {
//! let mesh = Mesh::new(vec![Vec3::ZERO, Vec3::X, Vec3::Y], vec![[0, 1, 2]])?;
//! let mut builder = SceneBuilder::new();
//! let node = builder.add_mesh("triangle", mesh)?;
//! let scene = builder.build(node)?;
//! assert_eq!(scene.item_count(), 1);
//! let view = View::new(Camera::look_at(Vec3::new(0.3, 0.3, 2.0), Vec3::ZERO), 64, 64)?;
//! assert!(view.frustum(&glam::Affine3A::IDENTITY).intersects_aabb(&scene.bounds()));
//! # Ok(())
//! # }
//! ```
#![deny(missing_docs)]

mod camera;
mod error;
mod geom;
pub mod memory;
mod mesh;
mod ray;
mod scene;
pub mod simd;
mod tri_box;

pub use camera::{check_resolution, Camera, View, MAX_PIXEL_COUNT, MAX_RESOLUTION};
pub use error::{CoreError, Result};
pub use geom::{Aabb, Containment, Frustum, Plane};
pub use glam::{self, Affine3A, Mat3, Mat4, Vec2, Vec3, Vec3A, Vec4};
pub use mesh::{Mesh, MeshColors, Rgba8};
pub use ray::{intersect_ray_triangle, sheared_edge_functions, Ray, RayHit};
pub use scene::{
    compose, Instance, ItemId, ItemLocation, Node, NodeId, NodeKind, Scene, SceneBuilder, MAX_FLATTEN_TRIANGLES,
    NO_ITEM,
};
pub use tri_box::tri_box_overlap;
