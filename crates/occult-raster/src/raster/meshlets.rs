//! A mesh's triangles grouped into clusters of few vertices (meshlets), for draws of some of
//! its clusters ([`DrawTriangles::Clusters`](super::DrawTriangles::Clusters)).
//!
//! A triangle list names each triangle's corners through the mesh's index buffer, so each corner
//! is transformed as it comes (three per triangle): neighbouring triangles share corners, but
//! the list does not say which. A cluster says it once: its distinct vertices (at most
//! [`MAX_CLUSTER_VERTICES`]) and, per triangle, its corners as indices into them. A draw of
//! clusters transforms each cluster's vertices once (eight at a time where the processor has
//! AVX2), about one per triangle on a closed mesh, then sets up the cluster's triangles from
//! them. Item ids stay the mesh's: triangle `t` of the mesh is `first_item + t`, whichever
//! cluster holds it.

use occult_core::{Mesh, Vec3};

use crate::RasterError;

/// Lanes of the projection (eight f32 lanes of AVX2).
const LANES: usize = 8;

/// Most distinct vertices of one cluster (local corner indices are bytes).
pub const MAX_CLUSTER_VERTICES: usize = 256;

/// Clusters of one mesh's triangles, each with its distinct vertices: a draw of some of them
/// ([`DrawTriangles::Clusters`](super::DrawTriangles::Clusters)) projects each cluster's
/// vertices once.
#[derive(Clone, Debug, Default)]
pub struct Meshlets {
    /// Cluster `c`'s triangles are `triangles[triangle_starts[c]..triangle_starts[c + 1]]`.
    triangle_starts: Vec<u32>,
    /// Cluster `c`'s vertices are `vertices[vertex_starts[c]..vertex_starts[c + 1]]`, their
    /// positions `positions[position_starts[c]..]` (as many; each cluster's block padded to a
    /// whole number of eight lanes with copies of its last vertex).
    vertex_starts: Vec<u32>,
    position_starts: Vec<u32>,
    /// Mesh vertex indices, cluster by cluster.
    vertices: Vec<u32>,
    /// Their positions, read eight at a time by the projection without gathering.
    positions: Vec<Vec3>,
    /// Per triangle (aligned with `triangles`), its corners as indices into its cluster's
    /// vertices.
    corners: Vec<[u8; 3]>,
    /// Per triangle, its index in the mesh.
    triangles: Vec<u32>,
}

impl Meshlets {
    /// The clusters of `mesh` whose triangles are `triangles[starts[c]..starts[c + 1]]` (mesh
    /// triangle indices; `starts` begins at 0, never decreases and ends at `triangles.len()`).
    ///
    /// # Errors
    /// [`RasterError::BadConfig`] naming the cluster or entry: bad `starts`, a triangle index
    /// out of the mesh, or a cluster of more than [`MAX_CLUSTER_VERTICES`] distinct vertices.
    pub fn new(mesh: &Mesh, triangles: &[u32], starts: &[u32]) -> Result<Self, RasterError> {
        let bad = |m: String| Err(RasterError::BadConfig(format!("meshlets: {m}")));
        check(mesh, triangles, starts, "cluster starts")?;
        let tris = mesh.triangles();
        // Per mesh vertex, its local index in the cluster being built, stamped by the cluster.
        let mut local = vec![(u32::MAX, 0u8); mesh.positions().len()];
        let mut m = Self {
            triangle_starts: starts.to_vec(),
            vertex_starts: vec![0],
            position_starts: vec![0],
            vertices: Vec::new(),
            positions: Vec::new(),
            corners: Vec::with_capacity(triangles.len()),
            triangles: triangles.to_vec(),
        };
        for (c, w) in starts.windows(2).enumerate() {
            let first = m.vertices.len();
            for &t in &triangles[w[0] as usize..w[1] as usize] {
                let mut corner = [0u8; 3];
                for (k, &v) in tris[t as usize].iter().enumerate() {
                    let slot = &mut local[v as usize];
                    if slot.0 != c as u32 {
                        let n = m.vertices.len() - first;
                        if n == MAX_CLUSTER_VERTICES {
                            return bad(format!(
                                "cluster {c} has more than {MAX_CLUSTER_VERTICES} distinct vertices"
                            ));
                        }
                        *slot = (c as u32, n as u8);
                        m.vertices.push(v);
                    }
                    corner[k] = slot.1;
                }
                m.corners.push(corner);
            }
            m.vertex_starts.push(m.vertices.len() as u32);
            let block = &m.vertices[first..];
            m.positions.extend(block.iter().map(|&v| mesh.positions()[v as usize]));
            let pad = block.len().next_multiple_of(LANES) - block.len();
            let last = m.positions.last().copied().unwrap_or(Vec3::ZERO);
            m.positions.extend(std::iter::repeat_n(last, pad));
            m.position_starts.push(m.positions.len() as u32);
        }
        Ok(m)
    }

