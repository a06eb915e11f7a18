//! One frame's walk of the grids ([module doc](super)): last frame's visible cells first, then
//! each node occurrence's grid in front-to-back slabs, batches of queries, and draws of the
//! visible cells.

use std::collections::{HashMap, HashSet};
use std::time::{Duration, Instant};

use occult_core::{Containment, Mat4, Mesh, NodeKind, Scene, Vec3, View};
use occult_raster::{Draw, DrawTriangles, Frame, PixelRect, Rasterizer, ZPyramid};
use occult_spatial::grid::{GridCell, NestedGrid, NO_CHILD};

use super::query::{self, query_cell, QueryOutcome};
use super::{
    cell_key, screen_area_estimate, CellTest, OqGridCounts, OqGridOptions, Order, VisibleCells, INFO,
    MAX_REMEMBERED_SHARES, MAX_VISIBLE_CELLS, PARALLEL_QUERY_MIN_PIXELS, WHOLE, WHOLE_PROBE_PERIOD,
};
use crate::hash::FxBuild;
use crate::list_choice::ListChoice;
use crate::payoff::{FramePayoff, Payoff, DIRECT_BATCH};
use crate::walk::{NodeAt, NodeTest, Placed, SceneWalk, Visitor};
use crate::{FrameStats, Phase, Result};

/// A node occurrence being traversed.
struct Occurrence<'a> {
    at: NodeAt<'a>,
    clip_from_object: Mat4,
    /// The camera in the node's space, for slab keys and the order of a cell's instances.
    eye: Vec3,
    dir: Vec3,
    epoch: u32,
    grid: &'a NestedGrid,
}

/// Visible triangles of one mesh occurrence gathered for the next draw.
struct Pending<'a> {
    mesh: &'a Mesh,
    /// Its triangle indices: `Walk::gathered[start..end]`; None: all of them.
    gathered: Option<(usize, usize)>,
    clip_from_object: Mat4,
    first_item: u64,
}

/// Per-frame traversal state.
struct Walk<'a> {
    walk: SceneWalk<'a>,
    grids: &'a [NestedGrid],
    stamps: &'a mut [Vec<u32>],
    epoch: &'a mut u32,
    shares: &'a mut HashMap<u64, (f32, u32), FxBuild>,
    /// Triangles gathered for drawing so far in the frame.
    gathered_count: u64,
    raster: &'a mut Rasterizer,
    options: &'a OqGridOptions,
    frame: &'a mut Frame,
    counts: OqGridCounts,
    query_time: Duration,
    raster_time: Duration,
    /// Time spent bringing the pyramid up to date.
    pyramid_time: Duration,
    /// The pyramid of `frame` ([`CellTest::Pyramid`]), up to date but for the `dirty` rectangles.
    pyramid: Option<&'a mut ZPyramid>,
    /// Triangle indices of the pending draws.
    gathered: Vec<u32>,
    pending: Vec<Pending<'a>>,
    /// Triangles of the pending draws.
    pending_triangles: usize,
    /// Where the pending draws may change the depth.
    dirty: Vec<PixelRect>,
    /// Whether the queries still pay this frame.
    payoff: FramePayoff,
    /// Records this frame's visible cells, when coherence is on.
    record: Option<&'a mut VisibleCells>,
    /// The cells drawn first this frame (keys as in [`Temporal::predrawn`]).
    predrawn: HashSet<(u64, u64), FxBuild>,
    /// Most cells the frame's list records and most shares remembered: the renderer's bounds
    /// shared over its strips of columns ([`Grids::strips`]).
    max_cells: usize,
    max_shares: usize,
}

