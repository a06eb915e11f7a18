//! One frame of [`super::Hzb`]: the visible list, the tested traversal, batches, the recheck.

use std::collections::HashSet;
use std::hash::Hasher;
use std::time::Instant;

use occult_core::{Affine3A, Containment, Frustum, Mat4, Mesh, NodeId, NodeKind, Scene, Vec3, View};
use occult_raster::{
    Draw, DrawTriangles, Frame, Meshlets, PixelRect, PyramidCounts, PyramidTest, Rasterizer, ZPyramid,
};
use occult_spatial::{octree::hybrid::NO_CHILD, HybridOctree};

use super::boxtest::{screen_rect, Occlusion};
use super::{ChildOrder, Distribution, HzbOptions, PerNode, VisEntry};
use crate::hash::{FxBuild, FxHasher};
use crate::payoff::{FramePayoff, Payoff, DIRECT_BATCH};
use crate::runs::RunClusters;
use crate::walk::{NodeAt, NodeTest, Placed, SceneWalk, Visitor};
use crate::{FrameStats, Phase};

type IdSet<K> = HashSet<K, FxBuild>;

/// Names one octree node of one instance of a DAG node: (DAG node, octree node, first item).
type NodeKey = (u32, u32, u64);

/// Marks a primitive that no other node shares in [`Stamps`]' numbering.
const NOT_SHARED: u32 = u32::MAX;

/// §3.1's frame stamps of shared primitives, kept per instance: every instance (DAG node, first
/// item) that draws a shared primitive this frame gets a bit set over its octree's shared
/// primitives, found once per node drawn (a one-entry cache covers the runs of one instance).
/// Exact: a primitive is drawn once per instance and frame, never skipped wrongly.
///
/// Memory: per frame, `⌈shared / 64⌉` words per instance that draws a shared primitive, i.e.
/// bounded by the frame's own walk (at most 8 bytes per 64 shared primitives of each instance
/// reached), and reused from frame to frame.
pub(super) struct Stamps {
    /// Per DAG node: primitive → its bit among the octree's shared primitives, or
    /// [`NOT_SHARED`]; empty where nothing is shared.
    bit_of: Vec<Vec<u32>>,
    /// Per DAG node: words of one instance's bit set.
    words: Vec<u32>,
    /// Per DAG node whose octree shares primitives: its nodes' shared own primitives (read for
    /// meshes).
    split: Vec<Option<Split>>,
    /// This frame's bit sets.
    sets: StampSets,
}

/// The shared own primitives of every node of a mesh octree, node by node, with their stamp
/// bits, read in order when a node is drawn (the per-primitive lookup of a bit in a table over
/// the whole mesh missed the cache). The unshared ones are drawn as clusters
/// ([`RunClusters`]).
struct Split {
    /// Per octree node: where its shared run starts and ends.
    ranges: Vec<[u32; 2]>,
    order: Vec<u32>,
    /// The stamp bit of each entry of `order`.
    bits: Vec<u32>,
}

/// The frame's stamp bit sets, one per instance that drew a shared primitive.
#[derive(Default)]
struct StampSets {
    /// Instance (DAG node, first item) → offset of its bit set in `bits`, this frame.
    slots: std::collections::HashMap<(u32, u64), usize, FxBuild>,
    bits: Vec<u64>,
    /// The last instance looked up and its offset.
    last: Option<((u32, u64), usize)>,
}

impl StampSets {
    /// Sets stamp `bit` of the instance of DAG node `id` at `first_item` (whose set has
    /// `words` words); false when it was already set this frame.
    #[inline]
    fn stamp(&mut self, id: NodeId, words: u32, bit: u32, first_item: u64) -> bool {
        let (word, mask) = (
            &mut self.set(id, words, first_item)[bit as usize / 64],
            1u64 << (bit % 64),
        );
        let fresh = *word & mask == 0;
        *word |= mask;
        fresh
    }

    /// The bit set of the instance of DAG node `id` at `first_item` (`words` words), made
    /// empty at its first use this frame.
    #[inline]
    fn set(&mut self, id: NodeId, words: u32, first_item: u64) -> &mut [u64] {
        let key = (id.0, first_item);
        let offset = match self.last {
            Some((k, o)) if k == key => o,
            _ => {
                let bits = &mut self.bits;
                let o = *self.slots.entry(key).or_insert_with(|| {
                    let o = bits.len();
                    bits.resize(o + words as usize, 0);
                    o
                });
                self.last = Some((key, o));
                o
            }
        };
        &mut self.bits[offset..offset + words as usize]
    }
}

impl Stamps {
    /// Stamp numbering for the shared primitives of `octrees`, and their node lists regrouped
    /// (see [`Split`]).
    pub(super) fn new(octrees: &[Option<HybridOctree>]) -> Self {
        let mut words = Vec::with_capacity(octrees.len());
        let bit_of: Vec<Vec<u32>> = octrees
            .iter()
            .map(|o| match o {
                Some(o) if o.shared_count() > 0 => {
                    let mut next = 0u32;
                    let bits: Vec<u32> = (0..o.primitive_count() as u32)
                        .map(|p| {
                            if o.is_shared(p) {
                                next += 1;
                                next - 1
                            } else {
                                NOT_SHARED
                            }
                        })
                        .collect();
                    words.push(next.div_ceil(64));
                    bits
                }
                _ => {
                    words.push(0);
                    Vec::new()
                }
            })
            .collect();
        let split = octrees
            .iter()
            .zip(&bit_of)
            .map(|(o, bit_of)| {
                let o = o.as_ref().filter(|_| !bit_of.is_empty())?;
                let mut split = Split {
                    ranges: Vec::with_capacity(o.nodes().len()),
                    order: Vec::new(),
                    bits: Vec::new(),
                };
                for n in 0..o.nodes().len() as u32 {
                    let own = o.node_primitives(n);
                    let start = split.order.len() as u32;
                    split
                        .order
                        .extend(own.iter().filter(|&&p| bit_of[p as usize] != NOT_SHARED));
                    split.ranges.push([start, split.order.len() as u32]);
                }
                split.bits = split.order.iter().map(|&p| bit_of[p as usize]).collect();
                Some(split)
            })
            .collect();
        Self {
            bit_of,
            words,
            split,
            sets: StampSets::default(),
        }
    }

