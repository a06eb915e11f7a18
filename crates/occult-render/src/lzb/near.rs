//! Step 3 of a frame (§II): the near set drawn with the z-buffer, whole (the paper) or
//! occlusion-culled front to back (`near_cull=on`).

use std::time::Instant;

use occult_core::{ItemId, Mat4, View, NO_ITEM};
use occult_raster::{Draw, DrawTriangles, Frame};

use super::*;

impl Lzb {
    /// Step 3 (§II): the near leaves `near` (`(instance, leaf)` pairs of `instances`) drawn
    /// with the z-buffer, in one draw, their triangles counted in `counter` (the far leaves
    /// of a frame given up are drawn so too).
    pub(super) fn draw_leaves(
        &mut self,
        view: &View,
        frame: &mut Frame,
        instances: &[(InstanceRec, ItemId, Mat4)],
        near: &[(u32, u32)],
        stats: &mut FrameStats,
        counter: &'static str,
    ) {
        let t = Instant::now();
        // A mesh instance all of whose leaves are near is drawn whole (its vertices shared, no
        // list to build); the others by their near leaves' clusters ([`super::owned`]).
        let (mut near_groups, mut whole) = (Vec::new(), Vec::new());
        for (inst, r) in group_ranges(near) {
            let (rec, base, _) = instances[inst as usize];
            match &self.accel[rec.node.index()] {
                Accel::Mesh { leaves, .. } if r.len() == *leaves as usize => whole.push((rec, base)),
                _ => near_groups.push((inst, rec, base, r)),
            }
        }
        let near_leaves: Vec<u32> = near.iter().map(|&(_, l)| l).collect();
        let first = self.reserve_stamps(near_groups.len() as u32);
        let stamps: Vec<u32> = (first..first + near_groups.len() as u32).collect();
        let mut lists = super::owned::LeafLists::default();
        self.emit_leaves(&near_groups, &near_leaves, &stamps, &mut lists, None);
        let whole_triangles: usize = whole
            .iter()
            .filter_map(|(rec, _)| self.scene.node(rec.node).mesh().map(|m| m.triangle_count()))
            .sum();
        stats
            .counters
            .add(counter, (lists.triangle_count() + whole_triangles) as u64);
        if counter == "near_triangles" {
            stats
                .counters
                .add("near_borrowed_triangles", lists.take_borrowed_count());
        }
        stats.phases.add(Phase::Other, t.elapsed());
        let mut draws = lists.draws(&self.scene, &self.accel, view);
        draws.extend(whole.iter().filter_map(|(rec, base)| {
            Some(Draw {
                mesh: self.scene.node(rec.node).mesh()?,
                triangles: DrawTriangles::All,
                clip_from_object: view.clip_from_object(&rec.world_from_object),
                first_item: *base,
            })
        }));
        crate::rasterize(&mut self.raster, view, frame, &draws, stats);
        drop(draws);
    }

