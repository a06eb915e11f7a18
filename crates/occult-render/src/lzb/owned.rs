//! A mesh octree's leaves drawn as clusters (the near pass, and what it draws directly).
//!
//! An octree leaf lists every triangle that overlaps its octant, so a triangle across octants is
//! listed by several leaves (about two on the suite's meshes). Drawn as index lists, each of a
//! leaf's triangles projects its three corners one by one, and the lists are built triangle by
//! triangle with a stamp each so that a triangle two drawn leaves list is drawn once. Here each
//! triangle is **owned** by one of the leaves that list it ([`owners`]: the last in node order,
//! the leaf that `near_temporal` names for it): a leaf's own triangles are clusters of few
//! vertices ([`RunClusters`]), drawn by their cluster indices, each vertex projected once; the
//! triangles it lists but does not own (**borrowed**) are drawn as an index list unless their
//! owner was drawn for the same instance ([`DrawnLeaves`]: a bit per node of its mesh, for each
//! instance that drew a leaf). The near pass weighs them once it drew every leaf it draws, in a
//! last batch (a borrowed triangle whose owner a later batch draws is then not drawn twice),
//! but for an instance it drew whole in the rest of a frame given up (the whole draw holds
//! them); a single draw of leaves (`near_cull=off`, and the far leaves of a frame given up,
//! which see the near pass's marks) weighs them at once. What a drawn leaf lists is thus always
//! drawn; a triangle still drawn twice (the near pass's last batch and the far leaves of a
//! frame given up, an instance drawn whole after some of its clusters) draws the same frame,
//! ties going to the same item. Counter `near_borrowed_triangles`: the borrowed triangles
//! drawn.

use std::ops::Range;

use occult_core::{ItemId, Mesh, Scene, View};
use occult_raster::{Draw, DrawTriangles, Meshlets};
use occult_spatial::RayOctree;

use super::cast::InstanceRec;
use super::{Accel, Lzb};
use crate::runs::RunClusters;
use crate::{RenderError, Result};

/// A mesh octree's leaves as clusters of the triangles they own, and the lists of those they
/// borrow ([module doc](self)).
pub(crate) struct LeafClusters {
    /// Run `n`, one per octree node (empty but for leaves): the triangles leaf `n` owns.
    owned: RunClusters,
    /// Leaf `n`'s borrowed triangles by owner: runs `runs[run_starts[n]..run_starts[n + 1]]`,
    /// each `(owner, end)`: the triangles of `borrowed` from the end of the run before (or
    /// the leaf's first) to `end`, all owned by leaf `owner` (one test of the owner a run).
    run_starts: Vec<u32>,
    runs: Vec<(u32, u32)>,
    borrowed: Vec<u32>,
    /// Per octree node, the triangles it owns (0 but for leaves): a leaf's share of the mesh's
    /// triangles, which sum to the triangles its leaves list (each counted once).
    owned_counts: Vec<u32>,
}

/// Each of a mesh's `triangle_count` triangles' owner among `octree`'s leaves: the last leaf in
/// node order that lists it (`u32::MAX` for a triangle no leaf lists).
///
/// # Errors
/// [`RenderError::BadParameter`] for a leaf list naming a triangle the mesh lacks.
pub(crate) fn owners(octree: &RayOctree, triangle_count: usize) -> Result<Vec<u32>> {
    let mut owner = vec![u32::MAX; triangle_count];
    for (n, node) in octree.nodes().iter().enumerate() {
        if node.is_leaf() {
            for &t in octree.leaf_primitives(n as u32) {
                *owner.get_mut(t as usize).ok_or_else(|| {
                    RenderError::BadParameter(format!(
                        "lzb: octree leaf {n} lists triangle {t} of a mesh of {triangle_count}"
                    ))
                })? = n as u32;
            }
        }
    }
    Ok(owner)
}