    /// Forgets the previous frame's stamps.
    fn begin_frame(&mut self) {
        self.sets.slots.clear();
        self.sets.bits.clear();
        self.sets.last = None;
    }

    /// Bytes held.
    pub(super) fn memory_bytes(&self) -> usize {
        self.bit_of.iter().map(|b| b.capacity() * 4).sum::<usize>()
            + self
                .split
                .iter()
                .flatten()
                .map(|s| s.ranges.capacity() * 8 + s.order.capacity() * 4 + s.bits.capacity() * 4)
                .sum::<usize>()
            + self.words.capacity() * 4
            + self.sets.bits.capacity() * 8
            + self.sets.slots.capacity() * 24
    }

    /// Appends to `out` the shared own primitives of octree node `n` of the instance of mesh
    /// `id` at `first_item` that it has not drawn yet this frame, stamping them.
    #[inline]
    fn gather_shared(&mut self, id: NodeId, n: u32, first_item: u64, out: &mut Vec<u32>) {
        let Some(split) = &self.split[id.index()] else {
            return;
        };
        let [start, end] = split.ranges[n as usize];
        if start == end {
            return;
        }
        let set = self.sets.set(id, self.words[id.index()], first_item);
        for k in start as usize..end as usize {
            let bit = split.bits[k];
            let (word, mask) = (&mut set[bit as usize / 64], 1u64 << (bit % 64));
            if *word & mask == 0 {
                *word |= mask;
                out.push(split.order[k]);
            }
        }
    }

    /// Stamps primitive `p` of the instance of DAG node `id` at `first_item`; false when it is
    /// shared and that instance already drew it this frame.
    #[inline]
    fn stamp(&mut self, id: NodeId, p: u32, first_item: u64) -> bool {
        match self.bit_of[id.index()].get(p as usize) {
            Some(&bit) if bit != NOT_SHARED => self.sets.stamp(id, self.words[id.index()], bit, first_item),
            _ => true,
        }
    }
}

/// Which part of the scene one worker of a §4.1 distribution owns.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) struct Share {
    pub distribution: Distribution,
    pub workers: u32,
    pub index: u32,
}

impl Share {
    /// The whole scene (no distribution).
    pub const ALL: Share = Share {
        distribution: Distribution::Off,
        workers: 1,
        index: 0,
    };

    fn mix(key: NodeKey) -> u64 {
        let mut h = FxHasher::default();
        h.write_u32(key.0);
        h.write_u32(key.1);
        h.write_u64(key.2);
        h.finish() >> 32
    }

    /// Whether this worker draws the own primitives of node `key` at all (hybrid: fine
    /// structures, kept whole, spread over the workers).
    fn owns_node(&self, key: NodeKey) -> bool {
        match self.distribution {
            Distribution::Hybrid => Self::mix(key) % self.workers as u64 == self.index as u64,
            _ => true,
        }
    }

    /// Whether this worker handles primitive `p` of node `key` of DAG node `id` (`root`:
    /// the scene's root). By structure: the root's primitives (whole subtrees) round robin;
    /// by primitive: every node's primitives round robin.
    fn owns_primitive(&self, id: NodeId, root: NodeId, key: NodeKey, p: u32) -> bool {
        match self.distribution {
            Distribution::Structure => id != root || p % self.workers == self.index,
            Distribution::Primitive => (Self::mix(key) + p as u64) % self.workers as u64 == self.index as u64,
            _ => true,
        }
    }

    /// Whether this worker enters the subtree of instance primitive `p` (by structure, only
    /// its own structures; otherwise every worker walks every octree).
    fn enters(&self, id: NodeId, root: NodeId, p: u32) -> bool {
        self.distribution != Distribution::Structure || id != root || p % self.workers == self.index
    }
}

/// An instance's frustum, matrix and eye, computed once per frame for the visible list.
#[derive(Clone, Copy)]
struct Placement {
    frustum: Frustum,
    clip_from_object: Mat4,
    eye: Vec3,
}

/// Which triangles of a mesh a pending draw holds.
#[derive(Clone, Copy)]
enum Triangles<'a> {
    /// The whole mesh.
    All,
    /// A range of `scratch` (a list filtered by stamps or shares).
    Scratch(u32, u32),
    /// Some clusters of the mesh's node clusters (an octree node's unshared triangles).
    Clusters(&'a Meshlets, &'a [u32]),
}

impl Triangles<'_> {
    fn count(self, mesh: &Mesh) -> usize {
        match self {
            Triangles::All => mesh.triangle_count(),
            Triangles::Scratch(s, e) => (e - s) as usize,
            Triangles::Clusters(m, list) => m.list_len(list),
        }
    }
}