impl<'a> Visitor<'a> for Walk<'a> {
    /// The node's box is tested but not counted: this renderer's box tests are its queries.
    const NODE_TEST: NodeTest = NodeTest::Uncounted;

    fn walk(&mut self) -> &mut SceneWalk<'a> {
        &mut self.walk
    }

    /// Traverses the occurrence's grid from its top level.
    fn visit(&mut self, at: &NodeAt<'a>) {
        self.counts.node_occurrences += 1;
        self.next_epoch();
        let view = self.walk.view();
        let clip_from_object = view.clip_from_object(&at.place.world_from_node);
        if self.options.queries && self.options.node_queries && !self.node_visible(at, &clip_from_object) {
            return;
        }
        if let NodeKind::Mesh(_) = at.node.kind() {
            if self.predrawn.contains(&(at.place.first_item, WHOLE)) {
                // Drawn whole first, from last frame's list: visible still (its box passed).
                if let Some((_, since)) = self.shares.get_mut(&at.place.first_item) {
                    *since += 1;
                }
                self.counts.whole_drawn += 1;
                self.remember(at.place, &[WHOLE]);
                return;
            }
        }
        if let (NodeKind::Mesh(mesh), true) = (at.node.kind(), self.payoff.stopped() && at.inside) {
            // Queries stopped paying: a mesh occurrence wholly in view is drawn whole.
            self.push_whole(mesh, at, clip_from_object);
            self.remember(at.place, &[WHOLE]);
            return;
        }
        let whole = self.options.whole_percent;
        if let (NodeKind::Mesh(mesh), true) = (at.node.kind(), whole > 0) {
            if let Some((share, since)) = self.shares.get_mut(&at.place.first_item) {
                if *share * 100.0 >= whole as f32 && *since + 1 < WHOLE_PROBE_PERIOD {
                    *since += 1;
                    self.counts.whole_drawn += 1;
                    self.push_whole(mesh, at, clip_from_object);
                    self.remember(at.place, &[WHOLE]);
                    return;
                }
            }
        }
        let gathered_before = self.gathered_count;
        // A mesh's cells are recorded by `batch` while its grid is traversed (a group's
        // instances record their own).
        let recorded_before = match at.node.kind() {
            NodeKind::Mesh(_) => self.record.as_ref().map(|r| r.cells.len()),
            NodeKind::Group(_) => None,
        };
        let node_from_world = at.place.world_from_node.inverse();
        let camera = view.camera();
        let occ = Occurrence {
            at: *at,
            clip_from_object,
            eye: node_from_world.transform_point3(camera.eye),
            dir: node_from_world.transform_vector3(camera.direction()),
            epoch: *self.epoch,
            grid: &self.grids[at.place.id.index()],
        };
        self.level(&occ, 0);
        if let (Some(record), Some(start)) = (self.record.as_deref_mut(), recorded_before) {
            if record.cells.len() > start {
                record.occurrences.push((at.place, start, record.cells.len()));
            }
        }
        if let (NodeKind::Mesh(mesh), true) = (at.node.kind(), whole > 0) {
            let drawn = (self.gathered_count - gathered_before) as f32;
            if self.shares.len() >= self.max_shares {
                self.shares.clear(); // bounded memory on scenes of countless occurrences
            }
            self.shares
                .insert(at.place.first_item, (drawn / mesh.triangle_count().max(1) as f32, 0));
        }
    }
}

impl<'a> Walk<'a> {
    /// Traverses level `level_index` of the occurrence's grid: §3.3 slabs, §3.4 batches.
    fn level(&mut self, occ: &Occurrence<'a>, level_index: u32) {
        let level = &occ.grid.levels()[level_index as usize];
        let thickness = occ.dir.abs().dot(level.cell_size);
        let thickness = if thickness.is_finite() && thickness > 0.0 {
            thickness
        } else {
            1.0
        };
        let mut order: Vec<(i64, u32)> = Vec::with_capacity(level.cells.len());
        for (i, cell) in level.cells.iter().enumerate() {
            self.counts.cells_visited += 1;
            if occ.at.frustum.classify_aabb(&cell.tight) == Containment::Outside {
                continue;
            }
            let key = match self.options.order {
                // §3.3: the slab of the cell's centre along the view direction.
                Order::Slabs => ((cell.tight.center() - occ.eye).dot(occ.dir) / thickness).floor() as i64,
                Order::Unordered => 0,
            };
            order.push((key, i as u32));
        }
        self.counts.cells_in_frustum += order.len() as u64;
        if self.options.order == Order::Slabs {
            order.sort_unstable();
        }
        let mut start = 0;
        while start < order.len() {
            let slab = order[start].0;
            let end = start + order[start..].iter().take_while(|(k, _)| *k == slab).count();
            // §3.4: the slab's cells n at a time; each batch drawn before the next is queried,
            // and the whole slab before the next slab.
            for batch in order[start..end].chunks(self.options.batch) {
                self.batch(occ, level_index, batch);
            }
            start = end;
        }
    }

