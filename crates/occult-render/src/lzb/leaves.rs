//! Step 1 of a frame: hierarchical view-frustum culling over the octrees, collecting the
//! leaves near and far of the plane.

use super::*;

/// Step 1: hierarchical view-frustum culling over the octrees (the crate's scene walk,
/// [`crate::walk`]), collecting leaves near and far of the plane.
pub(super) struct Walk<'a> {
    pub(super) walk: SceneWalk<'a>,
    pub(super) lzb: &'a Lzb,
    pub(super) ctx: &'a FrameCtx,
    pub(super) instances: Vec<(InstanceRec, ItemId, Mat4)>,
    pub(super) near: Vec<(u32, u32)>,
    pub(super) far: Vec<(u32, u32)>,
    /// `plane=cost`: every leaf `(instance, leaf, least view distance, triangle references)`,
    /// split once the plane is chosen.
    pub(super) deferred: Option<Vec<(u32, u32, f32, u32)>>,
}

/// The frustum-culled descent of `octree` from its root, children in order (`inside`: the
/// node occurrence lies wholly inside the frustum): empty leaves are skipped uncounted, every
/// other node reached is counted visited and tested unless inside; `leaf(walk, node_index,
/// inside)` is called for each leaf not outside.
pub(super) fn cull_octree<'s>(
    walk: &mut SceneWalk<'s>,
    octree: &RayOctree,
    frustum: &Frustum,
    inside: bool,
    mut leaf: impl FnMut(&mut SceneWalk<'s>, u32, bool),
) {
    let mut stack = vec![(0u32, inside)];
    while let Some((n, inside)) = stack.pop() {
        let on = &octree.nodes()[n as usize];
        if on.is_leaf() && on.count == 0 {
            continue;
        }
        walk.stats.nodes_visited += 1;
        let inside = inside
            || match walk.test(frustum, &on.bounds) {
                Containment::Outside => continue,
                c => c == Containment::Inside,
            };
        if on.is_leaf() {
            leaf(walk, n, inside);
        } else {
            stack.extend(on.children().rev().map(|c| (c, inside)));
        }
    }
}

impl<'a> Visitor<'a> for Walk<'a> {
    fn walk(&mut self) -> &mut SceneWalk<'a> {
        &mut self.walk
    }

    /// A mesh: its leaves in the frustum, near or far of the plane. A group: the instances of
    /// its leaves in the frustum, each tested with its own box.
    fn visit(&mut self, at: &NodeAt<'a>) {
        let lzb: &'a Lzb = self.lzb;
        match &lzb.accel[at.place.id.index()] {
            Accel::Empty => {}
            Accel::Mesh { octree, .. } => {
                let clip = self.ctx.view.clip_from_object(&at.place.world_from_node);
                let w_row = row_w(&clip);
                let inst = self.instances.len() as u32;
                let mut any = false;
                let (ctx, near, far) = (self.ctx, &mut self.near, &mut self.far);
                let deferred = &mut self.deferred;
                cull_octree(&mut self.walk, octree, &at.frustum, at.inside, |walk, n, _| {
                    let on = &octree.nodes()[n as usize];
                    any = true;
                    walk.meet_triangles(on.count as u64);
                    // The leaf's tight box (`RayOctree::tighten_leaves`).
                    if let Some(d) = deferred {
                        d.push((inst, n, near_distance(w_row, &on.bounds), on.count));
                    } else if ctx.is_near(w_row, &on.bounds) {
                        near.push((inst, n));
                    } else {
                        far.push((inst, n));
                    }
                });
                if any {
                    self.instances.push((
                        InstanceRec {
                            node: at.place.id,
                            world_from_object: at.place.world_from_node,
                        },
                        at.place.first_item,
                        clip,
                    ));
                }
            }
            Accel::Group { octree, bounds, .. } => {
                let mut chosen: Vec<(u32, bool)> = Vec::new();
                cull_octree(&mut self.walk, octree, &at.frustum, at.inside, |_, n, inside| {
                    // An instance overlaps its leaves without lying within them: the leaf's
                    // containment holds for it only when its box is within the leaf's.
                    let leaf = octree.nodes()[n as usize].bounds;
                    chosen.extend(octree.leaf_primitives(n).iter().map(|&i| {
                        let b = bounds[i as usize];
                        (i, inside && b.min.cmpge(leaf.min).all() && b.max.cmple(leaf.max).all())
                    }));
                });
                // Instances span leaves: each once, "inside" if any of its leaves was.
                chosen.sort_unstable_by_key(|&(i, inside)| (i, !inside));
                chosen.dedup_by_key(|&mut (i, _)| i);
                for (i, inside) in chosen {
                    let i = i as usize;
                    let inside = inside
                        || match self.walk.test(&at.frustum, &bounds[i]) {
                            Containment::Outside => continue,
                            c => c == Containment::Inside,
                        };
                    self.enter(at.child(i), inside);
                }
            }
        }
    }
}