    /// Clusters of `mesh` cut from runs of triangles: run `r` is
    /// `triangles[runs[r]..runs[r + 1]]` (mesh triangle indices; `runs` begins at 0, never
    /// decreases and ends at `triangles.len()`), cut in order into clusters of at most
    /// [`MAX_CLUSTER_VERTICES`] distinct vertices. Returns the clusters and, per run, the index
    /// of its first cluster, then the end: run `r`'s clusters are `first[r]..first[r + 1]`
    /// (none for an empty run).
    ///
    /// # Errors
    /// As [`Meshlets::new`], for bad `runs` or a triangle index out of the mesh.
    pub fn from_runs(mesh: &Mesh, triangles: &[u32], runs: &[u32]) -> Result<(Self, Vec<u32>), RasterError> {
        check(mesh, triangles, runs, "runs")?;
        let tris = mesh.triangles();
        // Per mesh vertex, the last cluster that counted it.
        let mut seen = vec![u32::MAX; mesh.positions().len()];
        let (mut starts, mut first) = (vec![0u32], Vec::with_capacity(runs.len()));
        for w in runs.windows(2) {
            first.push(starts.len() as u32 - 1);
            let mut distinct = 0;
            for i in w[0]..w[1] {
                let corners = tris[triangles[i as usize] as usize];
                let cluster = starts.len() as u32 - 1;
                let new = |seen: &[u32]| {
                    corners
                        .iter()
                        .enumerate()
                        .filter(|&(k, &v)| seen[v as usize] != cluster && !corners[..k].contains(&v))
                        .count()
                };
                let mut cluster = cluster;
                if i > w[0] && distinct + new(&seen) > MAX_CLUSTER_VERTICES {
                    starts.push(i);
                    (cluster, distinct) = (cluster + 1, 0);
                }
                for &v in &corners {
                    if seen[v as usize] != cluster {
                        seen[v as usize] = cluster;
                        distinct += 1;
                    }
                }
            }
            if w[1] > w[0] {
                starts.push(w[1]);
            }
        }
        first.push(starts.len() as u32 - 1);
        Ok((Self::new(mesh, triangles, &starts)?, first))
    }

    /// Number of clusters.
    pub fn len(&self) -> usize {
        self.triangle_starts.len() - 1
    }

    /// Whether there are no clusters.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The mesh triangle indices of cluster `c`.
    pub fn triangles(&self, c: usize) -> &[u32] {
        &self.triangles[self.triangle_starts[c] as usize..self.triangle_starts[c + 1] as usize]
    }

    /// Triangles of cluster `c`.
    #[inline]
    pub fn triangle_count(&self, c: usize) -> usize {
        (self.triangle_starts[c + 1] - self.triangle_starts[c]) as usize
    }

    /// Bytes held.
    pub fn memory_bytes(&self) -> usize {
        (self.triangle_starts.capacity()
            + self.vertex_starts.capacity()
            + self.position_starts.capacity()
            + self.vertices.capacity())
            * 4
            + self.positions.capacity() * 12
            + self.corners.capacity() * 3
            + self.triangles.capacity() * 4
    }

    /// Cluster `c`'s vertices (mesh indices), and the index of its first triangle in the
    /// per-triangle arrays.
    #[inline]
    pub(super) fn cluster(&self, c: usize) -> (&[u32], usize) {
        (
            &self.vertices[self.vertex_starts[c] as usize..self.vertex_starts[c + 1] as usize],
            self.triangle_starts[c] as usize,
        )
    }

    /// Cluster `c`'s vertex positions, padded to a whole number of eight lanes (the padding
    /// repeats its last vertex).
    #[inline]
    pub(super) fn positions(&self, c: usize) -> &[Vec3] {
        &self.positions[self.position_starts[c] as usize..self.position_starts[c + 1] as usize]
    }

    /// Triangle `i` of the per-triangle arrays: its local corners and its mesh index.
    #[inline]
    pub(super) fn triangle(&self, i: usize) -> ([u8; 3], u32) {
        (self.corners[i], self.triangles[i])
    }

    /// Where triangle `j` of the clusters `list` (taken in order) lies: the position in `list`
    /// of its cluster and the triangles of the clusters before it.
    #[inline]
    pub(super) fn seek(&self, list: &[u32], j: usize) -> (usize, usize) {
        let (mut k, mut base) = (0, 0);
        while base + self.triangle_count(list[k] as usize) <= j {
            base += self.triangle_count(list[k] as usize);
            k += 1;
        }
        (k, base)
    }

    /// The triangles of the clusters `list`, in order.
    pub fn list_len(&self, list: &[u32]) -> usize {
        list.iter().map(|&c| self.triangle_count(c as usize)).sum()
    }

    /// The mesh index of triangle `j` of the clusters `list` taken in order (a search from
    /// the first cluster: for the stream's generic paths, not per triangle of a setup).
    pub(super) fn list_triangle(&self, list: &[u32], mut j: usize) -> u32 {
        for &c in list {
            let n = self.triangle_count(c as usize);
            if j < n {
                return self.triangles(c as usize)[j];
            }
            j -= n;
        }
        panic!("triangle beyond the clusters' triangles");
    }
}