    /// Queries the cells of one batch against the same depth state, then draws the visible
    /// ones (§3.4) and recurses into the visible ones' subgrids (§3.2) and instances.
    fn batch(&mut self, occ: &Occurrence<'a>, level_index: u32, batch: &[(i64, u32)]) {
        if self.raster.config().control.is_cancelled() {
            return; // the frame is not drawn at all
        }
        let cells: &'a [GridCell] = &occ.grid.levels()[level_index as usize].cells;
        let options = self.options;
        let wants_query = |c: &GridCell| options.queries && c.weight >= options.query_threshold;
        // One balance check for the batch: its queries run together.
        let wanted = batch.iter().filter(|(_, i)| wants_query(&cells[*i as usize])).count() as u64;
        let testing = wanted == 0 || self.payoff.test();
        if !testing {
            self.payoff.skipped(wanted.saturating_sub(1));
        }
        let needs_query = |c: &GridCell| testing && wants_query(c);
        let view = self.walk.view();
        let t = Instant::now();
        let pyramid = self.pyramid.as_deref();
        let query = |c: &GridCell| -> QueryOutcome {
            if needs_query(c) {
                query_cell(self.frame, view, &occ.clip_from_object, &c.tight, pyramid)
            } else {
                QueryOutcome::Visible
            }
        };
        let queried = batch.iter().filter(|(_, i)| needs_query(&cells[*i as usize])).count() as u64;
        // Deviation (§3.4): a batch's queries run in parallel only when their screen area makes
        // it pay; small queries cost less than handing them to other threads.
        let parallel = queried > 1 && self.raster.thread_count() > 1 && {
            let (w, h) = (view.width() as f32, view.height() as f32);
            let area: f32 = batch
                .iter()
                .filter(|(_, i)| needs_query(&cells[*i as usize]))
                .map(|(_, i)| screen_area_estimate(&occ.clip_from_object, &cells[*i as usize].tight, w, h))
                .sum();
            area >= PARALLEL_QUERY_MIN_PIXELS
        };
        let outcomes: Vec<QueryOutcome> = if parallel {
            use rayon::prelude::*;
            self.counts.parallel_batches += 1;
            self.raster
                .install(|| batch.par_iter().map(|(_, i)| query(&cells[*i as usize])).collect())
        } else {
            batch.iter().map(|(_, i)| query(&cells[*i as usize])).collect()
        };
        if queried > 0 {
            self.query_time += t.elapsed();
        }
        self.counts.pyramid_hidden += outcomes.iter().filter(|&&o| o == QueryOutcome::HiddenByPyramid).count() as u64;
        let visible: Vec<bool> = outcomes.iter().map(|&o| o == QueryOutcome::Visible).collect();
        let visible_count = visible.iter().filter(|&&v| v).count() as u64;
        let hidden = batch
            .iter()
            .zip(&visible)
            .filter(|((_, i), v)| !**v && needs_query(&cells[*i as usize]))
            .count() as u64;
        self.counts.queries += queried;
        self.counts.queries_hidden += hidden;
        let saved: u64 = batch
            .iter()
            .zip(&visible)
            .filter(|(_, v)| !**v)
            .map(|((_, i), _)| cells[*i as usize].weight)
            .sum();
        self.payoff.saved(saved);
        self.counts.queries_skipped += batch.len() as u64 - queried;
        self.counts.cells_visible += visible_count;
        if visible_count == 0 {
            return;
        }
        let elements = occ.grid.elements();
        match occ.at.node.kind() {
            NodeKind::Mesh(mesh) => {
                // The visible leaf cells' triangles, each once per occurrence (§3.1 stamps).
                let start = self.gathered.len();
                let (w, h) = (view.width(), view.height());
                for (&(_, i), _) in batch.iter().zip(&visible).filter(|(_, v)| **v) {
                    let cell = &cells[i as usize];
                    if cell.child != NO_CHILD {
                        continue;
                    }
                    let key = cell_key(level_index, i);
                    if let Some(record) = self.record.as_deref_mut() {
                        if record.cells.len() < self.max_cells {
                            record.cells.push(key);
                        }
                    }
                    if !self.predrawn.is_empty() && self.predrawn.contains(&(occ.at.place.first_item, key)) {
                        continue; // drawn first, from last frame's list
                    }
                    let tris = &elements[cell.range()];
                    if options.stamps {
                        let stamps = &mut self.stamps[occ.at.place.id.index()];
                        for &t in tris {
                            if stamps[t as usize] != occ.epoch {
                                stamps[t as usize] = occ.epoch;
                                self.gathered.push(t);
                            }
                        }
                    } else {
                        self.gathered.extend_from_slice(tris);
                    }
                    // The pyramid is brought up to date over the cell's own box only: the parts of
                    // its triangles outside it are left to the cells they cross (a pyramid that
                    // misses pixels drawn is stale there, which is conservative).
                    if self.pyramid.is_some() {
                        if let Some(r) = query::screen_rect(&occ.clip_from_object, &cell.tight, w, h) {
                            self.dirty.push(r);
                        }
                    }
                }
                if self.gathered.len() > start {
                    self.pending_triangles += self.gathered.len() - start;
                    self.gathered_count += (self.gathered.len() - start) as u64;
                    self.pending.push(Pending {
                        mesh,
                        gathered: Some((start, self.gathered.len())),
                        clip_from_object: occ.clip_from_object,
                        first_item: occ.at.place.first_item,
                    });
                    if self.pending_triangles >= self.flush_at() {
                        self.flush();
                    }
                }
                for (&(_, i), _) in batch.iter().zip(&visible).filter(|(_, v)| **v) {
                    let child = cells[i as usize].child;
                    if child != NO_CHILD {
                        self.level(occ, child);
                    }
                }
            }
            NodeKind::Group(instances) => {
                let scene = self.walk.scene();
                // A cell's instances nearest first: a cell holds the near and the far of a
                // street, and an instance drawn before its occluders is drawn whole.
                let mut near_first: Vec<(f32, u32)> = Vec::new();
                for (&(_, i), _) in batch.iter().zip(&visible).filter(|(_, v)| **v) {
                    let cell = &cells[i as usize];
                    if cell.child != NO_CHILD {
                        self.level(occ, cell.child);
                        continue;
                    }
                    near_first.clear();
                    for &e in &elements[cell.range()] {
                        if options.stamps {
                            let s = &mut self.stamps[occ.at.place.id.index()][e as usize];
                            if *s == occ.epoch {
                                continue;
                            }
                            *s = occ.epoch;
                        }
                        let instance = &instances[e as usize];
                        let b = scene
                            .node(instance.child)
                            .bounds()
                            .transformed(&instance.parent_from_child);
                        near_first.push((occ.eye.clamp(b.min, b.max).distance_squared(occ.eye), e));
                    }
                    near_first.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
                    for &(_, e) in &near_first {
                        self.enter(occ.at.child(e as usize), false);
                    }
                }
            }
        }
    }
}