    /// Step 3 with `near_cull=on` (not in the paper): the near set drawn front to back in
    /// growing batches, each unit (a run of near leaves of an instance, or a mesh instance of
    /// a single leaf) tested against the depth drawn so far, as `hzb` tests its boxes
    /// (Greene's face test through a pyramid updated after each batch), after its group
    /// (consecutive units of the instance, [`NEAR_GROUP`]) was tested as one box; hidden
    /// units are not drawn. A batch draws its leaves' own triangles ([`super::owned`]); the
    /// triangles they borrow whose owner was not drawn for the instance come in a last batch,
    /// once every leaf the pass draws is known (none of an instance drawn whole in the rest of
    /// a frame given up: its whole draw holds them). The near z-buffer ends the same (a hidden
    /// unit draws no pixel), so are the unfinished pixels and the frame. With `near_temporal`,
    /// the near leaves that showed a pixel in the last frame ([`Lzb::remember_visible`]) make
    /// the first batch, untested (up to [`NEAR_MAX_BATCH`] references: the set may be stale):
    /// the rest is then
    /// tested against nearly the frame's final depth, as `hzb`'s visible list does. Counters
    /// `near_culled_units`, `near_culled_groups`, `near_culled_triangles`,
    /// `near_visible_triangles` (those last frame's visible leaves own),
    /// `near_borrowed_triangles`.
    ///
    /// # Errors
    /// [`RenderError::Raster`] when the pyramid cannot be allocated.
    pub(super) fn draw_near_culled(
        &mut self,
        view: &View,
        frame: &mut Frame,
        instances: &[(InstanceRec, ItemId, Mat4)],
        near: &[(u32, u32)],
        stats: &mut FrameStats,
        payoff: &mut FramePayoff,
    ) -> Result<()> {
        let t = Instant::now();
        let (w, h) = (view.width(), view.height());
        // With `near_temporal`, each instance's leaves visible last frame come first in its
        // run of pairs (and its units first in the order).
        let visible = std::mem::take(&mut self.near_visible);
        let mut scratch = std::mem::take(&mut self.near_scratch);
        let NearScratch {
            ordered,
            parts,
            units,
            sorted,
            keys,
            groups,
            eyes,
            state,
            lists,
            deferred,
        } = &mut scratch;
        deferred.clear();
        ordered.clear();
        parts.clear();
        state.clear();
        state.resize(instances.len(), NearInstance::default());
        for (inst, r) in group_ranges(near) {
            if let Accel::Mesh { leaves, .. } = &self.accel[instances[inst as usize].0.node.index()] {
                state[inst as usize].all_near = r.len() == *leaves as usize;
            }
            if visible.is_empty() {
                parts.push((inst, r, false));
                continue;
            }
            // This instance's visible leaves (`visible` is sorted by first item).
            let base = instances[inst as usize].1;
            let lo = visible.partition_point(|v| v.0 < base);
            let seen = &visible[lo..lo + visible[lo..].partition_point(|v| v.0 == base)];
            let at = ordered.len();
            if seen.is_empty() {
                // Nothing of it seen: its leaves in their order.
                ordered.extend_from_slice(&near[r]);
                parts.push((inst, at..ordered.len(), false));
                continue;
            }
            let was = |p: &(u32, u32)| seen.binary_search_by_key(&p.1, |v| v.1).is_ok();
            ordered.extend(near[r.clone()].iter().filter(|p| was(p)));
            let rest = ordered.len();
            ordered.extend(near[r].iter().filter(|p| !was(p)));
            parts.push((inst, at..rest, true));
            parts.push((inst, rest..ordered.len(), false));
        }
        let near = if visible.is_empty() { near } else { &ordered[..] };
        drop(visible);
        // The units: a mesh instance of one leaf (drawn whole), or runs of consecutive near
        // leaves of an instance (neighbours in the octree's depth-first order, so close in
        // space) of up to NEAR_UNIT triangle references; and their groups, runs of up to
        // NEAR_GROUP consecutive units of an instance, tested as one box first.
        units.clear();
        groups.clear();
        // Last frame's visible leaves: their triangles, and their references (the first
        // batch's size).
        let (mut visible_triangles, mut visible_refs) = (0usize, 0usize);
        for (inst, r, seen) in parts.drain(..).filter(|p| !p.1.is_empty()) {
            let first_unit = units.len();
            let (rec, _, clip) = &instances[inst as usize];
            let Accel::Mesh {
                octree,
                leaves,
                chunks,
                clusters,
                ..
            } = &self.accel[rec.node.index()]
            else {
                continue;
            };
            let owned_of = clusters.owned_counts();
            let w_row = row_w(clip);
            let whole = r.len() == *leaves as usize && *leaves == 1;
            // Every leaf near, in the walk's order (a part of several leaves holding them all
            // holds them in that order): the units made once.
            let full = r.len() == *leaves as usize && !whole && !chunks.is_empty();
            if full {
                for c in chunks {
                    if seen {
                        visible_triangles += c.owned as usize;
                        visible_refs += c.count as usize;
                    }
                    units.push(NearUnit {
                        distance: if seen {
                            f32::NEG_INFINITY
                        } else {
                            near_distance(w_row, &c.bounds)
                        },
                        inst,
                        leaves: r.start as u32 + c.leaves.start..r.start as u32 + c.leaves.end,
                        whole: false,
                        count: c.count,
                        owned: c.owned,
                        bounds: c.bounds,
                    });
                }
            }
            // Otherwise formed here from the frame's leaves, the same way.
            let mut at = if full { r.end } else { r.start };
            while at < r.end {
                let (end, mut count, mut owned, bounds) = near_unit(octree, owned_of, |i| near[i].1, at..r.end);
                if whole {
                    count = self
                        .scene
                        .node(rec.node)
                        .mesh()
                        .map_or(0, |m| m.triangle_count() as u32);
                    owned = count;
                }
                if seen {
                    visible_triangles += owned as usize;
                    visible_refs += count as usize;
                }
                units.push(NearUnit {
                    distance: if seen {
                        f32::NEG_INFINITY
                    } else {
                        near_distance(w_row, &bounds)
                    },
                    inst,
                    leaves: at as u32..end as u32,
                    whole,
                    count,
                    owned,
                    bounds,
                });
                at = end;
            }
            for start in (first_unit..units.len()).step_by(NEAR_GROUP) {
                let of = &units[start..(start + NEAR_GROUP).min(units.len())];
                groups.push(NearGroup {
                    distance: of.iter().map(|u| u.distance).fold(f32::INFINITY, f32::min),
                    inst,
                    units: start as u32..(start + of.len()) as u32,
                    owned: of.iter().map(|u| u64::from(u.owned)).sum(),
                    bounds: of.iter().fold(Aabb::EMPTY, |a, u| a.union(u.bounds)),
                });
            }
        }
        // Groups by their least view distance (last frame's visible ones first), and the units
        // of each by theirs (ties by their index): an order of the units' indices, each group a
        // run of it, the units themselves left in place (sorting and copying them cost more).
        groups.sort_unstable_by(|a, b| a.distance.total_cmp(&b.distance));
        sorted.clear();
        for g in groups.iter_mut() {
            let at = sorted.len();
            keys.clear();
            keys.extend(g.units.clone().map(|i| distance_key(units[i as usize].distance, i)));
            keys.sort_unstable();
            sorted.extend(keys.iter().map(|&k| k as u32));
            g.units = at as u32..sorted.len() as u32;
        }
        let (order, units) = (&*sorted, &*units);
        let mut pyramid = self.take_pyramid(w, h)?;
        pyramid.clear();
        let eye = view.camera().eye;
        eyes.clear();
        eyes.resize(instances.len(), None);
        let first_stamp = self.reserve_stamps(instances.len() as u32);
        let (mut tested, mut culled_units, mut culled_triangles, mut near_triangles) = (0u64, 0u64, 0u64, 0u64);
        // Groups and units found hidden by their own test (a hidden group's units are not tested).
        let (mut culled_groups, mut culled_boxes) = (0u64, 0u64);
        let mut pyramid_time = Duration::ZERO;
        let mut counts = PyramidCounts::default();
        // The first batch, drawn untested: last frame's visible leaves, or the nearest units.
        let mut batch_triangles = if visible_refs > 0 {
            visible_refs.min(NEAR_MAX_BATCH)
        } else {
            NEAR_FIRST_BATCH
        };
        let (mut next, mut group) = (0, 0);
        let mut first = true;
        // Given up (`crate::payoff`): the rest gathered into one batch, untested.
        let mut finishing = false;
        stats.phases.add(Phase::Other, t.elapsed());
        while next < order.len() {
            let t = Instant::now();
            // Gather a batch: the next units not hidden behind what is drawn.
            let (mut pairs, mut whole, mut rect) = (Vec::new(), Vec::new(), None::<PixelRect>);
            let mut gathered = 0usize;
            while next < order.len() && gathered < batch_triangles {
                // A group of several units starts: one test for all of them.
                if groups.get(group).is_some_and(|g| g.units.start as usize == next) {
                    let g = &groups[group];
                    group += 1;
                    if !first && !finishing && g.units.len() > 1 {
                        tested += 1;
                        let (rec, _, clip) = &instances[g.inst as usize];
                        let e = *eyes[g.inst as usize]
                            .get_or_insert_with(|| rec.world_from_object.inverse().transform_point3(eye));
                        if Occlusion::hierarchical(frame, &pyramid, view).box_hidden(clip, &g.bounds, e, &mut counts) {
                            culled_groups += 1;
                            culled_boxes += 1;
                            culled_units += g.units.len() as u64;
                            culled_triangles += g.owned;
                            payoff.saved(g.owned);
                            next = g.units.end as usize;
                            continue;
                        }
                    }
                }
                let NearUnit {
                    inst,
                    ref leaves,
                    whole: is_whole,
                    count,
                    owned,
                    bounds: b,
                    ..
                } = units[order[next] as usize];
                next += 1;
                let (rec, base, clip) = &instances[inst as usize];
                // The rest of a frame given up: an instance wholly near of which at most half
                // was drawn is drawn whole (its vertices shared, no list to build), once.
                let at = &mut state[inst as usize];
                if finishing && !is_whole {
                    if at.whole {
                        continue;
                    }
                    let all = self
                        .scene
                        .node(rec.node)
                        .mesh()
                        .map_or(0, occult_core::Mesh::triangle_count);
                    if at.all_near && 2 * at.drawn as usize <= all {
                        at.whole = true;
                        whole.push((*rec, *base));
                        gathered += all;
                        continue;
                    }
                }
                // Not weighed by the in-frame payoff's stop rule: it weighs the rays, and a
                // frame's coarse rays and first batch come before any gain of these tests.
                if !first && !finishing {
                    tested += 1;
                    let e = *eyes[inst as usize]
                        .get_or_insert_with(|| rec.world_from_object.inverse().transform_point3(eye));
                    if Occlusion::hierarchical(frame, &pyramid, view).box_hidden(clip, &b, e, &mut counts) {
                        culled_units += 1;
                        culled_boxes += 1;
                        culled_triangles += u64::from(owned);
                        payoff.saved(u64::from(owned));
                        continue;
                    }
                }
                if let Some(r) = screen_rect(clip, &b, w, h) {
                    rect = Some(rect.map_or(r, |a| PixelRect {
                        x0: a.x0.min(r.x0),
                        y0: a.y0.min(r.y0),
                        x1: a.x1.max(r.x1),
                        y1: a.y1.max(r.y1),
                    }));
                }
                if is_whole {
                    whole.push((*rec, *base));
                } else {
                    pairs.extend(near[leaves.start as usize..leaves.end as usize].iter().copied());
                }
                state[inst as usize].drawn = state[inst as usize].drawn.saturating_add(owned);
                gathered += count as usize;
            }
            // Draw it: the leaves' own triangles as clusters per instance (those they borrow
            // are weighed in the last batch), whole meshes whole.
            let (groups, leaves, stamps) = instance_groups(&mut pairs, instances, first_stamp);
            lists.clear();
            self.emit_leaves(&groups, &leaves, &stamps, lists, Some(deferred));
            let mut draws = lists.draws(&self.scene, &self.accel, view);
            draws.extend(whole.iter().filter_map(|(rec, base)| {
                Some(Draw {
                    mesh: self.scene.node(rec.node).mesh()?,
                    triangles: DrawTriangles::All,
                    clip_from_object: view.clip_from_object(&rec.world_from_object),
                    first_item: *base,
                })
            }));
            let submitted = lists.triangle_count()
                + whole
                    .iter()
                    .filter_map(|(rec, _)| self.scene.node(rec.node).mesh().map(|m| m.triangle_count()))
                    .sum::<usize>();
            near_triangles += submitted as u64;
            stats.phases.add(Phase::Other, t.elapsed());
            let raster_before = stats.phases.get(Phase::Raster);
            crate::rasterize(&mut self.raster, view, frame, &draws, stats);
            let raster_time = stats.phases.get(Phase::Raster).saturating_sub(raster_before);
            payoff.rasterized(submitted as u64, raster_time, false);
            drop(draws);
            // Given up (`crate::payoff`): the rest drawn untested, in one batch the rasterizer
            // shares over its threads, and no more pyramid updates.
            if payoff.given_up() {
                if finishing {
                    break;
                }
                finishing = true;
                batch_triangles = usize::MAX;
                continue;
            }
            // The pyramid over what the batch drew, for the next batch's tests.
            // Only where the batch wrote: its units' region cut to the box of the triangles
            // that wrote a fragment.
            let written = crate::written_region(&mut self.raster, view);
            if next < order.len() {
                let t = Instant::now();
                if let Some(r) = rect.zip(written).and_then(|(r, w)| r.intersect(&w)) {
                    pyramid.update(frame, r);
                }
                pyramid_time += t.elapsed();
            }
            batch_triangles = if first && visible_refs > 0 {
                NEAR_FIRST_BATCH
            } else {
                (batch_triangles * 2).min(NEAR_MAX_BATCH)
            };
            first = false;
        }
        // The triangles the drawn leaves borrow whose owner was not drawn for their instance
        // (hidden, far, or beyond the frustum), in one last batch; none of an instance drawn
        // whole in the rest of a frame given up.
        deferred.retain(|&(inst, _)| !state[inst as usize].whole);
        if !deferred.is_empty() {
            let t = Instant::now();
            let (groups, leaves, stamps) = instance_groups(deferred, instances, first_stamp);
            lists.clear();
            self.emit_borrowed(&groups, &leaves, &stamps, lists);
            let draws = lists.draws(&self.scene, &self.accel, view);
            near_triangles += lists.triangle_count() as u64;
            stats.phases.add(Phase::Other, t.elapsed());
            let raster_before = stats.phases.get(Phase::Raster);
            crate::rasterize(&mut self.raster, view, frame, &draws, stats);
            let raster_time = stats.phases.get(Phase::Raster).saturating_sub(raster_before);
            payoff.rasterized(lists.triangle_count() as u64, raster_time, false);
        }
        stats.phases.add(Phase::DepthStructure, pyramid_time);
        stats.boxes_tested += tested;
        stats.boxes_culled += culled_boxes;
        stats.counters.add("near_triangles", near_triangles);
        stats.counters.add("near_culled_units", culled_units);
        stats.counters.add("near_culled_groups", culled_groups);
        stats.counters.add("near_culled_triangles", culled_triangles);
        stats.counters.add("near_visible_triangles", visible_triangles as u64);
        stats
            .counters
            .add("near_borrowed_triangles", scratch.lists.take_borrowed_count());
        self.pyramid = Some(pyramid);
        self.near_scratch = scratch;
        Ok(())
    }

