//! A hierarchy's triangle lists as clusters of few vertices, so that a part of a mesh draws as a
//! cluster draw ([`DrawTriangles::Clusters`](occult_raster::DrawTriangles::Clusters)) rather
//! than as an index list.
//!
//! An index list projects three corners a triangle, gathered one by one; a cluster keeps its
//! distinct vertices in a row and projects each once, about a corner a triangle on a closed
//! mesh (the cost `clusters` measured: list draws of the same triangles were 1.4× slower on the
//! `city:blocks=32` orbit). A hierarchy's lists (an octree node's own triangles, a BVH leaf's)
//! are runs of one array; each run is cut into clusters of at most
//! [`occult_raster::MAX_CLUSTER_VERTICES`] vertices, so that any run, or any span of
//! consecutive runs (a BVH subtree), is a slice of cluster indices.

use std::ops::Range;

use occult_core::Mesh;
use occult_raster::Meshlets;

use crate::{RenderError, Result};

/// The clusters of runs of a mesh's triangles.
pub(crate) struct RunClusters {
    meshlets: Meshlets,
    /// Where each run starts in the triangle array, then its end.
    starts: Vec<u32>,
    /// Run `r`'s clusters are `ids[first[r]..first[r + 1]]`.
    first: Vec<u32>,
    /// `0..meshlets.len()`: consecutive runs have consecutive clusters, so their list is a
    /// slice of this.
    ids: Vec<u32>,
}

impl RunClusters {
    /// The clusters of `mesh`'s triangles `triangles`, cut in runs at `starts` (beginning at
    /// 0, never decreasing, ending at `triangles.len()`).
    ///
    /// # Errors
    /// [`RenderError::Raster`] for bad `starts` or a triangle the mesh lacks.
    pub(crate) fn build(mesh: &Mesh, triangles: &[u32], starts: Vec<u32>) -> Result<Self> {
        let (meshlets, first) = Meshlets::from_runs(mesh, triangles, &starts).map_err(RenderError::Raster)?;
        let ids = (0..meshlets.len() as u32).collect();
        Ok(Self {
            meshlets,
            starts,
            first,
            ids,
        })
    }

    /// The mesh's clusters.
    pub(crate) fn meshlets(&self) -> &Meshlets {
        &self.meshlets
    }

    /// The mesh's clusters, and those of runs `runs`.
    #[inline]
    pub(crate) fn runs(&self, runs: Range<usize>) -> (&Meshlets, &[u32]) {
        let list = &self.ids[self.first[runs.start] as usize..self.first[runs.end] as usize];
        (&self.meshlets, list)
    }

    /// The mesh's clusters, and those of the runs that make up entries `entries` of the
    /// triangle array; `None` unless both ends are where runs start (or the end).
    pub(crate) fn entries(&self, entries: Range<usize>) -> Option<(&Meshlets, &[u32])> {
        let at = |e: usize| self.starts.binary_search(&u32::try_from(e).ok()?).ok();
        Some(self.runs(at(entries.start)?..at(entries.end)?))
    }

    /// Bytes held.
    pub(crate) fn memory_bytes(&self) -> usize {
        self.meshlets.memory_bytes() + (self.starts.capacity() + self.first.capacity() + self.ids.capacity()) * 4
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use occult_core::Vec3;

    /// Runs and spans of runs are slices of clusters; a span must begin and end where runs do.
    #[test]
    fn spans_of_runs_are_their_clusters() {
        let n = 600u32;
        let positions = (0..n + 2).map(|i| Vec3::new(i as f32, (i % 2) as f32, 0.0)).collect();
        let mesh = Mesh::new(positions, (0..n).map(|i| [i, i + 1, i + 2]).collect()).expect("a strip");
        let triangles: Vec<u32> = (0..n).rev().collect();
        let c = RunClusters::build(&mesh, &triangles, vec![0, 10, 300, 600]).expect("valid runs");
        let (m, all) = c.entries(0..600).expect("the whole array");
        assert_eq!(m.list_len(all), 600);
        let (m, last_two) = c.entries(10..600).expect("runs 1 and 2");
        assert_eq!(last_two, c.runs(1..3).1);
        assert_eq!(m.list_len(last_two), 590);
        assert_eq!(m.list_len(c.runs(0..1).1), 10);
        assert!(c.entries(5..300).is_none(), "not where a run starts");
        assert!(c.entries(10..299).is_none(), "not where a run ends");
        assert!(RunClusters::build(&mesh, &triangles, vec![0, 700]).is_err());
    }
}