impl<'a> Walk<'a> {
    /// A fresh stamp epoch for the next occurrence.
    fn next_epoch(&mut self) {
        *self.epoch = self.epoch.wrapping_add(1);
        if *self.epoch == 0 {
            // After 2^32 occurrences: forget every stamp once, so old epochs cannot match.
            self.stamps.iter_mut().for_each(|s| s.fill(0));
            *self.epoch = 1;
        }
    }

    /// Records cells `keys` of mesh occurrence `place` in this frame's visible list.
    fn remember(&mut self, place: Placed, keys: &[u64]) {
        if let Some(record) = self.record.as_deref_mut() {
            if record.cells.len() + keys.len() <= self.max_cells {
                let start = record.cells.len();
                record.cells.extend_from_slice(keys);
                record.occurrences.push((place, start, record.cells.len()));
            }
        }
    }

    /// Draws last frame's visible list first, unqueried (frame-to-frame coherence): each
    /// remembered mesh occurrence in view, whole or its remembered cells in view, as one draw
    /// (shared over the rasterizer's threads when large), then the pyramid brought up to date
    /// over them. Their keys go to `predrawn`, so the traversal does not draw them again.
    fn predraw(&mut self, last: &VisibleCells) {
        let view = self.walk.view();
        let scene = self.walk.scene();
        let (w, h) = (view.width(), view.height());
        for &(place, start, end) in &last.occurrences {
            let node = scene.node(place.id);
            let NodeKind::Mesh(mesh) = node.kind() else {
                continue;
            };
            let frustum = view.frustum(&place.world_from_node);
            let bounds = node.bounds();
            if bounds.is_empty() || frustum.classify_aabb(&bounds) == Containment::Outside {
                continue;
            }
            let clip_from_object = view.clip_from_object(&place.world_from_node);
            let keys = &last.cells[start..end];
            // Drawn whole when the traversal would draw it whole (`visit`'s rule); not drawn
            // first when its grid is due to be traversed again, to measure its share.
            let whole_percent = self.options.whole_percent as f32;
            let share = self.shares.get(&place.first_item);
            let probe_due = share.is_some_and(|&(_, since)| since + 1 >= WHOLE_PROBE_PERIOD);
            let whole = if keys == [WHOLE] {
                if probe_due {
                    continue;
                }
                true
            } else {
                whole_percent > 0.0 && !probe_due && share.is_some_and(|&(s, _)| s * 100.0 >= whole_percent)
            };
            if whole {
                self.predrawn.insert((place.first_item, WHOLE));
                self.counts.coherent_cells += 1;
                self.counts.coherent_triangles += mesh.triangle_count() as u64;
                self.pend_whole(mesh, &bounds, place.first_item, clip_from_object);
                continue;
            }
            self.next_epoch();
            let epoch = *self.epoch;
            let grid = &self.grids[place.id.index()];
            let elements = grid.elements();
            let first = self.gathered.len();
            for &key in keys {
                let (level, index) = ((key >> 32) as usize, key as u32 as usize);
                let Some(cell) = grid.levels().get(level).and_then(|l| l.cells.get(index)) else {
                    continue;
                };
                if frustum.classify_aabb(&cell.tight) == Containment::Outside {
                    continue;
                }
                self.predrawn.insert((place.first_item, key));
                self.counts.coherent_cells += 1;
                let tris = &elements[cell.range()];
                if self.options.stamps {
                    let stamps = &mut self.stamps[place.id.index()];
                    for &t in tris {
                        if stamps[t as usize] != epoch {
                            stamps[t as usize] = epoch;
                            self.gathered.push(t);
                        }
                    }
                } else {
                    self.gathered.extend_from_slice(tris);
                }
                if self.pyramid.is_some() {
                    if let Some(r) = query::screen_rect(&clip_from_object, &cell.tight, w, h) {
                        self.dirty.push(r);
                    }
                }
            }
            if self.gathered.len() > first {
                let n = self.gathered.len() - first;
                self.counts.coherent_triangles += n as u64;
                self.pending_triangles += n;
                self.pending.push(Pending {
                    mesh,
                    gathered: Some((first, self.gathered.len())),
                    clip_from_object,
                    first_item: place.first_item,
                });
            }
        }
        self.flush();
    }