    /// Remembers which leaves showed a pixel of the finished `frame` (`near_temporal`; one
    /// pixel in [`VISIBLE_STRIDE`]² is read): a pixel's item names an instance of
    /// `instances` (by its first item) and a triangle of its mesh, held by a leaf
    /// ([`Accel::Mesh`]'s `leaf_of`). The next frame's near pass draws those of its near
    /// leaves first.
    pub(super) fn remember_visible(&mut self, frame: &Frame, instances: &[(InstanceRec, ItemId, Mat4)]) {
        // Each mesh instance's item range, by first item.
        let mut spans: Vec<(ItemId, ItemId, u32)> = instances
            .iter()
            .filter_map(|(rec, base, _)| {
                let m = self.scene.node(rec.node).mesh()?;
                Some((*base, base + m.triangle_count() as u64, rec.node.index() as u32))
            })
            .collect();
        // By first item, then end: of an empty mesh's span and the next sharing its first
        // item, the search below finds the next.
        spans.sort_unstable();
        let mut visible = std::mem::take(&mut self.near_visible);
        visible.clear();
        let (mut last_item, mut span) = (NO_ITEM, None::<(ItemId, ItemId, u32)>);
        // An ordering, not a proof: a leaf missed is tested like any other.
        let w = frame.width() as usize;
        let sampled = frame
            .items()
            .chunks(w)
            .step_by(VISIBLE_STRIDE)
            .flat_map(|row| row.iter().step_by(VISIBLE_STRIDE));
        for &item in sampled {
            if item == last_item || item == NO_ITEM {
                continue;
            }
            last_item = item;
            // Neighbouring pixels mostly show one instance: its span is tried first.
            if !span.is_some_and(|(b, e, _)| (b..e).contains(&item)) {
                let k = spans.partition_point(|s| s.0 <= item);
                span = k.checked_sub(1).map(|k| spans[k]).filter(|&(_, e, _)| item < e);
            }
            let Some((base, _, node)) = span else {
                continue;
            };
            if let Accel::Mesh { leaf_of, .. } = &self.accel[node as usize] {
                let leaf = leaf_of.get((item - base) as usize).copied().unwrap_or(u32::MAX);
                if leaf != u32::MAX && visible.last() != Some(&(base, leaf)) {
                    visible.push((base, leaf));
                }
            }
        }
        visible.sort_unstable();
        visible.dedup();
        self.near_visible = visible;
    }