/// Geometry gathered for the next rasterizer call.
struct Pending<'a> {
    mesh: &'a Mesh,
    triangles: Triangles<'a>,
    clip_from_object: Mat4,
    first_item: u64,
}

/// The DAG instance whose octree is being walked.
struct Instance<'a> {
    place: Placed,
    octree: &'a HybridOctree,
    frustum: Frustum,
    clip_from_object: Mat4,
    eye: Vec3,
}

pub(super) struct Walk<'a> {
    walk: SceneWalk<'a>,
    octrees: &'a [Option<HybridOctree>],
    /// Per DAG node with an octree: triangle instances below each octree node.
    subtree_items: &'a [Vec<u64>],
    /// Per mesh with an octree: its nodes' unshared triangles as clusters.
    meshlets: &'a [Option<RunClusters>],
    /// Whether the tests still pay this frame, and what the renderer learns from it.
    payoff: FramePayoff,
    payoff_state: &'a mut Payoff,
    options: &'a HzbOptions,
    raster: &'a mut Rasterizer,
    frame: &'a mut Frame,
    pyramid: &'a mut ZPyramid,
    how: PyramidTest,
    share: Share,
    pending: Vec<Pending<'a>>,
    scratch: Vec<u32>,
    pending_triangles: usize,
    /// The pending batch's screen region, within the view's (what `refresh` weighs).
    dirty: Option<PixelRect>,
    /// Nodes whose own primitives the visible list drew this frame.
    drawn_nodes: IdSet<NodeKey>,
    /// Mesh instances (DAG node, first item) the visible list drew whole this frame.
    whole: IdSet<(u32, u64)>,
    /// Shared primitives drawn (§3.1's frame stamp).
    stamps: &'a mut Stamps,
    /// The next visible list, and its keys.
    visible: Vec<VisEntry>,
    listed: IdSet<NodeKey>,
    placements: std::collections::HashMap<(u32, u64), Placement, FxBuild>,
    /// Whether the last instance visited was a small mesh queued whole.
    queued_whole: bool,
    /// Whether the visible list is being drawn: nothing reads the pyramid then (but a
    /// retested entry), so batches are large enough for the rasterizer's threads.
    listing: bool,
    pc: PyramidCounts,
    occlusion_tests: u64,
    occlusion_culled: u64,
    frustum_culled: u64,
    list_drawn: u64,
    list_culled: u64,
    recheck_dropped: u64,
    batches: u64,
    whole_drawn: u64,
    list_retested: u64,
    /// Entries of the visible list in view not drawn because the list was not trusted
    /// (`trust`).
    list_skipped: u64,
    /// The keys of last frame's list entries in view this frame, and their triangles: what
    /// the recheck measures the list's precision over.
    from_list: IdSet<NodeKey>,
    from_list_triangles: u64,
    /// The precision measured by this frame's recheck, in percent (a counter).
    list_precision_pct: Option<u64>,
    /// Batches drawn early for a test (`refresh`), and those after which the box was hidden.
    refreshes: u64,
    refreshes_paid: u64,
}