    /// Queries the box of occurrence `at` before its grid is traversed; false when hidden.
    fn node_visible(&mut self, at: &NodeAt<'a>, clip_from_object: &Mat4) -> bool {
        if !self.payoff.test() {
            return true;
        }
        let t = Instant::now();
        let outcome = query_cell(
            self.frame,
            self.walk.view(),
            clip_from_object,
            &at.node.bounds(),
            self.pyramid.as_deref(),
        );
        self.query_time += t.elapsed();
        self.counts.node_queries += 1;
        if outcome == QueryOutcome::Visible {
            return true;
        }
        self.counts.nodes_hidden += 1;
        self.counts.pyramid_hidden += (outcome == QueryOutcome::HiddenByPyramid) as u64;
        self.payoff.saved(at.node.item_count());
        false
    }

    /// Adds every triangle of mesh occurrence `at` to the pending draws, drawn once enough
    /// are pending.
    fn push_whole(&mut self, mesh: &'a Mesh, at: &NodeAt<'a>, clip_from_object: Mat4) {
        self.pend_whole(mesh, &at.node.bounds(), at.place.first_item, clip_from_object);
        if self.pending_triangles >= self.flush_at() {
            self.flush();
        }
    }

    /// Adds every triangle of the mesh occurrence with box `bounds` and first item `first_item`
    /// to the pending draws (and its screen rectangle to the pyramid's dirty ones).
    fn pend_whole(&mut self, mesh: &'a Mesh, bounds: &occult_core::Aabb, first_item: u64, clip_from_object: Mat4) {
        if self.pyramid.is_some() {
            let (w, h) = (self.frame.width(), self.frame.height());
            if let Some(r) = query::screen_rect(&clip_from_object, bounds, w, h) {
                self.dirty.push(r);
            }
        }
        self.pending_triangles += mesh.triangle_count();
        self.pending.push(Pending {
            mesh,
            gathered: None,
            clip_from_object,
            first_item,
        });
    }

