//! Per-node preprocessing shared by the renderers that build a hierarchy inside each scene
//! node: the boxes a node's hierarchy is built over, and one parallel pass over the nodes.

use occult_core::{Aabb, Instance, Mesh, Node, Scene};
use occult_raster::Rasterizer;
use rayon::prelude::*;

/// The bounds of each triangle of `mesh`, in triangle order (the primitives of a mesh node's
/// hierarchy).
pub(crate) fn triangle_boxes(mesh: &Mesh) -> Vec<Aabb> {
    (0..mesh.triangle_count())
        .map(|t| Aabb::from_points(mesh.triangle_positions(t)))
        .collect()
}

/// The bounds of each instance of a group node, in the group's space, in instance order (the
/// primitives of a group node's hierarchy).
pub(crate) fn instance_boxes(scene: &Scene, instances: &[Instance]) -> Vec<Aabb> {
    instances
        .iter()
        .map(|i| scene.node(i.child).bounds().transformed(&i.parent_from_child))
        .collect()
}

/// `build` applied to every node of `scene`, in parallel on `raster`'s thread pool, collected in
/// node order (into a `Vec`, or a `Result` of one that stops at an error).
pub(crate) fn per_node<T: Send, C: FromParallelIterator<T> + Send>(
    raster: &Rasterizer,
    scene: &Scene,
    build: impl Fn(&Node) -> T + Sync + Send,
) -> C {
    raster.install(|| scene.nodes().par_iter().map(build).collect())
}