    /// Step 3½ (`far_cull=on`, not in the paper): the far leaves hidden behind what the near
    /// pass drew are removed from `far` before step 4 projects their polygons. A leaf whose
    /// box is hidden over every pixel it covers (`hzb`'s face test, through a pyramid of the
    /// frame's depth) holds nothing a pixel shows: each of its pixels shows a near triangle
    /// in front of it, so no ray needs to be cast there for it (another far leaf may still
    /// cover the pixel). Tested per instance, the union of its far leaves' boxes: one test
    /// drops them all (tests leaf by leaf in the instances not hidden cost more than the
    /// projections they saved, docs/lzb.md). Returns the leaves removed.
    ///
    /// # Errors
    /// [`RenderError::Raster`] when the pyramid cannot be allocated.
    pub(super) fn cull_far(
        &mut self,
        view: &View,
        frame: &Frame,
        instances: &[(InstanceRec, ItemId, Mat4)],
        far: &mut Vec<(u32, u32)>,
        stats: &mut FrameStats,
    ) -> Result<u64> {
        let t = Instant::now();
        let (w, h) = (view.width(), view.height());
        let mut pyramid = self.take_pyramid(w, h)?;
        pyramid.rebuild(frame);
        stats.phases.add(Phase::DepthStructure, t.elapsed());
        let t = Instant::now();
        let occlusion = Occlusion::hierarchical(frame, &pyramid, view);
        let eye = view.camera().eye;
        let mut counts = PyramidCounts::default();
        let (mut tested, mut hidden) = (0u64, 0u64);
        // The walk lists an instance's leaves together, instances in order: grouped already
        // (sorting 143 k leaves a frame cost a twentieth of a city street's frame). The order
        // of the leaves does not matter to what follows (the pixels they project to).
        if !far.is_sorted_by_key(|p| p.0) {
            far.sort_unstable_by_key(|p| p.0);
        }
        let before = far.len();
        // The instances not hidden keep their leaves, moved down over the hidden ones'.
        let mut kept = 0;
        for (inst, r) in group_ranges(far) {
            let (rec, _, clip) = &instances[inst as usize];
            let hidden_instance = match &self.accel[rec.node.index()] {
                Accel::Mesh { octree, .. } => {
                    let nodes = octree.nodes();
                    let e = rec.world_from_object.inverse().transform_point3(eye);
                    let union = far[r.clone()]
                        .iter()
                        .fold(Aabb::EMPTY, |b, &(_, leaf)| b.union(nodes[leaf as usize].bounds));
                    tested += 1;
                    occlusion.box_hidden(clip, &union, e, &mut counts)
                }
                _ => false,
            };
            if hidden_instance {
                hidden += 1;
                continue;
            }
            far.copy_within(r.clone(), kept);
            kept += r.len();
        }
        far.truncate(kept);
        self.pyramid = Some(pyramid);
        stats.boxes_tested += tested;
        stats.boxes_culled += hidden;
        stats.phases.add(Phase::Cull, t.elapsed());
        Ok((before - far.len()) as u64)
    }