    /// Triangles gathered before a draw: the option's, or large threaded batches once the
    /// frame stopped querying.
    fn flush_at(&self) -> usize {
        if self.payoff.stopped() {
            DIRECT_BATCH.max(self.options.flush_triangles)
        } else {
            self.options.flush_triangles
        }
    }

    /// Draws the pending triangles as one draw list, then brings the pyramid up to date where
    /// they may have changed the depth.
    fn flush(&mut self) {
        if self.pending.is_empty() {
            return;
        }
        let view = self.walk.view();
        let draws: Vec<Draw<'_>> = self
            .pending
            .iter()
            .map(|p| Draw {
                mesh: p.mesh,
                triangles: match p.gathered {
                    Some((start, end)) => DrawTriangles::List(&self.gathered[start..end]),
                    None => DrawTriangles::All,
                },
                clip_from_object: p.clip_from_object,
                first_item: p.first_item,
            })
            .collect();
        let t = Instant::now();
        crate::rasterize(self.raster, view, self.frame, &draws, &mut self.walk.stats);
        drop(draws);
        self.counts.draws += 1;
        let spent = t.elapsed();
        self.raster_time += spent;
        let shared = self.pending_triangles >= DIRECT_BATCH;
        self.payoff.rasterized(self.pending_triangles as u64, spent, shared);
        // Only where the batch wrote: its rectangles cut to the box of the triangles that wrote
        // a fragment (none left when it was wholly hidden).
        match crate::written_region(self.raster, view) {
            Some(w) => {
                self.dirty.retain_mut(|r| match r.intersect(&w) {
                    Some(cut) => {
                        *r = cut;
                        true
                    }
                    None => false,
                });
            }
            None => self.dirty.clear(),
        }
        // Once the frame stopped querying, nothing reads the pyramid.
        let stopped = self.payoff.stopped();
        if let Some(pyramid) = self
            .pyramid
            .as_deref_mut()
            .filter(|_| !self.dirty.is_empty() && !stopped)
        {
            let t = Instant::now();
            // Rectangles overlap: where their bounding rectangle is no larger than their areas
            // together, one pass over it is less work.
            let area: u64 = self.dirty.iter().map(|r| r.area()).sum();
            let union = self.dirty.iter().fold(self.dirty[0], |u, r| PixelRect {
                x0: u.x0.min(r.x0),
                y0: u.y0.min(r.y0),
                x1: u.x1.max(r.x1),
                y1: u.y1.max(r.y1),
            });
            if union.area() <= area {
                pyramid.update(self.frame, union);
            } else {
                for &r in &self.dirty {
                    pyramid.update(self.frame, r);
                }
            }
            self.pyramid_time += t.elapsed();
        }
        self.pending.clear();
        self.pending_triangles = 0;
        self.gathered.clear();
        self.dirty.clear();
    }
}