/// Checks that `bounds` (`what`) begin at 0, never decrease and end at `triangles.len()`, and
/// that every entry of `triangles` names a triangle of `mesh`.
fn check(mesh: &Mesh, triangles: &[u32], bounds: &[u32], what: &str) -> Result<(), RasterError> {
    let bad = |m: String| Err(RasterError::BadConfig(format!("meshlets: {m}")));
    if bounds.first() != Some(&0)
        || bounds.last().map(|&s| s as usize) != Some(triangles.len())
        || bounds.windows(2).any(|w| w[0] > w[1])
    {
        return bad(format!(
            "{what} must begin at 0, never decrease and end at the {} triangles",
            triangles.len()
        ));
    }
    match triangles
        .iter()
        .enumerate()
        .find(|(_, &t)| t as usize >= mesh.triangle_count())
    {
        Some((i, t)) => bad(format!(
            "entry {i} names triangle {t} of a mesh of {}",
            mesh.triangle_count()
        )),
        None => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn strip(n: u32) -> Mesh {
        let positions = (0..n + 2).map(|i| Vec3::new(i as f32, (i % 2) as f32, 0.0)).collect();
        Mesh::new(positions, (0..n).map(|i| [i, i + 1, i + 2]).collect()).expect("a strip is a valid mesh")
    }

    #[test]
    fn clusters_share_their_vertices_and_keep_triangle_indices() {
        let mesh = strip(10);
        let m = Meshlets::new(&mesh, &[0, 1, 2, 9, 5, 4], &[0, 3, 3, 6]).expect("valid clusters");
        assert_eq!(m.len(), 3);
        assert_eq!(m.triangles(0), &[0, 1, 2]);
        assert!(m.triangles(1).is_empty());
        // Triangles 0..3 of the strip use vertices 0..5: five distinct, not nine.
        let (v, first) = m.cluster(0);
        assert_eq!((v, first), (&[0, 1, 2, 3, 4][..], 0));
        for i in 0..3 {
            let (corner, t) = m.triangle(i);
            assert_eq!(corner.map(|k| v[k as usize]), mesh.triangles()[t as usize]);
        }
        let (v, first) = m.cluster(2);
        for i in first..first + 3 {
            let (corner, t) = m.triangle(i);
            assert_eq!(corner.map(|k| v[k as usize]), mesh.triangles()[t as usize]);
        }
        for c in 0..3 {
            let (v, _) = m.cluster(c);
            let p = m.positions(c);
            assert_eq!(p.len(), v.len().next_multiple_of(LANES));
            assert!(v.iter().zip(p).all(|(&i, &q)| mesh.positions()[i as usize] == q));
        }
        assert_eq!(m.list_len(&[2, 0]), 6);
        assert_eq!(m.list_triangle(&[2, 0], 3), 0);
        assert_eq!(m.list_triangle(&[2, 0], 2), 4);
    }

    #[test]
    fn runs_are_cut_into_clusters_of_few_vertices() {
        // A strip of 600 triangles uses 602 vertices: one run of all of them needs three
        // clusters; an empty run gets none.
        let mesh = strip(600);
        let all: Vec<u32> = (0..600).collect();
        let (m, first) = Meshlets::from_runs(&mesh, &all, &[0, 10, 10, 600]).expect("valid runs");
        assert_eq!(first, vec![0, 1, 1, 4]);
        assert_eq!(m.triangles(0), &all[..10]);
        let run: Vec<u32> = (1..4).flat_map(|c| m.triangles(c).to_vec()).collect();
        assert_eq!(run, all[10..]);
        for c in 0..m.len() {
            assert!(m.cluster(c).0.len() <= MAX_CLUSTER_VERTICES);
        }
        // Full clusters: the first of the long run holds 254 triangles (256 vertices).
        assert_eq!(m.triangle_count(1), 254);
        assert!(
            Meshlets::from_runs(&mesh, &all, &[0, 700]).is_err(),
            "runs past the end"
        );
        assert!(
            Meshlets::from_runs(&mesh, &[0, 600], &[0, 2]).is_err(),
            "a triangle out of the mesh"
        );
        let (m, first) = Meshlets::from_runs(&mesh, &[], &[0, 0]).expect("one empty run");
        assert_eq!((m.len(), first), (0, vec![0, 0]));
    }

    #[test]
    fn bad_clusters_are_errors() {
        let mesh = strip(300);
        assert!(
            Meshlets::new(&mesh, &[0, 1], &[0, 1]).is_err(),
            "starts short of the end"
        );
        assert!(Meshlets::new(&mesh, &[0, 1], &[1, 2]).is_err(), "starts not from 0");
        assert!(
            Meshlets::new(&mesh, &[0, 1], &[0, 2, 1, 2]).is_err(),
            "starts decreasing"
        );
        assert!(
            Meshlets::new(&mesh, &[0, 300], &[0, 2]).is_err(),
            "a triangle out of the mesh"
        );
        let all: Vec<u32> = (0..300).collect();
        let e = Meshlets::new(&mesh, &all, &[0, 300]).unwrap_err();
        assert!(e.to_string().contains("cluster 0 has more than 256"), "{e}");
        assert!(Meshlets::new(&mesh, &all, &[0, 150, 300]).is_ok());
    }
}