impl LeafClusters {
    /// The clusters of `octree`'s leaves over `mesh`, each triangle owned by leaf `owner[t]`
    /// (a leaf that lists it, [`owners`]).
    ///
    /// # Errors
    /// [`RenderError::BadParameter`] for a leaf list naming a triangle that `owner` lacks;
    /// [`RenderError::Raster`] for one the mesh lacks.
    pub(crate) fn build(mesh: &Mesh, octree: &RayOctree, owner: &[u32]) -> Result<Self> {
        let nodes = octree.nodes();
        let mut owned = Vec::with_capacity(mesh.triangle_count());
        let mut starts = Vec::with_capacity(nodes.len() + 1);
        starts.push(0);
        let (mut run_starts, mut runs) = (Vec::with_capacity(nodes.len() + 1), Vec::new());
        run_starts.push(0);
        let mut borrowed: Vec<(u32, u32)> = Vec::new();
        let mut flat = Vec::new();
        for (n, node) in nodes.iter().enumerate() {
            if node.is_leaf() {
                borrowed.clear();
                for &t in octree.leaf_primitives(n as u32) {
                    match owner.get(t as usize) {
                        Some(&o) if o == n as u32 => owned.push(t),
                        Some(&o) => {
                            debug_assert!(
                                nodes.get(o as usize).is_some_and(|l| l.is_leaf()),
                                "triangle {t}'s owner {o} is a leaf"
                            );
                            borrowed.push((o, t));
                        }
                        None => {
                            return Err(RenderError::BadParameter(format!(
                                "lzb: octree leaf {n} lists triangle {t}, which has no owner"
                            )))
                        }
                    }
                }
                borrowed.sort_unstable();
                for (i, &(o, t)) in borrowed.iter().enumerate() {
                    flat.push(t);
                    if borrowed.get(i + 1).is_none_or(|next| next.0 != o) {
                        runs.push((o, flat.len() as u32));
                    }
                }
            }
            starts.push(owned.len() as u32);
            run_starts.push(runs.len() as u32);
        }
        let owned_counts = starts.windows(2).map(|w| w[1] - w[0]).collect();
        Ok(Self {
            owned_counts,
            owned: RunClusters::build(mesh, &owned, starts)?,
            run_starts,
            runs,
            borrowed: flat,
        })
    }

    /// The mesh's clusters, and those of the triangles leaf `leaf` owns.
    #[inline]
    pub(crate) fn owned(&self, leaf: u32) -> (&Meshlets, &[u32]) {
        self.owned.runs(leaf as usize..leaf as usize + 1)
    }

    /// Per octree node, the triangles it owns.
    pub(crate) fn owned_counts(&self) -> &[u32] {
        &self.owned_counts
    }

    /// The mesh's clusters.
    pub(crate) fn meshlets(&self) -> &Meshlets {
        self.owned.meshlets()
    }

    /// The triangles leaf `leaf` lists and does not own, by owner: `(owner, its triangles)`.
    #[inline]
    pub(crate) fn borrowed(&self, leaf: u32) -> impl Iterator<Item = (u32, &[u32])> {
        let runs = &self.runs[self.run_starts[leaf as usize] as usize..self.run_starts[leaf as usize + 1] as usize];
        // The first run starts where the leaf's runs before end.
        let mut start = match self.run_starts[leaf as usize] {
            0 => 0,
            r => self.runs[r as usize - 1].1,
        };
        runs.iter().map(move |&(owner, end)| {
            let of = &self.borrowed[start as usize..end as usize];
            start = end;
            (owner, of)
        })
    }

    /// Whether any leaf borrows a triangle.
    #[inline]
    pub(crate) fn any_borrowed(&self) -> bool {
        !self.runs.is_empty()
    }

    /// Whether leaf `leaf` borrows any triangle.
    #[inline]
    pub(crate) fn borrows(&self, leaf: u32) -> bool {
        self.run_starts[leaf as usize] != self.run_starts[leaf as usize + 1]
    }

    /// Bytes held.
    pub(crate) fn memory_bytes(&self) -> usize {
        self.owned.memory_bytes()
            + (self.run_starts.capacity()
                + self.borrowed.capacity()
                + 2 * self.runs.capacity()
                + self.owned_counts.capacity())
                * 4
    }
}

/// The leaves a frame drew, per instance of the frame: a bit per node of its mesh, made when the
/// instance draws its first leaf (so a frame holds bits for the instances it drew of meshes
/// whose leaves borrow, not for every instance of every mesh), within a budget of words the
/// frame sets: an instance beyond it has no bits, and its leaves count as not drawn (its
/// borrowed triangles are all drawn: more work, the same frame). Kept from frame to frame and
/// reset before each.
#[derive(Default)]
pub(super) struct DrawnLeaves {
    /// Per instance of the frame, the first of its words ([`NOT_YET`], [`REFUSED`]).
    first: Vec<usize>,
    words: Vec<u64>,
    /// Most words the frame may hold.
    budget: usize,
}

/// An instance that drew no leaf yet.
const NOT_YET: usize = usize::MAX;
/// An instance whose bits would have exceeded the budget.
const REFUSED: usize = usize::MAX - 1;