/// What one walker of the grids keeps from frame to frame: the pyramid of the frame it draws
/// and the per-node stamps with their epoch. One for the whole frame, or one per worker of the
/// columns distribution.
pub(super) struct Depth {
    /// Max-depth pyramid of the frame being drawn ([`CellTest::Pyramid`]).
    pub(super) pyramid: ZPyramid,
    /// Per node: the epoch at which each element (triangle or instance) was last drawn.
    pub(super) stamps: Vec<Vec<u32>>,
    pub(super) epoch: u32,
}

impl Depth {
    pub(super) fn memory_bytes(&self) -> usize {
        self.stamps.iter().map(|s| s.len() * 4).sum::<usize>() + self.pyramid.memory_bytes()
    }
}

/// What the frames of one view (the whole screen, or a strip of columns) keep from frame to
/// frame besides the payoff.
#[derive(Default)]
pub(super) struct Temporal {
    /// Per mesh occurrence (by its first item id, unique to it): the share of its triangles the
    /// last traversal of its grid drew, and the frames it was drawn whole since.
    pub(super) shares: HashMap<u64, (f32, u32), FxBuild>,
    /// The last queried frame's visible cells, drawn first by the next ([`OqGridOptions::coherence`]);
    /// dropped when a frame is drawn directly.
    pub(super) visible: VisibleCells,
    /// The list being recorded by the frame in progress.
    pub(super) next_visible: VisibleCells,
    /// The cells the frame in progress drew first: (first item of the occurrence, cell key).
    pub(super) predrawn: HashSet<(u64, u64), FxBuild>,
    /// Frame times with the list drawn first and without it ([`OqGridOptions::weigh`]).
    pub(super) choice: ListChoice,
    /// Whether the last queried frame drew the list first: a list recorded by a frame that
    /// did not holds cells found visible against a depth without it, hidden by that frame's
    /// end, and drawing it is not what the list costs (not recorded, as `hzb` and `clusters`
    /// do).
    pub(super) drew_list: bool,
}

impl Temporal {
    pub(super) fn memory_bytes(&self) -> usize {
        self.shares.capacity() * std::mem::size_of::<(u64, (f32, u32))>()
            + self.visible.memory_bytes()
            + self.next_visible.memory_bytes()
            + self.predrawn.capacity() * 16
    }
}

/// The grids of a scene and how to walk them.
#[derive(Clone, Copy)]
pub(super) struct Grids<'a> {
    pub(super) scene: &'a Scene,
    pub(super) grids: &'a [NestedGrid],
    pub(super) options: &'a OqGridOptions,
    /// The strips of columns a frame is drawn as (1: one walk): the visible lists and shares
    /// are bounded per strip by the renderer's bounds over this.
    pub(super) strips: usize,
}

