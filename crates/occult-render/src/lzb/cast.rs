//! The ray caster of local z-buffering: lazy (§III.A) and selective (§III.B) ray casting that
//! records ray paths into the PVL, naive ray casting (§II) that finds first hits, and the
//! coherence start (§III.D).

use std::collections::{HashMap, HashSet};

use occult_core::{compose, Aabb, Affine3A, ItemId, Mat4, NodeId, Vec3, Vec4};
use occult_spatial::{traverse, traverse_bvh, traverse_bvh_from, FatRay, RayBvh, ShearedRay, TraversalCounters};

use super::{Accel, FrameCtx, Lzb, Mode, Selection};
use crate::hash::FxBuild;

/// A mesh instance met during a frame: names its triangles' items and places them.
#[derive(Clone, Copy, Debug)]
pub(super) struct InstanceRec {
    pub node: NodeId,
    pub world_from_object: Affine3A,
}

/// Relative depth margin past a robust hit (§III.A's "current leaf", made conservative): the
/// rasterizer's winner at the pixel may lie slightly behind the ray's hit by rounding.
pub(super) const DEPTH_EPS: f32 = 2e-3;
/// A robust hit covers the pixel centre by at least this many pixels on every edge.
const EDGE_MARGIN_PX: f64 = 1.0 / 32.0;
/// With `caster=bvh`, the next ray's coherence start (§III.D) is the BVH subtree this many
/// levels above the leaf of the hit (1: the node holding the leaf).
const START_LEVELS: u32 = 2;
/// Absolute margin of a fat ray, relative to the magnitude of the coordinates.
const ABS_EPS: f32 = 1e-5;

/// What a ray's terminating hit was, for the next ray's coherence start (§III.D).
#[derive(Clone, Copy)]
struct LastHit {
    node: NodeId,
    /// The octree leaf, or with `caster=bvh` the root of a BVH subtree holding the leaf.
    leaf: u32,
    object_from_world: Affine3A,
    clip_from_object: Mat4,
}

/// A mesh instance a ray met that holds candidate leaves of its path.
struct Met {
    /// Item id of its first triangle.
    base: ItemId,
    node: NodeId,
    world_from_object: Affine3A,
    /// The ray in the node's space.
    ray: FatRay,
    /// Something of it is on the path.
    recorded: bool,
}

/// Per-thread state of the ray caster.
pub(super) struct Caster<'a> {
    lzb: &'a Lzb,
    ctx: &'a FrameCtx,
    /// PVL entries `(instance first item, leaf)`, without duplicates.
    pub pvl: HashSet<(ItemId, u32), FxBuild>,
    /// The instances the PVL names.
    pub instances: HashMap<ItemId, InstanceRec, FxBuild>,
    /// First hits of naive rays `(pixel index, depth, item)`.
    pub hits: Vec<(u32, f32, ItemId)>,
    pub counters: TraversalCounters,
    pub rays: u64,
    pub tri_tests: u64,
    pub coherent_starts: u64,
    /// Rays that ended at a robust hit (the others ran to the far plane or out of the scene).
    pub resolved: u64,
    /// Mailbox of the current ray: `(group visit serial, instance)` already cast.
    visited: HashSet<(u32, u32), FxBuild>,
    /// The current ray's mesh instances that hold candidate leaves.
    met: Vec<Met>,
    /// The current ray's candidate leaves, in far leaves: `(index into met, leaf, entry)`;
    /// those entered before the ray's final bound are its path (§III.A).
    candidates: Vec<(u32, u32, f32)>,
    serial: u32,
    last: Option<LastHit>,
    /// The hit that ended the current ray.
    found: Option<LastHit>,
    pixel: (f32, f32),
    best: Option<(f32, ItemId)>,
    naive: bool,
}

impl<'a> Caster<'a> {
    pub fn new(lzb: &'a Lzb, ctx: &'a FrameCtx, naive: bool) -> Self {
        Self {
            lzb,
            ctx,
            pvl: HashSet::default(),
            instances: HashMap::default(),
            hits: Vec::new(),
            counters: TraversalCounters::default(),
            rays: 0,
            tri_tests: 0,
            coherent_starts: 0,
            resolved: 0,
            visited: HashSet::default(),
            met: Vec::new(),
            candidates: Vec::new(),
            serial: 0,
            last: None,
            found: None,
            pixel: (0.0, 0.0),
            best: None,
            naive,
        }
    }