    /// The frame's pyramid (`w × h`), made when there is none of that size; handed back to
    /// `self.pyramid` by the caller.
    fn take_pyramid(&mut self, w: u32, h: u32) -> Result<ZPyramid> {
        match self.pyramid.take() {
            Some(p) if p.width() == w && p.height() == h => Ok(p),
            _ => Ok(ZPyramid::new(w, h)?),
        }
    }
}

/// The `(instance, leaf)` pairs `pairs` (sorted here) as [`Lzb::emit_leaves`] takes them: per
/// instance its record and range of the leaves, the leaves, and per instance its stamp of the
/// frame (`first_stamp` and the instance's index).
#[allow(clippy::type_complexity)]
fn instance_groups(
    pairs: &mut [(u32, u32)],
    instances: &[(InstanceRec, ItemId, Mat4)],
    first_stamp: u32,
) -> (
    Vec<(u32, InstanceRec, ItemId, std::ops::Range<usize>)>,
    Vec<u32>,
    Vec<u32>,
) {
    pairs.sort_unstable();
    let ranges = group_ranges(pairs);
    let stamps = ranges.iter().map(|&(inst, _)| first_stamp + inst).collect();
    let groups = ranges
        .into_iter()
        .map(|(inst, r)| {
            let (rec, base, _) = instances[inst as usize];
            (inst, rec, base, r)
        })
        .collect();
    (groups, pairs.iter().map(|&(_, l)| l).collect(), stamps)
}