impl<'a> Walk<'a> {
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        scene: &'a Scene,
        octrees: &'a [Option<HybridOctree>],
        options: &'a HzbOptions,
        view: &'a View,
        raster: &'a mut Rasterizer,
        frame: &'a mut Frame,
        pyramid: &'a mut ZPyramid,
        share: Share,
        stamps: &'a mut Stamps,
        per_node: &'a PerNode,
        payoff_state: &'a mut Payoff,
    ) -> Self {
        stamps.begin_frame();
        Self {
            walk: SceneWalk::new(scene, view),
            octrees,
            subtree_items: &per_node.subtree_items,
            meshlets: &per_node.meshlets,
            payoff: payoff_state.begin(Instant::now()),
            payoff_state,
            options,
            raster,
            frame,
            pyramid,
            how: PyramidTest {
                global: options.global,
                hierarchical: options.pyramid,
            },
            share,
            pending: Vec::new(),
            scratch: Vec::new(),
            pending_triangles: 0,
            dirty: None,
            drawn_nodes: IdSet::default(),
            whole: IdSet::default(),
            stamps,
            visible: Vec::new(),
            listed: IdSet::default(),
            placements: Default::default(),
            queued_whole: false,
            listing: false,
            pc: PyramidCounts::default(),
            occlusion_tests: 0,
            occlusion_culled: 0,
            frustum_culled: 0,
            list_drawn: 0,
            list_culled: 0,
            recheck_dropped: 0,
            batches: 0,
            whole_drawn: 0,
            list_retested: 0,
            list_skipped: 0,
            from_list: IdSet::default(),
            from_list_triangles: 0,
            list_precision_pct: None,
            refreshes: 0,
            refreshes_paid: 0,
        }
    }

    /// §3.3: draws last frame's visible list first (in descending screen area, §4.2), untested
    /// except against the frustum; entries outside it stay listed when `keep_culled` (§5.1).
    /// With `skip` (the list was not precise enough last time, `trust`), entries in view are
    /// not drawn, only noted for the recheck to measure the list's precision again: the
    /// tested traversal draws what is visible.
    pub fn draw_visible_list(&mut self, mut list: Vec<VisEntry>, skip: bool) {
        self.payoff.untested_first();
        let (w, h) = (self.frame.width(), self.frame.height());
        if self.options.area_sort && !skip {
            let mut keyed: Vec<(u64, VisEntry)> = list
                .into_iter()
                .map(|e| {
                    let b = self.node_of(&e).own_bounds;
                    let clip = self.placement(&e).clip_from_object;
                    (screen_rect(&clip, &b, w, h).map_or(0, |r| r.area()), e)
                })
                .collect();
            keyed.sort_by_key(|k| std::cmp::Reverse(k.0));
            list = keyed.into_iter().map(|(_, e)| e).collect();
        }
        let whole = if skip {
            IdSet::default()
        } else {
            self.whole_instances(&list)
        };
        self.listing = true;
        for e in list {
            let node = self.node_of(&e);
            let (own, count) = (node.own_bounds, node.count as u64);
            let key = (e.dag_node.0, e.octree_node, e.first_item);
            if skip && !e.stale {
                // Noted only (out of view now or not: either way it did not stay visible).
                if self.from_list.insert(key) {
                    self.from_list_triangles += count;
                    self.list_skipped += 1;
                }
                continue;
            }
            let pl = self.placement(&e);
            if !e.stale && pl.frustum.classify_aabb(&own) != Containment::Outside && self.from_list.insert(key) {
                self.from_list_triangles += count;
            }
            if whole.contains(&(e.dag_node.0, e.first_item)) {
                // Drawn whole (once, at its first entry); its entries stay listed, so that the
                // recheck keeps measuring how much of it is visible.
                if self.whole.insert((e.dag_node.0, e.first_item)) {
                    let scene: &'a Scene = self.walk.scene();
                    if let NodeKind::Mesh(mesh) = scene.node(e.dag_node).kind() {
                        let b = mesh.bounds();
                        if pl.frustum.classify_aabb(&b) != Containment::Outside {
                            self.whole_drawn += 1;
                            self.push(mesh, Triangles::All, pl.clip_from_object, e.first_item, &b);
                            self.maybe_flush();
                        }
                    }
                }
                self.list(e);
                continue;
            }
            if pl.frustum.classify_aabb(&own) == Containment::Outside {
                self.list_culled += 1;
                if self.options.keep_culled {
                    self.list(VisEntry { stale: true, ..e });
                }
                continue;
            }
            // An entry kept while outside the frustum was never rechecked there: when it comes
            // back into view it is tested like a node of the traversal (`retest`).
            if e.stale && self.options.retest && self.options.occlusion {
                self.list_retested += 1;
                // What the list drew so far, in the pyramid as far as a tested batch would be.
                if self.pending_triangles >= self.options.batch_triangles {
                    self.flush();
                }
                let items = self.own_items(e.dag_node, e.octree_node);
                if self.hidden(&pl.clip_from_object, &own, pl.eye, items) {
                    continue; // the traversal lists it again if it is drawn
                }
            }
            let e = VisEntry { stale: false, ..e };
            self.list_drawn += 1;
            // A flush may empty the batch; the entry stays listed either way.
            let _ = self.draw_own(
                e.dag_node,
                e.octree_node,
                &e.world_from_node,
                e.first_item,
                pl.clip_from_object,
                &own,
            );
            self.drawn_nodes.insert(key);
            self.list(e);
            self.maybe_flush();
        }
        self.listing = false;
        self.flush();
    }

    /// The mesh instances of `list` whose listed nodes hold at least the `whole` fraction of
    /// their mesh's triangles: most of such an instance was visible last frame, and one
    /// whole-mesh draw (vertices projected once, no box tests) costs less than its nodes'
    /// index lists and the tests of the rest. Not in the paper (see the module doc).
    fn whole_instances(&self, list: &[VisEntry]) -> IdSet<(u32, u64)> {
        let mut out = IdSet::default();
        let fraction = self.options.whole;
        if fraction <= 0.0 {
            return out;
        }
        let scene: &'a Scene = self.walk.scene();
        let mut listed: std::collections::HashMap<(u32, u64), u64, FxBuild> = Default::default();
        for e in list {
            if !e.stale && matches!(scene.node(e.dag_node).kind(), NodeKind::Mesh(_)) {
                *listed.entry((e.dag_node.0, e.first_item)).or_default() += self.node_of(e).count as u64;
            }
        }
        for (key, count) in listed {
            if let NodeKind::Mesh(mesh) = scene.node(NodeId(key.0)).kind() {
                if count as f64 >= fraction as f64 * mesh.triangle_count() as f64 {
                    out.insert(key);
                }
            }
        }
        out
    }

    /// The tested front-to-back traversal of the whole scene (§3.2).
    pub fn traverse(&mut self) {
        self.payoff.tests_begin(Instant::now());
        self.run();
        self.flush();
    }

    /// For a frame that skipped the visible list (`trust`): the share of the triangles of the
    /// skipped entries that the tested traversal drew anyway, an upper bound of the precision
    /// the recheck would measure (drawn is not yet visible at the frame's end), so that a list
    /// still too imprecise by it need not be rechecked. `None` with nothing skipped.
    pub fn skipped_drawn_share(&mut self) -> Option<f64> {
        if self.list_skipped == 0 || self.from_list_triangles == 0 {
            return None;
        }
        let drawn: u64 = self
            .from_list
            .iter()
            .filter(|k| self.listed.contains(k))
            .map(|&(id, n, _)| match &self.octrees[id as usize] {
                Some(o) => o.nodes()[n as usize].count as u64,
                None => 0,
            })
            .sum();
        let p = drawn as f64 / self.from_list_triangles as f64;
        self.list_precision_pct = Some((p * 100.0).round() as u64);
        Some(p)
    }

    /// §3.3: removes from the visible list the nodes whose own primitives are hidden in the
    /// final frame (frustum-culled ones stay when `keep_culled`, §5.1).
    /// Returns the list's precision (`trust`): the share of the triangles of last frame's
    /// entries in view that are still visible; `None` when there was nothing to measure.
    pub fn recheck(&mut self) -> Option<f64> {
        if self.payoff.stopped() {
            return None; // the list is dropped (`finish`): rechecking it would be testing again
        }
        let mut kept_from_list = 0u64;
        let t = Instant::now();
        self.pyramid.rebuild(self.frame);
        self.walk.stats.phases.add(Phase::DepthStructure, t.elapsed());
        let list = std::mem::take(&mut self.visible);
        let mut kept = Vec::with_capacity(list.len());
        for e in list {
            let own = self.node_of(&e).own_bounds;
            let pl = self.placement(&e);
            let outside = pl.frustum.classify_aabb(&own) == Containment::Outside;
            let keep = if outside {
                self.options.keep_culled
            } else {
                let mut pc = self.pc;
                let hidden = self.occlusion().box_hidden(&pl.clip_from_object, &own, pl.eye, &mut pc);
                self.pc = pc;
                !hidden
            };
            if keep {
                if !outside && self.from_list.contains(&(e.dag_node.0, e.octree_node, e.first_item)) {
                    kept_from_list += self.node_of(&e).count as u64;
                }
                kept.push(VisEntry { stale: outside, ..e });
            } else {
                self.recheck_dropped += 1;
                self.listed.remove(&(e.dag_node.0, e.octree_node, e.first_item));
            }
        }
        self.visible = kept;
        (self.from_list_triangles > 0).then(|| {
            let p = kept_from_list as f64 / self.from_list_triangles as f64;
            self.list_precision_pct = Some((p * 100.0).round() as u64);
            p
        })
    }

    /// The next visible list and the frame's statistics.
    pub fn finish(mut self) -> (Vec<VisEntry>, FrameStats) {
        if self.payoff.stopped() {
            // A frame that stopped testing lists only what it drew before it stopped; drawn
            // untested first next frame, in pieces, that costs more than it helps. The next
            // frame starts from the root, and stops again after a short probe if tests still
            // do not pay.
            self.visible.clear();
            self.listed.clear();
        }
        let c = &mut self.walk.stats.counters;
        c.add_all([
            ("occlusion_tests", self.occlusion_tests),
            ("occlusion_culled", self.occlusion_culled),
            ("frustum_culled", self.frustum_culled),
            ("pyramid_tests", self.pc.samples_tested),
            ("pyramid_descents", self.pc.descents),
            ("global_rejects", self.pc.global_rejects),
            ("visible_list", self.visible.len() as u64),
            ("visible_list_drawn", self.list_drawn),
            ("visible_list_frustum_culled", self.list_culled),
            ("recheck_dropped", self.recheck_dropped),
            ("batches", self.batches),
            ("whole_drawn", self.whole_drawn),
            ("visible_list_retested", self.list_retested),
            ("visible_list_skipped", self.list_skipped),
            ("refreshes", self.refreshes),
            ("refreshes_paid", self.refreshes_paid),
        ]);
        if let Some(p) = self.list_precision_pct {
            c.add(super::PRECISION, p);
        }
        c.add_all(self.payoff.counters());
        self.payoff_state.end(&self.payoff);
        (self.visible, self.walk.stats)
    }

    /// The placement of a visible-list entry's instance (cached: many entries share one).
    fn placement(&mut self, e: &VisEntry) -> Placement {
        let view = self.walk.view();
        *self
            .placements
            .entry((e.dag_node.0, e.first_item))
            .or_insert_with(|| Placement {
                frustum: view.frustum(&e.world_from_node),
                clip_from_object: view.clip_from_object(&e.world_from_node),
                eye: e.world_from_node.inverse().transform_point3(view.camera().eye),
            })
    }

    fn node_of(&self, e: &VisEntry) -> &'a occult_spatial::HybridOctreeNode {
        let octrees: &'a [Option<HybridOctree>] = self.octrees;
        match &octrees[e.dag_node.index()] {
            Some(o) => &o.nodes()[e.octree_node as usize],
            None => unreachable!("visible-list entries name octree nodes"),
        }
    }

    fn occlusion(&self) -> Occlusion<'_> {
        Occlusion {
            frame: self.frame,
            pyramid: self.pyramid,
            how: self.how,
            far_depth: self.walk.view().far_depth(),
        }
    }

    /// §3.1: false when primitive `p` is shared and this instance already drew it this frame.
    fn stamp(&mut self, id: NodeId, p: u32, first_item: u64) -> bool {
        self.stamps.stamp(id, p, first_item)
    }

    fn list(&mut self, e: VisEntry) {
        if self.listed.insert((e.dag_node.0, e.octree_node, e.first_item)) {
            self.visible.push(e);
        }
    }
}