impl Grids<'_> {
    /// Clears `view`'s pixels of `frame` and draws `view` into it, querying the grids against
    /// the depth drawn so far: last frame's visible cells first (`coherence`), then the grids
    /// front to back. Returns the statistics (the phases accounted for: clear, query, depth
    /// structure, raster, and the rest as culling) with the counters, and the counts.
    ///
    /// # Errors
    /// Cancellation (the frame's list and costs are then dropped); a pyramid refused.
    pub(super) fn walk_frame(
        &self,
        view: &View,
        raster: &mut Rasterizer,
        frame: &mut Frame,
        depth: &mut Depth,
        temporal: &mut Temporal,
        payoff: &mut Payoff,
    ) -> Result<(FrameStats, OqGridCounts)> {
        let options = self.options;
        let (_, t, cleared) = crate::begin_frame(raster, view, frame)?;
        let control = raster.config().control.clone();
        let pyramid = match options.test {
            CellTest::Query => None,
            CellTest::Pyramid => {
                if (depth.pyramid.width(), depth.pyramid.height()) != (frame.width(), frame.height()) {
                    depth.pyramid = ZPyramid::new(frame.width(), frame.height())?;
                }
                depth.pyramid.clear_for(frame);
                Some(&mut depth.pyramid)
            }
        };
        let mut walk = Walk {
            walk: SceneWalk::new(self.scene, view),
            grids: self.grids,
            stamps: &mut depth.stamps,
            epoch: &mut depth.epoch,
            shares: &mut temporal.shares,
            gathered_count: 0,
            raster,
            options,
            frame,
            counts: OqGridCounts::default(),
            query_time: Duration::ZERO,
            raster_time: Duration::ZERO,
            pyramid_time: Duration::ZERO,
            pyramid,
            gathered: Vec::new(),
            pending: Vec::new(),
            pending_triangles: 0,
            dirty: Vec::new(),
            payoff: payoff.begin(t),
            record: None,
            predrawn: std::mem::take(&mut temporal.predrawn),
            max_cells: MAX_VISIBLE_CELLS / self.strips.max(1),
            max_shares: MAX_REMEMBERED_SHARES / self.strips.max(1),
        };
        walk.walk.stats = cleared;
        walk.predrawn.clear();
        let coherent = options.coherence && options.queries;
        if coherent {
            // Last frame's visible list first (its keys in `predrawn`) unless the frame times
            // say it costs more than it saves, then the traversal, which records this frame's
            // list (what its queries found visible, drawn first or not: a list whatever this
            // frame drew first).
            if !(options.weigh && temporal.choice.skip()) {
                walk.predraw(&temporal.visible);
            }
            temporal.next_visible.clear();
            walk.record = Some(&mut temporal.next_visible);
        }
        walk.run();
        walk.flush();
        let walked = t.elapsed();
        let Walk {
            walk,
            counts,
            query_time,
            raster_time,
            pyramid_time,
            payoff: frame_payoff,
            predrawn,
            record,
            ..
        } = walk;
        temporal.predrawn = predrawn;
        let recorded = record.is_some();
        // A cancelled frame's list is incomplete, and its costs are no measure: both dropped.
        if control.is_cancelled() {
            return Err(crate::RenderError::Cancelled);
        }
        payoff.end(&frame_payoff);
        if coherent && options.weigh {
            // A frame that stopped querying is recorded too: its time is what its way cost. A
            // frame that drew a list made by a frame without one is not (`drew_list`): a probe
            // of the list then lasts two frames.
            let drew = counts.coherent_cells > 0;
            if !drew || temporal.drew_list {
                temporal.choice.record(drew, walked);
            }
            temporal.drew_list = drew;
        }
        let mut stats = walk.finish("oqgrid")?;
        if recorded {
            // This frame's list replaces the last (one that stopped querying, given up or not,
            // lists what it drew untested).
            std::mem::swap(&mut temporal.visible, &mut temporal.next_visible);
        }
        stats.phases.add(Phase::Query, query_time);
        stats.phases.add(Phase::DepthStructure, pyramid_time);
        stats.phases.add(
            Phase::Cull,
            walked.saturating_sub(query_time + raster_time + pyramid_time),
        );
        stats.boxes_tested += counts.queries + counts.node_queries;
        stats.boxes_culled += counts.queries_hidden + counts.nodes_hidden;
        for (&name, n) in INFO.counters.iter().zip(counts.values()) {
            stats.counters.add(name, n);
        }
        stats.counters.add_all(frame_payoff.counters());
        Ok((stats, counts))
    }
}