/// A unit of the near pass of an instance all of whose leaves are near ([`near_chunks`]).
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct NearChunk {
    /// Its leaves: positions in the order [`super::leaves::cull_octree`] meets the non-empty leaves.
    leaves: std::ops::Range<u32>,
    /// Its triangle references.
    count: u32,
    /// The triangles its leaves own ([`super::owned`]).
    owned: u32,
    /// The union of its leaves' boxes.
    bounds: Aabb,
}

/// The near pass's units of a mesh instance all of whose leaves are near (an instance wholly
/// in the frustum before the plane: most of them when the plane lies far), made once: runs of
/// consecutive non-empty leaves, in the order [`super::leaves::cull_octree`] meets them, of up to
/// [`super::NEAR_UNIT`] triangle references, exactly as the near pass forms them from a frame's
/// leaves, which reads every near leaf's node.
pub(super) fn near_chunks(octree: &RayOctree, owned_of: &[u32]) -> Vec<NearChunk> {
    let mut order = Vec::new();
    let mut stack = vec![0u32];
    while let Some(n) = stack.pop() {
        let on = &octree.nodes()[n as usize];
        if on.is_leaf() {
            if on.count > 0 {
                order.push(n);
            }
        } else {
            stack.extend(on.children().rev());
        }
    }
    let mut chunks = Vec::new();
    let mut at = 0;
    while at < order.len() {
        let (end, count, owned, bounds) = near_unit(octree, owned_of, |i| order[i], at..order.len());
        chunks.push(NearChunk {
            leaves: at as u32..end as u32,
            count,
            owned,
            bounds,
        });
        at = end;
    }
    chunks
}