impl<'a> Visitor<'a> for Walk<'a> {
    /// No test of the node's own box: an instance with an octree starts at its octree's root,
    /// a small mesh is tested (and counted) in [`Walk::small_mesh`].
    const NODE_TEST: NodeTest = NodeTest::None;

    fn walk(&mut self) -> &mut SceneWalk<'a> {
        &mut self.walk
    }

    /// Visits an instance: through its octree, or as one box (a small mesh). Sets
    /// `queued_whole` to whether a small mesh was queued whole (false for an instance walked
    /// through its octree).
    fn visit(&mut self, at: &NodeAt<'a>) {
        let octrees: &'a [Option<HybridOctree>] = self.octrees;
        let (id, first_item) = (at.place.id, at.place.first_item);
        self.queued_whole = match &octrees[id.index()] {
            Some(_) if self.whole.contains(&(id.0, first_item)) => false, // drawn whole
            Some(octree) if !octree.nodes().is_empty() => {
                let view = self.walk.view();
                let inst = Instance {
                    place: at.place,
                    octree,
                    frustum: at.frustum,
                    clip_from_object: view.clip_from_object(&at.place.world_from_node),
                    eye: at.place.world_from_node.inverse().transform_point3(view.camera().eye),
                };
                self.octree_node(&inst, 0, at.inside);
                false
            }
            Some(_) => false,
            None => self.small_mesh(at),
        };
    }
}

