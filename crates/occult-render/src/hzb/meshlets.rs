//! Each mesh octree node's own triangles as clusters of few vertices, so that a node draws as a
//! cluster draw ([`DrawTriangles::Clusters`](occult_raster::DrawTriangles::Clusters)) rather
//! than as an index list.
//!
//! An index list projects three corners a triangle, gathered one by one; a node's cluster
//! keeps its distinct vertices in a row and projects each once, about a corner a triangle on
//! a closed mesh (the cost `clusters` measured: list draws of the same triangles were 1.4×
//! slower on the `city:blocks=32` orbit). Only the unshared triangles of a node are clustered:
//! a shared one (a straddler held by several nodes, §3.1) is drawn once a frame, which its
//! stamp decides when the node is drawn, so it stays in an index list.

use occult_raster::Meshlets;
use occult_spatial::HybridOctree;

use crate::{RenderError, Result};

/// The clusters of one mesh octree's nodes.
pub(super) struct NodeMeshlets {
    meshlets: Meshlets,
    /// Node `n`'s clusters are `ids[first[n]..first[n + 1]]`.
    first: Vec<u32>,
    /// `0..meshlets.len()`: a node's clusters are consecutive, so its list is a slice of this.
    ids: Vec<u32>,
}

impl NodeMeshlets {
    /// The clusters of the unshared own triangles of every node of `octree`, built over
    /// `mesh`.
    ///
    /// # Errors
    /// [`RenderError::Raster`] where the octree names a triangle the mesh lacks.
    pub(super) fn build(mesh: &occult_core::Mesh, octree: &HybridOctree) -> Result<Self> {
        let nodes = octree.nodes().len() as u32;
        let mut triangles = Vec::with_capacity(octree.primitive_count());
        let mut runs = Vec::with_capacity(nodes as usize + 1);
        runs.push(0);
        for n in 0..nodes {
            triangles.extend(octree.node_primitives(n).iter().filter(|&&p| !octree.is_shared(p)));
            runs.push(triangles.len() as u32);
        }
        let (meshlets, first) = Meshlets::from_runs(mesh, &triangles, &runs).map_err(RenderError::Raster)?;
        let ids = (0..meshlets.len() as u32).collect();
        Ok(Self { meshlets, first, ids })
    }

    /// The mesh's clusters, and those holding node `n`'s unshared own triangles.
    #[inline]
    pub(super) fn node(&self, n: u32) -> (&Meshlets, &[u32]) {
        let list = &self.ids[self.first[n as usize] as usize..self.first[n as usize + 1] as usize];
        (&self.meshlets, list)
    }

    /// Bytes held.
    pub(super) fn memory_bytes(&self) -> usize {
        self.meshlets.memory_bytes() + (self.first.capacity() + self.ids.capacity()) * 4
    }
}
