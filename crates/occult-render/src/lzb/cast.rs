//! The ray caster of local z-buffering: lazy (§III.A) and selective (§III.B) ray casting that
//! records ray paths into the PVL, naive ray casting (§II) that finds first hits, and the
//! coherence start (§III.D).

use std::collections::{HashMap, HashSet};

use occult_core::{compose, Aabb, Affine3A, ItemId, Mat4, NodeId, Vec3, Vec4};
use occult_spatial::{
    intersect8_packet, traverse, traverse_bvh, traverse_bvh_from, traverse_bvh_packet, FatRay, RayBvh, RayPacket,
    ShearedRay, TraversalCounters, PACKET,
};

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
/// The cone of a `pvl=hits` ray, as a share of the lazy rays' (1/8 pixel): 1/64 pixel, four
/// times the most that vertex snapping (1/256 pixel) moves an edge. Its triangles are recorded
/// one by one, so a narrower cone records fewer; the lazy rays' leaves are recorded whole.
const HITS_SPREAD: f32 = 1.0 / 8.0;
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
    /// `pvl=hits`: PVL entries `(instance first item, triangle)`, in runs of one instance, one
    /// run per instance a packet recorded, sorted and without duplicates within it.
    pub pvl_hits: Vec<(ItemId, u32)>,
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
    /// `pvl=hits`: the mesh instances the current packet met.
    hit_met: Vec<HitMet>,
    /// `pvl=hits`: the current packet's close triangles (`Cand`).
    cands: Vec<Cand>,
}

/// A mesh instance a packet of `pvl=hits` rays met.
struct HitMet {
    base: ItemId,
    node: NodeId,
    world_from_object: Affine3A,
    recorded: bool,
}

/// A triangle that a ray's cone may touch (`pvl=hits`): the ray, the instance (index into
/// `hit_met`), the triangle's index in its mesh, and the parameter the ray's final bound must
/// reach for the triangle to be on its path (its corners' least parameter less the slack).
#[derive(Clone, Copy)]
struct Cand {
    ray: u8,
    met: u32,
    triangle: u32,
    t_reach: f32,
}