impl<'a> Walk<'a> {
    /// A node without an octree (a small mesh, or an empty group): tested as one box, then
    /// queued whole. Returns whether it was queued.
    fn small_mesh(&mut self, at: &NodeAt<'a>) -> bool {
        let scene: &'a Scene = self.walk.scene();
        let NodeKind::Mesh(mesh) = at.node.kind() else {
            return false; // an empty group
        };
        if mesh.triangle_count() == 0 || (at.place.id == scene.root() && self.share.index != 0) {
            return false; // a small mesh as the whole scene: the first worker draws it
        }
        let b = at.node.bounds();
        self.walk.stats.nodes_visited += 1;
        // `b` is not empty (the mesh has a triangle): the walk's test is the plain one.
        if !at.inside && self.walk.test(&at.frustum, &b) == Containment::Outside {
            self.frustum_culled += 1;
            return false;
        }
        let world_from_node = &at.place.world_from_node;
        let view = self.walk.view();
        let clip = view.clip_from_object(world_from_node);
        if self.options.occlusion {
            let eye = world_from_node.inverse().transform_point3(view.camera().eye);
            if self.hidden(&clip, &b, eye, mesh.triangle_count() as u64) {
                return false;
            }
        }
        self.push(mesh, Triangles::All, clip, at.place.first_item, &b);
        true
    }

    /// Triangle instances held by octree node `n`'s own primitives (not its children's).
    fn own_items(&self, id: NodeId, n: u32) -> u64 {
        let items = &self.subtree_items[id.index()];
        let Some(octree) = &self.octrees[id.index()] else {
            return 0;
        };
        let node = &octree.nodes()[n as usize];
        let below: u64 = node
            .children
            .iter()
            .filter(|&&c| c != NO_CHILD)
            .map(|&c| items[c as usize])
            .sum();
        items[n as usize] - below
    }

    /// The occlusion test of one box holding `items` triangle instances, counted; false
    /// without a test once tests stopped paying this frame.
    fn hidden(&mut self, clip: &Mat4, b: &occult_core::Aabb, eye: Vec3, items: u64) -> bool {
        if !self.payoff.test() {
            return false;
        }
        self.walk.stats.boxes_tested += 1;
        self.occlusion_tests += 1;
        let mut pc = self.pc;
        let mut hidden = self.occlusion().box_hidden(clip, b, eye, &mut pc);
        if !hidden && self.refresh_pays(clip, b) {
            // The batch may hide the box: draw it, and test again.
            self.flush();
            self.refreshes += 1;
            hidden = self.occlusion().box_hidden(clip, b, eye, &mut pc);
            self.refreshes_paid += u64::from(hidden);
        }
        self.pc = pc;
        if hidden {
            self.walk.stats.boxes_culled += 1;
            self.occlusion_culled += 1;
            self.payoff.saved(items);
        }
        hidden
    }

    /// Whether a box that failed its test should be tested again once the pending batch is
    /// drawn (`refresh`): the batch holds at least `refresh` triangles and its screen region
    /// meets the box's. Within a front-to-back walk the batch holds the nearest geometry drawn
    /// so far, often the very occluder of the box (the front of the same building); waiting
    /// for the batch to fill tests the box against a pyramid that lacks it.
    fn refresh_pays(&self, clip: &Mat4, b: &occult_core::Aabb) -> bool {
        let refresh = self.options.refresh;
        if refresh == 0 || self.pending_triangles < refresh || self.listing {
            return false;
        }
        let (Some(d), Some(r)) = (
            self.dirty,
            screen_rect(clip, b, self.frame.width(), self.frame.height()),
        ) else {
            return false;
        };
        d.x0 < r.x1 && r.x0 < d.x1 && d.y0 < r.y1 && r.y0 < d.y1
    }