impl DrawnLeaves {
    /// Nothing drawn, for a frame of `instances` instances holding at most `budget` words.
    pub(super) fn reset(&mut self, instances: usize, budget: usize) {
        self.first.clear();
        self.first.resize(instances, NOT_YET);
        self.words.clear();
        if self.words.capacity() > 4 * budget {
            self.words.shrink_to(budget);
        }
        self.budget = budget;
    }

    /// The bits of instance `inst`, whose mesh's octree has `nodes` nodes; `None` when they
    /// would exceed the budget.
    fn of(&mut self, inst: u32, nodes: usize) -> Option<&mut [u64]> {
        let n = nodes.div_ceil(64);
        let at = &mut self.first[inst as usize];
        if *at == NOT_YET {
            *at = if self.words.len() + n <= self.budget {
                self.words.len()
            } else {
                REFUSED
            };
            if *at != REFUSED {
                self.words.resize(self.words.len() + n, 0);
            }
        }
        match *at {
            REFUSED => None,
            at => Some(&mut self.words[at..at + n]),
        }
    }

    /// Bytes held.
    pub(super) fn memory_bytes(&self) -> usize {
        self.first.capacity() * 8 + self.words.capacity() * 8
    }
}

/// The draw lists of some leaves of some instances ([`Lzb::emit_leaves`]), kept from batch to
/// batch and cleared before each.
#[derive(Default)]
pub(super) struct LeafLists {
    /// Per instance, its owned triangles' clusters: a range of `clusters`.
    owned: Vec<(InstanceRec, ItemId, Range<usize>)>,
    clusters: Vec<u32>,
    /// Per instance, the borrowed triangles to draw: a range of `triangles`.
    borrowed: Vec<(InstanceRec, ItemId, Range<usize>)>,
    triangles: Vec<u32>,
    /// The triangles of both.
    count: usize,
    /// The borrowed triangles listed since the lists were made (not reset by
    /// [`LeafLists::clear`]: a frame's count).
    borrowed_count: u64,
}

impl LeafLists {
    /// Empties the lists for the next batch.
    pub(super) fn clear(&mut self) {
        self.owned.clear();
        self.clusters.clear();
        self.borrowed.clear();
        self.triangles.clear();
        self.count = 0;
    }

    /// The triangles the lists draw.
    pub(super) fn triangle_count(&self) -> usize {
        self.count
    }

    /// The borrowed triangles listed since the count was last taken, and the count reset.
    pub(super) fn take_borrowed_count(&mut self) -> u64 {
        std::mem::take(&mut self.borrowed_count)
    }

    /// One draw per instance of each kind: its clusters, its borrowed triangles.
    pub(super) fn draws<'s>(&'s self, scene: &'s Scene, accel: &'s [Accel], view: &View) -> Vec<Draw<'s>> {
        let owned = self.owned.iter().filter_map(|(rec, first_item, r)| {
            let Accel::Mesh { clusters, .. } = &accel[rec.node.index()] else {
                return None;
            };
            Some(Draw {
                mesh: scene.node(rec.node).mesh()?,
                triangles: DrawTriangles::Clusters {
                    meshlets: clusters.meshlets(),
                    list: &self.clusters[r.clone()],
                },
                clip_from_object: view.clip_from_object(&rec.world_from_object),
                first_item: *first_item,
            })
        });
        let borrowed = self.borrowed.iter().filter_map(|(rec, first_item, r)| {
            Some(Draw {
                mesh: scene.node(rec.node).mesh()?,
                triangles: DrawTriangles::List(&self.triangles[r.clone()]),
                clip_from_object: view.clip_from_object(&rec.world_from_object),
                first_item: *first_item,
            })
        });
        owned.chain(borrowed).collect()
    }

    /// Bytes held.
    pub(super) fn memory_bytes(&self) -> usize {
        (self.owned.capacity() + self.borrowed.capacity()) * std::mem::size_of::<(InstanceRec, ItemId, Range<usize>)>()
            + (self.clusters.capacity() + self.triangles.capacity()) * 4
    }
}