    /// Casts the ray of pixel `(x, y)`: lazy/selective rays record their path into the PVL
    /// (§III.A/B); naive rays (§II) return their first hit `(ray parameter = view distance, item)`.
    pub fn cast(&mut self, x: u32, y: u32) -> Option<(f32, ItemId)> {
        self.rays += 1;
        let (px, py) = (x as f32 + 0.5, y as f32 + 0.5);
        self.pixel = (px, py);
        let dir = self.ctx.pixel_direction(px, py);
        let origin = self.ctx.eye;
        self.visited.clear();
        self.best = None;
        self.found = None;
        // Nothing beyond the far plane is drawn: the path stops there.
        let mut t_limit = self.ctx.far * (1.0 + DEPTH_EPS);
        let spread = if self.naive { 0.0 } else { self.ctx.spread };
        if self.lzb.opts.coherence && !self.naive {
            if let Some(h) = self.last {
                // §III.D: start from the neighbour's result: its hit leaf, tested first, bounds
                // the whole traversal that follows.
                let o = h.object_from_world.transform_point3(origin);
                let d = h.object_from_world.transform_vector3(dir);
                if let Some(t) = self.test_start(&h, o, d, t_limit) {
                    t_limit = t * (1.0 + DEPTH_EPS);
                    self.found = Some(h);
                    self.coherent_starts += 1;
                }
            }
        }
        // One pass finds the bound (the first robust hit) and keeps every far leaf it enters with
        // its entry; those entered before the final bound are the path. The bound only falls
        // during the pass, so every leaf the cone enters before the final bound is met (a
        // traversal with the final bound from the start would meet no other, and perhaps fewer:
        // a leaf's tight box may start nearer than its octant). Recording as the pass goes would
        // record, in an instance met early whose box starts near, everything up to that
        // instance's own hit, before an instance met later (a wall) lowers the bound.
        self.met.clear();
        self.candidates.clear();
        let root = self.lzb.scene.root();
        self.visit(
            root,
            origin,
            dir,
            spread,
            &Affine3A::IDENTITY,
            &Affine3A::IDENTITY,
            0,
            &mut t_limit,
        );
        if !self.naive && self.lzb.opts.mode == Mode::Lazy {
            self.record(t_limit);
        }
        self.last = self.found;
        self.resolved += self.found.is_some() as u64;
        self.best
    }

    /// §III.D: the nearest robust hit before `t_max` in the region where the neighbour's ray
    /// ended: its octree leaf, or with `caster=bvh` the BVH subtree [`START_LEVELS`] above its
    /// leaf, walked by the thin ray (a leaf of a few triangles alone would seldom be hit again).
    fn test_start(&mut self, h: &LastHit, o: Vec3, d: Vec3, t_max: f32) -> Option<f32> {
        let lzb = self.lzb;
        let sheared = ShearedRay::new(o, d);
        let Accel::Mesh { bvh: Some(b), .. } = &lzb.accel[h.node.index()] else {
            return self.test_leaf(h.node, h.leaf, &sheared, d, &h.clip_from_object, t_max, 0);
        };
        let ray = FatRay::new(o, d, 0.0, 0.0);
        let mut bound = t_max;
        let mut best = None;
        let mut counters = TraversalCounters::default();
        traverse_bvh_from(
            &b.bvh,
            h.leaf,
            &ray,
            &mut bound,
            &mut counters,
            |leaf, _, _, _, bound| {
                if let Some(t) = self.test_leaf(h.node, leaf, &sheared, d, &h.clip_from_object, *bound, 0) {
                    *bound = t;
                    best = Some(t);
                }
            },
        );
        best
    }