    /// §3.2: test the node's box, draw its own primitives, then its children front to back.
    fn octree_node(&mut self, inst: &Instance<'a>, n: u32, inside: bool) {
        if self.raster.config().control.is_cancelled() {
            return; // the frame is not drawn at all
        }
        let node = &inst.octree.nodes()[n as usize];
        let stats = &mut self.walk.stats;
        stats.nodes_visited += 1;
        // Not `SceneWalk::test`: a cell holding only empty instances has an empty box, which
        // this test has always let through (and counted so); the counts must not move.
        let inside = inside || {
            stats.boxes_tested += 1;
            match inst.frustum.classify_aabb(&node.bounds) {
                Containment::Outside => {
                    stats.boxes_culled += 1;
                    self.frustum_culled += 1;
                    return;
                }
                c => c == Containment::Inside,
            }
        };
        if node.is_leaf()
            && matches!(self.walk.scene().node(inst.place.id).kind(), NodeKind::Mesh(_))
            && self.drawn_nodes.contains(&(inst.place.id.0, n, inst.place.first_item))
        {
            return; // a leaf the visible list drew: nothing left to test for
        }
        if self.payoff.stopped() && n == 0 && inside && self.share == Share::ALL {
            // Tests stopped paying: a mesh instance wholly in view is drawn whole, its vertices
            // projected once, as brute force draws it (what the visible list drew of it this
            // frame is drawn again, which changes no pixel).
            if let NodeKind::Mesh(mesh) = self.walk.scene().node(inst.place.id).kind() {
                let b = node.bounds;
                self.push(mesh, Triangles::All, inst.clip_from_object, inst.place.first_item, &b);
                self.maybe_flush();
                return;
            }
        }
        let items = self.subtree_items[inst.place.id.index()][n as usize];
        if self.options.occlusion && self.hidden(&inst.clip_from_object, &node.bounds, inst.eye, items) {
            return;
        }
        if node.count > 0 {
            let key = (inst.place.id.0, n, inst.place.first_item);
            let scene: &'a Scene = self.walk.scene();
            match scene.node(inst.place.id).kind() {
                NodeKind::Mesh(_) => {
                    // Deviation: an inner node's own primitives (its straddlers) get their own,
                    // tighter box test: the subtree's box passing says little about them.
                    let own_hidden = |w: &mut Self| {
                        w.options.occlusion
                            && !node.is_leaf()
                            && w.hidden(&inst.clip_from_object, &node.own_bounds, inst.eye, node.count as u64)
                    };
                    if !self.drawn_nodes.contains(&key) && !own_hidden(self) {
                        let own = node.own_bounds;
                        let drew = self.draw_own(
                            inst.place.id,
                            n,
                            &inst.place.world_from_node,
                            inst.place.first_item,
                            inst.clip_from_object,
                            &own,
                        );
                        if drew && self.options.temporal {
                            self.list_new(inst, n);
                        }
                    }
                }
                NodeKind::Group(instances) => {
                    let drawn = self.drawn_nodes.contains(&key);
                    let mut direct = false;
                    let root = scene.root();
                    // Deviation: front to back among the node's instances too (nearest centre
                    // first), so that a near instance is drawn before the far ones are tested.
                    let mut prims: Vec<(f32, u32)> = inst
                        .octree
                        .node_primitives(n)
                        .iter()
                        .map(|&p| {
                            let i = &instances[p as usize];
                            let c = i
                                .parent_from_child
                                .transform_point3(scene.node(i.child).bounds().center());
                            (c.distance_squared(inst.eye), p)
                        })
                        .collect();
                    prims.sort_by(|a, b| a.0.total_cmp(&b.0));
                    for &(_, p) in &prims {
                        let i = &instances[p as usize];
                        if !self.share.enters(inst.place.id, root, p) {
                            continue;
                        }
                        let has_octree = self.octrees[i.child.index()].is_some();
                        if !has_octree
                            && (drawn
                                || !self.share.owns_node(key)
                                || !self.share.owns_primitive(inst.place.id, root, key, p))
                        {
                            continue; // the visible list drew it, or another worker does
                        }
                        if !self.stamp(inst.place.id, p, inst.place.first_item) {
                            continue;
                        }
                        // The node joins the visible list only when one of its small meshes was
                        // drawn: a node whose small meshes were all culled would otherwise be
                        // drawn untested next frame.
                        self.enter(inst.place.child_of(scene.node(inst.place.id), p as usize), inside);
                        direct |= self.queued_whole;
                    }
                    if direct && !drawn && self.options.temporal {
                        self.list_new(inst, n);
                    }
                }
            }
            self.maybe_flush();
        }
        let (order, count) = match self.options.order {
            ChildOrder::FrontToBack => inst.octree.children_front_to_back(n, inst.eye),
            // Deviation: §4.2/§5.1's invisible-list order applied to siblings (see the module doc).
            ChildOrder::Count => {
                let mut c = node.children;
                c.sort_by_key(|&c| {
                    if c == NO_CHILD {
                        u32::MAX
                    } else {
                        inst.octree.nodes()[c as usize].subtree_count
                    }
                });
                (c, node.children.iter().filter(|&&c| c != NO_CHILD).count())
            }
        };
        for &c in &order[..count] {
            self.octree_node(inst, c, inside);
        }
    }

    fn list_new(&mut self, inst: &Instance<'a>, n: u32) {
        self.list(VisEntry {
            dag_node: inst.place.id,
            octree_node: n,
            first_item: inst.place.first_item,
            world_from_node: inst.place.world_from_node,
            stale: false,
        });
    }