impl<'a> Caster<'a> {
    pub fn new(lzb: &'a Lzb, ctx: &'a FrameCtx, naive: bool) -> Self {
        Self {
            lzb,
            ctx,
            pvl: HashSet::default(),
            pvl_hits: Vec::new(),
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
            hit_met: Vec::new(),
            cands: Vec::new(),
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

    /// Casts the naive rays (§II) of up to [`PACKET`] neighbouring pixels (`pixels`, indices
    /// into rows of `width`) together (`packets=on`; not in the paper): through each mesh's BVH
    /// as one packet ([`traverse_bvh_packet`]), through a group's octree as one cone holding
    /// them all. Pushes each ray's first hit to `hits` (ties: [`PacketHit::before`]).
    pub fn cast_packet(&mut self, pixels: &[u32], width: u32) {
        debug_assert!(self.naive && pixels.len() <= PACKET);
        if pixels.is_empty() {
            return;
        }
        self.rays += pixels.len() as u64;
        self.visited.clear();
        let mut dirs = [Vec3::ZERO; PACKET];
        for (d, &i) in dirs.iter_mut().zip(pixels) {
            *d = self
                .ctx
                .pixel_direction((i % width) as f32 + 0.5, (i / width) as f32 + 0.5);
        }
        let mut rays = Rays {
            t_limit: [self.ctx.far * (1.0 + DEPTH_EPS); PACKET],
            best: [None; PACKET],
        };
        let all = u64::MAX >> (PACKET - pixels.len());
        let root = self.lzb.scene.root();
        self.visit_packet(root, self.ctx.eye, &dirs, all, 0, &mut rays);
        // The hits' items, read only now: loads of the rays' triangle ids that do not wait on
        // one another, rather than one in each ray's chain of dependent misses.
        for (&i, best) in pixels.iter().zip(rays.best) {
            if let Some(hit) = best {
                let Accel::Mesh { bvh: Some(b), .. } = &self.lzb.accel[hit.node as usize] else {
                    unreachable!("a packet hit is in a mesh with a BVH");
                };
                self.hits
                    .push((i, hit.t, hit.base + u64::from(b.bvh.triangles()[hit.slot as usize])));
            }
        }
    }

    /// Casts the lazy rays of up to [`PACKET`] neighbouring pixels together with `pvl=hits`
    /// (not in the paper): each ray a cone of radius 1/64 pixel around the pixel centre's ray,
    /// bounded by its first robust hit (§III.A's rule), records the triangles its cone may
    /// touch no farther than that bound ([`ShearedRay::candidates8`]) instead of the leaves
    /// it enters. The rays walk each mesh's BVH as one packet of cones
    /// ([`RayPacket::fat`]) and a group's octree as one cone that holds them all.
    ///
    /// Why the PVL is still exact: the triangle the rasterizer shows at a pixel centre covers
    /// it (vertex snapping moves an edge by at most 1/256 pixel), so it lies within the cone
    /// there, in a leaf whose box the cone enters; it is no farther than the robust hit, which
    /// the rasterizer surely draws there, plus the depth margin; so it is close, within reach
    /// of the final bound, and recorded.
    pub fn cast_packet_hits(&mut self, pixels: &[u32], width: u32) {
        debug_assert!(!self.naive && pixels.len() <= PACKET);
        if pixels.is_empty() {
            return;
        }
        self.rays += pixels.len() as u64;
        self.visited.clear();
        self.hit_met.clear();
        self.cands.clear();
        let mut dirs = [Vec3::ZERO; PACKET];
        let mut centres = [(0f32, 0f32); PACKET];
        for ((d, c), &i) in dirs.iter_mut().zip(&mut centres).zip(pixels) {
            *c = ((i % width) as f32 + 0.5, (i / width) as f32 + 0.5);
            *d = self.ctx.pixel_direction(c.0, c.1);
        }
        let mut rays = HitRays {
            t_limit: [self.ctx.far * (1.0 + DEPTH_EPS); PACKET],
            resolved: 0,
            centres,
        };
        let all = u64::MAX >> (PACKET - pixels.len());
        let root = self.lzb.scene.root();
        self.visit_packet_hits(
            root,
            self.ctx.eye,
            &dirs,
            all,
            self.ctx.spread * HITS_SPREAD,
            &Affine3A::IDENTITY,
            0,
            &mut rays,
        );
        self.resolved += u64::from(rays.resolved.count_ones());
        let first = self.pvl_hits.len();
        for c in &self.cands {
            if c.t_reach <= rays.t_limit[c.ray as usize] {
                let met = &mut self.hit_met[c.met as usize];
                self.pvl_hits.push((met.base, c.triangle));
                met.recorded = true;
            }
        }
        // Neighbouring rays record mostly the same triangles.
        self.pvl_hits[first..].sort_unstable();
        let mut kept = first;
        for k in first..self.pvl_hits.len() {
            if kept == first || self.pvl_hits[k] != self.pvl_hits[kept - 1] {
                self.pvl_hits[kept] = self.pvl_hits[k];
                kept += 1;
            }
        }
        self.pvl_hits.truncate(kept);
        for met in self.hit_met.iter().filter(|m| m.recorded) {
            self.instances.entry(met.base).or_insert(InstanceRec {
                node: met.node,
                world_from_object: met.world_from_object,
            });
        }
    }

    /// Casts the `pvl=hits` cones `o + t·dirs[r]` (node space, radius `spread · t` plus a
    /// rounding margin) named by `mask` through node `id`, placed by `world_from_node`, whose
    /// first item is `base`.
    #[allow(clippy::too_many_arguments)]
    fn visit_packet_hits(
        &mut self,
        id: NodeId,
        o: Vec3,
        dirs: &[Vec3; PACKET],
        mask: u64,
        spread: f32,
        world_from_node: &Affine3A,
        base: ItemId,
        rays: &mut HitRays,
    ) {
        let lzb = self.lzb;
        let margin = |b: &Aabb| ABS_EPS * (b.min.abs().max(b.max.abs()).max_element() + o.abs().max_element());
        let mut counters = TraversalCounters::default();
        match &lzb.accel[id.index()] {
            Accel::Empty => {}
            Accel::Mesh {
                octree, bvh: Some(b), ..
            } => {
                let count = 64 - mask.leading_zeros() as usize;
                let margin = margin(&octree.bounds());
                let packet = RayPacket::fat(o, &dirs[..count], spread, margin);
                let clip = self.ctx.view.clip_from_object(world_from_node);
                let w_row = row_w(&clip);
                // Nothing of a mesh that reaches no nearer than the near limit is the near pass's.
                let any_near = self.ctx.is_near(w_row, &octree.bounds());
                let mut sheared = [ShearedRay::new(o, Vec3::X); PACKET];
                let mut made = 0u64;
                let mut met: Option<u32> = None;
                traverse_bvh_packet(
                    &b.bvh,
                    &packet,
                    mask,
                    &mut rays.t_limit,
                    &mut counters,
                    |leaf, m, t_limit| {
                        shear_new_rays(&mut sheared, &mut made, m, o, dirs);
                        let range = RayBvh::leaf_range(leaf);
                        let tris = b.bvh.leaf_triangles(leaf);
                        let ids = &b.bvh.triangles()[range];
                        self.tri_tests += u64::from(m.count_ones()) * tris.len() as u64;
                        let mut rest = m;
                        while rest != 0 {
                            let r = rest.trailing_zeros() as usize;
                            rest &= rest - 1;
                            let c = sheared[r].candidates8(tris, 0xff, spread, margin, 0.0, t_limit[r]);
                            let mut close = c.close;
                            while close != 0 {
                                let i = close.trailing_zeros() as usize;
                                close &= close - 1;
                                // A triangle wholly nearer than the near limit is the near pass's.
                                if any_near && self.ctx.is_wholly_near(w_row, &Aabb::from_points(tris[i].corners)) {
                                    continue;
                                }
                                let m = *met.get_or_insert_with(|| {
                                    self.hit_met.push(HitMet {
                                        base,
                                        node: id,
                                        world_from_object: *world_from_node,
                                        recorded: false,
                                    });
                                    (self.hit_met.len() - 1) as u32
                                });
                                self.cands.push(Cand {
                                    ray: r as u8,
                                    met: m,
                                    triangle: ids[i],
                                    t_reach: c.t_reach[i],
                                });
                            }
                            // The hits nearest first: the first robust one lowers the bound
                            // past every farther one.
                            let mut hits = c.hits;
                            while hits != 0 {
                                let mut i = hits.trailing_zeros() as usize;
                                let mut rest = hits & (hits - 1);
                                while rest != 0 {
                                    let j = rest.trailing_zeros() as usize;
                                    rest &= rest - 1;
                                    if c.t[j] < c.t[i] {
                                        i = j;
                                    }
                                }
                                hits &= !(1 << i);
                                let t = c.t[i];
                                if t * (1.0 + DEPTH_EPS) >= t_limit[r] {
                                    break;
                                }
                                if self.robust(&clip, tris[i].corners, t, rays.centres[r]) {
                                    t_limit[r] = t * (1.0 + DEPTH_EPS);
                                    rays.resolved |= 1 << r;
                                    break;
                                }
                            }
                        }
                    },
                );
            }
            Accel::Mesh { bvh: None, .. } => unreachable!("pvl=hits needs caster=bvh (options)"),
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
                let margin = margin(&octree.bounds());
                let cone = enclosing_cone(o, dirs, mask, spread, margin);
                let mut cone_limit = max_limit(&rays.t_limit, mask);
                let cones = packet_cones(o, dirs, mask, spread, margin);
                traverse(
                    octree,
                    &cone,
                    &mut cone_limit,
                    &mut counters,
                    |leaf, _, _, cone_limit| {
                        for &i in octree.leaf_primitives(leaf) {
                            // Mailbox: an instance spanning several leaves is cast once per packet.
                            if !self.visited.insert((serial, i)) {
                                continue;
                            }
                            let i = i as usize;
                            // The cones that enter the instance's box before their bounds: none
                            // where the cone holding them all does not.
                            if !cone.enter(&bounds[i]).is_some_and(|(e, _)| e <= *cone_limit) {
                                continue;
                            }
                            let sub = rays_entering(&cones, mask, &bounds[i], &rays.t_limit);
                            if sub == 0 {
                                continue;
                            }
                            let cfp = &child_from_parent[i];
                            let child_dirs = child_directions(cfp, dirs, sub);
                            let world_from_child = compose(world_from_node, &instances[i].parent_from_child);
                            self.visit_packet_hits(
                                instances[i].child,
                                cfp.transform_point3(o),
                                &child_dirs,
                                sub,
                                spread * stretch[i],
                                &world_from_child,
                                base + node.item_offset(i),
                                rays,
                            );
                            *cone_limit = max_limit(&rays.t_limit, mask);
                        }
                    },
                );
            }
        }
        self.counters.nodes_visited += counters.nodes_visited;
        self.counters.leaves_visited += counters.leaves_visited;
    }

    /// Casts the rays `o + t·dirs[r]` (node space) named by `mask` through node `id`, whose
    /// first item is `base`.
    fn visit_packet(&mut self, id: NodeId, o: Vec3, dirs: &[Vec3; PACKET], mask: u64, base: ItemId, rays: &mut Rays) {
        let lzb = self.lzb;
        let mut counters = TraversalCounters::default();
        match &lzb.accel[id.index()] {
            Accel::Empty => {}
            Accel::Mesh { bvh: Some(b), .. } => {
                let count = 64 - mask.leading_zeros() as usize;
                let packet = RayPacket::new(o, &dirs[..count]);
                // Each ray's shear for the triangle test, made when it first reaches a leaf.
                let mut sheared = [ShearedRay::new(o, Vec3::X); PACKET];
                let mut made = 0u64;
                traverse_bvh_packet(
                    &b.bvh,
                    &packet,
                    mask,
                    &mut rays.t_limit,
                    &mut counters,
                    |leaf, m, t_limit| {
                        shear_new_rays(&mut sheared, &mut made, m, o, dirs);
                        let range = RayBvh::leaf_range(leaf);
                        let tris = b.bvh.leaf_triangles(leaf);
                        self.tri_tests += u64::from(m.count_ones()) * tris.len() as u64;
                        let best = &mut rays.best;
                        intersect8_packet(tris, o, &sheared, m, 0.0, t_limit, |r, hits, ts| {
                            let mut h = hits;
                            while h != 0 {
                                let i = h.trailing_zeros() as usize;
                                h &= h - 1;
                                let hit = PacketHit {
                                    t: ts[i],
                                    base,
                                    slot: (range.start + i) as u32,
                                    node: id.index() as u32,
                                };
                                if best[r].is_none_or(|b| hit.before(&b)) {
                                    best[r] = Some(hit);
                                }
                            }
                        });
                        let mut rest = m;
                        while rest != 0 {
                            let r = rest.trailing_zeros() as usize;
                            rest &= rest - 1;
                            if let Some(hit) = best[r] {
                                t_limit[r] = t_limit[r].min(hit.t);
                            }
                        }
                    },
                );
            }
            Accel::Mesh { bvh: None, .. } => unreachable!("packets=on needs caster=bvh (options)"),
            Accel::Group {
                octree,
                bounds,
                child_from_parent,
                ..
            } => {
                let node = lzb.scene.node(id);
                let instances = node.instances();
                self.serial += 1;
                let serial = self.serial;
                let cone = enclosing_cone(o, dirs, mask, 0.0, 0.0);
                let mut cone_limit = max_limit(&rays.t_limit, mask);
                let thin = packet_cones(o, dirs, mask, 0.0, 0.0);
                traverse(
                    octree,
                    &cone,
                    &mut cone_limit,
                    &mut counters,
                    |leaf, _, _, cone_limit| {
                        for &i in octree.leaf_primitives(leaf) {
                            // Mailbox: an instance spanning several leaves is cast once per packet.
                            if !self.visited.insert((serial, i)) {
                                continue;
                            }
                            let i = i as usize;
                            // The rays that enter the instance's box before their bounds, each as a
                            // single ray would test it.
                            let sub = rays_entering(&thin, mask, &bounds[i], &rays.t_limit);
                            if sub == 0 {
                                continue;
                            }
                            let cfp = &child_from_parent[i];
                            let child_dirs = child_directions(cfp, dirs, sub);
                            self.visit_packet(
                                instances[i].child,
                                cfp.transform_point3(o),
                                &child_dirs,
                                sub,
                                base + node.item_offset(i),
                                rays,
                            );
                            *cone_limit = max_limit(&rays.t_limit, mask);
                        }
                    },
                );
            }
        }
        self.counters.nodes_visited += counters.nodes_visited;
        self.counters.leaves_visited += counters.leaves_visited;
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
                } else if self.robust(clip_from_object, chunk[i].corners, hit_t, self.pixel) {
                    best = Some(hit_t);
                }
            }
        }
        best
    }

    /// True when the rasterizer surely draws this triangle at pixel centre `pixel`: every
    /// corner well in front of the near plane, the centre inside every projected edge by
    /// [`EDGE_MARGIN_PX`] (vertex snapping moves edges by at most 1/256 pixel), facing right when
    /// back faces are culled, and the hit nearer than the far plane.
    fn robust(&self, clip_from_object: &Mat4, tri: [Vec3; 3], t: f32, pixel: (f32, f32)) -> bool {
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
        let (px, py) = (pixel.0 as f64, pixel.1 as f64);
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
            if lzb.opts.pvl == super::Pvl::Leaves {
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

/// The bounds of the cones of a `pvl=hits` packet (`Caster::cast_packet_hits`), the set of
/// those that met a robust hit, and their pixel centres.
struct HitRays {
    t_limit: [f32; PACKET],
    resolved: u64,
    centres: [(f32, f32); PACKET],
}

/// The bounds and first hits of the rays of a packet (`Caster::cast_packet`).
struct Rays {
    t_limit: [f32; PACKET],
    best: [Option<PacketHit>; PACKET],
}

/// A hit of a packet's ray: its parameter, and where its triangle is (the item is read once
/// the packet is done).
#[derive(Clone, Copy)]
struct PacketHit {
    t: f32,
    /// First item of the mesh instance.
    base: ItemId,
    /// The triangle's slot in its mesh's BVH order.
    slot: u32,
    /// The mesh.
    node: u32,
}

impl PacketHit {
    /// The nearer, and of equal parameters the one of the smaller instance base, then BVH
    /// slot: a total order, so the first hit does not depend on the order of the visits.
    fn before(&self, o: &Self) -> bool {
        (self.t, self.base, self.slot) < (o.t, o.base, o.slot)
    }
}

/// The rays `o + t·dirs[r]` of `mask` as cones of radius `spread · t + margin` (thin with
/// zeros), made once for all the instances of a group a packet meets.
fn packet_cones(o: Vec3, dirs: &[Vec3; PACKET], mask: u64, spread: f32, margin: f32) -> [FatRay; PACKET] {
    let mut cones = [FatRay::new(o, Vec3::X, 0.0, 0.0); PACKET];
    let mut rest = mask;
    while rest != 0 {
        let r = rest.trailing_zeros() as usize;
        rest &= rest - 1;
        cones[r] = FatRay::new(o, dirs[r], spread, margin);
    }
    cones
}

/// The rays of `mask` whose cone enters box `b` no later than their bound.
fn rays_entering(cones: &[FatRay; PACKET], mask: u64, b: &Aabb, t_limit: &[f32; PACKET]) -> u64 {
    let mut sub = 0u64;
    let mut rest = mask;
    while rest != 0 {
        let r = rest.trailing_zeros() as usize;
        rest &= rest - 1;
        let enters = cones[r].enter(b).is_some_and(|(e, _)| e <= t_limit[r]);
        sub |= u64::from(enters) << r;
    }
    sub
}

/// The directions of the rays up to the last of `sub` in a child's space.
fn child_directions(child_from_parent: &Affine3A, dirs: &[Vec3; PACKET], sub: u64) -> [Vec3; PACKET] {
    let mut child_dirs = [Vec3::ZERO; PACKET];
    let count = 64 - sub.leading_zeros() as usize;
    for (c, d) in child_dirs.iter_mut().zip(&dirs[..count]) {
        *c = child_from_parent.transform_vector3(*d);
    }
    child_dirs
}

/// Makes the shear of each ray of `m` not in `made` yet (when it first reaches a leaf).
#[inline]
fn shear_new_rays(sheared: &mut [ShearedRay; PACKET], made: &mut u64, m: u64, o: Vec3, dirs: &[Vec3; PACKET]) {
    let mut new = m & !*made;
    *made |= m;
    while new != 0 {
        let r = new.trailing_zeros() as usize;
        new &= new - 1;
        sheared[r] = ShearedRay::new(o, dirs[r]);
    }
}

/// The largest bound among the rays of `mask`.
fn max_limit(t_limit: &[f32; PACKET], mask: u64) -> f32 {
    let mut m = f32::NEG_INFINITY;
    let mut rest = mask;
    while rest != 0 {
        let r = rest.trailing_zeros() as usize;
        rest &= rest - 1;
        m = m.max(t_limit[r]);
    }
    m
}

/// A cone from `o` holding the rays `o + t·dirs[r]` of `mask` at every `t` (as its own
/// parameter): around their mean direction `c`, with the radius per unit of `t`
/// `max |d_r − c|`, scaled by `|c| / min |d_r|` because [`FatRay::enter`] measures a box's far
/// side along `c` while a ray reaches a point at `t` along its own, longer or shorter,
/// direction; then widened by a thousandth against rounding. Every box a ray enters at `t_e`
/// is entered by the cone no later than `t_e`. With cones around the rays (radius
/// `ray_spread · t + ray_margin`): their directions reach `ray_spread` farther from `c` and
/// may be that much shorter, and the margin adds to the cone's.
fn enclosing_cone(o: Vec3, dirs: &[Vec3; PACKET], mask: u64, ray_spread: f32, ray_margin: f32) -> FatRay {
    let (mut sum, mut n) = (Vec3::ZERO, 0.0f32);
    let mut rest = mask;
    while rest != 0 {
        let r = rest.trailing_zeros() as usize;
        rest &= rest - 1;
        sum += dirs[r];
        n += 1.0;
    }
    let c = sum / n;
    let (mut spread, mut shortest) = (0.0f32, f32::INFINITY);
    let mut rest = mask;
    while rest != 0 {
        let r = rest.trailing_zeros() as usize;
        rest &= rest - 1;
        spread = spread.max((dirs[r] - c).length());
        shortest = shortest.min(dirs[r].length());
    }
    // Cones so wide that a direction could shrink to nothing (an instance stretched some 10⁴
    // to 1): a cone that holds everything.
    let spread = if shortest > ray_spread {
        (spread + ray_spread) * (c.length() / (shortest - ray_spread)).max(1.0) * 1.001 + c.length() * 1e-6
    } else {
        f32::INFINITY
    };
    FatRay::new(o, c, spread, ABS_EPS * (o.abs().max_element() + 1.0) + ray_margin)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    /// Every box a ray of the packet enters at `t_e` (before its bound) is entered by the
    /// enclosing cone no later than `t_e`: the group traversal of a packet misses no instance a
    /// single ray would meet. Tiles of pixel directions (their forward component 1, as
    /// `pixel_direction` makes them), then stretched and sheared as instance placements do.
    #[test]
    fn enclosing_cone_enters_every_box_a_ray_enters() {
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(7);
        let mut checked = 0;
        for k in 0..400 {
            let o = Vec3::new(
                rng.random_range(-50.0..50.0),
                rng.random_range(-5.0..5.0),
                rng.random_range(-50.0..50.0),
            );
            let (w, h) = (rng.random_range(0.2..2.0f32), rng.random_range(0.2..2.0f32));
            let (cx, cy) = (rng.random_range(-1.0..1.0f32), rng.random_range(-1.0..1.0f32));
            let pixel = rng.random_range(0.001..0.05f32);
            let mut dirs = [Vec3::ZERO; PACKET];
            for (r, d) in dirs.iter_mut().enumerate() {
                let (i, j) = ((r % 8) as f32, (r / 8) as f32);
                *d = Vec3::new((cx + i * pixel) * w, (cy + j * pixel) * h, 1.0);
            }
            if k % 2 == 1 {
                // An instance's placement: a stretch and a shear.
                let m = occult_core::Mat3::from_cols(
                    Vec3::new(rng.random_range(0.2..3.0), 0.3, 0.0),
                    Vec3::new(0.0, rng.random_range(0.2..3.0), -0.4),
                    Vec3::new(0.5, 0.0, rng.random_range(0.2..3.0)),
                );
                dirs = dirs.map(|d| m * d);
            }
            let mask = u64::MAX >> rng.random_range(0..40);
            // A third of the packets are of cones (`pvl=hits`): their spread and margin widen
            // the enclosing cone.
            let (ray_spread, ray_margin) = if k % 3 == 2 {
                (pixel * rng.random_range(0.01..0.5), rng.random_range(0.0..0.05))
            } else {
                (0.0, 0.0)
            };
            let cone = enclosing_cone(o, &dirs, mask, ray_spread, ray_margin);
            for _ in 0..50 {
                // Near a ray of the packet, often at its edge: some rays enter, some miss.
                let r = rng.random_range(0..PACKET - mask.leading_zeros() as usize);
                let e = Vec3::new(
                    rng.random_range(0.01..3.0),
                    rng.random_range(0.01..3.0),
                    rng.random_range(0.01..3.0),
                );
                let jitter = Vec3::new(
                    rng.random_range(-1.2..1.2),
                    rng.random_range(-1.2..1.2),
                    rng.random_range(-1.2..1.2),
                );
                let c = o + dirs[r] * rng.random_range(0.5..100.0f32) + jitter * e;
                let b = Aabb::new(c - e, c + e);
                let first = (0..PACKET)
                    .filter(|r| mask & (1 << r) != 0)
                    .filter_map(|r| {
                        FatRay::new(o, dirs[r], ray_spread, ray_margin)
                            .enter(&b)
                            .map(|(t, _)| t)
                    })
                    .fold(f32::INFINITY, f32::min);
                if first.is_finite() {
                    checked += 1;
                    let entry = cone.enter(&b).map(|(t, _)| t);
                    assert!(
                        entry.is_some_and(|t| t <= first),
                        "packet {k}: a ray enters at {first}, the cone at {entry:?}"
                    );
                }
            }
        }
        assert!(checked > 10_000, "{checked}");
    }
}