    /// Tests the candidate triangles of mesh leaf `leaf` (an octree node, or with `caster=bvh` a
    /// BVH leaf code; per the selection, §III.B) and returns
    /// the nearest robust hit before `t_max` (lazy), or records the nearest hit (naive).
    /// `sheared` is the ray `o + t·d` (object space) prepared for the watertight test.
    #[allow(clippy::too_many_arguments)]
    fn test_leaf(
        &mut self,
        node: NodeId,
        leaf: u32,
        sheared: &ShearedRay,
        d: Vec3,
        clip_from_object: &Mat4,
        t_max: f32,
        base: ItemId,
    ) -> Option<f32> {
        let lzb = self.lzb;
        let Accel::Mesh {
            octree,
            refs,
            leaf_base,
            bvh,
            ..
        } = &lzb.accel[node.index()]
        else {
            return None;
        };
        let (ids, list, base_vis) = match bvh {
            Some(b) => {
                let list = b.bvh.leaf_triangles(leaf);
                // The base visibility from the leaf's own few triangles (the sum the octree's
                // leaves keep, in the same order), read with them rather than from a side
                // array, which would be one more miss per leaf.
                let base_vis = if lzb.opts.selection == Selection::All || self.naive {
                    0.0
                } else {
                    let sum: f32 = list.iter().map(|r| r.normal.length()).sum();
                    lzb.opts.base_cos * sum / list.len() as f32
                };
                (&b.bvh.triangles()[RayBvh::leaf_range(leaf)], list, base_vis)
            }
            None => {
                let range = octree.nodes()[leaf as usize].range();
                (
                    &octree.primitives()[range.clone()],
                    &refs[range],
                    leaf_base[leaf as usize],
                )
            }
        };
        let (n, filter) = if self.naive {
            (list.len(), false)
        } else {
            match lzb.opts.selection {
                Selection::All => (list.len(), false),
                // §III.B.1: the k largest triangles (the leaf list is sorted by area).
                Selection::Static => (list.len().min(lzb.opts.k), false),
                // §III.B.2: visibility = -v·n·area against the leaf's base visibility.
                Selection::Dynamic => (list.len(), true),
                // Hybrid: the pre-selected occluders, filtered by visibility.
                Selection::Hybrid => (list.len().min(lzb.opts.k), true),
            }
        };
        occult_spatial::prefetch_triangles(&list[..n]);
        let dn = if filter { d.normalize() } else { d };
        let mut best: Option<f32> = None;
        // Eight triangles at a time (the same hits and parameters as one at a time), the hits
        // then taken in list order as a one-at-a-time loop would.
        for (c, chunk) in list[..n].chunks(8).enumerate() {
            let mut active = (1u32 << chunk.len()) - 1;
            if filter {
                // Deviation: both faces are drawn unless back faces are culled, so |v·n|
                // (not -v·n).
                for (i, r) in chunk.iter().enumerate() {
                    if r.normal.dot(dn).abs() <= base_vis {
                        active &= !(1 << i);
                    }
                }
            }
            self.tri_tests += active.count_ones() as u64;
            let (mut hits, ts) = sheared.intersect8(chunk, active, 0.0, t_max);
            while hits != 0 {
                let i = hits.trailing_zeros() as usize;
                hits &= hits - 1;
                let hit_t = ts[i];
                if best.is_some_and(|bt| hit_t >= bt) {
                    continue;
                }
                if self.naive {
                    if self.best.is_none_or(|(bt, _)| hit_t < bt) {
                        self.best = Some((hit_t, base + ids[8 * c + i] as u64));
                    }
                    best = Some(hit_t);
                } else if self.robust(clip_from_object, chunk[i].corners, hit_t) {
                    best = Some(hit_t);
                }
            }
        }
        best
    }

    /// True when the rasterizer surely draws this triangle at the current pixel centre: every
    /// corner well in front of the near plane, the centre inside every projected edge by
    /// [`EDGE_MARGIN_PX`] (vertex snapping moves edges by at most 1/256 pixel), facing right when
    /// back faces are culled, and the hit nearer than the far plane.
    fn robust(&self, clip_from_object: &Mat4, tri: [Vec3; 3], t: f32) -> bool {
        let ctx = self.ctx;
        if t.is_nan() || t * (1.0 + DEPTH_EPS) >= ctx.far {
            return false;
        }
        let mut s = [(0f64, 0f64); 3];
        for (k, p) in tri.iter().enumerate() {
            let c: Vec4 = *clip_from_object * p.extend(1.0);
            if !c.is_finite() || c.w <= ctx.near * 1.01 {
                return false;
            }
            let x = (c.x / c.w * 0.5 + 0.5) as f64 * ctx.width;
            let y = (0.5 - c.y / c.w * 0.5) as f64 * ctx.height;
            if x.abs() > 16384.0 || y.abs() > 16384.0 {
                return false;
            }
            s[k] = (x, y);
        }
        let (px, py) = (self.pixel.0 as f64, self.pixel.1 as f64);
        let area = (s[1].0 - s[0].0) * (s[2].1 - s[0].1) - (s[2].0 - s[0].0) * (s[1].1 - s[0].1);
        if area == 0.0 || !area.is_finite() {
            return false;
        }
        // On screen (y down) a counter-clockwise front face has negative area.
        if ctx.cull_backfaces && area > 0.0 {
            return false;
        }
        (0..3).all(|k| {
            let (a, b) = (s[k], s[(k + 1) % 3]);
            let e = (b.0 - a.0) * (py - a.1) - (b.1 - a.1) * (px - a.0);
            let len = ((b.0 - a.0).powi(2) + (b.1 - a.1).powi(2)).sqrt();
            e * area.signum() / len >= EDGE_MARGIN_PX
        })
    }