/// The near pass's unit that starts at the first of the leaves `run` (`leaf(i)` the node of
/// the `i`th): it and the leaves after it while they hold fewer than [`super::NEAR_UNIT`] triangle
/// references. Returns where it ends, its references, the triangles its leaves own (`owned`:
/// per node) and the union of its leaves' boxes.
pub(super) fn near_unit(
    octree: &RayOctree,
    owned: &[u32],
    leaf: impl Fn(usize) -> u32,
    run: std::ops::Range<usize>,
) -> (usize, u32, u32, Aabb) {
    let (mut end, mut count, mut own, mut bounds) = (run.start, 0u32, 0u32, Aabb::EMPTY);
    while end < run.end && (end == run.start || count < NEAR_UNIT) {
        let n = leaf(end);
        let on = &octree.nodes()[n as usize];
        count += on.count;
        own += owned[n as usize];
        bounds = bounds.union(on.bounds);
        end += 1;
    }
    (end, count, own, bounds)
}

/// The near pass's lists (`near_cull=on`), kept from frame to frame and cleared before each: on
/// a view of a hundred thousand near leaves they hold megabytes, which fresh vectors faulted in
/// page by page every frame (docs/perf-log.md).
#[derive(Default)]
pub(super) struct NearScratch {
    /// The near pairs reordered (`near_temporal`: each instance's leaves seen last frame first).
    ordered: Vec<(u32, u32)>,
    /// Runs of `ordered` of an instance, seen last frame or not.
    parts: Vec<(u32, std::ops::Range<usize>, bool)>,
    /// The units as formed.
    units: Vec<NearUnit>,
    /// The order they are drawn in: indices into `units`, group by group.
    sorted: Vec<u32>,
    /// A group's units as sort keys ([`distance_key`]).
    keys: Vec<u64>,
    /// The groups of units.
    groups: Vec<NearGroup>,
    /// Per instance: the eye in its space, once needed.
    eyes: Vec<Option<Vec3>>,
    /// Per instance: what the rest of a frame given up draws whole.
    state: Vec<NearInstance>,
    /// A batch's draw lists.
    lists: super::owned::LeafLists,
    /// The drawn leaves that borrow triangles, `(instance, leaf)`: their borrowed triangles
    /// are weighed once the pass drew every leaf it draws.
    deferred: Vec<(u32, u32)>,
}