impl Lzb {
    /// Adds to `lists` the leaves of `(instance, leaf)` pairs grouped by instance (`groups`:
    /// each instance of the frame with its range of `leaves`), group `g` listing its borrowed
    /// triangles under stamp `stamps_of[g]` (the caller's, [`Lzb::reserve_stamps`]): each
    /// leaf's own clusters, and the triangles it borrows unless their owner was drawn for the
    /// instance in the frame so far ([`Lzb::drawn`], which this marks) or they were listed
    /// under that stamp already. With `deferred`, the borrowed triangles are not weighed now:
    /// each leaf that borrows is added there as `(instance, leaf)`, for
    /// [`Lzb::emit_borrowed`] once every leaf that the frame draws is marked (a borrowed
    /// triangle whose owner a later batch draws is then not drawn twice).
    pub(super) fn emit_leaves(
        &mut self,
        groups: &[(u32, InstanceRec, ItemId, Range<usize>)],
        leaves: &[u32],
        stamps_of: &[u32],
        lists: &mut LeafLists,
        deferred: Option<&mut Vec<(u32, u32)>>,
    ) {
        assert_eq!(groups.len(), stamps_of.len(), "a stamp for every group");
        for (inst, rec, first_item, range) in groups {
            let node = rec.node.index();
            let Accel::Mesh { clusters, .. } = &self.accel[node] else {
                continue;
            };
            let of = &leaves[range.clone()];
            // Every leaf of the group marked before any borrowed triangle is weighed: what a
            // leaf of the same group owns is drawn with it. Only where leaves borrow: the marks
            // serve nothing else.
            if clusters.any_borrowed() {
                if let Some(marks) = self.drawn.of(*inst, clusters.owned_counts().len()) {
                    for &leaf in of {
                        marks[leaf as usize / 64] |= 1 << (leaf % 64);
                    }
                }
            }
            let start = lists.clusters.len();
            for &leaf in of {
                let (meshlets, list) = clusters.owned(leaf);
                lists.clusters.extend_from_slice(list);
                lists.count += meshlets.list_len(list);
            }
            if lists.clusters.len() > start {
                lists.owned.push((*rec, *first_item, start..lists.clusters.len()));
            }
        }
        match deferred {
            Some(d) => {
                for (inst, rec, _, range) in groups {
                    if let Accel::Mesh { clusters, .. } = &self.accel[rec.node.index()] {
                        d.extend(
                            leaves[range.clone()]
                                .iter()
                                .filter(|&&leaf| clusters.borrows(leaf))
                                .map(|&leaf| (*inst, leaf)),
                        );
                    }
                }
            }
            None => self.emit_borrowed(groups, leaves, stamps_of, lists),
        }
    }