    /// Adds the own primitives of octree node `n` of an instance of `id` that can be drawn
    /// directly: a mesh's triangles, or a group's instances of small meshes (those of nodes with
    /// octrees are visited by the traversal, or listed themselves). Returns whether anything
    /// was queued.
    fn draw_own(
        &mut self,
        id: NodeId,
        n: u32,
        world_from_node: &Affine3A,
        first_item: u64,
        clip: Mat4,
        own_box: &occult_core::Aabb,
    ) -> bool {
        let scene: &'a Scene = self.walk.scene();
        let octrees: &'a [Option<HybridOctree>] = self.octrees;
        let Some(octree) = &octrees[id.index()] else {
            return false;
        };
        let key = (id.0, n, first_item);
        if !self.share.owns_node(key) {
            return false;
        }
        let queued = self.pending.len();
        let (share, root) = (self.share, scene.root());
        match scene.node(id).kind() {
            NodeKind::Mesh(mesh) => {
                let own = octree.node_primitives(n);
                let start = self.scratch.len() as u32;
                if self.share == Share::ALL {
                    // The unshared triangles as clusters, the shared ones not drawn yet as a list.
                    let meshlets: &'a [Option<RunClusters>] = self.meshlets;
                    match &meshlets[id.index()] {
                        Some(m) => {
                            let (meshlets, list) = m.runs(n as usize..n as usize + 1);
                            if !list.is_empty() {
                                self.push(mesh, Triangles::Clusters(meshlets, list), clip, first_item, own_box);
                            }
                        }
                        // Every mesh octree has its clusters (built with it); were one missing,
                        // its unshared triangles would go as a list.
                        None => self.scratch.extend(own.iter().filter(|&&p| !octree.is_shared(p))),
                    }
                    self.stamps.gather_shared(id, n, first_item, &mut self.scratch);
                    let end = self.scratch.len() as u32;
                    if end > start {
                        self.push(mesh, Triangles::Scratch(start, end), clip, first_item, own_box);
                    }
                    return self.pending.len() > queued;
                }
                for &p in own {
                    if !share.owns_primitive(id, root, key, p) {
                        continue;
                    }
                    // §3.1: a shared primitive is drawn once per frame.
                    if !self.stamp(id, p, first_item) {
                        continue;
                    }
                    self.scratch.push(p);
                }
                let end = self.scratch.len() as u32;
                if end > start {
                    self.push(mesh, Triangles::Scratch(start, end), clip, first_item, own_box);
                }
            }
            NodeKind::Group(instances) => {
                for &p in octree.node_primitives(n) {
                    let i = &instances[p as usize];
                    if octrees[i.child.index()].is_some() || !share.owns_primitive(id, root, key, p) {
                        continue;
                    }
                    let NodeKind::Mesh(mesh) = scene.node(i.child).kind() else {
                        continue;
                    };
                    if !self.stamp(id, p, first_item) {
                        continue;
                    }
                    let child = Placed {
                        id,
                        world_from_node: *world_from_node,
                        first_item,
                    }
                    .child_of(scene.node(id), p as usize);
                    let clip = self.walk.view().clip_from_object(&child.world_from_node);
                    let b = scene.node(i.child).bounds();
                    self.push(mesh, Triangles::All, clip, child.first_item, &b);
                }
            }
        }
        self.pending.len() > queued
    }

    /// Queues triangles whose object-space bounds are `b` (their screen region grows the
    /// pending batch's, for `refresh`).
    fn push(&mut self, mesh: &'a Mesh, triangles: Triangles<'a>, clip: Mat4, first_item: u64, b: &occult_core::Aabb) {
        self.pending_triangles += triangles.count(mesh);
        // Only the view's region is drawn (a strip of columns: `parallel=columns`, `bands`).
        let (columns, rows) = (self.walk.view().columns(), self.walk.view().rows());
        let region = PixelRect {
            x0: columns.start,
            y0: rows.start,
            x1: columns.end,
            y1: rows.end,
        };
        let in_region =
            screen_rect(&clip, b, self.frame.width(), self.frame.height()).and_then(|r| r.intersect(&region));
        if let Some(r) = in_region {
            self.dirty = Some(match self.dirty {
                None => r,
                Some(d) => PixelRect {
                    x0: d.x0.min(r.x0),
                    y0: d.y0.min(r.y0),
                    x1: d.x1.max(r.x1),
                    y1: d.y1.max(r.y1),
                },
            });
        }
        self.pending.push(Pending {
            mesh,
            triangles,
            clip_from_object: clip,
            first_item,
        });
    }

    fn maybe_flush(&mut self) {
        let batch = if self.payoff.stopped() || self.listing {
            DIRECT_BATCH
        } else {
            self.options.batch_triangles
        };
        if self.pending_triangles >= batch {
            self.flush();
        }
    }

    /// Rasterizes the batch, then brings the pyramid up to date where the batch wrote.
    fn flush(&mut self) {
        if self.pending.is_empty() {
            return;
        }
        let draws: Vec<Draw<'_>> = self
            .pending
            .iter()
            .map(|p| Draw {
                mesh: p.mesh,
                triangles: match p.triangles {
                    Triangles::All => DrawTriangles::All,
                    Triangles::Scratch(s, e) => DrawTriangles::List(&self.scratch[s as usize..e as usize]),
                    Triangles::Clusters(meshlets, list) => DrawTriangles::Clusters { meshlets, list },
                },
                clip_from_object: p.clip_from_object,
                first_item: p.first_item,
            })
            .collect();
        let t = Instant::now();
        crate::rasterize(self.raster, self.walk.view(), self.frame, &draws, &mut self.walk.stats);
        let shared = self.pending_triangles >= DIRECT_BATCH;
        self.payoff
            .rasterized(self.pending_triangles as u64, t.elapsed(), shared);
        drop(draws);
        self.batches += 1;
        // Only what the batch wrote changed: the box of its triangles that wrote a fragment
        // (none when the batch was wholly hidden), within the view's region.
        self.dirty = None;
        let dirty = crate::written_region(self.raster, self.walk.view());
        if let Some(d) = dirty {
            // Once tests stopped, only the recheck reads the pyramid, and it rebuilds it.
            if self.options.occlusion && !self.payoff.stopped() {
                let t = Instant::now();
                self.pyramid.update(self.frame, d);
                self.walk.stats.phases.add(Phase::DepthStructure, t.elapsed());
            }
        }
        self.pending.clear();
        self.scratch.clear();
        self.pending_triangles = 0;
    }
}