/// An instance in the near pass ([`NearScratch::state`]).
#[derive(Clone, Copy, Default)]
struct NearInstance {
    /// Every leaf of it is near.
    all_near: bool,
    /// Drawn whole, in the rest of a frame given up.
    whole: bool,
    /// Triangles its units' leaves own, of its units drawn.
    drawn: u32,
}

impl NearScratch {
    /// Bytes held.
    pub(super) fn memory_bytes(&self) -> usize {
        self.ordered.capacity() * std::mem::size_of::<(u32, u32)>()
            + self.parts.capacity() * std::mem::size_of::<(u32, std::ops::Range<usize>, bool)>()
            + self.units.capacity() * std::mem::size_of::<NearUnit>()
            + self.sorted.capacity() * std::mem::size_of::<u32>()
            + self.keys.capacity() * std::mem::size_of::<u64>()
            + self.groups.capacity() * std::mem::size_of::<NearGroup>()
            + self.eyes.capacity() * std::mem::size_of::<Option<Vec3>>()
            + self.state.capacity() * std::mem::size_of::<NearInstance>()
            + self.lists.memory_bytes()
            + self.deferred.capacity() * 8
    }
}

/// A unit's sort key: its distance in the high half, mapped so that integers order as
/// `f32::total_cmp` orders the distances, and its index in the low half (ties by index). An
/// integer sort of these is several times cheaper than a sort of the units by a comparison.
pub(super) fn distance_key(distance: f32, index: u32) -> u64 {
    let bits = distance.to_bits();
    let ordered = if bits & 0x8000_0000 != 0 {
        !bits
    } else {
        bits | 0x8000_0000
    };
    (u64::from(ordered) << 32) | u64::from(index)
}