    /// Adds to `lists` the triangles that the leaves of `groups` (as [`Lzb::emit_leaves`]
    /// takes them, marked drawn already) borrow, unless their owner was drawn for the
    /// instance in the frame so far or they were listed under the group's stamp already.
    pub(super) fn emit_borrowed(
        &mut self,
        groups: &[(u32, InstanceRec, ItemId, Range<usize>)],
        leaves: &[u32],
        stamps_of: &[u32],
        lists: &mut LeafLists,
    ) {
        assert_eq!(groups.len(), stamps_of.len(), "a stamp for every group");
        for ((inst, rec, first_item, range), &stamp) in groups.iter().zip(stamps_of) {
            let node = rec.node.index();
            let Accel::Mesh { clusters, .. } = &self.accel[node] else {
                continue;
            };
            let marks = self.drawn.of(*inst, clusters.owned_counts().len());
            let drawn = |owner: u32| {
                marks
                    .as_ref()
                    .is_some_and(|m| m[owner as usize / 64] & (1 << (owner % 64)) != 0)
            };
            let stamps = &mut self.stamps[node];
            let start = lists.triangles.len();
            for &leaf in &leaves[range.clone()] {
                for (owner, triangles) in clusters.borrowed(leaf) {
                    if drawn(owner) {
                        continue;
                    }
                    for &t in triangles {
                        if stamps[t as usize] != stamp {
                            stamps[t as usize] = stamp;
                            lists.triangles.push(t);
                        }
                    }
                }
            }
            if lists.triangles.len() > start {
                lists.count += lists.triangles.len() - start;
                lists.borrowed_count += (lists.triangles.len() - start) as u64;
                lists.borrowed.push((*rec, *first_item, start..lists.triangles.len()));
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use occult_core::Vec3;
    use occult_spatial::RayOctreeConfig;
    use rand::{Rng, SeedableRng};

    /// Each leaf's own triangles and those it borrows are, together, exactly what it lists;
    /// every listed triangle is owned by one leaf that lists it; a borrowed run names the owner
    /// of each of its triangles. Long thin triangles across many octants, so most leaves
    /// borrow; at depth 1 the leaves hold hundreds of triangles, each cut into several clusters
    /// of at most 256 vertices.
    #[test]
    fn a_leaf_owns_or_borrows_each_triangle_it_lists() {
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(3);
        let mut positions = Vec::new();
        let mut triangles = Vec::new();
        for i in 0..600u32 {
            let a = Vec3::new(
                rng.random_range(0.0..10.0),
                rng.random_range(0.0..10.0),
                rng.random_range(0.0..10.0),
            );
            let long = if i % 3 == 0 { 6.0 } else { 0.3 };
            let b = a + Vec3::new(rng.random_range(-long..long), rng.random_range(-0.3..0.3), 0.1);
            let c = a + Vec3::new(0.1, rng.random_range(-long..long), rng.random_range(-0.3..0.3));
            positions.extend([a, b, c]);
            triangles.push([3 * i, 3 * i + 1, 3 * i + 2]);
        }
        let mesh = Mesh::new(positions.clone(), triangles.clone()).expect("a valid mesh");
        for max_depth in [6, 1] {
            let config = RayOctreeConfig {
                max_depth,
                max_leaf_size: 8,
            };
            let octree = RayOctree::build_triangles(&positions, &triangles, config).expect("a valid octree");
            let owner = owners(&octree, triangles.len()).expect("valid lists");
            let leaves = LeafClusters::build(&mesh, &octree, &owner).expect("valid lists");
            let (mut owned_total, mut borrowed_total, mut clusters) = (0, 0, 0);
            for (n, node) in octree.nodes().iter().enumerate() {
                let leaf = n as u32;
                let (meshlets, list) = leaves.owned(leaf);
                clusters = clusters.max(list.len());
                let mut got: Vec<u32> = list
                    .iter()
                    .flat_map(|&c| meshlets.triangles(c as usize).iter().copied())
                    .collect();
                assert!(
                    got.iter().all(|&t| owner[t as usize] == leaf),
                    "depth {max_depth}: leaf {n} owns only its own"
                );
                assert_eq!(leaves.owned_counts()[n] as usize, got.len(), "leaf {n}'s count");
                owned_total += got.len();
                for (o, of) in leaves.borrowed(leaf) {
                    assert_ne!(o, leaf, "leaf {n} borrows from itself");
                    assert!(
                        of.iter()
                            .all(|&t| owner[t as usize] == o && octree.leaf_primitives(o).contains(&t)),
                        "a run of leaf {n} names its owner, a leaf that lists its triangles"
                    );
                    borrowed_total += of.len();
                    got.extend_from_slice(of);
                }
                got.sort_unstable();
                let mut want = if node.is_leaf() {
                    octree.leaf_primitives(leaf).to_vec()
                } else {
                    Vec::new()
                };
                want.sort_unstable();
                assert_eq!(got, want, "depth {max_depth}: leaf {n}");
            }
            let listed = owner.iter().filter(|&&o| o != u32::MAX).count();
            assert_eq!(listed, triangles.len(), "every triangle lies in a leaf");
            assert_eq!(owned_total, listed, "each listed triangle owned once");
            assert!(
                borrowed_total > listed / 8,
                "depth {max_depth}: the test's leaves borrow ({borrowed_total} of {listed})"
            );
            if max_depth == 1 {
                assert!(clusters > 1, "a leaf of several clusters");
            }
        }
    }

    /// An instance's bits are made once, kept within the frame's budget (an instance beyond it
    /// has none, for the whole frame), and start clear each frame.
    #[test]
    fn drawn_leaves_keep_to_their_budget() {
        let mut d = DrawnLeaves::default();
        d.reset(3, 3);
        d.of(0, 100).expect("two words")[1] = 5;
        assert!(d.of(1, 129).is_none(), "three more words exceed the budget");
        assert_eq!(d.of(0, 100).expect("made").to_vec(), [0, 5]);
        assert!(d.of(1, 1).is_none(), "refused for the frame");
        assert_eq!(d.of(2, 64).expect("one word fits").len(), 1);
        d.reset(3, 3);
        assert_eq!(d.of(0, 100).expect("two words").to_vec(), [0, 0], "clear again");
        assert!(d.of(1, 64).is_some(), "a new frame");
    }

    /// A leaf list naming a triangle the mesh lacks is an error, not a panic.
    #[test]
    fn a_list_beyond_the_mesh_is_an_error() {
        let positions = vec![Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::Z];
        let triangles = vec![[0, 1, 2], [0, 1, 3]];
        let octree = RayOctree::build_triangles(&positions, &triangles, RayOctreeConfig::default()).expect("an octree");
        assert!(owners(&octree, 1).is_err());
        let mesh = Mesh::new(positions, vec![[0, 1, 2]]).expect("a valid mesh");
        let owner = owners(&octree, 2).expect("valid lists");
        assert!(LeafClusters::build(&mesh, &octree, &owner[..1]).is_err());
    }
}