    /// Records the current ray's path: its candidate leaves entered no later than `t_limit`,
    /// the final bound, into the PVL (with their instances). With `pvl=triangles`
    /// (deviation), only the triangles of those leaves whose box the cone enters before the
    /// bound: as conservative as the leaf, the pixel's winner lying within the cone, nearer
    /// than the bound.
    fn record(&mut self, t_limit: f32) {
        let lzb = self.lzb;
        for &(m, leaf, t_enter) in &self.candidates {
            if t_enter > t_limit {
                continue;
            }
            let met = &mut self.met[m as usize];
            let Accel::Mesh { octree, refs, bvh, .. } = &lzb.accel[met.node.index()] else {
                continue;
            };
            if !lzb.opts.pvl_triangles {
                // The leaf (with `caster=bvh` a BVH leaf of a few triangles, listed when the
                // PVL is assembled).
                self.pvl.insert((met.base, leaf));
                met.recorded = true;
                continue;
            }
            let (list, ids) = match bvh {
                Some(b) => {
                    let range = RayBvh::leaf_range(leaf);
                    (b.bvh.leaf_triangles(leaf), &b.bvh.triangles()[range])
                }
                None => {
                    let range = octree.nodes()[leaf as usize].range();
                    (&refs[range.clone()], &octree.primitives()[range])
                }
            };
            for (r, &t) in list.iter().zip(ids) {
                if met
                    .ray
                    .enter(&Aabb::from_points(r.corners))
                    .is_some_and(|(e, _)| e <= t_limit)
                {
                    self.pvl.insert((met.base, t));
                    met.recorded = true;
                }
            }
        }
        for met in self.met.iter().filter(|m| m.recorded) {
            self.instances.entry(met.base).or_insert(InstanceRec {
                node: met.node,
                world_from_object: met.world_from_object,
            });
        }
    }

    /// The index in `met` of mesh instance `id` (first item `base`) the current ray meets
    /// (`slot`: its index once known), added on first use.
    fn meet(
        &mut self,
        slot: &mut Option<u32>,
        base: ItemId,
        id: NodeId,
        world_from_node: &Affine3A,
        ray: &FatRay,
    ) -> u32 {
        *slot.get_or_insert_with(|| {
            self.met.push(Met {
                base,
                node: id,
                world_from_object: *world_from_node,
                ray: *ray,
                recorded: false,
            });
            (self.met.len() - 1) as u32
        })
    }

    /// Lowers the bound to hit `t` of leaf `leaf` of mesh `node` (by the depth margin when
    /// lazy), keeping the hit for the next ray's coherence start.
    #[inline]
    fn lower_bound(
        &mut self,
        t: f32,
        t_limit: &mut f32,
        node: NodeId,
        leaf: u32,
        node_from_world: &Affine3A,
        clip: Mat4,
    ) {
        if self.naive {
            *t_limit = t;
        } else if t * (1.0 + DEPTH_EPS) < *t_limit {
            *t_limit = t * (1.0 + DEPTH_EPS);
            self.found = Some(LastHit {
                node,
                leaf,
                object_from_world: *node_from_world,
                clip_from_object: clip,
            });
        }
    }

    /// Casts the ray `o + t·d` (node space) through node `id` placed by `world_from_node`.
    #[allow(clippy::too_many_arguments)]
    fn visit(
        &mut self,
        id: NodeId,
        o: Vec3,
        d: Vec3,
        spread: f32,
        world_from_node: &Affine3A,
        node_from_world: &Affine3A,
        base: ItemId,
        t_limit: &mut f32,
    ) {
        let lzb = self.lzb;
        let margin =
            |b: &occult_core::Aabb| ABS_EPS * (b.min.abs().max(b.max.abs()).max_element() + o.abs().max_element());
        let mut counters = TraversalCounters::default();
        match &lzb.accel[id.index()] {
            Accel::Empty => {}
            Accel::Mesh { octree, bvh, .. } => {
                let ray = FatRay::new(o, d, spread, if self.naive { 0.0 } else { margin(&octree.bounds()) });
                // Naive rays take any hit: the projection serves only the robustness test.
                let clip = if self.naive {
                    Mat4::IDENTITY
                } else {
                    self.ctx.view.clip_from_object(world_from_node)
                };
                let w_row = row_w(&clip);
                let keep = !self.naive && lzb.opts.mode == Mode::Lazy;
                let mut met: Option<u32> = None;
                let sheared = ShearedRay::new(o, d);
                if let Some(b) = bvh {
                    // `caster=bvh` (deviation): the mesh's BVH. A leaf all of whose box lies
                    // nearer than the near limit holds only triangles the near pass draws; the
                    // others are candidates of the path.
                    traverse_bvh(
                        &b.bvh,
                        &ray,
                        t_limit,
                        &mut counters,
                        |leaf, t_enter, bounds, parent, t_limit| {
                            if keep && !self.ctx.is_wholly_near(w_row, bounds) {
                                let m = self.meet(&mut met, base, id, world_from_node, &ray);
                                self.candidates.push((m, leaf, t_enter));
                            }
                            if let Some(t) = self.test_leaf(id, leaf, &sheared, d, &clip, *t_limit, base) {
                                // The coherence start of the next ray: a subtree holding the leaf.
                                let start = (1..START_LEVELS).fold(parent, |n, _| b.bvh.parent(n));
                                self.lower_bound(t, t_limit, id, start, node_from_world, clip);
                            }
                        },
                    );
                    self.counters.nodes_visited += counters.nodes_visited;
                    self.counters.leaves_visited += counters.leaves_visited;
                    return;
                }
                // Deviation: the leaves' boxes are their tight boxes, not their octants
                // (`RayOctree::tighten_leaves`): the traversal hands over only leaves whose tight
                // box the cone enters before the bound.
                traverse(octree, &ray, t_limit, &mut counters, |leaf, t_enter, _, t_limit| {
                    // §III.A: every far leaf on the path up to (and past, by the margin) the hit
                    // is recorded once the bound is final (`record`); near leaves are drawn
                    // already (step 3).
                    if keep && !self.ctx.is_near(w_row, &octree.nodes()[leaf as usize].bounds) {
                        let m = self.meet(&mut met, base, id, world_from_node, &ray);
                        self.candidates.push((m, leaf, t_enter));
                    }
                    if let Some(t) = self.test_leaf(id, leaf, &sheared, d, &clip, *t_limit, base) {
                        self.lower_bound(t, t_limit, id, leaf, node_from_world, clip);
                    }
                });
            }
            Accel::Group {
                octree,
                bounds,
                child_from_parent,
                stretch,
            } => {
                let node = lzb.scene.node(id);
                let instances = node.instances();
                self.serial += 1;
                let serial = self.serial;
                let ray = FatRay::new(o, d, spread, if self.naive { 0.0 } else { margin(&octree.bounds()) });
                traverse(octree, &ray, t_limit, &mut counters, |leaf, _, _, t_limit| {
                    for &i in octree.leaf_primitives(leaf) {
                        // Mailbox: an instance spanning several leaves is cast once per ray.
                        if !self.visited.insert((serial, i)) {
                            continue;
                        }
                        let i = i as usize;
                        if !ray.enter(&bounds[i]).is_some_and(|(e, _)| e <= *t_limit) {
                            continue;
                        }
                        let cfp = &child_from_parent[i];
                        let world_from_child = compose(world_from_node, &instances[i].parent_from_child);
                        let child_from_world = *cfp * *node_from_world;
                        self.visit(
                            instances[i].child,
                            cfp.transform_point3(o),
                            cfp.transform_vector3(d),
                            spread * stretch[i],
                            &world_from_child,
                            &child_from_world,
                            base + node.item_offset(i),
                            t_limit,
                        );
                    }
                });
            }
        }
        self.counters.nodes_visited += counters.nodes_visited;
        self.counters.leaves_visited += counters.leaves_visited;
    }
}

/// The row of `clip_from_object` giving clip `w` (the view distance).
#[inline]
pub(super) fn row_w(m: &Mat4) -> Vec4 {
    Vec4::new(m.x_axis.w, m.y_axis.w, m.z_axis.w, m.w_axis.w)
}
